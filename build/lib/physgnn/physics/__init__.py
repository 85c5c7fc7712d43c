"""Physics rules of spheres: scenes and trajectories, quaternions, kinematics, energy, integration,
geometry. numpy and torch only.
"""

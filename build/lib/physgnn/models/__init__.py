"""Simulators: the learned simulator, the trivial baselines, sleeping spheres and the Simulator
protocol that the rollout relies on.
"""

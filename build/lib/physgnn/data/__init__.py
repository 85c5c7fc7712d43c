"""Data on disk and in memory: the HDF5 dataset, the simulator's view of a scene (SceneState) and
one-step state pairs.
"""

"""Ground truth: scene families, the pybullet engine, dataset generation and the cached hard
scenes.
"""

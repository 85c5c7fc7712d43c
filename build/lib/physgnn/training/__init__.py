"""Training with Lightning: the module, the data module, the rollout callback, train(cfg) and
finished runs on disk.
"""

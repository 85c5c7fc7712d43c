"""Evaluation of finished runs: rollouts on test, OOD and hard scenes, metrics rows, the data
report and the sleep study.
"""

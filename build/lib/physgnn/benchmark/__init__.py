"""make bench: what accuracy costs in time (machine, learned steps, pybullet, training throughput,
activity).
"""

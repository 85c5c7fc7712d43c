"""Who is near whom: neighbour search and the graph (pp and ps edges with their features) rebuilt
every step.
"""

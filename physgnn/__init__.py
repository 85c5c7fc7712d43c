"""physgnn: learned rigid-body physics of spheres with graph networks."""

__version__ = "0.1.0"

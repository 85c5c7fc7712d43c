"""physgnn: learned rigid-body physics of spheres with graph networks."""

__version__ = "0.1.0"

from pathlib import Path as _Path

# The Hydra configs live beside the package (editable install); an absolute path lets
# `main` run from `python -m`, from a console script or from a test alike.
CONF_DIR = str(_Path(__file__).resolve().parent.parent / "conf")

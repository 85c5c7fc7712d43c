"""physgnn: learned rigid-body physics of spheres with graph networks."""

__version__ = "0.1.0"

import os as _os
from pathlib import Path as _Path

# The Hydra configs live beside the package (editable install); an absolute path lets
# `main` run from `python -m`, from a console script or from a test alike.
CONF_DIR = str(_Path(__file__).resolve().parent.parent / "conf")

# OpenMP threads that wait for work spin 300 000 rounds by default (GNU OpenMP, which torch's
# CPU wheel uses) before they sleep. When other processes keep the cores busy, those spinning
# threads take the CPU from the one thread still working: 2-thread training steps ran about
# 8x slower than 1-thread ones (docs/PERFORMANCE.md). 1 000 rounds still bridge the short
# gaps between the operations of one step. Read by the OpenMP runtime when torch is first
# imported, so it acts for `python -m physgnn.X`; an explicit setting wins.
_os.environ.setdefault("GOMP_SPINCOUNT", "1000")

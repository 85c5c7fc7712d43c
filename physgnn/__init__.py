"""physgnn: learned rigid-body physics of spheres with graph networks."""

__version__ = "0.1.0"

import os as _os
from pathlib import Path as _Path


def _conf_dir() -> str:
    """The Hydra configs: a checkout's top-level ``conf/`` (beside ``pyproject.toml``), else the
    copy an installed wheel carries as ``physgnn/conf``. Absolute, so that ``main`` runs alike
    from ``python -m``, the ``physgnn`` console script or a test."""
    package = _Path(__file__).resolve().parent
    checkout = package.parent
    if (checkout / "pyproject.toml").is_file() and (checkout / "conf").is_dir():
        return str(checkout / "conf")
    return str(package / "conf")


CONF_DIR = _conf_dir()
# The scenes known by name, the config group ``scene``: scene families and the example scene
# files (``simulate scene=throw`` and ``load_scene("throw")`` find ``throw.yaml`` here).
SCENES_DIR = str(_Path(CONF_DIR) / "scene")

# OpenMP threads that wait for work spin 300 000 rounds by default (GNU OpenMP, which torch's
# CPU wheel uses) before they sleep. When other processes keep the cores busy, those spinning
# threads take the CPU from the one thread still working: 2-thread training steps ran about
# 8x slower than 1-thread ones (docs/PERFORMANCE.md). 1 000 rounds still bridge the short
# gaps between the operations of one step. Read by the OpenMP runtime when torch is first
# imported, so it acts for `python -m physgnn.X`; an explicit setting wins.
_os.environ.setdefault("GOMP_SPINCOUNT", "1000")

"""``python -m physgnn.ship RUN_DIR [OUT_DIR] [CHECKPOINT]`` (``physgnn ship``, ``make ship
RUN=...``): a trained run shipped as a small run folder of weights only, loadable wherever a
run is. ``OUT_DIR`` (default ``physgnn/pretrained``, what ``run=pretrained`` names) holds the
run's config, the weights of its best checkpoint (or ``CHECKPOINT``) without the optimiser
state, and its ``run.json``; a folder of yours is never written over.

The work is :func:`physgnn.training.export.main` (imported after ``--help``: :mod:`physgnn.cli`).
"""

import sys

from physgnn.cli import resolve


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else [str(arg) for arg in argv]
    if argv and argv[0] in ("-h", "--help"):
        print(__doc__.strip())
        return 0
    return resolve("physgnn.training.export:main")(argv)


if __name__ == "__main__":
    sys.exit(main())

"""``physgnn <command> [arguments]``: the console script; ``python -m physgnn`` is the same.

Each command is its ``python -m physgnn.<module>`` (same arguments, same ``--help``):
``physgnn train model.network.M=3`` runs ``python -m physgnn.train model.network.M=3``.
"""

from __future__ import annotations

import importlib
import sys

# command -> (module whose ``main`` runs it, what it does)
COMMANDS = {
    "train": ("physgnn.train", "train a learned simulator (Hydra overrides)"),
    "generate": ("physgnn.generate", "generate a dataset (data=small|tiny|paper)"),
    "eval": ("physgnn.eval", "evaluate the finished runs and write the report"),
    "simulate": ("physgnn.simulate", "simulate a scene file, and roll a run out on it"),
    "study": ("physgnn.study", "the ablation study (every sweep x 3 seeds)"),
    "bench": ("physgnn.bench", "accuracy versus time"),
    "ship": ("physgnn.ship", "export a run's weights as the shipped model"),
    "data-report": ("physgnn.data_report", "Table 1 of a dataset"),
    "sleep-study": ("physgnn.sleep_study", "sleeping spheres off versus on"),
}


def usage() -> str:
    lines = [
        "usage: physgnn <command> [arguments]   (physgnn <command> --help; physgnn --version)",
        "",
        "commands:",
    ]
    lines += [f"  {name:<12} {text}" for name, (_, text) in COMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> object:
    """Run ``argv[0]``'s command with the rest of ``argv`` (default ``sys.argv[1:]``)."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    if argv[0] in ("-V", "--version"):
        print(f"physgnn {importlib.import_module('physgnn').__version__}")
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(
            f"error: unknown command '{name}'; choose one of {', '.join(COMMANDS)}", file=sys.stderr
        )
        sys.exit(2)
    module = importlib.import_module(COMMANDS[name][0])
    sys.argv = [f"physgnn {name}", *rest]  # what the command parses, and its help's name
    if name == "ship":
        sys.exit(module.main(rest))
    # DDP's launcher starts the other processes as `python -m <__main__'s module>` followed by
    # sys.argv[1:]: as the command's module, they run `python -m physgnn.train <rest>`, not
    # this script without its command (the console script's __main__ has no module at all).
    main_module = sys.modules["__main__"]
    kept = getattr(main_module, "__spec__", None)
    main_module.__spec__ = module.__spec__
    try:
        return module.main()
    finally:
        main_module.__spec__ = kept


if __name__ == "__main__":
    main()

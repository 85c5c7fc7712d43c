"""``python -m physgnn.eval [runs=PATH] [dataset=PATH]``: evaluate finished runs (``make eval``).

The work is :func:`physgnn.evaluation.evaluate.evaluate`: metrics.csv, report.md, figures,
videos and the stability section (imported once the command line composes: :mod:`physgnn.cli`).
"""

from physgnn.cli import command


def _written(path) -> str:
    return f"report written to {path}"


main = command("eval", "physgnn.evaluation.evaluate:evaluate", done=_written)

if __name__ == "__main__":
    main()

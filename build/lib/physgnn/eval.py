"""``python -m physgnn.eval [runs=PATH] [dataset=PATH]``: evaluate finished runs (``make eval``).

The work is :func:`physgnn.evaluation.evaluate.evaluate`: metrics.csv, report.md, figures,
videos and the stability section.
"""

from physgnn.cli import command
from physgnn.evaluation.evaluate import evaluate

main = command("eval", evaluate, done=lambda path: f"report written to {path}")

if __name__ == "__main__":
    main()

"""``python -m physgnn.sleep_study run=PATH``: sleeping off against on (``make sleep-study``).

The work is :func:`physgnn.evaluation.sleep_study.study`; prints its markdown table.
"""

from physgnn.cli import command
from physgnn.evaluation.sleep_study import markdown, study

main = command("sleep_study", study, done=markdown)

if __name__ == "__main__":
    main()

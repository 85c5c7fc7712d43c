"""``python -m physgnn.sleep_study run=PATH``: sleeping off against on (``make sleep-study``).

The work is :func:`physgnn.evaluation.sleep_study.study`; prints its markdown table (imported
once the command line composes: :mod:`physgnn.cli`).
"""

from physgnn.cli import command

WORK = "physgnn.evaluation.sleep_study"
main = command("sleep_study", f"{WORK}:study", done=f"{WORK}:markdown")

if __name__ == "__main__":
    main()

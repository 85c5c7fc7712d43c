"""``python -m physgnn.data_report [preset=NAME | dataset=PATH]``: Table 1 of a dataset
(``make data-report PRESET=NAME``).

The work is :func:`physgnn.evaluation.data_report.data_report` (prints the table, writes
``<dataset>/report.json``; imported once the command line composes: :mod:`physgnn.cli`).
"""

from physgnn.cli import command

main = command("data_report", "physgnn.evaluation.data_report:data_report")

if __name__ == "__main__":
    main()

"""``python -m physgnn.study [--dry-run] [key=value ...]``: the ablation study (``make study``).

The work is :func:`physgnn.ablation.study.run_study`; config ``conf/study.yaml``. ``--dry-run``
(= ``dry_run=true``) lists the jobs, which are already in the registry and the estimated time.
"""

import sys

from physgnn.ablation.study import run_study, written
from physgnn.cli import command

_main = command("study", run_study, done=written)


def main():
    sys.argv = ["dry_run=true" if a == "--dry-run" else a for a in sys.argv]
    return _main()


if __name__ == "__main__":
    main()

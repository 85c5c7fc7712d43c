"""``python -m physgnn.study [--dry-run] [key=value ...]``: the ablation study (``make study``).

The work is :func:`physgnn.ablation.study.run_study` (imported once the command line
composes: :mod:`physgnn.cli`); config ``conf/study.yaml``. ``--dry-run`` (= ``dry_run=true``)
lists the jobs, which are already in the registry and the estimated time.
"""

import sys

from physgnn.cli import command

WORK = "physgnn.ablation.study"
_main = command("study", f"{WORK}:run_study", done=f"{WORK}:written")


def main():
    sys.argv = ["dry_run=true" if a == "--dry-run" else a for a in sys.argv]
    return _main()


if __name__ == "__main__":
    main()

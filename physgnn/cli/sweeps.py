"""A Hydra callback that calls a function once every job of a sweep is done, in the process
that launched them: whichever launcher ran the jobs (Hydra's own, joblib's processes,
submitit's SLURM jobs, for which that process waits), it runs once, after all of them.

``hydra.callbacks.<name>: {_target_: physgnn.cli.sweeps.AfterSweep, run: <function>}`` in a
command's config (conf/generate.yaml merges the shards of a sweep over them).
"""

from __future__ import annotations

import sys
import traceback

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.experimental.callback import Callback
from hydra.utils import get_method
from omegaconf import DictConfig, OmegaConf

from physgnn.cli import USER_ERRORS, disk_error, disk_problem, fail


def swept_values(config: DictConfig) -> dict[str, list]:
    """The values each key of a sweep's command line took (``shard=range(0,3)`` -> [0, 1, 2],
    ``data=tiny`` -> ['tiny'])."""
    task = [str(o) for o in OmegaConf.select(config, "hydra.overrides.task") or []]
    values = {}
    for override in OverridesParser.create().parse_overrides(task):
        sweep = override.is_sweep_override()
        values[override.key_or_group] = (
            list(override.sweep_iterator()) if sweep else [override.value()]
        )
    return values


class AfterSweep(Callback):
    """``run(config, swept)`` at the end of a sweep (``config``: the sweep's, ``swept``:
    :func:`swept_values`); the line it returns is printed. A user's error is one line and its
    exit code, a bug its traceback and exit code 1 (Hydra would only warn)."""

    def __init__(self, run: str) -> None:
        self.run = run

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        try:
            line = get_method(self.run)(config, swept_values(config))
        except USER_ERRORS as err:
            fail(err)
        except Exception as err:
            if disk_problem(err):
                fail(disk_error(err))
            traceback.print_exception(err)
            sys.exit(1)
        if line:
            print(line)

"""A run folder claimed by one training, before Hydra writes into it.

Hydra writes ``.hydra/config.yaml``, ``hydra.yaml`` and ``overrides.yaml`` into the run folder
before the training's own checks run: a second training there (two started within one second
share the default ``runs/<experiment>/<time>`` folder; or one ``run_dir=`` given twice)
rewrote the first run's config, and the finished run no longer loaded. :class:`ClaimRunDir`, a
Hydra callback (``hydra.callbacks.claim_run_dir`` in conf/train.yaml), runs before those
writes: it holds ``<run_dir>.lock`` (:func:`physgnn.locks.exclusive`) until the run ends and
checks the folder (:func:`~physgnn.training.resume_checks.check_run_dir`), so a refused training
writes nothing there. DDP's other processes leave it to the first.
"""

from __future__ import annotations

import atexit
import sys
from contextlib import ExitStack
from pathlib import Path

from hydra.experimental.callback import Callback
from lightning.pytorch.utilities.rank_zero import rank_zero_only
from omegaconf import DictConfig, OmegaConf

from physgnn.errors import PhysgnnError, one_line
from physgnn.locks import exclusive
from physgnn.training.resume_checks import check_run_dir

# The lock of this process's run: released at the run's end, or when the process exits.
_held = ExitStack()
atexit.register(_held.close)


def claim_run_dir(run_dir: Path) -> Path:
    """Hold ``<run_dir>.lock`` until :func:`release` (a live holder: one line naming it)."""
    _held.close()  # a run of this process before this one is over
    way_out = (
        "wait for it to end, stop it (it saves last.ckpt; train again there to resume), or "
        "choose another run_dir"
    )
    lock = run_dir.with_name(run_dir.name + ".lock")
    return _held.enter_context(exclusive(lock, f"run_dir {run_dir}", way_out))


def release() -> None:
    _held.close()


class ClaimRunDir(Callback):
    """Hydra callback: claim and check the run folder before Hydra writes into it; let go of
    it when the run ends."""

    def on_run_start(self, config: DictConfig, **kwargs) -> None:
        if rank_zero_only.rank != 0:
            return
        run_dir = Path(str(OmegaConf.select(config, "hydra.run.dir"))).absolute()
        overrides = [str(o) for o in OmegaConf.select(config, "hydra.overrides.task") or []]
        try:
            claim_run_dir(run_dir)
            check_run_dir(config, run_dir, overrides)
        except PhysgnnError as err:
            release()
            print(f"error: {one_line(err)}", file=sys.stderr)
            sys.exit(err.exit_code)

    def on_run_end(self, config: DictConfig, **kwargs) -> None:
        release()

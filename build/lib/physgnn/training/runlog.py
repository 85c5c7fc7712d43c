"""``<run_dir>/train.log``: every training session's log lines, in the run's own folder.

Under Hydra the log file is ``<Hydra's output dir>/train.log``. When ``run_dir`` is
elsewhere (``run_dir=<run>``, the resume command an interrupted run prints, or a fresh run
given its folder), :func:`run_log` moves the session's file logging there (appending, so the
run's log goes on after its interruption) for as long as training runs."""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from hydra.core.hydra_config import HydraConfig

LOG_NAME = "train.log"
FORMAT = "[%(asctime)s][%(name)s][%(levelname)s] - %(message)s"


def _file_handlers(logger: logging.Logger) -> list[logging.FileHandler]:
    return [h for h in logger.handlers if isinstance(h, logging.FileHandler)]


@contextmanager
def run_log(run_dir: Path) -> Iterator[None]:
    """Within, the root logger's file output goes to ``run_dir/train.log`` (appended) instead
    of Hydra's log file; nothing changes outside Hydra or where the two are one file."""
    root, path = logging.getLogger(), (Path(run_dir) / LOG_NAME).resolve()
    hydras = _file_handlers(root)
    if not HydraConfig.initialized() or any(Path(h.baseFilename) == path for h in hydras):
        yield
        return
    handler = logging.FileHandler(path, mode="a")
    handler.setFormatter(hydras[0].formatter if hydras else logging.Formatter(FORMAT))
    for old in hydras:
        root.removeHandler(old)
    root.addHandler(handler)
    try:
        yield
    finally:
        root.removeHandler(handler)
        handler.close()
        for old in hydras:
            root.addHandler(old)

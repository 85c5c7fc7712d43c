"""Lightning's known-harmless messages kept off a training's first screen, each by its own
words (never a blanket filter: any other warning still shows):

- torch's deprecation of ``LeafSpec``, which Lightning's own code still uses;
- "The 'train_dataloader' does not have many workers": physgnn's loaders gather batches from
  tables held in memory, so worker processes would only copy them;
- the "💡 Tip:" adverts (litlogger, litmodels);
- "`weights_only` was not set": Lightning loading the run's own checkpoint.
"""

from __future__ import annotations

import logging
import re
import warnings

from lightning.pytorch.utilities.warnings import PossibleUserWarning

# (category, a regular expression the message starts with)
WARNINGS = (
    (FutureWarning, re.escape("`isinstance(treespec, LeafSpec)` is deprecated")),
    (PossibleUserWarning, r"The '\w+' does not have many workers"),
)
# Lightning's logger -> the starts of its INFO lines dropped
LOG_LINES = {
    "lightning.pytorch.utilities.rank_zero": ("💡 Tip:",),
    "lightning.pytorch.trainer.connectors.checkpoint_connector": ("`weights_only` was not set",),
}


class DropLines(logging.Filter):
    """Drops the records whose message starts with one of ``starts``."""

    def __init__(self, starts: tuple[str, ...]):
        super().__init__()
        self.starts = starts

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith(self.starts)


def quiet_lightning() -> None:
    """Filter the messages of the module doc (again: no filter is added twice)."""
    for category, words in WARNINGS:
        warnings.filterwarnings("ignore", message=words, category=category)
    for name, starts in LOG_LINES.items():
        logger = logging.getLogger(name)
        if not any(isinstance(f, DropLines) for f in logger.filters):
            logger.addFilter(DropLines(starts))

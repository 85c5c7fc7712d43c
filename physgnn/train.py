"""``python -m physgnn.train [overrides]``: train a learned simulator (``make train``).

The work is :func:`physgnn.training.train.train` (imported once the command line composes:
:mod:`physgnn.cli`); ``main`` returns the final validation loss, the value a Hydra sweeper
optimises.
"""

from physgnn.cli import command
from physgnn.training.layout import check_renamed

# A flat recipe key of an earlier physgnn names today's before the config composes; a resume
# with other overrides is refused before Hydra rewrites the run's .hydra folder.
CHECKS = (check_renamed, "physgnn.training.resume_checks:check_resume_argv")
main = command("train", "physgnn.training.train:val_loss", before=CHECKS)

if __name__ == "__main__":
    main()

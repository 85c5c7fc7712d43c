"""``python -m physgnn.train [overrides]``: train a learned simulator (``make train``).

The work is :func:`physgnn.training.train.train`; ``main`` returns the final validation loss,
the value a Hydra sweeper optimises.
"""

from physgnn.cli import command
from physgnn.training.checks import check_resume_argv
from physgnn.training.train import train


def _val_loss(cfg) -> float | None:
    return train(cfg)["val_loss"]


# A resume with other overrides is refused before Hydra rewrites the run's .hydra folder.
main = command("train", _val_loss, before=check_resume_argv)

if __name__ == "__main__":
    main()

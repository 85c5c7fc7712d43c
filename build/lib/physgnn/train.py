"""``python -m physgnn.train [overrides]``: train a learned simulator (``make train``).

The work is :func:`physgnn.training.train.train`; ``main`` returns the final validation loss,
the value a Hydra sweeper optimises.
"""

from physgnn.cli import command
from physgnn.training.train import train


def _val_loss(cfg) -> float | None:
    return train(cfg)["val_loss"]


main = command("train", _val_loss)

if __name__ == "__main__":
    main()

"""``python -m physgnn.generate [data=small|tiny|paper] [overwrite=true] [workers=N]``.

The work is :func:`physgnn.groundtruth.generate.generate` (``make data``).
"""

from physgnn.cli import command
from physgnn.groundtruth.generate import generate

main = command("generate", generate, done=lambda out: f"dataset written to {out}")

if __name__ == "__main__":
    main()

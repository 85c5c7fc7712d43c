"""``python -m physgnn.generate [data=small|tiny|paper] [overwrite=true] [workers=N]
[export_scene=FOLDER] [shard=i num_shards=n | merge=true num_shards=n]``.

The work is :func:`physgnn.groundtruth.generate.generate` (``make data``).
"""

from physgnn.cli import command
from physgnn.groundtruth.generate import generate, written

main = command("generate", generate, done=written)

if __name__ == "__main__":
    main()

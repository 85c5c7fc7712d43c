"""``python -m physgnn.generate [data=small|tiny|paper] [overwrite=true] [workers=N]
[export_scene=FOLDER] [shard=i num_shards=n | merge=true num_shards=n]``.

The work is :func:`physgnn.groundtruth.generate.generate` (``make data``; imported once the
command line composes: :mod:`physgnn.cli`).
"""

from physgnn.cli import command

WORK = "physgnn.groundtruth.generate"
main = command("generate", f"{WORK}:generate", done=f"{WORK}:written")

if __name__ == "__main__":
    main()

"""``python -m physgnn.generate [data=small|tiny|paper] [overwrite=true] [workers=N]
[export_scene=FOLDER] [shard=i num_shards=n | merge=true num_shards=n]``.

The work is :func:`physgnn.groundtruth.generate.generate` (``make data``; imported once the
command line composes: :mod:`physgnn.cli`); each scene's clock is checked first, by key."""

from physgnn.cli import USER_ERRORS, command, compose_config, resolve

WORK = "physgnn.groundtruth.generate"


def check_clock(argv: list[str]) -> None:
    """:func:`physgnn.groundtruth.families.check_clock` of the preset ``argv`` composes (one
    that does not is left to the check that says why; a sweep, ``-m``, to its jobs)."""
    try:
        data = compose_config("generate", [a for a in argv if not a.startswith("hydra")]).data
    except USER_ERRORS:
        return
    resolve("physgnn.groundtruth.families:check_clock")(data)


main = command("generate", f"{WORK}:generate", done=f"{WORK}:written", before=check_clock)

if __name__ == "__main__":
    main()

"""``python -m physgnn.bench [key=value ...]``: accuracy versus time (``make bench``).

The work is :func:`physgnn.benchmark.run.bench`: bench.json, bench_extra.json and bench.md
(imported once the command line composes: :mod:`physgnn.cli`).
"""

from physgnn.cli import command

main = command("bench", "physgnn.benchmark.run:bench")

if __name__ == "__main__":
    main()

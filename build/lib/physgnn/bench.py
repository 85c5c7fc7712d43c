"""``python -m physgnn.bench [key=value ...]``: accuracy versus time (``make bench``).

The work is :func:`physgnn.benchmark.run.bench`: bench.json, bench_extra.json and bench.md.
"""

from physgnn.benchmark.run import bench
from physgnn.cli import command

main = command("bench", bench)

if __name__ == "__main__":
    main()

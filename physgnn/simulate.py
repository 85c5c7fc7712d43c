"""``python -m physgnn.simulate scene=FILE [run=RUN_DIR] [out=DIR] [video=true] [frames=N]
[tol=0] [rerun=FILE.rrd] [paths.outputs=DIR] [overwrite=true]``.

The work is :func:`physgnn.evaluation.simulate.simulate`: the truth and, given a run, the
learned rollout of a YAML scene file, to HDF5, metrics.json, a shaded 3-D video and (optional)
a Rerun recording. Arguments are ``key=value`` (not Hydra: ``scene=`` names a file).
"""

from physgnn.cli import command
from physgnn.evaluation import simulate as work

main = command("simulate", work.simulate, done=work.summary, parse=work.parse_args,
               usage=f"{__doc__}\n{work.__doc__}")  # fmt: skip

if __name__ == "__main__":
    main()

"""``python -m physgnn.simulate scene=NAME | scene_file=PATH [run=RUN_DIR|pretrained] [out=DIR]
[video=true] [frames=N] [tol=0] [constraints=0] [rerun=FILE.rrd] [overwrite=false] [seed=0]``.

A Hydra app like every command (``conf/simulate.yaml``; ``--help`` lists its keys and the
scenes of ``scene=``). The work is :func:`physgnn.evaluation.simulate.simulate`: the truth
and, given a run, the learned rollout of one scene, to HDF5, metrics.json, a shaded 3-D video
and (optional) a Rerun recording. A key or a scene the config lacks is one line before Hydra
runs (:func:`physgnn.cli.overrides.check_composes`).
"""

from functools import partial

from physgnn.cli import command
from physgnn.cli.overrides import check_composes
from physgnn.evaluation import simulate as work

main = command(
    "simulate",
    work.simulate,
    done=work.summary,
    before=partial(check_composes, "simulate", missing=work.NOT_IN_GROUP),
)

if __name__ == "__main__":
    main()

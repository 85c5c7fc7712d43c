"""``python -m physgnn.simulate scene=NAME | scene_file=PATH [run=RUN_DIR|pretrained] [out=DIR]
[video=true] [frames=N] [tol=0] [constraints=0] [rerun=FILE.rrd] [overwrite=false] [seed=0]``.

A Hydra app like every command (``conf/simulate.yaml``; ``--help`` lists its keys and the
scenes of ``scene=``). The work is :func:`physgnn.evaluation.simulate.simulate`: the truth
and, given a run, the learned rollout of one scene, to HDF5, metrics.json, a shaded 3-D video
and (optional) a Rerun recording. A key or a scene the config lacks is one line before
anything heavy is imported (:mod:`physgnn.cli`).
"""

from physgnn.cli import command

WORK = "physgnn.evaluation.simulate"
# What to say where ``scene=NAME`` names no entry of the scene group (a file of the user's).
NOT_IN_GROUP = {"scene": "a YAML scene file of yours is scene_file={option}"}
main = command("simulate", f"{WORK}:simulate", done=f"{WORK}:summary", missing=NOT_IN_GROUP)

if __name__ == "__main__":
    main()

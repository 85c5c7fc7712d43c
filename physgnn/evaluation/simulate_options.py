"""The options of ``python -m physgnn.simulate`` (``conf/simulate.yaml``, its one source of
defaults) as one typed group, each value checked when the group is made
(:mod:`physgnn.ranges`), in one line naming the key (:class:`SimulateError`)."""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

from omegaconf import DictConfig

from physgnn.errors import PhysgnnError
from physgnn.metrics import TOLERANCE
from physgnn.models.settings import ALLOWED
from physgnn.ranges import FLAG, check_fields, ranged, whole

# The values of the options the notebook API takes as well (physgnn.api)
FRAMES = whole(2, what="the first frame is the start", example=100)
CONSTRAINTS = whole(0, what="iterations of the constraint stage; 0: the learned model alone")
THREADS = ALLOWED["threads"]  # a learned setting's knob of the same name
# The keys of paths (conf/paths/default.yaml) a simulate reads
PATHS = ("outputs", "compile_cache")


class SimulateError(PhysgnnError, ValueError):
    """Bad command line (one line naming the problem)."""


@dataclass(frozen=True)
class SimulateOptions:
    """What a simulate is asked: ``scene`` (a node of the ``scene`` config group) or
    ``scene_file`` (a path), exactly one; ``seed``: the draw of a scene family's one scene;
    ``frames``: the scene's frame count instead of its own (None: its own); ``run``: a
    training run folder or ``pretrained`` (None: the truth only); ``constraints``: iterations
    of the constraint stage after each learned step; ``tol``: the penetration tolerance;
    ``video``, ``rerun`` (a ``.rrd`` file or None), ``compile`` (the learned step compiled,
    its code kept in ``compile_cache``), ``threads`` (torch threads of the learned rollout;
    None: the process's); ``out`` (None: under ``outputs``), ``overwrite``."""

    NODE: ClassVar[str] = ""
    constraints: int = ranged(CONSTRAINTS)
    tol: float = ranged(TOLERANCE)
    video: bool = ranged(FLAG)
    overwrite: bool = ranged(FLAG)
    compile: bool = ranged(FLAG)
    threads: int | None = ranged(THREADS)
    seed: int = ranged(whole(0, what="the draw of a scene family", example=0))
    frames: int | None = ranged(replace(FRAMES, also=(None,)))
    scene: Any = None
    scene_file: str | None = None
    run: str | None = None
    out: str | None = None
    rerun: str | None = None
    outputs: str = "outputs"
    compile_cache: str | None = None

    def __post_init__(self) -> None:
        check_fields(self, SimulateError)
        if (self.scene is None) == (self.scene_file is None):
            how = "both given: give one" if self.scene is not None else "missing"
            raise SimulateError(
                f"scene: {how} (scene=NAME: an example or a scene family of conf/scene/, e.g. "
                "scene=throw; scene_file=PATH: a YAML scene file of yours)"
            )

    @classmethod
    def of(cls, cfg: DictConfig) -> SimulateOptions:
        """The options of a composed ``conf/simulate.yaml``."""
        given = {f.name: cfg.get(f.name) for f in fields(cls) if f.name not in PATHS}
        paths = {key: cfg.paths.get(key) for key in PATHS}
        return cls(**given, **paths)

    @property
    def cache(self) -> str | None:
        """The compile cache when compiling (None: eager)."""
        return self.compile_cache if self.compile else None

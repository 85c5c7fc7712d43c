"""The hard scenes of the stability report (``conf/scene/{resting_pile,drop_1000,
tight_pack}.yaml``), simulated once by the engine and cached as a split file
``<hard_dir>/hard.h5`` (:func:`physgnn.data.dataset.write_split`), rebuilt when the scene or
engine config or the seed changes."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np
from omegaconf import OmegaConf

from physgnn.data.dataset import read_split, write_split
from physgnn.groundtruth import engine
from physgnn.groundtruth.families import build_scene, plain_config
from physgnn.groundtruth.settings import EngineSettings
from physgnn.physics.trajectory import Trajectory

HARD_FILE = "hard.h5"


def cache_key(scenes: Mapping, engine_cfg: Mapping | None, seed: int) -> str:
    """Canonical JSON of what the hard split is built from (stored as a file attribute)."""
    settings = EngineSettings.from_cfg(plain_config(engine_cfg) if engine_cfg else None)
    plain = {name: plain_config(c) for name, c in scenes.items()}
    return json.dumps(
        {"scenes": plain, "engine": dataclasses.asdict(settings), "seed": int(seed)}, sort_keys=True
    )


def _cached(path: Path, key: str) -> bool:
    if not path.exists():
        return False
    try:
        with h5py.File(path, "r") as f:
            stored = f.attrs.get("config")
    except OSError:  # truncated or not HDF5: rebuild it
        return False
    if isinstance(stored, bytes):
        stored = stored.decode()
    return stored == key


def hard_split(
    hard_dir, scenes: Mapping, engine_cfg: Mapping | None = None, seed: int = 0
) -> list[Trajectory]:
    """The hard scenes' ground truth, from ``hard_dir/hard.h5`` when it was built from the same
    ``scenes`` (name → scene config), engine settings and ``seed``; else simulated now
    (scene ``k`` with ``numpy.random.default_rng([seed, k])``) and written atomically.
    Groups are named after the scenes (the keys of ``scenes``), in the order given."""
    path = Path(hard_dir) / HARD_FILE
    key = cache_key(scenes, engine_cfg, seed)
    if not _cached(path, key):
        trajs = []
        for k, (name, cfg) in enumerate(scenes.items()):
            c = plain_config(cfg)
            scene = build_scene(c, np.random.default_rng([seed, k]))
            traj = engine.simulate(scene, plain_config(engine_cfg))
            traj.attrs.update(group=str(name), scene=c["name"], seed=seed)
            traj.attrs["scene_config"] = OmegaConf.to_yaml(OmegaConf.create(c))
            trajs.append(traj)
        write_split(path, trajs, {"split": "hard", "preset": "hard", "config": key})
    by_name = {t.name: t for t in read_split(path)}
    return [by_name[str(name)] for name in scenes]

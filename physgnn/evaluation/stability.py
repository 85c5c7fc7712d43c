"""Stability of simulators on hard scenes: the ``stability`` section of the eval report.

Hard scenes (``conf/scene/{resting_pile,drop_1000,tight_pack}.yaml``; SPEC "Hard cases") are
simulated once with the engine and cached as a split file ``<hard.dir>/hard.h5``
(:func:`physgnn.data.dataset.write_split`; rebuilt when the scene or engine config changes). Every
learned run is rolled out on them (:func:`physgnn.rollout.rollout`) and, through the eval, on
its dataset's OOD scenes. One row per (run, scene), columns :data:`COLUMNS`:

- ``diverged_at``: first non-finite / runaway frame (None: stable to the end);
  ``steps_to_divergence`` = ``diverged_at − start`` (steps the model took before it).
- ``max_pen_sphere``, ``max_pen_ground``, ``max_pen_static``: the deepest intersection of the
  rollout (sphere pair, ground, other planes), divided by the diameter (pairs: the mean
  diameter); 0 when there is none. Definitions of depth as in :mod:`physgnn.metrics`.
- ``energy_gain``: :func:`physgnn.metrics.energy_gain` of the rollout's energy (its own
  finite-difference velocities; the ground-truth row uses the engine's positions with
  finite-difference velocities too, so the rows compare like with like).
- ``rest_drift``: largest displacement, in radii, of the spheres that rest in the ground truth
  (move less than ``rest_tol`` radii over the whole trajectory; ``n_resting`` of them); None
  when no sphere rests.

Metrics of a diverged rollout are computed on its finite prefix.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np
from omegaconf import DictConfig, OmegaConf

from physgnn import metrics
from physgnn.files import read_rows, write_rows
from physgnn.physics.scene import GROUND, Trajectory

HARD_FILE = "hard.h5"
COLUMNS = [
    "run",
    "experiment",
    "source",
    "scene",
    "n_spheres",
    "n_frames",
    "start",
    "diverged_at",
    "steps_to_divergence",
    "max_pen_sphere",
    "max_pen_ground",
    "max_pen_static",
    "energy_gain",
    "rest_drift",
    "n_resting",
]
_FLOATS = ("max_pen_sphere", "max_pen_ground", "max_pen_static", "energy_gain", "rest_drift")
_INTS = ("n_spheres", "n_frames", "start", "diverged_at", "steps_to_divergence", "n_resting")


# ---------------------------------------------------------------- measurements


def max_penetration(pos, radius, planes, plane_kind) -> dict[str, float]:
    """Deepest intersection over all frames, as a fraction of the diameter.

    pos ``[T, N, 3]``, radius ``[N]``, planes ``[S, 11]``, plane_kind ``[S]`` → ``{max_pen_sphere,
    max_pen_ground, max_pen_static}`` (0 when nothing intersects). The ground is a half-space;
    other planes are bounded rectangles (as :func:`physgnn.metrics.penetration`).
    """
    pos = np.asarray(pos, dtype=np.float64)
    radius = np.asarray(radius, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[-1] != 3 or 0 in pos.shape[:2] or radius.shape != pos.shape[1:2]:
        raise metrics.MetricError(
            f"need pos [T, N, 3] and radius [N] with T, N >= 1, got {list(pos.shape)} and "
            f"{list(radius.shape)}"
        )
    if not (np.isfinite(pos).all() and np.isfinite(radius).all()):
        raise metrics.MetricError("pos or radius has NaN or inf")
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 11)
    kinds = np.asarray(plane_kind).reshape(-1)
    sphere = 0.0
    if pos.shape[1] > 1:
        for pos_t in pos:
            i, j, depth = metrics.sphere_overlaps(pos_t, radius)
            if depth.size:
                sphere = max(sphere, float((depth / (radius[i] + radius[j])).max()))
    ground, static = 0.0, 0.0
    for plane, kind in zip(planes, kinds, strict=True):
        if kind == GROUND:
            depth = radius - (pos - plane[0:3]) @ plane[3:6]
            ground = max(ground, float((depth / (2 * radius)).max()))
        else:
            depth = radius - metrics.plane_distance(pos, plane)
            static = max(static, float((depth / (2 * radius)).max()))
    return {"max_pen_sphere": sphere, "max_pen_ground": ground, "max_pen_static": static}


def measure(
    truth: Trajectory,
    pos,
    vel,
    start: int = 0,
    diverged_at: int | None = None,
    rest_tol: float = 0.01,
) -> dict:
    """The stability numbers of one rollout of ``truth``'s scene (columns of :data:`COLUMNS`
    from ``scene`` on). pos, vel ``[T', N, 3]``: the rollout's finite prefix."""
    pos = np.asarray(pos, dtype=np.float64)
    vel = np.asarray(vel, dtype=np.float64)
    energy = metrics.energy_series(pos, vel, truth.mass, truth.radius)
    resting = metrics.resting_mask(truth.pos, truth.radius, rest_tol)
    return {
        "scene": truth.name,
        "n_spheres": truth.n_spheres,
        "n_frames": int(pos.shape[0]),
        "start": int(start),
        "diverged_at": diverged_at,
        "steps_to_divergence": None if diverged_at is None else int(diverged_at) - int(start),
        **max_penetration(pos, truth.radius, truth.planes, truth.plane_kind),
        "energy_gain": metrics.energy_gain(energy, metrics.energy_scale(truth.mass, truth.radius)),
        "rest_drift": metrics.rest_drift(pos, truth.radius, resting),
        "n_resting": int(resting.sum()),
    }


def truth_row(truth: Trajectory, source: str, rest_tol: float = 0.01) -> dict:
    """The ground truth's own row (engine positions, finite-difference velocities)."""
    d = metrics.trajectory_dict(truth, velocities="finite")
    row = measure(truth, d["pos"], d["vel"], rest_tol=rest_tol)
    return {"run": "ground_truth", "experiment": "ground_truth", "source": source, **row}


def rollout_rows(
    name: str,
    experiment: str,
    simulator,
    trajectories: list[Trajectory],
    source: str,
    rest_tol: float = 0.01,
    **rollout_kwargs,
) -> list[dict]:
    """Roll ``simulator`` out on every trajectory (from its first H+1 frames; keyword
    arguments of :func:`physgnn.rollout.rollout`, e.g. ``sleeping``) and measure."""
    from physgnn.rollout import rollout

    rows = []
    results = rollout(simulator, trajectories, **rollout_kwargs)
    for truth, res in zip(trajectories, results, strict=True):
        row = measure(truth, res.pos, res.vel, res.start, res.diverged_at, rest_tol)
        rows.append({"run": name, "experiment": experiment, "source": source, **row})
    return rows


# ---------------------------------------------------------------- hard scenes (cached)


def _plain(cfg) -> dict:
    if isinstance(cfg, DictConfig):
        return OmegaConf.to_container(cfg, resolve=True)
    return dict(cfg or {})


def cache_key(scenes: Mapping, engine: Mapping | None, seed: int) -> str:
    """Canonical JSON of what the hard split is built from (stored as a file attribute)."""
    from physgnn.groundtruth.engine import EngineSettings

    settings = EngineSettings.from_cfg(_plain(engine) if engine else None)
    plain = {name: _plain(c) for name, c in scenes.items()}
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
    hard_dir, scenes: Mapping, engine: Mapping | None = None, seed: int = 0
) -> list[Trajectory]:
    """The hard scenes' ground truth, from ``hard_dir/hard.h5`` when it was built from the same
    ``scenes`` (name → scene config), ``engine`` settings and ``seed``; else simulated now
    (scene ``k`` with ``numpy.random.default_rng([seed, k])``) and written atomically.
    Groups are named after the scenes (the keys of ``scenes``), in the order given."""
    from physgnn.data.dataset import read_split, write_split
    from physgnn.groundtruth.engine import simulate
    from physgnn.groundtruth.families import build_scene

    path = Path(hard_dir) / HARD_FILE
    key = cache_key(scenes, engine, seed)
    if not _cached(path, key):
        trajs = []
        for k, (name, cfg) in enumerate(scenes.items()):
            c = _plain(cfg)
            traj = simulate(build_scene(c, np.random.default_rng([seed, k])), _plain(engine))
            traj.attrs.update(group=str(name), scene=c["name"], seed=seed)
            traj.attrs["scene_config"] = OmegaConf.to_yaml(OmegaConf.create(c))
            trajs.append(traj)
        write_split(path, trajs, {"split": "hard", "preset": "hard", "config": key})
    by_name = {t.name: t for t in read_split(path)}
    return [by_name[str(name)] for name in scenes]


# ---------------------------------------------------------------- csv and report section


def write_csv(path, rows: list[dict]) -> Path:
    """``stability.csv`` (columns :data:`COLUMNS`; None → empty cell), written atomically."""
    return write_rows(path, rows, COLUMNS)


def read_csv(path) -> list[dict]:
    return read_rows(path, _FLOATS, _INTS)


def _fmt(x) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    if x == 0:
        return "0"
    if 1e-2 <= abs(x) < 1e4:
        return f"{x:.3g}"
    return f"{x:.2e}"


def section(rows: list[dict]) -> str:
    """Markdown of the report's stability section: one table row per (scene, run)."""
    if not rows:
        return "No stability measurements (eval with `stability=true`)."
    header = [
        "scene",
        "source",
        "run",
        "frames",
        "diverged",
        "max pen. sphere",
        "max pen. ground",
        "max pen. other",
        "energy gain",
        "rest drift (radii)",
    ]
    order = sorted(
        rows, key=lambda r: (r["source"], r["scene"], r["run"] != "ground_truth", r["run"])
    )
    body = []
    for r in order:
        steps = r["steps_to_divergence"]
        diverged = (
            "no"
            if r["diverged_at"] is None
            else f"⚠ after {steps} steps (frame {r['diverged_at']})"
        )
        drift = (
            "–"
            if r["rest_drift"] is None
            else f"{_fmt(r['rest_drift'])} ({r['n_resting']} at rest)"
        )
        body.append(
            [r["scene"], r["source"], f"`{r['run']}`", str(r["n_frames"]), diverged]
            + [_fmt(r[k]) for k in ("max_pen_sphere", "max_pen_ground", "max_pen_static")]
            + [_fmt(r["energy_gain"]), drift]
        )
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(b) + " |" for b in body]
    note = (
        "Penetration: the deepest intersection of the rollout over its diameter (walls and "
        "other planes are two-sided rectangles: 0.5 means a centre on the plane, i.e. "
        "passing through it). Energy gain: normalised cumulative gain of the rollout's own "
        "energy. Rest drift: largest displacement of the spheres that rest in the ground "
        "truth. A diverged rollout is measured on its finite prefix."
    )
    return note + "\n\n" + "\n".join(lines)

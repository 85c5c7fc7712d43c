"""Stability suite: hard scenes, their measurements, engine rest, float32 vs float64,
gradient clipping and one-line configuration errors. Slow cases: test_stability_slow.py."""

from __future__ import annotations

import copy
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from simdata import learned, trajectory
from torch import nn

import physgnn.evaluation.stability as S
from physgnn import CONF_DIR, metrics
from physgnn import train as train_command
from physgnn.groundtruth import hard
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.families import build_scene
from physgnn.groundtruth.layouts import pile_positions
from physgnn.metrics import MetricError
from physgnn.models.baselines import GravityOnlySimulator, StaticSimulator
from physgnn.physics.scene import WALL, Material, ground_plane, make_plane
from physgnn.physics.trajectory import Trajectory
from physgnn.report import freefall as freefall_report
from physgnn.report import stability as stability_report
from physgnn.rollout import rollout
from physgnn.training.build import build

ROOT = Path(__file__).resolve().parents[1]
SCENE_DIR = Path(CONF_DIR) / "scene"
G, DT, R = 9.81, 0.1, 0.5


def scene_cfg(name: str, **overrides) -> dict:
    cfg = OmegaConf.to_container(OmegaConf.load(SCENE_DIR / f"{name}.yaml"))
    cfg.update(overrides)
    return cfg


def resting_layer(n: int = 3, frames: int = 30) -> Trajectory:
    """An n×n layer of touching spheres (r 0.5 m, 1 kg) at rest on the ground, built by hand."""
    p = pile_positions(n, 1, R)
    k = len(p)
    quat = np.zeros((frames, k, 4), np.float32)
    quat[..., 0] = 1
    zeros = np.zeros((frames, k, 3), np.float32)
    return Trajectory(
        name="layer",
        pos=np.broadcast_to(p, (frames, k, 3)).astype(np.float32),
        quat=quat,
        vel=zeros,
        angvel=zeros,
        radius=np.full(k, R, np.float32),
        mass=np.ones(k, np.float32),
        material=np.zeros(k, np.int64),
        planes=ground_plane()[None],
        plane_kind=np.zeros(1, np.int64),
        materials=Material().as_array()[None],
        dt=DT,
    )


def gaps(pos):
    i, j = np.triu_indices(len(pos), 1)
    return np.linalg.norm(pos[i] - pos[j], axis=1) - 2 * R


# ---------------------------------------------------------------- hard scenes


def test_resting_pile_spheres_touch_exactly_and_rest_on_the_ground():
    scene = build_scene(scene_cfg("resting_pile"), np.random.default_rng(0))
    pos = scene.pos.astype(np.float64)
    assert scene.n_spheres == 25 + 16
    g = gaps(pos)
    assert g.min() > -1e-6  # no overlap (float32 positions)
    # 40 + 40 contacts in the two layers, 4 per sphere of the top layer onto the bottom one
    assert int((np.abs(g) < 1e-6).sum()) == 40 + 24 + 16 * 4
    np.testing.assert_allclose(pos[:25, 2], R)
    np.testing.assert_allclose(pos[25:, 2], R + np.sqrt(2) * R, rtol=1e-6)


def test_tight_pack_and_drop_1000_configs():
    pack = build_scene(scene_cfg("tight_pack"), np.random.default_rng(0))
    g = gaps(pack.pos.astype(np.float64))
    assert pack.n_spheres == 64 and g.min() > -1e-6
    assert int((np.abs(g) < 1e-6).sum()) == 3 * 4 * 4 * 3  # every lattice neighbour touches
    assert pack.pos[:, 2].min() == pytest.approx(R)
    drop = build_scene(scene_cfg("drop_1000"), np.random.default_rng(0))
    np.testing.assert_array_equal(drop.pos[:, 2], 1000.0)
    assert gaps(drop.pos).min() > 1.0  # spaced: they never touch


def test_resting_pile_rejects_more_layers_than_its_base():
    with pytest.raises(Exception, match="1 <= layers <= n"):
        build_scene(scene_cfg("resting_pile", layers=6), np.random.default_rng(0))


def test_engine_keeps_a_5x5_layer_at_rest_for_2000_frames():
    # Measured (pybullet 3.2.7, default settings): 2.0e-5 radii, reached at frame 1 (the
    # spheres settle into their contact depth), with sleeping on or off. Bound: 5x that.
    cfg = scene_cfg("resting_pile", layers=1, n_frames=2000)
    traj = simulate(build_scene(cfg, np.random.default_rng(0)))
    drift = np.linalg.norm(traj.pos - traj.pos[0], axis=-1) / traj.radius
    assert np.isfinite(traj.pos).all() and traj.n_frames == 2000
    assert drift.max() < 1e-4


# ---------------------------------------------------------------- measurements by hand


def test_max_penetration_by_hand():
    wall = make_plane((2, 0, 1), (-1, 0, 0), (0, 1, 0), 1.0, 1.0)  # x = 2, facing -x
    planes = np.stack([ground_plane(), wall])
    kinds = np.array([0, WALL])
    pos = np.array(
        [
            [[0.0, 0, 2], [0.8, 0, 2], [1.6, 0, 1]],  # pair overlapping by 0.2 m; 0.1 m in wall
            [[0.0, 0, 0.3], [5.0, 0, 2], [1.0, 0, 5]],  # 0.2 m into the ground; nothing else
        ]
    )
    out = metrics.max_penetration(pos, np.full(3, R), planes, kinds)
    assert out == pytest.approx(
        {
            "max_pen_sphere": 0.2,
            "max_pen_ground": 0.2,
            "max_pen_static": 0.1,
            "mean_pen_sphere": 0.2,
            "tunnelled": 0,
        }
    )
    apart = metrics.max_penetration(pos[:, :1] + [0, 0, 3], np.full(1, R), planes, kinds)
    assert apart == {
        "max_pen_sphere": 0.0,
        "max_pen_ground": 0.0,
        "max_pen_static": 0.0,
        "mean_pen_sphere": 0.0,
        "tunnelled": 0,
    }
    # Sphere 2 passes behind the wall (centre at x = 2.2 over its footprint), sphere 0 sinks
    # below the ground: both tunnelled; depths r + 0.2 and r + 0.1 over the diameter 1.
    crossed = pos.copy()
    crossed[1, 2] = [2.2, 0, 1]
    crossed[1, 0] = [0.0, 0, -0.1]
    out = metrics.max_penetration(crossed, np.full(3, R), planes, kinds)
    assert out["tunnelled"] == 2
    assert out["max_pen_static"] == pytest.approx(0.7)
    assert out["max_pen_ground"] == pytest.approx(0.6)
    bad = pos.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(MetricError, match="NaN or inf"):
        metrics.max_penetration(bad, np.full(3, R), planes, kinds)
    with pytest.raises(MetricError, match=r"need pos \[T, N, 3\]"):
        metrics.max_penetration(pos[:, :0], np.zeros(0), planes, kinds)


def test_static_model_keeps_the_layer_at_rest_exactly():
    (row,) = S.rollout_rows("static", "static", StaticSimulator(), [resting_layer()], "hard")
    assert row["diverged_at"] is None and row["n_frames"] == 30 and row["n_resting"] == 9
    assert row["rest_drift"] == 0.0 and row["energy_gain"] == 0.0
    assert row["max_pen_ground"] == row["max_pen_sphere"] == 0.0


def test_gravity_only_model_sinks_through_the_ground_by_the_hand_computed_depth():
    (row,) = S.rollout_rows("g", "g", GravityOnlySimulator(), [resting_layer()], "hard")
    k = 29  # steps after frame 0: semi-implicit Euler falls g·dt²·k(k+1)/2
    fall = G * DT**2 * k * (k + 1) / 2
    assert row["rest_drift"] == pytest.approx(fall / R, rel=1e-5)
    assert row["max_pen_ground"] == pytest.approx(fall / (2 * R), rel=1e-5)
    assert row["max_pen_sphere"] == 0.0 and row["diverged_at"] is None


class Exploding(nn.Module):
    """``v̂ = 10·v + (1, 0, 0)``: speeds 1, 11, 111, 1111, 11111 > 1e4 at step 5."""

    H = 0

    def forward(self, state):
        kick = torch.zeros_like(state.pos)
        kick[:, 0] = 1.0
        return 10.0 * state.vel[:, 0] + kick, state.angvel[:, 0]


def test_exploding_model_reports_steps_to_divergence_and_finite_metrics():
    (row,) = S.rollout_rows("x", "x", Exploding(), [resting_layer()], "hard")
    assert row["diverged_at"] == 5 and row["steps_to_divergence"] == 5 and row["n_frames"] == 5
    assert all(np.isfinite(row[k]) for k in ("max_pen_sphere", "energy_gain", "rest_drift"))
    text = stability_report.section([row])
    assert "⚠ after 5 steps (frame 5)" in text


def test_truth_row_of_a_resting_layer_is_zero_and_csv_round_trips(tmp_path):
    truth = S.truth_row(resting_layer(), "hard")
    assert truth["rest_drift"] == 0.0 and truth["energy_gain"] == 0.0
    assert truth["max_pen_sphere"] == 0.0  # touching exactly is not an intersection
    (x,) = S.rollout_rows("x", "x", Exploding(), [resting_layer()], "hard")
    path = stability_report.write_csv(tmp_path / "stability.csv", [truth, x])
    back = stability_report.read_csv(path)
    for want, got in zip([truth, x], back, strict=True):
        assert {k: got[k] for k in stability_report.COLUMNS} == pytest.approx(
            {k: want[k] for k in stability_report.COLUMNS}
        )
    assert "No stability measurements" in stability_report.section([])


# ---------------------------------------------------------------- hard split cache


def tiny_hard() -> dict:
    return {
        "resting_pile": scene_cfg("resting_pile", n=2, layers=1, n_frames=5),
        "drop_1000": scene_cfg("drop_1000", grid=1, height=3.0, n_frames=6),
    }


def test_hard_split_is_built_once_then_read_from_the_cache(tmp_path, monkeypatch):
    first = hard.hard_split(tmp_path, tiny_hard())
    assert [t.name for t in first] == ["resting_pile", "drop_1000"]
    assert [t.n_frames for t in first] == [5, 6] and first[0].attrs["scene"] == "resting_pile"

    def no_engine(*args, **kwargs):
        raise AssertionError("simulated again")

    monkeypatch.setattr("physgnn.groundtruth.engine.simulate", no_engine)
    again = hard.hard_split(tmp_path, tiny_hard())
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a.pos, b.pos)
    changed = tiny_hard()
    changed["drop_1000"]["height"] = 4.0
    with pytest.raises(AssertionError, match="simulated again"):  # another config: rebuilt
        hard.hard_split(tmp_path, changed)
    (tmp_path / hard.HARD_FILE).write_bytes(b"truncated")
    with pytest.raises(AssertionError, match="simulated again"):  # a corrupt cache: rebuilt
        hard.hard_split(tmp_path, tiny_hard())


# ---------------------------------------------------------------- float32 against float64


def test_float32_and_float64_rollouts_agree_over_the_first_frames(one_thread):
    # Measured on these 3 scenes (5 spheres, up to 41 m): |Δp| <= 4.9e-6 m after 10 steps,
    # i.e. a few float32 ulps of the coordinates (the rollout records float32). Bound 4x.
    torch.manual_seed(0)
    sim = learned(H=1, M=2, hidden=32).eval()
    trajs = [trajectory(5, 12, seed=s) for s in range(3)]
    with pytest.warns(UserWarning, match="never saw"):
        r32 = rollout(sim, trajs)
        r64 = rollout(copy.deepcopy(sim).double(), trajs, dtype=torch.float64)
    for a, b in zip(r32, r64, strict=True):
        assert a.diverged_at is None and b.diverged_at is None and a.pos.shape == (12, 5, 3)
        np.testing.assert_array_equal(a.pos[:2], b.pos[:2])  # the seed frames
        print(f"float32 vs float64, {a.name}: max |dp| = {np.abs(a.pos - b.pos).max():.3g} m")
        assert np.abs(a.pos - b.pos).max() <= 2e-5
        assert np.abs(a.pos - b.pos).max() > 0  # the two precisions did differ


# ---------------------------------------------------------------- training configuration


def train_cfg(tiny_dataset, run_dir, *overrides):
    base = ["data=tiny", f"paths.outputs={Path(tiny_dataset).parents[1]}", f"run_dir={run_dir}"]
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose("train", overrides=base + list(overrides))


def sgd_step(tiny_dataset, run_dir, clip) -> float:
    """Norm of the parameter change of one SGD step (lr 1) with ``gradient_clip_val=clip``."""
    cfg = train_cfg(
        tiny_dataset,
        run_dir,
        "model.network.M=1",
        "model.network.hidden=16",
        "+trainer.max_steps=1",
        "trainer.max_epochs=1",
        "trainer.max_time=null",
        "trainer.enable_progress_bar=false",
        "trainer.enable_model_summary=false",
        "+trainer.limit_val_batches=0",
        "datamodule.batch_size=4",
        "datamodule.pairs_per_epoch=4",
        "datamodule.val_pairs=4",
        "lit.optimizer._target_=torch.optim.SGD",
        "lit.optimizer.lr=1.0",
        "lit.noise.std=0",
        "~logger",
        "callbacks=none",
        f"trainer.gradient_clip_val={clip}",
    )
    torch.manual_seed(0)
    datamodule, lit, trainer = build(cfg)
    assert trainer.gradient_clip_val == (None if clip == "null" else float(clip))
    before = [p.detach().clone() for p in lit.parameters()]
    trainer.fit(lit, datamodule=datamodule)
    assert trainer.global_step == 1
    diff = [(p.detach() - b).flatten() for p, b in zip(lit.parameters(), before, strict=True)]
    return float(torch.cat(diff).norm())


def test_gradient_clipping_is_a_config_that_bounds_the_step(tiny_dataset, tmp_path):
    assert train_cfg(tiny_dataset, tmp_path).trainer.gradient_clip_val == 1.0  # the default
    free = sgd_step(tiny_dataset, tmp_path / "free", "null")
    clipped = sgd_step(tiny_dataset, tmp_path / "clip", "1e-3")
    print(f"one SGD step (lr 1): |Δθ| = {free:.3g} unclipped, {clipped:.3g} clipped at 1e-3")
    assert clipped <= 1e-3 * (1 + 1e-5)  # global gradient norm clipped to 1e-3, lr 1
    assert free > 10 * clipped  # without clipping the step is far larger


# ---------------------------------------------------------------- one-line config errors


def run_cli(monkeypatch, capsys, main, *args) -> tuple[int, list[str]]:
    monkeypatch.setattr(sys, "argv", ["physgnn", *args])
    with pytest.raises(SystemExit) as info:
        main()
    return info.value.code, capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize(
    "override, problem",
    [
        ("model.MM=3", "model.MM is not a key of the train config: did you mean model.network.M?"),
        ("trainer=cpuu", "no 'cpuu' in the config group trainer (options: cpu, ddp,"),
        ("+experiment=nope", "+experiment=nope: no 'nope' in the config group experiment"),
    ],
)
def test_config_typos_name_the_problem_without_traceback(monkeypatch, capsys, override, problem):
    code, err = run_cli(monkeypatch, capsys, train_command.main, override)
    assert code == 2 and len(err) == 1 and problem in err[0]  # one line, before Hydra runs
    assert not any("Traceback" in line for line in err)


def test_unknown_model_key_appended_is_one_error_line(monkeypatch, capsys, tiny_dataset, tmp_path):
    args = ["data=tiny", f"paths.outputs={Path(tiny_dataset).parents[1]}", f"run_dir={tmp_path}"]
    code, err = run_cli(monkeypatch, capsys, train_command.main, *args, "+model.MM=3")
    assert code == 2 and err[-1].startswith("error: +model.MM=3: model.MM is not an argument of")
    assert not any("Traceback" in line for line in err)


# ---------------------------------------------------------------- the eval's stability section

TINY_HARD = [
    "hard.scenes.resting_pile.n=2",
    "hard.scenes.resting_pile.layers=1",
    "hard.scenes.resting_pile.n_frames=8",
    "hard.scenes.drop_1000.grid=1",
    "hard.scenes.drop_1000.height=3.0",
    "hard.scenes.drop_1000.n_frames=8",
    "hard.scenes.tight_pack.k=2",
    "hard.scenes.tight_pack.n_frames=8",
]
# What these evals do not check: videos, the sleeping comparison, pybullet on the same work
# (and its Pareto figures: tests/test_eval.py), the invariance checks (test_invariance_checks.py)
QUIET = [
    *("videos=false", "sleeping_compare=false", "pybullet=null", "invariance=null"),
    "learned_settings=null",  # the fake simulators have no knobs to set
]


class Falling(GravityOnlySimulator):
    H = history = 1


def fake_eval(tmp_path, monkeypatch, *overrides, entry=None):
    """A dataset (test: one flight; OOD: the resting layer) and two finished fake runs, a
    free-falling and an exploding one; returns the eval's report.md text and its folder
    (``entry``: call this with the config instead, and return what it returns)."""
    import json

    import physgnn.training.runs
    from physgnn.data.dataset import write_split
    from physgnn.evaluation import evaluate as ev

    outputs = tmp_path / "outputs"
    data = outputs / "data" / "hand"
    write_split(data / "test.h5", [trajectory(3, 10, seed=1)], {"split": "test", "preset": "h"})
    layer = resting_layer(2, 10)
    layer.attrs["group"] = "layer"
    write_split(data / "ood.h5", [layer], {"split": "ood", "preset": "h"})
    sims = {"falling": Falling(), "exploding": Exploding()}
    for name in sims:
        run = outputs / "runs" / name / "t0"
        run.mkdir(parents=True)
        info = {"status": "finished", "experiment": name, "overrides": [], "seed": 0}
        (run / "run.json").write_text(json.dumps(info))

    def fake_load_run(run_dir):
        cfg = OmegaConf.create({"datamodule": {"data_dir": str(data)}})
        return sims[Path(run_dir).parent.name], cfg, {}

    monkeypatch.setattr(physgnn.training.runs, "load_run", fake_load_run)
    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        cfg = compose(
            "eval",
            [f"paths.outputs={outputs}", *QUIET, *TINY_HARD] + list(overrides),
        )
    if entry is not None:
        return entry(cfg)
    path = ev.evaluate(cfg)
    return path.read_text(), path.parent, outputs


def test_eval_reports_stability_of_every_run_on_hard_and_ood_scenes(tmp_path, monkeypatch):
    text, report_dir, outputs = fake_eval(tmp_path, monkeypatch)
    assert (outputs / "data" / "hard" / hard.HARD_FILE).exists()  # cached for the next eval
    rows = stability_report.read_csv(report_dir / "stability.csv")
    scenes = ["drop_1000", "layer", "resting_pile", "tight_pack"]
    for run in ("ground_truth", "runs/falling/t0", "runs/exploding/t0"):
        assert sorted(r["scene"] for r in rows if r["run"] == run) == scenes
    by = {(r["run"], r["scene"]): r for r in rows}
    truth = by[("ground_truth", "resting_pile")]
    assert truth["n_resting"] == 4 and truth["rest_drift"] < 1e-3 and truth["source"] == "hard"
    # the free fall (H = 1, from frame 1) sinks the resting layer of the OOD split: 8 steps
    fall = G * DT**2 * 8 * 9 / 2
    assert by[("runs/falling/t0", "layer")]["rest_drift"] == pytest.approx(fall / R, rel=1e-5)
    assert by[("runs/falling/t0", "layer")]["source"] == "ood"
    assert by[("runs/exploding/t0", "tight_pack")]["steps_to_divergence"] == 5
    assert "## Stability on hard scenes" in text and "⚠ after 5 steps" in text
    # Free fall: from analytic seed frames with H = 1 the free flight stays on the parabola.
    falls = freefall_report.read_csv(report_dir / "freefall.csv")
    mine = [r for r in falls if r["run"] == "runs/falling/t0"]
    assert [r["height"] for r in mine] == [10.0, 100.0, 1000.0]
    assert max(r["z_error_pct"] for r in mine) < 0.05  # float32 positions near 1 000 m
    assert [r["dvz_first"] for r in mine] == pytest.approx([-G * DT] * 3, abs=1e-3)
    assert "## Free fall against ½gt²" in text


def test_eval_without_stability_says_so(tmp_path, monkeypatch):
    text, report_dir, _ = fake_eval(tmp_path, monkeypatch, "stability=false")
    assert not (report_dir / "stability.csv").exists()
    assert "No stability measurements" in text


def test_bad_hard_scene_config_is_one_error_line(tmp_path, monkeypatch, capsys):
    from physgnn import eval as eval_command

    with pytest.raises(SystemExit) as info:
        fake_eval(
            tmp_path,
            monkeypatch,
            "hard.scenes.resting_pile.layers=9",
            entry=eval_command.main.__wrapped__,
        )
    err = capsys.readouterr().err.strip().splitlines()
    assert info.value.code == 2 and len(err) == 1
    assert err[0] == "error: resting_pile: need n >= 1 and 1 <= layers <= n (got 2, 9)"

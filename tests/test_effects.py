"""Effects end to end: scene effects → graph → network → rollout → checkpoint."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import lightning as L
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf
from simdata import batch, learned, trajectory

from physgnn import CONF_DIR
from physgnn.models.learned import LearnedSimulator
from physgnn.physics.scene import EFFECT_NAMES, GROUND, Effects
from physgnn.rollout import rollout
from physgnn.training.lit import LitSimulator
from physgnn.training.runs import load_run

MODEL = dict(H=1, M=2, hidden=16, epsilon=0.05)
CONF = Path(CONF_DIR)


def make() -> LearnedSimulator:
    torch.manual_seed(0)
    sim = learned(**MODEL).eval()
    sim.effects_trained.fill_(True)
    return sim


def crowded(effects: Effects | None = None, walls: bool = True, n: int = 6):
    """``n`` spheres packed against the wall x = −5, overlapping their neighbours."""
    traj = trajectory(n, frames=8, seed=1, effects=effects)
    pos = traj.pos.copy()
    pos[:, :, 0] = -5 + 0.45 + 0.7 * np.arange(n)  # radius ≥ 0.4: every neighbour overlaps
    pos[:, :, 1] = 0.0
    traj = dataclasses.replace(traj, pos=pos)
    if not walls:
        keep = traj.plane_kind == GROUND
        traj = dataclasses.replace(traj, planes=traj.planes[keep], plane_kind=traj.plane_kind[keep])
    return traj


def pp_call_counter(sim: LearnedSimulator) -> list[str]:
    """Forward hooks on the pp encoder and every block's pp interaction: names of calls."""
    calls: list[str] = []
    net = sim.network
    net.pp_encoder.register_forward_hook(lambda *_: calls.append("pp_encoder"))
    for k, block in enumerate(net.blocks):
        block.pp.register_forward_hook(lambda *_, k=k: calls.append(f"block{k}.pp"))
        block.pp.mlp.register_forward_hook(lambda *_, k=k: calls.append(f"block{k}.pp.mlp"))
    return calls


def wall_edges(sim, traj) -> int:
    state = batch([traj], t=2, H=1)
    _, graph = sim.normalized_prediction(state)
    return int((state.plane_kind[graph.ps_index[0]] != GROUND).sum())


def test_no_walls_and_surface_contact_off_give_no_wall_edges():
    sim = make()
    assert wall_edges(sim, crowded()) > 0  # control: the first sphere touches a wall
    assert wall_edges(sim, crowded(walls=False)) == 0
    assert wall_edges(sim, crowded(Effects(surface_contact=False))) == 0


def test_contacts_off_builds_no_pp_edge_and_calls_no_pp_mlp_in_a_rollout():
    sim = make()
    calls = pp_call_counter(sim)
    rollout(sim, [crowded()], n_frames=4)
    assert "pp_encoder" in calls and "block1.pp" in calls  # control: overlapping spheres
    calls.clear()
    off = crowded(Effects(sphere_contact=False))
    state = batch([off], t=2, H=1)
    _, graph = sim.normalized_prediction(state)
    assert graph.pp_index.shape == (2, 0) and graph.pp_attr.shape == (0, 4)
    rollout(sim, [off], n_frames=4)
    assert calls == []


def test_contacts_off_in_one_scene_of_a_batch_only_drops_that_scene_s_pairs():
    sim = make()
    state = batch([crowded(), crowded(Effects(sphere_contact=False))], t=2, H=1)
    _, graph = sim.normalized_prediction(state)
    scenes = state.batch[graph.pp_index]
    assert graph.pp_index.shape[1] > 0 and bool((scenes == 0).all())


def test_rotation_off_keeps_every_quaternion_bit_identical_through_a_rollout():
    sim = make()
    still = trajectory(4, frames=10, seed=2, effects=Effects(rotation=False))
    spun = trajectory(3, frames=10, seed=3)
    res_still, res_spun = rollout(sim, [still, spun])
    start = torch.as_tensor(still.quat[1])
    assert res_still.quat.shape == (10, 4, 4)
    for k in range(1, 10):  # from the start frame H = 1 on, every bit stays
        assert torch.equal(torch.as_tensor(res_still.quat[k]), start)
    assert not np.array_equal(res_spun.quat[-1], res_spun.quat[1])  # control: same batch


def test_effects_trained_round_trip_through_a_lightning_checkpoint(tmp_path):
    sim = make()
    pattern = torch.tensor([True, False, True, False, True])
    sim.effects_trained.copy_(pattern)
    lit = LitSimulator(sim, optimizer=torch.optim.Adam)
    trainer = L.Trainer(
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
        accelerator="cpu",
    )
    trainer.strategy.connect(lit)
    (tmp_path / "checkpoints").mkdir()
    trainer.save_checkpoint(tmp_path / "checkpoints" / "last.ckpt")
    # every key of the model, as a run's config holds it (a run without the keys added since
    # is an earlier physgnn's, loaded with the earlier model's values)
    nodes = {"H": 1, "network": {"M": 2, "hidden": 16}, "graph": {"epsilon": 0.05}}  # MODEL
    model = OmegaConf.merge(OmegaConf.load(CONF / "model" / "baseline.yaml"), nodes)
    (tmp_path / ".hydra").mkdir()
    OmegaConf.save(OmegaConf.create({"model": model}), tmp_path / ".hydra" / "config.yaml")
    loaded, _, info = load_run(tmp_path)
    assert info["checkpoint"].endswith("last.ckpt")
    assert loaded.effects_trained.dtype == torch.bool
    assert torch.equal(loaded.effects_trained, pattern)
    state = batch([trajectory(3, seed=5)], t=2, H=1)
    assert torch.equal(loaded(state)[0], sim(state)[0])


def test_rollout_asking_for_an_unseen_effect_warns_once_in_one_line():
    sim = make()
    sim.effects_trained[EFFECT_NAMES.index("rotation")] = False
    trajs = [trajectory(3, frames=6, seed=s) for s in range(3)]
    for traj in trajs:  # exact velocities: no warning of positions only
        traj.attrs["engine"] = "analytic"
    with pytest.warns(UserWarning) as record:
        rollout(sim, trajs, batch_size=1)
    messages = [str(w.message) for w in record if "never" in str(w.message)]
    assert len(messages) == 1 and "\n" not in messages[0] and "rotation" in messages[0]
    no_rotation = [trajectory(3, frames=6, seed=0, effects=Effects(rotation=False))]
    no_rotation[0].attrs["engine"] = "analytic"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rollout(sim, no_rotation)  # asks only for what the model saw: silent

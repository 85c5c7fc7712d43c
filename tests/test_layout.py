"""The config's layout: runs whose model holds the network's, the graph builder's or the
simulator's groups' keys flat, or whose ``lit`` holds the recipe's keys flat (an earlier
physgnn's, the shipped weights), load as today's nested nodes and groups; their overrides
resume, a flat key typed today is one line naming its new spelling, and the study reads their
registry keys in today's spelling."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest
import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf
from simdata import batch, trajectory

from physgnn.ablation.jobs import current_fingerprint, defaults_fingerprint
from physgnn.ablation.registry import append_record, read_registry
from physgnn.cli import compose_config
from physgnn.errors import ConfigError
from physgnn.training.layout import (
    EARLIER_MODEL,
    FLAT_KEYS,
    NODES,
    PREVIOUS_MODEL,
    flat_layout,
    key_of_today,
    lit_of_today,
    model_of_today,
)
from physgnn.training.lit import LitSimulator
from physgnn.training.recipe import Compile, InputNoise, LossTerms, PushForward
from physgnn.training.resume_checks import check_resume_argv, check_resume_overrides
from physgnn.training.runs import RunError, load_run
from physgnn.training.schedule import RunLengthDecay

PREVIOUS_SHIPPED = Path(__file__).parent / "previous_shipped"

# A recipe of the flat layout, written by hand as an earlier physgnn saved it
FLAT_LIT = {
    "_target_": "physgnn.training.lit.LitSimulator",
    "lambda_energy": 0.5,
    "noise_std": 0.01,
    "seed": "${seed}",
    "pushforward_steps": 3,
    "pushforward_after": 10,
    "pushforward_growth": 5,
    "lambda_contact": 2.0,
    "contact_tol": 0.03,
    "contact_noise_depth": 0.1,
    "contact_noise_prob": 0.4,
    "contact_touch": 0.06,
    "noise_rest_scale": 0.5,
    "lambda_rest": 0.25,
    "compile": False,
    "compile_mode": "default",
    "compile_shapes": 8,
    "optimizer": {"_target_": "torch.optim.Adam", "_partial_": True, "lr": 0.002},
    "scheduler": {
        "_target_": "physgnn.training.schedule.RunLengthDecay",
        "_partial_": True,
        "final_lr_factor": 0.25,
    },
}


def flat_model(model, nodes=tuple(NODES)) -> dict:
    """A model config of today's layout with the keys of ``nodes`` flat (all: the layout of an
    earlier physgnn; ``("inputs", "contacts")``: the layout before the simulator's groups)."""
    flat = {k: v for k, v in model.items() if k not in nodes}
    keys = {key: where for key, where in FLAT_KEYS.items() if where[0] in nodes}
    return flat | {key: model[node][name] for key, (node, name) in keys.items()}


def flatten(config: Path, nodes=tuple(NODES)) -> None:
    """Rewrite a run's ``.hydra/config.yaml`` with the keys of ``nodes`` of its model flat."""
    cfg = OmegaConf.load(config)
    cfg.model = flat_model(cfg.model, nodes)
    OmegaConf.save(cfg, config)


@pytest.fixture
def flat_run(tiny_fd_run, tmp_path) -> Path:
    """A copy of the session's tiny run of the finite-difference state (M = 1; earlier layouts
    predate the engine state) with its model config flat."""
    run = Path(shutil.copytree(tiny_fd_run, tmp_path / "run"))
    flatten(run / ".hydra" / "config.yaml")
    return run


def test_a_run_of_the_layout_before_the_groups_loads_as_today_and_predicts_alike(
    tiny_fd_run, tmp_path
):
    run = Path(shutil.copytree(tiny_fd_run, tmp_path / "groups"))
    config = run / ".hydra" / "config.yaml"
    flatten(config, ("inputs", "contacts"))
    saved = OmegaConf.load(config).model
    assert "network" in saved and "contacts" not in saved and "contact_passes" in saved
    (run / ".hydra" / "config.yaml").write_text(
        config.read_text().replace("contact_passes: 2", "contact_passes: 1")
    )
    then, then_cfg, _ = load_run(run)
    now, now_cfg, _ = load_run(tiny_fd_run)
    assert then_cfg.model.contacts.contact_passes == then.contacts.contact_passes == 1
    then_cfg.model.contacts.contact_passes = 2
    assert then_cfg.model == now_cfg.model
    state = batch([trajectory(3, seed=5)], t=2, H=now.H)
    now.contacts = dataclasses.replace(now.contacts, contact_passes=1)
    with torch.no_grad():
        assert torch.equal(then(state)[0], now(state)[0])


def test_a_run_of_the_flat_layout_loads_as_today_and_predicts_alike(tiny_fd_run, flat_run):
    assert "network" not in OmegaConf.load(flat_run / ".hydra" / "config.yaml").model
    then, then_cfg, _ = load_run(flat_run)
    now, now_cfg, _ = load_run(tiny_fd_run)
    assert then_cfg.model == now_cfg.model and then_cfg.model.network.M == 1
    state = batch([trajectory(3, seed=5)], t=2, H=now.H)
    with torch.no_grad():
        assert torch.equal(then(state)[0], now(state)[0])


def test_a_flat_run_whose_weights_do_not_fit_names_todays_key(flat_run):
    config = flat_run / ".hydra" / "config.yaml"
    config.write_text(config.read_text().replace("\n  M: 1\n", "\n  M: 2\n"))
    with pytest.raises(RunError, match=r"\(model\.network\.M is 1 in the weights, 2 in the"):
        load_run(flat_run)


def test_a_run_whose_weights_do_not_fit_names_the_groups_key(flat_run):
    config = flat_run / ".hydra" / "config.yaml"
    config.write_text(
        config.read_text().replace("\n  mass_ratio: true\n", "\n  mass_ratio: false\n")
    )
    match = r"\(model\.inputs\.mass_ratio is True in the weights, False in the"
    with pytest.raises(RunError, match=match):
        load_run(flat_run)


def previous_shipped_run(folder: Path) -> Path:
    """A run folder with the config of the previously shipped weights (flat model and recipe
    keys) and a checkpoint of its names, dtypes and shapes (placeholder values):
    ``tests/previous_shipped``."""
    (folder / ".hydra").mkdir(parents=True)
    shutil.copy(PREVIOUS_SHIPPED / "config.yaml", folder / ".hydra" / "config.yaml")
    layout = json.loads((PREVIOUS_SHIPPED / "weights.json").read_text())
    state = {
        name: torch.ones(entry["shape"], dtype=getattr(torch, entry["dtype"]))
        for name, entry in layout.items()
    }
    (folder / "checkpoints").mkdir()
    torch.save(
        {"state_dict": state, "global_step": 22_500},
        folder / "checkpoints" / "best-step022500.ckpt",
    )
    (folder / "run.json").write_text(json.dumps({"status": "finished", "weights_format": 1}))
    return folder


def test_the_previously_shipped_weights_hold_a_flat_config_and_load_in_todays_layout(tmp_path):
    run = previous_shipped_run(tmp_path / "shipped")
    assert "network" not in OmegaConf.load(run / ".hydra" / "config.yaml").model
    simulator, cfg, _ = load_run(run)
    assert cfg.model.network.M == simulator.M == 5 and cfg.model.graph.backend == "auto"
    assert cfg.model.inputs.mass_ratio and cfg.model.contacts.rest_speed == 0.01
    # trained before the contact changes: one pass, no pair impulses, the latch
    contacts = simulator.contacts
    assert (contacts.contact_passes, contacts.pair_impulses, contacts.recent_contact) == (
        0,
        False,
        True,
    )
    assert simulator.graph_builder.connectivity == cfg.model.graph.connectivity == "approach"


def test_a_flat_model_lacking_the_later_keys_gets_its_own_models_values():
    old = OmegaConf.create(
        {
            "_target_": "physgnn.simulator.LearnedSimulator",
            "H": 2,
            "M": 3,
            "connectivity": "vi",
            "neighbor_backend": "torch",
        }
    )
    today = model_of_today(old)
    assert today._target_ == "physgnn.models.learned.LearnedSimulator"
    assert today.network == NODES["network"] | {"M": 3, "aggregation": "sum"}
    graph = {"connectivity": "vi", "backend": "torch", "fixed_capacity": False}
    assert today.graph == NODES["graph"] | graph
    nested = {key: today[node].get(name) for key, (node, name) in FLAT_KEYS.items()}
    assert {key: nested[key] for key in EARLIER_MODEL} == EARLIER_MODEL
    assert {key: nested[key] for key in PREVIOUS_MODEL} == PREVIOUS_MODEL
    assert today.contacts._target_ == "physgnn.models.options.ContactHandling"
    assert model_of_today(today) == today  # today's layout comes back as it is


def test_keys_translate_both_ways_and_the_default_keeps_its_fingerprint():
    assert key_of_today("model.M=1") == "model.network.M=1"
    assert key_of_today("model.neighbor_backend") == "model.graph.backend"
    assert key_of_today("model.H=0") == "model.H=0" == key_of_today("model.H=0")
    assert key_of_today("model.network.M=1") == "model.network.M=1"
    assert key_of_today("model.contact_passes=0") == "model.contacts.contact_passes=0"
    assert key_of_today("model.mass_ratio") == "model.inputs.mass_ratio"
    flat = {"model.network.M": 5, "model.network._target_": "x", "model.graph.backend": "auto"}
    assert flat_layout(flat) == {"model.M": 5, "model.neighbor_backend": "auto"}
    # the default's fingerprint names its model, not the layout that spells it
    cfg = compose_config("train")
    before = cfg.copy()
    before.model = flat_model(cfg.model)
    assert "network" not in before.model
    assert current_fingerprint() == defaults_fingerprint(before)
    # nor how it runs, nor how its schedule is spelt: the default of the engine state with the
    # planes by Newton's law (the study's records are of the defaults before it, 4c8ff143bb
    # and earlier)
    assert current_fingerprint() == "9c3b1d1bcf"


def test_a_run_of_the_flat_recipe_loads_with_todays_groups(tiny_run, tmp_path):
    run = Path(shutil.copytree(tiny_run, tmp_path / "run"))
    config = run / ".hydra" / "config.yaml"
    cfg = OmegaConf.load(config)
    cfg.lit = FLAT_LIT
    OmegaConf.save(cfg, config)
    simulator, cfg, _ = load_run(run)
    lit = instantiate(cfg.lit, simulator=simulator)
    assert lit.seed == cfg.seed and isinstance(lit, LitSimulator)
    assert lit.noise == InputNoise(0.01, 0.5, 0.1, 0.4, 0.06)
    assert lit.pushforward == PushForward(3, 10, 5)
    # a run without truth_contacts had the previous default: the state's own motion
    assert lit.loss_terms == LossTerms(0.5, 2.0, 0.03, 0.25, False)
    assert cfg.lit.compile == {
        "_target_": f"{Compile.__module__}.Compile",
        "enabled": False,
        "mode": "default",
        "shapes": 8,
    }
    decay = lit.scheduler_factory(torch.optim.SGD([torch.nn.Parameter(torch.zeros(1))], lr=1))
    assert isinstance(decay, RunLengthDecay) and decay.final_lr_factor == 0.25  # the same
    assert lit_of_today(cfg.lit) == cfg.lit  # today's layout comes back as it is


def test_the_previously_shipped_weights_hold_a_flat_recipe_read_in_todays_groups(tmp_path):
    run = previous_shipped_run(tmp_path / "shipped")
    assert "noise_std" in OmegaConf.load(run / ".hydra" / "config.yaml").lit
    _, cfg, _ = load_run(run)
    assert cfg.lit.noise.std == 0.03 and cfg.lit.pushforward.steps == 2
    assert cfg.lit.scheduler.gamma == 0.99696  # its per-epoch decay, as it was


def test_a_flat_recipe_key_typed_today_is_one_line_naming_the_new_one():
    with pytest.raises(
        ConfigError,
        match=r"^lit.noise_std is now lit.noise.std: write "
        r"lit.noise.std=0.01$",
    ):
        check_resume_argv(["data=tiny", "lit.noise_std=0.01"])
    with pytest.raises(ConfigError, match=r"^lit.compile is now lit.compile.enabled"):
        check_resume_argv(["+lit.compile=true"])
    with pytest.raises(ConfigError, match=r"lit.scheduler.decay_per_epoch=0.1 lit.schedul"):
        check_resume_argv(["lit.scheduler.final_lr_factor=0.1"])
    check_resume_argv(["lit.noise.std=0.01", "lit.compile.enabled=true"])  # today's: taken
    with pytest.raises(
        ConfigError,
        match=r"^model.contact_passes is now model.contacts.contact_passes: write "
        r"model.contacts.contact_passes=0$",
    ):
        check_resume_argv(["model.contact_passes=0"])
    with pytest.raises(ConfigError, match=r"^model.boundary_features is now model.inputs.bound"):
        check_resume_argv(["+model.boundary_features=true"])
    check_resume_argv(["model.contacts.contact_passes=0", "model.H=1"])  # today's: taken


def test_an_interrupted_run_of_flat_overrides_resumes_with_todays_spelling(tmp_path):
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "last.ckpt").write_bytes(b"")
    info = {"status": "interrupted", "overrides": ["lit.noise_std=0.01", "model.M=3"]}
    (tmp_path / "run.json").write_text(json.dumps(info))
    check_resume_overrides(tmp_path, ["lit.noise.std=0.01", "model.network.M=3"])
    # the run's name in the loggers is not what it trains (a study's job named since)
    check_resume_overrides(tmp_path, ["lit.noise.std=0.01", "model.network.M=3", "run_name=x"])
    with pytest.raises(ConfigError, match="missing: lit.noise.std=0.01; new: lit.noise.std=0.02"):
        check_resume_overrides(tmp_path, ["lit.noise.std=0.02", "model.network.M=3"])


def test_recipe_keys_translate_both_ways():
    assert key_of_today("lit.noise_std=0") == "lit.noise.std=0"
    assert key_of_today("lit.compile_mode") == "lit.compile.mode"
    assert key_of_today("lit.noise.std=0") == "lit.noise.std=0"
    flat = {
        "lit.noise.std": 0,
        "lit.noise._target_": "x",
        "lit.compile.enabled": True,
        "datamodule.pushforward_steps": "${lit.pushforward.steps}",
    }
    assert flat_layout(flat) == {
        "lit.noise_std": 0,
        "lit.compile": True,
        "datamodule.pushforward_steps": "${lit.pushforward_steps}",
    }


def test_registry_records_of_the_flat_layout_read_with_todays_keys(tmp_path):
    path = tmp_path / "registry.jsonl"
    keys = [
        "model.M=1",
        "model.aggregation=sum model.boundary_features=True",
        "baseline",
        "lit.pushforward_growth=450 lit.pushforward_steps=4",
    ]
    for key in keys:
        append_record(path, {"key": key, "seed": 0, "budget": {"steps": 1}, "status": "finished"})
    assert [r["key"] for r in read_registry(path)] == [
        "model.network.M=1",
        "model.inputs.boundary_features=True model.network.aggregation=sum",
        "baseline",
        "lit.pushforward.growth=450 lit.pushforward.steps=4",
    ]

"""The model config's layout: runs whose model holds the network's and the graph builder's keys
flat (an earlier physgnn's, the shipped weights) load as today's nested ``network`` and
``graph`` nodes, and the study reads their registry keys in today's spelling."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf
from simdata import batch, trajectory

from physgnn.ablation.jobs import current_fingerprint, defaults_fingerprint
from physgnn.ablation.registry import append_record, read_registry
from physgnn.cli import compose_config
from physgnn.training.layout import (
    EARLIER_MODEL,
    FLAT_KEYS,
    NODES,
    flat_layout,
    key_of_today,
    model_of_today,
)
from physgnn.training.runs import PRETRAINED_DIR, RunError, load_run


def flat_model(model) -> dict:
    """A model config of today's layout in the flat layout of an earlier physgnn."""
    flat = {k: v for k, v in model.items() if k not in NODES}
    return flat | {key: model[node][name] for key, (node, name) in FLAT_KEYS.items()}


def flatten(config: Path) -> None:
    """Rewrite a run's ``.hydra/config.yaml`` with its model in the flat layout."""
    cfg = OmegaConf.load(config)
    cfg.model = flat_model(cfg.model)
    OmegaConf.save(cfg, config)


@pytest.fixture
def flat_run(tiny_run, tmp_path) -> Path:
    """A copy of the session's tiny run (M = 1) with its model config flat."""
    run = Path(shutil.copytree(tiny_run, tmp_path / "run"))
    flatten(run / ".hydra" / "config.yaml")
    return run


def test_a_run_of_the_flat_layout_loads_as_today_and_predicts_alike(tiny_run, flat_run):
    assert "network" not in OmegaConf.load(flat_run / ".hydra" / "config.yaml").model
    then, then_cfg, _ = load_run(flat_run)
    now, now_cfg, _ = load_run(tiny_run)
    assert then_cfg.model == now_cfg.model and then_cfg.model.network.M == 1
    state = batch([trajectory(3, seed=5)], t=2, H=now.H)
    with torch.no_grad():
        assert torch.equal(then(state)[0], now(state)[0])


def test_a_flat_run_whose_weights_do_not_fit_names_todays_key(flat_run):
    config = flat_run / ".hydra" / "config.yaml"
    config.write_text(config.read_text().replace("\n  M: 1\n", "\n  M: 2\n"))
    with pytest.raises(RunError, match=r"\(model\.network\.M is 1 in the weights, 2 in the"):
        load_run(flat_run)


def test_the_shipped_weights_hold_a_flat_config_and_load_in_todays_layout():
    assert "network" not in OmegaConf.load(PRETRAINED_DIR / ".hydra" / "config.yaml").model
    simulator, cfg, _ = load_run("pretrained")
    assert cfg.model.network.M == simulator.M == 5 and cfg.model.graph.backend == "auto"
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
    nested = ("aggregation", "fixed_capacity")  # keys of the nodes
    assert {k: today[k] for k in EARLIER_MODEL if k not in nested} == {
        k: v for k, v in EARLIER_MODEL.items() if k not in nested
    }
    assert model_of_today(today) == today  # today's layout comes back as it is


def test_keys_translate_both_ways_and_the_default_keeps_its_fingerprint():
    assert key_of_today("model.M=1") == "model.network.M=1"
    assert key_of_today("model.neighbor_backend") == "model.graph.backend"
    assert key_of_today("model.H=0") == "model.H=0" == key_of_today("model.H=0")
    assert key_of_today("model.network.M=1") == "model.network.M=1"
    flat = {"model.network.M": 5, "model.network._target_": "x", "model.graph.backend": "auto"}
    assert flat_layout(flat) == {"model.M": 5, "model.neighbor_backend": "auto"}
    # the default's fingerprint names its model, not the layout that spells it
    cfg = compose_config("train")
    before = cfg.copy()
    before.model = flat_model(cfg.model)
    assert "network" not in before.model
    assert current_fingerprint() == defaults_fingerprint(before)
    # nor how it runs, nor how its schedule is spelt: the same default as its study records
    assert current_fingerprint() == "2ae034a7d1"


def test_registry_records_of_the_flat_layout_read_with_todays_keys(tmp_path):
    path = tmp_path / "registry.jsonl"
    keys = ["model.M=1", "model.aggregation=sum model.boundary_features=True", "baseline"]
    for key in keys:
        append_record(path, {"key": key, "seed": 0, "budget": {"steps": 1}, "status": "finished"})
    assert [r["key"] for r in read_registry(path)] == [
        "model.network.M=1",
        "model.boundary_features=True model.network.aggregation=sum",
        "baseline",
    ]

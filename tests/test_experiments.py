"""Every sweep of conf/experiment/ composes as a multirun and every job of it instantiates;
the single-run experiments compose with their budget."""

from __future__ import annotations

import itertools
from pathlib import Path

import pytest
from hydra.types import RunMode
from hydra.utils import instantiate
from omegaconf import OmegaConf
from simdata import REPORT_MODEL
from trainkit import compose_train

from physgnn import CONF_DIR
from physgnn.training.build import build, strategy_of
from physgnn.training.layout import dotted_model, key_of_today

CONF = Path(CONF_DIR)
# Experiments of one run (not sweeps), with their optimiser-step budget.
SINGLE = {"long": 22_500, "engine_state": 2_250, "narrow": 2_250}
EXPERIMENTS = sorted(p.stem for p in (CONF / "experiment").glob("*.yaml") if p.stem not in SINGLE)
RUNS = {
    "ablation_H": 15,
    "ablation_M": 15,
    "ablation_connectivity": 12,
    "ablation_lambda": 12,
    "ablation_components": 24,
    "ablation_contacts": 45,
    "ablation_state": 48,
}


def parse(value: str):
    """A sweep value as Hydra reads it (int, float or string)."""
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    return value


def sweep_jobs(params) -> list[list[str]]:
    """The override lists of the jobs a basic-sweeper multirun launches."""
    axes = [
        [f"{key}={value}" for value in str(values).split(",")] for key, values in params.items()
    ]
    return [list(job) for job in itertools.product(*axes)]


def optimiser_steps(cfg) -> int:
    """The optimiser steps of a composed training config's budget."""
    return cfg.trainer.max_epochs * cfg.datamodule.pairs_per_epoch // cfg.datamodule.batch_size


def test_every_experiment_is_listed():
    files = sorted(p.stem for p in (CONF / "experiment").glob("*.yaml"))
    assert files == sorted([*RUNS, *SINGLE])


def test_the_long_run_is_ten_default_budgets_with_milestones(tiny_dataset, tmp_path):
    base = ["data=tiny", f"paths.outputs={Path(tiny_dataset).parents[1]}", f"run_dir={tmp_path}"]
    cfg = compose_train(["+experiment=long", "model.network.hidden=8", *base])
    assert cfg.hydra.mode != RunMode.MULTIRUN and cfg.experiment_name == "long"
    steps = optimiser_steps(cfg)
    assert steps == SINGLE["long"] == 10 * 2250
    # the default's decay over 90 epochs (0.97^90), spread over the 900
    decay = cfg.lit.scheduler
    assert decay.decay_per_epoch**decay.epochs == 0.97**90  # tests/test_schedule.py
    _, _, trainer = build(cfg)
    kept = [c for c in trainer.callbacks if getattr(c, "dirpath", "").endswith("milestones")]
    assert len(kept) == 1 and kept[0]._every_n_train_steps == 2250 and kept[0].save_top_k == -1


def test_the_narrow_network_is_the_default_model_with_64_wide_layers_and_3_blocks(
    tiny_dataset, tmp_path
):
    base = ["data=tiny", f"paths.outputs={Path(tiny_dataset).parents[1]}", f"run_dir={tmp_path}"]
    cfg, default = compose_train(["+experiment=narrow", *base]), compose_train(base)
    steps = optimiser_steps(cfg)
    assert cfg.experiment_name == "narrow" and steps == SINGLE["narrow"]
    model, base_model = OmegaConf.to_container(cfg.model), OmegaConf.to_container(default.model)
    assert model.pop("network") == base_model.pop("network") | {"hidden": 64, "M": 3}
    assert model == base_model  # the rest of the model is the default's
    _, lit, _ = build(cfg)
    network = lit.simulator.network
    assert len(network.blocks) == 3 and network.node_encoder.lin1.out_features == 64


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_experiment_composes_and_every_job_instantiates(name, tiny_dataset, tmp_path):
    base = [
        "data=tiny",
        f"paths.outputs={Path(tiny_dataset).parents[1]}",
        f"run_dir={tmp_path}",
        "model.network.hidden=8",
    ]
    cfg = compose_train([f"+experiment={name}", *base])
    assert cfg.hydra.mode == RunMode.MULTIRUN and cfg.experiment_name == name
    params = cfg.hydra.sweeper.params
    assert params.seed == "0,1,2"
    jobs = sweep_jobs(params)
    assert len(jobs) == RUNS[name]
    datamodule, lit, trainer = build(compose_train([f"+experiment={name}", *base, *jobs[0]]))
    assert trainer.max_epochs == 90 and datamodule.batch_size == 256  # 2250 steps for all
    stats = datamodule.stats()
    for job in jobs[::3]:  # one seed of each value: the model and module that job trains
        key, value = job[0].split("=")
        if key == "+variant":  # named variants: composed in the test below
            assert (CONF / "variant" / f"{value}.yaml").exists()
            continue
        job_cfg = cfg.copy()
        OmegaConf.update(job_cfg, key, parse(value))
        lit = instantiate(job_cfg.lit, simulator=instantiate(job_cfg.model, stats=stats))
        assert lit.simulator.H == job_cfg.model.H == job_cfg.datamodule.H
        built = {
            "model.H": lit.simulator.H,
            "model.network.M": lit.simulator.M,
            "model.graph.connectivity": lit.simulator.graph_builder.connectivity,
            "lit.loss.lambda_energy": lit.loss_terms.lambda_energy,
        }
        assert built[key] == OmegaConf.select(job_cfg, key) == parse(value)


def test_components_variants_change_what_they_name(tiny_dataset, tmp_path):
    base = ["data=tiny", f"paths.outputs={Path(tiny_dataset).parents[1]}", f"run_dir={tmp_path}"]
    baseline = compose_train([*base, "+variant=baseline"])
    expected = {
        "m1": {"model.network.M": 1},
        "epsilon": {"model.graph.connectivity": "epsilon"},
        "h0": {},  # the report's H = 0 row: the default's history since the engine state
        "energy": {"lit.loss.lambda_energy": 10.0},
        "no_noise": {"lit.noise.std": 0.0},
        "no_third_law": {"model.network.third_law": False},
        "gns": {
            "model.network.third_law": False,
            "model.network.use_surfaces": False,
            "model.inputs.boundary_features": True,
            "model.H": 2,
            **REPORT_INPUTS,
        },
        # each invariance of the default model undone alone
        "vi_connectivity": {"model.graph.connectivity": "vi"},
        "absolute_pairs": {"model.inputs.relative_pairs": False},
        "absolute_mass": {"model.inputs.mass_ratio": False},
        "sum_aggregation": {"model.network.aggregation": "sum"},
        "no_rest_decision": {"model.contacts.rest_decision": False},
        "uniform_noise": {"lit.noise.rest_scale": 1.0},
        "no_dense_data": {},  # the data only (below)
    }
    stats = build(baseline)[0].stats()
    for variant, changes in expected.items():
        cfg = compose_train([*base, f"+variant={variant}"])
        lit = instantiate(cfg.lit, simulator=instantiate(cfg.model, stats=stats))
        assert lit.simulator.M == cfg.model.network.M and lit.noise.std == cfg.lit.noise.std
        for section in ("model", "lit"):  # the keys of the network and the graph too
            default = dotted_model(baseline[section])
            for key, value in dotted_model(cfg[section]).items():
                want = changes.get(f"{section}.{key}", default[key])
                assert value == want, (variant, key)
    assert baseline.model.network.M == 5 and baseline.model.H == 0
    assert baseline.lit.loss.lambda_energy == 0
    assert baseline.model.graph.connectivity == "approach" and baseline.lit.noise.std == 0.03
    assert baseline.model.network.aggregation == "mean" and baseline.lit.noise.rest_scale == 0.05
    nodense = compose_train([*base, "+variant=no_dense_data"]).data
    assert nodense.fit_scene.dense_fraction == 0.0 and nodense.dir.endswith("small_nodense")


# the report's model (model=report, which model=gns builds on) against the default
REPORT_INPUTS = {key_of_today(f"model.{key}"): value for key, value in REPORT_MODEL.items()}


def test_gns_model_config_is_the_gns_variant(tiny_dataset, tmp_path):
    base = ["data=tiny", f"paths.outputs={Path(tiny_dataset).parents[1]}", f"run_dir={tmp_path}"]
    assert compose_train([*base, "model=gns"]).model == compose_train([*base, "+variant=gns"]).model


@pytest.mark.parametrize(
    "choice",
    [
        "trainer=gpu",
        "trainer=ddp",
        "logger=wandb",
        "logger=tensorboard",
        "callbacks=rollout",
        "debug=short",
    ],
)
def test_other_config_choices_compose(choice, tmp_path):
    cfg = compose_train([choice, f"run_dir={tmp_path}"])
    if choice.startswith("logger="):  # building a logger starts no run and needs no network
        logger = instantiate(cfg.logger)
        assert Path(logger.save_dir) == tmp_path
    if choice == "logger=wandb":
        assert cfg.logger.offline is True
    if choice == "trainer=ddp":
        # the network skips the MLPs of absent interactions: DDP must allow unused parameters
        strategy = strategy_of(cfg.trainer)
        assert strategy._ddp_kwargs == {"find_unused_parameters": True}
        assert cfg.trainer.accelerator == "gpu"
    if choice == "callbacks=rollout":
        names = [type(instantiate(c)).__name__ for c in cfg.callbacks.values()]
        assert names == ["RolloutCallback", "ModelCheckpoint", "LearningRateMonitor"]
        assert cfg.callbacks.rollout.ood is True and cfg.callbacks.checkpoint.monitor == (
            "val/rollout_score"
        )


@pytest.mark.parametrize("preset,frames", [("tiny", None), ("small", None), ("paper", 300)])
def test_the_data_preset_sizes_the_validation_rollouts(preset, frames, tmp_path):
    rollout = compose_train([f"data={preset}", f"run_dir={tmp_path}"]).callbacks.rollout
    assert (rollout.n_val_trajectories, rollout.max_frames) == (10, frames)


@pytest.mark.parametrize(
    "launcher,plugin",
    [
        ("local", "hydra_plugins.hydra_joblib_launcher"),
        ("slurm", "hydra_plugins.hydra_submitit_launcher"),
        ("slurm_ddp", "hydra_plugins.hydra_submitit_launcher"),
    ],
)
def test_launcher_configs_compose_when_installed(launcher, plugin, tmp_path):
    pytest.importorskip(plugin)
    cfg = compose_train([f"hydra/launcher={launcher}", f"run_dir={tmp_path}"])
    assert "Launcher" in cfg.hydra.launcher._target_

"""A user's mistake in a training, study, ship or generate command is one line naming the key
(or the argument), the value given and the fix: never a traceback, never Hydra's "Error in call
to target" wrapper, never a wrong value taken silently. A training's config is checked whole
(:func:`~physgnn.training.build.check_config`) before anything is built."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from physgnn import generate as generate_command
from physgnn.ablation.jobs import StudyError
from physgnn.ablation.launch import launch
from physgnn.ablation.study import check_study, run_study
from physgnn.cli import compose_config
from physgnn.data.dataset import DATASET_MARKER, generate_hint, write_marker
from physgnn.errors import ConfigError, PhysgnnError
from physgnn.graph import neighbors, rules
from physgnn.training import ranges
from physgnn.training.build import check_config, check_devices, check_max_time
from physgnn.training.export import export_run
from physgnn.training.export import main as ship
from physgnn.training.runs import RunMissing, load_run, resolve_run


def check_train(*overrides: str) -> None:
    """:func:`check_config` of the training config of ``overrides``."""
    check_config(compose_config("train", list(overrides)))


# --- training: Hydra's wrapper, and values taken silently ----------------------------------------


@pytest.mark.parametrize(
    "override,message",
    [
        (
            "model.graph.connectivity=epsilonn",
            "model.graph.connectivity must be one of approach, epsilon, vmax, vi (the rules "
            "that link pairs), got 'epsilonn' (did you mean model.graph.connectivity=epsilon?)",
        ),
        (
            "callbacks.rollout.every_n_epochs=0",
            "callbacks.rollout.every_n_epochs must be a whole number >= 1 (validation epochs "
            "between rollouts), got 0 (e.g. callbacks.rollout.every_n_epochs=1)",
        ),
        (
            "trainer.devices=0",
            "trainer.devices must be a whole number >= 1, auto on the CPU "
            "(trainer.accelerator=cpu), got 0 (e.g. trainer.devices=1)",
        ),
        (
            "trainer.devices=[0,1]",
            "trainer.devices must be a whole number >= 1, auto on the CPU "
            "(trainer.accelerator=cpu), got [0, 1] (e.g. trainer.devices=1)",
        ),
        (
            "trainer.max_time=1h",
            "trainer.max_time must be a duration > 0 written DD:HH:MM:SS (days, hours, minutes, "
            "seconds) or a mapping of days, hours, minutes, seconds, or null (no clock guard), "
            "got '1h' (e.g. trainer.max_time=00:04:00:00: 4 hours)",
        ),
        (
            "trainer.gradient_clip_val=-1",
            "trainer.gradient_clip_val must be a number >= 0 or null (the gradients' largest "
            "norm; 0 or null: no clipping), got -1 (e.g. trainer.gradient_clip_val=1.0)",
        ),
        (
            "model.graph.epsilon=-0.1",
            "model.graph.epsilon must be a number >= 0 (m), got -0.1 (e.g. model.graph.epsilon=0)",
        ),
    ],
)
def test_a_constructor_or_trainer_value_is_one_line_naming_it(override, message):
    with pytest.raises(ConfigError) as err:
        check_train(override)
    assert str(err.value) == message


@pytest.mark.parametrize(
    "overrides",
    [
        [],
        ["trainer.devices=auto"],
        ["trainer.devices=2"],
        ["trainer.max_time=00:04:00:00"],
        ["trainer.max_time={hours: 4}"],
        ["trainer.gradient_clip_val=null"],
        ["trainer.gradient_clip_val=0"],
        ["model.graph.connectivity=vi"],
    ],
)
def test_the_values_lightning_and_the_constructors_take_pass(overrides):
    check_train(*overrides)


def test_a_gpu_takes_all_its_devices_or_a_list_of_them():
    for devices in (-1, 1, [0, 1], "0,1", "0,", "-1", "auto"):
        check_devices(devices, "gpu")
    for devices in (0, [], [-2], "0", "x"):
        with pytest.raises(ConfigError, match="trainer.devices must be a whole number >= 1"):
            check_devices(devices, "gpu")


def test_a_clock_guard_that_is_no_duration_longer_than_0_is_refused():
    check_max_time(OmegaConf.create({"days": 1, "minutes": 30}))
    for value in ("00:00:00:00", 3600, "4:00:00", {"hour": 4}, {"hours": -1}):
        with pytest.raises(ConfigError, match="trainer.max_time must be a duration > 0"):
            check_max_time(value)


def test_the_graph_choices_are_the_graph_builders():
    assert ranges.CONNECTIVITIES == rules.CONNECTIVITIES
    assert ranges.BACKENDS == neighbors.BACKENDS


@pytest.mark.parametrize("override", ["lit.noise.std=-1", "model.H=-1", "trainer.max_epochs=0"])
def test_range_errors_of_lit_model_and_trainer_are_one_check(override):
    with pytest.raises(ConfigError, match=f"^{override.split('=')[0]} must be"):
        check_train(override)


# --- ckpt_path ---------------------------------------------------------------------------------


def test_a_ckpt_path_that_is_not_a_checkpoint_says_so(tmp_path):
    text = tmp_path / "notes.txt"
    text.write_text("hello, this is text\n")
    with pytest.raises(ConfigError) as err:
        check_train(f"ckpt_path={text}")
    assert str(err.value) == (
        f"ckpt_path={text} is not a checkpoint (torch.save writes a zip, this file is not one): "
        "give a run's .ckpt (<run>/checkpoints/last.ckpt)"
    )
    with pytest.raises(ConfigError, match=f"^ckpt_path={tmp_path / 'gone.ckpt'}: no such file"):
        check_train(f"ckpt_path={tmp_path / 'gone.ckpt'}")


# --- study ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "override,message",
    [
        (
            "seeds=[abc]",
            "seeds[0] must be a whole number from 0 to 4294967295, got 'abc' (e.g. seeds=[0,1,2])",
        ),
        ("seeds=[]", "seeds must be a list of at least one seed, got [] (e.g. seeds=[0,1,2])"),
        (
            "launcher.n_jobs=0",
            "launcher.n_jobs must be a whole number >= 1 (jobs at a time on this machine), got 0 "
            "(e.g. launcher.n_jobs=2)",
        ),
        (
            "launcher.name=slurmm",
            "launcher.name must be one of local, slurm (this machine, or one SLURM job per run), "
            "got 'slurmm' (did you mean launcher.name=slurm?)",
        ),
        (
            "preset=smal",
            "preset must be one of paper, small, tiny (the training data: "
            "conf/data/<preset>.yaml), got 'smal' (did you mean preset=small?)",
        ),
    ],
)
def test_a_study_mistake_is_refused_before_any_job_is_listed(override, message, tmp_path, capsys):
    cfg = compose_config("study", ["dry_run=true", override, f"runs_dir={tmp_path}"])
    with pytest.raises(StudyError) as err:
        check_study(cfg)
    assert str(err.value) == message
    with pytest.raises(StudyError):
        run_study(cfg)  # the dry run too
    assert capsys.readouterr().out == ""


def test_the_launcher_checks_its_values_even_without_jobs():
    with pytest.raises(StudyError, match="launcher.n_jobs must be a whole number >= 1"):
        launch([], OmegaConf.create({"name": "local", "n_jobs": 0}), Path("."))


# --- ship ----------------------------------------------------------------------------------------


def finished_run(folder: Path, step: int = 7) -> Path:
    """A finished run folder with one checkpoint."""
    (folder / ".hydra").mkdir(parents=True)
    (folder / ".hydra" / "config.yaml").write_text("model: {}\n")
    (folder / "checkpoints").mkdir()
    state = {"simulator.w": torch.zeros(3)}
    torch.save({"state_dict": state, "global_step": step}, folder / "checkpoints" / "last.ckpt")
    (folder / "run.json").write_text(json.dumps({"status": "finished", "seed": 0}))
    return folder


def test_ship_refuses_another_runs_checkpoint(tmp_path, capsys):
    seed0, seed1 = finished_run(tmp_path / "seed0"), finished_run(tmp_path / "seed1", step=9)
    other = seed1 / "checkpoints" / "last.ckpt"
    assert ship([str(seed0), str(tmp_path / "O"), str(other)]) == 2
    assert capsys.readouterr().err == (
        f"error: CHECKPOINT {other} is not one of RUN_DIR's checkpoints (in "
        f"{seed0 / 'checkpoints'}): the package's run.json names RUN_DIR as the run its weights "
        "come from; give a checkpoint of that folder, or ship the checkpoint's own run (physgnn "
        "ship <its run folder> OUT_DIR CHECKPOINT)\n"
    )
    assert not (tmp_path / "O").exists()
    own = seed0 / "checkpoints" / "last.ckpt"
    assert export_run(seed0, tmp_path / "O", own).name == "best-step000007.ckpt"


def test_ship_names_a_missing_checkpoint_and_a_missing_run(tmp_path, capsys):
    run = finished_run(tmp_path / "run")
    missing = run / "checkpoints" / "best.ckpt"
    assert ship([str(run), str(tmp_path / "O"), str(missing)]) == 2
    assert capsys.readouterr().err == (
        f"error: CHECKPOINT {missing} does not exist: give one of RUN_DIR's checkpoints "
        f"({run / 'checkpoints'}/last.ckpt or best-*.ckpt), or leave it out (its best)\n"
    )
    assert ship([str(tmp_path / "nonexistent"), str(tmp_path / "O")]) == 2
    assert capsys.readouterr().err == (
        f"error: RUN_DIR {tmp_path / 'nonexistent'} does not exist: give the folder of a "
        "finished run (outputs/runs/<experiment>/<time>)\n"
    )


def test_ship_names_a_checkpoint_that_is_not_one(tmp_path):
    run = finished_run(tmp_path / "run")
    text = run / "checkpoints" / "notes.ckpt"
    text.write_text("not weights")
    with pytest.raises(PhysgnnError, match=f"^CHECKPOINT {text} is not a checkpoint"):
        export_run(run, tmp_path / "O", text)


# --- run folders ---------------------------------------------------------------------------------


def test_a_misspelt_pretrained_is_answered_with_it(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(RunMissing) as err:
        resolve_run("pretrianed")
    assert str(err.value) == (
        "run folder pretrianed does not exist: did you mean pretrained? Else give a run folder "
        "(outputs/runs/<experiment>/<time>) or pretrained"
    )
    assert resolve_run("outputs/runs/x") == Path("outputs/runs/x")  # eval says what is missing


def test_loading_a_run_that_is_not_there_is_physgnns_error(tmp_path):
    with pytest.raises(PhysgnnError) as err:
        load_run(tmp_path / "nowhere")
    assert str(err.value) == (
        f"run folder {tmp_path / 'nowhere'} does not exist: give a run folder "
        "(outputs/runs/<experiment>/<time>) or pretrained"
    )
    with pytest.raises(RunMissing, match=r"is not a training run \(no .hydra/config.yaml\): give"):
        load_run(tmp_path)


# --- datasets ------------------------------------------------------------------------------------


def test_a_folder_that_is_not_a_dataset_is_never_told_to_be_overwritten(tmp_path):
    folder = tmp_path / "conf"
    folder.mkdir()
    (folder / "train.yaml").write_text("x: 1\n")
    assert generate_hint(folder, "small") == (
        f"{folder} is not a dataset (no {DATASET_MARKER}): point data.dir at a dataset, or "
        "generate into a new folder (`python -m physgnn.generate data=small "
        "data.dir=<a new folder>`)"
    )
    write_marker(folder, "small")
    assert generate_hint(folder).endswith(f"data=small data.dir={folder} overwrite=true`")
    shutil.rmtree(folder)
    assert "overwrite" not in generate_hint(folder)


# --- generate ------------------------------------------------------------------------------------


def test_a_scenes_clock_is_named_by_its_key():
    with pytest.raises(ConfigError) as err:
        generate_command.check_clock(["data.scene.n_frames=1"])
    assert str(err.value) == (
        "data.scene.n_frames must be a whole number >= 2 (frames of a trajectory: the first is "
        "the start), got 1 (e.g. data.scene.n_frames=300)"
    )
    with pytest.raises(ConfigError, match=r"^data.ood.ood_cubes.dt must be a number > 0"):
        generate_command.check_clock(["data.ood.ood_cubes.dt=0"])
    generate_command.check_clock(["data=tiny"])

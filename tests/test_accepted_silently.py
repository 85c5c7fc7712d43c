"""Values that used to be accepted silently (and made wrong figures): each now refused in one
line naming the key or the file, and the fix."""

from __future__ import annotations

import importlib
import re
import shutil
import sys
from pathlib import Path

import h5py
import pytest
from hydra import compose, initialize_config_dir

from physgnn import CONF_DIR
from physgnn import simulate as simulate_command
from physgnn.cli.overrides import check_composes
from physgnn.data.dataset import DatasetError, read_split
from physgnn.errors import ConfigError
from physgnn.evaluation.evaluate import evaluate
from physgnn.groundtruth.scenefile import scene_from_dict
from physgnn.physics.scene import SceneError

ROOT = Path(__file__).resolve().parents[1]


# --- keys added with '+' that nothing reads ------------------------------------------------------


@pytest.mark.parametrize(
    "command,override,message",
    [
        (
            "train",
            "+lr=0.01",
            "+lr=0.01: lr is not a key of the train config and nothing reads "
            "it ('+' adds a key that is not there): did you mean lit.optimizer.lr?",
        ),
        (
            "train",
            "+trainer.max_epoch=5",
            "+trainer.max_epoch=5: trainer.max_epoch is not an argument of lightning.Trainer "
            "(did you mean trainer.max_epochs or trainer.min_epochs?)",
        ),
        (
            "train",
            "+model.Hx=3",
            "+model.Hx=3: model.Hx is not an argument of "
            "physgnn.models.learned.LearnedSimulator (did you mean model.H?)",
        ),
        (
            "train",
            "+model.network.Mx=3",
            "+model.network.Mx=3: model.network.Mx is not an "
            "argument of physgnn.nn.epd.EncodeProcessDecode (did you mean model.network.M?)",
        ),
        (
            "train",
            "+model.M=3",
            "+model.M=3: model.M is not an argument of "
            "physgnn.models.learned.LearnedSimulator (did you mean model.network.M?)",
        ),
        (
            "generate",
            "+data.scene.n_maxx=2",
            "+data.scene.n_maxx=2: data.scene.n_maxx is not a "
            "key of the generate config and nothing reads it ('+' adds a key that is not there): "
            "did you mean data.scene.n_max?",
        ),
        ("eval", "+max_frame=3", "+max_frame=3: max_frame is not a key of the eval config"),
        ("bench", "+quik=true", "+quik=true: quik is not a key of the bench config"),
        (
            "data_report",
            "+splitz=[test]",
            "+splitz=[test]: splitz is not a key of the data_report config",
        ),
        ("sleep_study", "+tresh=1", "+tresh=1: tresh is not a key of the sleep_study config"),
        ("study", "+seed=[0]", "+seed=[0]: seed is not a key of the study config"),
    ],
)
def test_an_added_key_nothing_reads_is_refused(
    tmp_path, monkeypatch, capsys, command, override, message
):
    module = importlib.import_module(f"physgnn.{command}")
    argv = [f"physgnn.{command}", f"paths.outputs={tmp_path}", f"hydra.run.dir={tmp_path}/h"]
    monkeypatch.setattr(sys, "argv", [*argv, override])
    with pytest.raises(SystemExit) as exit_info:
        module.main()
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1
    assert err.startswith(f"error: {message}")
    assert not (tmp_path / "runs").exists() and not (tmp_path / "data").exists()


def test_a_new_setting_in_a_mapping_with_fixed_keys_names_the_fix():
    """A mapping on the command line is merged into the config's: a setting it lacks was
    called "not a key of the eval config"; the line now names the keys and the null-first fix,
    and that fix composes."""
    given = "learned_settings={fast: {compile: true}}"
    with pytest.raises(ConfigError) as refused:
        check_composes("eval", [given])
    assert str(refused.value) == (
        f"{given}: fast is not one of the keys of learned_settings (passes0, passes1, "
        "constraints5, threads2), and a mapping given on the command line is merged into "
        f"them: to replace the whole mapping, set it to null first (learned_settings=null "
        f"'{given}')"
    )
    check_composes("eval", ["learned_settings=null", given])


# --- values out of range -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "arg,message",
    [
        (
            "tol=-1",
            "tol must be a number >= 0 (a fraction of the diameter; 0: any overlap counts), got -1",
        ),
        ("tol=nan", "tol must be a number >= 0"),
        (
            "frames=abc",
            "frames must be a whole number >= 2 or null (the first frame is the start), got "
            "'abc' (e.g. frames=100)",
        ),
        ("frames=1", "frames must be a whole number >= 2"),
        ("video=yes", "video must be true or false, got 'yes'"),
    ],
)
def test_bad_simulate_values_are_one_line(tmp_path, capsys, arg, message):
    scene = Path(CONF_DIR) / "scene" / "head_on.yaml"
    with pytest.raises(SystemExit) as exit_info:
        simulate_command.main([f"scene_file={scene}", "video=false", f"out={tmp_path / 'o'}", arg])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and len(err.splitlines()) == 1
    assert err.startswith(f"error: {message}")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "override,message",
    [
        (
            "max_frames=0",
            "max_frames must be a whole number >= 2 or null (whole trajectories), got 0",
        ),
        ("max_frames=-1", "max_frames must be a whole number >= 2 or null"),
        ("tol=-1", "tol must be a number >= 0 (a fraction of the diameter"),
        (
            "learned_settings.passes0.contact_passes=-1",
            "learned_settings.passes0.contact_passes must be a whole number >= 0 or null",
        ),
    ],
)
def test_bad_eval_values_are_refused(tmp_path, override, message):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose("eval", overrides=[f"paths.outputs={tmp_path}", override])
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}"):
        evaluate(cfg)
    assert not (tmp_path / "report").exists()


# --- datasets that lie ------------------------------------------------------------------------


def test_a_split_file_holding_another_split_is_refused(tiny_dataset, tmp_path):
    shutil.copy(tiny_dataset / "train.h5", tmp_path / "val.h5")
    message = f"{tmp_path / 'val.h5'} holds the train split (its file attribute split=train), "
    with pytest.raises(DatasetError, match=f"^{re.escape(message)}not val: put the val split"):
        read_split(tmp_path / "val.h5")


@pytest.mark.parametrize("key", ["radius", "mass"])
def test_a_dataset_with_a_negative_radius_or_mass_is_refused(tiny_dataset, tmp_path, key):
    path = shutil.copy(tiny_dataset / "val.h5", tmp_path / "val.h5")
    with h5py.File(path, "r+") as f:
        f["traj_00000"][key][1] = -0.5
    with pytest.raises(
        DatasetError, match=f"{path}:traj_00000: {key} of sphere 1 is -0.5; every {key} must be > 0"
    ):
        read_split(path)


# --- scenes float32 cannot hold ---------------------------------------------------------------


@pytest.mark.parametrize(
    "position,radius,message",
    [
        ([1.0e30, 0.0, 5.0], 0.5, "sphere 0 has radius 0.5 m in a scene reaching 1e\\+30 m"),
        ([0.0, 0.0, 5.0], 1.0e-9, "sphere 0 has radius 1e-09 m in a scene reaching 5 m"),
    ],
)
def test_a_scene_float32_cannot_hold_is_refused(position, radius, message):
    scene = {
        "name": "far",
        "frames": 3,
        "spheres": [{"radius": radius, "mass": 1.0, "position": position}],
    }
    with pytest.raises(
        SceneError,
        match=f"scene 'far': {message} from the origin, finer than "
        "float32 resolves there: bring the scene near the origin",
    ):
        scene_from_dict(scene)

"""A dataset error's fix names a command that makes that folder, and names the preset only
where the folder is a preset's; a dataset of another preset is refused in one line."""

from __future__ import annotations

import errno
import os
import shutil

import pytest
import torch
from omegaconf import OmegaConf

from physgnn.cli import check_outputs_env, command
from physgnn.data.dataset import DatasetError, generate_hint, write_marker
from physgnn.errors import ConfigError
from physgnn.training.build import check_trainer_config
from physgnn.training.datamodule import StatePairDataModule


def test_a_preset_folder_is_named_by_its_preset_with_overwrite_when_it_exists(
    tmp_path, monkeypatch
):
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(tmp_path))  # make data writes <it>/data/small
    folder = tmp_path / "data" / "small"
    assert generate_hint(folder) == (
        "run `make data PRESET=small` or `python -m physgnn.generate data=small`"
    )
    write_marker(folder, "small")  # a dataset: generate replaces it with overwrite=true
    (folder / "train.h5").write_text("x")
    assert generate_hint(folder) == (
        "run `make data PRESET=small ARGS=overwrite=true` or "
        "`python -m physgnn.generate data=small overwrite=true`"
    )


def test_a_preset_named_folder_elsewhere_is_named_by_data_dir(tmp_path, monkeypatch):
    monkeypatch.setenv("PHYSGNN_OUTPUTS", str(tmp_path / "outputs"))
    elsewhere = tmp_path / "scratch" / "tiny"  # make data PRESET=tiny would not write here
    assert generate_hint(elsewhere) == (
        f"run `python -m physgnn.generate data=tiny data.dir={elsewhere}`"
    )


def test_another_folder_is_named_by_data_dir_and_its_markers_preset(tiny_dataset, tmp_path):
    trunc = tmp_path / "trunc"
    shutil.copytree(tiny_dataset, trunc)
    assert generate_hint(trunc) == (
        f"run `python -m physgnn.generate data=tiny data.dir={trunc} overwrite=true`"
    )
    assert "PRESET=trunc" not in generate_hint(tmp_path / "fresh")


def test_a_dataset_of_another_preset_is_refused(tiny_dataset):
    dm = StatePairDataModule(data_dir=str(tiny_dataset), preset="small", H=2)
    with pytest.raises(DatasetError) as err:
        dm.setup()
    message = str(err.value)
    assert "\n" not in message
    assert f"data.dir {tiny_dataset} holds the 'tiny' dataset" in message
    assert "not 'small' (data=small): train with data=tiny" in message


def test_paths_outputs_naming_a_file_is_one_line(tmp_path):
    a_file = tmp_path / "outputs"
    a_file.write_text("not a folder")
    with pytest.raises(ConfigError, match=f"paths.outputs={a_file} is a file: give a folder"):
        check_outputs_env(["data=tiny", f"paths.outputs={a_file}"])
    check_outputs_env(["data=tiny", f"paths.outputs={tmp_path}"])  # a folder: fine


@pytest.mark.skipif(torch.cuda.is_available(), reason="a GPU is there")
def test_trainer_gpu_without_a_gpu_is_one_line_with_the_fix():
    with pytest.raises(ConfigError, match="trainer.accelerator=gpu needs a CUDA GPU") as err:
        check_trainer_config(OmegaConf.create({"accelerator": "gpu"}))
    assert "trainer=cpu" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EROFS, errno.EACCES])
def test_a_full_or_read_only_disk_is_one_line_naming_the_file(capsys, code):
    def writes(cfg):
        raise OSError(code, os.strerror(code), "outputs/data/tiny.partial/train.h5")

    with pytest.raises(SystemExit) as exit_info:
        command("generate", writes).__wrapped__(OmegaConf.create())
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (
        f"error: {os.strerror(code)}: outputs/data/tiny.partial/train.h5; free space, or choose "
        "a writable paths.outputs (or PHYSGNN_OUTPUTS)\n"
    )


def test_other_os_errors_keep_their_traceback():
    def broken(cfg):
        raise OSError(errno.EIO, "Input/output error")

    with pytest.raises(OSError, match="Input/output"):
        command("generate", broken).__wrapped__(OmegaConf.create())

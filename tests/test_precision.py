"""Reduced-precision options train: bf16 autocast (``trainer.precision=bf16-mixed``) and TF32
matrix products (``matmul_precision=high``), each for one short epoch on the tiny preset."""

from __future__ import annotations

import math

import pytest
import torch
from trainkit import SHORT, config

from physgnn.errors import ConfigError
from physgnn.training.train import train


@pytest.fixture
def restored_precision():
    before = torch.get_float32_matmul_precision()
    yield
    torch.set_float32_matmul_precision(before)


@pytest.mark.parametrize("option", ["trainer.precision=bf16-mixed", "matmul_precision=high"])
def test_a_reduced_precision_option_trains(tiny_dataset, tmp_path, restored_precision, option):
    info = train(config(tiny_dataset, tmp_path, *SHORT, option))
    assert info["status"] == "finished" and info["global_step"] == 2
    assert math.isfinite(info["train_loss"]) and math.isfinite(info["val_loss"])
    if option.startswith("matmul"):
        assert torch.get_float32_matmul_precision() == "high"


def test_an_unknown_matmul_precision_is_one_line(tiny_dataset, tmp_path, restored_precision):
    with pytest.raises(ConfigError, match=r"matmul_precision must be one of .*'tf32'"):
        train(config(tiny_dataset, tmp_path, *SHORT, "matmul_precision=tf32"))

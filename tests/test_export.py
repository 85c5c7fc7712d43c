"""Shipped weights: an exported run loads like its source, run=pretrained names it, and weights
of another format or model are refused in one line."""

from __future__ import annotations

import json

import pytest
import torch
from torch.testing import assert_close

import physgnn.training.runs as runs_module
from physgnn.training.export import export_run, main
from physgnn.training.runs import RunError, load_run


@pytest.fixture
def exported(tiny_run, tmp_path):
    out = tmp_path / "shipped"
    export_run(tiny_run, out)
    return out


def test_an_exported_run_predicts_as_its_source_from_a_third_of_the_file(tiny_run, exported):
    (weights,) = (exported / "checkpoints").glob("best-step*.ckpt")
    (source,) = (tiny_run / "checkpoints").glob("best-*.ckpt")
    assert weights.stat().st_size < source.stat().st_size / 2
    original, _, _ = load_run(tiny_run)
    shipped, cfg, info = load_run(exported)
    for key, value in original.state_dict().items():
        assert_close(shipped.state_dict()[key], value, rtol=0, atol=0)
    assert info["status"] == "finished" and info["weights_format"] == 1
    assert info["checkpoint_step"] == torch.load(source, weights_only=True)["global_step"]
    assert cfg.model.network.M == 1 and info["exported_from"].endswith(f"({source.name})")


def test_pretrained_names_the_shipped_folder(exported, monkeypatch):
    monkeypatch.setattr(runs_module, "PRETRAINED_DIR", exported)
    simulator, _, info = load_run("pretrained")
    assert info["checkpoint"].startswith(str(exported))
    assert simulator.M == 1


def test_weights_of_another_format_are_refused_in_one_line(exported):
    info = json.loads((exported / "run.json").read_text())
    (exported / "run.json").write_text(json.dumps(info | {"weights_format": 99}))
    with pytest.raises(RunError, match="format 99; this physgnn reads format 1") as err:
        load_run(exported)
    assert "\n" not in str(err.value)


def test_weights_that_do_not_fit_the_model_are_refused_in_one_line(exported):
    config = exported / ".hydra" / "config.yaml"
    config.write_text(config.read_text().replace("hidden: 16", "hidden: 24"))
    with pytest.raises(RunError, match="does not fit the model") as err:
        load_run(exported)
    assert "\n" not in str(err.value)


def test_the_export_command_refuses_a_folder_it_did_not_write(tiny_run, tmp_path, capsys):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    assert main([str(tiny_run), str(mine)]) == 2
    assert "did not write" in capsys.readouterr().err
    assert (mine / "notes.txt").read_text() == "keep me"
    assert main([str(tmp_path / "nowhere")]) == 2


def test_pretrained_without_shipped_weights_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr(runs_module, "PRETRAINED_DIR", tmp_path / "none")
    with pytest.raises(RunError, match="ships no trained weights yet") as err:
        load_run("pretrained")
    assert "\n" not in str(err.value)


def test_the_shipped_weights_load_and_fall_as_gravity_says():
    """The committed physgnn/pretrained: its format is read, it fits the model this code builds,
    and a sphere released at 100 m falls for one second as the truth's integrator does (the
    gravity prior of the engine state: each frame moves dt·(v_t + s·g·dt), s = (k+1)/(2k) at k
    substeps, so after n frames it lies g·dt²·n·(s − ½) below z = h − ½gt²)."""
    from physgnn.evaluation.freefall import freefall_rows
    from physgnn.physics.energy import G

    simulator, cfg, info = load_run("pretrained")
    assert info["status"] == "finished" and info["global_step"] >= 22_500
    dt = cfg.data.scene.dt
    (row,) = freefall_rows("pretrained", simulator, [100.0], seconds=1.0, dt=dt)
    assert row["dvz_first"] == pytest.approx(-G * dt, rel=1e-4)
    below = G * dt**2 * round(1.0 / dt) * (float(simulator.gravity_share) - 0.5)
    assert row["z_true"] - row["z_pred"] == pytest.approx(below, rel=1e-3)

"""Rerun recordings (evaluation.rerun_log): read back when rerun-sdk is installed (the optional
``rerun`` extra), one clear line when it is not."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
from simdata import trajectory

from physgnn import CONF_DIR, metrics
from physgnn.evaluation.rerun_log import RerunMissing, log_rerun
from physgnn.simulate import main

SCENE = Path(CONF_DIR) / "scene" / "head_on.yaml"


def read_back(path) -> dict:
    """``{entity path: record batch}`` of a recording."""
    reader = pytest.importorskip("rerun.chunk").RrdReader(path)
    return {c.entity_path: c.to_record_batch() for c in reader.stream().to_chunks()}


def column(batch, suffix: str) -> list:
    [name] = [n for n in batch.schema.names if n.endswith(suffix)]
    return batch.column(name).to_pylist()


def test_recording_holds_truth_prediction_planes_and_energy(tmp_path):
    pytest.importorskip("rerun")
    truth = trajectory(n=3, frames=12)
    short = {k: getattr(truth, k)[:8] + 0.25 * (k == "pos") for k in ("pos", "quat", "vel")}
    pred = dataclasses.replace(truth, **short, angvel=truth.angvel[:8], diverged_at=8)
    chunks = read_back(log_rerun(tmp_path / "r.rrd", truth, pred))
    assert {"/truth/spheres", "/prediction/spheres", "/planes"} <= set(chunks)
    spheres = chunks["/truth/spheres"]
    assert spheres.num_rows == 12 and chunks["/prediction/spheres"].num_rows == 8
    assert column(spheres, "frame") == list(range(12))
    np.testing.assert_allclose(column(spheres, ":centers")[5], truth.pos[5], rtol=1e-6)
    moved = column(chunks["/prediction/spheres"], ":centers")[7]
    np.testing.assert_allclose(moved, truth.pos[7] + 0.25, rtol=1e-6)
    np.testing.assert_allclose(
        column(spheres, ":half_sizes")[0], np.repeat(truth.radius, 3, 0).reshape(3, 3), rtol=1e-6
    )
    assert len(column(chunks["/planes"], ":half_sizes")[0]) == len(truth.planes)
    energy = metrics.energy_series(truth.pos, truth.vel, truth.mass, truth.radius)
    np.testing.assert_allclose(
        np.ravel(column(chunks["/energy/truth"], ":scalars")), energy, rtol=1e-6
    )


def test_simulate_writes_the_recording(tmp_path, capsys):
    pytest.importorskip("rerun")
    rrd = tmp_path / "head_on.rrd"
    main([f"scene_file={SCENE}", f"out={tmp_path}", "frames=5", "video=false", f"rerun={rrd}"])
    assert f"rerun: {rrd}" in capsys.readouterr().out
    chunks = read_back(rrd)
    assert chunks["/truth/spheres"].num_rows == 5 and "/prediction/spheres" not in chunks


def test_simulate_without_the_extra_is_one_line_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun raises ImportError
    with pytest.raises(SystemExit) as e:
        main([f"scene_file={SCENE}", f"out={tmp_path}", "rerun=x.rrd"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1
    assert 'needs the optional rerun-sdk: pip install -e ".[rerun]"' in err
    assert not (tmp_path / "simulate.h5").exists()


def test_log_rerun_without_the_extra_raises(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rerun", None)
    with pytest.raises(RerunMissing):
        log_rerun(tmp_path / "r.rrd", trajectory(n=1, frames=2))

"""Command-line faults: a generate sweep whose jobs fail exits non-zero, a second training
into a run_dir in use leaves its files alone, and the console script's own lines."""

from __future__ import annotations

import sys

import pytest

from physgnn import generate as generate_command


def test_a_generate_sweep_whose_jobs_fail_exits_1_naming_them(tmp_path, monkeypatch, capsys):
    sweep = tmp_path / "sweep"
    args = ["-m", "data=tiny", f"paths.outputs={tmp_path}", "workers=1", "progress=false",
            "shard=range(0,2)", f"hydra.sweep.dir={sweep}"]  # fmt: skip
    monkeypatch.setattr(sys, "argv", ["physgnn.generate", *args])
    with pytest.raises(SystemExit) as exit_info:
        generate_command.main()
    assert exit_info.value.code == 1
    lines = capsys.readouterr().err.strip().splitlines()
    why = "needs num_shards=N, the number of shards in all"
    assert lines[-3:] == [
        f"  job 0: shard=0 {why}",
        f"  job 1: shard=1 {why}",
        f"error: 2 job(s) of the sweep failed (their errors above; logs in {sweep})",
    ]
    assert not (tmp_path / "data").exists()

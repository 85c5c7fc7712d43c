"""physgnn bounds OpenMP spin-waiting before torch starts its threads, unless the user chose."""

from __future__ import annotations

import os
import subprocess
import sys

SHOW = "import physgnn, os, torch; print(os.environ['GOMP_SPINCOUNT'])"


def spincount(env: dict) -> str:
    done = subprocess.run([sys.executable, "-c", SHOW], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_spin_count_default_and_override():
    env = {k: v for k, v in os.environ.items() if k != "GOMP_SPINCOUNT"}
    assert spincount(env) == "1000"
    assert spincount(env | {"GOMP_SPINCOUNT": "7"}) == "7"


def test_threads_are_the_cores_left_free(monkeypatch):
    import torch

    from physgnn import cli

    before = torch.get_num_threads()
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    try:
        for busy, threads in ((0.2, 4), (1.4, 3), (2.6, 1), (9.0, 1)):
            monkeypatch.setattr(cli, "busy_cores", lambda busy=busy: busy)
            assert cli.free_threads() == threads and torch.get_num_threads() == threads
        monkeypatch.setenv("OMP_NUM_THREADS", "2")
        assert cli.free_threads() is None and torch.get_num_threads() == 1  # untouched
    finally:
        torch.set_num_threads(before)


def test_busy_cores_from_two_readings_of_proc_stat(tmp_path, monkeypatch):
    """Busy = all ticks but idle and iowait; the share of the window, times the cores."""
    from physgnn import cli

    stat = tmp_path / "stat"
    readings = iter(
        [
            "cpu  100 0 50 800 50 0 0 0 0 0\ncpu0 1 2 3\n",  # busy 150 of 1000
            "cpu  400 0 100 1150 50 0 0 0 0 0\ncpu0 1 2 3\n",  # +350 busy of +700
        ]
    )
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    monkeypatch.setattr(cli.time, "sleep", lambda s: stat.write_text(next(readings)))
    stat.write_text(next(readings))
    assert cli.cpu_times(str(stat)) == (150, 1000)
    assert cli.busy_cores(0.0, str(stat)) == 4 * 350 / 700


def test_busy_cores_falls_back_to_the_load_average(tmp_path, monkeypatch):
    from physgnn import cli

    monkeypatch.setattr(os, "getloadavg", lambda: (1.5, 1.0, 0.5))
    assert cli.cpu_times(str(tmp_path / "missing")) is None
    assert cli.busy_cores(0.0, str(tmp_path / "missing")) == 1.5

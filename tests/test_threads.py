"""physgnn bounds OpenMP spin-waiting before torch starts its threads, unless the user chose."""

from __future__ import annotations

import ast
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
    monkeypatch.setattr(cli, "own_cpus", lambda: [0, 1, 2, 3])
    try:
        for busy, threads in ((0.2, 4), (1.4, 3), (2.6, 1), (9.0, 1)):
            monkeypatch.setattr(cli, "busy_cores", lambda cpus, busy=busy: busy)
            assert cli.free_threads() == threads and torch.get_num_threads() == threads
        monkeypatch.setenv("OMP_NUM_THREADS", "2")
        assert cli.free_threads() is None and torch.get_num_threads() == 1  # untouched
    finally:
        torch.set_num_threads(before)


def test_a_process_pinned_to_one_core_takes_one_thread():
    """A cluster job given one core (its CPU affinity) trains on one thread, whatever the
    machine has."""
    pin = (
        "import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
        "from physgnn import cli; print(cli.own_cpus(), cli.free_threads())"
    )
    env = {k: v for k, v in os.environ.items() if k != "OMP_NUM_THREADS"}
    done = subprocess.run([sys.executable, "-c", pin], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    cpus, threads = done.stdout.strip().rsplit(" ", 1)
    assert len(ast.literal_eval(cpus)) == 1 and threads == "1"


def test_busy_cores_counts_only_the_given_cores(tmp_path, monkeypatch):
    """Busy = all ticks but idle and iowait, over the window, of the given cores only."""
    from physgnn import cli

    stat = tmp_path / "stat"
    readings = iter(
        [
            # cpu0: busy 150 of 1000; cpu1 (not ours): busy 900 of 1000; cpu2: 0 of 1000
            "cpu  9 9 9 9 9\ncpu0 100 0 50 800 50 0 0 0 0 0\n"
            "cpu1 900 0 0 100 0 0 0 0\ncpu2 0 0 0 1000 0 0 0 0\nintr 1 2\n",
            # then cpu0 +350 busy of +700, cpu1 +700 busy of +700, cpu2 +0 of +700
            "cpu  9 9 9 9 9\ncpu0 400 0 100 1150 50 0 0 0 0 0\n"
            "cpu1 1600 0 0 100 0 0 0 0\ncpu2 0 0 0 1700 0 0 0 0\nintr 1 2\n",
        ]
    )
    monkeypatch.setattr(cli.time, "sleep", lambda s: stat.write_text(next(readings)))
    stat.write_text(next(readings))
    assert cli.cpu_times([0, 2], str(stat)) == (150, 2000)
    assert cli.busy_cores([0, 2], 0.0, str(stat)) == 2 * 350 / 1400


def test_busy_cores_falls_back_to_the_load_average(tmp_path, monkeypatch):
    from physgnn import cli

    monkeypatch.setattr(os, "getloadavg", lambda: (1.5, 1.0, 0.5))
    stat = tmp_path / "stat"
    assert cli.cpu_times([0], str(tmp_path / "missing")) is None
    stat.write_text("cpu  1 2 3 4 5\ncpu0 1 2 3 4 5 0 0 0\n")
    assert cli.cpu_times([0, 1], str(stat)) is None  # cpu1 is not there
    assert cli.busy_cores([0], 0.0, str(tmp_path / "missing")) == 1.5

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
        for load, threads in ((0.2, 4), (1.4, 3), (2.6, 1), (9.0, 1)):
            monkeypatch.setattr(os, "getloadavg", lambda load=load: (load, load, load))
            assert cli.free_threads() == threads and torch.get_num_threads() == threads
        monkeypatch.setenv("OMP_NUM_THREADS", "2")
        assert cli.free_threads() is None and torch.get_num_threads() == 1  # untouched
    finally:
        torch.set_num_threads(before)

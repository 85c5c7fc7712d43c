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

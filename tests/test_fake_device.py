"""The hot path on a fake accelerator (physgnn/benchmark/fake_device.py), in a process of its
own: no device mismatch, no host-to-device copy, and no read-back beyond the budgets."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from gpukit import ROLLOUT_FRAME_SYNCS, TRAIN_STEP_SYNCS

# A host-to-device copy in each network call, as the material features once had.
REGRESSION = """
import sys
from pathlib import Path
import physgnn.models.contact_inputs as ci
from physgnn.benchmark import fake_device
def material_features(state):
    params = state.material_params
    return params * params.new_tensor(ci.MATERIAL_SCALE)
ci.material_features = material_features
try:
    fake_device.rollout_frame(Path(sys.argv[1]))
except Exception as err:
    print("caught:", type(err).__name__)
"""


def run(args: list[str]) -> subprocess.CompletedProcess:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, env=env)


def test_a_training_step_and_a_rollout_frame_run_on_a_fake_accelerator(tiny_dataset):
    done = run(["-m", "physgnn.benchmark.fake_device", str(tiny_dataset)])
    assert done.returncode == 0, done.stderr[-3000:]
    result = json.loads(done.stdout.strip().splitlines()[-1])
    step, frame = result["train_step"], result["rollout_frame"]
    assert 0 < step["reads"] <= TRAIN_STEP_SYNCS and 0 < frame["reads"] <= ROLLOUT_FRAME_SYNCS
    fixed = result["train_step_fixed_capacity"], result["rollout_frame_fixed_capacity"]
    assert fixed[0]["reads"] == 0 and fixed[1]["reads"] == 1  # the divergence test only
    for counts in (step, frame, *fixed):
        assert counts["copies"] == 0 and counts["other_syncs"] == 0, result


def test_a_host_to_device_copy_in_the_hot_path_is_caught(tiny_dataset):
    done = run(["-c", REGRESSION, str(tiny_dataset)])
    assert "caught: NotImplementedError" in done.stdout, done.stderr[-3000:]  # no allocation

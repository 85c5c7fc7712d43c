"""The distributed path, run for real on CPU (README "Sweeps, clusters and several GPUs"): a
2-job sweep with the joblib launcher and with submitit's local executor (the executor of the
SLURM launcher, minus SLURM), a pre-empted submitit job that is requeued and resumes by itself,
and 2-process DDP (gloo) whose losses and weights match one process on the same global batch.
Those start Python processes, so they are slow tests; how the pairs are shared out is not."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from conftest import compose_generate
from test_train import SHORT, config, outputs_of

from physgnn.data.pairs import EpochSampler
from physgnn.groundtruth.generate import generate
from physgnn.training.runs import read_run_json
from physgnn.training.train import train

ROOT = Path(__file__).resolve().parents[1]


def sweep(outputs: Path, name: str, *args: str, background: bool = False):
    """``python -m physgnn.train -m model.network.M=1,2`` of two tiny jobs (experiment ``name``)."""
    cmd = [sys.executable, "-m", "physgnn.train", "-m", "model.network.M=1,2", "data=tiny",
           f"paths.outputs={outputs}", f"experiment_name={name}", *SHORT[1:], *args]  # fmt: skip
    if background:
        return subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                text=True)  # fmt: skip
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)


def jobs_of(outputs: Path, name: str) -> list[dict]:
    (summary,) = (outputs / "multirun" / name).glob("*/sweep.json")
    return json.loads(summary.read_text())["jobs"]


@pytest.mark.slow
def test_joblib_sweep_runs_two_jobs_in_worker_processes(tiny_dataset):
    outputs = outputs_of(tiny_dataset)
    done = sweep(outputs, "joblib", "hydra/launcher=local", "hydra.launcher.n_jobs=2")
    assert done.returncode == 0, done.stderr[-3000:]
    jobs = jobs_of(outputs, "joblib")
    assert [j["status"] for j in jobs] == ["finished", "finished"]
    assert [j["overrides"][0] for j in jobs] == ["model.network.M=1", "model.network.M=2"]
    pids = {read_run_json(j["run_dir"])["pid"] for j in jobs}
    assert len(pids) == 2 and os.getpid() not in pids


@pytest.mark.slow
def test_submitit_local_sweep_requeues_a_preempted_job_which_resumes(tiny_dataset):
    outputs = outputs_of(tiny_dataset)
    proc = sweep(outputs, "submitit", "hydra/launcher=submitit_local", "trainer.max_epochs=2",
                 "datamodule.pairs_per_epoch=40", background=True)  # fmt: skip
    first = next(iter(wait_for_glob(outputs / "multirun" / "submitit", "*/0_*/run.json", proc)))
    pid = read_run_json(first.parent)["pid"]
    os.kill(pid, signal.SIGUSR2)  # what SLURM sends signal_delay_s before pre-empting
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err[-3000:]
    jobs = jobs_of(outputs, "submitit")
    assert [j["status"] for j in jobs] == ["finished", "finished"]
    info = [read_run_json(j["run_dir"]) for j in jobs]
    last = str(Path(jobs[0]["run_dir"]) / "checkpoints" / "last.ckpt")
    assert info[0]["sessions"] == 2 and info[0]["resumed_from"] == last  # same folder
    assert info[1]["sessions"] == 1 and info[1]["resumed_from"] is None
    assert [i["global_step"] for i in info] == [20, 20]  # 2 epochs of 10 steps, whole run
    assert [i["pairs_seen"] for i in info] == [80, 80]
    logs = "".join(p.read_text() for p in (first.parents[1] / ".submitit").rglob("*_log.*"))
    assert "Requeued job" in logs and "SIGUSR2 received: stopping after this batch" in logs


def wait_for_glob(root: Path, pattern: str, proc, timeout: float = 300) -> list[Path]:
    end = time.monotonic() + timeout
    while not (found := sorted(root.glob(pattern))):
        assert proc.poll() is None, proc.communicate()[1][-3000:]
        assert time.monotonic() < end, f"no {pattern} under {root}"
        time.sleep(0.05)
    return found


@pytest.fixture(scope="module")
def three_sphere_dataset(tmp_path_factory) -> Path:
    """Every scene with exactly 3 spheres: per-process loss means then average to the
    global one, as DDP averages gradients."""
    outputs = tmp_path_factory.mktemp("outputs")
    cfg = compose_generate(["data=tiny", f"paths.outputs={outputs}", "workers=1",
                            "progress=false", "data.scene.n_min=3", "data.scene.n_max=3",
                            "data.splits.train=4"])  # fmt: skip
    return generate(cfg)


@pytest.mark.slow
def test_two_ddp_processes_match_one_on_the_same_global_batch(three_sphere_dataset, tmp_path):
    # No random draws (noise, contact noise, push-forward) and no gravity prior: its loss is a
    # mean over the spheres in reach of a contact, and two processes average two such means,
    # which equals one process's mean only when both count as many spheres.
    common = ["model.network.M=1", "model.network.hidden=16", "trainer.max_epochs=2",
              "trainer.max_time=null", "trainer.enable_progress_bar=false",
              "trainer.enable_model_summary=false", "datamodule.pairs_per_epoch=32",
              "datamodule.val_pairs=8", "lit.noise_std=0",
              "lit.contact_noise_depth=0", "model.gravity_prior=false",
              "lit.pushforward_steps=0", f"data.dir={three_sphere_dataset}"]  # fmt: skip
    one = train(config(three_sphere_dataset, tmp_path / "one", *common, "datamodule.batch_size=8"))
    two_dir = tmp_path / "two"
    cmd = [sys.executable, "-m", "physgnn.train", "trainer=ddp_cpu", "trainer.devices=2",
           "data=tiny", f"hydra.run.dir={two_dir}", *common, "datamodule.batch_size=4"]  # fmt: skip
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    two = read_run_json(two_dir)
    assert two["status"] == one["status"] == "finished"
    assert two["global_step"] == one["global_step"] == 8  # 2 epochs of 4 steps of 8 pairs
    assert two["pairs_seen"] == one["pairs_seen"] == 64  # summed over the 2 processes
    for key in ("train_loss", "val_loss"):
        assert two[key] == pytest.approx(one[key], rel=1e-5), key
    w1 = torch.load(one["checkpoints"]["last"], weights_only=True)["state_dict"]
    w2 = torch.load(two["checkpoints"]["last"], weights_only=True)["state_dict"]
    for key, value in w1.items():
        torch.testing.assert_close(w2[key], value, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("num_samples", [12, 13])
def test_ddp_processes_share_out_one_draw_in_order(num_samples):
    whole = EpochSampler(50, num_samples, seed=3)
    shares = [EpochSampler(50, num_samples, seed=3, rank=r, world_size=2) for r in (0, 1)]
    for epoch in (0, 4):
        for sampler in (whole, *shares):
            sampler.set_epoch(epoch)
        drawn, (a, b) = list(whole), [list(s) for s in shares]
        assert len(a) == len(b) == len(shares[0]) == 6  # cut to a multiple of 2: equal steps
        assert a == drawn[0:12:2] and b == drawn[1:12:2]
        # batches of 2 per process together are the batches of 4 of one process
        assert sorted(a[:2] + b[:2]) == sorted(drawn[:4])

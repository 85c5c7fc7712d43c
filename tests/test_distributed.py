"""The distributed path, run for real on CPU (docs/CLUSTERS.md): a tiny 2-process DDP run
(gloo) with test hooks (tests/ddp_hooks.py) that shows each process's own noise, the shared
push-forward length, one rollout score and checkpoint, and a NaN in one process stopping both;
the strategy several devices get; and, slow: a 2-job sweep with the joblib launcher and with
submitit's local executor (the executor of the SLURM launcher, minus SLURM), a pre-empted
submitit job that is requeued and resumes by itself, and 2-process DDP whose losses and
weights match one process on the same global batch."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
from conftest import compose_generate
from lightning.pytorch.strategies import DDPStrategy, SingleDeviceStrategy
from omegaconf import OmegaConf
from trainkit import SHORT, config, outputs_of

from physgnn.data.pairs import EpochSampler
from physgnn.groundtruth.generate import generate
from physgnn.training.build import build_trainer, several_processes, strategy_of
from physgnn.training.callbacks import RolloutCallback
from physgnn.training.noise import RANK_STRIDE
from physgnn.training.runs import load_run, read_run_json
from physgnn.training.train import train

ROOT = Path(__file__).resolve().parents[1]


def sweep(outputs: Path, name: str, *args: str, background: bool = False):
    """``python -m physgnn.train -m model.network.M=1,2`` of two tiny jobs (experiment ``name``)."""
    cmd = [
        sys.executable,
        "-m",
        "physgnn.train",
        "-m",
        "model.network.M=1,2",
        "data=tiny",
        f"paths.outputs={outputs}",
        f"experiment_name={name}",
        *SHORT[1:],
        *args,
    ]
    if background:
        return subprocess.Popen(
            cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
        )
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
    proc = sweep(
        outputs,
        "submitit",
        "hydra/launcher=submitit_local",
        "trainer.max_epochs=2",
        "datamodule.pairs_per_epoch=40",
        background=True,
    )
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
    global one, as DDP averages gradients. Two validation trajectories: one for each of two
    processes' rollouts."""
    outputs = tmp_path_factory.mktemp("outputs")
    cfg = compose_generate(
        [
            "data=tiny",
            f"paths.outputs={outputs}",
            "workers=1",
            "progress=false",
            "data.scene.n_min=3",
            "data.scene.n_max=3",
            "data.fit_scene.rest_fraction=0",  # rest scenes have their own sizes
            "data.splits.train=4",
            "data.splits.val=2",
        ]
    )
    return generate(cfg)


# A tiny 2-process run: 3 epochs of 2 steps of 2 × 4 pairs, hidden size 8, the default noise
# and contact noise, push-forward from the first step, a validation rollout every epoch; the
# loss of process 1 is NaN at step 5, epoch 2's last batch.
TINY_DDP = [
    "trainer=ddp_cpu",
    "trainer.devices=2",
    "data=tiny",
    "seed=5",
    "model.network.M=1",
    "model.network.hidden=8",
    "trainer.max_epochs=3",
    "trainer.max_time=null",
    "trainer.enable_progress_bar=false",
    "trainer.enable_model_summary=false",
    "datamodule.batch_size=4",
    "datamodule.pairs_per_epoch=16",
    "datamodule.val_pairs=8",
    "lit.pushforward.after=0",
    "callbacks.rollout.every_n_epochs=1",
]
HANG_S = 120  # a run still going after this long hangs


@pytest.fixture(scope="module")
def ddp_run(three_sphere_dataset, tmp_path_factory) -> dict:
    """``tests/ddp_hooks.py`` (physgnn.train with a probe and the NaN) on 2 gloo processes:
    exit code, stderr, run folder and what each process probed. Still running after
    ``HANG_S`` (a hang), both processes are killed and the tests fail."""
    run_dir, probe = tmp_path_factory.mktemp("ddp") / "run", tmp_path_factory.mktemp("probe")
    cmd = [
        sys.executable,
        str(ROOT / "tests" / "ddp_hooks.py"),
        *TINY_DDP,
        f"data.dir={three_sphere_dataset}",
        f"hydra.run.dir={run_dir}",
    ]
    env = os.environ | {"PHYSGNN_PROBE": str(probe), "PHYSGNN_NAN_AT": "1:5"}
    proc = subprocess.Popen(
        cmd,
        cwd=ROOT,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        _, err = proc.communicate(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the launcher and the process it started
        _, err = proc.communicate()
        pytest.fail(f"2 DDP processes still running after {HANG_S} s (a hang): {err[-2000:]}")
    probes = [json.loads((probe / f"rank{r}.json").read_text()) for r in (0, 1)]
    return {"code": proc.returncode, "err": err, "run_dir": run_dir, "probes": probes}


def test_a_nan_in_one_ddp_process_stops_both_with_the_one_line_error(ddp_run):
    # step 5 is an epoch's last batch, where finiteness is read: process 0's own losses are
    # all finite there, and without the shared read it would go on and wait for process 1
    line = (
        "error: non-finite training loss (nan) at epoch 2, step 5 in DDP process 1 of 2: "
        "the model exploded, training stopped"
    )
    assert ddp_run["code"] == 1, ddp_run["err"][-3000:]
    assert ddp_run["err"].count(line) == 2  # one line from each process
    assert read_run_json(ddp_run["run_dir"])["status"] == "diverged"


def test_ddp_processes_draw_their_own_noise_and_the_same_unroll(ddp_run):
    zero, one = (p["steps"] for p in ddp_run["probes"])
    # noise of (seed, process, step): process 0 draws what one process draws (seed 5)
    assert [s[:2] for s in zero] == [[k, 5 * 1_000_003 + k] for k in range(6)]
    assert [s[1] for s in one] == [s[1] + RANK_STRIDE for s in zero]
    # the push-forward length (it shapes the graph) is the same in both, and not always 0
    assert [s[2] for s in one] == [s[2] for s in zero] and any(s[2] for s in zero)


def test_ddp_processes_log_one_rollout_score_and_choose_one_checkpoint(
    ddp_run, three_sphere_dataset
):
    zero, one = ddp_run["probes"]
    # each process rolled out one validation trajectory; both logged the score of the two
    assert zero["rolled"] == one["rolled"] == [1, 1]
    assert len(zero["scores"]) == 2 and zero["scores"] == one["scores"]
    assert zero["best"] == one["best"] and zero["best_score"] == one["best_score"]
    # the score one process gets from that checkpoint's weights on both trajectories
    simulator, _, info = load_run(ddp_run["run_dir"])
    assert info["checkpoint"] == zero["best"]
    both = RolloutCallback(n_val_trajectories=2, max_frames=None, horizon=10, ood=False)
    module = SimpleNamespace(simulator=simulator, log=lambda *a, **k: None)
    alone = both.log_rollouts(module, three_sphere_dataset)["val/rollout_score"]
    assert alone == pytest.approx(zero["best_score"], rel=1e-5) and alone < float("inf")


@pytest.mark.slow
def test_two_ddp_processes_match_one_on_the_same_global_batch(three_sphere_dataset, tmp_path):
    # No random draws (noise, contact noise, push-forward) and no gravity prior: its loss is a
    # mean over the spheres in reach of a contact, and two processes average two such means,
    # which equals one process's mean only when both count as many spheres.
    common = [
        "model.network.M=1",
        "model.network.hidden=16",
        "trainer.max_epochs=2",
        "trainer.max_time=null",
        "trainer.enable_progress_bar=false",
        "trainer.enable_model_summary=false",
        "datamodule.pairs_per_epoch=32",
        "datamodule.val_pairs=8",
        "lit.noise.std=0",
        "lit.noise.contact_depth=0",
        "model.contacts.gravity_prior=false",
        "lit.pushforward.steps=0",
        f"data.dir={three_sphere_dataset}",
    ]
    one = train(config(three_sphere_dataset, tmp_path / "one", *common, "datamodule.batch_size=8"))
    two_dir = tmp_path / "two"
    cmd = [
        sys.executable,
        "-m",
        "physgnn.train",
        "trainer=ddp_cpu",
        "trainer.devices=2",
        "data=tiny",
        f"hydra.run.dir={two_dir}",
        *common,
        "datamodule.batch_size=4",
    ]
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
    # Adam normalises each gradient, so a weight whose gradient is rounding-level (the first
    # biases of the antisymmetric pp messages and pair decoder cancel in h_ij − h_ji to first
    # order) may move by up to a step's size differently; every other weight agrees to 1e-6
    step = cfg_lr(one)
    apart = 0
    weights = {k: v for k, v in w1.items() if v.is_floating_point()}
    assert all(torch.equal(w2[k], v) for k, v in w1.items() if k not in weights)
    for key, value in weights.items():
        torch.testing.assert_close(
            w2[key], value, rtol=1e-5, atol=step, msg=lambda m, key=key: f"{key}: {m}"
        )
        apart += int(((w2[key] - value).abs() > 1e-6 + 1e-5 * value.abs()).sum())
    assert apart <= 0.01 * sum(v.numel() for v in weights.values()), apart


def cfg_lr(run: dict) -> float:
    """The learning rate of a finished run's composed config (one Adam step's size)."""
    cfg = OmegaConf.load(Path(run["run_dir"]) / ".hydra" / "config.yaml")
    return float(cfg.lit.optimizer.lr)


@pytest.mark.parametrize("accelerator", ["cpu", "gpu"])
def test_several_devices_get_ddp_that_finds_unused_parameters(accelerator, tiny_dataset, tmp_path):
    cfg = config(tiny_dataset, tmp_path, f"trainer={accelerator}", "trainer.devices=2")
    strategy = strategy_of(cfg.trainer)  # what the Trainer is built with (no GPU needed)
    assert isinstance(strategy, DDPStrategy)
    assert strategy._ddp_kwargs == {"find_unused_parameters": True}
    if accelerator == "cpu":  # the Trainer itself
        trainer = build_trainer(cfg)
        assert isinstance(trainer.strategy, DDPStrategy) and trainer.num_devices == 2
        assert trainer.strategy._ddp_kwargs == {"find_unused_parameters": True}
    one = build_trainer(config(tiny_dataset, tmp_path, "trainer=cpu"))
    assert isinstance(one.strategy, SingleDeviceStrategy)


@pytest.mark.parametrize(
    "devices,nodes,several",
    [
        (1, 1, False),
        ("1", 1, False),
        ([0], 1, False),
        ("0,", 1, False),
        (1, 2, True),
        (2, 1, True),
        (-1, 1, True),
        ("auto", 1, True),
        ("0,1", 1, True),
        ([0, 1], 1, True),
    ],
)
def test_what_counts_as_several_processes(devices, nodes, several):
    trainer = OmegaConf.create({"devices": devices, "num_nodes": nodes})
    assert several_processes(trainer) is several


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

"""Compiled regions (``lit.compile.enabled=true`` on counted graphs): the graph rules and the
step after the graph build each run as one region with dynamic shapes; results equal eager's to
float rounding; a training step dispatches at most 1 500 aten ops outside them.

The regions are compiled with ``aot_eager`` (dynamo and AOT autograd, no code generation): what
runs inside or outside a region does not depend on the backend, and it compiles in seconds.
The inductor backend is the slow test of tests/test_lit.py."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch
from gpukit import OPS_PER_TRAINING_STEP, training_batch
from hydra.utils import instantiate
from omegaconf import OmegaConf
from simdata import trajectory
from torch.testing import assert_close

from physgnn import CONF_DIR
from physgnn.benchmark.gpu_readiness import training_step_counts
from physgnn.benchmark.syncs import profiling_ops
from physgnn.cli import compose_config
from physgnn.models.capture import ShapeBoundCall, compile_simulator
from physgnn.rollout import rollout


def default_pair(stats):
    """The default model twice with the same random weights."""
    model = OmegaConf.load(Path(CONF_DIR) / "model/baseline.yaml")
    eager, other = (instantiate(model, stats=stats) for _ in range(2))
    other.load_state_dict(eager.state_dict())
    return eager, other


def compiled_pair(stats):
    """:func:`default_pair`, the second compiled (``aot_eager``)."""
    eager, compiled = default_pair(stats)
    compile_simulator(compiled, backend="aot_eager")
    assert isinstance(compiled.head, ShapeBoundCall)
    assert isinstance(compiled.graph_builder.rules, ShapeBoundCall)
    return eager, compiled


@pytest.mark.slow  # 30 s of dynamo's compiles of a rollout's shapes: make test-slow
def test_a_compiled_simulator_rolls_out_as_the_eager_one(tiny_train):
    trajectories, stats = tiny_train
    eager, compiled = (s.eval() for s in compiled_pair(stats))
    scenes = trajectories[:2] + [trajectory(6, seed=3)]  # contacts, and flight between walls
    out = [rollout(sim, scenes, n_frames=10) for sim in (eager, compiled)]
    for a, b in zip(*out, strict=True):
        assert_close(b.pos, a.pos, rtol=1e-5, atol=1e-5)
        assert_close(b.quat, a.quat, rtol=1e-5, atol=1e-5)


def test_compiled_regions_give_the_eager_losses_and_gradients(tiny_train):
    trajectories, stats = tiny_train
    recipe = compose_config("bench").gpu_readiness.lit  # the training recipe, the bench's deltas
    eager, compiled = default_pair(stats)
    lits = [instantiate(recipe, simulator=s) for s in (eager, compiled)]
    lits[1].compile_regions(backend="aot_eager")
    assert isinstance(lits[1].graph_losses, ShapeBoundCall)
    batch = training_batch(trajectories, eager.H)
    results = []
    for lit in lits:
        losses = lit.losses(batch)
        losses["loss"].backward()
        grads = [p.grad for p in lit.parameters()]
        results.append(({k: v.detach() for k, v in losses.items()}, grads))
    (losses_e, grads_e), (losses_c, grads_c) = results
    for key, value in losses_e.items():
        assert_close(losses_c[key], value, rtol=1e-5, atol=1e-6, msg=key)
    assert [g is None for g in grads_c] == [g is None for g in grads_e]
    for g_c, g_e in zip(grads_c, grads_e, strict=True):
        if g_e is not None:
            assert_close(g_c, g_e, rtol=1e-4, atol=1e-6)


@pytest.mark.slow
def test_a_compiled_training_step_dispatches_at_most_the_budget(tiny_train):
    """The default recipe through Lightning (noise, contact noise, push-forward up to 2, the
    loss, backward, clipping, Adam): eager it dispatches far more than the budget. Slow (its
    compile takes minutes on 2 busy cores); so is the same budget on the quick bench's compiled
    training step (tests/test_bench.py), the same model and recipe."""
    trajectories, stats = tiny_train
    cfg = compose_config("bench").gpu_readiness
    model = OmegaConf.merge(OmegaConf.load(Path(CONF_DIR) / "model/baseline.yaml"), cfg.model)
    c = OmegaConf.create({"steps": 4, "warmup_steps": 2, "batch_size": 16})
    compiled = training_step_counts(model, cfg.lit, trajectories, stats, c, compiled=True)
    eager = training_step_counts(model, cfg.lit, trajectories, stats, c)
    assert compiled["syncs"] is None and compiled["host_ms"] is None  # not counted there
    assert 0 < compiled["kernels"] <= OPS_PER_TRAINING_STEP < eager["kernels"]


def test_the_profiled_count_sees_eager_ops_and_not_a_compiled_regions():
    x = torch.randn(8, 8)

    def f(a):
        return (a @ a).relu().sum(1).exp()

    with profiling_ops() as eager:
        f(x)
    compiled = torch.compile(f, backend="aot_eager", dynamic=True)
    compiled(x)  # compiles
    with profiling_ops() as inside:
        compiled(x)
    assert eager.kernels == 4 and inside.kernels == 0

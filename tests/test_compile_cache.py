"""Compiled rollouts for simulate and eval: the step compiled with its code kept on disk, the
same results as eager to float rounding, and one compiled graph across the interaction's two
algebraic paths. The inductor backend's times (minutes cold, seconds warm) are measured in
docs/performance-log.md, not here: the fast tests compile with ``aot_eager``, which takes seconds,
and one slow test with inductor."""

from __future__ import annotations

import functools
import json
import os

import numpy as np
import pytest
import torch
import yaml
from torch.testing import assert_close
from truthkit import SCENE

import physgnn.evaluation.runs as R
import physgnn.evaluation.simulate as S
import physgnn.evaluation.simulate_learned as SL
from physgnn.cli import compose_config
from physgnn.data.dataset import read_split
from physgnn.groundtruth.scenefile import scene_from_dict
from physgnn.models.capture import compile_simulator, compiled_graphs, use_cache_dir
from physgnn.nn.interaction import InteractionBlock
from physgnn.rollout import rollout
from physgnn.simulate import main
from physgnn.training.runs import load_run


def test_the_cache_folder_is_made_and_named_for_inductor(tmp_path, monkeypatch):
    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", "elsewhere")
    path = use_cache_dir(tmp_path / "cache" / "compile")
    assert path.is_dir() and os.environ["TORCHINDUCTOR_CACHE_DIR"] == str(path)
    assert path.is_absolute()


@pytest.mark.slow  # ~40 s of tracing; the compiled rollout itself: test_compiled_regions.py
def test_simulate_compiled_rolls_out_as_eager_and_says_what_compiling_cost(
    tiny_run, tmp_path, monkeypatch
):
    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path / "before"))
    fast = functools.partial(compile_simulator, backend="aot_eager")
    monkeypatch.setattr(SL, "compile_simulator", fast)
    scene, out = tmp_path / "tiny.yaml", tmp_path / "out"
    scene.write_text(SCENE)
    args = [f"scene_file={scene}", f"run={tiny_run}", f"out={out}", "video=false", "frames=8"]
    main([*args, "compile=true", f"paths.compile_cache={tmp_path / 'cache'}"])
    result = json.loads((out / "metrics.json").read_text())
    assert result["compile_s"] > 0
    assert os.environ["TORCHINDUCTOR_CACHE_DIR"] == str((tmp_path / "cache").resolve())
    groups = {t.attrs["group"]: t for t in read_split(out / "simulate.h5")}
    eager = rollout(load_run(tiny_run)[0].eval(), [groups["truth"]])[0]
    np.testing.assert_allclose(groups["prediction"].pos, eager.pos, rtol=0, atol=1e-5)


def test_one_compiled_graph_serves_fewer_and_more_nodes_than_messages():
    torch.manual_seed(0)
    block = InteractionBlock(8, third_law=True, concat_trick="auto")
    compiled = torch.compile(block, backend="aot_eager", dynamic=True)

    def graph(n, pairs):
        i = torch.arange(pairs) % n
        j = (i + 1) % n
        index = torch.stack([torch.cat([i, j]), torch.cat([j, i])])
        return torch.randn(n, 8), index, torch.randn(2 * pairs, 8)

    torch._dynamo.reset()
    before = compiled_graphs()
    for n, pairs in [(5, 6), (9, 3), (12, 20), (40, 7)]:  # N < E, then N > E, ...
        args = graph(n, pairs)
        assert_close(compiled(*args)[0], block(*args)[0], rtol=1e-5, atol=1e-5)
    assert compiled_graphs() - before == 1


def test_eval_compiles_every_learned_run_when_asked(tiny_run, tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(
        R, "compile_simulator", lambda sim, cache_dir: calls.append((sim, cache_dir))
    )
    cfg = compose_config("eval", [f"runs={tiny_run}", f"paths.outputs={tmp_path}", "compile=true"])
    infos, skipped = R.load_runs(cfg, tmp_path)
    assert skipped == [] and [sim for sim, _ in calls] == [info.simulator for info in infos]
    assert len(calls) == 1 and calls[0][1] == f"{tmp_path}/cache/compile"
    calls.clear()
    R.load_runs(compose_config("eval", [f"runs={tiny_run}", f"paths.outputs={tmp_path}"]), tmp_path)
    assert calls == []  # eager by default


@pytest.mark.slow
def test_inductor_keeps_its_code_in_the_cache_and_steps_as_eager(tiny_run, tmp_path, monkeypatch):
    monkeypatch.setenv("TORCHINDUCTOR_CACHE_DIR", str(tmp_path / "before"))
    simulator = load_run(tiny_run)[0].eval()
    truth = tiny_truth()
    eager = rollout(simulator, [truth.truncated(simulator.H + 2)])[0]  # one step
    compile_simulator(simulator, cache_dir=tmp_path / "cache")
    compiled = rollout(simulator, [truth.truncated(simulator.H + 2)])[0]
    assert_close(compiled.pos, eager.pos, rtol=0, atol=1e-5)
    assert_close(compiled.vel, eager.vel, rtol=0, atol=1e-5)
    assert any((tmp_path / "cache").rglob("*.py"))  # inductor's generated code, on disk


def tiny_truth():
    """The ground truth of the tiny scene file (pybullet)."""
    return S.simulate_with_progress(scene_from_dict(yaml.safe_load(SCENE)))

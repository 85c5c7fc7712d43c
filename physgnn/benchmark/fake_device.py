"""A default training step and a rollout frame on an accelerator this machine does not have.

Without a GPU, the hot path is run where every tensor claims to live on an accelerator: torch's
``FakeTensorMode`` (shapes and devices, no data) on a Python backend registered for the
``PrivateUse1`` key and named ``fakegpu`` (a fake tensor on ``cuda`` cannot go through
indexing or autograd in a CPU build of torch: their device guard needs CUDA). On it, as on a
GPU:

- a tensor left on the CPU that meets a device tensor fails (a device mismatch), 0-dim host
  scalars excepted;
- a tensor made on the device from host data fails (nothing can be allocated there), and a
  copy from the host is counted (:class:`~physgnn.benchmark.syncs.DispatchCounter`);
- a value read back fails, except those the step is known to read: the graph's edge counts,
  the finiteness flag and a rollout's divergence flag. They cannot be computed without data,
  so they are recorded from the same step run on the CPU, replayed, and counted.

Checked: a training step of the default recipe (input noise, contact noise, the longest
push-forward, the loss and its contact penalty, backward), and a rollout frame. Registering
the backend changes the process for good: run it in a process of its own,
``python -m physgnn.benchmark.fake_device DATA_DIR`` (a dataset folder), which prints a JSON
line ``{"train_step": {"reads", "copies"}, "rollout_frame": {...}}`` and exits non-zero on a
device mismatch or an unexpected read-back.
"""

from __future__ import annotations

import json
import sys
from contextlib import contextmanager
from pathlib import Path

import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf

from physgnn import CONF_DIR
from physgnn.benchmark.syncs import DispatchCounter
from physgnn.data.dataset import read_split
from physgnn.data.pairs import PairDataset
from physgnn.data.state import TrajectoryFrames
from physgnn.rollout.batch import SceneBatch, one_step, start_state

NAME = "fakegpu"
_READS = ("tolist", "__bool__", "item")


@contextmanager
def replayed_reads(record: list | None):
    """Within it, ``Tensor.tolist``, ``bool(tensor)`` and ``item`` return the values of
    ``record`` in order; ``record=None`` records them into the list yielded instead."""
    from torch._subclasses.fake_tensor import FakeTensor

    seen: list = []
    originals = {(torch.Tensor, name): getattr(torch.Tensor, name) for name in _READS}
    originals |= {
        (FakeTensor, n): FakeTensor.__dict__[n] for n in _READS if n in FakeTensor.__dict__
    }

    def patched(cls, name):
        def method(self, *args, **kwargs):
            if record is None:
                value = originals[cls, name](self, *args, **kwargs)
            else:
                want, value = record[len(seen)]
                assert want == name, f"read {name} where the CPU step read {want}"
            seen.append((name, value))
            return value

        return method

    for cls, name in originals:
        setattr(cls, name, patched(cls, name))
    try:
        yield seen
    finally:
        for (cls, name), method in originals.items():
            setattr(cls, name, method)


def register() -> torch.device:
    """The fake accelerator's device (module doc), registered once per process."""
    from torch.utils.backend_registration import _setup_privateuseone_for_python_backend

    if torch._C._get_privateuse1_backend_name() != NAME:
        _setup_privateuseone_for_python_backend(NAME)
    return torch.device(NAME, 0)


def _models(data: Path, hidden: int, fixed_capacity: bool = False):
    """``(simulator, lit)``: the default model (hidden size ``hidden``, graphs of fixed
    capacity if asked) and the default recipe with its longest push-forward from the first step
    and contact noise on every batch."""
    stats = json.loads((data / "stats.json").read_text())
    conf = Path(CONF_DIR)
    model = OmegaConf.load(conf / "model" / "baseline.yaml")
    model.pop("defaults", None)
    model.network.hidden, model.graph.fixed_capacity = hidden, fixed_capacity
    lit_cfg = OmegaConf.load(conf / "lit" / "default.yaml")
    lit_cfg.seed, lit_cfg.pushforward.after, lit_cfg.noise.contact_prob = 0, 0, 1.0
    torch.manual_seed(0)
    simulator = instantiate(model, stats=stats)
    lit = instantiate(lit_cfg, simulator=simulator)
    lit._unroll_length = lambda: lit.pushforward.steps  # the longest push-forward
    lit._noise_generator = lambda: None  # a generator of the fake device cannot be made
    return simulator, lit


def _moved(module, batch, convert):
    """``module``'s parameters and buffers and a copy of ``batch`` made by ``convert``."""
    module._apply(convert)
    moved = batch.clone().apply(convert)
    moved.host_sizes = batch.host_sizes
    return moved


def training_step(
    data: Path, hidden: int = 8, batch_size: int = 12, fixed_capacity: bool = False
) -> dict:
    """``{"reads", "copies"}`` of a training step and its backward on the fake device."""
    from torch._subclasses.fake_tensor import FakeTensor, FakeTensorMode

    device = register()
    _, lit = _models(data, hidden, fixed_capacity)
    pairs = PairDataset(read_split(data / "train.h5"), lit.simulator.H, future=2)
    batch = pairs.batch(torch.arange(min(batch_size, len(pairs))))
    with torch.no_grad(), replayed_reads(None) as reads:
        lit.training_step(batch, 0)
    _, lit = _models(data, hidden, fixed_capacity)  # a fresh one: the step keeps running sums
    mode = FakeTensorMode(allow_non_fake_inputs=False)
    fake = _moved(lit, batch, lambda t: FakeTensor(mode, t.to("meta"), device))
    with mode, replayed_reads(reads), DispatchCounter() as counter:
        loss = lit.training_step(fake, 0)
        loss.backward()
    grads = [p.grad for p in lit.parameters() if p.grad is not None]
    assert loss.device == device and grads and all(g.device == device for g in grads)
    return {"reads": len(reads), "copies": counter.copies, "other_syncs": counter.syncs}


def rollout_frame(
    data: Path, hidden: int = 8, scenes: int = 2, fixed_capacity: bool = False
) -> dict:
    """``{"reads", "copies"}`` of one rollout frame of ``scenes`` test scenes batched."""
    from torch._subclasses.fake_tensor import FakeTensor, FakeTensorMode

    device = register()
    simulator, _ = _models(data, hidden, fixed_capacity)
    simulator.eval()
    frames = [TrajectoryFrames(t) for t in read_split(data / "test.h5")[:scenes]]
    bound = torch.full((len(frames),), 100.0, dtype=torch.float64)  # m/s: none diverges
    state = SceneBatch([start_state(f, simulator.H) for f in frames], bound, "cpu", torch.float32)
    with torch.no_grad(), replayed_reads(None) as reads:
        one_step(simulator, state, 1e3, None, None)
    mode = FakeTensorMode(allow_non_fake_inputs=False)

    def convert(t: torch.Tensor) -> FakeTensor:
        return FakeTensor(mode, t.to("meta"), device)

    state.batch = _moved(simulator, state.batch, convert)
    for key in ("pos", "quat", "vel", "angvel"):
        setattr(state, key, state.batch[key])
    state.node_batch, state.dt, state.bound = (
        state.batch.batch,
        convert(state.dt),
        convert(state.bound),
    )
    if isinstance(state.rotate, torch.Tensor):
        state.rotate = convert(state.rotate)
    with mode, torch.no_grad(), replayed_reads(reads), DispatchCounter() as counter:
        one_step(simulator, state, 1e3, None, None)
    assert state.pos.device == device
    return {"reads": len(reads), "copies": counter.copies, "other_syncs": counter.syncs}


def main(argv: list[str] | None = None) -> None:
    data = Path((argv if argv is not None else sys.argv[1:])[0])
    result = {}
    for suffix, fixed in (("", False), ("_fixed_capacity", True)):
        result[f"train_step{suffix}"] = training_step(data, fixed_capacity=fixed)
        result[f"rollout_frame{suffix}"] = rollout_frame(data, fixed_capacity=fixed)
    print(json.dumps(result))


if __name__ == "__main__":
    main()

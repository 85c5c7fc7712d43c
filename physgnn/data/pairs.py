"""One-step state pairs ``(X_t, v_{t+1}, ω_{t+1})`` of trajectories, the seeded sampler that
draws them and the loader that batches them (plain torch: the Lightning data module and the
bench use them).

A *pair* is a frame ``t`` of a trajectory with ``t ∈ [H, T − 2]``: the state at ``t`` with
``H + 1`` velocities of history, and the finite-difference velocities of frame ``t + 1`` as
targets (the values of :class:`physgnn.data.state.TrajectoryFrames`).

**No per-item Python.** When a split is loaded, the finite-difference velocities of every
trajectory are computed once and all frames are stacked into flat tables (one row per
sphere and frame); the static arrays (radius, mass, material, planes, dt, effects) likewise.
A batch of pairs is then a handful of index gathers into those tables, giving the batched
:class:`~physgnn.data.state.SceneState` that ``Batch.from_data_list`` of the pairs' states
would give (same fields, same values, same order), without building one object per pair.
"""

from __future__ import annotations

import functools
import math

import torch
from torch.utils.data import DataLoader, Dataset, Sampler
from torch_geometric.data import Batch

from physgnn.data.state import SceneState, TrajectoryFrames

_DYNAMIC = ("pos", "quat", "vel", "angvel")
_MEAN = ("mean_vel", "mean_angvel")  # the frame's mean motion, with the engine state
_SPHERE = ("radius", "mass", "material", "material_params")
_PLANE = ("planes", "plane_kind", "plane_materials")


class PairDataset(Dataset):
    """Every valid ``(trajectory, t)`` pair of a list of trajectories (``pairs [P, 2]``).

    ``future`` = K > 0 adds the K + 1 next frames to each item (push-forward targets) and
    keeps only the frames ``t ≤ T − K − 2`` that have them. ``engine_state``: the state's
    velocities are the engine's end-of-frame ones, and the targets also hold the frame's mean
    motion (:class:`~physgnn.data.state.TrajectoryFrames`). ``dataset[k]`` is the batch of
    pair k alone; :meth:`batch` (and ``__getitems__``, which the torch DataLoader calls)
    assembles many at once.
    """

    def __init__(self, trajectories: list, H: int, future: int = 0, engine_state: bool = False):
        self.H, self.future, self.engine_state = int(H), int(future), bool(engine_state)
        frames = [TrajectoryFrames(traj, self.engine_state) for traj in trajectories]
        last = 1 + self.future
        pairs = [(i, t) for i, f in enumerate(frames) for t in range(self.H, f.n_frames - last)]
        self.pairs = torch.tensor(pairs, dtype=torch.long).reshape(-1, 2)
        self._stack(frames)
        # host copies: a batch's layout is read here, whatever device the tables are on
        self.device = torch.device("cpu")
        self.host = {"pairs": self.pairs, "n_spheres": self.n_spheres, "n_planes": self.n_planes}

    _ON_DEVICE = (
        "pairs",
        "n_spheres",
        "n_planes",
        "frame_start",
        "sphere_start",
        "plane_start",
        "dt",
        "effects",
    )

    def to(self, device) -> PairDataset:
        """Keep the tables on ``device`` (in place): a batch is then a few gathers there, with
        no copy from the host but its pair indices (the layout stays on the host)."""
        self.device = torch.device(device)
        for key in self._ON_DEVICE:
            setattr(self, key, getattr(self, key).to(self.device))
        self.tables = {k: v.to(self.device) for k, v in self.tables.items()}
        return self

    def _stack(self, frames: list[TrajectoryFrames]) -> None:
        """Flat tables: ``pos``, ``quat``, ``vel``, ``angvel`` ``[Σ T_i N_i, ·]`` (row of
        trajectory i, frame t, sphere n = ``frame_start[i] + t·N_i + n``), the per-sphere
        arrays ``[Σ N_i]``, the planes ``[Σ S_i, ·]``, and per trajectory ``n_spheres``,
        ``n_planes``, their first rows, ``dt [n_traj]`` and ``effects [n_traj, 5]``."""
        long = functools.partial(torch.tensor, dtype=torch.long)
        self.n_spheres = long([f.pos.shape[1] for f in frames])
        self.n_planes = long([f.static["planes"].shape[0] for f in frames])
        rows = long([f.pos.shape[0] * f.pos.shape[1] for f in frames])
        self.frame_start, self.sphere_start, self.plane_start = (
            torch.cumsum(c, 0) - c for c in (rows, self.n_spheres, self.n_planes)
        )
        dynamic = (*_DYNAMIC, *_MEAN) if self.engine_state else _DYNAMIC
        self.tables = {key: torch.cat([_rows(getattr(f, key)) for f in frames]) for key in dynamic}
        for key in (*_SPHERE, *_PLANE):
            self.tables[key] = torch.cat([f.static[key] for f in frames])
        self.dt = torch.cat([f.static["dt"] for f in frames])
        self.effects = torch.cat([f.static["effects"] for f in frames])

    def __len__(self) -> int:
        return int(self.pairs.shape[0])

    def __getitem__(self, k: int) -> Batch:
        return self.batch(torch.tensor([k]))

    def __getitems__(self, ks: list[int]) -> Batch:
        return self.batch(torch.as_tensor(ks, dtype=torch.long))

    def batch(self, index: torch.Tensor) -> Batch:
        """The batched :class:`SceneState` of the pairs ``index [B]`` (on the host), in that
        order, on the tables' device (``num_graphs`` from ``ptr``; it keeps no per-pair slices
        for ``to_data_list``; ``host_sizes`` holds its layout as host ints)."""
        traj_host = self.host["pairs"][index, 0]
        sizes = (
            tuple(self.host["n_spheres"][traj_host].tolist()),
            tuple(self.host["n_planes"][traj_host].tolist()),
        )
        device = self.device
        traj, t = self.pairs[index.to(device, non_blocking=True)].unbind(1)
        node_graph, local, ptr = _segments(self.n_spheres[traj], sum(sizes[0]))
        n = self.n_spheres[traj][node_graph][:, None]  # [N, 1] spheres of the node's scene
        base = self.frame_start[traj][node_graph][:, None] + local[:, None]  # frame 0 rows
        frame = t[node_graph][:, None]
        now, back = base + frame * n, torch.arange(self.H + 1, device=device)
        history = base + (frame - back) * n  # [N, H+1] rows of t, t−1, …, t−H
        tab = self.tables
        fields = {"pos": tab["pos"][now[:, 0]], "quat": tab["quat"][now[:, 0]]}
        fields["vel"], fields["angvel"] = tab["vel"][history], tab["angvel"][history]
        sphere = self.sphere_start[traj][node_graph] + local
        fields |= {key: tab[key][sphere] for key in _SPHERE}
        plane_graph, plane_local, _ = _segments(self.n_planes[traj], sum(sizes[1]))
        plane = self.plane_start[traj][plane_graph] + plane_local
        fields |= {key: tab[key][plane] for key in _PLANE}
        fields |= {"plane_batch": plane_graph, "dt": self.dt[traj], "effects": self.effects[traj]}
        after = now[:, 0] + n[:, 0]  # frame t + 1
        fields["target_vel"], fields["target_angvel"] = tab["vel"][after], tab["angvel"][after]
        mean_angvel = tab["mean_angvel"] if self.engine_state else tab["angvel"]
        if self.engine_state:
            fields["target_mean_vel"] = tab["mean_vel"][after]
            fields["target_mean_angvel"] = mean_angvel[after]
        if self.future > 0:
            ahead = base + (frame + 1 + torch.arange(self.future + 1, device=device)) * n
            fields["future_pos"], fields["future_angvel"] = tab["pos"][ahead], mean_angvel[ahead]
            if self.engine_state:
                fields["future_vel"] = tab["vel"][ahead]
                fields["future_end_angvel"] = tab["angvel"][ahead]
        batch = Batch(_base_cls=SceneState, **fields, batch=node_graph, ptr=ptr)
        batch.host_sizes = sizes  # graph builds then read no size back
        return batch


def _rows(x: torch.Tensor) -> torch.Tensor:
    """``x [..., C]`` as ``[rows, C]``."""
    return x.reshape(-1, x.shape[-1])


def _segments(counts: torch.Tensor, total: int) -> tuple[torch.Tensor, ...]:
    """Rows of consecutive segments of ``counts [B]`` rows, ``total`` in all (a host int):
    ``(segment of each row [R], position within its segment [R], ptr [B + 1])``."""
    device = counts.device
    ptr = torch.cat([counts.new_zeros(1), torch.cumsum(counts, 0)])
    segment = torch.arange(counts.numel(), device=device)
    segment = torch.repeat_interleave(segment, counts, output_size=total)
    return segment, torch.arange(total, device=device) - ptr[segment], ptr


def _as_is(batch: Batch) -> Batch:
    """Collate of a batch that ``PairDataset.__getitems__`` already assembled."""
    return batch


def pair_loader(pairs: Dataset, batch_size: int, sampler=None, num_workers: int = 0):
    """A torch DataLoader of ``pairs`` (a :class:`PairDataset` or a ``Subset`` of one): each
    batch of ``batch_size`` sampled indices is assembled in one call (no collate)."""
    return DataLoader(
        pairs,
        batch_size=batch_size,
        sampler=sampler,
        shuffle=False,
        num_workers=num_workers,
        persistent_workers=num_workers > 0,
        collate_fn=_as_is,
    )


class EpochSampler(Sampler):
    """``num_samples`` indices drawn uniformly with replacement from ``range(size)``, seeded by
    ``(seed, epoch)``: epoch k draws the same pairs whether training ran straight through or
    resumed from a checkpoint. Lightning calls ``set_epoch`` before each epoch; without it
    each iteration moves on to the next epoch.

    With ``world_size`` > 1 (DDP) process ``rank`` takes every ``world_size``-th index from
    the ``rank``-th (the draw cut to a multiple of ``world_size``): the processes' batches of a
    step together are the batch of one process with a ``world_size`` times larger batch.

    ``batches_done()`` (optional) is the number of batches this process has trained on so far,
    read when a pass starts: a run resumed from a mid-epoch checkpoint then leaves out the
    ``batch_size``-sized batches its epoch had already given, and goes on as a straight run
    would."""

    def __init__(
        self,
        size: int,
        num_samples: int,
        seed: int,
        rank: int = 0,
        world_size: int = 1,
        batch_size: int = 1,
        batches_done=None,
    ):
        self.size, self.num_samples, self.seed = int(size), int(num_samples), int(seed)
        self.rank, self.world_size = int(rank), int(world_size)
        self.batch_size, self.batches_done = int(batch_size), batches_done
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return self.num_samples // self.world_size

    def __iter__(self):
        generator = torch.Generator().manual_seed(self.seed * 1_000_003 + self.epoch)
        skip = self._resumed_batches() * self.batch_size
        self.epoch += 1
        drawn = torch.randint(self.size, (self.num_samples,), generator=generator)
        share = drawn[self.rank : len(self) * self.world_size : self.world_size]
        yield from share[skip:].tolist()

    def _resumed_batches(self) -> int:
        """Batches of the epoch starting now that were trained before (0 unless resumed)."""
        if self.batches_done is None:
            return 0
        per_epoch = math.ceil(len(self) / self.batch_size)
        return min(max(int(self.batches_done()) - self.epoch * per_epoch, 0), per_epoch)

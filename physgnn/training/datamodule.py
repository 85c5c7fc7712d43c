"""Lightning data: random one-step state pairs ``(X_t, v_{t+1}, ω_{t+1})`` from a dataset.

A *pair* is a frame ``t`` of a training trajectory with ``t ∈ [H, T − 2]``: the state at ``t``
with ``H + 1`` velocities of history, and the finite-difference velocities of frame ``t + 1``
as targets (:class:`physgnn.data.state.TrajectoryFrames`). An epoch is ``pairs_per_epoch`` pairs
drawn uniformly with replacement by a sampler seeded by (seed, epoch), shared out between DDP
processes; validation is a fixed subset of the validation split drawn with ``val_seed``, not
the run's seed, so that every seed of a study is validated, and its checkpoint chosen, on the
same pairs (each process validates all of it). Input noise is added by the Lightning module,
not here, so the data stream is the same with or without noise. Batches are assembled by index
gathers into the split's stacked tables (:class:`physgnn.data.pairs.PairDataset`).
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import lightning as L
import torch

from physgnn.data.dataset import (
    DATASET_MARKER,
    DatasetError,
    dataset_preset,
    generate_hint,
    read_split,
)
from physgnn.data.pairs import EpochSampler, PairDataset, pair_loader
from physgnn.data.stats import read_stats, split_substeps

# The files of a dataset that training reads
TRAINING_FILES = ("stats.json", "train.h5", "val.h5")


def dataset_file(data_dir: str | Path, preset: str, name: str) -> Path:
    """``<data_dir>/<name>``, refused in one line with the command that makes it if missing."""
    path = Path(data_dir) / name
    if not path.exists():
        raise DatasetError(
            f"dataset '{preset}' not found ({path} is missing): " + generate_hint(data_dir, preset)
        )
    return path


def check_preset(data_dir: str | Path, preset: str) -> None:
    """The dataset in ``data_dir`` is of the configured preset (its marker says which)."""
    found = dataset_preset(Path(data_dir))
    if found is not None and found != preset:
        raise DatasetError(
            f"data.dir {data_dir} holds the '{found}' dataset (its {DATASET_MARKER}), not "
            f"'{preset}' (data={preset}): train with data={found}, or set data.dir to a "
            f"'{preset}' dataset"
        )


def check_training_data(data_dir: str | Path, preset: str) -> None:
    """The files training reads are there, of ``preset`` (a sweep checks once before its
    jobs: :mod:`physgnn.training.sweep`)."""
    for name in TRAINING_FILES:
        dataset_file(data_dir, preset, name)
    check_preset(data_dir, preset)


def dataset_identity(data_dir: str | Path, preset: str) -> dict:
    """Which dataset a run trains on, beyond its path (run.json ``dataset``): ``preset``,
    ``dir`` and ``sha256``, a hash of stats.json's bytes and of the sizes of the files training
    reads (the splits are not read whole: gigabytes). Another dataset at the same path, or the
    same one regenerated with another seed, has another hash; a file missing, None."""
    digest, folder = hashlib.sha256(), Path(data_dir)
    try:
        digest.update((folder / "stats.json").read_bytes())
        for name in TRAINING_FILES:
            digest.update(f"{name}:{(folder / name).stat().st_size};".encode())
    except OSError:
        return {"preset": preset, "dir": str(data_dir), "sha256": None}
    return {"preset": preset, "dir": str(data_dir), "sha256": digest.hexdigest()}


class StatePairDataModule(L.LightningDataModule):
    """Reads ``<data_dir>/{train,val}.h5`` and ``stats.json`` (written by ``physgnn.generate``).

    ``preset`` only names the dataset in error messages. ``H`` must equal the model's history;
    ``pushforward_steps`` the Lightning module's (the training pairs carry that many more
    future frames; validation pairs are one-step). ``engine_state``, an attribute set from the
    model before :meth:`setup` (:func:`~physgnn.training.build.build`): the pairs' velocities
    are the engine's (``model.inputs.engine_state``).
    """

    def __init__(
        self,
        data_dir: str,
        preset: str = "small",
        H: int = 2,
        batch_size: int = 256,
        pairs_per_epoch: int = 6400,
        val_pairs: int = 512,
        num_workers: int = 0,
        seed: int = 0,
        pushforward_steps: int = 0,
        val_seed: int = 0,
    ):
        super().__init__()
        if batch_size < 1 or pairs_per_epoch < 1 or val_pairs < 1:
            raise ValueError("batch_size, pairs_per_epoch and val_pairs must be >= 1")
        self.data_dir = Path(data_dir)
        self.preset = preset
        self.H = int(H)
        self.batch_size = int(batch_size)
        self.pairs_per_epoch = int(pairs_per_epoch)
        self.val_pairs = int(val_pairs)
        self.num_workers = int(num_workers)
        self.seed = int(seed)
        self.val_seed = int(val_seed)
        if pushforward_steps < 0:
            raise ValueError(f"pushforward_steps must be >= 0 (got {pushforward_steps})")
        self.pushforward_steps = int(pushforward_steps)
        self.engine_state = False  # the model's state: build() sets it from the model
        self.train_set: PairDataset | None = None
        self.val_set: PairDataset | None = None

    def _path(self, name: str) -> Path:
        return dataset_file(self.data_dir, self.preset, name)

    def _check_preset(self) -> None:
        check_preset(self.data_dir, self.preset)

    def stats(self) -> dict:
        """The training split's normalisation statistics (``stats.json``), with the engine's
        substeps per frame read from ``train.h5`` where ``stats.json`` predates them."""
        self._path("stats.json")
        stats = read_stats(self.data_dir)
        if "substeps" not in stats:
            stats["substeps"] = split_substeps(self._path("train.h5"))
        return stats

    def setup(self, stage: str | None = None) -> None:
        if self.train_set is None:
            self._check_preset()
            self.train_set = self._load("train.h5", self.pushforward_steps)
            self.val_set = self._load("val.h5")

    def _load(self, name: str, future: int = 0) -> PairDataset:
        pairs = PairDataset(read_split(self._path(name)), self.H, future, self.engine_state)
        if len(pairs) == 0:
            raise DatasetError(
                f"{self.data_dir / name} has no trajectory longer than H + {future + 2} frames"
            )
        return pairs

    def effects_trained(self) -> torch.Tensor:
        """``[5]`` bool: effects present in at least one training scene."""
        self.setup()
        return self.train_set.effects.any(0)

    def train_dataloader(self) -> torch.utils.data.DataLoader:
        self.setup()
        # Under DDP each process draws its share itself (the trainer is built with
        # use_distributed_sampler=False: Lightning's sampler would reshuffle the step's pairs)
        rank, world = (
            (self.trainer.global_rank, self.trainer.world_size) if self.trainer else (0, 1)
        )
        sampler = EpochSampler(
            len(self.train_set),
            self.pairs_per_epoch,
            self.seed,
            rank,
            world,
            self.batch_size,
            self._batches_done,
        )
        return pair_loader(
            self._on_device(self.train_set), self.batch_size, sampler, self.num_workers
        )

    def _on_device(self, pairs: PairDataset) -> PairDataset:
        """``pairs`` with its tables on the training device when batches are made in this
        process (``num_workers`` 0): a batch is then gathered there, not copied from the host."""
        if self.trainer is not None and self.num_workers == 0:
            pairs.to(self.trainer.strategy.root_device)
        return pairs

    def _batches_done(self) -> int:
        """Batches this process has trained on so far (the trainer's step count; 0 without a
        trainer): a run resumed mid-epoch goes on with the pairs its epoch had not reached (so
        Lightning's warning of a loader that cannot resume does not apply)."""
        trainer = self.trainer
        if trainer is None:
            return 0
        return trainer.global_step * trainer.accumulate_grad_batches

    def val_dataloader(self) -> torch.utils.data.DataLoader:
        self.setup()
        generator = torch.Generator().manual_seed(self.val_seed + 1)
        n = min(self.val_pairs, len(self.val_set))
        index = torch.randperm(len(self.val_set), generator=generator)[:n].sort().values
        subset = torch.utils.data.Subset(self._on_device(self.val_set), index.tolist())
        return pair_loader(subset, self.batch_size, num_workers=self.num_workers)

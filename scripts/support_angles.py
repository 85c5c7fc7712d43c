"""Support angles of the spheres resting on spheres in a dataset split.

    python scripts/support_angles.py outputs/data/small/train.h5 [--speed 0.01] [--gap 0.001]

A sphere *rests on spheres* in a frame when it is off the ground (z − r > gap), slower than
``speed`` m/s, and touches (surface gap <= ``gap`` m) a sphere below it that is also slower than
``speed``; each such contact's support angle is its normal's angle from vertical. Prints the
contact-frames' and the distinct contacts' (trajectory, pair; their median over frames) count,
minimum, median, and count below 25°, and a histogram in 10° bins.
"""

from __future__ import annotations

import argparse

import numpy as np

from physgnn.data.dataset import read_split


def resting_angles(traj, speed: float, gap: float) -> tuple[np.ndarray, np.ndarray]:
    """``(angle [C], pair id [C])`` in degrees of every resting contact-frame of ``traj``."""
    n = traj.n_spheres
    i, j = np.nonzero(~np.eye(n, dtype=bool))
    r = traj.radius.astype(np.float64)
    angles, ids = [], []
    for pos, vel in zip(traj.pos.astype(np.float64), traj.vel, strict=True):
        slow = np.linalg.norm(vel, axis=1) < speed
        d = pos[i] - pos[j]
        dist = np.linalg.norm(d, axis=1)
        hit = (dist - r[i] - r[j] <= gap) & slow[i] & slow[j] & (d[:, 2] > 0)
        hit &= pos[i, 2] - r[i] > gap  # i rests on spheres, not on the ground
        angles.append(np.degrees(np.arccos(d[hit, 2] / dist[hit])))
        ids.append(i[hit] * n + j[hit])
    return np.concatenate(angles), np.concatenate(ids)


def summary(name: str, angles: np.ndarray) -> str:
    if angles.size == 0:
        return f"{name}: none"
    low = int(np.sum(angles < 25))
    median = np.median(angles)
    return f"{name}: {angles.size}, min {angles.min():.1f}°, median {median:.1f}°, below 25°: {low}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("split")
    parser.add_argument("--speed", type=float, default=0.01)
    parser.add_argument("--gap", type=float, default=1e-3)
    args = parser.parse_args()
    frames, distinct = [], []
    trajectories = read_split(args.split)
    for traj in trajectories:
        angles, ids = resting_angles(traj, args.speed, args.gap)
        frames.append(angles)
        for pair in np.unique(ids):
            distinct.append(np.median(angles[ids == pair]))
    frames, distinct = np.concatenate(frames), np.asarray(distinct)
    print(summary("contact-frames", frames))
    print(
        summary(
            f"distinct contacts (median over their frames; {len(trajectories)} trajectories)",
            distinct,
        )
    )
    counts, edges = np.histogram(distinct, bins=np.arange(0, 100, 10))
    print(
        "distinct contacts per 10° bin:",
        dict(zip(edges[:-1].astype(int).tolist(), counts.tolist(), strict=True)),
    )


if __name__ == "__main__":
    main()

"""Candidate edges from the scene layout, and mask compaction, with no host round trip.

A batch's layout (spheres and planes per scene) is known on the host when the batch is made;
from it every candidate of a small scene is written down without looking at the positions:

- :func:`scene_pairs`: every pair ``(i, j)``, ``i < j``, of spheres of the same scene,
  ``P = Σ_s n_s (n_s − 1) / 2`` of them, sorted lexicographically;
- :func:`scene_plane_pairs`: every ``(plane, sphere)`` of the same scene,
  ``Q = Σ_s S_s n_s``, sorted by plane then sphere.

Sizes come from host ints, so ``repeat_interleave`` gets its ``output_size`` and nothing is read
back; the per-scene counts on the device come from the scene of each sphere (a scatter), so
nothing is copied from the host either. The graph rule then makes a boolean mask, and
:func:`compact` keeps the masked candidates in order given their count: the one value a build
must read back.
"""

from __future__ import annotations

import torch


def scene_counts(scene: torch.Tensor, scenes: int) -> torch.Tensor:
    """``[scenes]`` long: spheres per scene, from ``scene [N]`` (long, the scene of each
    sphere) on its device: a scatter, no host copy."""
    counts = torch.zeros(scenes, dtype=torch.long, device=scene.device)
    return counts.index_add_(0, scene, torch.ones_like(scene))


def scene_pairs(
    spheres: tuple[int, ...], scene: torch.Tensor, counts: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(i [P], j [P])``: all same-scene pairs with ``i < j`` (module doc), for scenes of
    ``spheres[s]`` consecutive spheres; ``scene [N]`` (long) the scene of each sphere, ``counts``
    its :func:`scene_counts`."""
    device = scene.device
    n = sum(spheres)
    total = sum(c * (c - 1) // 2 for c in spheres)
    end = torch.cumsum(counts, 0)[scene]  # one past the last sphere of each sphere's scene
    node = torch.arange(n, device=device)
    partners = end - 1 - node  # spheres after i in its scene
    i = torch.repeat_interleave(node, partners, output_size=total)
    first = torch.cumsum(partners, 0) - partners
    j = i + 1 + torch.arange(total, device=device) - first[i]
    return i, j


def scene_plane_pairs(
    spheres: tuple[int, ...],
    planes: tuple[int, ...],
    plane_scene: torch.Tensor,
    counts: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(plane [Q], sphere [Q])``: every plane with every sphere of its scene (module doc);
    ``plane_scene [S]`` (long) is the scene of each plane, planes grouped by scene, and
    ``counts [B]`` the spheres per scene (:func:`scene_counts`)."""
    device = plane_scene.device
    total = sum(p * s for p, s in zip(planes, spheres, strict=True))
    per_plane = counts[plane_scene]
    plane = torch.repeat_interleave(
        torch.arange(plane_scene.shape[0], device=device), per_plane, output_size=total
    )
    first_candidate = torch.cumsum(per_plane, 0) - per_plane
    first_sphere = (torch.cumsum(counts, 0) - counts)[plane_scene]
    local = torch.arange(total, device=device) - first_candidate[plane]
    return plane, first_sphere[plane] + local


def compact(mask: torch.Tensor, count: int) -> torch.Tensor:
    """Positions of the ``count`` True entries of ``mask [P]``, in order, ``[count]`` long:
    ``nonzero`` with its size given, so nothing is read back."""
    slot = torch.cumsum(mask, 0) - 1
    slot = torch.where(mask, slot, count)  # the rest goes to a spare slot, then dropped
    out = torch.empty(count + 1, dtype=torch.long, device=mask.device)
    out.scatter_(0, slot, torch.arange(mask.shape[0], device=mask.device))
    return out[:count]

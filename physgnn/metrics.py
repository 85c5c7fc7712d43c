"""Physics and accuracy metrics of one trajectory (pure functions; numpy in, floats out).

Arrays are converted to float64. Every function refuses NaN/inf input and empty scenes with
one :class:`MetricError` line instead of returning a silent NaN. Conventions (SPEC, Metrics):

- penetration: an *intersection* is a (sphere pair | sphere–plane, frame) with a positive
  depth; its normalised depth is the depth divided by the diameter (pairs: the mean diameter
  ``r_i + r_j``). ``depth_*`` is the mean normalised depth of all intersections (0 when there
  is none); ``pct_*`` the percentage of spheres with at least one intersection whose
  normalised depth exceeds ``tol`` (default 0: any overlap counts, as in the report).
  The ground (kind 0) is a half-space: depth ``r − (p − c)·n``. Other planes (walls, static)
  are two-sided bounded rectangles: depth ``r − |p − closest point of the rectangle|``.
- energy: kinetic + potential ``m·g·(z − r)`` (:mod:`physgnn.physics.energy`) from the velocities
  given (ground truth: the engine's by default; rollouts: their own); the normalised gain is
  ``Σ max(0, E_{k+1} − E_k) / E_0``; when ``E_0`` is zero (``≤ 1e-6·Σ m·g·r``, float noise of a
  resting scene) or negative, the sum is divided by ``Σ m·g·r`` instead.
- accuracy metrics are averaged over all frames given (seed frames included, as the report).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from physgnn.errors import PhysgnnError
from physgnn.physics import quaternion as Q
from physgnn.physics.energy import G, sphere_energy
from physgnn.physics.kinematics import finite_difference_velocities
from physgnn.physics.scene import GROUND, Trajectory

# Above this many pair distances (T·N·M) the per-frame cKDTree path is used.
_BRUTE_FORCE_MAX = 2_000_000
# E_0 below this fraction of Σ m·g·r counts as zero initial energy.
_ZERO_ENERGY = 1e-6
PENETRATION_KEYS = (
    "depth_sphere",
    "depth_ground",
    "depth_static",
    "pct_sphere",
    "pct_ground",
    "pct_static",
)


class MetricError(PhysgnnError, ValueError):
    """A metric cannot be computed from its input (one line naming the problem)."""


def _frames(x, name: str, width: int = 3) -> np.ndarray:
    """Checked ``[T, N, width]`` float64 array: at least one frame and one sphere, finite."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 3 or x.shape[-1] != width:
        raise MetricError(f"{name} must have shape [T, N, {width}], got {list(x.shape)}")
    if x.shape[0] == 0 or x.shape[1] == 0:
        raise MetricError(f"{name} is empty (shape {list(x.shape)}): no frame or no sphere")
    finite = np.isfinite(x).all(axis=(1, 2))
    if not finite.all():
        raise MetricError(f"{name} has NaN or inf at frame {int(np.argmin(finite))}")
    return x


def _per_sphere(x, n: int, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape != (n,):
        raise MetricError(f"{name} must have shape [{n}], got {list(x.shape)}")
    if not np.isfinite(x).all():
        raise MetricError(f"{name} has NaN or inf")
    return x


def _same_shape(a: np.ndarray, b: np.ndarray) -> None:
    if a.shape != b.shape:
        raise MetricError(f"prediction {list(a.shape)} and truth {list(b.shape)} differ in shape")


# ----------------------------------------------------------------------------- penetration
def sphere_overlaps(pos_t: np.ndarray, radius: np.ndarray):
    """Overlapping pairs of one frame. pos_t ``[N, 3]`` → ``(i [P], j [P], depth [P])``, i < j,
    depth = ``r_i + r_j − |p_i − p_j| > 0`` (cKDTree candidates within ``2·r_max``)."""
    pairs = cKDTree(pos_t).query_pairs(2.0 * radius.max(), output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    depth = radius[i] + radius[j] - np.linalg.norm(pos_t[i] - pos_t[j], axis=-1)
    keep = depth > 0
    return i[keep], j[keep], depth[keep]


def _sphere_sphere(pos: np.ndarray, radius: np.ndarray, tol: float):
    """Normalised depths of all intersections ``[K]`` and ``[N]`` bool: the spheres with one
    deeper than ``tol``."""
    t_count, n = pos.shape[:2]
    touched = np.zeros(n, dtype=bool)
    if n < 2:
        return np.zeros(0), touched
    if t_count * n * n <= _BRUTE_FORCE_MAX:
        iu, ju = np.triu_indices(n, k=1)
        sum_r = radius[iu] + radius[ju]
        norm_depth = (sum_r - np.linalg.norm(pos[:, iu] - pos[:, ju], axis=-1)) / sum_r  # [T, P]
        deep = (norm_depth > tol).any(0)
        touched[iu[deep]] = True
        touched[ju[deep]] = True
        return norm_depth[norm_depth > 0], touched
    depths = []
    for pos_t in pos:  # one neighbour query per frame
        i, j, depth = sphere_overlaps(pos_t, radius)
        norm_depth = depth / (radius[i] + radius[j])
        deep = norm_depth > tol
        touched[i[deep]] = True
        touched[j[deep]] = True
        depths.append(norm_depth)
    return np.concatenate(depths), touched


def plane_distance(pos: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """Distance from centres ``[..., 3]`` to the closest point of a bounded plane row ``[11]``
    (infinite half lengths give the distance to the unbounded plane). → ``[...]``."""
    centre, normal, ref = plane[0:3], plane[3:6], plane[6:9]
    rel = pos - centre
    u, w = rel @ ref, rel @ np.cross(normal, ref)
    du = u - np.clip(u, -plane[9], plane[9])
    dw = w - np.clip(w, -plane[10], plane[10])
    return np.sqrt(du * du + dw * dw + (rel @ normal) ** 2)


def _sphere_planes(pos, radius, planes, kinds, tol: float, ground: bool):
    """Normalised depths ``[K]`` and deeper-than-``tol`` ``[N]`` against the ground or the
    other planes."""
    depths, touched = [], np.zeros(pos.shape[1], dtype=bool)
    for plane, kind in zip(planes, kinds, strict=True):
        if (kind == GROUND) != ground:
            continue
        if ground:  # half-space: a sphere below the ground is deeper than its radius
            depth = radius - (pos - plane[0:3]) @ plane[3:6]
        else:
            depth = radius - plane_distance(pos, plane)
        norm_depth = depth / (2.0 * radius)  # [T, N]
        touched |= (norm_depth > tol).any(0)
        depths.append(norm_depth[norm_depth > 0])
    return (np.concatenate(depths) if depths else np.zeros(0)), touched


def penetration(pos, radius, planes, plane_kind, tol: float = 0.0) -> dict[str, float]:
    """Penetration metrics of a trajectory (definitions in the module docstring).

    pos ``[T, N, 3]``, radius ``[N]``, planes ``[S, 11]``, plane_kind ``[S]``; ``tol`` is a
    fraction of the diameter. Returns the floats of :data:`PENETRATION_KEYS` (pct in %).
    """
    pos = _frames(pos, "pos")
    n = pos.shape[1]
    radius = _per_sphere(radius, n, "radius")
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 11)
    kinds = np.asarray(plane_kind).reshape(-1)
    if len(kinds) != len(planes):
        raise MetricError(f"{len(planes)} planes but {len(kinds)} plane kinds")
    parts = {
        "sphere": _sphere_sphere(pos, radius, tol),
        "ground": _sphere_planes(pos, radius, planes, kinds, tol, ground=True),
        "static": _sphere_planes(pos, radius, planes, kinds, tol, ground=False),
    }
    out = {}
    for key, (depths, touched) in parts.items():
        out[f"depth_{key}"] = float(depths.mean()) if depths.size else 0.0
        out[f"pct_{key}"] = 100.0 * float(touched.mean())
    return {k: out[k] for k in PENETRATION_KEYS}


# ----------------------------------------------------------------------------------- energy
def energy_series(pos, vel, mass, radius, g: float = G) -> np.ndarray:
    """Total kinetic + potential energy of every frame. pos, vel ``[T, N, 3]`` → ``[T]`` (J)."""
    pos, vel = _frames(pos, "pos"), _frames(vel, "vel")
    _same_shape(pos, vel)
    n = pos.shape[1]
    mass, radius = _per_sphere(mass, n, "mass"), _per_sphere(radius, n, "radius")
    t = torch.from_numpy
    return sphere_energy(t(pos), t(vel), t(mass), t(radius), g).sum(-1).numpy()


def energy_scale(mass, radius, g: float = G) -> float:
    """``Σ m·g·r``: the divisor of the energy gain when the initial energy is zero."""
    return float(np.sum(np.asarray(mass, np.float64) * g * np.asarray(radius, np.float64)))


def energy_gain(energy, scale: float | None = None) -> float:
    """``Σ_k max(0, E_{k+1} − E_k) / E_0``; divided by ``scale`` (``Σ m·g·r``) instead when
    ``E_0 ≤ 1e-6·scale``. energy ``[T]``. Zero initial energy without a scale is an error."""
    e = np.asarray(energy, dtype=np.float64)
    if e.ndim != 1 or e.size == 0:
        raise MetricError(f"energy series must have shape [T] with T >= 1, got {list(e.shape)}")
    if not np.isfinite(e).all():
        raise MetricError(f"energy series has NaN or inf at frame {int(np.argmin(np.isfinite(e)))}")
    gain = float(np.clip(np.diff(e), 0.0, None).sum())
    floor = 0.0 if scale is None else _ZERO_ENERGY * scale
    if e[0] > floor:
        return gain / float(e[0])
    if scale is None or scale <= 0:
        raise MetricError(
            f"initial energy is {e[0]:.3g} <= 0: pass scale = sum(m*g*r) to normalise"
        )
    return gain / scale


# --------------------------------------------------------------------------------- accuracy
def position_mse(pred, true) -> float:
    """Mean over frames and spheres of ``|p̂ − p|²``. ``[T, N, 3]`` × ``[T, N, 3]``."""
    pred, true = _frames(pred, "pred pos"), _frames(true, "true pos")
    _same_shape(pred, true)
    return float(((pred - true) ** 2).sum(-1).mean())


def mse_at(pred, true, k: int) -> float:
    """Position MSE of frame ``k`` only (mean over spheres)."""
    pred, true = _frames(pred, "pred pos"), _frames(true, "true pos")
    _same_shape(pred, true)
    if not 0 <= k < pred.shape[0]:
        raise MetricError(f"frame {k} is outside the {pred.shape[0]} frames given")
    return float(((pred[k] - true[k]) ** 2).sum(-1).mean())


def _nearest_sq(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared distance from each point of a ``[T, N, 3]`` to the nearest of b ``[T, M, 3]``
    and back: ``([T, N], [T, M])``."""
    t_count, n, m = a.shape[0], a.shape[1], b.shape[1]
    if t_count * n * m <= _BRUTE_FORCE_MAX:
        d2 = ((a[:, :, None, :] - b[:, None, :, :]) ** 2).sum(-1)  # [T, N, M]
        return d2.min(2), d2.min(1)
    ab = np.stack([cKDTree(bt).query(at)[0] for at, bt in zip(a, b, strict=True)])
    ba = np.stack([cKDTree(at).query(bt)[0] for at, bt in zip(a, b, strict=True)])
    return ab**2, ba**2


def chamfer(pred, true) -> float:
    """Symmetric squared Chamfer distance averaged over frames (report §4.2).

    pred ``[T, N, 3]``, true ``[T, M, 3]``: mean over frames of
    ``mean_i min_j |p̂_i − p_j|² + mean_j min_i |p_j − p̂_i|²``.
    """
    pred, true = _frames(pred, "pred pos"), _frames(true, "true pos")
    if pred.shape[0] != true.shape[0]:
        raise MetricError(f"prediction has {pred.shape[0]} frames, truth {true.shape[0]}")
    ab, ba = _nearest_sq(pred, true)
    return float((ab.mean(1) + ba.mean(1)).mean())


def rotation_error(q_pred, q_true) -> float:
    """Mean geodesic angle (rad) between orientations ``[T, N, 4]`` (q and −q are equal)."""
    a, b = _frames(q_pred, "pred quat", 4), _frames(q_true, "true quat", 4)
    _same_shape(a, b)
    return float(Q.geodesic_angle(torch.from_numpy(a), torch.from_numpy(b)).mean())


def momentum_drift(vel, mass) -> float:
    """Largest change of the centre-of-mass velocity ``|Σm·v_k − Σm·v_0| / Σm`` (m/s) over
    the frames; meaningful only when no external force acts. vel ``[T, N, 3]``."""
    vel = _frames(vel, "vel")
    mass = _per_sphere(mass, vel.shape[1], "mass")
    momentum = (mass[:, None] * vel).sum(1)  # [T, 3]
    return float(np.linalg.norm(momentum - momentum[0], axis=-1).max() / mass.sum())


def resting_mask(pos, radius, tol: float = 0.01) -> np.ndarray:
    """Spheres that never move more than ``tol`` radii from their first position ``[N]``."""
    pos = _frames(pos, "pos")
    radius = _per_sphere(radius, pos.shape[1], "radius")
    return (np.linalg.norm(pos - pos[0], axis=-1) <= tol * radius).all(0)


def rest_drift(pos, radius, mask) -> float | None:
    """Largest displacement from the first frame, in radii, of the spheres in ``mask`` ``[N]``
    (those that should stay at rest); None when the mask is empty."""
    pos = _frames(pos, "pos")
    radius = _per_sphere(radius, pos.shape[1], "radius")
    mask = np.asarray(mask, dtype=bool)
    if not mask.any():
        return None
    disp = np.linalg.norm(pos[:, mask] - pos[0, mask], axis=-1) / radius[mask]
    return float(disp.max())


def drift_before_hit(pred, true, radius, start: int, tol: float = 0.01) -> np.ndarray:
    """Rest drift of spheres that rest until something hits them: for each sphere the truth
    keeps within ``tol`` radii of its first position through the seed frames ``0..start``,
    the largest displacement (in radii) of ``pred`` from its first frame over the frames
    before the truth moves it. pred / true ``[T, N, 3]`` → ``[R]`` (R such spheres, maybe 0)."""
    pred, true = _frames(pred, "pred pos"), _frames(true, "true pos")
    radius = _per_sphere(radius, pred.shape[1], "radius")
    t = min(len(pred), len(true))
    moved = np.linalg.norm(true[:t] - true[0], axis=-1) > tol * radius  # [T, N]
    rest_until = np.where(moved.any(0), moved.argmax(0), t)  # first frame moved, [N]
    before = np.arange(t)[:, None] < rest_until[None, :]
    disp = np.linalg.norm(pred[:t] - pred[0], axis=-1) / radius
    return np.where(before, disp, 0.0).max(0)[rest_until > start]


# ------------------------------------------------------------------------------- one rollout
_SCENE_KEYS = ("radius", "mass", "planes", "plane_kind", "effects")


def trajectory_dict(traj: Trajectory, velocities: str = "engine") -> dict:
    """A ground-truth trajectory in the form :func:`trajectory_metrics` takes: pos, quat, vel
    and the scene arrays.

    ``velocities="engine"``: the engine's instantaneous velocities (the physics of the data);
    ``"finite"``: ``(p_k − p_{k−1})/dt`` (``v_0`` the engine's), what a rollout records. At
    dt = 0.1 s a bounce inside a frame interval makes the finite-difference kinetic energy dip
    and recover, which the energy gain counts: the gain a perfect rollout would show.
    """
    pos, quat = np.asarray(traj.pos, np.float64), np.asarray(traj.quat, np.float64)
    if velocities == "engine":
        vel = np.asarray(traj.vel, np.float64)
    elif velocities == "finite":
        vel = finite_difference_velocities(
            torch.from_numpy(pos),
            torch.from_numpy(quat),
            torch.as_tensor(np.asarray(traj.vel[0], np.float64)),
            torch.as_tensor(np.asarray(traj.angvel[0], np.float64)),
            traj.dt,
        )[0].numpy()
    else:
        raise MetricError(f"velocities must be 'engine' or 'finite', got {velocities!r}")
    scene = {k: getattr(traj, k) for k in _SCENE_KEYS}
    return dict(pos=pos, quat=quat, vel=vel, start=0, diverged_at=None, **scene)


def trajectory_metrics(
    pred: dict,
    true: Trajectory | None = None,
    *,
    tol: float = 0.0,
    horizon: int = 20,
    rest_mask=None,
    rest_tol: float = 0.01,
    g: float = G,
) -> dict:
    """All metrics of one (possibly truncated) rollout.

    ``pred``: ``pos [T, N, 3]``, ``vel [T, N, 3]``, optional ``quat [T, N, 4]``, ``start``
    (the last seed frame, H), ``diverged_at``; scene arrays (radius, mass, planes, plane_kind,
    effects) are taken from ``true`` when given, else from ``pred``. Without ``true`` only the
    physics metrics are computed. Comparisons use the first ``min(T, T_true)`` frames.
    ``mse{horizon}`` is the MSE at frame ``start + horizon``; None when not reached.
    ``momentum_drift`` only for scenes without gravity or surface contact. ``rest_drift`` for
    the spheres of ``rest_mask``, by default those that move less than ``rest_tol`` radii in
    the truth; ``drift_before_hit`` (:func:`drift_before_hit`) for those that rest until hit.
    Keys with nothing to measure are None.
    """
    scene = {k: getattr(true, k) if true is not None else pred.get(k) for k in _SCENE_KEYS}
    missing = [k for k in _SCENE_KEYS[:4] if scene[k] is None]
    if missing:
        raise MetricError(
            f"no scene arrays {missing}: pass the true trajectory or put them in pred"
        )
    pos = _frames(pred["pos"], "pred pos")
    if pred.get("vel") is None:
        raise MetricError("pred has no 'vel' (velocities are needed for the energy)")
    vel = _frames(pred["vel"], "pred vel")
    radius, mass = scene["radius"], scene["mass"]
    start = int(pred.get("start", 0))
    energy = energy_series(pos, vel, mass, radius, g)
    out = {
        "n_spheres": int(pos.shape[1]),
        "n_frames": int(pos.shape[0]),
        "diverged_at": pred.get("diverged_at"),
        "energy_gain": energy_gain(energy, energy_scale(mass, radius, g)),
        **penetration(pos, radius, scene["planes"], scene["plane_kind"], tol),
    }
    effects = scene["effects"]
    free = effects is not None and not (effects.gravity or effects.surface_contact)
    out["momentum_drift"] = momentum_drift(vel, mass) if free else None
    mse_key = f"mse{horizon}"
    out.update(mse=None, **{mse_key: None}, chamfer=None, rotation_error=None)
    out.update(rest_drift=None, drift_before_hit=None)
    if true is None:
        if rest_mask is not None:
            out["rest_drift"] = rest_drift(pos, radius, rest_mask)
        return out
    t_count = min(pos.shape[0], true.n_frames)
    p_hat, p_true = pos[:t_count], np.asarray(true.pos[:t_count], np.float64)
    out["mse"] = position_mse(p_hat, p_true)
    out["chamfer"] = chamfer(p_hat, p_true)
    if start + horizon < t_count:
        out[mse_key] = mse_at(p_hat, p_true, start + horizon)
    if pred.get("quat") is not None:
        out["rotation_error"] = rotation_error(pred["quat"][:t_count], true.quat[:t_count])
    if rest_mask is None:
        rest_mask = resting_mask(true.pos, radius, rest_tol)
    out["rest_drift"] = rest_drift(pos, radius, rest_mask)
    hit = drift_before_hit(pos, true.pos, radius, start, rest_tol)
    out["drift_before_hit"] = float(hit.max()) if hit.size else None
    return out

"""Sleeping spheres: resting spheres are frozen and left out of the network, as Bullet
deactivates resting bodies.

:class:`SleepingSimulator` wraps a simulator (same call: ``state -> (v_next, ω_next)``) for one
rollout. Before each step it

1. counts, for every awake sphere, the consecutive frames whose speed
   ``max(|v_t|, r·|ω_t|)`` stayed below ``threshold`` (at the first call, the velocity
   history of the state counts: spheres resting through a rollout's ``H + 1`` seed frames
   start with ``H + 1`` still frames, so with ``k ≤ H + 1`` they sleep before the network
   can set them in motion);
2. puts to sleep the spheres still for ``k`` frames or more that touch nothing awake and that
   no moving sphere can reach before the next frame. Touching (``gap ≤ touch · min(r_i,
   r_j)``) is followed through chains, like Bullet's islands: a still sphere touching a moving
   one keeps every still sphere of its chain awake;
3. wakes the sleeping spheres within reach of an awake sphere (the pair rule of the
   simulator's graph builder, the sleeper's velocity being 0), with every sleeping sphere
   that touches a woken one, recursively (the whole island wakes);
4. runs the simulator on the awake spheres only (a smaller graph) and returns ``v = ω = 0``
   for the sleeping ones. :meth:`SleepingSimulator.hold` then restores their position and
   orientation exactly after the integration step.

While no sphere sleeps the wrapped simulator sees the very same state object, so a rollout
is bit-identical to one without sleeping. Sleeping spheres cost nothing in the network; the
search for spheres to wake costs O(awake · neighbours): a k-d tree over the sleepers (on CPU),
built again only when spheres fall asleep. The wrapper is driven from the host by design (which
spheres sleep, which islands wake): it reads a few values back each frame, so it suits CPU
rollouts of scenes that come to rest, not a captured GPU step.
"""

from __future__ import annotations

import math

import torch

from physgnn.data.state import scene_of_sphere, subset_state
from physgnn.graph.builder import GraphBuilder
from physgnn.graph.neighbors import BallIndex, extent_span, radius_pairs
from physgnn.models.protocol import engine_state_of


class SleepingSimulator:
    """``simulator`` with resting spheres frozen; one instance per rollout (it keeps state).

    ``threshold`` (m/s): speed below which a frame counts as still; ``k``: still frames
    before a sphere may sleep; ``touch``: contact tolerance as a fraction of the smaller
    radius. Other attributes (``H``, ``timings``, …) are the wrapped simulator's.
    ``asleep [N]`` (bool) and ``still [N]`` (frames) describe the spheres after the last call;
    ``sleep_frames`` counts sphere-frames spent asleep, ``wakes`` the spheres woken.
    """

    def __init__(self, simulator, threshold: float = 0.05, k: int = 3, touch: float = 0.1):
        if not (math.isfinite(float(threshold)) and float(threshold) >= 0):
            raise ValueError(f"sleeping threshold must be finite and >= 0 (got {threshold})")
        if int(k) != k or int(k) < 1:
            raise ValueError(f"sleeping k must be an integer >= 1 (got {k})")
        if not (math.isfinite(float(touch)) and float(touch) >= 0):
            raise ValueError(f"sleeping touch must be finite and >= 0 (got {touch})")
        self.simulator = simulator
        self.threshold, self.k, self.touch = float(threshold), int(k), float(touch)
        self.asleep: torch.Tensor | None = None
        self.still: torch.Tensor | None = None
        self.sleep_frames = 0
        self.wakes = 0
        self._index: _RestIndex | None = None

    def __getattr__(self, name):
        # Only called for attributes not found on the wrapper: delegate to the simulator.
        if name == "simulator":
            raise AttributeError(name)
        return getattr(self.simulator, name)

    # ----- the step -----------------------------------------------------------------------
    def __call__(self, state) -> tuple[torch.Tensor, torch.Tensor]:
        """``(vel_next [N, 3], ω_next [N, 3])``; zero for sleeping spheres."""
        n = state.pos.shape[0]
        if self.asleep is None or self.asleep.shape[0] != n:
            self.asleep = torch.zeros(n, dtype=torch.bool, device=state.pos.device)
            self.still = self._still_history(state)
            self._index = None
        else:
            self._count(state)
        self._fall_asleep(state)
        woken = self._wake(state)
        asleep = int(self.asleep.sum())  # a read-back, as every decision of the wrapper
        self.sleep_frames += asleep
        if not asleep:
            return self.simulator(state)
        awake = ~self.asleep
        # sleeping spheres answer zeros: 2 tensors, or 4 for a simulator of the engine state
        engine = engine_state_of(self.simulator)
        answer = [state.pos.new_zeros(n, 3) for _ in range(4 if engine else 2)]
        if bool(awake.any()):
            sub = subset_state(state, awake)
            fresh = woken[awake]  # just woken: their history is the rest they were frozen in
            sub.vel = torch.where(fresh[:, None, None], torch.zeros_like(sub.vel), sub.vel)
            sub.angvel = torch.where(fresh[:, None, None], torch.zeros_like(sub.angvel), sub.angvel)
            for whole, part in zip(answer, self.simulator(sub), strict=True):
                whole[awake] = part
        return tuple(answer)

    def hold(
        self, pos: torch.Tensor, quat: torch.Tensor, pos_next: torch.Tensor, quat_next: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """After integration: sleeping spheres keep ``pos [N, 3]`` and ``quat [N, 4]`` exactly."""
        if self.asleep is None or not bool(self.asleep.any()):
            return pos_next, quat_next
        a = self.asleep[:, None]
        return torch.where(a, pos, pos_next), torch.where(a, quat, quat_next)

    def select(self, keep: torch.Tensor) -> None:
        """Keep the sleep state of the spheres ``keep [N]`` (bool) only, in order: call it
        when the rollout drops spheres (finished or diverged scenes) from its batch."""
        if self.asleep is not None:
            keep = keep.to(self.asleep.device)
            self.asleep, self.still = self.asleep[keep], self.still[keep]
            self._index = None

    def rotating(self, state) -> torch.Tensor:
        """``[N]`` bool: the wrapped simulator's rotating spheres that are awake."""
        rot = self.simulator.rotating(state)
        return rot if self.asleep is None else rot & ~self.asleep

    # ----- sleep state ----------------------------------------------------------------------
    def _still_history(self, state) -> torch.Tensor:
        """``[N]``: how many of the latest velocities of the history (``v_t, v_{t−1}, …``)
        are in a row below the threshold: a sphere resting through a rollout's seed frames
        starts with ``H + 1`` still frames."""
        speed = torch.maximum(
            state.vel.norm(dim=-1), state.angvel.norm(dim=-1) * state.radius[:, None]
        )
        return torch.cumprod((speed < self.threshold).long(), dim=1).sum(1)

    def _count(self, state) -> None:
        speed = state.vel[:, 0].norm(dim=-1)
        spin = state.angvel[:, 0].norm(dim=-1) * state.radius
        still = (torch.maximum(speed, spin) < self.threshold) & ~self.asleep
        self.still = torch.where(still, self.still + 1, torch.where(self.asleep, self.still, 0))

    def _fall_asleep(self, state) -> None:
        """Spheres still for ``k`` frames sleep unless a moving sphere reaches them, directly
        (the wake rule, which would wake them at once) or through a chain of touching ones."""
        ready = ~self.asleep & (self.still >= self.k)
        if not bool(ready.any()):
            return
        moving = torch.nonzero(~self.asleep & ~ready).flatten()
        candidates = torch.nonzero(ready).flatten()
        near = self._within_reach(state, moving, candidates)
        seeds = torch.cat([moving, near])
        left = candidates[~torch.isin(candidates, near)]
        kept = _flood(state, seeds, left, self._touching, self._touch_extra(state))
        sleep = ready.clone()
        sleep[near] = False
        sleep[kept] = False
        if bool(sleep.any()):
            self.asleep |= sleep
            self._index = None  # new sleepers: rebuild the index of spheres at rest

    def _wake(self, state) -> torch.Tensor:
        """Wake the sleepers within reach of an awake sphere and every sleeper touching them,
        recursively (the whole island); returns the woken ``[N]`` bool."""
        woken = torch.zeros_like(self.asleep)
        if not bool(self.asleep.any()) or bool(self.asleep.all()):
            return woken
        if self._index is None:
            sleepers = torch.nonzero(self.asleep).flatten()
            self._index = _RestIndex(state, sleepers, self._touching, self._touch_extra(state))
        movers = torch.nonzero(~self.asleep).flatten()
        reach = _Reach(state, self.simulator, ~self.asleep)
        search = state.radius[movers].double() + reach.allow[movers] + reach.max_extra
        q, j = self._index.near(state, movers, search)
        hit = self.asleep[j] & reach(state, q, j)
        if not bool(hit.any()):
            return woken
        woken[j[hit]] = True
        i, j = self._index.pairs
        woken = _spread(woken, self.asleep, i, j)
        self.asleep &= ~woken
        self.still[woken] = 0
        self.wakes += int(woken.sum())
        return woken

    def _within_reach(self, state, movers: torch.Tensor, others: torch.Tensor) -> torch.Tensor:
        """The ``others`` (at rest) that one of ``movers`` may touch before the next frame,
        by the simulator's graph rule; ``[R]`` sphere indices."""
        if movers.numel() == 0 or others.numel() == 0:
            return others[:0]
        moving = torch.zeros_like(self.asleep)
        moving[movers] = True
        reach = _Reach(state, self.simulator, moving)
        hit = _pairs_within(state, movers, others, reach.allow[movers], reach.max_extra)
        hit = hit[:, reach(state, movers[hit[0]], others[hit[1]])]
        return torch.unique(others[hit[1]])

    def _touch_extra(self, state) -> float:
        """Bound on the centre distance of touching spheres, ``(2 + touch) · r_max``."""
        return (2.0 + self.touch) * float(state.radius.max()) * (1 + 1e-6)

    def _touching(self, state, i: torch.Tensor, j: torch.Tensor) -> torch.Tensor:
        """``[P]`` bool: ``gap_ij ≤ touch · min(r_i, r_j)``."""
        gap, r = _gap(state, i, j)
        return gap <= self.touch * torch.minimum(r[i], r[j])


# ----- helpers -------------------------------------------------------------------------------
class _Reach:
    """The simulator's pp rule between moving spheres and spheres at rest (speed 0): its graph
    builder's ``gap ≤ a_i + a_j + ε``; without a graph builder (baselines) ``gap ≤ 0``."""

    def __init__(self, state, simulator, moving: torch.Tensor):
        """``moving [N]`` bool: the spheres that move."""
        self.builder = getattr(simulator, "graph_builder", None) or _TOUCHING
        self.allow = self.builder.allowance(state, moving)
        self.max_extra = float(self.builder.reach(state, self.allow).max())  # r_i + a_i + ε

    def __call__(self, state, i: torch.Tensor, j: torch.Tensor) -> torch.Tensor:
        return self.builder.pair_within_reach(state, i, j, self.allow)


_TOUCHING = GraphBuilder("epsilon", epsilon=0.0)


def _gap(state, i: torch.Tensor, j: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Float64 ``gap_ij = |p_i − p_j| − r_i − r_j`` ``[P]`` and the radii ``[N]``."""
    p = state.pos.to(torch.float64)
    r = state.radius.to(torch.float64)
    return (p[i] - p[j]).norm(dim=-1) - r[i] - r[j], r


class _RestIndex:
    """A k-d tree over spheres at rest and the touching pairs among them. Sleepers do not
    move, so it stays valid until a sphere falls asleep (woken members are filtered out by
    the caller through the current ``asleep`` mask)."""

    def __init__(self, state, members: torch.Tensor, touching, touch_reach: float):
        batch = scene_of_sphere(state)
        self.members = members
        self.index = BallIndex(state.pos[members], batch[members], extent_span(state.pos))
        local = radius_pairs(state.pos[members], touch_reach, batch[members])
        i, j = members[local[0]], members[local[1]]
        keep = touching(state, i, j)
        self.pairs = (i[keep], j[keep])

    def near(self, state, query: torch.Tensor, search: torch.Tensor):
        """Candidate pairs ``(query sphere [P], member [P])`` with centres at most ``search
        [Q]`` apart (a superset: the caller applies the exact rule)."""
        rows, cols = self.index.near(state.pos[query], scene_of_sphere(state)[query], search)
        return query[rows], self.members[cols]


def _pairs_within(
    state, query: torch.Tensor, data: torch.Tensor, extra: torch.Tensor, data_extra: float
) -> torch.Tensor:
    """Candidate pairs ``[2, P]`` (positions into ``query`` and ``data``) with
    ``|p_q − p_d| ≤ r_q + extra_q + data_extra`` (a superset the caller filters)."""
    if query.numel() == 0 or data.numel() == 0:
        return torch.empty(2, 0, dtype=torch.long, device=state.pos.device)
    search = state.radius[query].double() + extra.double() + data_extra
    batch = scene_of_sphere(state)
    span = extent_span(state.pos, 2.0 * float(search.max()))
    rows, cols = BallIndex(state.pos[data], batch[data], span).near(
        state.pos[query], batch[query], search
    )
    return torch.stack([rows, cols]).reshape(2, -1)


def _spread(reached: torch.Tensor, allowed: torch.Tensor, i: torch.Tensor, j: torch.Tensor):
    """Grow ``reached [N]`` (bool) along the undirected pairs ``(i, j)`` into ``allowed [N]``
    spheres until it stops; returns the grown mask."""
    src, dst = torch.cat([i, j]), torch.cat([j, i])
    into = allowed[dst]
    src, dst = src[into], dst[into]
    reached = reached.clone()
    while True:
        new = torch.zeros_like(reached)
        new[dst[reached[src]]] = True
        new &= ~reached
        if not bool(new.any()):
            return reached
        reached |= new


def _flood(state, seeds: torch.Tensor, targets: torch.Tensor, linked, reach: float) -> torch.Tensor:
    """The ``targets`` reachable from ``seeds`` through chains of ``linked`` pairs (centres
    at most ``reach`` apart), ``[R]`` sphere indices."""
    n = state.pos.shape[0]
    nodes = torch.cat([seeds, targets])
    local = radius_pairs(state.pos[nodes], reach, scene_of_sphere(state)[nodes])
    i, j = nodes[local[0]], nodes[local[1]]
    keep = linked(state, i, j)
    is_target = torch.zeros(n, dtype=torch.bool, device=state.pos.device)
    is_target[targets] = True
    start = torch.zeros_like(is_target)
    start[seeds] = True
    reached = _spread(start, is_target, i[keep], j[keep])
    return torch.nonzero(reached & is_target).flatten()

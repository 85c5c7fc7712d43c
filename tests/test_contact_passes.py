"""Contacts found within the frame, pair impulses that conserve, and free flight after a contact
(physgnn/graph/rebuild.py "Contacts within the frame", physgnn/models/impulses.py,
physgnn/models/reach.py): brute force and conservation laws as oracles."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from handmade import DT, make, scene
from omegaconf import OmegaConf
from torch.testing import assert_close
from torch_geometric.data import Batch

from physgnn import CONF_DIR
from physgnn.data.state import TrajectoryFrames
from physgnn.graph.builder import GraphBuilder
from physgnn.graph.rules import ballistic_velocity
from physgnn.groundtruth.engine import simulate
from physgnn.groundtruth.families import build_scene
from physgnn.models.impulses import sphere_inertia
from physgnn.physics.geometry import edge_plane_depth
from physgnn.physics.integrator import step

G_DT = torch.tensor([0.0, 0.0, -9.81 * DT])


def edges_of(graph) -> set[tuple[int, int]]:
    src, dst = graph.pp_index
    return {(min(a, b), max(a, b)) for a, b in zip(src.tolist(), dst.tolist(), strict=True)}


def touching_by_next_frame(pos, radius, vel, dt) -> set[tuple[int, int]]:
    """Brute force: pairs that come within contact at some τ in [0, dt] moving with ``vel``
    (sampled at 201 instants: what it finds does touch)."""
    tau = torch.linspace(0, dt, 201, dtype=torch.float64)[:, None, None]
    p = pos.double()[None] + tau * vel.double()[None]  # [T, N, 3]
    dist = torch.cdist(p, p).amin(0)
    reach = radius.double()[:, None] + radius.double()[None, :]
    i, j = torch.nonzero(torch.triu(dist <= reach, 1), as_tuple=True)
    return set(zip(i.tolist(), j.tolist(), strict=True))


def random_supported_state(seed: int):
    """Spheres in a 6 m box near the ground, a third resting on it (zero velocity), the rest
    falling or thrown, several within a frame's travel of each other."""
    rng = np.random.default_rng(seed)
    n = 24
    radius = rng.uniform(0.3, 0.7, n)
    pos = rng.uniform([-3, -3, 0], [3, 3, 4], (n, 3))
    pos[: n // 3, 2] = radius[: n // 3]  # on the ground
    vel = rng.normal(0, 3, (n, 3))
    vel[: n // 3] = 0
    return scene(pos, vel, radius)


def test_a_rebuild_on_provisional_velocities_links_every_pair_that_touches_under_them():
    builder = GraphBuilder()
    for seed in range(6):
        state = random_supported_state(seed)
        ballistic = ballistic_velocity(state)
        resting = torch.zeros(state.pos.shape[0], dtype=torch.bool)
        resting[: state.pos.shape[0] // 3] = True  # supported: the ground stops them
        provisional = torch.where(resting[:, None], torch.zeros_like(ballistic), ballistic)
        graph = builder(state, [provisional])
        touching = touching_by_next_frame(state.pos, state.radius, provisional, DT)
        assert touching <= edges_of(graph), seed
        assert edges_of(builder(state)) <= edges_of(graph)  # a rebuild only adds


def accepted(basis):
    """The candidate pairs and plane edges a basis's masks accept."""
    src, dst, plane, sphere = basis.candidates
    pp, ps = basis.masks
    pairs = set(zip(src[pp].tolist(), dst[pp].tolist(), strict=True))
    return pairs, set(zip(plane[ps].tolist(), sphere[ps].tolist(), strict=True))


def test_a_rebuild_from_the_last_builds_candidates_is_the_whole_builds_graph():
    """extend reuses the candidates and earlier masks where the allowance holds, and searches
    pairs for the grown spheres only where a faster velocity widens it: the graph is the whole
    build's, edge for edge."""
    builders = [GraphBuilder(), GraphBuilder(fixed_capacity=True)] * 3
    for seed, builder in zip(range(6), builders, strict=True):
        state = random_supported_state(seed)
        ballistic = ballistic_velocity(state)
        slower = 0.5 * ballistic  # every allowance holds: the cheap path
        faster = ballistic.clone()
        faster[0] = 3 * faster[0] + 1  # one allowance widens: a whole build
        for velocities in ([slower], [slower, 0.9 * ballistic], [faster], [slower, faster]):
            _, basis = builder.build(state, velocities[:-1])
            graph, extended = builder.extend(state, basis, velocities)
            whole, whole_basis = builder.build(state, velocities)
            for field in ("pp_index", "pp_attr", "ps_index", "ps_attr", "allowance", "pp_mask"):
                assert_close(getattr(graph, field), getattr(whole, field), rtol=0, atol=0)
            assert accepted(extended) == accepted(whole_basis)
            if velocities[-1] is not faster or builder.fixed_capacity:
                assert_close(extended.masks, whole_basis.masks, rtol=0, atol=0)


def test_a_sphere_falling_onto_a_resting_one_is_linked_once_the_resting_one_stops():
    # the upper sphere falls at 1 m/s 0.15 m above a sphere resting on the ground: ballistic,
    # both fall alike and the rule sees no approach; the lower one stops, the upper one moves
    # (1 + g·dt)·dt = 0.198 m within the frame
    state = scene([[0, 0, 0.5], [0, 0, 1.65]], [[0, 0, 0], [0, 0, -1.0]], [0.5, 0.5])
    builder = GraphBuilder()
    assert edges_of(builder(state)) == set()  # the gravity hole of the first pass
    provisional = ballistic_velocity(state)
    provisional[0] = 0.0
    assert edges_of(builder(state, [provisional])) == {(0, 1)}
    sim = make(gravity_prior=True)
    heads = []

    def oracle(state, graph, provisional=()):  # spheres in reach stop, the rest fly
        reach = sim.reach(state, graph, provisional).spheres
        heads.append(graph)
        vel = torch.where(reach[:, None], 0.0, ballistic_velocity(state))
        return vel, state.angvel[:, 0]

    sim.head = oracle
    vel, _, graph = sim.predict(state)
    assert edges_of(graph) == {(0, 1)} and len(heads) == 2  # a second pass, then no growth
    assert torch.equal(vel, torch.zeros_like(vel))


def test_with_the_truths_velocities_in_reach_one_step_of_ood_cubes_overlaps_as_the_truth():
    cfg = OmegaConf.to_container(OmegaConf.load(Path(CONF_DIR) / "scene" / "ood_cubes.yaml"))
    cfg["n_frames"] = 40  # every cube has landed by then
    engine = OmegaConf.load(Path(CONF_DIR) / "generate.yaml").engine
    truth = simulate(build_scene(cfg, np.random.default_rng(0)), engine)
    sim = make(gravity_prior=True)

    def oracle(state, graph, provisional=()):  # a perfect network under the gating
        reach = sim.reach(state, graph, provisional).spheres
        vel = torch.where(reach[:, None], state.target_vel, ballistic_velocity(state))
        return vel, state.angvel[:, 0]

    sim.head = oracle
    frames = TrajectoryFrames(truth)
    diameter = 2 * cfg["radius"]
    for t in range(2, truth.pos.shape[0] - 1):
        state = Batch.from_data_list([frames.state(t, 2, future=1)])
        vel, _, _ = sim.predict(state)
        depth = deepest(state, state.pos + DT * vel)
        truth_depth = deepest(state, torch.as_tensor(truth.pos[t + 1]))
        assert depth <= truth_depth + 0.01 * diameter, (t, depth, truth_depth)


def deepest(state, pos) -> float:
    """The largest sphere–sphere or sphere–plane overlap at ``pos`` (m; 0 without)."""
    dist = torch.cdist(pos.double(), pos.double())
    overlap = state.radius.double()[:, None] + state.radius.double()[None] - dist
    overlap.fill_diagonal_(0)
    n, s = pos.shape[0], state.planes.shape[0]
    every = torch.stack(torch.meshgrid(torch.arange(s), torch.arange(n), indexing="ij")).flatten(1)
    planes = edge_plane_depth(pos, state.radius, state.planes, state.plane_kind, every)
    return max(float(overlap.max().clamp_min(0)), float(planes.max().clamp_min(0)))


def colliding_group(masses, radii, seed=0, gravity=True):
    """Spheres 50 m up (no plane in reach), pairs approaching each other, spinning."""
    rng = np.random.default_rng(seed)
    n = len(masses)
    pos = np.stack([np.arange(n) * 2.0 * max(radii), np.zeros(n), np.full(n, 50.0)], 1)
    pos[:, 1:] += rng.normal(0, 0.2, (n, 2))
    vel = rng.normal(0, 2, (n, 3))
    vel[::2, 0] += 4.0  # the even spheres run into their right neighbours
    state = scene(pos, vel, radii, mass=masses)
    state.angvel = torch.as_tensor(rng.normal(0, 1, (n, 3)), dtype=torch.float32)[:, None]
    state.angvel = state.angvel.expand(-1, 3, -1).clone()
    if not gravity:
        state.effects[:, 0] = False
    return state


def momenta(state, vel, angvel):
    """``(Σ m (v_next − v_t − g·dt), Σ (p × m (v_next − v_t − g·dt) + I (ω_next − ω_t)))``
    and the scale of the changes (Σ of their magnitudes)."""
    mass, pos = state.mass[:, None].double(), state.pos.double()
    change = mass * (vel - ballistic_velocity(state)).double()
    inertia = sphere_inertia(state.mass, state.radius)[:, None].double()
    spin = inertia * (angvel - state.angvel[:, 0]).double()
    angular = torch.linalg.cross(pos, change) + spin
    scale = change.norm(dim=1).sum() + angular.norm(dim=1).sum()
    return change.sum(0), angular.sum(0), float(scale)


def test_pair_impulses_conserve_momentum_for_any_weights():
    cases = [
        ([1.0, 1.0], [0.5, 0.5]),
        ([1.0, 2.0], [0.5, 0.75]),
        ([1.0, 8.0, 1.0, 8.0], [0.5, 0.75, 0.6, 0.5]),
        ([1.0, 1e4, 3.0], [0.5, 0.5, 0.7]),
    ]
    for seed, (masses, radii) in enumerate(cases):
        sim = make(gravity_prior=True)
        torch.manual_seed(seed)
        for p in sim.network.parameters():  # random weights, changes of 0.1-10 m/s
            torch.nn.init.normal_(p, 0, 0.1)
        state = colliding_group(masses, radii, seed)
        with torch.no_grad():
            vel, angvel, graph = sim.predict(state)
        assert graph.pp_index.shape[1] > 0, seed  # they do interact
        linear, angular, scale = momenta(state, vel, angvel)
        assert scale > 1e-3, seed  # the network did change something
        tol = 1e-6 * scale * max(masses)
        assert_close(linear, torch.zeros(3, dtype=torch.float64), rtol=0, atol=tol)
        assert_close(angular, torch.zeros(3, dtype=torch.float64), rtol=0, atol=50 * tol)


def step_frames(sim, state, frames: int) -> list:
    """``[(state, graph)]`` of ``frames`` frames of ``sim`` from ``state``: each state and the
    graph of its prediction."""
    out = []
    for _ in range(frames):
        with torch.no_grad():
            vel, angvel, graph = sim.predict(state)
        out.append((state, graph))
        state = state.clone()
        state.pos, state.quat, state.vel, state.angvel = step(
            state.pos, state.quat, state.vel, state.angvel, vel, angvel, state.scene_dt
        )
    return out


def test_once_apart_two_spheres_fly_ballistically_with_constant_momentum_and_energy():
    sim = make(gravity_prior=True)
    for p in sim.network.parameters():
        torch.nn.init.normal_(p, 0, 0.1)
    # head-on 50 m up, without gravity: after the contact frames, nothing changes
    state = scene([[0, 0, 50.0], [1.05, 0, 50.0]], [[1, 0, 0], [-1, 0, 0]], [0.5, 0.5])
    state.effects[:, 0] = False
    history = step_frames(sim, state, 30)
    linked = [graph.pp_index.shape[1] > 0 for _, graph in history]
    assert linked[0] and not any(linked[-10:])  # they met, then parted for good
    first = max(k for k, on in enumerate(linked) if on) + 2  # the first state after the contact
    vels = torch.stack([s.vel[:, 0] for s, _ in history[first:]]).double()
    masses = state.mass[:, None].double()
    momentum = (masses * vels).sum(1)
    energy = (0.5 * masses[:, 0] * vels.square().sum(-1)).sum(1)
    # finite differences at 50 m in float32: ulp(50 m) / dt ≈ 4e-5 m/s
    assert_close(momentum, momentum[:1].expand_as(momentum), rtol=0, atol=1e-4)
    assert_close(energy, energy[:1].expand_as(energy), rtol=1e-4, atol=0)
    assert float(vels.abs().max()) > 0.1  # still moving


def test_contact_memory_keeps_a_contact_of_the_last_frame_in_reach_for_one_frame():
    # rising at 5 m/s, 0.3 m above the ground: it moved 0.5 m in the last frame, so it may have
    # bounced within it; 0.8 m above it it cannot have
    state = scene([[0, 0, 0.8], [5, 0, 1.3]], [[0, 0, 5.0], [0, 0, 5.0]], [0.5, 0.5])
    plain, memory = make(gravity_prior=True), make(gravity_prior=True, contact_memory=True)
    assert plain.reach(state, plain.graph_builder(state)).spheres.tolist() == [False, False]
    recalled = memory.recalled(state)
    graph = memory.graph_builder(state, recalled)
    assert memory.reach(state, graph, recalled).planes.tolist() == [True, False]
    # a pair parting at 2 m/s: linked while its gap is within the last frame's travel
    near = scene([[0, 0, 50.0], [1.15, 0, 50.0]], [[-1, 0, 0], [1, 0, 0]], [0.5, 0.5])
    far = scene([[0, 0, 50.0], [1.3, 0, 50.0]], [[-1, 0, 0], [1, 0, 0]], [0.5, 0.5])
    for state, linked in ((near, True), (far, False)):
        graph = memory.graph_builder(state, memory.recalled(state))
        assert (graph.pp_index.shape[1] > 0) == linked
        assert plain.graph_builder(state).pp_index.shape[1] == 0


def test_a_rebuild_that_widens_an_allowance_makes_no_whole_build(monkeypatch):
    builder = GraphBuilder()
    state = random_supported_state(1)
    ballistic = ballistic_velocity(state)
    faster = ballistic.clone()
    faster[:3] = 4 * faster[:3] + 2  # three allowances widen
    _, basis = builder.build(state, [ballistic])
    whole = builder.build(state, [ballistic, faster])[0]

    def no_whole_build(*args, **kwargs):
        raise AssertionError("a whole build within extend")

    monkeypatch.setattr(builder, "build", no_whole_build)
    graph, _ = builder.extend(state, basis, [ballistic, faster])
    for field in ("pp_index", "pp_attr", "ps_index", "ps_attr", "allowance"):
        assert_close(getattr(graph, field), getattr(whole, field), rtol=0, atol=0)

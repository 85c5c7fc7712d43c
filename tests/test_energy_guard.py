"""The energy guard (physgnn/models/energy_guard.py): a rollout frame's contacts raise no
scene's energy by more than the slack, momentum kept; an answer that adds no energy is left
as it is; training sees the network's own answer."""

from types import SimpleNamespace

import torch
from simdata import STATS, batch, learned, trajectory

from physgnn.graph.rules import GRAVITY
from physgnn.models.energy_guard import PARTED, contact_groups, guarded, parting_energy
from physgnn.models.protocol import motion_of
from physgnn.physics.energy import G

DT = 0.1
F64 = torch.float64


def pair(vel, angvel=None, scenes=None):
    """Two spheres (1 kg and 8 kg, radii 0.5 and 1) side by side 50 m up, gravity on, at
    ``vel [N, 3]``; ``scenes``: each sphere's scene (one scene by default)."""
    vel = torch.tensor(vel, dtype=F64)
    n = vel.shape[0]
    spin = torch.zeros(n, 3, dtype=F64) if angvel is None else torch.tensor(angvel, dtype=F64)
    state = SimpleNamespace(
        pos=torch.tensor([[0.0, 0, 50], [1.5, 0, 50]] * (n // 2), dtype=F64),
        vel=vel[:, None],
        angvel=spin[:, None],
        mass=torch.tensor([1.0, 8.0] * (n // 2), dtype=F64),
        radius=torch.tensor([0.5, 1.0] * (n // 2), dtype=F64),
        scene_dt=torch.full((n,), DT, dtype=F64),
        effects=torch.ones(1 if scenes is None else max(scenes) + 1, 6, dtype=torch.bool),
    )
    if scenes is not None:
        state.batch = torch.tensor(scenes)
        state.num_graphs = max(scenes) + 1
    return state


def free(state, share: float = 0.6):
    """Free flight ``(v + g·dt, ω, v + s·g·dt, ω)`` of ``state``."""
    g = torch.tensor([0.0, 0.0, -G * DT], dtype=F64)
    vel, ang = state.vel[:, 0], state.angvel[:, 0]
    return vel + g, ang, vel + share * g, ang


def kinetic(state, vel, ang):
    """``[N]``: each sphere's kinetic energy (J), translation and rotation."""
    inertia = 0.4 * state.mass * state.radius**2
    return 0.5 * (state.mass * (vel * vel).sum(1) + inertia * (ang * ang).sum(1))


def energy(state, moves):
    """``[B]``: each scene's energy after ``moves``, from its start's potential energy (J)."""
    vel, ang, mean, _ = moves
    per = kinetic(state, vel, ang) + state.mass * G * DT * mean[:, 2]
    scene = getattr(state, "batch", torch.zeros(len(per), dtype=torch.long))
    return per.new_zeros(int(scene.max()) + 1).index_add_(0, scene, per)


def energy_now(state):
    """``[N]``: each sphere's kinetic energy at the frame's start (J)."""
    return kinetic(state, state.vel[:, 0], state.angvel[:, 0])


def kicked(state, impulse):
    """Free flight plus an equal and opposite impulse ``impulse [3]`` (N·s) on the pair, in
    the end velocity and the move alike."""
    moves = list(free(state))
    push = torch.stack([impulse / state.mass[0], -impulse / state.mass[1]])
    push = push.repeat(state.pos.shape[0] // 2, 1)
    moves[0], moves[2] = moves[0] + push, moves[2] + push
    return tuple(moves)


def test_an_answer_that_creates_energy_is_cut_to_the_start_energy_with_momentum_kept():
    state = pair([[1.0, 0, 0], [-1.0, 0, 0]])
    moves = kicked(state, torch.tensor([-30.0, 0, 0], dtype=F64))  # far more than a bounce
    after = guarded(state, free(state), moves, None, slack=0.0)
    torch.testing.assert_close(energy(state, after)[0], energy_now(state).sum())
    mass = state.mass[:, None]
    for k in (0, 2):  # momentum of the end velocity and of the move as the answer's
        torch.testing.assert_close((mass * after[k]).sum(0), (mass * moves[k]).sum(0))
    # the cut is along the answer: the contact change keeps its direction
    change = after[0] - free(state)[0]
    assert torch.linalg.cross(change, moves[0] - free(state)[0]).abs().max() < 1e-12


def test_the_slack_is_a_height_of_the_scenes_weight():
    state = pair([[1.0, 0, 0], [-1.0, 0, 0]])
    moves = kicked(state, torch.tensor([-30.0, 0, 0], dtype=F64))
    after = guarded(state, free(state), moves, None, slack=0.002)
    allowed = energy_now(state).sum() + 0.002 * G * state.mass.sum()
    torch.testing.assert_close(energy(state, after)[0], allowed)


def test_an_answer_that_adds_no_energy_is_left_as_it_is():
    state = pair([[1.0, 0, 0], [-1.0, 0, 0]], angvel=[[0.0, 0, 1.0], [0, 0, 0]])
    inelastic = kicked(state, torch.tensor([-16.0 / 9.0, 0, 0], dtype=F64))  # the pair stops
    for moves in (inelastic, free(state)):
        after = guarded(state, free(state), moves, None, slack=0.0)
        for a, m in zip(after, moves, strict=True):
            torch.testing.assert_close(a, m)


def test_each_scene_has_its_own_factor_and_stopped_spheres_stay_stopped():
    # scene 0 an energetic answer, scene 1 a dissipative one
    state = pair([[1.0, 0, 0], [-1.0, 0, 0]] * 2, scenes=[0, 0, 1, 1])
    hot = kicked(state, torch.tensor([-30.0, 0, 0], dtype=F64))
    calm = kicked(state, torch.tensor([-16.0 / 9.0, 0, 0], dtype=F64))
    moves = tuple(torch.cat([h[:2], c[2:]]) for h, c in zip(hot, calm, strict=True))
    after = guarded(state, free(state), moves, None, slack=0.0)
    torch.testing.assert_close(energy(state, after)[0], energy_now(state)[:2].sum())
    for a, m in zip(after, moves, strict=True):
        torch.testing.assert_close(a[2:], m[2:])
    still = torch.tensor([True, False, False, False])
    stopped = tuple(torch.where(still[:, None], torch.zeros_like(m), m) for m in moves)
    after = guarded(state, free(state), stopped, still, slack=0.0)
    torch.testing.assert_close(after[0][0], torch.zeros(3, dtype=F64))
    assert energy(state, after)[0] <= energy_now(state)[:2].sum() + 1e-9


def test_a_scene_without_gravity_is_judged_on_its_kinetic_energy_alone():
    state = pair([[1.0, 0, 0], [-1.0, 0, 0]])
    state.effects[0, GRAVITY] = False
    still = (state.vel[:, 0], state.angvel[:, 0]) * 2  # free flight without gravity
    push = torch.tensor([[-30.0, 0, 5.0], [30.0 / 8.0, 0, -5.0 / 8.0]], dtype=F64)
    moves = (still[0] + push, still[1], still[2] + push, still[3])  # a move up and apart
    vel, ang = guarded(state, still, moves, None, slack=0.0)[:2]
    torch.testing.assert_close(kinetic(state, vel, ang).sum(), energy_now(state).sum())


def scene_energy(state, vel, ang, pos):
    """``state``'s one scene's energy (J) at ``vel``, ``ang``, ``pos`` ``[N, 3]``."""
    return float((kinetic(state, vel, ang) + state.mass * G * pos[:, 2]).sum())


@torch.no_grad()
def test_a_simulator_with_loud_random_weights_gains_no_energy_in_a_rollout_frame():
    torch.manual_seed(0)
    traj = trajectory(4, frames=3, seed=1)
    keys = dict(H=0, M=1, hidden=8, contact_passes=0, engine_state=True)
    sim = learned(STATS, **keys, energy_slack=0.0).eval()
    for name, weight in sim.network.named_parameters():  # it answers every contact loudly
        if "decoder" in name:
            weight.mul_(4.0)
    state = batch([traj], t=0, H=0)
    (vel, ang), (mean, _) = motion_of(sim(state))
    after = scene_energy(state, vel, ang, state.pos + DT * mean)
    before = scene_energy(state, state.vel[:, 0], state.angvel[:, 0], state.pos)
    parting = float(parting_energy(state, sim.graph_builder(state)).sum())  # one overlap
    assert after <= before + parting + 1e-6 * abs(before), (after, before, parting)
    unguarded = learned(STATS, **keys, energy_guard=False).eval()
    unguarded.load_state_dict(sim.state_dict())
    (vel_u, ang_u), (mean_u, _) = motion_of(unguarded(state))
    assert scene_energy(state, vel_u, ang_u, state.pos + DT * mean_u) > before  # it acted
    mass = state.mass[:, None]  # the pair impulses stay equal and opposite: momentum kept
    change = mass * (vel - state.vel[:, 0] - torch.tensor([0.0, 0.0, -G * DT]))
    assert change.sum(0).norm() <= 1e-5 * change.norm(dim=1).sum()
    sim.train()  # training sees the network's own answer
    torch.testing.assert_close(motion_of(sim(state))[0][0], vel_u)


def test_the_energy_to_part_an_overlap_is_its_reduced_mass_at_the_overlap_per_frame():
    state = pair([[0.0, 0, 0], [0.0, 0, 0]])
    state.pos[1, 0] = 1.492  # 8 mm into each other
    state.pos[:, 2] = 0.495  # the small one 5 mm into the ground (its one ps edge below)
    graph = SimpleNamespace(
        pp_index=torch.tensor([[1, 0], [0, 1]]),
        ps_index=torch.tensor([[0], [0]]),
        ps_attr=torch.tensor([[0.0, 0, 0, 0, 0, 1, 0, 0, 0.495, 0.495]], dtype=F64),
        pp_weight=lambda like: None,
        ps_weight=lambda like: None,
    )
    expected = 0.5 * (8.0 / 9.0) * (0.008 / DT) ** 2 + 0.5 * 1.0 * (0.005 / DT) ** 2
    torch.testing.assert_close(
        parting_energy(state, graph), torch.tensor([expected, 0.0], dtype=F64)
    )
    state.pos[1, 0] = 1.0  # half a metre deep: a network's error, parted only to PARTED
    expected = 0.5 * (8.0 / 9.0) * (PARTED / DT) ** 2 + 0.5 * 1.0 * (0.005 / DT) ** 2
    torch.testing.assert_close(parting_energy(state, graph)[0], torch.tensor(expected).double())


def graph_of(pairs, n_pp_attr: int = 1):
    """A hand-built graph of pp ``pairs`` (both directions) and no ps edge."""
    src, dst = torch.tensor(pairs, dtype=torch.long).T
    return SimpleNamespace(
        pp_index=torch.stack([torch.cat([src, dst]), torch.cat([dst, src])]),
        pp_attr=torch.zeros(2 * len(pairs), n_pp_attr, dtype=F64),
        ps_index=torch.zeros(2, 0, dtype=torch.long),
        ps_attr=torch.zeros(0, 10, dtype=F64),
        pp_weight=lambda like: None,
        ps_weight=lambda like: None,
    )


def test_contact_groups_are_the_spheres_linked_through_pp_edges():
    scene = torch.zeros(9, dtype=torch.long)
    chain = [(8, 7), (7, 6), (6, 5), (5, 4), (4, 3)]  # a chain 3..8, and 0–1 apart; 2 alone
    group, whole = contact_groups(graph_of(chain + [(1, 0)]), scene, 1)
    torch.testing.assert_close(group, torch.tensor([0, 0, 2, 3, 3, 3, 3, 3, 3]))
    assert bool(whole[0])
    group, whole = contact_groups(graph_of(chain), scene, 1, rounds=1)
    assert not bool(whole[0])  # one round does not settle a chain of six: one factor


def test_each_contact_group_has_its_own_factor():
    # one scene, two pairs apart: the first answers with energy, the second dissipates
    state = pair([[1.0, 0, 0], [-1.0, 0, 0]] * 2)
    state.pos[2:, 0] += 20.0
    hot = kicked(state, torch.tensor([-30.0, 0, 0], dtype=F64))
    calm = kicked(state, torch.tensor([-16.0 / 9.0, 0, 0], dtype=F64))
    moves = tuple(torch.cat([h[:2], c[2:]]) for h, c in zip(hot, calm, strict=True))
    graph = graph_of([(1, 0), (3, 2)])
    after = guarded(state, free(state), moves, None, slack=0.0, graph=graph)
    for a, m in zip(after, moves, strict=True):  # the calm pair keeps its answer
        torch.testing.assert_close(a[2:], m[2:])
    first = SimpleNamespace(**{**vars(state), "batch": torch.tensor([0, 0, 1, 1])})
    first.num_graphs = 2
    torch.testing.assert_close(energy(first, after)[0], energy_now(state)[:2].sum())
    # as one scene without its graph, the calm pair's loss pays for the other's gain
    scene_wide = guarded(state, free(state), moves, None, slack=0.0)
    assert energy(state, scene_wide)[0] <= energy_now(state).sum() + 1e-9
    assert not torch.allclose(scene_wide[0][2:], moves[0][2:])

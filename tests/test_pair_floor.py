"""The pairs' floor (physgnn/models/pair_floor.py): no pair's move closes its gap past contact,
momentum kept, for hand-built pairs and for a simulator with random weights."""

from types import SimpleNamespace

import torch
from simdata import STATS, batch, head_on, learned

from physgnn.models.pair_floor import pair_floor
from physgnn.models.protocol import motion_of

DT = 0.1


def spheres(pos, radius, mass):
    pos = torch.tensor(pos, dtype=torch.float64)
    n = pos.shape[0]
    return SimpleNamespace(
        pos=pos,
        radius=torch.tensor(radius, dtype=torch.float64),
        mass=torch.tensor(mass, dtype=torch.float64),
        scene_dt=torch.full((n,), DT, dtype=torch.float64),
    )


def paired(pairs):
    """``[2, 2P]``: each pair (src, dst) then its reverse, the paired layout."""
    src, dst = torch.tensor(pairs).T
    return torch.stack([torch.cat([src, dst]), torch.cat([dst, src])])


def test_a_head_on_pair_closes_its_gap_exactly_and_keeps_its_momentum():
    state = spheres([[0.0, 0, 0], [1.5, 0, 0]], [0.5, 1.0], [1.0, 8.0])  # gap 0, then 0.1 m?
    state.pos[1, 0] = 1.6  # gap 0.1 m: at most 1 m/s of closing in a frame of 0.1 s
    mean = torch.tensor([[2.0, 0, 0], [-2.0, 0, 0]], dtype=torch.float64)
    end = torch.tensor([[1.0, 0.5, 0], [-3.0, 0, 0]], dtype=torch.float64)
    after, end_after = pair_floor(state, paired([[0, 1]]), mean, end)
    torch.testing.assert_close(after[0, 0] - after[1, 0], torch.tensor(1.0, dtype=torch.float64))
    mass = state.mass[:, None]
    torch.testing.assert_close((mass * after).sum(0), (mass * mean).sum(0))
    torch.testing.assert_close((mass * end_after).sum(0), (mass * end).sum(0))
    # the end velocities no longer approach, and only along the normal were they changed
    torch.testing.assert_close(end_after[0, 0] - end_after[1, 0], torch.tensor(0.0).double())
    torch.testing.assert_close(end_after[:, 1:], end[:, 1:])


def test_a_pair_that_keeps_apart_or_is_masked_is_left_alone():
    state = spheres([[0.0, 0, 0], [2.0, 0, 0]], [0.5, 0.5], [1.0, 1.0])  # gap 1 m
    mean = torch.tensor([[4.0, 1, 0], [-4.0, 0, 2]], dtype=torch.float64)  # closes 0.8 m
    after, end = pair_floor(state, paired([[0, 1]]), mean, mean.clone())
    torch.testing.assert_close(after, mean)
    torch.testing.assert_close(end, mean)
    closing = torch.tensor([[9.0, 0, 0], [-9.0, 0, 0]], dtype=torch.float64)
    weight = torch.zeros(1, dtype=torch.float64)
    torch.testing.assert_close(
        pair_floor(state, paired([[0, 1]]), closing, weight=weight)[0], closing
    )


def test_a_row_pressed_from_both_ends_stops_overlapping_after_its_iterations():
    x = [0.0, 1.0, 2.0, 3.0]  # four touching unit spheres
    state = spheres([[v, 0, 0] for v in x], [0.5] * 4, [1.0, 2.0, 3.0, 4.0])
    mean = torch.tensor([[3.0, 0, 0], [0, 0, 0], [0, 0, 0], [-3.0, 0, 0]], dtype=torch.float64)
    pairs = paired([[0, 1], [1, 2], [2, 3]])
    after, _ = pair_floor(state, pairs, mean, iterations=40)
    moved = state.pos[:, 0] + DT * after[:, 0]
    assert (moved[1:] - moved[:-1]).min() > 1.0 - 1e-3  # Jacobi: the overlap falls geometrically
    unfloored = state.pos[:, 0] + DT * mean[:, 0]
    four = state.pos[:, 0] + DT * pair_floor(state, pairs, mean)[0][:, 0]  # the default 4
    assert (unfloored[1:] - unfloored[:-1]).min() < (four[1:] - four[:-1]).min() < 1.0
    mass = state.mass[:, None]
    torch.testing.assert_close((mass * after).sum(0), (mass * mean).sum(0))


def test_a_simulator_with_the_pair_floor_stops_a_collision_at_contact_with_random_weights():
    torch.manual_seed(0)
    traj = head_on()
    state = batch([traj], t=0, H=0)
    keys = dict(H=0, M=1, hidden=8, contact_passes=0)
    sims = [learned(STATS, **keys, pair_floor=on) for on in (False, True)]
    sims[1].load_state_dict(sims[0].state_dict())
    moves = [motion_of(sim.eval()(state))[1][0].detach() for sim in sims]
    mass = state.mass[:, None]
    torch.testing.assert_close((mass * moves[1]).sum(0), (mass * moves[0]).sum(0))
    moved = state.pos + DT * moves[1]
    gap = (moved[1] - moved[0]).norm() - state.radius.sum()
    assert gap > -1e-5, gap  # the gap of 0.1 m closes at most to contact

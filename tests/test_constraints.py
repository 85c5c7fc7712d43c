"""The constraint stage: analytic oracles for the projection and the wrapped simulator."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from handmade import DT, ballistic, scene
from simdata import learned
from torch.testing import assert_close

from physgnn.models.constrained import ConstrainedSimulator
from physgnn.physics.constraints import project_contacts
from physgnn.physics.scene import GROUND, STATIC, ground_plane, make_plane

T = torch.tensor
F64 = torch.float64
GROUND_ROW = T(ground_plane()[None], dtype=F64)
NO_PAIRS = torch.zeros(2, 0, dtype=torch.long)


def project(
    pos,
    pos_next,
    radius,
    mass,
    pairs=NO_PAIRS,
    planes=GROUND_ROW,
    kinds=(GROUND,),
    ps=None,
    iterations=1,
):
    pos, pos_next = T(pos, dtype=F64), T(pos_next, dtype=F64)
    ps = torch.zeros(2, 0, dtype=torch.long) if ps is None else T(ps)
    return project_contacts(
        pos,
        pos_next,
        T(radius, dtype=F64),
        T(mass, dtype=F64),
        T(pairs),
        planes,
        T(kinds),
        ps,
        iterations,
    )


def test_a_pair_separates_along_its_normal_with_its_momentum_kept():
    pos = [[0.0, 0.0, 5.0], [1.7, 0.3, 5.0]]  # apart now
    nxt = [[0.5, 0.1, 5.2], [1.0, 0.2, 4.9]]  # overlapping predicted
    radius, mass = [0.5, 1.0], [1.0, 3.0]
    x = project(pos, nxt, radius, mass, pairs=[[0], [1]])
    assert_close(float((x[0] - x[1]).norm()), 1.5)  # touching
    shift = x - T(nxt, dtype=F64)
    normal = T(nxt[0], dtype=F64) - T(nxt[1], dtype=F64)
    assert_close(
        torch.linalg.cross(shift[0], normal), torch.zeros(3, dtype=F64), atol=1e-12, rtol=0
    )
    momentum = 1.0 * shift[0] + 3.0 * shift[1]
    assert_close(momentum, torch.zeros(3, dtype=F64), atol=1e-12, rtol=0)
    assert_close(shift[0].norm() / shift[1].norm(), T(3.0, dtype=F64))  # the light one moves more


def test_a_pair_that_already_overlaps_is_not_pushed_apart():
    pos = [[0.0, 0.0, 5.0], [0.8, 0.0, 5.0]]  # overlapping by 0.2 now
    nxt = [[0.1, 0.0, 5.0], [0.7, 0.0, 5.0]]  # closing further
    x = project(pos, nxt, [0.5, 0.5], [1.0, 1.0], pairs=[[0], [1]])
    assert_close(float((x[0] - x[1]).norm()), 0.8)  # no deeper than now, no further apart


def test_a_sphere_that_would_pass_the_ground_ends_on_it():
    x = project([[1.0, 2.0, 1.0]], [[1.5, 2.5, -2.0]], [0.5], [1.0], ps=[[0], [0]])
    assert_close(x[0], T([1.5, 2.5, 0.5], dtype=F64))


def test_a_sphere_crossing_a_tilted_plane_in_one_frame_ends_on_its_front_face():
    ramp = make_plane((0, 0, 2), (0, np.sin(0.5), np.cos(0.5)), (1, 0, 0), 5.0, 5.0)
    planes = T(np.stack([ground_plane(), ramp]), dtype=F64)
    normal = planes[1, 3:6]
    start = planes[1, 0:3] + 1.0 * normal
    through = planes[1, 0:3] - 1.5 * normal + T([0.3, 0.0, 0.0], dtype=F64)  # behind, over it
    x = project(
        [start.tolist()],
        [through.tolist()],
        [0.5],
        [1.0],
        planes=planes,
        kinds=(GROUND, STATIC),
        ps=[[1], [0]],
    )
    assert_close(float(((x[0] - planes[1, 0:3]) * normal).sum()), 0.5)
    # a sphere behind the ramp's plane, beside it, is never lifted onto it
    below = (planes[1, 0:3] - 1.0 * normal + T([7.0, 0, 0], dtype=F64)).tolist()
    under = (planes[1, 0:3] - 1.0 * normal).tolist()
    x = project(
        [below], [under], [0.5], [1.0], planes=planes, kinds=(GROUND, STATIC), ps=[[1], [0]]
    )
    assert_close(x[0], T(under, dtype=F64))


def test_a_contact_grazed_by_rounding_does_not_halve_a_deep_one():
    wall = make_plane((3, 0, 5), (-1, 0, 0), (0, 1, 0), 5.0, 5.0)  # faces -x at x = 3
    planes = T(np.stack([ground_plane(), wall]), dtype=F64)
    # resting on the ground (a graze of 1e-9 predicted) and sent 0.2 into the wall in one frame
    x = project(
        [[2.0, 0.0, 0.5]],
        [[2.7, 0.0, 0.5 - 1e-9]],
        [0.5],
        [1.0],
        planes=planes,
        kinds=(GROUND, STATIC),
        ps=[[0, 1], [0, 0]],
    )
    assert_close(float(x[0, 0]), 2.5, atol=1e-8, rtol=0)  # back on the wall in one pass
    assert float(x[0, 2]) >= 0.5 - 1e-8


def test_a_sphere_from_behind_a_ramp_meets_its_edge_and_is_not_lifted():
    ramp = make_plane((0, 0, 2), (0, 0, 1), (1, 0, 0), 5.0, 5.0)  # a table: edge at x = 5
    planes = T(np.stack([ground_plane(), ramp]), dtype=F64)
    # from below the table's plane, beside it, up into its edge (0.2 from it)
    x = project(
        [[6.0, 0.0, 1.0]],
        [[5.2, 0.0, 2.0]],
        [0.5],
        [1.0],
        planes=planes,
        kinds=(GROUND, STATIC),
        ps=[[1], [0]],
    )
    assert_close(float(x[0, 0]), 5.5)  # pushed off the edge, along the edge normal
    assert_close(float(x[0, 2]), 2.0)
    # from below, beside it, to under its footprint just behind it: kept r away, behind
    x = project(
        [[6.0, 0.0, 1.0]],
        [[4.0, 0.0, 1.8]],
        [0.5],
        [1.0],
        planes=planes,
        kinds=(GROUND, STATIC),
        ps=[[1], [0]],
    )
    assert_close(x[0], T([4.0, 0.0, 1.5], dtype=F64))


def test_a_stack_stays_put_and_loses_energy():
    pos = [[0.0, 0.0, 0.5], [0.0, 0.0, 1.5]]  # resting on the ground, one on the other
    fall = -9.81 * DT * DT
    nxt = [[0.0, 0.0, 0.5 + fall], [0.0, 0.0, 1.5 + fall]]
    x = project(
        pos, nxt, [0.5, 0.5], [1.0, 1.0], pairs=[[0], [1]], ps=[[0, 0], [0, 1]], iterations=40
    )
    assert_close(x, T(pos, dtype=F64), atol=1e-4, rtol=0)
    v_hat, v = (T(nxt, dtype=F64) - T(pos, dtype=F64)) / DT, (x - T(pos, dtype=F64)) / DT
    assert float((v**2).sum()) <= float((v_hat**2).sum())


def test_a_sphere_pressed_into_the_ground_by_a_pair_is_lifted_within_the_iteration():
    pos = [[0.0, 0.0, 0.5], [0.0, 0.0, 1.5]]  # resting, one on the other
    nxt = [[0.0, 0.0, 0.5], [0.0, 0.0, 1.1]]  # the top one sinks 0.4 into the lower one
    x = project(pos, nxt, [0.5, 0.5], [1.0, 1.0], pairs=[[0], [1]], ps=[[0, 0], [0, 1]])
    assert float(x[0, 2]) == 0.5  # the pair pushed it 0.2 down, the ground put it back
    assert_close(float(x[1, 2]), 1.3)  # its pair correction: half of the 0.4


def test_an_inactive_plane_edge_constrains_nothing():
    pos, nxt = T([[1.0, 2.0, 1.0]], dtype=F64), T([[1.5, 2.5, -2.0]], dtype=F64)
    one = T([0.5], dtype=F64)
    args = (NO_PAIRS, GROUND_ROW, T([GROUND]), T([[0], [0]]), 3)
    x = project_contacts(pos, nxt, one, one, *args, ps_active=T([False]))
    assert torch.equal(x, nxt)
    x = project_contacts(pos, nxt, one, one, *args, ps_active=T([True]))
    assert_close(x[0], T([1.5, 2.5, 0.5], dtype=F64))


def test_energy_never_rises_on_random_falls():
    gen = torch.Generator().manual_seed(0)
    for _ in range(20):
        n = 6
        pos = torch.rand(n, 3, generator=gen, dtype=F64) * T([4.0, 4.0, 0.0]) + T([0, 0, 0.6])
        pos[:, 2] += torch.arange(n, dtype=F64) * 1.2  # a column, apart
        vel = torch.randn(n, 3, generator=gen, dtype=F64) * 3
        mass = torch.rand(n, generator=gen, dtype=F64) + 0.5
        iu = torch.triu_indices(n, n, 1)
        ps = torch.stack([torch.zeros(n, dtype=torch.long), torch.arange(n)])
        x = project_contacts(
            pos,
            pos + DT * vel,
            torch.full((n,), 0.5, dtype=F64),
            mass,
            iu,
            GROUND_ROW,
            T([GROUND]),
            ps,
            10,
        )
        v = (x - pos) / DT
        kinetic_before = float((mass[:, None] * vel**2).sum())
        assert float((mass[:, None] * v**2).sum()) <= kinetic_before + 1e-9
        assert float(x[:, 2].min()) >= 0.5 - 1e-9  # nobody below the ground


def make_sim(**kwargs):
    torch.manual_seed(0)
    return learned(H=2, M=1, hidden=8, gravity_prior=True, **kwargs)


def test_a_scene_without_contact_is_untouched_bit_for_bit():
    sim = make_sim()
    state = ballistic(scene([[0, 0, 20], [5, 0, 30]], [[1, 2, -3], [0, 0, 4]], [0.5, 0.7]))
    answer = sim(state)
    wrapped = ConstrainedSimulator(sim, 5)
    for got, want in zip(wrapped(state), answer, strict=True):
        assert torch.equal(got, want)
    assert wrapped.H == 2 and wrapped.graph_builder is sim.graph_builder


def test_the_wrapped_step_keeps_spheres_out_of_the_ground():
    sim = make_sim()
    state = scene([[0, 0, 0.52], [3, 0, 0.5]], [[0, 0, -3.0], [0, 0, 0]], [0.5, 0.5])
    move = ConstrainedSimulator(sim, 5)(state)[2]  # the engine state's mean motion moves
    z_next = state.pos[:, 2] + DT * move[:, 2]
    assert float(z_next.min()) >= 0.5 - 1e-5


def test_a_sphere_sent_beyond_its_graphs_reach_still_meets_a_plane():
    """The prediction may move a sphere further than the graph's reach (its edges are drawn
    from the state's speed): the stage still keeps it out of every plane of its scene."""
    sim = make_sim()

    class Plunge(torch.nn.Module):
        H = 2

        def predict(self, state):
            vel, angvel, graph = sim.predict(state)
            return torch.zeros_like(vel) + T([0.0, 0.0, -100.0]), angvel, graph

    table = make_plane((0, 0, 2), (0, 0, 1), (1, 0, 0), 5.0, 5.0)
    state = ballistic(
        scene(
            [[0, 0, 10.0], [0, 0, 40.0]],
            [[0, 0, 0], [0, 0, 0]],
            [0.5, 0.5],
            planes=[ground_plane(), table],
            kinds=[GROUND, STATIC],
        )
    )
    _, _, graph = sim.predict(state)
    assert not (state.plane_kind[graph.ps_index[0]] == STATIC).any()  # no edge to the table
    vel, _ = ConstrainedSimulator(Plunge(), 3)(state)
    z_next = state.pos[:, 2] + DT * vel[:, 2]
    assert_close(z_next, T([2.5, 40.0 - 10.0], dtype=z_next.dtype))  # on the table; in the air


def test_constraints_need_a_learned_simulator():
    class Still(torch.nn.Module):
        H = 1

        def forward(self, state):
            return torch.zeros_like(state.pos), torch.zeros_like(state.pos)

    with pytest.raises(TypeError, match="learned simulator"):
        ConstrainedSimulator(Still(), 3)
    with pytest.raises(ValueError, match=">= 1"):
        ConstrainedSimulator(make_sim(), 0)

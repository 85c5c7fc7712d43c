"""The plane answers last (physgnn/models/floor.py): each ps edge a one-sided floor after the
pair impulses, by hand."""

from __future__ import annotations

import torch
from handmade import WALL_ROW, make_state
from torch.testing import assert_close

from physgnn.graph.builder import GraphBuilder
from physgnn.models.floor import contact_directions, plane_floor
from physgnn.physics.scene import WALL


def floor_of(state, mean, end=None):
    graph = GraphBuilder()(state, (mean,))
    return plane_floor(state, graph, mean, end)


def test_a_falling_sphere_stops_on_the_ground_and_its_end_velocity_does_not_approach():
    # r 0.5, centre 0.8 m up: clearance 0.3 m; falling at 10 m/s over dt 0.1 s would sink 0.7 m
    state = make_state([[0.0, 0, 0.8]], vel=[[1.0, 0, -10.0]], dt=0.1)
    mean, end = floor_of(state, torch.tensor([[1.0, 0, -10.0]]), torch.tensor([[1.0, 0, -11.0]]))
    assert_close(mean, torch.tensor([[1.0, 0, -3.0]]))  # it ends touching, sliding on
    assert_close(end, torch.tensor([[1.0, 0, 0.0]]))  # no normal approach; restitution is learned


def test_a_resting_sphere_keeps_still_and_one_clear_of_the_plane_is_untouched():
    state = make_state([[0.0, 0, 0.5], [5.0, 0, 3.0], [9.0, 0, 0.6]], dt=0.1)
    fall = torch.tensor([[0.0, 0, -0.98], [0.0, 0, -0.98], [0.0, 0, 2.0]])
    mean, end = floor_of(state, fall.clone(), fall.clone())
    assert_close(mean[0], torch.zeros(3))  # resting on the ground: gravity answered
    assert_close(end[0], torch.zeros(3))
    assert_close(mean[1:], fall[1:])  # 2.5 m above the ground; leaving the ground
    assert_close(end[1:], fall[1:])


def test_a_finite_difference_state_floors_its_move_only():
    state = make_state([[0.0, 0, 0.8]], dt=0.1)
    mean, end = floor_of(state, torch.tensor([[0.0, 0, -10.0]]))
    assert end is None
    assert_close(mean, torch.tensor([[0.0, 0, -3.0]]))


def test_a_wall_and_its_rim_answer_along_their_contact_direction():
    # the wall x = 4 faces −x over y ∈ [−2, 2]; one sphere before its face, one past its rim
    state = make_state([[3.2, 0, 2.0], [3.8, 2.4, 2.0]], planes=[WALL_ROW], kinds=[WALL], dt=0.1)
    move = torch.tensor([[10.0, 0, 0], [10.0, 0, 0]])
    graph = GraphBuilder()(state, (move,))
    direction, clearance = contact_directions(graph, state.radius)
    walls = graph.ps_index[0] == 1
    face = walls & (graph.ps_index[1] == 0)
    assert_close(direction[face], torch.tensor([[-1.0, 0, 0]]))
    assert_close(clearance[face], torch.tensor([0.3]))
    mean, _ = plane_floor(state, graph, move)
    assert_close(mean[0], torch.tensor([3.0, 0, 0]))  # stops touching the wall's face
    rim = walls & (graph.ps_index[1] == 1)
    if bool(rim.any()):  # past the rim: the direction from the rim's closest point
        assert_close(direction[rim].norm(dim=1), torch.ones(int(rim.sum())))
        assert float(direction[rim][0, 1]) > 0

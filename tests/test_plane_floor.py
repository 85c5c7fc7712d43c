"""The plane answers last (physgnn/models/floor.py): each ps edge a one-sided floor after the
pair impulses, by hand."""

from __future__ import annotations

import torch
from handmade import WALL_ROW, make_state
from torch.testing import assert_close

from physgnn.graph.builder import GraphBuilder
from physgnn.models.floor import contact_directions, plane_floor
from physgnn.physics.energy import G
from physgnn.physics.scene import WALL


def floor_of(state, mean, end=None, bounce=False):
    graph = GraphBuilder()(state, (mean,))
    return plane_floor(state, graph, mean, end, bounce)


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


def with_restitution(state, sphere: float, plane: float = 1.0):
    """The state with every sphere's restitution ``sphere`` and every plane's ``plane``."""
    n, s = state.pos.shape[0], state.planes.shape[0]
    state.material_params = torch.tensor([[sphere, 0.5, 0.0, 0.0]]).repeat(n, 1)
    state.plane_materials = torch.tensor([[plane, 1.0, 0.0, 0.0]]).repeat(s, 1)
    return state


def drop_apex(e_sphere: float, e_plane: float, height: float = 10.0, dt: float = 0.1) -> float:
    """The highest centre after the first rebound of a sphere (r 0.5) dropped from ``height``,
    every frame the ballistic move then the floor with its rebound (a network that adds
    nothing), sampled at the frames."""
    pos, vel, heights, rising = torch.tensor([[0.0, 0, height]]), torch.zeros(1, 3), [], False
    fall = torch.tensor([[0.0, 0, -G * dt]])
    for _ in range(60):
        state = with_restitution(make_state(pos, vel, dt=dt), e_sphere, e_plane)
        mean, end = floor_of(state, vel + 0.5 * fall, vel + fall, bounce=True)
        pos, vel = pos + dt * mean, end
        rising = rising or float(vel[0, 2]) > 0
        if rising:
            heights.append(float(pos[0, 2]))
        if rising and float(vel[0, 2]) < 0 and heights[-1] < heights[0]:
            break
    return max(heights)


def test_a_dropped_sphere_rebounds_by_newtons_law_to_e_squared_its_height():
    # e_c = e_sphere · e_plane; the apex of the rebound is e_c² times the drop (centre above
    # the contact height r), to the frame's sampling of the flight
    for e_sphere, e_plane in ((0.3, 1.0), (0.5, 1.0), (0.9, 0.8), (0.95, 1.0)):
        e = e_sphere * e_plane
        apex = drop_apex(e_sphere, e_plane) - 0.5
        assert abs(apex / (e * e * 9.5) - 1) < 0.01, (e_sphere, e_plane, apex)


def test_the_rebound_in_closed_form_at_a_wall():
    # no gravity along the wall's normal: at 10 m/s, 0.3 m from the face, the sphere meets it
    # after 0.03 s and leaves with e_c·10 = 6 m/s for the last 0.07 s of the frame
    state = make_state([[3.2, 0, 2.0]], vel=[[10.0, 0, 0]], planes=[WALL_ROW], kinds=[WALL])
    state = with_restitution(state, 0.6)
    move = torch.tensor([[10.0, 0, 0]])
    graph = GraphBuilder()(state, (move,))
    mean, end = plane_floor(state, graph, move, move.clone(), bounce=True)
    dt = float(state.dt[0])
    assert_close(end, torch.tensor([[-6.0, 0, 0]]))
    assert_close(mean, torch.tensor([[(0.3 - 6.0 * (dt - 0.03)) / dt, 0, 0]]))


def test_no_rebound_at_rest_nor_from_a_push_passed_down_a_stack():
    # a resting sphere, and one at rest pushed down by a pair impulse of 2 m/s (the weight of
    # the layers above): neither arrives in free flight, so the floor's answer stays inelastic
    state = with_restitution(make_state([[0.0, 0, 0.5], [5.0, 0, 0.5]], dt=0.1), 0.9)
    fall = torch.tensor([[0.0, 0, -0.98], [0.0, 0, -2.98]])
    mean, end = floor_of(state, fall.clone(), fall.clone(), bounce=True)
    assert_close(mean, torch.zeros(2, 3))
    assert_close(end, torch.zeros(2, 3))


def test_a_rebound_that_would_land_again_within_the_frame_counts_as_none():
    # arriving at 0.5 m/s with e 0.3: 0.15 m/s up cannot clear g·dt/2 before the frame ends
    state = with_restitution(make_state([[0.0, 0, 0.52]], vel=[[0, 0, -0.5]], dt=0.1), 0.3)
    fall = torch.tensor([[0.0, 0, -G * 0.1]])
    vel = state.vel[:, 0]
    mean, end = floor_of(state, vel + 0.5 * fall, vel + fall, bounce=True)
    assert_close(end, torch.zeros(1, 3))
    assert_close(mean, torch.tensor([[0.0, 0, -0.2]]))

"""The learned step followed by a constraint stage: :class:`ConstrainedSimulator`.

After each learned prediction ``v̂``, the predicted positions ``p + dt·v̂`` are projected
(:func:`physgnn.physics.constraints.project_contacts`, ``iterations`` Jacobi passes) on the
prediction's own pp pairs (no second neighbour search) and on every plane of each sphere's
scene (of scenes with surface contact): planes are few, and a sphere the network sends
further than its graph's reach (a fall sped up by the prediction) must still meet them. The
velocity returned is the one that reaches the corrected position, ``(x − p)/dt``, so the
semi-implicit Euler step of the rollout lands on it and position and velocity stay
consistent (as position-based dynamics does); a sphere that no constraint moved keeps ``v̂``
bit for bit, and ω is never changed. Opt-in everywhere (``rollout.constraints=N`` in ``make
eval``, ``constraints=N`` in ``physgnn.simulate``) and always reported as its own variant
beside the pure learned model.
"""

from __future__ import annotations

import torch
from torch import nn

from physgnn.data.state import host_sizes, scene_of_sphere
from physgnn.graph.candidates import scene_counts, scene_plane_pairs
from physgnn.models.protocol import engine_state_of
from physgnn.physics.constraints import project_contacts
from physgnn.physics.scene import EFFECT_NAMES

SURFACE_CONTACT = EFFECT_NAMES.index("surface_contact")


class ConstrainedSimulator(nn.Module):
    """Wraps a simulator with a ``predict(state) -> (vel, angvel, graph)`` method (the
    :class:`~physgnn.models.learned.LearnedSimulator`) and corrects its velocities (module
    doc). ``iterations`` ≥ 1."""

    def __init__(self, simulator, iterations: int):
        super().__init__()
        if not callable(getattr(simulator, "predict", None)):
            raise TypeError(
                f"constraints need a learned simulator (with its graph); "
                f"{type(simulator).__name__} has none"
            )
        if int(iterations) < 1:
            raise ValueError(f"constraints must be a whole number >= 1, got {iterations}")
        self.simulator = simulator
        self.iterations = int(iterations)

    @property
    def H(self) -> int:
        return self.simulator.H

    @property
    def effects_trained(self):
        return self.simulator.effects_trained

    @property
    def graph_builder(self):
        return self.simulator.graph_builder

    @property
    def network(self):
        return self.simulator.network

    def rotating(self, state) -> torch.Tensor:
        return self.simulator.rotating(state)

    def forward(self, state) -> tuple[torch.Tensor, ...]:
        """The learned step's answer after the constraint stage: the move (the frame's mean
        velocity ū; the velocity itself for a finite-difference state) corrected, and the
        engine state's end velocity changed by the same correction."""
        if not engine_state_of(self.simulator):
            vel, angvel, graph = self.simulator.predict(state)
            return self.correct(state, vel, graph), angvel
        (vel, angvel, mean_vel, mean_angvel), graph = self.simulator.predict_motion(state)
        moved = self.correct(state, mean_vel, graph)
        return vel + (moved - mean_vel), angvel, moved, mean_angvel

    def correct(self, state, vel: torch.Tensor, graph) -> torch.Tensor:
        """``[N, 3]``: ``vel`` after the constraint stage on ``graph``."""
        dt = state.scene_dt[:, None].to(vel.dtype)
        pos_next = state.pos + dt * vel
        graph = graph.compacted()  # the rules' own pairs (a fixed-capacity graph reads back)
        pairs = graph.pp_index[:, : graph.pp_index.shape[1] // 2]
        spheres, planes = host_sizes(state)
        scene = scene_of_sphere(state)
        counts = scene_counts(scene, len(spheres))
        plane, sphere = scene_plane_pairs(spheres, planes, state.plane_batch.long(), counts)
        surfaces = state.effects[scene[sphere], SURFACE_CONTACT]
        x = project_contacts(
            state.pos,
            pos_next,
            state.radius,
            state.mass,
            pairs,
            state.planes,
            state.plane_kind,
            torch.stack([plane, sphere]),
            self.iterations,
            ps_active=surfaces,
        )
        moved = (x != pos_next).any(1, keepdim=True)
        return torch.where(moved, (x - state.pos) / dt, vel)

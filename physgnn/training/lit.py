"""Lightning module: one-step loss, energy-increase penalty and input noise.

Loss of a batch of state pairs:

``L = MSE(normalised prediction, normalised target)
+ λ · mean_scenes max(E_{t+1} − E_t, 0) / Σ m g + λ_c · contact penalty + λ_r · rest BCE``

- The rest term (with the simulator's ``rest_decision``, :mod:`physgnn.models.rest`): binary
  cross-entropy of the seventh output against "at rest next frame", over the spheres in reach.
- Velocity noise is scaled to each sphere's regime (:func:`physgnn.training.noise.regime_scale`,
  ``noise.rest_scale``): a resting sphere gets a small share of it, so rest stays resolvable.

- MSE over the 6 normalised outputs of every sphere (:mod:`physgnn.models.outputs` explains the
  target); the 3 angular outputs of spheres whose scene has rotation off are left out, and
  with the simulator's gravity prior so is every sphere out of reach of a contact (its next
  velocity is ballistic, not the network's). The loss's graph is also built on the target
  velocities (``loss.truth_contacts``): a sphere that touches something in the truth is in reach.
- The contact penalty and the contact noise: :mod:`physgnn.training.contacts` (lengths in
  units of the simulator's ``length_scale``, the mean sphere diameter).
- ``E`` = kinetic + potential energy of a scene (:mod:`physgnn.physics.energy`, potential
  from the ground contact height); ``E_{t+1}`` is the energy after integrating the predicted
  ``v̂_{t+1}`` with :func:`physgnn.physics.integrator.euler_step`. Dividing a scene's energy
  increase by its weight ``Σ m·g`` turns joules into *metres of height gained per sphere
  mass*, so ``λ`` means the same for a scene of 1 or 300 spheres, light or heavy.
- Noise (training only), shaped like the errors a rollout feeds back: a random walk along
  each velocity history (``σ · std(v)`` at the latest velocity, ``σ`` in normalised units),
  integrated into the position, so the noisy ``p̃_t`` and ``ṽ`` are again finite differences of
  one another, as in a rollout; likewise ``σ · std(ω)`` on angular velocity histories, and
  ``σ`` per quaternion component then renormalised. Spheres of scenes without rotation keep
  their orientation and angular velocity. The velocity target is the one that brings the
  noisy position back onto the truth, ``v*_{t+1} = (p_{t+1} − p̃_t)/dt`` (as GNS does with
  accelerations): the model learns to undo its own drift, e.g. to push apart spheres that a
  rollout let overlap. ``ω_{t+1}`` stays the clean one.
- Push-forward (training only, ``pushforward.steps`` = K > 0): each batch first runs
  ``k ~ U{0..K}`` steps of the model itself, without gradients, from the noisy state, then
  takes the loss of the next step against ``(p_{t+k+1} − p̂_{t+k})/dt`` and ``ω_{t+k+1}``. The
  model so sees, and learns to correct, the states its own rollouts reach.
"""

from __future__ import annotations

import random
from dataclasses import asdict

import lightning as L
import torch

from physgnn.models.capture import compile_in_place, compile_simulator
from physgnn.models.learned import LearnedSimulator
from physgnn.models.outputs import angular_columns, velocity_changes
from physgnn.models.protocol import motion_of
from physgnn.physics.integrator import step
from physgnn.training.contacts import contact_penalty, perturb_contacts
from physgnn.training.epoch_means import EpochMeans
from physgnn.training.finite import FiniteWatch
from physgnn.training.losses import energy_increase, masked_mse, regime_weights, rest_loss
from physgnn.training.noise import add_noise, noise_seed
from physgnn.training.recipe import Compile, InputNoise, LossTerms, PushForward
from physgnn.training.schedule import lr_scheduler


@torch.no_grad()
def push_forward(state, simulator: LearnedSimulator, steps: int):
    """The state after ``steps`` frames of the simulator's own rollout from ``state``, with
    the targets of the frame after: ``(p_{t+k+1} − p̂_{t+k})/dt`` and ``ω_{t+k+1}``
    (``state.future_pos`` / ``future_angvel [N, K+1, 3]``, K ≥ steps); with the engine state
    those are the mean-motion targets, and the end velocities' are the engine's
    (``future_vel`` / ``future_end_angvel``)."""
    out = state.clone()
    dt = state.scene_dt
    for _ in range(steps):  # the rollout's own integration step
        (vel_next, angvel_next), mean = motion_of(simulator(out))
        rotating = simulator.rotating(out)
        moved = (out.pos, out.quat, out.vel, out.angvel, vel_next, angvel_next, dt, rotating)
        out.pos, out.quat, out.vel, out.angvel = step(*moved, mean=mean)
    motion = (state.future_pos[:, steps] - out.pos) / dt[:, None]
    if getattr(state, "future_vel", None) is None:
        out.target_vel, out.target_angvel = motion, state.future_angvel[:, steps]
        return out
    out.target_mean_vel, out.target_mean_angvel = motion, state.future_angvel[:, steps]
    out.target_vel = state.future_vel[:, steps]
    out.target_angvel = state.future_end_angvel[:, steps]
    return out


# The recipe's defaults (frozen: one instance serves every module)
DEFAULT_NOISE, DEFAULT_PUSHFORWARD = InputNoise(), PushForward()
DEFAULT_LOSS, DEFAULT_COMPILE = LossTerms(), Compile()


class LitSimulator(L.LightningModule):
    """Trains a :class:`LearnedSimulator` on one-step pairs.

    ``optimizer``: a partial (``_partial_: true``) taking the parameters; ``scheduler``: an
    optional partial taking the optimizer, stepped once per epoch, or a
    :class:`~physgnn.training.schedule.RunLengthDecay` over the trainer's run length (the
    default: :mod:`physgnn.training.schedule`). ``seed`` seeds the noise (and the DDP process)
    and the push-forward length of each step together with the step number. The recipe's
    groups (:mod:`physgnn.training.recipe`, their defaults and units): ``noise`` (input and
    contact noise), ``pushforward`` (the model's own unroll before the loss), ``loss`` (the
    terms' weights; with ``truth_contacts`` the loss's graph is built on the state's motion and
    on its target velocities, :meth:`losses`, so every contact of the truth has its edges and
    its spheres count in the loss: the rebuild passes of a rollout find these edges from the
    model's own provisional velocities, ``contact_passes``) and ``compile`` (the regions of
    :meth:`compile_regions`; weights and checkpoints are the same as without).
    """

    def __init__(
        self,
        simulator: LearnedSimulator,
        optimizer,
        scheduler=None,
        seed: int = 0,
        noise: InputNoise = DEFAULT_NOISE,
        pushforward: PushForward = DEFAULT_PUSHFORWARD,
        loss: LossTerms = DEFAULT_LOSS,
        compile: Compile = DEFAULT_COMPILE,
    ):
        super().__init__()
        groups = {"noise": noise, "pushforward": pushforward, "loss": loss, "compile": compile}
        self.save_hyperparameters({"seed": int(seed)} | {k: asdict(g) for k, g in groups.items()})
        self.simulator = simulator
        self.optimizer_factory = optimizer
        self.scheduler_factory = scheduler
        self.seed = int(seed)
        self.noise, self.pushforward, self.loss_terms = noise, pushforward, loss
        if compile.enabled:
            self.compile_regions(compile.mode, compile.shapes)
        self._finite, self._train_means = FiniteWatch(), EpochMeans()

    def compile_regions(self, mode: str = "default", shapes: int = 16, **options) -> None:
        """What ``compile.enabled`` compiles (``options``: ``backend``, as
        :func:`~physgnn.models.capture.compile_in_place`). Graphs padded to buckets (fixed
        shapes, what CUDA graphs replay): the network alone, static. Otherwise regions with
        dynamic shapes: the simulator's graph rules and its step after the graph build
        (:func:`compile_simulator`: push-forward, rollouts) and the losses after theirs."""
        if getattr(self.simulator, "padded", False):
            compile_in_place(self.simulator.network, mode, False, shapes, **options)
            return
        compile_simulator(self.simulator, mode, shapes, **options)
        compile_in_place(self, mode, True, shapes, method="graph_losses", **options)

    def losses(self, state) -> dict[str, torch.Tensor]:
        """``{"loss", "loss_mse", "loss_energy", "energy_share", "loss_contact", "loss_rest"}``
        of a batch (no noise added here); ``energy_share`` = ``λ·energy / loss``, the part of
        the loss the energy term is (logged, so that a λ sweep shows whether the term mattered
        at all). With ``truth_contacts`` the graph is also built on the target velocities."""
        provisional = self.simulator.recalled(state)
        provisional += (state.target_vel,) if self.loss_terms.truth_contacts else ()
        graph = self.simulator.graph_builder(state, provisional)
        return self.graph_losses(state, graph, provisional)

    def graph_losses(self, state, graph, provisional=()) -> dict[str, torch.Tensor]:
        """:meth:`losses` on ``graph``, built from ``state`` with ``provisional`` velocities:
        the simulator's one :meth:`~physgnn.models.learned.LearnedSimulator.step`, as in a
        rollout, then the terms on its outputs."""
        sim = self.simulator
        outputs = sim.step(state, graph, provisional)
        target = sim.normalized_target(state)
        pred = velocity_changes(outputs.out, sim.outputs)
        angular = angular_columns(sim.outputs)
        terms = self.loss_terms
        counted = outputs.reach
        if terms.event_share > 0:
            share, speed = terms.event_share, terms.event_speed
            counted = regime_weights(state, sim, counted, share, speed)
        mse = masked_mse(pred, target, sim.rotating(state), counted, angular)
        energy = energy_increase(state, outputs.vel, outputs.mean_vel).mean()
        weighted = terms.lambda_energy * energy
        tol = terms.contact_tol * sim.length_scale
        contact = contact_penalty(state, outputs.mean_vel, graph, tol, sim.delta_speed_scale)
        rest = rest_loss(sim, state, outputs.out, outputs.reach)
        loss = mse + weighted + terms.lambda_contact * contact + terms.lambda_rest * rest
        share = (weighted / loss.clamp_min(1e-30)).detach()
        return {
            "loss": loss,
            "loss_mse": mse,
            "loss_energy": energy,
            "energy_share": share,
            "loss_contact": contact,
            "loss_rest": rest,
        }

    def _log_all(self, prefix: str, losses: dict, batch_size: int) -> None:
        """Epoch means under the exact names ``{prefix}/loss`` etc. (weighted by scene count;
        with DDP, averaged over the processes)."""
        for name, value in losses.items():
            self.log(
                f"{prefix}/{name}",
                value,
                batch_size=batch_size,
                on_step=False,
                on_epoch=True,
                prog_bar=name == "loss",
                sync_dist=True,
            )

    def _noise_generator(self) -> torch.Generator:
        """Seeded by (seed, DDP process, global step) (:func:`noise_seed`): a resumed run draws
        the same noise as a straight one, and every process its own."""
        generator = torch.Generator(device=self.device)
        return generator.manual_seed(noise_seed(self.seed, self.global_step, self.global_rank))

    def _unroll_length(self) -> int:
        """Push-forward steps of this batch, ``U{0..K}`` (0 before ``pushforward.after``; K
        grown as :class:`~physgnn.training.recipe.PushForward` says), drawn on the host from
        (seed, global step), the same in every DDP process: no value of the device is read."""
        push = self.pushforward
        if push.steps == 0 or self.global_step < push.after:
            return 0
        high = push.steps + 1
        if push.growth > 0:
            high = min(high, 2 + (self.global_step - push.after) // push.growth)
        return random.Random(noise_seed(self.seed, self.global_step)).randrange(high)

    def training_step(self, batch, batch_idx: int) -> torch.Tensor:
        generator = self._noise_generator()
        noise = self.noise
        if noise.std > 0:
            batch = add_noise(batch, self.simulator, noise.std, generator, noise.rest_scale)
        if noise.contacts:
            scale = self.simulator.length_scale  # a tensor: no read-back to the host
            depth, touch = scale * noise.contact_depth, scale * noise.contact_touch
            graph = self.simulator.graph_builder(batch)
            batch = perturb_contacts(batch, graph, depth, touch, noise.contact_prob, generator)
        steps = self._unroll_length()
        if steps > 0:
            batch = push_forward(batch, self.simulator, steps)
        losses = self.losses(batch)
        loss = losses["loss"]
        last = self._trainer is not None and self.trainer.is_last_batch
        self._finite.update(loss, self.current_epoch, self.global_step, last)
        self._train_means.add(losses, batch.num_graphs)
        if (
            self._trainer is not None
            and (self.global_step + 1) % self.trainer.log_every_n_steps == 0
        ):
            self.log("train/loss_step", loss, batch_size=batch.num_graphs, on_step=True)
        return loss

    def on_train_epoch_end(self) -> None:
        """The epoch means of the training losses (:mod:`physgnn.training.epoch_means`)."""
        for name, value in self._train_means.pop().items():
            self.log(f"train/{name}", value, prog_bar=name == "loss", sync_dist=True)

    def validation_step(self, batch, batch_idx: int) -> None:
        self._log_all("val", self.losses(batch), batch.num_graphs)

    def configure_optimizers(self):
        optimizer = self.optimizer_factory(self.parameters())
        if self.scheduler_factory is None:
            return optimizer
        scheduler = lr_scheduler(self.scheduler_factory, optimizer, self._trainer)
        return {"optimizer": optimizer, "lr_scheduler": scheduler}

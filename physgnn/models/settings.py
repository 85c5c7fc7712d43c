"""A trained model at one of its own settings: the knobs that change how a loaded model runs,
not what it learned, set on a copy of it.

A *learned setting* is a name and a mapping of :data:`KNOBS` (``make bench``'s
``crossover.learned_settings``, ``make eval``'s ``learned_settings``): ``contact_passes`` (graph
rebuilds within a frame, :class:`~physgnn.models.options.ContactHandling`; absent or null: the
model's own), ``constraints`` (iterations of the constraint stage,
:class:`~physgnn.models.constrained.ConstrainedSimulator`; absent, null or 0: none),
``compile`` (the step compiled as :func:`~physgnn.models.capture.compile_simulator` does;
absent or null: the caller's default) and ``threads`` (torch's intra-op threads while it runs,
:func:`torch_threads`; absent or null: the caller's default). :func:`check_knobs` refuses a
bad one in one line naming its key; :func:`with_knobs` sets them.
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Mapping

import torch

from physgnn.errors import ConfigError
from physgnn.models.capture import compile_simulator
from physgnn.models.constrained import ConstrainedSimulator
from physgnn.ranges import Allowed, whole

# The knobs a learned setting may set, with their values (null: the default of the knob)
ALLOWED = {
    "contact_passes": whole(0, also=(None,), what="graph rebuilds within a frame", example=0),
    "constraints": whole(0, also=(None,), what="iterations of the constraint stage", example=5),
    "compile": Allowed(bool, also=(None,)),
    "threads": whole(1, also=(None,), what="torch threads", example=1),
}
KNOBS = tuple(ALLOWED)


def check_knobs(key: str, knobs, error: type = ConfigError) -> dict:
    """The knobs of the setting at ``key`` (e.g. ``learned_settings.passes0``) as a plain dict,
    each one of its :data:`ALLOWED` values; null is ``{}`` (the model as it is). Refused in one
    line naming the key: not a mapping, a knob not in :data:`KNOBS`, a value out of range."""
    if knobs is None:
        return {}
    if not isinstance(knobs, Mapping):
        raise error(
            f"{key} must be a mapping of knobs ({', '.join(KNOBS)}), got {knobs!r} "
            f"(e.g. {key}={{contact_passes: 0}})"
        )
    unknown = sorted(set(knobs) - set(KNOBS))
    if unknown:
        raise error(
            f"{key}: unknown knob {', '.join(map(str, unknown))} (knobs: {', '.join(KNOBS)})"
        )
    return {k: ALLOWED[k].check(f"{key}.{k}", knobs[k], error=error) for k in knobs}


def with_contact_passes(sim, passes: int):
    """``sim`` with at most ``passes`` graph rebuilds within a frame
    (:class:`~physgnn.models.options.ContactHandling` ``contact_passes``), in place."""
    sim.contacts = dataclasses.replace(sim.contacts, contact_passes=int(passes))
    return sim


def with_knobs(sim, knobs: dict, threads: int, compile: bool = False, cache_dir=None):
    """``sim`` (a :class:`~physgnn.models.learned.LearnedSimulator` of its own: changed in
    place) at the knobs ``knobs`` (checked by :func:`check_knobs`); ``threads`` and
    ``compile``: the defaults of those knobs, ``cache_dir``: the compiled code's
    (:func:`~physgnn.models.capture.use_cache_dir`). Returns ``(simulator, used)``: the
    simulator to roll out (wrapped by the constraint stage when it has one) and every knob of
    :data:`KNOBS` as it runs."""
    if knobs.get("contact_passes") is not None:
        with_contact_passes(sim, knobs["contact_passes"])
    passes = int(sim.contacts.contact_passes)
    compiled = bool(compile if knobs.get("compile") is None else knobs["compile"])
    if compiled:  # as lit.compile.enabled=true: two regions, dynamic shapes
        compile_simulator(sim, cache_dir=cache_dir)
    constraints = int(knobs.get("constraints") or 0)
    if constraints:
        sim = ConstrainedSimulator(sim, constraints)
    used = {
        "contact_passes": passes,
        "constraints": constraints,
        "compile": compiled,
        "threads": int(knobs.get("threads") or threads),
    }
    return sim, used


@contextlib.contextmanager
def torch_threads(n: int | None):
    """torch's intra-op threads set to ``n`` inside the block, restored after it; None: left
    as they are. Gives the block the count it runs on (``with torch_threads(n) as ran_on``)."""
    before = torch.get_num_threads()
    torch.set_num_threads(int(n) if n is not None else before)
    try:
        yield torch.get_num_threads()
    finally:
        torch.set_num_threads(before)

"""The sizes of a scene family's config (``data.scene``, ``data.fit_scene``, ``data.ood.<x>``)
checked before any scene is drawn, each mistake one line naming its key: an arena narrower than
its largest sphere would otherwise end the generation at some scene with "sphere of radius
... does not fit in the spawn volume", naming no key.

A rule applies where the family's config has the key (``random_box`` and its pile, dense and
rest scenes have them all); a bound may be another key's value (``side_min >= 2 ×
radius_max``). The radii are the family's own check (``random_box``).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

from physgnn.ranges import number, whole


def _diameter(c: Mapping) -> float:
    return 2 * float(c.get("radius_max", 0.0))


# key -> (its least value from the config, what it is), checked in this order
NUMBERS: dict[str, tuple[Callable[[Mapping], float], str]] = {
    "side_min": (_diameter, "m, an arena's side: the largest sphere's diameter 2 × radius_max"),
    "side_max": (lambda c: c.get("side_min", 0.0), "m, at least side_min"),
    "pile_side_min": (_diameter, "m, a pile arena's side: at least 2 × radius_max"),
    "pile_side_max": (lambda c: c.get("pile_side_min", 0.0), "m, at least pile_side_min"),
    "h_max": (lambda c: c.get("radius_max", 0.0), "m, the highest centre: at least radius_max"),
    "pile_h_max": (lambda c: c.get("radius_max", 0.0), "m, at least radius_max"),
}
WHOLE: dict[str, tuple[Callable[[Mapping], int], str]] = {
    "n_min": (lambda c: 1, "spheres: a scene needs one"),
    "n_max": (lambda c: c.get("n_min", 1), "spheres, at least n_min"),
}


def check_family(c: Mapping, key_of: Callable[[str], str]) -> None:
    """Every size of the family config ``c`` within its range, else a ``ConfigError``
    naming ``key_of(key)`` (``data.scene.side_min``), the least value and the one given."""
    for key, (least, what) in WHOLE.items():
        if key in c:
            whole(int(least(c)), what=what).check(key_of(key), c[key])
    for key, (least, what) in NUMBERS.items():
        if key in c:
            bound = least(c)
            least_ = bound if isinstance(bound, int | float) else 0
            number(least_, what=what).check(key_of(key), c[key])


def check_preset_scenes(scene: Mapping, fit: Mapping | None, ood: Mapping | None) -> None:
    """A preset's ``data.scene``, ``data.scene`` with ``data.fit_scene`` over it (each key named
    where it was set) and each ``data.ood`` scene, by :func:`check_family`."""
    fit = fit or {}
    check_family(scene, lambda key: f"data.scene.{key}")
    if fit:
        check_family(
            {**scene, **fit}, lambda key: f"data.{'fit_scene' if key in fit else 'scene'}.{key}"
        )
    for name, cfg in (ood or {}).items():
        check_family(cfg, lambda key, name=name: f"data.ood.{name}.{key}")

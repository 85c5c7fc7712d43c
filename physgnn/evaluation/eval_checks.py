"""The values of ``make eval``'s config, each checked before any run or dataset is read and
refused in one line naming its key (conf/eval.yaml); the seed frames a run needs, once the runs
are loaded."""

from __future__ import annotations

from collections.abc import Mapping

from omegaconf import DictConfig

from physgnn.errors import ConfigError
from physgnn.evaluation import learned_settings, onestep, same_work, turns
from physgnn.evaluation.bounce import check_settings as bounce_settings
from physgnn.evaluation.freefall import check_frames
from physgnn.evaluation.freefall import check_settings as freefall_settings
from physgnn.evaluation.rollouts import rollout_threads
from physgnn.evaluation.runs import RunInfo, check_runs
from physgnn.metrics import check_tolerance
from physgnn.models.protocol import hooks_of
from physgnn.ranges import FLAG, Allowed, check_seed, number, whole

# The eval's switches: true or false (``save_rollouts=maybe`` is refused, not taken as true).
FLAGS = (
    "overwrite",
    "videos",
    "save_rollouts",
    "sleeping_compare",
    "stability",
    "compile",
    "rerun",
)
# The eval's other values (conf/eval.yaml)
VALUES = {
    "report_dir": Allowed(str, what="a folder", example="outputs/report"),
    "dataset": Allowed(str, also=(None,), what="null: each run's own", example="outputs/data/tiny"),
    "max_frames": whole(2, also=(None,), what="whole trajectories", example=100, exact=True),
    "energy_runs": whole(0, what="learned runs drawn in the OOD energy figure", example=3),
    "video_frames": whole(1, what="frames of a video at most", example=60),
}
# Groups of settings measured only when given (null: not measured)
GROUPS = ("pybullet", "onestep", "freefall", "bounce", "invariance")
REST_FRAMES = whole(2, what="frames of the resting grids, the first the start", example=2000)
# The eval's rollout settings besides threads (conf/eval.yaml: rollout), and its hard scenes'
CONSTRAINTS = whole(0, also=(None,), what="iterations of the constraint stage; 0: none", example=0)
SLEEP = {
    "threshold": number(0, what="m/s", example=0.05),
    "k": whole(1, what="still frames", example=3),
    "touch": number(0, what="a fraction of the radius", example=0.1),
}
HARD_DIR = Allowed(str, what="a folder", example="outputs/data/hard")
REST_TOL = number(0, above=True, what="radii", example=0.01)


def check_eval_values(cfg: DictConfig) -> None:
    """Every value of ``cfg`` before any work, each refused in one line naming its key:
    ``runs`` (:func:`~physgnn.evaluation.runs.check_runs`), the :data:`VALUES` (``max_frames``
    null or a whole number >= 2: a rollout needs frames to predict), ``tol`` a number >= 0,
    each switch true or false, ``rollout`` (its ``threads`` before ``pybullet.processes``,
    which is it unless given), ``hard`` and the :data:`GROUPS`, ``learned_settings`` null or
    its settings' knobs."""
    check_runs(cfg.get("runs"))
    for key, allowed in VALUES.items():
        allowed.check(key, cfg.get(key))
    check_tolerance(cfg.get("tol"), ConfigError)
    for key in FLAGS:
        FLAG.check(key, cfg.get(key))
    check_rollout(cfg)
    check_hard(cfg)
    check_groups(cfg)
    learned_settings.check_settings(cfg.get("learned_settings"))


def check_groups(cfg: DictConfig) -> None:
    """Each of the :data:`GROUPS` null or a mapping of its settings, each checked by its own
    module (``invariance``: ``rest_frames``, :data:`REST_FRAMES`)."""
    for key in GROUPS:
        if cfg.get(key) is not None and not isinstance(cfg.get(key), Mapping):
            raise ConfigError(
                f"{key} must be null (not measured) or a mapping of its settings, got "
                f"{cfg.get(key)!r} (e.g. {key}=null)"
            )
    same_work.check_settings(cfg.get("pybullet"))
    turns.check_turns(cfg.get("pybullet"))
    onestep.check_settings(cfg.get("onestep"))
    freefall_settings(cfg.get("freefall"))
    bounce_settings(cfg.get("bounce"))
    checks = cfg.get("invariance") or {}
    if not set(checks) <= {"rest_frames"}:
        raise ConfigError(
            f"invariance takes rest_frames only, got {checks!r} (the default: "
            "invariance.rest_frames=2000)"
        )
    if "rest_frames" in checks:
        REST_FRAMES.check("invariance.rest_frames", checks["rest_frames"])


def check_seed_frames(cfg: DictConfig, runs: list[RunInfo]) -> None:
    """Each learned run has frames to predict in every fall of ``freefall`` and the resting
    grids of ``invariance``: more than its H + 1 seed frames (else a row would measure the
    seed, not a prediction)."""
    falls = freefall_settings(cfg.get("freefall"))
    rest = (cfg.get("invariance") or {}).get("rest_frames")
    for run in (r for r in runs if r.run_dir is not None):
        H = hooks_of(run.simulator).history or 0
        if falls is not None:
            check_frames(*falls, H, run.name)
        if rest is not None:
            what = f"run {run.name} starts from H + 1 = {H + 1} frames, then one to predict"
            whole(H + 2, what=what, example=2000).check("invariance.rest_frames", rest)


def check_rollout(cfg: DictConfig) -> None:
    """``cfg.rollout``: ``threads`` first (``pybullet.processes`` is it unless given), the
    switches, ``constraints`` and ``sleep`` (null or :data:`SLEEP`'s keys), each refused in
    one line naming its key."""
    r = cfg.get("rollout")
    if not isinstance(r, Mapping):
        raise ConfigError(
            "rollout must be the rollouts' settings (batch_scenes, threads, constraints, "
            f"sleeping, sleep), got {r!r} (set one of them instead, e.g. rollout.threads=1)"
        )
    rollout_threads(cfg)
    FLAG.check("rollout.batch_scenes", r.get("batch_scenes", True))
    FLAG.check("rollout.sleeping", r.get("sleeping", False))
    CONSTRAINTS.check("rollout.constraints", r.get("constraints"))
    sleep = r.get("sleep")
    if sleep is not None and (not isinstance(sleep, Mapping) or not set(sleep) <= set(SLEEP)):
        raise ConfigError(
            f"rollout.sleep must be null or a mapping of {', '.join(SLEEP)}, got {sleep!r} "
            "(the default: rollout.sleep={threshold: 0.05, k: 3, touch: 0.1})"
        )
    for key in sleep or {}:
        SLEEP[key].check(f"rollout.sleep.{key}", sleep[key])


def check_hard(cfg: DictConfig) -> None:
    """``cfg.hard``, the hard scenes of the stability section: its folder, seed and rest
    tolerance (null only with ``stability=false``)."""
    hard = cfg.get("hard")
    if hard is None and not cfg.get("stability"):
        return
    if not isinstance(hard, Mapping):
        raise ConfigError(
            f"hard must be the hard scenes' settings (null only with stability=false), got "
            f"{hard!r} (stability=false leaves the stability section out)"
        )
    HARD_DIR.check("hard.dir", hard.get("dir"))
    check_seed(hard.get("seed"), "hard.seed", "conf/eval.yaml: hard.seed")
    REST_TOL.check("hard.rest_tol", hard.get("rest_tol"))

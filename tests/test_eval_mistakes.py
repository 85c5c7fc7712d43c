"""``make eval``'s mistakes of value: each one line naming the key, the value given and the fix,
before any run or dataset is read (:func:`physgnn.evaluation.eval_checks.check_eval_values`); a
list of run folders is evaluated, each run once."""

from __future__ import annotations

import re

import pytest
from fakeruns import eval_cfg, evaluate_fake_runs
from hydra import compose, initialize_config_dir

from physgnn import CONF_DIR
from physgnn import eval as eval_command
from physgnn.errors import ConfigError
from physgnn.evaluation import bounce, freefall
from physgnn.evaluation.eval_checks import check_eval_values
from physgnn.evaluation.runs import EvalError
from physgnn.report.table import read_csv

RUNS = (
    "runs must be a run folder, a folder of runs or a non-empty list of them (null: every "
    "finished run under paths.outputs), got {} (e.g. runs=outputs/runs/default/seed0 or "
    "'runs=[outputs/runs/default/seed0,outputs/runs/default/seed1]'; a folder named by a "
    "number: runs=./5)"
)
BASELINE = "runs/baseline/2026-01-01_00-00-00"
M3 = "multirun/ablation_M/t0/model.network.M=3,seed=1"


def eval_config(*overrides: str):
    """The whole eval config (every group on, as ``make eval`` has it) with ``overrides``."""
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose("eval", overrides=list(overrides))


@pytest.mark.parametrize(
    "overrides,message",
    [
        (["runs=[]"], RUNS.format("[]")),
        (["runs=5"], RUNS.format("5")),
        (["runs=[a,5]"], RUNS.format("['a', 5]")),
        (
            ["freefall.heights=[-10]"],
            "freefall.heights[0] must be a number >= 5.04905 (m: at least one frame's fall, "
            "g·dt²/2, above freefall.floor=5), got -10 (e.g. freefall.heights=[10.0, 100.0, "
            "1000.0])",
        ),
        (
            ["freefall.heights=10"],
            "freefall.heights must be a list of heights (m), got 10 (e.g. "
            "freefall.heights=[10.0, 100.0, 1000.0])",
        ),
        (
            ["freefall.dt=0"],
            "freefall.dt must be a number > 0 (s between frames), got 0 (e.g. freefall.dt=0.1)",
        ),
        (
            ["freefall.seconds=0"],
            "freefall.seconds must be a number >= 0.1 (s: at least one frame of freefall.dt), "
            "got 0 (e.g. freefall.seconds=4.0)",
        ),
        (
            ["freefall.floor=-3"],
            "freefall.floor must be a number >= 0.5 (m: the sphere's centre, kept off the "
            "ground), got -3 (e.g. freefall.floor=5.0)",
        ),
        (
            ["freefall=5"],
            "freefall must be null (not measured) or a mapping of its settings, got 5 "
            "(e.g. freefall=null)",
        ),
        (
            ["bounce.height=-5"],
            "bounce.height must be a number > 0 (m, the sphere's bottom above the ground), "
            "got -5 (e.g. bounce.height=10.0)",
        ),
        (
            ["bounce.radius=0"],
            "bounce.radius must be a number > 0 (m), got 0 (e.g. bounce.radius=0.75)",
        ),
        (
            ["bounce.dt=-0.1"],
            "bounce.dt must be a number > 0 (s between frames), got -0.1 (e.g. bounce.dt=0.1)",
        ),
        (
            [
                "bounce.materials=[{restitution: 0, lateral_friction: 0.5, "
                "rolling_friction: 0.01, spinning_friction: 0.01}]"
            ],
            "bounce.materials[0].restitution must be a number in (0, 1] (the apex is e² of the "
            "drop), got 0 (e.g. {restitution: 0.5, lateral_friction: 0.5, rolling_friction: "
            "0.01, spinning_friction: 0.01})",
        ),
        (
            ["bounce.materials=[{restitution: 0.5}]"],
            "bounce.materials[0] must be a material of the keys restitution, lateral_friction, "
            "rolling_friction, spinning_friction, got {'restitution': 0.5} (e.g. {restitution: "
            "0.5, lateral_friction: 0.5, rolling_friction: 0.01, spinning_friction: 0.01})",
        ),
        (
            ["hard.seed=-1"],
            "hard.seed must be a whole number from 0 to 4294967295, got -1 (conf/eval.yaml: "
            "hard.seed; e.g. hard.seed=0)",
        ),
        (
            ["hard.rest_tol=0"],
            "hard.rest_tol must be a number > 0 (radii), got 0 (e.g. hard.rest_tol=0.01)",
        ),
        (
            ["hard=null"],
            "hard must be the hard scenes' settings (null only with stability=false), got None "
            "(stability=false leaves the stability section out)",
        ),
        (
            ["invariance.rest_frames=1"],
            "invariance.rest_frames must be a whole number >= 2 (frames of the resting grids, "
            "the first the start), got 1 (e.g. invariance.rest_frames=2000)",
        ),
        (
            ["energy_runs=-1"],
            "energy_runs must be a whole number >= 0 (learned runs drawn in the OOD energy "
            "figure), got -1 (e.g. energy_runs=3)",
        ),
        (
            ["video_frames=0"],
            "video_frames must be a whole number >= 1 (frames of a video at most), got 0 "
            "(e.g. video_frames=60)",
        ),
        (
            ["rollout.threads=0"],
            "rollout.threads must be a whole number >= 1 or null (torch threads), got 0 "
            "(e.g. rollout.threads=1)",
        ),
        (
            ["pybullet.processes=0"],
            "pybullet.processes must be a whole number >= 1 or null (one per core), got 0 "
            "(e.g. pybullet.processes=1)",
        ),
        (
            ["rollout.constraints=1.5"],
            "rollout.constraints must be a whole number >= 0 or null (iterations of the "
            "constraint stage; 0: none), got 1.5 (e.g. rollout.constraints=0)",
        ),
        (
            ["rollout.sleep.k=0"],
            "rollout.sleep.k must be a whole number >= 1 (still frames), got 0 "
            "(e.g. rollout.sleep.k=3)",
        ),
        (
            ["rollout.sleeping=maybe"],
            "rollout.sleeping must be true or false, got 'maybe' (e.g. rollout.sleeping=true)",
        ),
        (
            ["rollout=null"],
            "rollout must be the rollouts' settings (batch_scenes, threads, constraints, "
            "sleeping, sleep), got None (set one of them instead, e.g. rollout.threads=1)",
        ),
        (["compile=maybe"], "compile must be true or false, got 'maybe' (e.g. compile=true)"),
        (["rerun=maybe"], "rerun must be true or false, got 'maybe' (e.g. rerun=true)"),
        (
            ["dataset=5"],
            "dataset must be a string or null (null: each run's own), got 5 "
            "(e.g. dataset=outputs/data/tiny)",
        ),
        (
            ["report_dir=5"],
            "report_dir must be a string (a folder), got 5 (e.g. report_dir=outputs/report)",
        ),
    ],
)
def test_a_wrong_eval_value_is_one_line_naming_the_key(overrides, message):
    with pytest.raises(ConfigError) as caught:
        check_eval_values(eval_config(*overrides))
    assert str(caught.value) == message


def test_the_default_eval_config_passes_and_the_groups_read_as_numbers():
    cfg = eval_config()
    check_eval_values(cfg)
    assert freefall.check_settings(cfg.freefall) == ([10.0, 100.0, 1000.0], 4.0, 0.1, 5.0)
    materials, height, dt, radius = bounce.check_settings(cfg.bounce)
    assert materials[0] == [0.7, 0.5, 0.005, 0.005] and (height, dt, radius) == (10.0, 0.1, 0.75)
    check_eval_values(eval_config("freefall=null", "bounce=null", "stability=false", "hard=null"))


@pytest.mark.parametrize(
    "override,message",
    [
        ("runs=[]", "error: " + RUNS.format("[]")),
        (
            "rollout.threads=0",
            "error: rollout.threads must be a whole number >= 1 or null (torch threads), got 0 "
            "(e.g. rollout.threads=1)",
        ),
    ],
)
def test_the_command_prints_the_one_line_and_exits_2(tmp_path, capsys, override, message):
    cfg = eval_cfg(override, f"paths.outputs={tmp_path}", f"report_dir={tmp_path / 'r'}")
    with pytest.raises(SystemExit) as exit_:
        eval_command.main.__wrapped__(cfg)  # the Hydra task itself, without the process around it
    assert exit_.value.code == 2
    assert capsys.readouterr().err.strip() == message
    assert not (tmp_path / "r").exists()


def test_a_list_of_run_folders_is_evaluated_each_run_once(tmp_path):
    outputs = tmp_path / "outputs"
    runs = f"{outputs}/{BASELINE},{outputs}/multirun/ablation_M/t0,{outputs}/{BASELINE}"
    report = evaluate_fake_runs(outputs, f"runs=[{runs}]", "videos=false", "pybullet=null")
    rows = read_csv(outputs / "report" / "metrics.csv")
    learned = [r["run"] for r in rows if r["run"] in (BASELINE, M3)]
    assert set(learned) == {BASELINE, M3}
    assert learned.count(BASELINE) == learned.count(M3)  # the baseline's rows once, not twice
    assert "status diverged" in report.read_text()  # the sweep's diverged run is named


def test_video_run_not_evaluated_lists_the_runs_that_are(tmp_path):
    message = (
        f"video_run nosuchrun is not among the evaluated runs ({M3}, {BASELINE}): name one of "
        "them, or leave video_run=null to film the first baseline run"
    )
    with pytest.raises(EvalError, match=f"^{re.escape(message)}$"):
        evaluate_fake_runs(tmp_path / "outputs", "video_run=nosuchrun")
    assert not (tmp_path / "outputs" / "report" / "report.md").exists()


def test_a_fall_shorter_than_a_runs_seed_frames_is_refused_before_any_rollout(tmp_path):
    message = (
        f"freefall.heights[0]=5.1 gives 1 frame(s) of fall (above freefall.floor=5, within "
        f"freefall.seconds=4) and run {M3} needs 2 (its H + 1 = 2 seed frames, then one to "
        "predict): give heights from 5.1962 m and freefall.seconds from 0.2"
    )
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        evaluate_fake_runs(tmp_path / "outputs", "freefall.heights=[5.1]")
    assert not (tmp_path / "outputs" / "report" / "metrics.csv").exists()


def test_resting_grids_shorter_than_a_runs_seed_frames_are_refused(tmp_path):
    message = (
        "invariance.rest_frames must be a whole number >= 3 (run "
        f"{M3} starts from H + 1 = 2 frames, then one to predict), got 2 "
        "(e.g. invariance.rest_frames=2000)"
    )
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        evaluate_fake_runs(tmp_path / "outputs", "invariance={rest_frames: 2}")

"""Values a command took for something else: each is now one line naming the key or file and
the fix (a scene file's duplicate key, whole frames, switches, speeds; eval's switches)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from trainkit import SHORT, outputs_of, run_main

from physgnn import CONF_DIR
from physgnn.errors import ConfigError
from physgnn.evaluation import simulate as simulate_module
from physgnn.evaluation.evaluate import evaluate
from physgnn.groundtruth.scenefile import load_scene, scene_from_dict
from physgnn.physics.scene import MAX_FRAMES, Effects, SceneError

ROOT = Path(__file__).resolve().parents[1]
SPHERE = "spheres:\n  - {radius: 0.5, position: [0, 0, 1]%s}\n"


@pytest.mark.parametrize(
    "text,message",
    [
        (
            "frames: 5\nframes: 7\n" + SPHERE % "",
            "not valid YAML (line 2): key 'frames' given twice (keep one)",
        ),
        (
            "spheres:\n  - {radius: 0.5, radius: 0.4, position: [0, 0, 1]}\n",
            "not valid YAML (line 2): key 'radius' given twice (keep one)",
        ),
        (
            "frames: 2.5\n" + SPHERE % "",
            "frames must be a whole number >= 2 (frames to simulate, "
            "the first is the start), got 2.5 (e.g. frames: 100)",
        ),
        (
            "effects: {gravity: 'no'}\n" + SPHERE % "",
            "effects: effect gravity must be true or false, got 'no'",
        ),
        (
            "effects: {rotation: 1}\n" + SPHERE % "",
            "effects: effect rotation must be true or false, got 1",
        ),
        (
            SPHERE % ", velocity: [1e30, 0, 0]",
            "sphere 0 starts at 1e+30 m/s, which carries it "
            "farther in the scene's 9.9 s than float32 resolves a radius of 0.5 m: give speeds "
            "below 5050.4 m/s",
        ),
    ],
)
def test_a_scene_file_value_taken_for_another_is_one_line(tmp_path, text, message):
    path = tmp_path / "s.yaml"
    path.write_text(text)
    with pytest.raises(SceneError) as err:
        load_scene(path)
    assert str(err.value).startswith(f"{path}: ") and str(err.value).endswith(message)
    assert "\n" not in str(err.value)


def test_a_fast_scene_within_float32_and_whole_frames_as_floats_load(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("frames: 1e1\n" + SPHERE % ", velocity: [1000, 0, 0]")
    assert load_scene(path).n_frames == 10


def test_effects_read_from_a_file_take_numpy_booleans():
    assert Effects.from_dict({"gravity": np.bool_(False)}).gravity is False


@pytest.mark.parametrize("key", ["save_rollouts", "overwrite", "videos", "stability"])
def test_an_eval_switch_that_is_not_true_or_false_is_refused(tmp_path, key):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose("eval", overrides=[f"paths.outputs={tmp_path}", f"{key}=maybe"])
    message = f"{key} must be true or false, got 'maybe' (e.g. {key}=true)"
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        evaluate(cfg)
    assert not (tmp_path / "report").exists()


@pytest.mark.parametrize(
    "override,message",
    [
        (
            "lit.compile.mode=fastest",
            "lit.compile.mode must be one of default, reduce-overhead, "
            "max-autotune, max-autotune-no-cudagraphs, got 'fastest'",
        ),
        ("lit.compile.shapes=0", "lit.compile.shapes must be a whole number >= 1"),
        (
            "trainer.precision=fp8",
            "trainer.precision must be one of transformer-engine, "
            "transformer-engine-float16, "
            "16-true, 16-mixed, bf16-true, bf16-mixed, 32-true, 64-true, got 'fp8'",
        ),
    ],
)
def test_compile_and_precision_words_are_one_line_while_compile_is_off(
    tiny_dataset, tmp_path, monkeypatch, capsys, override, message
):
    args = ["data=tiny", f"paths.outputs={outputs_of(tiny_dataset)}", f"run_dir={tmp_path}"]
    code, line = run_main(monkeypatch, capsys, *args, *SHORT, "lit.compile.enabled=false", override)
    assert code == 2 and line.startswith(f"error: {message}")


def test_a_billion_frames_are_refused_above_the_documented_cap(tmp_path):
    path = tmp_path / "s.yaml"
    path.write_text("frames: 1000000000\n" + SPHERE % "")
    with pytest.raises(SceneError) as err:
        load_scene(path)
    assert str(err.value) == (
        f"{path}: scene 'scene': 1000000000 frames is more than {MAX_FRAMES} (a trajectory is "
        "kept whole in memory; 1e9 frames of pybullet would run for years): simulate at most "
        f"{MAX_FRAMES} frames, or a longer dt"
    )
    schema = json.loads((ROOT / "docs" / "scene.schema.json").read_text())
    assert schema["properties"]["frames"]["maximum"] == MAX_FRAMES == 100_000


def test_a_long_simulation_says_so_off_a_terminal(monkeypatch, capsys):
    scene = scene_from_dict({"frames": 3, "spheres": [{"radius": 0.5, "position": [0, 0, 1]}]})
    scene.n_frames = simulate_module.LONG  # one sphere: the least that is long
    monkeypatch.setattr(simulate_module, "engine_simulate", lambda s, on_frame=None: s)
    simulate_module.simulate_with_progress(scene)
    assert capsys.readouterr().err.startswith(
        f"simulating with pybullet: 1 spheres, {simulate_module.LONG} frames ...\n"
    )

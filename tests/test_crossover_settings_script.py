"""scripts/crossover_settings.py: the bench's crossover alone, at learned settings given as a
YAML mapping."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SPEC = importlib.util.spec_from_file_location(
    "crossover_settings", ROOT / "scripts/crossover_settings.py"
)
script = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(script)


def test_settings_that_are_not_a_mapping_are_refused_in_one_line(monkeypatch):
    monkeypatch.setattr(sys, "argv", ["crossover_settings.py", "pretrained", "--settings", "[1]"])
    with pytest.raises(SystemExit, match="--settings must be a mapping of name to knobs"):
        script.main()


@pytest.mark.slow
def test_the_shipped_model_at_two_settings_on_small_piles(monkeypatch, tmp_path, capsys):
    out = tmp_path / "crossover.json"
    settings = "{as_trained: {}, passes0: {contact_passes: 0}}"
    argv = ["x", "pretrained", "--sizes", "10", "--settings", settings, "--out", str(out)]
    monkeypatch.setattr(sys, "argv", argv)
    script.main()
    result = json.loads(out.read_text())
    assert result["settings"]["passes0"]["contact_passes"] == 0
    assert [(c["n_spheres"], c["window"]) for c in result["cases"]] == [
        (10, "in_motion"),
        (10, "landed"),
    ]
    names = [p["simulator"] for p in result["cases"][1]["points"]]
    assert names[:2] == ["learned as_trained", "learned passes0"]
    assert "10 spheres, landed" in capsys.readouterr().out

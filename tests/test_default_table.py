"""``make default-table``: the default model's table regenerated from a registry, each row
naming the commit it was measured on (marked when it is not this checkout's)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from physgnn.ablation.default_table import main

ROOT = Path(__file__).resolve().parents[1]


def record(seed: int, mse: float, commit: str, diverged: int | None = None) -> dict:
    ood = [
        {"trajectory": s, "mse": 10.0 * (i + 1), "max_depth_sphere": 0.5, "diverged_at": None}
        for i, s in enumerate(
            ["ood_cubes", "ood_cubes_ramps", "ood_resting_hit", "ood_spaced_drop"]
        )
    ]
    ood[0]["diverged_at"] = diverged
    test = [{"trajectory": "traj_00000", "mse": mse, "chamfer": mse / 2, "diverged_at": None}]
    return {
        "key": "baseline",
        "seed": seed,
        "status": "finished",
        "commit": commit,
        "date": "2026-01-01 00:00",
        "budget": {"steps": 300},
        "checkpoint": {"step": 250},
        "splits": {"test": test, "ood": ood},
    }


def test_the_default_table_names_each_rows_commit(tmp_path, capsys):
    head = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    registry, out = tmp_path / "registry.jsonl", tmp_path / "default.md"
    lines = [record(0, 30.0, head), record(1, 34.0, "0000000", diverged=12)]
    lines.append(record(2, 99.0, head) | {"key": "model.network.M=1"})  # another configuration
    registry.write_text("".join(json.dumps(r) + "\n" for r in lines))
    assert main([str(registry), str(out)]) == 0
    rows = [line for line in out.read_text().splitlines() if line.startswith("| ")]
    assert rows[1].startswith(f"| 0 | `{head}` | 2026-01-01 00:00 | 250 | 30 | 15 | 10 | 20 |")
    assert rows[2].startswith("| 1 | `0000000` * | 2026-01-01 00:00 | 250 | 34 | 17 | ∞ (diverged)")
    assert rows[3].startswith("| mean ± std | | | | 32 ± 2.83 | 16 ± 1.41 | 10 (1 of 2 seeds")
    assert len(rows) == 4
    assert main([str(registry), str(out), "model.H=0"]) == 2
    assert capsys.readouterr().err == (
        "error: the registry holds no measured run of model.H=0: run make study first\n"
    )

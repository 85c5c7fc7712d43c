"""The study report, from the registry alone: ``docs/results/README.md`` and its figures."""

from __future__ import annotations

from pathlib import Path

from physgnn.files import write_text


def write_study_report(records: list[dict], configs, cfg) -> Path:
    lines = ["# Ablation study", ""]
    for r in records:
        lines.append(f"- {r['key']} seed {r['seed']}: {r['status']}")
    return write_text(Path(cfg.results_dir) / "README.md", "\n".join(lines) + "\n")

"""``report.md`` and its figures from ``metrics.csv`` (written by the eval), the stability
table and the bench results."""

from __future__ import annotations

from pathlib import Path

from physgnn.files import write_text
from physgnn.report import bounce, freefall, invariance, onestep, pareto, same_work, stability
from physgnn.report.sections import (
    baselines_table,
    components_section,
    sleeping_section,
    table1,
)
from physgnn.report.sweeps import fps_figure, rel, sweep_sections
from physgnn.report.table import SLEEP_SCENE, group_rows, read_csv


def pareto_section(rows: list[dict], fig_dir: Path, root: Path) -> str:
    """Accuracy against ms per frame on the same work: the learned runs and pybullet's rows,
    a table per split and the Pareto figures."""
    if not same_work.engine_groups(rows):
        return same_work.section(rows)
    paths = pareto.pareto_figures(rows, fig_dir)
    return "\n\n".join(
        [
            "Every simulator from the same start states (each trajectory's first H+1 truth "
            "frames; pybullet restarts from frame H at the truth's other settings), scored with "
            "the same metrics against the same truth; means over the rollouts. frames/s: as the "
            "learned rollouts were timed (batched scenes: pybullet runs each split's scenes in "
            "pybullet.processes processes, as many as the learned rollouts' threads unless "
            "set, every row the split's scene-frames per second, each split timed again in "
            "pybullet.turns rounds of every learned rollout then every pybullet setting, the "
            "median; one scene at a time: both in one process; a simulator's frames/s: its "
            "rows' frames over their seconds, so that ms/frame is the mean cost of a frame); "
            "threads: the cores a row ran on (a learned rollout's torch threads, the eval's "
            "rollout.threads or its setting's; "
            "pybullet's processes). pybullet's own curve on the bench pile is in the bench "
            "report (bench.md).",
            same_work.section(rows),
            *(f"![{p.stem}]({rel(p, root)})" for p in paths),
        ]
    )


def stability_section(root: Path) -> str:
    """The stability table from ``root/stability.csv`` (written by the eval's ``stability``)."""
    path = root / "stability.csv"
    if not path.exists():
        return "No stability measurements (`make eval` with `stability=true` writes them)."
    return stability.section(stability.read_csv(path))


def freefall_section(root: Path) -> str:
    """The free-fall table from ``root/freefall.csv`` (written by the eval)."""
    path = root / "freefall.csv"
    return freefall.section(freefall.read_csv(path) if path.exists() else [])


def invariance_section(root: Path) -> str:
    """The invariance checks from ``root/invariance.csv`` (written by the eval)."""
    path = root / "invariance.csv"
    return invariance.section(invariance.read_csv(path) if path.exists() else [])


def onestep_section(root: Path) -> str:
    """The one-step error by regime from ``root/onestep.csv`` (written by the eval)."""
    path = root / "onestep.csv"
    return onestep.section(onestep.read_csv(path) if path.exists() else [])


def bounce_section(root: Path) -> str:
    """The bounce table from ``root/bounce.csv`` (written by the eval)."""
    path = root / "bounce.csv"
    return bounce.section(bounce.read_csv(path) if path.exists() else [])


def write_report(
    report_dir: str | Path, rows: list[dict] | None = None, skipped: list[str] | None = None
) -> Path:
    """Write ``report.md`` (and the sweep / FPS / Pareto figures) from ``report_dir/metrics.csv``.

    Figures the eval already wrote (``figures/energy_ood.png``, ``videos/*.gif`` and
    ``.mp4``) are linked; the Pareto view needs pybullet's rows (the eval's ``pybullet``).
    """
    root = Path(report_dir)
    rows = read_csv(root / "metrics.csv") if rows is None else rows
    fig_dir = root / "figures"
    parts = [
        "# physgnn evaluation report",
        f"{len({r['run'] for r in rows})} runs (with the references ground_truth, static, "
        "gravity_only), metrics per rollout in `metrics.csv`. Every cell is the mean ± std "
        "over the rollouts of a group (trajectories × seeds). ⚠ marks a group where a "
        "rollout diverged: its metrics are computed on the finite prefix.",
        "## Table 1: ground truth",
        table1(rows),
        "## Learned simulators against the trivial baselines",
        baselines_table(rows),
        "## Table 2: ablation of components (OOD first)",
        components_section(rows),
        "## Experiments and sweeps",
        *sweep_sections(rows, fig_dir, root),
        f"## OOD (c) `{SLEEP_SCENE}` with sleeping off and on",
        sleeping_section(rows),
        "## One-step error by regime",
        onestep_section(root),
        "## Stability on hard scenes",
        stability_section(root),
        "## Free fall against ½gt²",
        freefall_section(root),
        "## Bounces against restitution",
        bounce_section(root),
        "## Invariances of rigid contact",
        invariance_section(root),
    ]
    parts += _figures(rows, root)
    if skipped:
        parts += ["## Runs not evaluated", "\n".join(f"- {s}" for s in skipped)]
    return write_text(root / "report.md", "\n\n".join(parts) + "\n")


def _video_line(gif: Path, root: Path) -> str:
    """``- [scene](videos/scene.gif) ([MP4](videos/scene.mp4))``, the MP4 when there is one."""
    mp4 = gif.with_suffix(".mp4")
    return f"- [{gif.stem}]({rel(gif, root)})" + (
        f" ([MP4]({rel(mp4, root)}))" if mp4.exists() else ""
    )


def _figures(rows: list[dict], root: Path) -> list[str]:
    """The sections of figures and videos: runtime, Pareto view, OOD energy, videos."""
    fig_dir = root / "figures"
    fps = fps_figure(fig_dir / "fps.png", group_rows(rows))
    energy = fig_dir / "energy_ood.png"
    videos = sorted((root / "videos").glob("*.gif"))
    return [
        "## Runtime (the report's Figure 18)",
        f"![fps]({rel(fps, root)})" if fps else "No learned rollout timed.",
        "## Accuracy versus time on the same work (Pareto view)",
        pareto_section(rows, fig_dir, root),
        "## Energy over time on the OOD scenes",
        f"![energy]({rel(energy, root)})" if energy.exists() else "No OOD energy figure.",
        "## Videos (ground truth left, prediction right; shaded 3-D)",
        "\n".join(_video_line(v, root) for v in videos) or "No videos.",
    ]

"""The learning curve: one row per checkpoint step, from an eval's rows, and its figure."""

from __future__ import annotations

from physgnn.report.learning_curve import curve_rows, main, plot_curve


def metrics_row(run, split, mse, diverged_at=None):
    return {"run": run, "split": split, "trajectory": "t0", "mse": mse, "diverged_at": diverged_at}


def hard_row(run, scene, source="hard", diverged_at=None, **values):
    return {"run": run, "scene": scene, "source": source, "diverged_at": diverged_at, **values}


def test_rows_per_step_in_order_with_the_measures_of_each_checkpoint(tmp_path):
    metrics = [
        metrics_row("m/step004500", "test", 2.0),
        metrics_row("m/step004500", "test", 4.0),
        metrics_row("m/step002250", "test", 9.0),
        metrics_row("m/step002250", "ood", 99.0),
        metrics_row("runs/default/x", "test", 1.0),
    ]
    hard = [
        hard_row("m/step002250", "ood_cubes", max_pen_sphere=0.7),
        hard_row("m/step002250", "resting_pile", rest_drift=27.0),
        hard_row("m/step004500", "ood_cubes", max_pen_sphere=0.6),
    ]
    fall = [
        {"run": "m/step002250", "z_error_pct": -2.0},
        {"run": "m/step002250", "z_error_pct": 4.0},
    ]
    rows = curve_rows(metrics, hard, fall)
    assert [r["step"] for r in rows] == [2250, 4500]  # a run without a step is left out
    assert rows[0]["test_mse"] == 9.0 and rows[1]["test_mse"] == 3.0
    assert rows[0]["ood_mse"] == 99.0 and rows[1]["ood_mse"] is None
    assert rows[0]["freefall_pct"] == 3.0 and rows[1]["freefall_pct"] is None
    assert rows[0]["cubes_depth"] == 0.7 and rows[0]["pile_drift"] == 27.0
    assert rows[1]["pile_drift"] is None and rows[1]["tight_depth"] is None
    assert rows[0]["diverged"] == rows[1]["diverged"] == ""
    assert plot_curve(rows, tmp_path / "curve.png").stat().st_size > 0


def test_a_diverged_rollout_has_no_mse_and_is_named(tmp_path):
    metrics = [
        metrics_row("m/step002250", "test", 2.0),
        metrics_row("m/step002250", "ood", 1.0, diverged_at=12),
        metrics_row("m/step002250", "ood", 50.0),
    ]
    hard = [
        hard_row("m/step002250", "tight_pack", diverged_at=40, max_pen_sphere=0.1),
        hard_row("m/step002250", "ood_cubes", "ood", diverged_at=12, max_pen_sphere=0.2),
    ]
    (row,) = curve_rows(metrics, hard)
    assert row["test_mse"] == 2.0 and row["ood_mse"] is None  # no average over a prefix
    assert row["diverged"] == "ood/t0@12 tight_pack@40"  # OOD scenes named once, from metrics
    assert plot_curve([row], tmp_path / "curve.png").stat().st_size > 0


def test_a_report_without_its_tables_is_one_line(tmp_path, capsys):
    assert main([str(tmp_path)]) == 2
    out = capsys.readouterr().out
    assert out.startswith("error: ") and out.strip().endswith(
        "run make eval over the checkpoints first"
    )

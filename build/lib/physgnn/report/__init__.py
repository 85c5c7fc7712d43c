"""Reports: metrics.csv and stability.csv, report.md with its figures, the Pareto view."""

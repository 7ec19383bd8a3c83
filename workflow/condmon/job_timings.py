"""Per-job wall time and peak memory of a run, from the benchmark files Snakemake writes for every
rule with a `benchmark:` directive (columns `s`, `max_rss` in MB, `cpu_time`, ...)."""
from __future__ import annotations

from pathlib import Path

import pandas as pd

COLUMNS = ["rule", "jobs", "wall_seconds_total", "wall_seconds_median", "wall_seconds_max", "cpu_seconds_total",
           "peak_rss_mb_max"]


def read_benchmarks(folder) -> pd.DataFrame:
    """One row per job: `rule` (the first folder or file name under `folder`), `job`, and the
    benchmark columns. No folder or no file: an empty frame."""
    folder = Path(folder)
    rows = []
    for path in sorted(folder.rglob("*.tsv")) if folder.is_dir() else []:
        relative = path.relative_to(folder)
        frame = pd.read_csv(path, sep="\t")
        if frame.empty:
            continue
        frame = frame.assign(rule=relative.parts[0].removesuffix(".tsv"), job=str(relative.with_suffix("")))
        rows.append(frame)
    return pd.concat(rows, ignore_index=True) if rows else pd.DataFrame(columns=["rule", "job", "s", "max_rss"])


def summarise(folder) -> pd.DataFrame:
    """Per rule: jobs, total / median / longest wall seconds, CPU seconds, largest peak RSS (MB)."""
    jobs = read_benchmarks(folder)
    if jobs.empty:
        return pd.DataFrame(columns=COLUMNS)
    numeric = {c: pd.to_numeric(jobs[c], errors="coerce") for c in ("s", "max_rss", "cpu_time") if c in jobs}
    jobs = jobs.assign(**numeric)
    if "cpu_time" not in jobs:
        jobs["cpu_time"] = float("nan")
    grouped = jobs.groupby("rule", sort=True)
    out = pd.DataFrame({"jobs": grouped.size(), "wall_seconds_total": grouped["s"].sum(),
                        "wall_seconds_median": grouped["s"].median(), "wall_seconds_max": grouped["s"].max(),
                        "cpu_seconds_total": grouped["cpu_time"].sum(), "peak_rss_mb_max": grouped["max_rss"].max()})
    return out.reset_index()[COLUMNS].round(2)

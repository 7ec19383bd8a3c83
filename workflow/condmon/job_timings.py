"""Per-job wall time and peak memory of a run, from the benchmark files Snakemake writes for every
rule with a `benchmark:` directive (columns `s`, `max_rss` in MB, `cpu_time`, ...)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

COLUMNS = [
    "rule",
    "jobs",
    "wall_seconds_total",
    "wall_seconds_median",
    "wall_seconds_max",
    "cpu_seconds_total",
    "peak_rss_mb_max",
]


def read_benchmarks(files_by_rule: dict) -> pd.DataFrame:
    """One row per job: `rule`, `job` (its file's name) and the benchmark columns, from
    {rule: its jobs' benchmark files}. An empty file (a job Snakemake could not measure) gives no
    row; no file: an empty frame."""
    rows = []
    for rule, paths in files_by_rule.items():
        for path in map(Path, paths):
            frame = pd.read_csv(path, sep="\t")
            if not frame.empty:
                rows.append(frame.assign(rule=rule, job=path.stem))
    return (
        pd.concat(rows, ignore_index=True)
        if rows
        else pd.DataFrame(columns=["rule", "job", "s", "max_rss"])
    )


def summarise(files_by_rule: dict) -> pd.DataFrame:
    """Per rule: jobs, total / median / longest wall seconds, CPU seconds, largest peak RSS (MB)."""
    jobs = read_benchmarks(files_by_rule)
    if jobs.empty:
        return pd.DataFrame(columns=COLUMNS)
    numeric = {
        c: pd.to_numeric(jobs[c], errors="coerce")
        for c in ("s", "max_rss", "cpu_time")
        if c in jobs
    }
    jobs = jobs.assign(**numeric)
    if "cpu_time" not in jobs:
        jobs["cpu_time"] = float("nan")
    grouped = jobs.groupby("rule", sort=True)
    out = pd.DataFrame(
        {
            "jobs": grouped.size(),
            "wall_seconds_total": grouped["s"].sum(),
            "wall_seconds_median": grouped["s"].median(),
            "wall_seconds_max": grouped["s"].max(),
            "cpu_seconds_total": grouped["cpu_time"].sum(),
            "peak_rss_mb_max": grouped["max_rss"].max(),
        }
    )
    return out.reset_index()[COLUMNS].round(2)

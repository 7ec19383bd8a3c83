"""Per-job wall time and peak memory of a run, from the benchmark files Snakemake writes for every
rule with a `benchmark:` directive (columns `s`, `max_rss` in MB, `cpu_time`, ...), and the run's
elapsed time against its CPU work: a benchmark file is written when its job ends, so its
modification time less the job's wall seconds is when the job started."""

from __future__ import annotations

from pathlib import Path

import numpy as np
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
RUN_ROW = (
    "run"  # the row of the whole run: its elapsed seconds, CPU seconds and parallel efficiency
)
RUN_COLUMNS = ["cores", "cpu_seconds_per_core", "parallel_efficiency"]


def read_benchmarks(files_by_rule: dict) -> pd.DataFrame:
    """One row per job: `rule`, `job` (its file's name) and the benchmark columns, from
    {rule: its jobs' benchmark files}. An empty file (a job Snakemake could not measure) gives no
    row; no file: an empty frame."""
    rows = []
    for rule, paths in files_by_rule.items():
        for path in map(Path, paths):
            frame = pd.read_csv(path, sep="\t")
            if not frame.empty:
                rows.append(frame.assign(rule=rule, job=path.stem, end=path.stat().st_mtime))
    return (
        pd.concat(rows, ignore_index=True)
        if rows
        else pd.DataFrame(columns=["rule", "job", "s", "max_rss"])
    )


def summarise(files_by_rule: dict, cores: int | None = None) -> pd.DataFrame:
    """Per rule: jobs, total / median / longest wall seconds, CPU seconds, largest peak RSS (MB);
    with `cores` (the run's `--cores`) a last row `run` (`run_row`)."""
    return summarise_jobs(read_benchmarks(files_by_rule), cores)


def summarise_jobs(jobs: pd.DataFrame, cores: int | None = None) -> pd.DataFrame:
    """`summarise` of the jobs `read_benchmarks` read."""
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
    out = out.reset_index()[COLUMNS]
    if cores:
        out = pd.concat([out, run_row(jobs, cores)], ignore_index=True)
    return out.round(2)


def timeline(jobs: pd.DataFrame) -> pd.DataFrame:
    """One row per job of those `read_benchmarks` read, in the order the jobs started: `rule`,
    `job`, `start` and `end` in seconds from the first job's start, `cpu_seconds`; empty where no
    job was measured."""
    if jobs.empty:
        return pd.DataFrame(columns=["rule", "job", "start", "end", "cpu_seconds"])
    wall = pd.to_numeric(jobs["s"], errors="coerce")
    start = jobs["end"] - wall
    cpu = pd.to_numeric(jobs.get("cpu_time", pd.Series(float("nan"), index=jobs.index)), "coerce")
    out = pd.DataFrame(
        {
            "rule": jobs["rule"],
            "job": jobs["job"],
            "start": start - start.min(),
            "end": jobs["end"] - start.min(),
            "cpu_seconds": cpu,
        }
    )
    return out.sort_values(["start", "rule", "job"], kind="stable").reset_index(drop=True)


def busy_cores(jobs: pd.DataFrame, step: float = 1.0) -> pd.DataFrame:
    """The timeline's jobs running at each `step` seconds (`time`, `jobs`) and the cores their CPU
    work kept busy on average (`cores`: each job's CPU seconds spread evenly over its wall time)."""
    end = float(jobs["end"].max()) if len(jobs) else 0.0
    times = np.arange(0.0, end + step, step)
    running = np.zeros_like(times)
    cores = np.zeros_like(times)
    for row in jobs.itertuples():
        inside = (times >= row.start) & (times < row.end)
        running += inside
        wall = row.end - row.start
        if wall > 0 and np.isfinite(row.cpu_seconds):
            cores += inside * row.cpu_seconds / wall
    return pd.DataFrame({"time": times, "jobs": running, "cores": cores})


def run_row(jobs: pd.DataFrame, cores: int) -> pd.DataFrame:
    """The run as one row: `wall_seconds_total` its elapsed seconds, from the first job's start to
    the last job's end (the jobs `read_benchmarks` read), `cpu_seconds_total` its jobs' CPU
    seconds; `cpu_seconds_per_core` those over `cores`, the least the run could take, and
    `parallel_efficiency` that least over the elapsed seconds (1: every core busy all along)."""
    start, end = (jobs["end"] - jobs["s"]).min(), jobs["end"].max()
    elapsed, cpu = float(end - start), float(jobs["cpu_time"].sum())
    per_core = cpu / cores
    return pd.DataFrame(
        [
            {
                "rule": RUN_ROW,
                "jobs": len(jobs),
                "wall_seconds_total": elapsed,
                "wall_seconds_median": float("nan"),
                "wall_seconds_max": elapsed,
                "cpu_seconds_total": cpu,
                "peak_rss_mb_max": float(jobs["max_rss"].max()),
                "cores": cores,
                "cpu_seconds_per_core": per_core,
                "parallel_efficiency": per_core / elapsed if elapsed > 0 else float("nan"),
            }
        ]
    )

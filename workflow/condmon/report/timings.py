"""The job timings section: per rule the jobs' wall time and peak memory (condmon.job_timings,
from the benchmark files of every job before the report) and the run's elapsed time against its
CPU seconds over the cores (row `run`): job_timings.csv, its plot, the jobs' timeline (when each
ran, and how many cores were busy) and summary.json's `job_timings` ({rule: figures})."""

from __future__ import annotations

from condmon import job_timings, plots
from condmon.report.section import Section, Table


def write(report) -> dict:
    """job_timings.csv, summary.json's `job_timings`, and the plot where any job was measured."""
    upstream = report.inputs.upstream
    jobs = job_timings.read_benchmarks(upstream.benchmarks)  # every benchmark file read once
    timings = job_timings.summarise_jobs(jobs, cores=upstream.cores)
    rules = timings[timings["rule"] != job_timings.RUN_ROW]
    if not rules.empty:
        note = _note(report.run.run_name, timings)
        report.save(plots.job_timings(rules, note), "job_timings.png")
        started = job_timings.timeline(jobs)
        busy = job_timings.busy_cores(started)
        report.save(plots.job_timeline(started, busy, upstream.cores, note), "job_timeline.png")
    report.summary["job_timings"] = {row.pop("rule"): row for row in timings.to_dict("records")}
    return {"job_timings": timings}


def _note(run_name: str, timings) -> str:
    """The plot's note: the run, and its elapsed time against its CPU work where known."""
    run = timings[timings["rule"] == job_timings.RUN_ROW]
    if run.empty:
        return f"run {run_name}"
    row = run.iloc[0]
    return (
        f"run {run_name}: {row.wall_seconds_total:.0f} s elapsed for {row.cpu_seconds_total:.0f} CPU-s on "
        f"{row.cores:.0f} cores ({row.cpu_seconds_per_core:.0f} s per core; parallel efficiency "
        f"{row.parallel_efficiency:.2f})"
    )


SECTION = Section(
    "job_timings",
    write,
    inputs=("upstream.benchmarks",),
    requires=("upstream.benchmarks",),
    tables=(Table("job_timings", "job_timings.csv", "Job timings per rule (job_timings.csv)"),),
    summary_keys=("job_timings",),
)

"""The job timings section: per rule the jobs' wall time and peak memory (condmon.job_timings,
from the benchmark files of every job before the report): job_timings.csv, its plot and
summary.json's `job_timings` ({rule: figures})."""

from __future__ import annotations

from condmon import job_timings, plots
from condmon.report.section import Section, Table


def write(report) -> dict:
    """job_timings.csv, summary.json's `job_timings`, and the plot where any job was measured."""
    timings = job_timings.summarise(report.inputs.upstream.benchmarks)
    if not timings.empty:
        report.save(plots.job_timings(timings, f"run {report.run.run_name}"), "job_timings.png")
    report.summary["job_timings"] = {row.pop("rule"): row for row in timings.to_dict("records")}
    return {"job_timings": timings}


SECTION = Section(
    "job_timings",
    write,
    inputs=("upstream.benchmarks",),
    requires=("upstream.benchmarks",),
    tables=(Table("job_timings", "job_timings.csv", "Job timings per rule (job_timings.csv)"),),
    summary_keys=("job_timings",),
)

"""Time a run of the workflow (issue 74): run `snakemake --cores N` with the given arguments in this
checkout, or read a run that finished here (`--collect-only`), and record its elapsed time against
its CPU work: Snakemake's own wall and CPU seconds (every process it waited for) where it ran here,
and from the run's `report/job_timings.csv` the jobs' window (first job's start to the last job
before the report), their CPU seconds, the parallel efficiency and the figures per rule. A run
timed here names the load average at its start and end: one timed beside other work says so; a
collected run's record says it was collected. `benchmarks/records/run_times-<name>.json`.

    python3 benchmarks/run_times.py [--cores 2] [--name default] [-- more snakemake arguments]
    python3 benchmarks/run_times.py --collect-only --run default [--name default]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "workflow"), str(ROOT / "benchmarks")]  # condmon, suite_times
from condmon.job_timings import RUN_ROW  # noqa: E402
from condmon.records import run_configfiles, save_record  # noqa: E402
from suite_times import cpu_seconds  # noqa: E402


def run_workflow(cores: int, extra: list[str]) -> dict:
    """Snakemake on `cores` cores with `extra` arguments in the project folder; its figures."""
    command = [sys.executable, "-m", "snakemake", "--cores", str(cores), *extra]
    cpu, start = cpu_seconds(), time.monotonic()
    subprocess.run(command, cwd=ROOT, check=True)
    return {
        "snakemake": " ".join(["snakemake", "--cores", str(cores), *extra]),
        "wall_seconds": round(time.monotonic() - start, 1),
        "cpu_seconds": round(cpu_seconds() - cpu, 1),
    }


def job_figures(run: Path) -> dict:
    """The run's jobs from its report/job_timings.csv: the row `run` and the rules."""
    timings = pd.read_csv(run / "report" / "job_timings.csv")
    whole = timings[timings["rule"] == RUN_ROW].iloc[0]
    cores = float(whole["cores"])
    return {
        "jobs_window_seconds": float(whole["wall_seconds_total"]),
        "jobs_cpu_seconds": float(whole["cpu_seconds_total"]),
        "cores": int(cores),
        "parallel_efficiency": float(whole["parallel_efficiency"]),
        "window_over_cpu_per_core": round(
            float(whole["wall_seconds_total"]) / (float(whole["cpu_seconds_total"]) / cores), 3
        ),
        "rules": timings[timings["rule"] != RUN_ROW]
        .drop(columns=["cores", "cpu_seconds_per_core", "parallel_efficiency"], errors="ignore")
        .to_dict(orient="records"),
    }


def run_name(snakemake_arguments: list[str]) -> str:
    """The run_name of the config the Snakemake arguments name (`--configfile A B ...`, else the
    default config; `--config run_name=X` over it), as the workflow reads it."""
    from condmon.config import DEFAULT_CONFIG, load_config

    paths, reading, override = [], None, None
    for argument in snakemake_arguments:
        if argument.startswith("-"):
            reading = argument
        elif reading in ("--configfile", "--configfiles"):
            paths.append(ROOT / argument)
        elif reading == "--config" and argument.startswith("run_name="):
            override = argument.split("=", 1)[1]
    return override or load_config(paths or [ROOT / DEFAULT_CONFIG], project=ROOT)["run_name"]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument(
        "--run", default=None, help="the run's name (results/<run>; default: its config's run_name)"
    )
    parser.add_argument("--name", default=None, help="the record's name (default: the run's)")
    parser.add_argument("--collect-only", action="store_true", help="read a finished run only")
    args, extra = parser.parse_known_args(argv)
    extra = [a for a in extra if a != "--"]
    args.run = args.run or run_name(extra)
    figures = {"run": args.run, "collected": args.collect_only}
    if not args.collect_only:
        load = [round(x, 2) for x in os.getloadavg()]
        figures.update(run_workflow(args.cores, extra), load_average_at_start=load)
        figures["load_average_at_end"] = [round(x, 2) for x in os.getloadavg()]
    run = ROOT / "results" / args.run
    figures.update(job_figures(run))
    save_record(
        "run_times",
        args.name or args.run,
        figures,
        script=__file__,
        argv=argv,
        configfiles=[str(Path(p).relative_to(ROOT)) for p in run_configfiles(run)],
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Render docs/results.md and the README's table of the default run from the committed benchmark
records (benchmarks/records/, condmon.records): every figure in them comes from a record, with
the command, commit, config hash and machine that made it. tests/test_results_pages.py fails when
either page differs from what the records render.

    python3 benchmarks/render_results.py            # rewrite docs/results.md and README.md's table
    python3 benchmarks/render_results.py --check    # exit 1, naming the page, where one is stale
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from condmon.records import read_records

ROOT = Path(__file__).resolve().parents[1]
README_BEGIN = "<!-- results: rendered by benchmarks/render_results.py from benchmarks/records/ -->"
README_END = "<!-- /results -->"
SEED_COMMAND = "python3 benchmarks/bench_seeds.py --configfile config/config.yaml --seeds 7 8 9 10 11 --name default"
NO_RECORD = "No record yet: run `{command}` (it writes the record under `benchmarks/records/`)."


def number(value, digits: int = 3) -> str:
    """A figure as the tables print it: fixed decimals, `-` where there is none."""
    if value is None or value != value:  # None or NaN
        return "-"
    return f"{value:.{digits}f}" if isinstance(value, float) else str(value)


def table(header: list[str], rows: list[list]) -> list[str]:
    """A Markdown table."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(number(c) for c in row) + " |" for row in rows]


def provenance(record: dict) -> str:
    """Where a record's figures come from: command, commit, config hash and machine."""
    machine = record["machine"]
    config = f", config hash `{record['config_hash']}`" if record.get("config_hash") else ""
    return (
        f"`{record['command']}` at commit `{record['commit'][:10]}`{config}; {machine['cpu_count']} cores "
        f"({machine['cpu']}), Python {machine['python']}; `benchmarks/records/{record['benchmark']}-"
        f"{record['name']}.json`."
    )


def bench_of(record: dict) -> str:
    """Which bench a seed record ran: a variant of config/benches/, else its first config's stem
    (`config` is the default bench)."""
    files = [Path(p) for p in record.get("configfiles", [])]
    variants = [p.stem for p in files if p.parent.name == "benches"]
    if variants:
        return variants[0]
    return "default" if not files or files[0].stem == "config" else files[0].stem


def seed_rows(figures: dict) -> tuple[list[str], list[list]]:
    """The seed table of a bench_seeds record: one row per seed, speed and measured share, then the
    mean over the seeds, with each health state's recall."""
    states = sorted({s for row in figures["per_seed"] + figures["mean"] for s in row["recall"]})
    header = [
        "bench",
        "speed (rpm)",
        "measured",
        "classifier",
        "balanced accuracy",
        "false alarms",
        *[f"recall {s}" for s in states],
        "simulation alone",
        "tooth named right",
        "exempt",
    ]
    default = figures["per_seed"][0]["classifier"] if figures["per_seed"] else "-"

    def bench(row):  # records from before the variants ran beside the seeds name the seed only
        return row.get("bench") or f"seed {row['seed']}"

    def located(row):
        return (
            ", ".join(f"{s} {v:.2f}" for s, v in sorted((row.get("located") or {}).items())) or "-"
        )

    rows = [
        [
            bench(row),
            f"{row['speed_rpm']:g}",
            f"{row['measured_percent']} %",
            row["classifier"],
            row["balanced_accuracy"],
            row["false_alarm_rate"],
            *[row["recall"].get(s) for s in states],
            row.get("simulation_alone"),
            located(row),
            ", ".join(row["exempt"]) or "none",
        ]
        for row in sorted(
            figures["per_seed"],
            key=lambda r: (r["classifier"], r["measured_percent"], bench(r), r["speed_rpm"]),
        )
    ]
    rows += [
        [
            f"**mean of {row['seeds']}**",
            f"{row['speed_rpm']:g}",
            f"{row['measured_percent']} %",
            row.get("classifier", default),
            row["balanced_accuracy"],
            row["false_alarm_rate"],
            *[row["recall"].get(s) for s in states],
            row.get("simulation_alone"),
            "-",
            "; ".join(f"{k}: {', '.join(v)}" for k, v in row["exempt"].items()) or "none",
        ]
        for row in sorted(
            figures["mean"],
            key=lambda r: (r.get("classifier", default), r["measured_percent"], r["speed_rpm"]),
        )
    ]
    return header, rows


SIMULATION_ALONE = (
    "*simulation alone*: the same classifier trained on the simulated records alone and tested on "
    "a simulated machine it never saw (`simulated_separability`), what training on the simulation "
    "can teach at most; `-` in records from before it."
)


def seed_section(title: str, records: list[dict], command: str) -> list[str]:
    """A section of seed tables, one per record, newest first."""
    lines = [f"## {title}", ""]
    if not records:
        return lines + [NO_RECORD.format(command=command), ""]
    lines += [SIMULATION_ALONE, ""]
    for record in reversed(records):
        lines += [
            f"### {record['name']} ({bench_of(record)} bench, {record['date']})",
            "",
            provenance(record),
            "",
        ]
        lines += table(*seed_rows(record["figures"])) + [""]
    return lines


def bearing_seed_section(records: list[dict]) -> list[str]:
    """The bearing rig over simulation seeds (bench_seeds --system bearing records): per protocol,
    measured share, group of records and method the balanced accuracy's mean and range over the
    seeds, each class's mean recall (over the records that show their line beside it), then each
    seed's balanced accuracy."""
    lines = ["## The CWRU bearing rig over simulation seeds", ""]
    command = (
        "python3 benchmarks/bench_seeds.py --system bearing --configfile config/cwru.yaml "
        "--seeds 1 2 3 --name cwru"
    )
    if not records:
        return lines + [NO_RECORD.format(command=command), ""]
    for record in reversed(records):
        figures = record["figures"]
        lines += [f"### {record['name']} ({record['date']})", "", provenance(record), ""]
        labels = sorted({k for m in figures["mean"] for k in m["recall"]})
        rows = []
        for m in figures["mean"]:
            b = m["balanced_accuracy"]
            rows.append(
                [
                    m["protocol"],
                    f"{m['measured_percent']} %",
                    m["group"],
                    m["classifier"],
                    ", ".join(map(str, m["seeds"])),
                    b["mean"],
                    f"{b['lowest']:.3f}-{b['highest']:.3f}",
                    b["std"],
                    *[(m["recall"].get(k) or {}).get("mean") for k in labels],
                    *[
                        (m["recall_shows_line"].get(k) or {}).get("mean")
                        for k in labels
                        if k != "normal"
                    ],
                ]
            )
        header = [
            "protocol",
            "measured",
            "records",
            "method",
            "seeds",
            "balanced accuracy (mean)",
            "range",
            "std",
            *[f"recall {k}" for k in labels],
            *[f"recall {k}, line shown" for k in labels if k != "normal"],
        ]
        lines += table(header, rows) + [""]
        per_seed = [
            [
                r["seed"],
                r["protocol"],
                f"{r['measured_percent']} %",
                r["group"],
                r["classifier"],
                r["balanced_accuracy"],
                *[r["recall"].get(k) for k in labels],
            ]
            for r in figures["per_seed"]
        ]
        lines += (
            ["Per seed:", ""]
            + table(
                [
                    "seed",
                    "protocol",
                    "measured",
                    "records",
                    "method",
                    "balanced accuracy",
                    *[f"recall {k}" for k in labels],
                ],
                per_seed,
            )
            + [""]
        )
    return lines


def throughput_section(records: list[dict]) -> list[str]:
    """The newest throughput record: cost per simulated second and throughput per system."""
    lines = ["## Simulation throughput", ""]
    if not records:
        return lines + [NO_RECORD.format(command="python3 benchmarks/throughput.py"), ""]
    record = records[-1]
    figures = record["figures"]
    workers = figures["workers"]
    load = figures["machine"].get("load_average_at_start")
    lines += [
        f"{record['date']}: "
        + provenance(record)
        + (f" Load average at the start: {load}." if load else ""),
        "",
        "Wall seconds per simulated second on one core (median, min-max over the repeats after a "
        "warm-up); samples per hour on one core and on all workers; the step check is the largest "
        "difference of the noise-free spectrum bands within 40 dB of each channel's strongest against a "
        "step four times smaller.",
        "",
    ]
    rows = []
    for system, entry in figures["systems"].items():
        cost = entry["wall_seconds_per_simulated_second"]
        check = entry.get("convergence", {}).get("max_difference_db", {}).get("bands_within_40_db")
        where = ", ".join(
            f"{p['function']} {100 * p['share']:.0f} %" for p in entry.get("profile", [])[:2]
        )
        rows.append(
            [
                system,
                f"{cost['median']:.3f} ({cost['min']:.3f}-{cost['max']:.3f})",
                entry["samples_per_hour_one_core"],
                entry[f"samples_per_hour_{workers}_cores"],
                f"{entry['speedup']:.2f}",
                entry["peak_memory_mb_per_worker"],
                "-" if check is None else f"{check:.3f}",
                where,
            ]
        )
    lines += table(
        [
            "system",
            "wall s per simulated s",
            "samples/h, 1 core",
            f"samples/h, {workers} cores",
            "speed-up",
            "peak MB per worker",
            "step check (dB)",
            "where the time goes",
        ],
        rows,
    )
    jobs = figures.get("dag_jobs")
    if jobs:
        lines += [
            "",
            "Jobs in the whole DAG: " + ", ".join(f"`{c}` {n}" for c, n in jobs.items()) + ".",
        ]
    return lines + [""]


def specimen_section(records: list[dict]) -> list[str]:
    """The CWRU runs' figures per group of records and per specimen (specimen_table records)."""
    lines = ["## CWRU bearings per specimen", ""]
    command = "python3 benchmarks/specimen_table.py results/<cwru run>"
    if not records:
        return lines + [NO_RECORD.format(command=command), ""]
    for record in reversed(records):
        figures = record["figures"]
        lines += [
            f"### {record['name']}: {figures['protocol']}, {figures['measured_percent']} % measured "
            f"({record['date']})",
            "",
            provenance(record),
            "",
        ]
        groups = figures["per_group"]
        labels = sorted(
            {k for g in groups for k in g} - {"group", "classifier", "accuracy", "balanced"}
        )
        lines += table(
            ["records", "method", "accuracy", "balanced", *labels],
            [
                [
                    g["group"],
                    g["classifier"],
                    g["accuracy"],
                    g["balanced"],
                    *[g.get(k) for k in labels],
                ]
                for g in groups
            ],
        ) + [""]
        specimens = figures["per_specimen"]
        methods = sorted({k for s in specimens for k in s} - {"group", "specimen"})
        lines += table(
            ["records", "specimen", *methods],
            [[s["group"], s["specimen"], *[s.get(m) for m in methods]] for s in specimens],
        ) + [""]
    return lines


def flatten(value, prefix: str = "") -> list[tuple[str, object]]:
    """(dotted key, leaf) pairs of nested figures, for records without a table of their own."""
    if isinstance(value, dict):
        return [pair for key, sub in value.items() for pair in flatten(sub, f"{prefix}{key}.")]
    if isinstance(value, list) and any(isinstance(v, (dict, list)) for v in value):
        return [pair for i, sub in enumerate(value) for pair in flatten(sub, f"{prefix}{i}.")]
    return [(prefix.rstrip("."), value)]


def minutes(seconds: float) -> str:
    """Seconds as `6 min 13 s`."""
    whole = int(round(seconds))
    return f"{whole // 60} min {whole % 60} s"


def run_times_section(records: list[dict]) -> list[str]:
    """The newest run_times record per name: the run's time against its CPU work, and its rules."""
    lines = ["## Run times", ""]
    if not records:
        return lines + [NO_RECORD.format(command="python3 benchmarks/run_times.py"), ""]
    newest = {record["name"]: record for record in records}
    lines += [
        "Elapsed time of a run against its CPU work. Where `run_times.py` ran the workflow, the CPU "
        "seconds are every process Snakemake waited for (its own included); a collected run has "
        "only its jobs' benchmark files, whose CPU Snakemake samples now and then (worker processes "
        "that end between samples are missed: a lower bound).",
        "",
    ]
    rows = []
    for name, record in newest.items():
        f = record["figures"]
        measured = not f.get("collected", True)
        wall = f["wall_seconds"] if measured else f["jobs_window_seconds"]
        cpu = f["cpu_seconds"] if measured else f["jobs_cpu_seconds"]
        rows.append(
            [
                name,
                f.get("snakemake", "(collected: the jobs' window)"),
                record["commit"][:10],
                minutes(wall),
                f"{cpu:.0f}",
                f"{wall / (cpu / f['cores']):.2f}",
                f.get("load_average_at_start", ["-"])[0],
            ]
        )
    lines += table(
        [
            "record",
            "run",
            "commit",
            "elapsed",
            "CPU s",
            "elapsed / (CPU s / cores)",
            "load at start",
        ],
        rows,
    )
    for name, record in newest.items():
        lines += ["", f"### {name}", "", provenance(record), ""]
        lines += table(
            ["rule", "jobs", "wall s (sum)", "longest job s", "CPU s (sampled)", "peak RSS MB"],
            [
                [
                    r["rule"],
                    r["jobs"],
                    f"{r['wall_seconds_total']:.1f}",
                    f"{r['wall_seconds_max']:.1f}",
                    f"{r['cpu_seconds_total']:.1f}",
                    f"{r['peak_rss_mb_max']:.0f}",
                ]
                for r in record["figures"]["rules"]
            ],
        )
    return lines + [""]


def other_section(records: list[dict]) -> list[str]:
    """Every other benchmark's newest record per name, its figures as key-value rows."""
    lines = ["## Other benchmarks", ""]
    if not records:
        return lines + [
            "No record yet of the other benchmarks (hunting_cycle.py, track_logging.py, "
            "join_candidates.py, measured_holdout.py, gear_signatures.py, bench_separability.py, "
            "mesh_stiffness_cost.py, study_table.py).",
            "",
        ]
    for record in records:
        lines += [
            f"### {record['benchmark']}: {record['name']} ({record['date']})",
            "",
            provenance(record),
            "",
        ]
        rest = (
            dict(record["figures"])
            if isinstance(record["figures"], dict)
            else {"figures": record["figures"]}
        )
        for key, value in list(rest.items()):
            columns = row_columns(value)
            if columns:  # a dict of like rows: one table, a row per entry
                lines += (
                    [f"`{key}`:", ""]
                    + table(
                        ["", *columns],
                        [[name, *[row.get(c) for c in columns]] for name, row in value.items()],
                    )
                    + [""]
                )
                del rest[key]
        if rest:
            lines += table(["figure", "value"], [[k, v] for k, v in flatten(rest)]) + [""]
    return lines


def row_columns(value) -> list[str]:
    """The common keys of a dict of flat dicts (a table's columns); [] for anything else."""
    if (
        not isinstance(value, dict)
        or not value
        or not all(isinstance(v, dict) for v in value.values())
    ):
        return []
    keys = [list(v) for v in value.values()]
    flat = all(not isinstance(x, (dict, list)) for v in value.values() for x in v.values())
    return keys[0] if flat and all(k == keys[0] for k in keys) else []


def render_results(records: list[dict]) -> str:
    """docs/results.md from the records (oldest first, as condmon.records.read_records gives them)."""
    bearing = [
        r
        for r in records
        if r["benchmark"] == "bench_seeds" and r["figures"].get("system") == "bearing"
    ]
    seeds = [r for r in records if r["benchmark"] == "bench_seeds" and r not in bearing]
    default = [r for r in seeds if bench_of(r) == "default"]
    cfrp = [r for r in seeds if bench_of(r).startswith("cfrp")]
    variants = [r for r in seeds if r not in default and r not in cfrp]
    tables = {"bench_seeds", "throughput", "specimen_table", "run_times"}
    lines = [
        "# Results",
        "",
        "Rendered by `python3 benchmarks/render_results.py` from the records in `benchmarks/records/`; "
        "do not edit by hand. Each benchmark writes its record when it runs; the history of how the "
        "method came to these figures is in [experiments/](experiments/).",
        "",
    ]
    lines += seed_section("The default bench over seeds", default, SEED_COMMAND)
    lines += seed_section(
        "The CFRP rig over seeds",
        cfrp,
        "python3 benchmarks/bench_seeds.py --configfile config/cfrp.yaml --seeds 7 --name cfrp",
    )
    lines += seed_section(
        "The bench variants (config/benches/)",
        variants,
        "python3 benchmarks/bench_seeds.py --configfile config/config.yaml "
        "config/benches/<bench>.yaml --seeds <its seed> --name variant-<bench>",
    )
    lines += bearing_seed_section(bearing)
    lines += specimen_section([r for r in records if r["benchmark"] == "specimen_table"])
    lines += throughput_section([r for r in records if r["benchmark"] == "throughput"])
    lines += run_times_section([r for r in records if r["benchmark"] == "run_times"])
    lines += other_section([r for r in records if r["benchmark"] not in tables])
    return "\n".join(lines).rstrip("\n") + "\n"


def render_readme_table(records: list[dict]) -> str:
    """The README's one table: the newest default-bench seed record's means at 0 % and 100 %
    measured data (no date: the README says what the run shows now)."""
    default = [
        r
        for r in records
        if r["benchmark"] == "bench_seeds"
        and bench_of(r) == "default"
        and r["figures"].get("system") != "bearing"
    ]
    if not default:
        return (
            "No record yet of the default run's figures over bench seeds: "
            f"`{SEED_COMMAND}` writes it ([docs/results.md](docs/results.md))."
        )
    record = default[-1]
    means = {(m["speed_rpm"], m["measured_percent"]): m for m in record["figures"]["mean"]}
    speeds = sorted({speed for speed, _ in means})
    rows = []
    for speed in speeds:
        zero, full = means.get((speed, 0), {}), means.get((speed, 100), {})
        rows.append(
            [
                f"{speed:g}",
                zero.get("balanced_accuracy"),
                zero.get("lowest_balanced_accuracy"),
                zero.get("false_alarm_rate"),
                full.get("balanced_accuracy"),
            ]
        )
    seeds = sorted({row["seed"] for row in record["figures"]["per_seed"]})
    classifier = record["figures"]["per_seed"][0]["classifier"].upper()
    lines = table(
        [
            "speed (rpm)",
            "0 % measured: balanced accuracy",
            "lowest seed",
            "false alarms",
            "100 % measured",
        ],
        rows,
    )
    return "\n".join(
        lines
        + [
            "",
            f"{classifier}, `record_split`, mean over bench seeds "
            f"{', '.join(map(str, seeds))}; from `{record['command']}` at commit "
            f"`{record['commit'][:10]}` (per seed and state: [docs/results.md](docs/results.md)).",
            *run_time_sentence(records),
        ]
    )


def run_time_sentence(records: list[dict]) -> list[str]:
    """The README's sentence on the default run's time: the newest run_times record of a default
    run that `run_times.py` ran itself (none: no sentence)."""
    timed = [
        r
        for r in records
        if r["benchmark"] == "run_times"
        and r["figures"].get("run") == "default"
        and not r["figures"].get("collected", True)
    ]
    if not timed:
        return []
    f = timed[-1]["figures"]
    return [
        "",
        f"The default run took {minutes(f['wall_seconds'])} alone on {f['cores']} cores, for "
        f"{f['cpu_seconds'] / 60:.1f} CPU minutes (`run_times-{timed[-1]['name']}` in "
        "[docs/results.md](docs/results.md#run-times)).",
    ]


def with_readme_table(readme: str, block: str) -> str:
    """README text with the text between its result markers replaced by `block`."""
    start, end = readme.index(README_BEGIN) + len(README_BEGIN), readme.index(README_END)
    return readme[:start] + "\n" + block + "\n" + readme[end:]


def pages(root: Path = ROOT, records: list[dict] | None = None) -> dict[Path, str]:
    """{path: text} of the rendered pages."""
    records = read_records(root / "benchmarks" / "records") if records is None else records
    readme = (root / "README.md").read_text()
    return {
        root / "docs" / "results.md": render_results(records),
        root / "README.md": with_readme_table(readme, render_readme_table(records)),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="only say which page is stale")
    args = parser.parse_args(argv)
    stale = []
    for path, text in pages().items():
        if path.exists() and path.read_text() == text:
            continue
        stale.append(path)
        if not args.check:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
            print(f"wrote {path.relative_to(ROOT)}")
    if args.check and stale:
        print(
            "stale (run python3 benchmarks/render_results.py): "
            + ", ".join(str(p.relative_to(ROOT)) for p in stale)
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The gear runs over several virtual-bench seeds (issue 48): one bench is one draw of a rig's
hidden make-up (its gears, the phases of its fluctuations, its pits' craters, its noise), so a
figure on one seed says little about the method. Each seed is a run of its own
(`run_name <base>-seed<k>`, `virtual_bench.seed k`, every other setting the config's); the script
runs what is missing and collects, per seed and speed:

The config's own bench seed is the config's own run where it has finished.

- at 0 % and 100 % measured data (protocol `record_split`, first repeat's split for 100 %: every
  classifier's mean over repeats from evaluation_summary.csv): balanced accuracy, false-alarm rate,
  each class's recall (prediction_shares.csv);
- the bench-only ceiling: each class's recall by a classifier trained on that bench's own records,
  every record held out once, and its permutation chance level (summary.json
  `measured_separability`): a class is *exempt* on that seed where the ceiling names it
  `not_shown` (its recall below `EXEMPT_BELOW` while the ceiling reads above chance: the bench
  cannot show it, so no method trained on simulation can be asked to);
- the fault-signature correlation per class (summary.json `fault_signatures`);
- the simulation's own ceiling: the same classifier on the simulated records alone, one simulated
  machine held out at a time (summary.json `simulated_separability`), its balanced accuracy
  (`simulation_alone`; None in a report from before it);
- the share of each localised fault's records whose damaged tooth is named right (summary.json
  `fault_location`), where the bench's records carry the truth.

With `--benches` the shipped bench variants (config/benches/*.yaml but two-stage.yaml, a rig of its
own: other gears, housings, grids, fault sizes and teeth, each with its own seed) run beside the seeds, layered over the config
files, each under its own run name; with several `--classifier`s every classifier's rows. Then
the mean over every bench per classifier, speed and class, to `results/benchmark/bench_seeds.json` (the
default run; `bench_seeds_<name>.json` for another) and to its committed record
`benchmarks/records/bench_seeds-<name>.json` (condmon.records; docs/results.md renders it).

    python3 benchmarks/bench_seeds.py [--configfile config/config.yaml ...] [--seeds 7 8 9 10 11]
        [--benches config/benches/*.yaml] [--layer benchmarks/seeds.yaml] [--cores 2]
        [--classifier svm knn cnn] [--collect-only] [--name default]

`--layer` (default benchmarks/seeds.yaml; `--layer none` for the whole config) is layered over the
config files: the SVM alone at 0 % and 100 %, whose figures are those of the full config.

With `--system bearing` (issue 71) a seed is a simulation seed (`simulation.seed k`, run name
`<run_name>-seed<k>`; the config's own seed is the config's own run where it has finished), the
layer benchmarks/bearing_seeds.yaml (0 % and 100 % measured, protocols unseen_fault and
specimen_holdout), and per seed, protocol and measured share, per group of records (design
specimens at loads 0-1 and 2-3, evaluation specimens, another bearing; benchmarks/specimen_table.py)
and method (the joined methods, the classifiers, the envelope rule): accuracy, balanced accuracy,
each class's recall, the recall over the fault records that show their line and over those that
do not (recall_per_record.csv's `shows_line`), and each specimen's recall; then the mean, lowest,
highest and standard deviation over the seeds. Its record is
`benchmarks/records/bench_seeds-<name>.json` with `system: bearing` in its figures.

    python3 benchmarks/bench_seeds.py --system bearing --configfile config/cwru.yaml --seeds 1 2 3 --name cwru
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from condmon.records import save_record
from condmon.separability import SHOWN_RECALL

import numpy as np
import pandas as pd
import yaml

ROOT = Path(__file__).resolve().parents[1]
EXEMPT_BELOW = (
    SHOWN_RECALL  # a class the bench's own records find less often than this is exempt there
)
PROTOCOL = "record_split"
COLUMNS = (
    "bench",
    "seed",
    "speed_rpm",
    "measured_percent",
    "classifier",
    "balanced_accuracy",
    "false_alarm_rate",
    "recall",
    "bench_only_recall",
    "bench_only_chance",
    "exempt",
    "signature_correlation",
    "simulation_alone",
    "located",
)


def config_value(configfiles, section: str, key: str, default):
    """A key as Snakemake merges the config files: the last file that sets it."""
    value = default
    for path in configfiles:
        loaded = yaml.safe_load(Path(path).read_text()) or {}
        loaded = loaded.get(section, {}) if section else loaded
        value = (loaded or {}).get(key, value)
    return value


def run_name_of(configfiles, seed: int) -> tuple[str, bool]:
    """(run name, whether to run it) of one seed: `<run_name>-seed<k>`; the config's own bench
    seed is the config's own run where it has finished (the same bench, so the same SVM figures)."""
    base = config_value(configfiles, None, "run_name", "default")
    if (
        seed == config_value(configfiles, "virtual_bench", "seed", None)
        and (ROOT / "results" / base / "report" / "summary.json").exists()
    ):
        return base, False
    return f"{base}-seed{seed}", True


def run_seed(
    configfiles, seed: int | None, run_name: str, cores: int, section: str = "virtual_bench"
) -> float:
    """Run (or complete) the pipeline of one seed (None: the config files' own bench) of
    `section` (`virtual_bench`; `simulation` for the bearing rig); its wall seconds."""
    bench = [f"{section}={json.dumps({'seed': seed})}"] if seed is not None else []
    command = [
        sys.executable,
        "-m",
        "snakemake",
        "--cores",
        str(cores),
        "--configfile",
        *configfiles,
        "--config",
        f"run_name={run_name}",
        *bench,
    ]
    start = time.perf_counter()
    print(f"seed {seed}: {' '.join(command)}", flush=True)
    subprocess.run(command, cwd=ROOT, check=True)
    return time.perf_counter() - start


def speed_of(condition: str) -> float | None:
    """450.0 of `speed_rpm=450`; None for `all`."""
    return float(condition.split("=", 1)[1]) if "=" in condition else None


def seed_rows(report: Path, seed: int, classifier: str, bench: str | None = None) -> list[dict]:
    """One row per speed and measured percentage (0, 100) of one bench's report (module
    docstring); `bench` its name (default `seed<k>`)."""
    summary = json.loads((report / "summary.json").read_text())
    located = (summary.get("fault_location") or {}).get("per_class") or {}
    evaluation = pd.read_csv(report / "evaluation_summary.csv")
    shares = pd.read_csv(report / "prediction_shares.csv")
    separability = summary.get("measured_separability", {}).get("per_condition", {})
    signatures = summary.get("fault_signatures", {}).get("per_condition", {})
    simulated = (summary.get("simulated_separability") or {}).get("per_condition", {})
    rows = []
    for percent in (0, 100):
        chosen = evaluation[
            (evaluation["classifier"] == classifier)
            & (evaluation["protocol"] == PROTOCOL)
            & (evaluation["measured_percent"] == percent)
            & (evaluation["records"] == "all")
        ]
        for row in chosen.itertuples():
            speed = speed_of(row.condition)
            if speed is None:
                continue
            here = shares[
                (shares["classifier"] == classifier)
                & (shares["protocol"] == PROTOCOL)
                & (shares["measured_percent"] == percent)
                & (shares["speed_rpm"] == speed)
            ]
            recall = {
                str(s): float(g.loc[g["predicted_label"] == s, "share"].sum())
                for s, g in here.groupby("true_label")
            }
            entry = separability.get(f"{speed:g}") or {}
            ceiling = entry.get("recall_per_class") or {}
            classes = (signatures.get(f"{speed:g}") or {}).get("classes", {})
            rows.append(
                {
                    "bench": bench or f"seed{seed}",
                    "seed": seed,
                    "speed_rpm": speed,
                    "measured_percent": percent,
                    "classifier": classifier,
                    "balanced_accuracy": float(row.balanced_accuracy_mean),
                    "false_alarm_rate": float(row.false_alarm_rate_mean),
                    "recall": recall,
                    "bench_only_recall": ceiling,
                    "bench_only_chance": entry.get("chance"),
                    "exempt": sorted(entry.get("not_shown") or []),
                    "signature_correlation": {
                        c: v.get("direction_correlation") for c, v in classes.items()
                    },
                    "simulation_alone": (simulated.get(f"{speed:g}") or {}).get(
                        "balanced_accuracy"
                    ),
                    "located": located,
                }
            )
    return rows


def means(rows: list[dict]) -> list[dict]:
    """Per speed and measured percentage: the mean over seeds of the balanced accuracy, the
    false-alarm rate and each class's recall (a class's mean over the seeds where it is not
    exempt), the lowest seed's balanced accuracy and the highest false-alarm rate, and the
    simulation's own ceiling over the seeds that have one."""
    out = []
    frame = pd.DataFrame(rows)
    if "classifier" not in frame:  # rows of one classifier from before several were collected
        frame["classifier"] = "svm"
    for (classifier, speed, percent), part in frame.groupby(
        ["classifier", "speed_rpm", "measured_percent"]
    ):
        classes = sorted({c for r in part["recall"] for c in r})
        recall = {
            c: float(
                np.mean(
                    [
                        r[c]
                        for r, ex in zip(part["recall"], part["exempt"])
                        if c in r and c not in ex
                    ]
                    or [np.nan]
                )
            )
            for c in classes
        }
        correlation = {
            c: float(
                np.nanmean(
                    [
                        s.get(c) if s.get(c) is not None else np.nan
                        for s in part["signature_correlation"]
                    ]
                    or [np.nan]
                )
            )
            for c in classes
            if any(c in s for s in part["signature_correlation"])
        }
        alone = [  # None (NaN in the frame): a report from before the simulation's own ceiling
            v for v in part.get("simulation_alone", pd.Series(dtype=float)) if pd.notna(v)
        ]
        out.append(
            {
                "classifier": classifier,
                "speed_rpm": float(speed),
                "measured_percent": int(percent),
                "seeds": int(len(part)),
                "balanced_accuracy": float(part["balanced_accuracy"].mean()),
                "lowest_balanced_accuracy": float(part["balanced_accuracy"].min()),
                "false_alarm_rate": float(part["false_alarm_rate"].mean()),
                "highest_false_alarm_rate": float(part["false_alarm_rate"].max()),
                "recall": recall,
                "simulation_alone": float(np.mean(alone)) if alone else None,
                "signature_correlation": correlation,
                "exempt": {
                    str(getattr(r, "bench", r.seed)): r.exempt
                    for r in part.itertuples()
                    if r.exempt
                },
            }
        )
    return out


# -- the bearing rig over simulation seeds -------------------------------------------------------
BEARING_PROTOCOLS = ("unseen_fault", "specimen_holdout")
BEARING_LAYER = "benchmarks/bearing_seeds.yaml"


def bearing_run_name(configfiles, seed: int) -> tuple[str, bool]:
    """(run name, whether to run it) of one simulation seed (`run_name_of` for the bearing rig)."""
    base = config_value(configfiles, None, "run_name", "default")
    if (
        seed == config_value(configfiles, "simulation", "seed", None)
        and (ROOT / "results" / base / "report" / "summary.json").exists()
    ):
        return base, False
    return f"{base}-seed{seed}", True


def bearing_rows(run: Path, seed: int) -> list[dict]:
    """One row per protocol, measured share, group of records and method of one seed's run (module
    docstring)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from specimen_table import group_table, load, specimen_table

    rows = []
    for protocol in BEARING_PROTOCOLS:
        for percent in (0, 100):
            records = load(run, protocol, percent)
            if records.empty:
                continue
            groups = group_table(records).reset_index()
            specimens = specimen_table(records)
            for row in groups.to_dict(orient="records"):
                here = records[
                    (records["group"] == row["group"])
                    & (records["classifier"] == row["classifier"])
                ]
                shown = {}
                if "shows_line" in here:
                    for key, flag in (("shows_line", True), ("no_line", False)):
                        part = here[here["shows_line"].astype(str) == str(flag)]
                        per_class = part.groupby("true_label").agg(
                            right=("right", "sum"), n=("n_test", "sum")
                        )
                        shown[key] = {
                            label: float(r.right / r.n) for label, r in per_class.iterrows()
                        }
                labels = [
                    k for k in row if k not in ("group", "classifier", "accuracy", "balanced")
                ]
                rows.append(
                    {
                        "seed": seed,
                        "protocol": protocol,
                        "measured_percent": percent,
                        "group": row["group"],
                        "classifier": row["classifier"],
                        "accuracy": float(row["accuracy"]),
                        "balanced_accuracy": float(row["balanced"]),
                        "recall": {k: float(row[k]) for k in labels if row[k] == row[k]},
                        "recall_shows_line": shown.get("shows_line", {}),
                        "recall_no_line": shown.get("no_line", {}),
                        "per_specimen": {
                            specimen: float(value)
                            for (group, specimen), value in specimens[row["classifier"]].items()
                            if group == row["group"] and value == value
                        },
                    }
                )
    return rows


def spread(values) -> dict:
    """mean, lowest, highest and standard deviation (population) of a list of figures."""
    values = np.asarray([v for v in values if v is not None and v == v], dtype=float)
    if not len(values):
        return {"mean": None, "lowest": None, "highest": None, "std": None}
    return {
        "mean": float(values.mean()),
        "lowest": float(values.min()),
        "highest": float(values.max()),
        "std": float(values.std()),
    }


def bearing_means(rows: list[dict]) -> list[dict]:
    """Per protocol, measured share, group and method: the spread over the seeds of the balanced
    accuracy, of each class's recall (over every record and over those that show their line) and of
    each specimen's recall."""
    out = []
    frame = pd.DataFrame(rows)
    for (protocol, percent, group, classifier), part in frame.groupby(
        ["protocol", "measured_percent", "group", "classifier"], sort=True
    ):

        def of(column):
            keys = sorted({k for r in part[column] for k in r})
            return {k: spread([r.get(k) for r in part[column]]) for k in keys}

        out.append(
            {
                "protocol": protocol,
                "measured_percent": int(percent),
                "group": group,
                "classifier": classifier,
                "seeds": sorted(int(s) for s in part["seed"]),
                "balanced_accuracy": spread(part["balanced_accuracy"]),
                "accuracy": spread(part["accuracy"]),
                "recall": of("recall"),
                "recall_shows_line": of("recall_shows_line"),
                "per_specimen": of("per_specimen"),
            }
        )
    return out


def bearing_main(args) -> int:
    configfiles = list(args.configfile) + ([] if args.layer == "none" else [args.layer])
    rows, seconds, runs = [], {}, {}
    for seed in args.seeds:
        run_name, to_run = bearing_run_name(args.configfile, seed)
        if to_run and not args.collect_only:
            seconds[f"seed{seed}"] = run_seed(
                configfiles, seed, run_name, args.cores, section="simulation"
            )
        runs[seed] = run_name
        rows += bearing_rows(ROOT / "results" / run_name, seed)
    result = {
        "system": "bearing",
        "configfiles": configfiles,
        "runs": runs,
        "per_seed": rows,
        "mean": bearing_means(rows),
        "wall_seconds": seconds,
    }
    name = args.name or config_value(args.configfile, None, "run_name", "cwru")
    out = ROOT / "results" / "benchmark" / f"bench_seeds_{name}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    for row in result["mean"]:
        b = row["balanced_accuracy"]
        print(
            f"{row['protocol']} {row['measured_percent']:3d} % {row['group']:18s} {row['classifier']:14s} "
            f"balanced {b['mean']:.3f} ({b['lowest']:.3f}-{b['highest']:.3f}) recall "
            f"{json.dumps({k: round(v['mean'], 2) for k, v in row['recall'].items()})}"
        )
    print(f"wrote {out}")
    save_record(
        "bench_seeds", name, result, script=__file__, argv=argv_of(args), configfiles=configfiles
    )
    return 0


def argv_of(args):
    return getattr(args, "argv", None)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configfile", nargs="+", default=["config/config.yaml"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[7, 8, 9, 10, 11])
    parser.add_argument(
        "--layer", default="benchmarks/seeds.yaml", help="config layered last, or none"
    )
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--classifier", nargs="+", default=["svm"])
    parser.add_argument(
        "--benches", nargs="*", default=[], help="bench variants (config/benches/*.yaml)"
    )
    parser.add_argument("--collect-only", action="store_true", help="only collect finished runs")
    parser.add_argument("--name", default=None, help="output name (default: the config's run_name)")
    parser.add_argument(
        "--system",
        choices=["gear", "bearing"],
        default="gear",
        help="bearing: simulation seeds of a CWRU config (module docstring)",
    )
    args = parser.parse_args(argv)
    args.argv = argv
    if args.system == "bearing":
        if args.layer == parser.get_default("layer"):
            args.layer = BEARING_LAYER
        return bearing_main(args)
    base = config_value(args.configfile, None, "run_name", "default")
    configfiles = list(args.configfile) + ([] if args.layer == "none" else [args.layer])
    rows, seconds = [], {}
    for seed in args.seeds:
        run_name, to_run = run_name_of(args.configfile, seed)
        if to_run and not args.collect_only:
            seconds[f"seed{seed}"] = run_seed(configfiles, seed, run_name, args.cores)
        rows += [
            row
            for classifier in args.classifier
            for row in seed_rows(ROOT / "results" / run_name / "report", seed, classifier)
        ]
    for (
        variant
    ) in args.benches:  # each its own bench: its run name and seed, layered over the config
        files = list(args.configfile) + [variant] + configfiles[len(args.configfile) :]
        run_name, bench = (
            config_value(files, None, "run_name", Path(variant).stem),
            Path(variant).stem,
        )
        if not args.collect_only:
            seconds[bench] = run_seed(files, None, run_name, args.cores)
        rows += [
            row
            for classifier in args.classifier
            for row in seed_rows(
                ROOT / "results" / run_name / "report",
                config_value(files, "virtual_bench", "seed", None),
                classifier,
                bench,
            )
        ]
    result = {
        "configfiles": configfiles,
        "benches": list(args.benches),
        "protocol": PROTOCOL,
        "exempt_below": EXEMPT_BELOW,
        "columns": list(COLUMNS),
        "per_seed": rows,
        "mean": means(rows),
        "wall_seconds": seconds,
    }
    name = args.name or base
    out = (
        ROOT
        / "results"
        / "benchmark"
        / ("bench_seeds.json" if name == "default" else f"bench_seeds_{name}.json")
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1))
    for row in result["mean"]:
        print(
            f"{row['classifier']} {row['speed_rpm']:g} rpm {row['measured_percent']:3d} %: "
            f"balanced {row['balanced_accuracy']:.3f} "
            f"(lowest {row['lowest_balanced_accuracy']:.3f}), false alarms {row['false_alarm_rate']:.3f}, "
            f"recall {json.dumps({k: round(v, 2) for k, v in row['recall'].items()})}"
        )
    print(f"wrote {out}")
    save_record("bench_seeds", name, result, script=__file__, argv=argv, configfiles=configfiles)
    return 0


if __name__ == "__main__":
    sys.exit(main())

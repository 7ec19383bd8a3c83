"""A finished run's figures per operating condition (`hybrid.condition`: a speed, or a load with
`rig.loads`), into the committed record `benchmarks/records/condition_table-<run>.json`
(docs/results.md renders it): per condition, classifier and measured share (0 and 100 %,
`record_split`, the mean over repeats), the balanced accuracy and the false-alarm rate from
`report/evaluation.csv`, and the measured-only ceiling with its permutation chance from
`summary.json`. What `bench_seeds.py` gives per speed over seeds, for one run of any condition.

The run must have finished (`snakemake --cores 2 --configfile config/loads.yaml`).

    python3 benchmarks/condition_table.py --run bench-loads
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from condmon.records import run_configfiles, save_record  # noqa: E402

PROTOCOL, PERCENTS = "record_split", (0, 100)


def per_condition(evaluation: pd.DataFrame) -> dict:
    """{`<condition>, <classifier>, <percent> %`: {balanced_accuracy, false_alarm_rate}}: the mean
    over repeats of every condition's rows (`all` too) of `PROTOCOL` over all records."""
    chosen = evaluation[
        (evaluation["protocol"] == PROTOCOL)
        & (evaluation["records"] == "all")
        & evaluation["measured_percent"].isin(PERCENTS)
    ]
    means = chosen.groupby(["condition", "classifier", "measured_percent"], sort=True)[
        ["balanced_accuracy", "false_alarm_rate"]
    ].mean()
    return {
        f"{condition}, {classifier}, {percent} %": {
            name: round(float(value), 3) for name, value in row.items()
        }
        for (condition, classifier, percent), row in means.iterrows()
    }


def ceiling(summary: dict) -> dict:
    """{condition value: {balanced_accuracy, chance_upper, reads_above_chance}} of the measured-only
    classifier (every record held out once)."""
    separability = summary.get("measured_separability", {})
    return {
        f"{separability.get('condition', 'condition')}={value}": {
            "balanced_accuracy": round(float(entry["balanced_accuracy"]), 3),
            "chance_upper": round(float(entry["chance"]["upper"]), 3),
            "reads_above_chance": entry.get("reads_above_chance"),
        }
        for value, entry in (separability.get("per_condition") or {}).items()
        if entry.get("balanced_accuracy") is not None
    }


def condition_table(run: str) -> dict:
    report = ROOT / "results" / run / "report"
    summary = json.loads((report / "summary.json").read_text())
    return {
        "run": run,
        "protocol": PROTOCOL,
        "per_condition": per_condition(pd.read_csv(report / "evaluation.csv")),
        "ceiling": ceiling(summary),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", required=True, help="the finished run's name (results/<run>)")
    args = parser.parse_args(argv)
    figures = condition_table(args.run)
    path = save_record(
        "condition_table",
        args.run,
        figures,
        script=__file__,
        argv=argv if argv is not None else sys.argv[1:],
        configfiles=run_configfiles(ROOT / "results" / args.run),
    )
    print(json.dumps(figures, indent=1))
    print(f"record: {path}")


if __name__ == "__main__":
    main()

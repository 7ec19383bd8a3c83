"""A study's set-up run side by side with the study's own figures (issue 69 item 5): the run's
simulation-trained SVM at 0 % measured per speed (accuracy and balanced accuracy per segment, each
class's recall), its simulated validation accuracy (records of the simulation held out: what a
study that tests on simulation reports), the measured-only ceiling with its permutation chance,
the run's CPU seconds, beside the accuracies the study publishes, into the committed record
`benchmarks/records/study_table-<run>.json` (docs/results.md renders it).

The run must have finished (`snakemake --cores 2 --configfile config/cfrp-study.yaml`).

    python3 benchmarks/study_table.py --run cfrp-study --study 0.994 0.918 0.982
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


def per_speed(report: Path, classifier: str = "svm") -> dict:
    """{speed: {accuracy, balanced_accuracy, recall per class}} at 0 % measured, record_split."""
    shares = pd.read_csv(report / "prediction_shares.csv")
    chosen = shares[
        (shares["classifier"] == classifier)
        & (shares["protocol"] == "record_split")
        & (shares["measured_percent"] == 0)
    ]
    right = chosen[chosen["true_label"] == chosen["predicted_label"]]
    recall = right.pivot_table(index="speed_rpm", columns="true_label", values="share")
    accuracy = pd.read_csv(report / "accuracy.csv")
    accuracy = (
        accuracy[
            (accuracy["classifier"] == classifier)
            & (accuracy["protocol"] == "record_split")
            & (accuracy["measured_percent"] == 0)
        ]
        .groupby("speed_rpm")["accuracy"]
        .mean()
    )
    return {
        f"{speed:g} rpm": {
            "accuracy": round(float(accuracy[speed]), 3),
            "balanced_accuracy": round(float(recall.loc[speed].mean()), 3),
            **{f"recall {label}": round(float(v), 2) for label, v in recall.loc[speed].items()},
        }
        for speed in recall.index
    }


def study_table(run: str, study: list[float]) -> dict:
    report = ROOT / "results" / run / "report"
    summary = json.loads((report / "summary.json").read_text())
    rows = per_speed(report)
    for (key, row), published in zip(rows.items(), study):
        row["study"] = published
    ceiling = summary.get("measured_separability", {}).get("all", {})
    validation = [
        r["accuracy_mean"]
        for r in summary.get("simulated_validation", {}).get("results", [])
        if r.get("classifier") == "svm" and r.get("measured_percent") == 0
    ]
    timings = summary.get("job_timings", {})
    return {
        "run": run,
        "per_speed": rows,
        "simulated_validation_accuracy": round(float(validation[0]), 3) if validation else None,
        "ceiling_balanced_accuracy": round(
            float(ceiling.get("balanced_accuracy", float("nan"))), 3
        ),
        "ceiling_chance_upper": round(
            float(ceiling.get("chance", {}).get("upper", float("nan"))), 3
        ),
        "ceiling_reads_above_chance": ceiling.get("reads_above_chance"),
        "cpu_seconds": round(
            sum(v.get("cpu_seconds_total") or 0.0 for k, v in timings.items() if k != "run"), 1
        ),
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--run", required=True, help="the finished run's name (results/<run>)")
    parser.add_argument(
        "--study", type=float, nargs="+", required=True, help="the study's accuracy per speed"
    )
    args = parser.parse_args(argv)
    figures = study_table(args.run, args.study)
    path = save_record(
        "study_table",
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

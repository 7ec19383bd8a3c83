"""Per-specimen recall of every method of a finished bearing run (the README's CWRU tables).

    python benchmarks/specimen_table.py results/cwru_full [--protocol unseen_fault] [--percent 0]

From the run's report/recall_per_record.csv (each record's recall and test segments),
report/summary.json (`design_records`: which records are design, evaluation or another bearing)
and measured/records.csv (each record's specimen and load): per specimen and method, the share of
its test segments called right, pooled over its records; then, per group of records (evaluation
specimens; design specimens at the loads the shared folder has and at the others; another
bearing), each method's accuracy, class recalls and balanced accuracy (their mean). Methods are
the report's classifiers: the joined methods, the classifiers and the physics rules. Read only:
it computes nothing the report did not, it groups it. Its record:
benchmarks/records/specimen_table-<run>.json (condmon.records; docs/results.md renders it).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pandas as pd

from condmon.records import run_configfiles, save_record


def load(run: Path, protocol: str, percent: int) -> pd.DataFrame:
    per_record = pd.read_csv(run / "report" / "recall_per_record.csv", dtype={"record_id": str})
    per_record = per_record[
        (per_record["protocol"] == protocol) & (per_record["measured_percent"] == percent)
    ]
    records = pd.read_csv(run / "measured" / "records.csv", dtype={"record_id": str})
    design = json.loads((run / "report" / "summary.json").read_text())["design_records"]
    apart = set(design.get("unmodelled", {}).get("records", {}))
    designed = set(design["records"])
    rows = per_record.merge(
        records[["record_id", "specimen", "load_hp"]], on="record_id", how="left"
    )
    rows["group"] = [
        "another bearing"
        if r in apart
        else (f"design, loads {'0-1' if load <= 1 else '2-3'}" if r in designed else "evaluation")
        for r, load in zip(rows["record_id"], rows["load_hp"])
    ]
    rows["right"] = rows["recall"] * rows["n_test"]
    return rows


def specimen_table(rows: pd.DataFrame) -> pd.DataFrame:
    pooled = rows.groupby(["group", "specimen", "classifier"]).agg(
        right=("right", "sum"), n=("n_test", "sum")
    )
    return (pooled["right"] / pooled["n"]).unstack("classifier").round(3)


def group_table(rows: pd.DataFrame) -> pd.DataFrame:
    out = []
    for (group, classifier), here in rows.groupby(["group", "classifier"]):
        per_class = here.groupby("true_label").agg(right=("right", "sum"), n=("n_test", "sum"))
        recalls = per_class["right"] / per_class["n"]
        out.append(
            {
                "group": group,
                "classifier": classifier,
                "accuracy": round(here["right"].sum() / here["n_test"].sum(), 3),
                "balanced": round(recalls.mean(), 3),
                **{label: round(value, 3) for label, value in recalls.items()},
            }
        )
    return pd.DataFrame(out).set_index(["group", "classifier"])


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, help="the run's results folder, e.g. results/cwru_full")
    parser.add_argument("--protocol", default="unseen_fault")
    parser.add_argument("--percent", type=int, default=0, help="measured share, percent")
    args = parser.parse_args(argv)
    rows = load(args.run, args.protocol, args.percent)
    with pd.option_context("display.width", 200, "display.max_rows", 200):
        print(f"{args.run}: {args.protocol}, {args.percent} % measured, per segment\n")
        print(specimen_table(rows).to_string(), "\n")
        print(group_table(rows).to_string())
    figures = {
        "protocol": args.protocol,
        "measured_percent": args.percent,
        "per_specimen": json.loads(specimen_table(rows).reset_index().to_json(orient="records")),
        "per_group": json.loads(group_table(rows).reset_index().to_json(orient="records")),
    }
    save_record(
        "specimen_table",
        args.run.name,
        figures,
        script=__file__,
        argv=argv,
        configfiles=run_configfiles(args.run),
    )


if __name__ == "__main__":
    main()

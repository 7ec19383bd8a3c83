"""The evaluation section (condmon.evaluation's tables, with the measured features): evaluation.csv
per evaluation, evaluation_summary.csv over repeats, and in summary.json each result's honest
figures (per-segment, per-record, balanced accuracy, false alarms, baselines, gain), per
condition, on design and evaluation records apart (`by_records`), per specimen; `design_records`
(which records count as design and which as evaluation), `repeats` and `evaluation` (what the
figures are).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from condmon import evaluation
from condmon.report.aggregate import json_number
from condmon.report.headline import NO_EVALUATION_SPECIMEN
from condmon.report.loading import design_record_ids
from condmon.report.section import Section, Table


def write(report) -> dict:
    """The summary figures and keys; evaluation.csv and evaluation_summary.csv."""
    tables, chosen = report.evaluation, report.inputs.evaluation
    add_evaluation(
        report.summary,
        tables.overall,
        report.predictions,
        report.inputs.upstream.measured_records,
        report.design_records,
        chosen.design_specimens,
        report.specimens,
        report.apart,
    )
    return {"evaluation": tables.table, "evaluation_summary": tables.overall}


SECTION = Section(
    "evaluation",
    write,
    inputs=(
        "evaluation.measured_features",
        "evaluation.condition",
        "evaluation.design_records",
        "evaluation.design_specimens",
        "evaluation.unmodelled",
        "upstream.measured_records",
        "train.measured_only",
        "train.physics",
        "train.measured_only_predictions",
    ),
    requires=("evaluation.measured_features",),
    tables=(
        Table("evaluation", "evaluation.csv", page=False),
        Table(
            "evaluation_summary",
            "evaluation_summary.csv",
            "Evaluation over repeats (evaluation_summary.csv)",
        ),
    ),
    summary_keys=("design_records", "repeats", "evaluation"),
)


def design_summary(
    predictions: pd.DataFrame,
    design_records,
    design_specimens,
    specimens: dict,
    apart: dict | None = None,
) -> dict:
    """summary.json's `design_records`: which tested records and specimens count as design and
    which as evaluation, what the headline is on, and a note that says so plainly. Records of
    unmodelled specimens (`apart`: {record_id: reason}) are neither: `unmodelled` lists them."""
    design, apart = set(map(str, design_records)), dict(apart or {})
    tested = sorted(set(predictions["record_id"].astype(str)))
    evaluation_records = [r for r in tested if r not in design and r not in apart]
    entry = {
        "records": sorted(design),
        "design_specimens": sorted(map(str, design_specimens)),
        "tested_design_records": [r for r in tested if r in design],
        "tested_evaluation_records": evaluation_records,
        "evaluation_specimens": sorted(
            {specimens[r] for r in evaluation_records if r in specimens}
        ),
    }
    if apart:
        entry["unmodelled"] = {
            "records": {
                r: {"specimen": specimens.get(r), "reason": apart[r], "tested": r in tested}
                for r in sorted(apart)
            },
            "note": (
                "records of specimens the model does not describe: their figures are in rows "
                "of their own (records 'unmodelled'), never in the headline nor among "
                "the evaluation records"
            ),
        }
    if not design and not apart:
        entry["headline_records"] = "all"
        entry["note"] = (
            "report.design_records is empty and the system declares no design "
            "specimen: no record is declared as used in design"
        )
        return entry
    entry["headline_records"] = "evaluation" if evaluation_records else "none"
    entry["note"] = (
        "results on the records of the design specimens (whose records design choices were "
        "tuned on; and report.design_records) are given apart ('design') from the others "
        "('evaluation': specimens the design never looked at); the headline is on the "
        "evaluation records"
        + (
            ""
            if evaluation_records
            else "; "
            + NO_EVALUATION_SPECIMEN.split(". The design")[0]
            + ": no figure here is a headline"
        )
    )
    return entry


def add_evaluation(
    summary: dict,
    overall: pd.DataFrame,
    predictions: pd.DataFrame,
    measured_records,
    design_records,
    design_specimens=(),
    specimens: dict | None = None,
    apart: dict | None = None,
) -> None:
    """summary.json: each result's honest figures (all test data), its accuracy per condition,
    its figures on design and evaluation records apart (`by_records`), and recall per specimen
    where records.csv names them (`specimens`: {record_id: specimen}, read here if None)."""
    figures = [
        "n_repeats",
        "distinct_repeats",
        "accuracy_ci_low",
        "accuracy_ci_high",
        "record_accuracy_mean",
        "record_accuracy_ci_low",
        "record_accuracy_ci_high",
        "balanced_accuracy_mean",
        "false_alarm_rate_mean",
        "false_alarm_ci_low",
        "false_alarm_ci_high",
        "small_test_set",
        "majority_class_mean",
        "measured_only_best_mean",
        "physics_baseline",
        "physics_baseline_accuracy_mean",
        "strongest_baseline",
        "strongest_baseline_accuracy_mean",
        "gain_vs_strongest_mean",
    ]
    if specimens is None:
        specimens = design_record_ids((), (), measured_records)[1]
    recalls = {}
    if specimens:
        hits = predictions.assign(
            hit=predictions["true_label"] == predictions["predicted_label"],
            specimen=predictions["record_id"].map(specimens),
        )
        recalls = hits.groupby(["classifier", "protocol", "measured_percent", "specimen"])[
            "hit"
        ].mean()
    keys = ["classifier", "protocol", "measured_percent"]
    for result in summary["results"]:
        key = tuple(result[k] for k in keys)
        mine = overall[
            (overall["classifier"] == key[0])
            & (overall["protocol"] == key[1])
            & (overall["measured_percent"] == key[2])
        ]
        everything = mine[
            (mine["condition"] == evaluation.ALL) & (mine["records"] == evaluation.ALL)
        ]
        if everything.empty:
            continue
        row = everything.iloc[0]
        result.update(_figures(row, figures))
        result["records"] = "all" if not design_records else "all (design and evaluation together)"
        if result["distinct_repeats"] == 1 and result["n_repeats"] > 1:
            # a spread of 0 would claim a stability nobody measured
            result["accuracy_std"] = result["macro_f1_std"] = None
            result["repeats_note"] = (
                "the repeats predicted alike: one repeat, no spread (the "
                "seed changed neither the training set nor the fit)"
            )
        result["accuracy_mean_per_condition"] = {
            r.condition: json_number(r.accuracy_mean)
            for r in mine[
                (mine["condition"] != evaluation.ALL) & (mine["records"] == evaluation.ALL)
            ].itertuples()
        }
        by_records = mine[
            (mine["condition"] == evaluation.ALL) & (mine["records"] != evaluation.ALL)
        ]
        result["accuracy_mean_by_records"] = {
            r.records: json_number(r.accuracy_mean) for r in by_records.itertuples()
        }
        if design_records or apart:
            # every figure on each side, the baselines and the gain on those records alone
            result["by_records"] = {
                records: (
                    _figures(
                        by_records[by_records["records"] == records].iloc[0],
                        ["accuracy_mean", *figures],
                    )
                    if (by_records["records"] == records).any()
                    else {"note": f"no {records} record tested"}
                )
                for records in ("evaluation", "design")
                + ((evaluation.UNMODELLED,) if apart else ())
            }
        if len(recalls):
            result["recall_per_specimen"] = {s: json_number(v) for s, v in recalls.loc[key].items()}
    summary["design_records"] = design_summary(
        predictions, design_records, design_specimens, specimens, apart
    )
    summary["repeats"] = (
        "a repeat redraws which measured records (time blocks, or segments under segment_share) "
        "join each share and seeds the fit (the CNN's initialisation and batches, a "
        "classifier's own randomness); the simulated training data are the same in every "
        "repeat (simulation.seed), so where no measured record trains (0 %) or every one does, "
        "deterministic classifiers (SVM, KNN, grouped feature selection) repeat one result: "
        "distinct_repeats counts the repeats that predicted differently, and only those give "
        "a spread"
    )
    summary["evaluation"] = (
        "per-segment, per-record (majority vote) and balanced accuracy with 95 % Wilson "
        "intervals (per evaluation on its test set; over repeats on one repeat's distinct test "
        "segments/records: repeats and holdouts that test a segment again add no data; still "
        "optimistic: segments of a record are not independent), false-alarm rate (healthy test segments called faulty), gain against "
        "the strongest of chance, the test set's majority class, the best measured-only "
        "classifier and the physics baseline (negative: a baseline wins); evaluation.csv per "
        "evaluation, evaluation_summary.csv over repeats, physics_baselines.csv the physics "
        "baselines' own figures on the same test sets"
    )


def _figures(row, names) -> dict:
    """{name: JSON value} of one evaluation_summary row."""
    return {
        name: row[name]
        if isinstance(row[name], str)
        else (
            bool(row[name]) if isinstance(row[name], (bool, np.bool_)) else json_number(row[name])
        )
        for name in names
    }

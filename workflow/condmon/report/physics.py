"""The physics baselines section (with the measured features): physics_baselines.csv, the
system's training-free rules' own evaluation summary on the same test sets (a header alone, the
evaluation summary's columns, without any rule), and summary.json's `physics_baselines` (per
rule, protocol and percent its mean accuracy, balanced accuracy, false-alarm rate and recall per
class)."""

from __future__ import annotations

import pandas as pd

from condmon import evaluation
from condmon.report.aggregate import json_number, recall_per_class
from condmon.report.section import Section, Table


def write(report) -> dict:
    tables = report.evaluation
    if tables.physics_overall is None:
        return {"physics_baselines": tables.overall.iloc[:0]}
    report.summary["physics_baselines"] = physics_baselines_summary(
        tables.physics_overall, report.physics
    )
    return {"physics_baselines": tables.physics_overall}


SECTION = Section(
    "physics_baselines",
    write,
    inputs=("evaluation.measured_features", "train.physics"),
    requires=("evaluation.measured_features",),
    tables=(
        Table(
            "physics_baselines",
            "physics_baselines.csv",
            "Physics baselines (physics_baselines.csv)",
        ),
    ),
    summary_keys=("physics_baselines",),
)


def physics_baselines_summary(table: pd.DataFrame, predictions: pd.DataFrame) -> list[dict]:
    """summary.json's `physics_baselines`: per rule, protocol and percent its mean accuracy,
    balanced accuracy, false-alarm rate and recall per class on the same test sets."""
    whole = table[(table["condition"] == evaluation.ALL) & (table["records"] == evaluation.ALL)]
    recalls = recall_per_class(predictions)
    entries = []
    for row in whole.itertuples(index=False):
        mine = recalls[
            (recalls["classifier"] == row.classifier)
            & (recalls["protocol"] == row.protocol)
            & (recalls["measured_percent"] == row.measured_percent)
        ]
        entries.append(
            {
                "baseline": row.classifier,
                "protocol": row.protocol,
                "measured_percent": int(row.measured_percent),
                "accuracy_mean": json_number(row.accuracy_mean),
                "balanced_accuracy_mean": json_number(row.balanced_accuracy_mean),
                "false_alarm_rate_mean": json_number(row.false_alarm_rate_mean),
                "recall_per_class": {
                    r.true_label: json_number(r.recall) for r in mine.itertuples()
                },
            }
        )
    return entries

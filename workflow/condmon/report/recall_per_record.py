"""The recall per record section: recall_per_record.csv, the share of every measured record's
test segments predicted right per (classifier, protocol, percent), beside the physics rules' own,
whether a fault record shows its defect line (the envelope rule's `fault_lines`), how much of the
record lies outside the simulated range (and outside its classifier's training range, the joined
jobs' coverage.csv) and why a record is reported apart (`unmodelled`); and summary.json's
`fault_lines` (each class's recall over the records that show their line and over those that do
not) and `simulation_coverage` (whether the design records lie inside the training range)."""

from __future__ import annotations

import pandas as pd

from condmon.joined import joined_name
from condmon.report.section import Section, Table
from condmon.signature import pooled_coverage, simulation_coverage


def write(report) -> dict:
    predictions, fault_lines = report.predictions, report.fault_lines
    tables = {}
    if report.wants("recall_per_record"):
        per_record = recall_per_record(
            predictions, fault_lines, report.physics, report.outside, report.coverage
        )
        # why a record is reported apart (empty for every modelled record)
        per_record["unmodelled"] = [
            report.apart.get(r, "") for r in per_record["record_id"].astype(str)
        ]
        tables["recall_per_record"] = per_record
    if fault_lines is not None:
        report.summary["fault_lines"] = fault_lines_summary(
            predictions, fault_lines, report.fault_line_rule
        )
    if report.coverage is not None and len(report.coverage):
        report.summary["simulation_coverage"] = simulation_coverage(
            report.coverage, report.design_records
        )
    return tables


SECTION = Section(
    "recall_per_record",
    write,
    inputs=(
        "train.predictions",
        "train.physics",
        "train.physics_info",
        "evaluation.measured_features",
        "evaluation.simulated_features",
        "evaluation.unmodelled",
        "train.coverage",
    ),
    tables=(
        Table(
            "recall_per_record",
            "recall_per_record.csv",
            "Recall per record (recall_per_record.csv)",
        ),
    ),
    summary_keys=("fault_lines", "simulation_coverage"),
)


def recall_per_record(
    predictions: pd.DataFrame,
    fault_lines: pd.DataFrame | None = None,
    physics: pd.DataFrame | None = None,
    outside: pd.DataFrame | None = None,
    coverage: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """Share of every measured record's test segments predicted right, per (classifier,
    protocol, percent), pooled over repeats and holdouts: shows which records a class's recall
    loses (a class's near-healthy records, say). With `fault_lines` (`load_fault_lines`) the columns
    `shows_line`: whether the fault record's defect line stands out of its envelope spectrum by
    any analysis the rule consults (empty for a healthy record), `line_shown_by`: the analyses
    that show it, strongest first, and `no_line_why`: why none does. With `physics` (the physics baselines' predictions) their rows
    too, `classifier` = the rule: where the classifiers and the training-free rule both call a
    record the same other class, the record has that class's envelope line within the rule's
    tolerance (a fault record with another location's line, say): look at its envelope spectrum.
    With `outside` (`condmon.signature.outside_simulation`) its two columns: the share of the
    record's segments whose features leave the simulated range, and which features do. With
    `coverage` (the joined jobs' coverage.csv) `outside_training`: the share of the record's
    segments outside its classifier's training range on the fit's own features, on the rows of
    that classifier and of its joined method (empty on others)."""
    if physics is not None:
        predictions = pd.concat([predictions, physics], ignore_index=True)
    hit = predictions["true_label"] == predictions["predicted_label"]
    table = (
        predictions.assign(hit=hit)
        .groupby(
            ["classifier", "protocol", "measured_percent", "record_id", "true_label"],
            as_index=False,
        )
        .agg(
            recall=("hit", "mean"),
            n_test=("hit", "size"),
            most_predicted=("predicted_label", lambda s: s.value_counts().index[0]),
        )
    )
    if fault_lines is not None:
        by_record = fault_lines.set_index("record_id")
        table["shows_line"] = (
            table["record_id"].astype(str).map(by_record["shows_line"]).astype(object)
        )
        # which analyses show the line, or why none does (a rule from before they were named: empty)
        for column, source in (("line_shown_by", "shown_by"), ("no_line_why", "no_line_why")):
            table[column] = (
                table["record_id"].astype(str).map(by_record[source]).astype(object)
                if source in by_record
                else None
            )
    if outside is not None:
        by_record = outside.set_index("record_id")
        for column in ("outside_simulation", "features_outside_simulation"):
            table[column] = table["record_id"].astype(str).map(by_record[column])
    if coverage is not None:
        pooled = pooled_coverage(coverage)
        pooled = pd.concat(
            [pooled, pooled.assign(classifier=pooled["classifier"].map(joined_name))]
        )
        keys = ["classifier", "protocol", "measured_percent", "record_id"]
        table = table.merge(
            pooled[keys + ["outside_training"]].astype(
                {"measured_percent": table["measured_percent"].dtype}
            ),
            on=keys,
            how="left",
        )
    return table


def fault_lines_summary(predictions: pd.DataFrame, fault_lines: pd.DataFrame, rule: dict) -> dict:
    """summary.json's `fault_lines`: every fault record's line ratio and whether it shows, and per
    (classifier, protocol, percent, class) the recall over the records that show their line and
    over those that do not."""
    shows = (
        predictions["record_id"].astype(str).map(fault_lines.set_index("record_id")["shows_line"])
    )
    known = predictions[shows.notna()].assign(
        shows_line=shows[shows.notna()].astype(bool),
        hit=lambda f: f["true_label"] == f["predicted_label"],
    )
    recall = []
    for (classifier, protocol, percent, label), part in known.groupby(
        ["classifier", "protocol", "measured_percent", "true_label"], sort=True
    ):
        row = {
            "classifier": classifier,
            "protocol": protocol,
            "measured_percent": int(percent),
            "label": label,
        }
        for shown, key in ((True, "shows_line"), (False, "no_line")):
            chosen = part[part["shows_line"] == shown]
            row[f"recall_{key}"] = float(chosen["hit"].mean()) if len(chosen) else None
            row[f"records_{key}"] = int(chosen["record_id"].nunique())
        recall.append(row)
    return {
        **rule,
        "what": "a fault record shows its line when, by any envelope analysis the rule consults, the "
        "median over its segments of the line ratio at its defect's line lies above the "
        "threshold the healthy calibration segments set for that analysis (the envelope "
        "rule's)",
        "records": fault_lines.to_dict(orient="records"),
        "recall": recall,
    }

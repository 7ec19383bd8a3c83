"""The measured share section (issue 71): where measured data of other records lower a figure.

A hybrid set at 100 % measured trains on the measured records the protocol does not test (in
`specimen_holdout`: the other specimens) beside the simulation. Where that lowers a method's
balanced accuracy against 0 % measured, the report says so and why: measured_share.csv, per
method and protocol, the balanced accuracy at the lowest and the highest measured share, the
change, the class whose recall falls most and the record that loses most, what that record is
called instead, and a sentence; summary.json's `measured_share` lists the figures that are lowered.
"""

from __future__ import annotations

import pandas as pd

from condmon.report.aggregate import json_number
from condmon.report.section import Section, Table

# a change smaller than this is no change (one segment in a few hundred)
LOWERED_BELOW = -0.01
COLUMNS = [
    "classifier",
    "protocol",
    "percent_from",
    "percent_to",
    "balanced_from",
    "balanced_to",
    "change",
    "lowered",
    "class_most_lowered",
    "class_change",
    "record_most_lowered",
    "specimen",
    "record_change",
    "record_called",
    "why",
]


def write(report) -> dict:
    table = measured_share(report.predictions, report.physics, report.specimens)
    lowered = table[table["lowered"]]
    report.summary["measured_share"] = {
        "what": "per method and protocol, the balanced accuracy at the lowest and the highest measured share; "
        f"lowered where it falls by more than {-LOWERED_BELOW:g} with measured data of the records the "
        "protocol does not test",
        "lowered": [
            {
                key: json_number(value) if isinstance(value, float) else value
                for key, value in row.items()
            }
            for row in lowered.to_dict(orient="records")
        ],
    }
    return {"measured_share": table}


SECTION = Section(
    "measured_share",
    write,
    inputs=(
        "train.predictions",
        "train.physics",
        "evaluation.measured_features",
        "upstream.measured_records",
    ),
    tables=(
        Table(
            "measured_share",
            "measured_share.csv",
            "Where measured data of other records lower a figure (measured_share.csv)",
            "Balanced accuracy at the lowest and the highest measured share per method and protocol; where "
            "it falls, the class and record that lose most and why.",
        ),
    ),
    summary_keys=("measured_share",),
)


def _recalls(part: pd.DataFrame) -> tuple[float, pd.Series, pd.DataFrame]:
    hit = part["true_label"] == part["predicted_label"]
    by_class = hit.groupby(part["true_label"]).mean()
    by_record = (
        part.assign(hit=hit)
        .groupby("record_id")
        .agg(recall=("hit", "mean"), label=("true_label", "first"))
    )
    # what a record's missed segments are called most often ("" where none is missed)
    missed = (
        part[~hit].groupby("record_id")["predicted_label"].agg(lambda s: s.value_counts().index[0])
    )
    by_record["called"] = missed.reindex(by_record.index).fillna("")
    return float(by_class.mean()), by_class, by_record


def measured_share(
    predictions: pd.DataFrame, physics: pd.DataFrame | None = None, specimens: dict | None = None
) -> pd.DataFrame:
    """The measured_share table (module docstring) from the predictions of every method (train's
    format: classifier, protocol, measured_percent, record_id, true_label, predicted_label; the
    physics rules' beside, whose calls do not depend on the measured share and so stay the same).

    Parameters
    ----------
    predictions, physics : pandas.DataFrame
    specimens : dict, optional
        {record_id: specimen} (records.csv), named beside the record that loses most.

    Returns
    -------
    pandas.DataFrame
        Columns `COLUMNS`, one row per method and protocol with at least two measured shares.
    """
    frames = [predictions] + ([physics] if physics is not None and len(physics) else [])
    every = pd.concat(frames, ignore_index=True).astype({"record_id": str})
    specimens = {str(k): v for k, v in (specimens or {}).items()}
    rows = []
    for (classifier, protocol), part in every.groupby(["classifier", "protocol"], sort=True):
        shares = sorted(part["measured_percent"].unique())
        if len(shares) < 2:
            continue
        low, high = int(shares[0]), int(shares[-1])
        before, classes_before, records_before = _recalls(part[part["measured_percent"] == low])
        after, classes_after, records_after = _recalls(part[part["measured_percent"] == high])
        change = after - before
        class_change = (classes_after - classes_before).dropna()
        record_change = (records_after["recall"] - records_before["recall"]).dropna()
        row = {
            "classifier": classifier,
            "protocol": protocol,
            "percent_from": low,
            "percent_to": high,
            "balanced_from": before,
            "balanced_to": after,
            "change": change,
            "lowered": bool(change < LOWERED_BELOW),
            "class_most_lowered": "",
            "class_change": None,
            "record_most_lowered": "",
            "specimen": "",
            "record_change": None,
            "record_called": "",
            "why": "",
        }
        if len(class_change) and len(record_change):
            worst_class, worst_record = class_change.idxmin(), record_change.idxmin()
            label, called = (
                records_after.loc[worst_record, "label"],
                records_after.loc[worst_record, "called"],
            )
            row.update(
                class_most_lowered=worst_class,
                class_change=float(class_change[worst_class]),
                record_most_lowered=worst_record,
                specimen=specimens.get(worst_record, ""),
                record_change=float(record_change[worst_record]),
                record_called=called,
            )
            if row["lowered"]:
                specimen = f" ({row['specimen']})" if row["specimen"] else ""
                row["why"] = (
                    f"with {high} % measured data the fit also learns the measured records {protocol} does not "
                    f"test; {worst_record}{specimen}, labelled {label}, is then called {called} on most of the "
                    f"{1 - records_after.loc[worst_record, 'recall']:.0%} of its segments it misses (recall "
                    f"{records_before.loc[worst_record, 'recall']:.2f} -> {records_after.loc[worst_record, 'recall']:.2f}): "
                    f"the measured {label} records it trains on resemble it less than the simulation does, "
                    f"and {worst_class}'s recall falls by {-class_change[worst_class]:.2f}"
                )
        rows.append(row)
    return pd.DataFrame(rows, columns=COLUMNS)

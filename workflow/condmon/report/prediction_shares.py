"""The prediction-shares section: where each true class's test predictions go.

prediction_shares.csv: per classifier, protocol, measured percentage and operating condition
(hybrid.condition: the speed, or e.g. the load), the share of each true class's test predictions
per predicted class (the CFRP study's Fig. 9), plotted per classifier and protocol at the
confusion percentages (``prediction_shares_<clf>_<protocol>.png``); beside it the confusion
matrices (``confusion_<clf>_<protocol>_<condition>.png``, all conditions and each one, and where
records of several kinds of specimens are tested each side apart: ``..._evaluation.png``,
``..._design.png``, ``..._unmodelled.png``).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from sklearn.metrics import confusion_matrix

from condmon import evaluation, plots
from condmon.labels import format_speed
from condmon.report.section import Section, Table

# prediction_shares.csv: per (classifier, protocol, percent, speed), true class x predicted class
SHARE_KEYS = ["classifier", "protocol", "measured_percent", "speed_rpm"]
SHARE_COLUMNS = SHARE_KEYS + ["true_label", "predicted_label", "share", "n"]


def write(report) -> dict:
    """The confusion matrices and prediction-share plots of every classifier and protocol, and
    prediction_shares.csv. A classifier may train on fewer percentages
    (classifiers.cnn.measured_percent): its plots show the chosen ones it has, and its own largest."""
    predictions, labels, condition = report.by_condition, report.labels, report.grouping
    shares = prediction_shares(predictions, labels, condition)
    record_ids = predictions["record_id"].astype(str)
    sides = record_sides(
        record_ids.isin(set(map(str, report.design_records))),
        record_ids.isin(set(map(str, report.apart))),
    )
    note, side_note = report.note(report.design_tested), report.note()
    for (classifier, protocol), group in predictions.groupby(["classifier", "protocol"]):
        own = sorted(int(p) for p in group["measured_percent"].unique())
        own_percents = sorted({p for p in report.percents if p in own} | {own[-1]})
        panels = [
            (
                group if value is None else group[group[condition] == value],
                plots.condition_label(condition, value),
                condition_file_part(condition, value),
                note,
            )
            for value in [None] + sorted(group[condition].unique())
        ]
        panels += [
            (group[side.loc[group.index]], where, name, f"{side_note} | {where} only")
            for name, side, where in sides
        ]
        for subset, where, name, panel_note in panels:
            matrices = {}
            for percent in own_percents:
                chosen = subset[subset["measured_percent"] == percent]
                matrices[percent] = (
                    confusion_counts(chosen["true_label"], chosen["predicted_label"], labels),
                    int(chosen["repeat"].nunique()),
                )
            report.save(
                plots.confusion_matrices(matrices, labels, classifier, protocol, where, panel_note),
                f"confusion_{classifier}_{protocol}_{name}.png",
            )
        own_shares = shares[(shares["classifier"] == classifier) & (shares["protocol"] == protocol)]
        report.save(
            plots.prediction_shares(
                own_shares, labels, classifier, protocol, own_percents, note, condition
            ),
            f"prediction_shares_{classifier}_{protocol}.png",
        )
    return {"prediction_shares": shares}


SECTION = Section(
    "prediction_shares",
    write,
    inputs=(
        "train.predictions",
        "evaluation.measured_features",
        "evaluation.condition",
        "evaluation.confusion_percent",
        "evaluation.design_records",
        "evaluation.design_specimens",
        "evaluation.unmodelled",
    ),
    tables=(
        Table(
            "prediction_shares",
            "prediction_shares.csv",
            "Prediction shares (prediction_shares.csv)",
        ),
    ),
)


def confusion_counts(true_labels, predicted_labels, labels) -> np.ndarray:
    """Counts, rows = true label, columns = predicted label, in the order of ``labels``; all zero
    when nothing was predicted (sklearn refuses empty input)."""
    true_labels, predicted_labels = list(true_labels), list(predicted_labels)
    if not true_labels:
        return np.zeros((len(labels), len(labels)), dtype=int)
    return confusion_matrix(true_labels, predicted_labels, labels=list(labels))


def share_rows(key: tuple, counts: np.ndarray, labels) -> list[tuple]:
    """Rows (*key, true, predicted, share, n) of one confusion matrix (rows = true labels in the
    order of ``labels``): every predicted label of every true label that was tested (n > 0),
    share = count / n, so a true label's shares sum to 1."""
    totals = counts.sum(axis=1)
    return [
        (*key, true, predicted, counts[i, j] / totals[i], int(totals[i]))
        for i, true in enumerate(labels)
        if totals[i] > 0
        for j, predicted in enumerate(labels)
    ]


def prediction_shares(
    predictions: pd.DataFrame, labels, condition: str = "speed_rpm"
) -> pd.DataFrame:
    """The study's prediction percentages (Fig. 9): per (classifier, protocol, measured percent,
    operating condition), the share of each true class's test segments predicted as each class,
    counts pooled over repeats and holdouts as in the confusion matrices and recall (with equal
    test sets per repeat, the mean over repeats). ``labels``: the class order (label_order).
    ``condition``: the predictions' column of the operating condition (speed_rpm, or e.g. the
    load: with_condition). Columns SHARE_COLUMNS, `condition` in place of speed_rpm; n = the true
    class's test segments at that condition."""
    keys = [condition if key == "speed_rpm" else key for key in SHARE_KEYS]
    columns = [condition if key == "speed_rpm" else key for key in SHARE_COLUMNS]
    rows = []
    for key, group in predictions.groupby(keys, sort=True):
        counts = confusion_counts(group["true_label"], group["predicted_label"], labels)
        rows += share_rows(key, counts, labels)
    shares = pd.DataFrame(rows, columns=columns)
    return shares.astype({"measured_percent": int, condition: float, "share": float, "n": int})


def condition_file_part(condition: str, value) -> str:
    """A per-condition plot's file name part: all, 450rpm, load2."""
    if value is None:
        return "all"
    if condition == "speed_rpm":
        return f"{format_speed(value)}rpm"
    return f"{condition}{float(value):g}"


def record_sides(
    is_design: pd.Series, is_apart: pd.Series | None = None
) -> list[tuple[str, pd.Series, str]]:
    """(file name part, row mask, title) of the tested records of evaluation specimens, of
    design specimens (`is_design`: per prediction, whether its record is of a design specimen)
    and of unmodelled specimens (`is_apart`, never among the evaluation records), where more than one
    side is tested (else none: the pooled figures are one side's)."""
    is_apart = pd.Series(False, index=is_design.index) if is_apart is None else is_apart
    sides = [
        ("evaluation", ~is_design & ~is_apart, "records of evaluation specimens"),
        ("design", is_design & ~is_apart, "records of design specimens"),
        (evaluation.UNMODELLED, is_apart, "records the model does not describe"),
    ]
    sides = [side for side in sides if side[1].any()]
    return sides if len(sides) > 1 else []

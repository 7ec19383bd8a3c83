"""Aggregates the report's sections share: accuracy over repeats and per speed, recall per class,
the simulation gain against the same classifier's measured-only baseline, a summary entry.

Aggregation over repeats: for ``condition_holdout`` one repeat has one evaluation per held-out
condition; these are first averaged per repeat (every condition weighs the same), then mean,
std, min and max are taken over repeats. Per-speed values are means over all evaluations that
tested that speed.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from condmon.labels import format_speed


def per_repeat_accuracy(accuracy: pd.DataFrame) -> pd.DataFrame:
    """All-speeds accuracy and macro-F1 per (classifier, protocol, percent, repeat).

    Held-out conditions of one repeat are averaged first (see module docstring).
    """
    all_speeds = accuracy[accuracy["speed_rpm"].isna()]
    return all_speeds.groupby(
        ["classifier", "protocol", "measured_percent", "repeat"], as_index=False
    ).agg(accuracy=("accuracy", "mean"), macro_f1=("macro_f1", "mean"), n_test=("n_test", "sum"))


def over_repeats(accuracy: pd.DataFrame) -> pd.DataFrame:
    """Mean, sample std (NaN with one repeat), min and max over repeats, all speeds."""
    per_repeat = per_repeat_accuracy(accuracy)
    return per_repeat.groupby(["classifier", "protocol", "measured_percent"], as_index=False).agg(
        n_repeats=("repeat", "nunique"),
        accuracy_mean=("accuracy", "mean"),
        accuracy_std=("accuracy", "std"),
        accuracy_min=("accuracy", "min"),
        accuracy_max=("accuracy", "max"),
        macro_f1_mean=("macro_f1", "mean"),
        macro_f1_std=("macro_f1", "std"),
        n_test_segments=("n_test", "mean"),
    )


def per_speed(accuracy: pd.DataFrame) -> pd.DataFrame:
    """Mean and std of accuracy per (classifier, protocol, percent, speed) over evaluations."""
    speeds = accuracy[accuracy["speed_rpm"].notna()]
    return speeds.groupby(
        ["classifier", "protocol", "measured_percent", "speed_rpm"], as_index=False
    ).agg(
        accuracy_mean=("accuracy", "mean"),
        accuracy_std=("accuracy", "std"),
        macro_f1_mean=("macro_f1", "mean"),
        n_evaluations=("accuracy", "size"),
    )


def json_number(value):
    """NaN -> None so summary.json stays valid JSON; numpy scalars -> Python."""
    if value is None:
        return None
    value = float(value)
    return None if not np.isfinite(value) else value


def recall_per_class(predictions: pd.DataFrame) -> pd.DataFrame:
    """Recall of every true class per (classifier, protocol, percent): the share of its test
    segments predicted right, pooled over repeats and holdouts."""
    hit = predictions["true_label"] == predictions["predicted_label"]
    return (
        predictions.assign(hit=hit)
        .groupby(["classifier", "protocol", "measured_percent", "true_label"], as_index=False)
        .agg(recall=("hit", "mean"), n_test=("hit", "size"))
    )


def simulation_gain(accuracy: pd.DataFrame, baseline: pd.DataFrame) -> pd.DataFrame:
    """Per (classifier, protocol, percent): mean accuracy with the simulated data, of the same
    classifier on the same measured training data alone, and their difference (the gain).
    Splits with no measured training data have no baseline (NaN)."""
    keys = ["classifier", "protocol", "measured_percent"]
    if baseline.empty:
        return pd.DataFrame(columns=keys + ["hybrid", "measured_only", "gain"])
    hybrid = over_repeats(accuracy)[keys + ["accuracy_mean"]].rename(
        columns={"accuracy_mean": "hybrid"}
    )
    alone = over_repeats(baseline)[keys + ["accuracy_mean"]].rename(
        columns={"accuracy_mean": "measured_only"}
    )
    gain = hybrid.merge(alone, on=keys, how="left")
    gain["gain"] = gain["hybrid"] - gain["measured_only"]
    return gain


def accuracy_entry(row, speeds: pd.DataFrame) -> dict:
    """The accuracy part of a summary entry: one row of over_repeats and its per_speed rows."""
    speed_rows = speeds[
        (speeds["classifier"] == row.classifier)
        & (speeds["protocol"] == row.protocol)
        & (speeds["measured_percent"] == row.measured_percent)
    ]
    return {
        "classifier": row.classifier,
        "protocol": row.protocol,
        "measured_percent": int(row.measured_percent),
        "n_repeats": int(row.n_repeats),
        "accuracy_mean": json_number(row.accuracy_mean),
        "accuracy_std": json_number(row.accuracy_std),
        "accuracy_min": json_number(row.accuracy_min),
        "accuracy_max": json_number(row.accuracy_max),
        "macro_f1_mean": json_number(row.macro_f1_mean),
        "macro_f1_std": json_number(row.macro_f1_std),
        "accuracy_mean_per_speed": {
            format_speed(s.speed_rpm): json_number(s.accuracy_mean)
            for s in speed_rows.itertuples(index=False)
        },
    }

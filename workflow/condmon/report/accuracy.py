"""The accuracy section: accuracy.csv (the train jobs' metrics, labelled), summary.json's head
(data source, calibration, labels, per classifier x protocol x measured percentage the mean and
spread of accuracy over repeats, per-speed means, recall per class, the simulation gain, record
counts, the plot list) and the accuracy plots (vs measured percentage, per speed, recall per class).
"""

from __future__ import annotations

import pandas as pd

from condmon import plots
from condmon.evaluation import SMALL_TEST_SET, wilson_interval
from condmon.labels import (
    LEAKY_PROTOCOLS,
    data_source_label,
    is_synthetic,
    label_order,
    protocol_label,
)
from condmon.report.aggregate import (
    accuracy_entry,
    json_number,
    over_repeats,
    per_repeat_accuracy,
    per_speed,
    recall_per_class,
    simulation_gain,
)
from condmon.report.section import Section, Table

HEAD = (
    "run_name",
    "data_source",
    "calibration",
    "labels",
    "chance_accuracy",
    "n_measured_records",
    "n_evaluations",
    "aggregation",
    "protocols",
    "simulation_gain",
    "results",
    "plots",
)


def write(report) -> dict:
    """The accuracy plots, summary.json's head, accuracy.csv."""
    accuracy, predictions, run = report.accuracy, report.by_condition, report.run
    note, percents = report.note(report.design_tested), report.percents
    report.save(
        plots.accuracy_vs_measured_percent(per_repeat_accuracy(accuracy), report.chance, note),
        "accuracy_vs_measured_percent.png",
    )
    if report.grouping == "speed_rpm":  # accuracy_per_condition.png covers any condition
        report.save(
            plots.accuracy_per_speed(
                accuracy[accuracy["speed_rpm"].notna()], percents, report.chance, note
            ),
            "accuracy_per_speed.png",
        )
    report.save(plots.recall_per_class(recall_per_class(predictions), note), "recall_per_class.png")
    report.summary.update(
        summarize(
            accuracy,
            report.predictions,
            report.calibration,
            run.run_name,
            run.data_source,
            report.plots,
            report.baseline,
            run.healthy_state,
        )
    )
    if run.bench_differences:
        report.summary["data_source"]["bench_differences"] = [
            dict(row) for row in run.bench_differences
        ]
    return {"accuracy": labelled_accuracy(accuracy)}


SECTION = Section(
    "accuracy",
    write,
    inputs=(
        "run.run_name",
        "run.data_source",
        "run.healthy_state",
        "run.bench_differences",
        "train.metrics",
        "train.predictions",
        "train.measured_only",
        "calibration.params",
        "evaluation.confusion_percent",
    ),
    tables=(Table("accuracy", "accuracy.csv", "Accuracy per evaluation (accuracy.csv)"),),
    summary_keys=HEAD,
)


def labelled_accuracy(accuracy: pd.DataFrame) -> pd.DataFrame:
    """accuracy.csv as written: every row with `leaky` (segments of one record on both sides of
    the split), a 95 % Wilson interval of the accuracy over its test segments (segments of one
    record are not independent, so the interval is optimistic) and `small_test_set` (under
    SMALL_TEST_SET segments)."""
    out = accuracy.copy()
    out["leaky"] = out["protocol"].isin(LEAKY_PROTOCOLS)
    bounds = [
        wilson_interval(int(round(a * n)), int(n)) for a, n in zip(out["accuracy"], out["n_test"])
    ]
    out["accuracy_ci_low"] = [low for low, _ in bounds]
    out["accuracy_ci_high"] = [high for _, high in bounds]
    out["small_test_set"] = out["n_test"] < SMALL_TEST_SET
    return out


def summarize(
    accuracy: pd.DataFrame,
    predictions: pd.DataFrame,
    calibration: dict,
    run_name: str,
    data_source: str,
    plot_names: list[str],
    baseline: pd.DataFrame | None = None,
    healthy_state: str | None = None,
) -> dict:
    """The content of summary.json (see module docstring)."""
    recalls = recall_per_class(predictions)
    gains = simulation_gain(accuracy, baseline if baseline is not None else accuracy.iloc[:0])
    gains = gains.set_index(["classifier", "protocol", "measured_percent"])
    test_records = (
        predictions.groupby(["classifier", "protocol", "measured_percent", "repeat"])["record_id"]
        .nunique()
        .groupby(level=["classifier", "protocol", "measured_percent"])
        .mean()
    )
    speeds = per_speed(accuracy)
    results = []
    for row in over_repeats(accuracy).itertuples(index=False):
        key = (row.classifier, row.protocol, row.measured_percent)
        results.append(
            {
                **accuracy_entry(row, speeds),
                "n_test_records_per_repeat": json_number(test_records.get(key)),
                "n_test_segments_per_repeat": json_number(row.n_test_segments),
                "protocol_label": protocol_label(row.protocol),
                "recall_per_class": {
                    r.true_label: json_number(r.recall)
                    for r in recalls[
                        (recalls["classifier"] == row.classifier)
                        & (recalls["protocol"] == row.protocol)
                        & (recalls["measured_percent"] == row.measured_percent)
                    ].itertuples()
                },
                "measured_only_accuracy_mean": (
                    json_number(gains.loc[key, "measured_only"]) if key in gains.index else None
                ),
                "simulation_gain": (
                    json_number(gains.loc[key, "gain"]) if key in gains.index else None
                ),
            }
        )
    labels = label_order(
        [*predictions["true_label"], *predictions["predicted_label"]], healthy_state
    )
    return {
        "run_name": run_name,
        "data_source": {
            "kind": data_source,
            "synthetic": is_synthetic(data_source),
            "label": data_source_label(data_source),
            "note": (
                "synthetic data from the virtual bench, not real measurements; every "
                "number below is measured on it"
                if is_synthetic(data_source)
                else ""
            ),
        },
        "calibration": calibration,
        "labels": labels,
        "chance_accuracy": 1.0 / len(labels),
        "n_measured_records": int(predictions["record_id"].nunique()),
        "n_evaluations": int(accuracy["speed_rpm"].isna().sum()),
        "aggregation": (
            "accuracy_std is the sample std over repeats (null with one repeat); "
            "condition_holdout: held-out conditions are averaged within a repeat first"
        ),
        "protocols": {p: protocol_label(p) for p in sorted(accuracy["protocol"].unique())},
        "simulation_gain": (
            "accuracy with the simulated data minus accuracy of the same "
            "classifier on the same measured training data alone (null: no "
            "measured-only baseline, or no measured training data); the "
            "headline is gain_vs_strongest_mean, against the strongest of "
            "chance, majority class, the best measured-only classifier (its "
            "feature selection chosen by its own inner CV) and the system's "
            "training-free physics baseline (physics_baselines); negative where "
            "a baseline wins"
        ),
        "results": results,
        "plots": plot_names,
    }

"""The report stage: accuracy table, summary and plots from the train and calibration outputs.

Reads only the files of the stage contracts (train/<classifier>/<protocol>/metrics.csv and
predictions.parquet, calibration/<calibration variant>/params.json, spectra.parquet,
history.parquet) and writes

- ``accuracy.csv``: the concatenated metrics files, sorted; columns ``condmon.train_tables.ACCURACY_COLUMNS``;
- ``summary.json``: data source, calibration (the one the simulated data come from; with one
  calibration per calibration variant each one's model variant, final and nominal cost,
  evaluations and seconds under ``calibration_by_variant``), per classifier x
  protocol x measured percentage the mean and spread of accuracy over repeats, per-speed means,
  record counts, plot list;
- ``prediction_shares.csv``: per classifier, protocol, measured percentage and speed, the share of
  each true class's test predictions per predicted class (the CFRP study's Fig. 9); plotted per
  classifier and protocol at the confusion percentages (``prediction_shares_<clf>_<protocol>.png``);
- ``plots/*.png``: see ``condmon.plots``.

With hybrid.simulated_validation_share > 0 the train stage's ``simulated_validation.csv`` files
(accuracy on held-out SIMULATED records) go to ``summary.json`` under ``simulated_validation``,
aggregated like the measured results but never mixed into them (nor into accuracy.csv or plots).

Aggregation over repeats: for ``condition_holdout`` one repeat has one evaluation per held-out
condition; these are first averaged per repeat (every condition weighs the same), then mean,
std, min and max are taken over repeats. Per-speed values are means over all evaluations that
tested that speed.
"""
from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import confusion_matrix

from condmon import evaluation, job_timings, plots
from condmon.evaluation import SMALL_TEST_SET, wilson_interval
from condmon.features import read_feature_table
from condmon.atomic import staging_directory, write_text
from condmon.hybrid import SIMULATED_VALIDATION
from condmon.joined import joined_name
from condmon.labels import (LEAKY_PROTOCOLS, data_source_label, format_speed, is_synthetic,
                            label_order, protocol_label, protocol_title)
from condmon.report_inputs import CalibrationOutputs, ReportInputs, RunIdentity
from condmon.separability import SHOWN_RECALL, measured_separability
from condmon.signature import (fault_signatures, outside_simulation, pooled_coverage,
                               signature_table, simulation_coverage)
from condmon.train_tables import ReportInputError, load_metrics, load_predictions, read_table

log = logging.getLogger(__name__)

# prediction_shares.csv: per (classifier, protocol, percent, speed), true class x predicted class
SHARE_KEYS = ["classifier", "protocol", "measured_percent", "speed_rpm"]
SHARE_COLUMNS = SHARE_KEYS + ["true_label", "predicted_label", "share", "n"]
SIMULATED_VALIDATION_LABEL = (
    "accuracy on SIMULATED records held out of training (hybrid.simulated_validation_share), "
    "not on measured data: never part of the measured results")


# --------------------------------------------------------------------------- inputs

def load_simulated_validation(paths) -> pd.DataFrame | None:
    """The train stage's simulated_validation.csv files as one table (columns ACCURACY_COLUMNS
    and test_source), or None when no file has a row (no simulated record was held out)."""
    with_rows = [p for p in paths if len(pd.read_csv(p))]
    if not with_rows:
        return None
    table = load_metrics(with_rows, extra_columns=("test_source",))
    sources = set(table["test_source"]) if "test_source" in table.columns else {None}
    if sources != {SIMULATED_VALIDATION}:
        raise ReportInputError(f"simulated validation files {[str(p) for p in with_rows]}: "
                               f"test_source {sorted(map(str, sources))}, expected "
                               f"only {SIMULATED_VALIDATION!r}")
    return table


def load_calibration(params_path) -> dict:
    """The calibration summary: model variant, cost, evaluations, parameters."""
    params_path = Path(params_path)
    try:
        params = json.loads(params_path.read_text())
    except FileNotFoundError:
        raise ReportInputError(f"{params_path}: no such calibration file") from None
    except json.JSONDecodeError as exc:
        raise ReportInputError(f"{params_path}: not valid JSON ({exc})") from exc
    missing = [k for k in ("model_variant", "parameters", "cost", "evaluations") if k not in params]
    if missing:
        raise ReportInputError(f"{params_path}: calibration file lacks keys {missing}")
    summary = {"model_variant": params["model_variant"], "cost": params["cost"],
               "evaluations": params["evaluations"], "parameters": params["parameters"]}
    for key in ("nominal_cost", "seconds", "sensor_noise"):
        if key in params:
            summary[key] = params[key]
    return summary


# --------------------------------------------------------------------------- aggregation

def labelled_accuracy(accuracy: pd.DataFrame) -> pd.DataFrame:
    """accuracy.csv as written: every row with `leaky` (segments of one record on both sides of
    the split), a 95 % Wilson interval of the accuracy over its test segments (segments of one
    record are not independent, so the interval is optimistic) and `small_test_set` (under
    SMALL_TEST_SET segments)."""
    out = accuracy.copy()
    out["leaky"] = out["protocol"].isin(LEAKY_PROTOCOLS)
    bounds = [wilson_interval(int(round(a * n)), int(n)) for a, n in zip(out["accuracy"], out["n_test"])]
    out["accuracy_ci_low"] = [low for low, _ in bounds]
    out["accuracy_ci_high"] = [high for _, high in bounds]
    out["small_test_set"] = out["n_test"] < SMALL_TEST_SET
    return out


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
    return [(*key, true, predicted, counts[i, j] / totals[i], int(totals[i]))
            for i, true in enumerate(labels) if totals[i] > 0
            for j, predicted in enumerate(labels)]


def prediction_shares(predictions: pd.DataFrame, labels,
                      condition: str = "speed_rpm") -> pd.DataFrame:
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


def record_conditions(measured_features_path, condition: str) -> dict:
    """{record_id: its value of the operating condition} from the measured features."""
    features = pd.read_parquet(measured_features_path, columns=["record_id", condition])
    return dict(zip(features["record_id"].astype(str), features[condition].astype(float)))


def with_condition(predictions: pd.DataFrame, conditions: dict, condition: str) -> pd.DataFrame:
    """The predictions with a column `condition` (each record's operating condition, e.g. a
    motor load, where each file's stored speed would split one load into many groups);
    speed_rpm is there already. A tested record without a condition is an error."""
    if condition in predictions.columns:
        return predictions
    values = predictions["record_id"].astype(str).map(conditions)
    missing = sorted(set(predictions.loc[values.isna(), "record_id"].astype(str)))
    if missing:
        raise ReportInputError(f"the measured features give no {condition!r} (hybrid.condition) "
                               f"for the tested records {missing[:5]}")
    return predictions.assign(**{condition: values.astype(float)})


def per_repeat_accuracy(accuracy: pd.DataFrame) -> pd.DataFrame:
    """All-speeds accuracy and macro-F1 per (classifier, protocol, percent, repeat).

    Held-out conditions of one repeat are averaged first (see module docstring).
    """
    all_speeds = accuracy[accuracy["speed_rpm"].isna()]
    return (all_speeds
            .groupby(["classifier", "protocol", "measured_percent", "repeat"], as_index=False)
            .agg(accuracy=("accuracy", "mean"), macro_f1=("macro_f1", "mean"),
                 n_test=("n_test", "sum")))


def over_repeats(accuracy: pd.DataFrame) -> pd.DataFrame:
    """Mean, sample std (NaN with one repeat), min and max over repeats, all speeds."""
    per_repeat = per_repeat_accuracy(accuracy)
    return (per_repeat
            .groupby(["classifier", "protocol", "measured_percent"], as_index=False)
            .agg(n_repeats=("repeat", "nunique"),
                 accuracy_mean=("accuracy", "mean"), accuracy_std=("accuracy", "std"),
                 accuracy_min=("accuracy", "min"), accuracy_max=("accuracy", "max"),
                 macro_f1_mean=("macro_f1", "mean"), macro_f1_std=("macro_f1", "std"),
                 n_test_segments=("n_test", "mean")))


def per_speed(accuracy: pd.DataFrame) -> pd.DataFrame:
    """Mean and std of accuracy per (classifier, protocol, percent, speed) over evaluations."""
    speeds = accuracy[accuracy["speed_rpm"].notna()]
    return (speeds
            .groupby(["classifier", "protocol", "measured_percent", "speed_rpm"], as_index=False)
            .agg(accuracy_mean=("accuracy", "mean"), accuracy_std=("accuracy", "std"),
                 macro_f1_mean=("macro_f1", "mean"), n_evaluations=("accuracy", "size")))


def _json_number(value):
    """NaN -> None so summary.json stays valid JSON; numpy scalars -> Python."""
    if value is None:
        return None
    value = float(value)
    return None if not np.isfinite(value) else value


def recall_per_class(predictions: pd.DataFrame) -> pd.DataFrame:
    """Recall of every true class per (classifier, protocol, percent): the share of its test
    segments predicted right, pooled over repeats and holdouts."""
    hit = predictions["true_label"] == predictions["predicted_label"]
    return (predictions.assign(hit=hit)
            .groupby(["classifier", "protocol", "measured_percent", "true_label"], as_index=False)
            .agg(recall=("hit", "mean"), n_test=("hit", "size")))


def recall_per_record(predictions: pd.DataFrame, fault_lines: pd.DataFrame | None = None,
                      physics: pd.DataFrame | None = None,
                      outside: pd.DataFrame | None = None,
                      coverage: pd.DataFrame | None = None) -> pd.DataFrame:
    """Share of every measured record's test segments predicted right, per (classifier,
    protocol, percent), pooled over repeats and holdouts: shows which records a class's recall
    loses (a class's near-healthy records, say). With `fault_lines` (`load_fault_lines`) a column
    `shows_line`: whether the fault record's defect line stands out of its envelope spectrum
    (empty for a healthy record). With `physics` (the physics baselines' predictions) their rows
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
    table = (predictions.assign(hit=hit)
             .groupby(["classifier", "protocol", "measured_percent", "record_id", "true_label"],
                      as_index=False)
             .agg(recall=("hit", "mean"), n_test=("hit", "size"),
                  most_predicted=("predicted_label", lambda s: s.value_counts().index[0])))
    if fault_lines is not None:
        table["shows_line"] = table["record_id"].astype(str).map(
            fault_lines.set_index("record_id")["shows_line"]).astype(object)
    if outside is not None:
        by_record = outside.set_index("record_id")
        for column in ("outside_simulation", "features_outside_simulation"):
            table[column] = table["record_id"].astype(str).map(by_record[column])
    if coverage is not None:
        pooled = pooled_coverage(coverage)
        pooled = pd.concat([pooled, pooled.assign(classifier=pooled["classifier"].map(joined_name))])
        keys = ["classifier", "protocol", "measured_percent", "record_id"]
        table = table.merge(pooled[keys + ["outside_training"]].astype({"measured_percent": table[
            "measured_percent"].dtype}), on=keys, how="left")
    return table


def load_fault_lines(info_paths) -> tuple[pd.DataFrame | None, dict]:
    """(per fault record whether its defect line shows, the rule's description) from the physics
    baselines' info.json (the first rule that gives `fault_lines`, `EnvelopeRule.fault_lines`);
    (None, {}) without one."""
    for path in info_paths:
        for name, rule in json.loads(Path(path).read_text()).get("baselines", {}).items():
            if rule.get("fault_lines"):
                return pd.DataFrame(rule["fault_lines"]), {"rule": name, "threshold": rule.get("threshold"),
                                                           "threshold_from": rule.get("threshold_from")}
    return None, {}


def fault_lines_summary(predictions: pd.DataFrame, fault_lines: pd.DataFrame, rule: dict) -> dict:
    """summary.json's `fault_lines`: every fault record's line ratio and whether it shows, and per
    (classifier, protocol, percent, class) the recall over the records that show their line and
    over those that do not."""
    shows = predictions["record_id"].astype(str).map(fault_lines.set_index("record_id")["shows_line"])
    known = predictions[shows.notna()].assign(shows_line=shows[shows.notna()].astype(bool),
                                              hit=lambda f: f["true_label"] == f["predicted_label"])
    recall = []
    for (classifier, protocol, percent, label), part in known.groupby(
            ["classifier", "protocol", "measured_percent", "true_label"], sort=True):
        row = {"classifier": classifier, "protocol": protocol, "measured_percent": int(percent), "label": label}
        for shown, key in ((True, "shows_line"), (False, "no_line")):
            chosen = part[part["shows_line"] == shown]
            row[f"recall_{key}"] = float(chosen["hit"].mean()) if len(chosen) else None
            row[f"records_{key}"] = int(chosen["record_id"].nunique())
        recall.append(row)
    return {**rule, "what": "a fault record shows its line when the median over its segments of the envelope "
                            "line ratio at its defect's line lies above the threshold the healthy calibration "
                            "segments set (the envelope rule's)",
            "records": fault_lines.to_dict(orient="records"), "recall": recall}


def simulation_gain(accuracy: pd.DataFrame, baseline: pd.DataFrame) -> pd.DataFrame:
    """Per (classifier, protocol, percent): mean accuracy with the simulated data, of the same
    classifier on the same measured training data alone, and their difference (the gain).
    Splits with no measured training data have no baseline (NaN)."""
    keys = ["classifier", "protocol", "measured_percent"]
    if baseline.empty:
        return pd.DataFrame(columns=keys + ["hybrid", "measured_only", "gain"])
    hybrid = over_repeats(accuracy)[keys + ["accuracy_mean"]].rename(
        columns={"accuracy_mean": "hybrid"})
    alone = over_repeats(baseline)[keys + ["accuracy_mean"]].rename(
        columns={"accuracy_mean": "measured_only"})
    gain = hybrid.merge(alone, on=keys, how="left")
    gain["gain"] = gain["hybrid"] - gain["measured_only"]
    return gain


def gain_against_strongest(overall: pd.DataFrame) -> pd.DataFrame:
    """The simulation_gain plot's table from evaluation_summary's `all` rows: per classifier,
    protocol and percent the hybrid accuracy, the strongest baseline's, the gain, and each
    baseline's (best measured-only, physics baseline, majority class)."""
    whole = overall[(overall["condition"] == evaluation.ALL) & (overall["records"] == evaluation.ALL)]
    return whole.rename(columns={
        "accuracy_mean": "hybrid", "strongest_baseline_accuracy_mean": "strongest",
        "gain_vs_strongest_mean": "gain", "measured_only_best_mean": "measured_only_best",
        "physics_baseline_accuracy_mean": "physics_baseline_accuracy",
        "majority_class_mean": "majority_class"})[
        ["classifier", "protocol", "measured_percent", "hybrid", "strongest", "gain",
         "measured_only_best", "physics_baseline_accuracy", "majority_class"]]


def _mean_and_range(row) -> str:
    """A headline cell: the mean over repeats, with its min-max where repeats differ."""
    if row is None or not np.isfinite(row["accuracy_mean"]):
        return "-"
    text = f"{row['accuracy_mean']:.3f}"
    if row.get("accuracy_max", np.nan) - row.get("accuracy_min", np.nan) > 0:
        text += f" ({row['accuracy_min']:.3f}-{row['accuracy_max']:.3f})"
    return text


HEADLINE_RECORDS = {evaluation.ALL: "all", "evaluation": "evaluation specimens",
                    "design": "design specimens"}
NO_EVALUATION_SPECIMEN = ("no evaluation specimen in this data: every tested record is of a "
                          "design specimen; add records of other specimens (point measured_dir "
                          "at a full download of the data set). The design-specimen figures "
                          "below are no headline")


def records_over_repeats(table: pd.DataFrame, records: str) -> pd.DataFrame:
    """over_repeats of the evaluation table's rows of condition `all` and these `records`
    (design, evaluation): held-out conditions averaged within a repeat first, as accuracy.csv's."""
    rows = table[(table["condition"] == evaluation.ALL) & (table["records"] == records)]
    return over_repeats(rows.assign(speed_rpm=np.nan, macro_f1=np.nan))


def headline_table(accuracy: pd.DataFrame, baseline: pd.DataFrame | None,
                   physics_overall: pd.DataFrame | None, chance: float,
                   table: pd.DataFrame | None = None,
                   physics_table: pd.DataFrame | None = None,
                   measured_only_table: pd.DataFrame | None = None) -> pd.DataFrame:
    """The report's front-page table: per protocol, every classifier's accuracy on held-out
    measured records at the smallest and the largest measured share in training (0 and 100 %
    in a default run; mean over repeats as accuracy.csv and summary.json give it, with its
    min-max over repeats), then the baselines on the same test sets where the run has them: the
    best measured-only classifier, each physics baseline (training-free), chance.

    `table`, `physics_table`, `measured_only_table`: the evaluation tables (condmon.evaluation)
    of the classifiers, the physics baselines and the measured-only baselines (from their
    predictions; None: that baseline is left out of the design and evaluation rows); where they
    hold design and evaluation rows (design records declared), the headline is on the
    evaluation specimens' records, then the design specimens' follow, each labelled in the
    `records` column; without any evaluation record one row says so (NO_EVALUATION_SPECIMEN).
    Otherwise every row is on all test records (`records` all)."""
    percents = sorted(int(p) for p in accuracy["measured_percent"].unique())
    chosen = sorted({percents[0], percents[-1]})
    columns = {p: ("simulation only (0 % measured)" if p == 0 else f"{p} % measured")
               for p in chosen}
    if table is None or not table["records"].isin(["design", "evaluation"]).any():
        alone = over_repeats(baseline) if baseline is not None and not baseline.empty else None
        return _headline_rows(evaluation.ALL, over_repeats(accuracy), alone, physics_overall,
                              chance, chosen, columns)
    parts = []
    for records in ("evaluation", "design"):
        results = records_over_repeats(table, records)
        if results.empty and records == "design":
            continue
        if results.empty:
            parts.append(pd.DataFrame([{"records": HEADLINE_RECORDS[records], "protocol": "-",
                                        "model": NO_EVALUATION_SPECIMEN,
                                        **{c: "-" for c in columns.values()}}]))
            continue
        physics = (None if physics_table is None else
                   records_over_repeats(physics_table, records).assign(
                       condition=evaluation.ALL, records=evaluation.ALL))
        alone = (None if measured_only_table is None else
                 records_over_repeats(measured_only_table, records))
        parts.append(_headline_rows(records, results, alone, physics, chance, chosen, columns))
    return pd.concat(parts, ignore_index=True)


CEILING_PROTOCOL = "measured records alone"
CEILING_MODEL = ("ceiling: a classifier on the measured records alone, each record left out "
                 "(balanced accuracy; summary.json measured_separability)")


def with_ceiling(headline: pd.DataFrame, separability: dict | None) -> pd.DataFrame:
    """The headline with a last row, in its largest share's column: how well the measured records
    separate their classes on their own (`measured_separability`'s balanced accuracy over all
    records), the most a classifier trained elsewhere can be expected to reach on them; unchanged
    without that figure (a class with a single record)."""
    ceiling = None if separability is None else separability["all"]["balanced_accuracy"]
    if ceiling is None:
        return headline
    shares = list(headline.columns[3:])
    row = {"records": HEADLINE_RECORDS[evaluation.ALL], "protocol": CEILING_PROTOCOL, "model": CEILING_MODEL,
           **{column: "-" for column in shares[:-1]}, shares[-1]: f"{ceiling:.3f}"}
    return pd.concat([headline, pd.DataFrame([row])], ignore_index=True)


def _headline_rows(records: str, results: pd.DataFrame, alone: pd.DataFrame | None,
                   physics_overall: pd.DataFrame | None, chance: float, chosen: list,
                   columns: dict) -> pd.DataFrame:
    """headline_table's rows of one set of test records (`results`, `alone`: over_repeats of
    the classifiers' and the measured-only baselines' accuracy on them)."""

    def cells(rows: pd.DataFrame) -> dict:
        by_percent = {int(r["measured_percent"]): r for _, r in rows.iterrows()}
        return {columns[p]: _mean_and_range(by_percent.get(p)) for p in chosen}

    alone = alone if alone is not None and not alone.empty else None
    physics = None
    if physics_overall is not None and not physics_overall.empty:
        physics = physics_overall[(physics_overall["condition"] == evaluation.ALL)
                                  & (physics_overall["records"] == evaluation.ALL)]
    rows = []
    for protocol in sorted(results["protocol"].unique()):
        title = protocol_title(protocol)
        mine = results[results["protocol"] == protocol]
        for classifier in sorted(mine["classifier"].unique()):
            rows.append({"protocol": title, "model": f"{classifier} (simulated + measured)",
                         **cells(mine[mine["classifier"] == classifier])})
        if alone is not None and not alone[alone["protocol"] == protocol].empty:
            # per share, the best measured-only classifier (its name in the cell)
            own = alone[alone["protocol"] == protocol]
            best = own.loc[own.groupby("measured_percent")["accuracy_mean"].idxmax().dropna()]
            row = {"protocol": title, "model": "baseline: measured data only (best classifier)"}
            for p in chosen:
                at = best[best["measured_percent"] == p]
                row[columns[p]] = ("-" if at.empty else
                                   f"{_mean_and_range(at.iloc[0])} {at.iloc[0]['classifier']}")
            rows.append(row)
        if physics is not None:
            for rule, own in physics[physics["protocol"] == protocol].groupby("classifier"):
                row = {"protocol": title, "model": f"baseline: physics rule {rule} (no training)"}
                for p in chosen:
                    at = own[own["measured_percent"] == p]
                    row[columns[p]] = ("-" if at.empty or not np.isfinite(at.iloc[0]["accuracy_mean"])
                                       else f"{at.iloc[0]['accuracy_mean']:.3f}")
                rows.append(row)
        rows.append({"protocol": title, "model": "chance",
                     **{columns[p]: f"{chance:.3f}" for p in chosen}})
    return pd.DataFrame(rows, columns=["protocol", "model", *columns.values()]).assign(
        records=HEADLINE_RECORDS[records])[["records", "protocol", "model", *columns.values()]]


def physics_baselines_summary(table: pd.DataFrame, predictions: pd.DataFrame) -> list[dict]:
    """summary.json's `physics_baselines`: per rule, protocol and percent its mean accuracy,
    balanced accuracy, false-alarm rate and recall per class on the same test sets."""
    whole = table[(table["condition"] == evaluation.ALL) & (table["records"] == evaluation.ALL)]
    recalls = recall_per_class(predictions)
    entries = []
    for row in whole.itertuples(index=False):
        mine = recalls[(recalls["classifier"] == row.classifier)
                       & (recalls["protocol"] == row.protocol)
                       & (recalls["measured_percent"] == row.measured_percent)]
        entries.append({"baseline": row.classifier, "protocol": row.protocol,
                        "measured_percent": int(row.measured_percent),
                        "accuracy_mean": _json_number(row.accuracy_mean),
                        "balanced_accuracy_mean": _json_number(row.balanced_accuracy_mean),
                        "false_alarm_rate_mean": _json_number(row.false_alarm_rate_mean),
                        "recall_per_class": {r.true_label: _json_number(r.recall)
                                             for r in mine.itertuples()}})
    return entries


def accuracy_entry(row, speeds: pd.DataFrame) -> dict:
    """The accuracy part of a summary entry: one row of over_repeats and its per_speed rows."""
    speed_rows = speeds[(speeds["classifier"] == row.classifier)
                        & (speeds["protocol"] == row.protocol)
                        & (speeds["measured_percent"] == row.measured_percent)]
    return {
        "classifier": row.classifier,
        "protocol": row.protocol,
        "measured_percent": int(row.measured_percent),
        "n_repeats": int(row.n_repeats),
        "accuracy_mean": _json_number(row.accuracy_mean),
        "accuracy_std": _json_number(row.accuracy_std),
        "accuracy_min": _json_number(row.accuracy_min),
        "accuracy_max": _json_number(row.accuracy_max),
        "macro_f1_mean": _json_number(row.macro_f1_mean),
        "macro_f1_std": _json_number(row.macro_f1_std),
        "accuracy_mean_per_speed": {format_speed(s.speed_rpm): _json_number(s.accuracy_mean)
                                    for s in speed_rows.itertuples(index=False)},
    }


def simulated_validation_summary(validation: pd.DataFrame) -> dict:
    """summary.json's ``simulated_validation``: per classifier, protocol and measured percent the
    accuracy on the held-out simulated records (mean, spread over repeats, per speed), labelled
    as simulated; ``validation`` is the table of load_simulated_validation."""
    segments = (validation[validation["speed_rpm"].isna()]
                .groupby(["classifier", "protocol", "measured_percent"])["n_test"].max())
    speeds = per_speed(validation)
    results = [{**accuracy_entry(row, speeds),
                "n_validation_segments": int(segments[(row.classifier, row.protocol,
                                                       row.measured_percent)])}
               for row in over_repeats(validation).itertuples(index=False)]
    return {"test_source": SIMULATED_VALIDATION, "label": SIMULATED_VALIDATION_LABEL,
            "aggregation": "as the measured results: mean and sample std over repeats, "
                           "condition_holdout's holdouts averaged within a repeat first",
            "results": results}


def summarize(accuracy: pd.DataFrame, predictions: pd.DataFrame, calibration: dict,
              run_name: str, data_source: str, plot_names: list[str],
              baseline: pd.DataFrame | None = None, healthy_state: str | None = None) -> dict:
    """The content of summary.json (see module docstring)."""
    recalls = recall_per_class(predictions)
    gains = simulation_gain(accuracy, baseline if baseline is not None else accuracy.iloc[:0])
    gains = gains.set_index(["classifier", "protocol", "measured_percent"])
    test_records = (predictions
                    .groupby(["classifier", "protocol", "measured_percent", "repeat"])["record_id"]
                    .nunique()
                    .groupby(level=["classifier", "protocol", "measured_percent"]).mean())
    speeds = per_speed(accuracy)
    results = []
    for row in over_repeats(accuracy).itertuples(index=False):
        key = (row.classifier, row.protocol, row.measured_percent)
        results.append({
            **accuracy_entry(row, speeds),
            "n_test_records_per_repeat": _json_number(test_records.get(key)),
            "n_test_segments_per_repeat": _json_number(row.n_test_segments),
            "protocol_label": protocol_label(row.protocol),
            "recall_per_class": {r.true_label: _json_number(r.recall) for r in recalls[
                (recalls["classifier"] == row.classifier) & (recalls["protocol"] == row.protocol)
                & (recalls["measured_percent"] == row.measured_percent)].itertuples()},
            "measured_only_accuracy_mean": (_json_number(gains.loc[key, "measured_only"])
                                            if key in gains.index else None),
            "simulation_gain": (_json_number(gains.loc[key, "gain"])
                                if key in gains.index else None),
        })
    labels = label_order([*predictions["true_label"], *predictions["predicted_label"]], healthy_state)
    return {
        "run_name": run_name,
        "data_source": {
            "kind": data_source,
            "synthetic": is_synthetic(data_source),
            "label": data_source_label(data_source),
            "note": ("synthetic data from the virtual bench, not real measurements; every "
                     "number below is measured on it" if is_synthetic(data_source) else ""),
        },
        "calibration": calibration,
        "labels": labels,
        "chance_accuracy": 1.0 / len(labels),
        "n_measured_records": int(predictions["record_id"].nunique()),
        "n_evaluations": int(accuracy["speed_rpm"].isna().sum()),
        "aggregation": ("accuracy_std is the sample std over repeats (null with one repeat); "
                        "condition_holdout: held-out conditions are averaged within a repeat first"),
        "protocols": {p: protocol_label(p) for p in sorted(accuracy["protocol"].unique())},
        "simulation_gain": ("accuracy with the simulated data minus accuracy of the same "
                            "classifier on the same measured training data alone (null: no "
                            "measured-only baseline, or no measured training data); the "
                            "headline is gain_vs_strongest_mean, against the strongest of "
                            "chance, majority class, the best measured-only classifier (its "
                            "feature selection chosen by its own inner CV) and the system's "
                            "training-free physics baseline (physics_baselines); negative where "
                            "a baseline wins"),
        "results": results,
        "plots": plot_names,
    }


# --------------------------------------------------------------------------- outputs

def confusion_percents(accuracy: pd.DataFrame, requested) -> list[int]:
    """The requested measured percentages plus the largest one, checked against the data."""
    available = sorted(int(p) for p in accuracy["measured_percent"].unique())
    requested = [int(p) for p in requested]
    unknown = [p for p in requested if p not in available]
    if unknown:
        raise ReportInputError(f"confusion_percent {unknown} not among the trained measured "
                               f"percentages {available}")
    return sorted(set(requested) | {available[-1]})


def plot_note(run_name: str, data_source: str, bench_differences=(),
              design: bool = False, state_models=()) -> str:
    """Every plot's footnote: the data source and run (and how far a bench differs from the model;
    the fault states whose model their own records tuned; with design records, that the plot
    pools them with the evaluation records)."""
    note = f"Data: {data_source_label(data_source)} | run {run_name}"
    differences = [row for row in bench_differences if row["handled"] != "same"]
    if differences:
        neither = sum(row["handled"] == "neither" for row in differences)
        note += (f" | bench differs from the model in {len(differences)} ways, {neither} neither "
                 "calibrated nor randomised (summary.json)")
    if state_models:
        note += (f" | PER-STATE CALIBRATION: {', '.join(state_models)} models tuned on their first measured "
                 "record per condition (never tested)")
    if design:
        note += (" | all test records: design specimens' included (apart: "
                 "accuracy_design_vs_evaluation.png, headline.csv)")
    return note


def evaluation_plots(overall: pd.DataFrame, chance: float, note: str, plots_dir: Path) -> list:
    """Accuracy per operating condition (`hybrid.condition`'s value of each record) and, with
    design records, on design records against records never used in design; the file names."""
    whole = overall["condition"] == evaluation.ALL
    subsets = [("condition", overall[~whole & (overall["records"] == evaluation.ALL)],
                "Accuracy per operating condition", "accuracy_per_condition.png"),
               ("records", overall[whole & (overall["records"] != evaluation.ALL)],
                "Accuracy on design records vs records never used in design",
                "accuracy_design_vs_evaluation.png")]
    names = []
    for column, rows, title, name in subsets:
        if not rows.empty:
            plots.save_figure(plots.accuracy_per_subset(rows, column, chance, note, title),
                              plots_dir / name)
            names.append(name)
    return names


def condition_file_part(condition: str, value) -> str:
    """A per-condition plot's file name part: all, 450rpm, load2."""
    if value is None:
        return "all"
    if condition == "speed_rpm":
        return f"{format_speed(value)}rpm"
    return f"{condition}{float(value):g}"


def record_sides(is_design: pd.Series, is_apart: pd.Series | None = None) -> list[tuple[str, pd.Series, str]]:
    """(file name part, row mask, title) of the tested records of evaluation specimens, of
    design specimens (`is_design`: per prediction, whether its record is of a design specimen)
    and of unmodelled specimens (`is_apart`, never among the evaluation records), where more than one
    side is tested (else none: the pooled figures are one side's)."""
    is_apart = pd.Series(False, index=is_design.index) if is_apart is None else is_apart
    sides = [("evaluation", ~is_design & ~is_apart, "records of evaluation specimens"),
             ("design", is_design & ~is_apart, "records of design specimens"),
             (evaluation.UNMODELLED, is_apart, "records the model does not describe")]
    sides = [side for side in sides if side[1].any()]
    return sides if len(sides) > 1 else []


def make_plots(accuracy, predictions, calibrated: tuple, plots_dir: Path, run: RunIdentity,
               confusion_percent, shares: pd.DataFrame | None = None, condition: str = "speed_rpm",
               design_records=(), apart_records=()) -> list[str]:
    """Write every report plot into ``plots_dir``; returns the file names. ``run``: the footnote's
    run and data source (and how many effects the bench has that the model lacks: the note says
    so; summary.json lists them), the healthy state the class order starts from. ``calibrated``:
    load_calibrations' (summaries, spectra, histories).
    ``shares``: prediction_shares of the predictions (computed here if not given).
    ``condition``: the predictions' column of the operating condition the per-condition figures
    (confusion matrices, prediction shares) group by: speed_rpm, or e.g. a motor load
    (with_condition); the per-speed accuracy bars only where the condition is the speed
    (accuracy_per_condition.png covers any condition). ``design_records``: the records of design
    specimens; where tested, every plot's note says it pools them, and where records of other
    specimens are tested too, each classifier and protocol gets its confusion matrices on each
    side apart (`confusion_<classifier>_<protocol>_evaluation.png`, `..._design.png`; records of
    unmodelled specimens, ``apart_records``, in `..._unmodelled.png`)."""
    is_design = predictions["record_id"].astype(str).isin(set(map(str, design_records)))
    sides = record_sides(is_design, predictions["record_id"].astype(str).isin(set(map(str, apart_records))))
    note = plot_note(run.run_name, run.data_source, run.bench_differences, bool(is_design.any()),
                     run.state_models)
    side_note = plot_note(run.run_name, run.data_source, run.bench_differences, state_models=run.state_models)
    calibration, spectra, history = calibrated
    labels = label_order([*predictions["true_label"], *predictions["predicted_label"]],
                         run.healthy_state)
    chance = 1.0 / len(labels)
    percents = confusion_percents(accuracy, confusion_percent)
    if shares is None:
        shares = prediction_shares(predictions, labels, condition)
    names = []

    def save(fig, name):
        plots.save_figure(fig, plots_dir / name)
        names.append(name)

    save(plots.accuracy_vs_measured_percent(per_repeat_accuracy(accuracy), chance, note),
         "accuracy_vs_measured_percent.png")
    if condition == "speed_rpm":
        save(plots.accuracy_per_speed(accuracy[accuracy["speed_rpm"].notna()], percents, chance,
                                      note), "accuracy_per_speed.png")
    save(plots.recall_per_class(recall_per_class(predictions), note),
         "recall_per_class.png")
    for (classifier, protocol), group in predictions.groupby(["classifier", "protocol"]):
        # a classifier may train on fewer percentages (classifiers.cnn.measured_percent): show
        # the chosen ones it has, and its own largest
        own = sorted(int(p) for p in group["measured_percent"].unique())
        own_percents = sorted({p for p in percents if p in own} | {own[-1]})
        panels = [(group if value is None else group[group[condition] == value],
                   plots.condition_label(condition, value), condition_file_part(condition, value), note)
                  for value in [None] + sorted(group[condition].unique())]
        panels += [(group[side.loc[group.index]], where, name, f"{side_note} | {where} only")
                   for name, side, where in sides]
        for subset, where, name, panel_note in panels:
            matrices = {}
            for percent in own_percents:
                chosen = subset[subset["measured_percent"] == percent]
                matrices[percent] = (confusion_counts(chosen["true_label"],
                                                      chosen["predicted_label"], labels),
                                     int(chosen["repeat"].nunique()))
            save(plots.confusion_matrices(matrices, labels, classifier, protocol, where, panel_note),
                 f"confusion_{classifier}_{protocol}_{name}.png")
        # the study's Fig. 9 at the same percentages: per speed, where each true class's
        # predictions go
        own_shares = shares[(shares["classifier"] == classifier)
                            & (shares["protocol"] == protocol)]
        save(plots.prediction_shares(own_shares, labels, classifier, protocol, own_percents, note,
                                     condition),
             f"prediction_shares_{classifier}_{protocol}.png")
    if not isinstance(spectra, dict):  # one calibration
        save(plots.spectra_grid(spectra, note), "spectra_measured_vs_calibrated.png")
        save(plots.calibration_convergence(history, calibration["model_variant"], note),
             "calibration_convergence.png")
        return names
    # one calibration per calibration variant: all against the measured spectra, then each
    save(plots.spectra_grid(pd.concat([frame.assign(calibration_variant=variant)
                                       for variant, frame in spectra.items()], ignore_index=True),
                            note), "spectra_measured_vs_calibrated.png")
    for variant in spectra:
        variant_note = f"{note} | calibration variant: {variant}" if len(spectra) > 1 else note
        if len(spectra) > 1:
            save(plots.spectra_grid(spectra[variant], variant_note),
                 f"spectra_measured_vs_calibrated_{variant}.png")
        save(plots.calibration_convergence(history[variant], calibration[variant]["model_variant"],
                                           variant_note), f"calibration_convergence_{variant}.png")
    return names


def state_convergence_plots(results: dict, histories, plots_dir: Path, run: RunIdentity) -> list[str]:
    """Per-state calibration (calibration.per_state): each state's convergence from its history
    file (`histories`: state -> path; `results`: state -> its params.json content),
    `calibration_convergence_state_<state>.png`; the file names."""
    note = plot_note(run.run_name, run.data_source, run.bench_differences, state_models=run.state_models)
    names = []
    for state, path in histories.items():
        name = f"calibration_convergence_state_{state}.png"
        fit = plots.state_fit_label(results[state])
        plots.save_figure(plots.calibration_convergence(pd.read_parquet(path), results[state]["model_variant"],
                                                        f"{note} | the {state} model" + (f": {fit}" if fit else ""),
                                                        no_change_cost=results[state].get("no_change_cost")),
                          plots_dir / name)
        names.append(name)
    return names


def evaluation_tables(predictions, baseline, labels, healthy_state, measured_features_path,
                      condition, design_records, physics=None, baseline_predictions=None,
                      apart_records=()):
    """condmon.evaluation's tables: per evaluation, and over repeats; the physics baselines'
    own, per evaluation and over repeats (None without physics predictions); and the
    measured-only baselines' per evaluation (None without their predictions). `apart_records`:
    records of unmodelled specimens (rows `unmodelled`, never `evaluation`)."""
    conditions = record_conditions(measured_features_path, condition)
    table = evaluation.evaluation_table(predictions, healthy_state, labels, conditions, condition,
                                        design_records, baseline, physics, baseline_predictions,
                                        apart_records)
    baseline_table = (None if baseline_predictions is None else
                      evaluation.evaluation_table(baseline_predictions, healthy_state, labels,
                                                  conditions, condition, design_records,
                                                  apart_records=apart_records))
    overall = evaluation.summarise(table, predictions, healthy_state, conditions, condition,
                                   design_records, apart_records)
    physics_table = physics_overall = None
    if physics is not None:
        physics_table = evaluation.evaluation_table(physics, healthy_state, labels, conditions,
                                                    condition, design_records,
                                                    apart_records=apart_records)
        physics_overall = evaluation.summarise(physics_table, physics, healthy_state, conditions,
                                               condition, design_records, apart_records)
    return table, overall, physics_table, physics_overall, baseline_table


def design_record_ids(design_records, design_specimens, measured_records) -> tuple[list, dict]:
    """The records reported as design records: `design_records` (report.design_records) and every
    record of a design specimen (System.design_specimens, matched to records.csv's `specimen`);
    and {record_id: specimen} of the measured records (empty where records.csv names none).
    Design specimens without a specimen column to match are an error, never ignored."""
    specimens = {}
    if measured_records is not None:
        records = pd.read_csv(measured_records, dtype=str, keep_default_na=False)
        if "specimen" in records.columns:
            kept = records[records["status"] == "kept"] if "status" in records.columns else records
            specimens = dict(zip(kept["record_id"], kept["specimen"]))
    design_specimens = set(map(str, design_specimens))
    if design_specimens and not specimens:
        raise ReportInputError(
            f"design specimens {sorted(design_specimens)} are declared, but the measured records "
            f"({measured_records}) name no specimen to match them to")
    of_specimens = {r for r, specimen in specimens.items() if specimen in design_specimens}
    return sorted(set(map(str, design_records)) | of_specimens), specimens


def unmodelled_records(unmodelled: dict, specimens: dict) -> dict:
    """{record_id: reason} of the unmodelled records: every record whose specimen (records.csv's,
    `specimens`: {record_id: specimen}) the system says its model does not describe
    (`unmodelled`: {specimen: reason}, System.unmodelled_specimens). Declared without a
    specimen to match: an error, never ignored."""
    if unmodelled and not specimens:
        raise ReportInputError(f"unmodelled specimens {sorted(unmodelled)} are declared, "
                               "but the measured records name no specimen to match them to")
    return {record: unmodelled[specimen] for record, specimen in sorted(specimens.items())
            if specimen in unmodelled}


def design_summary(predictions: pd.DataFrame, design_records, design_specimens,
                   specimens: dict, apart: dict | None = None) -> dict:
    """summary.json's `design_records`: which tested records and specimens count as design and
    which as evaluation, what the headline is on, and a note that says so plainly. Records of
    unmodelled specimens (`apart`: {record_id: reason}) are neither: `unmodelled` lists them."""
    design, apart = set(map(str, design_records)), dict(apart or {})
    tested = sorted(set(predictions["record_id"].astype(str)))
    evaluation_records = [r for r in tested if r not in design and r not in apart]
    entry = {"records": sorted(design), "design_specimens": sorted(map(str, design_specimens)),
             "tested_design_records": [r for r in tested if r in design],
             "tested_evaluation_records": evaluation_records,
             "evaluation_specimens": sorted({specimens[r] for r in evaluation_records
                                             if r in specimens})}
    if apart:
        entry["unmodelled"] = {
            "records": {r: {"specimen": specimens.get(r), "reason": apart[r],
                            "tested": r in tested} for r in sorted(apart)},
            "note": ("records of specimens the model does not describe: their figures are in rows "
                     "of their own (records 'unmodelled'), never in the headline nor among "
                     "the evaluation records")}
    if not design and not apart:
        entry["headline_records"] = "all"
        entry["note"] = ("report.design_records is empty and the system declares no design "
                         "specimen: no record is declared as used in design")
        return entry
    entry["headline_records"] = "evaluation" if evaluation_records else "none"
    entry["note"] = (
        "results on the records of the design specimens (whose records design choices were "
        "tuned on; and report.design_records) are given apart ('design') from the others "
        "('evaluation': specimens the design never looked at); the headline is on the "
        "evaluation records" + ("" if evaluation_records else
                                "; " + NO_EVALUATION_SPECIMEN.split(". The design")[0]
                                + ": no figure here is a headline"))
    return entry


def add_evaluation(summary: dict, overall: pd.DataFrame, predictions: pd.DataFrame,
                   measured_records, design_records, design_specimens=(),
                   specimens: dict | None = None, apart: dict | None = None) -> None:
    """summary.json: each result's honest figures (all test data), its accuracy per condition,
    its figures on design and evaluation records apart (`by_records`), and recall per specimen
    where records.csv names them (`specimens`: {record_id: specimen}, read here if None)."""
    figures = ["n_repeats", "distinct_repeats", "accuracy_ci_low", "accuracy_ci_high",
               "record_accuracy_mean", "record_accuracy_ci_low", "record_accuracy_ci_high",
               "balanced_accuracy_mean", "false_alarm_rate_mean", "false_alarm_ci_low",
               "false_alarm_ci_high", "small_test_set", "majority_class_mean",
               "measured_only_best_mean", "physics_baseline", "physics_baseline_accuracy_mean",
               "strongest_baseline", "strongest_baseline_accuracy_mean", "gain_vs_strongest_mean"]
    if specimens is None:
        specimens = design_record_ids((), (), measured_records)[1]
    recalls = {}
    if specimens:
        hits = predictions.assign(hit=predictions["true_label"] == predictions["predicted_label"],
                                  specimen=predictions["record_id"].map(specimens))
        recalls = (hits.groupby(["classifier", "protocol", "measured_percent", "specimen"])["hit"]
                   .mean())
    keys = ["classifier", "protocol", "measured_percent"]
    for result in summary["results"]:
        key = tuple(result[k] for k in keys)
        mine = overall[(overall["classifier"] == key[0]) & (overall["protocol"] == key[1])
                       & (overall["measured_percent"] == key[2])]
        everything = mine[(mine["condition"] == evaluation.ALL) & (mine["records"] == evaluation.ALL)]
        if everything.empty:
            continue
        row = everything.iloc[0]
        result.update(_figures(row, figures))
        result["records"] = "all" if not design_records else "all (design and evaluation together)"
        if result["distinct_repeats"] == 1 and result["n_repeats"] > 1:
            # a spread of 0 would claim a stability nobody measured
            result["accuracy_std"] = result["macro_f1_std"] = None
            result["repeats_note"] = ("the repeats predicted alike: one repeat, no spread (the "
                                      "seed changed neither the training set nor the fit)")
        result["accuracy_mean_per_condition"] = {
            r.condition: _json_number(r.accuracy_mean)
            for r in mine[(mine["condition"] != evaluation.ALL)
                          & (mine["records"] == evaluation.ALL)].itertuples()}
        by_records = mine[(mine["condition"] == evaluation.ALL) & (mine["records"] != evaluation.ALL)]
        result["accuracy_mean_by_records"] = {r.records: _json_number(r.accuracy_mean)
                                              for r in by_records.itertuples()}
        if design_records or apart:
            # every figure on each side, the baselines and the gain on those records alone
            result["by_records"] = {
                records: (_figures(by_records[by_records["records"] == records].iloc[0],
                                   ["accuracy_mean", *figures])
                          if (by_records["records"] == records).any() else
                          {"note": f"no {records} record tested"})
                for records in ("evaluation", "design") + ((evaluation.UNMODELLED,) if apart else ())}
        if len(recalls):
            result["recall_per_specimen"] = {s: _json_number(v)
                                             for s, v in recalls.loc[key].items()}
    summary["design_records"] = design_summary(predictions, design_records, design_specimens,
                                               specimens, apart)
    summary["repeats"] = (
        "a repeat redraws which measured records (time blocks, or segments under segment_share) "
        "join each share and seeds the fit (the CNN's initialisation and batches, a "
        "classifier's own randomness); the simulated training data are the same in every "
        "repeat (simulation.seed), so where no measured record trains (0 %) or every one does, "
        "deterministic classifiers (SVM, KNN, grouped feature selection) repeat one result: "
        "distinct_repeats counts the repeats that predicted differently, and only those give "
        "a spread")
    summary["evaluation"] = (
        "per-segment, per-record (majority vote) and balanced accuracy with 95 % Wilson "
        "intervals (per evaluation on its test set; over repeats on one repeat's distinct test "
        "segments/records: repeats and holdouts that test a segment again add no data; still "
        "optimistic: segments of a record are not independent), false-alarm rate (healthy test segments called faulty), gain against "
        "the strongest of chance, the test set's majority class, the best measured-only "
        "classifier and the physics baseline (negative: a baseline wins); evaluation.csv per "
        "evaluation, evaluation_summary.csv over repeats, physics_baselines.csv the physics "
        "baselines' own figures on the same test sets")


def _figures(row, names) -> dict:
    """{name: JSON value} of one evaluation_summary row."""
    return {name: row[name] if isinstance(row[name], str) else (
        bool(row[name]) if isinstance(row[name], (bool, np.bool_)) else _json_number(row[name]))
        for name in names}


def simulation_summary(report_paths) -> dict:
    """Samples, failures (with their parameters) and cost of the simulation jobs."""
    reports = [json.loads(Path(p).read_text()) for p in report_paths]
    wall = [s for r in reports for s in r["wall_seconds"]]
    simulated = sum(r["simulated_seconds_per_sample"] * r["samples"] for r in reports)
    return {"samples": sum(r["samples"] for r in reports),
            "failed": sum(len(r["failures"]) for r in reports),
            "failures": [f for r in reports for f in r["failures"]],
            "wall_seconds_per_sample": float(np.mean(wall)) if wall else None,
            "wall_seconds_per_simulated_second": sum(wall) / simulated if simulated else None}


def measured_records_summary(records_path) -> dict:
    """What the measured stage kept and left out (file, class, reason) from records.csv."""
    records = pd.read_csv(records_path, dtype=str, keep_default_na=False)
    left_out = records[records["status"] != "kept"]
    columns = [c for c in ("file", "record_id", "fault", "diameter_in", "load_hp", "reason")
               if c in records.columns]
    return {"kept": int((records["status"] == "kept").sum()),
            "left_out": left_out[columns].to_dict(orient="records")}


def write_job_timings(files_by_rule: dict, csv_path, plots_dir, plot_names: list, note: str) -> dict:
    """Per-rule wall time and peak memory from {rule: its jobs' benchmark files}: a CSV (when
    csv_path is given), a plot in plots_dir (added to plot_names) and {rule: figures} for
    summary.json."""
    timings = job_timings.summarise(files_by_rule)
    if csv_path is not None:
        write_text(timings.to_csv(index=False), csv_path)
    if not timings.empty:
        plots.save_figure(plots.job_timings(timings, note), Path(plots_dir) / "job_timings.png")
        plot_names.append("job_timings.png")
    return {row.pop("rule"): row for row in timings.to_dict("records")}


def load_calibrations(calibration: CalibrationOutputs) -> tuple:
    """(summaries, spectra, histories) of the calibration files: each {variant: ...} with one
    calibration per variant (each summary with its `calibration_variant`), else the one's own."""
    params_paths, spectra_paths, history_paths = calibration.by_variant()
    if not (list(params_paths) == list(spectra_paths) == list(history_paths)) or not params_paths:
        raise ReportInputError("calibration params, spectra and history must name the same "
                               f"calibration variants: {list(params_paths)}, "
                               f"{list(spectra_paths)}, {list(history_paths)}")
    calibrations = {m: load_calibration(p) for m, p in params_paths.items()}
    for variant, summary in calibrations.items():
        if variant is not None:
            summary["calibration_variant"] = variant
    spectra = {m: read_table(p, ["speed_rpm", "channel", "freq_hz", "measured", "calibrated"],
                             "calibration spectra") for m, p in spectra_paths.items()}
    history = {m: read_table(p, ["evaluation", "model_variant", "cost"], "calibration history")
               for m, p in history_paths.items()}
    if not calibration.per_variant:
        return calibrations[None], spectra[None], history[None]
    return calibrations, spectra, history


def signature_report(summary: dict, measured_frame, names, simulated_features, healthy_state: str,
                     condition: str, note: str, staging) -> tuple[list[str], pd.DataFrame]:
    """summary.json `fault_signatures` (condmon.signature: each fault class's measured and
    simulated shift from healthy, and how alike their directions are) and its plot; returns the
    plot's name (none without a fault class measured and simulated at one condition) and each
    measured record's share of segments outside the simulated range (`outside_simulation`)."""
    simulated_frame, simulated_names = read_feature_table(simulated_features)
    if list(simulated_names) != list(names):
        raise ReportInputError(f"{simulated_features}: its features differ from the measured features' "
                         f"({len(simulated_names)} against {len(names)}); rerun the features stage")
    signatures = fault_signatures(measured_frame, simulated_frame, names, healthy_state, condition)
    summary["fault_signatures"] = signatures
    outside = outside_simulation(measured_frame, simulated_frame, names)
    table = signature_table(signatures)
    if table.empty:
        return [], outside
    log.info("fault signatures (shift in simulated healthy spreads, measured / simulated, direction):\n%s",
             table.round(2).to_string(index=False))
    plots.save_figure(plots.fault_signatures(table, condition, note), staging / "fault_signatures.png")
    return ["fault_signatures.png"], outside


def write_report(inputs: ReportInputs) -> dict:
    """Build the whole report from `inputs` (condmon.report_inputs: what each input adds, and
    which outputs are optional); returns the summary dict. Every output is written atomically.

    With the measured features (inputs.evaluation.measured_features) the evaluation tables
    (condmon.evaluation: per evaluation; over repeats) get `design_records` and the records of
    `design_specimens` apart as design records, summary.json's results the per-record, balanced,
    false-alarm and baseline figures (all test records, and design and evaluation records
    apart; the headline is then on the evaluation records), and plots/simulation_gain.png the
    gain against the strongest baseline (without them: against the same classifier's
    measured-only baseline)."""
    run, train, chosen = inputs.run, inputs.train, inputs.evaluation
    upstream, out = inputs.upstream, inputs.outputs
    accuracy = load_metrics(train.metrics)
    # measured-only baselines (empty files where hybrid.measured_only_baseline is off)
    with_rows = [p for p in train.measured_only if len(pd.read_csv(p))]
    baseline = load_metrics(with_rows) if with_rows else None
    predictions = load_predictions(train.predictions)
    # the system's physics baselines (empty files where it has none)
    physics_with_rows = [p for p in train.physics
                         if len(pd.read_parquet(p, columns=["record_id"]))]
    physics = load_predictions(physics_with_rows) if physics_with_rows else None
    fault_lines, fault_line_rule = load_fault_lines(train.physics_info)
    coverage = (pd.concat([pd.read_csv(p, dtype={"record_id": str, "holdout": str})
                           for p in train.coverage], ignore_index=True) if train.coverage else None)
    alone_with_rows = [p for p in train.measured_only_predictions
                       if len(pd.read_parquet(p, columns=["record_id"]))]
    baseline_predictions = load_predictions(alone_with_rows) if alone_with_rows else None
    simulated_validation = load_simulated_validation(train.simulated_validation)
    labels = label_order([*predictions["true_label"], *predictions["predicted_label"]],
                         run.healthy_state)
    # the per-condition figures and prediction_shares.csv group by the operating condition
    # (hybrid.condition: the speed, or e.g. the load), each record's value from its features
    features, condition = chosen.measured_features, chosen.condition
    grouping = condition if features is not None else "speed_rpm"
    by_condition = (with_condition(predictions, record_conditions(features, condition), condition)
                    if grouping != "speed_rpm" else predictions)
    shares = prediction_shares(by_condition, labels, grouping)
    calibrations, spectra, history = load_calibrations(inputs.calibration)
    per_model = inputs.calibration.per_variant
    # the one the simulated data come from
    calibration = next(iter(calibrations.values())) if per_model else calibrations
    log.info("%d metrics rows from %d files, %d predictions", len(accuracy),
             len(train.metrics), len(predictions))

    design_records, specimens, apart = chosen.design_records, {}, {}
    if features is not None:
        design_records, specimens = design_record_ids(design_records, chosen.design_specimens,
                                                      upstream.measured_records)
        apart = unmodelled_records(dict(chosen.unmodelled), specimens)
        if apart:
            log.info("unmodelled records, reported apart and never in the headline: %s",
                     apart)
    design_tested = bool(set(map(str, design_records)) & set(predictions["record_id"].astype(str)))
    with staging_directory(out.plots) as staging:
        plot_names = make_plots(accuracy, by_condition, (calibrations, spectra, history), staging,
                                run, chosen.confusion_percent, shares, grouping, design_records,
                                list(apart))
        # calibration.per_state: what each fault's own records tuned
        state_results = {state: json.loads(Path(path).read_text())
                         for state, path in inputs.calibration.states.items()}
        plot_names += state_convergence_plots(state_results, inputs.calibration.state_histories, staging, run)
        summary = summarize(accuracy, predictions, calibration, run.run_name, run.data_source,
                            plot_names, baseline, run.healthy_state)
        if run.bench_differences:
            summary["data_source"]["bench_differences"] = [dict(row) for row in run.bench_differences]
        if state_results:
            summary["state_calibration"] = state_results
        if per_model:
            summary["calibration_by_variant"] = calibrations
        summary["simulation"] = simulation_summary(upstream.simulation_reports)
        if upstream.measured_records is not None:
            summary["measured_records"] = measured_records_summary(upstream.measured_records)
        if train.simulated_validation:  # hybrid.simulated_validation_share > 0
            summary["simulated_validation"] = (
                simulated_validation_summary(simulated_validation)
                if simulated_validation is not None else
                {"test_source": SIMULATED_VALIDATION, "label": SIMULATED_VALIDATION_LABEL,
                 "results": [], "note": "no simulated record was held out (every stratum's "
                                        "share rounds to zero records)"})
        if upstream.benchmarks is not None:
            summary["job_timings"] = write_job_timings(upstream.benchmarks, out.job_timings,
                                                       staging, summary["plots"],
                                                       note=f"run {run.run_name}")
        note = plot_note(run.run_name, run.data_source, run.bench_differences, state_models=run.state_models)
        table = physics_table = baseline_table = physics_overall = separability = outside = None
        if features is not None:
            table, overall, physics_table, physics_overall, baseline_table = evaluation_tables(
                predictions, baseline, labels, run.healthy_state, features, condition,
                design_records, physics, baseline_predictions, list(apart))
            add_evaluation(summary, overall, predictions, upstream.measured_records,
                           design_records, chosen.design_specimens, specimens, apart)
            measured_frame, names = read_feature_table(features)
            # the ceiling is the headline's too: on the modelled specimens' records alone
            separability = measured_separability(
                measured_frame[~measured_frame["record_id"].astype(str).isin(apart)], names, condition)
            summary["measured_separability"] = separability
            log.info("measured records alone, leave one record out: %s over all, %s per %s",
                     separability["all"]["balanced_accuracy"],
                     {k: v["balanced_accuracy"] for k, v in separability["per_condition"].items()}, condition)
            for value, entry in separability["per_condition"].items():
                if entry["not_shown"]:  # no simulation can be asked to find what its own records do not show
                    log.warning("%s %s: the measured records' own classifier finds %s less than %.0f %% of the "
                                "time (exempt from the simulation-trained figures)", condition, value,
                                entry["not_shown"], 100 * SHOWN_RECALL)
            if chosen.simulated_features is not None and run.healthy_state is not None:
                signature_plots, outside = signature_report(
                    summary, measured_frame, names, chosen.simulated_features, run.healthy_state,
                    condition, note, staging)
                summary["plots"] += signature_plots
            plots.save_figure(plots.simulation_gain(
                gain_against_strongest(overall), 1.0 / len(labels),
                plot_note(run.run_name, run.data_source, run.bench_differences, design_tested,
                          run.state_models)),
                staging / "simulation_gain.png")
            summary["plots"].append("simulation_gain.png")
            if physics_overall is not None:
                summary["physics_baselines"] = physics_baselines_summary(physics_overall, physics)
            if out.physics_baselines is not None:
                # without any rule, a header alone: the evaluation summary's columns, no rows
                write_text((physics_overall if physics_overall is not None else overall.iloc[:0])
                           .to_csv(index=False), out.physics_baselines)
            summary["plots"] += evaluation_plots(overall, 1.0 / len(labels), note, staging)
            if out.evaluation is not None:
                write_text(table.to_csv(index=False), out.evaluation)
            if out.evaluation_summary is not None:
                write_text(overall.to_csv(index=False), out.evaluation_summary)
        elif baseline is not None:  # no evaluation tables: the same classifier's baseline
            gains = simulation_gain(accuracy, baseline).rename(columns={"measured_only": "strongest"})
            plots.save_figure(plots.simulation_gain(gains, 1.0 / len(labels), note),
                              staging / "simulation_gain.png")
            summary["plots"].append("simulation_gain.png")
        write_text(labelled_accuracy(accuracy).to_csv(index=False), out.accuracy)
        if out.headline is not None:
            headline = with_ceiling(headline_table(accuracy, baseline, physics_overall, 1.0 / len(labels),
                                                   table, physics_table, baseline_table), separability)
            write_text(headline.to_csv(index=False), out.headline)
        if out.recall_per_record is not None:
            per_record = recall_per_record(predictions, fault_lines, physics, outside, coverage)
            # why a record is reported apart (empty for every modelled record)
            per_record["unmodelled"] = [apart.get(r, "") for r in per_record["record_id"].astype(str)]
            write_text(per_record.to_csv(index=False), out.recall_per_record)
        if fault_lines is not None:
            summary["fault_lines"] = fault_lines_summary(predictions, fault_lines, fault_line_rule)
        if coverage is not None and len(coverage):
            summary["simulation_coverage"] = simulation_coverage(coverage, design_records)
        if out.prediction_shares is not None:
            write_text(shares.to_csv(index=False), out.prediction_shares)
        write_text(json.dumps(summary, indent=2) + "\n", out.summary)
    log.info("wrote %s, %s and %d plots in %s", out.accuracy, out.summary, len(plot_names),
             out.plots)
    return summary

"""Train on simulated (+ a share of measured) segments, test on held-out measured records.

One fit per (measured_percent, repeat, holdout) of a split table: training is every simulated
segment plus the measured segments of records with role "train"; the test set is the measured
segments of records with role "test". Labels are the health_state strings.
"""
from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path

import joblib
import numpy as np
import pandas as pd
import pyarrow as pa
from sklearn.metrics import accuracy_score, f1_score

from condmon import classifiers
from condmon.atomic import staging_directory, write_table, write_text
from condmon.hybrid import sorted_holdouts, validate_splits
from condmon.seeds import derive_seed, stable_int
from condmon.signals import package_versions

log = logging.getLogger(__name__)

PREDICTION_SCHEMA = pa.schema([
    ("protocol", pa.string()),
    ("measured_percent", pa.int32()),
    ("repeat", pa.int32()),
    ("holdout", pa.string()),
    ("record_id", pa.string()),
    ("segment", pa.int32()),
    ("speed_rpm", pa.float64()),
    ("true_label", pa.string()),
    ("predicted_label", pa.string()),
])
PREDICTION_COLUMNS = PREDICTION_SCHEMA.names
METRIC_COLUMNS = ["classifier", "protocol", "measured_percent", "repeat", "holdout", "speed_rpm",
                  "accuracy", "macro_f1", "n_train_simulated", "n_train_measured", "n_test",
                  "fit_seconds"]
REQUIRED_COLUMNS = ["record_id", "segment", "health_state", "speed_rpm"]


def evaluation_metrics(y_true, y_pred) -> dict:
    """Accuracy and macro F1 over the classes present in truth or prediction.

    Classes absent from both would only add F1 = 0 terms and deflate the macro mean (e.g. at a
    speed where a fault was never measured), so they are left out.
    """
    labels = sorted(set(y_true) | set(y_pred))
    return {"accuracy": float(accuracy_score(y_true, y_pred)),
            "macro_f1": float(f1_score(y_true, y_pred, labels=labels, average="macro",
                                       zero_division=0))}


def matching_feature_names(simulated_names, measured_names) -> list[str]:
    """The common feature names; an error naming the first difference if they disagree."""
    simulated_names, measured_names = list(simulated_names), list(measured_names)
    if simulated_names != measured_names:
        only_sim = [n for n in simulated_names if n not in set(measured_names)][:5]
        only_meas = [n for n in measured_names if n not in set(simulated_names)][:5]
        raise ValueError("simulated and measured features differ: "
                         f"{len(simulated_names)} vs {len(measured_names)} columns, only simulated "
                         f"{only_sim}, only measured {only_meas} (same names in another order "
                         "if both are empty)")
    return simulated_names


def _check_columns(frame: pd.DataFrame, feature_names, what: str) -> None:
    missing = [c for c in REQUIRED_COLUMNS + list(feature_names) if c not in frame.columns]
    if missing:
        raise ValueError(f"{what} features lack column(s) {missing[:10]}"
                         + (f" and {len(missing) - 10} more" if len(missing) > 10 else ""))
    if frame.empty:
        raise ValueError(f"{what} features have no rows")


def _split_keys(splits: pd.DataFrame) -> list[tuple[int, int, str]]:
    """(measured_percent, repeat, holdout) of every split, in a stable order."""
    holdout_order = {h: i for i, h in enumerate(sorted_holdouts(splits["holdout"]))}
    keys = splits[["measured_percent", "repeat", "holdout"]].drop_duplicates()
    keys = [(int(p), int(r), str(h)) for p, r, h in keys.itertuples(index=False)]
    return sorted(keys, key=lambda k: (k[0], k[1], holdout_order[k[2]]))


def run_protocol(classifier_name: str, classifier_params: dict | None,
                 simulated_features: pd.DataFrame, measured_features: pd.DataFrame,
                 splits: pd.DataFrame, feature_names, seed: int):
    """Fit and evaluate one classifier on every split of a split table.

    Returns (predictions, metrics, models): predictions and metrics per the train contract, and
    the fitted pipelines keyed by (measured_percent, repeat, holdout).
    """
    feature_names = list(feature_names)
    classifiers.make_classifier(classifier_name, classifier_params, seed)  # fail early if bad
    validate_splits(splits)
    _check_columns(simulated_features, feature_names, "simulated")
    _check_columns(measured_features, feature_names, "measured")
    protocol = str(splits["protocol"].iloc[0])

    measured_ids = set(measured_features["record_id"].astype(str))
    unknown = sorted(set(splits["record_id"]) - measured_ids)
    if unknown:
        raise ValueError(f"split table names record(s) {unknown[:5]} absent from the measured "
                         "features")
    unlisted = sorted(measured_ids - set(splits["record_id"]))
    if unlisted:
        log.warning("measured record(s) %s are in no split and are never used", unlisted[:5])

    x_sim = simulated_features[feature_names].to_numpy(np.float32)
    y_sim = simulated_features["health_state"].astype(str).to_numpy()
    x_meas = measured_features[feature_names].to_numpy(np.float32)
    y_meas = measured_features["health_state"].astype(str).to_numpy()
    meas_records = measured_features["record_id"].astype(str)
    meas_speed = measured_features["speed_rpm"].to_numpy(float)

    holdout_index = {h: i for i, h in enumerate(sorted_holdouts(splits["holdout"]))}
    predictions, metrics, models = [], [], {}
    for percent, repeat, holdout in _split_keys(splits):
        split = splits[(splits["measured_percent"] == percent) & (splits["repeat"] == repeat)
                       & (splits["holdout"] == holdout)]
        role = meas_records.map(dict(zip(split["record_id"], split["role"]))).to_numpy()
        train, test = role == "train", role == "test"
        where = f"measured_percent={percent} repeat={repeat} holdout={holdout!r}"
        if not test.any():
            log.warning("%s: no test records, skipped", where)
            continue
        x_train = np.concatenate([x_sim, x_meas[train]])
        y_train = np.concatenate([y_sim, y_meas[train]])
        if len(set(y_train)) < 2:
            raise ValueError(f"{where}: training data has only class(es) {sorted(set(y_train))}; "
                             "a classifier needs at least two")

        fit_seed = derive_seed(seed, stable_int(protocol), percent, repeat, holdout_index[holdout])
        model = classifiers.make_classifier(classifier_name, classifier_params, fit_seed)
        start = time.perf_counter()
        model.fit(x_train, y_train)
        fit_seconds = time.perf_counter() - start
        y_pred = model.predict(x_meas[test]).astype(str)
        y_true = y_meas[test]
        models[(percent, repeat, holdout)] = model

        test_rows = measured_features.loc[test]
        predictions.append(pd.DataFrame({
            "protocol": protocol, "measured_percent": percent, "repeat": repeat,
            "holdout": holdout, "record_id": test_rows["record_id"].astype(str).to_numpy(),
            "segment": test_rows["segment"].to_numpy(), "speed_rpm": meas_speed[test],
            "true_label": y_true, "predicted_label": y_pred}))

        common = {"classifier": classifier_name, "protocol": protocol,
                  "measured_percent": percent, "repeat": repeat, "holdout": holdout,
                  "n_train_simulated": len(x_sim), "n_train_measured": int(train.sum()),
                  "fit_seconds": fit_seconds}
        overall = evaluation_metrics(y_true, y_pred)
        metrics.append({**common, "speed_rpm": np.nan, **overall, "n_test": len(y_true)})
        for speed in sorted(set(meas_speed[test])):
            at_speed = meas_speed[test] == speed
            metrics.append({**common, "speed_rpm": speed,
                            **evaluation_metrics(y_true[at_speed], y_pred[at_speed]),
                            "n_test": int(at_speed.sum())})
        log.info("%s: %d simulated + %d measured training segments, %d test segments, "
                 "accuracy %.3f, fit %.1f s", where, len(x_sim), train.sum(), len(y_true),
                 overall["accuracy"], fit_seconds)

    predictions = (pd.concat(predictions, ignore_index=True) if predictions
                   else pd.DataFrame(columns=PREDICTION_COLUMNS))
    predictions = predictions.astype({"measured_percent": "int32", "repeat": "int32",
                                      "segment": "int32", "speed_rpm": float})
    metrics = pd.DataFrame(metrics, columns=METRIC_COLUMNS)
    return predictions[PREDICTION_COLUMNS], metrics, models


# -- outputs --------------------------------------------------------------------------------
def model_filename(percent: int, repeat: int, holdout_index: int | None = None) -> str:
    """p<percent:03d>_r<repeat>[_h<holdout index>].joblib (no _h without a holdout)."""
    suffix = "" if holdout_index is None else f"_h{holdout_index}"
    return f"p{percent:03d}_r{repeat}{suffix}.joblib"


def write_models(models: dict, directory) -> list[dict]:
    """Dump every fitted model into `directory` (built aside, then renamed into place).

    Returns one entry per file: file name, measured_percent, repeat, holdout, holdout_index.
    """
    directory = Path(directory)
    order = {h: i for i, h in enumerate(sorted_holdouts(key[2] for key in models))}
    # Holdout indices count the real holdouts only; "" (nothing held out) gets no _h suffix.
    holdout_index = {h: i for i, h in enumerate(h for h in order if h)}
    entries = []
    with staging_directory(directory) as tmp:
        for percent, repeat, holdout in sorted(models, key=lambda k: (k[0], k[1], order[k[2]])):
            index = holdout_index.get(holdout)  # None without a holdout
            name = model_filename(percent, repeat, index)
            joblib.dump(models[(percent, repeat, holdout)], tmp / name)
            entries.append({"file": name, "measured_percent": percent, "repeat": repeat,
                            "holdout": holdout, "holdout_index": index})
    return entries


def write_predictions(predictions: pd.DataFrame, path) -> None:
    write_table(pa.Table.from_pandas(predictions[PREDICTION_COLUMNS], schema=PREDICTION_SCHEMA,
                                      preserve_index=False), path)


def write_metrics(metrics: pd.DataFrame, path) -> None:
    """metrics.csv; speed_rpm is empty on the all-speeds rows."""
    write_text(metrics[METRIC_COLUMNS].to_csv(index=False), path)


def train_info(classifier_name: str, params: dict | None, seed: int, protocol: str,
               labels, feature_names, metrics: pd.DataFrame, model_files: list[dict],
               total_seconds: float) -> dict:
    """Contents of info.json: what was trained, on which features, and how long it took."""
    names_json = json.dumps(list(feature_names))
    return {
        "classifier": classifier_name,
        "classifier_params": classifiers.classifier_params(classifier_name, params),
        "seed": int(seed),
        "protocol": protocol,
        "labels": sorted(map(str, labels)),
        "n_features": len(feature_names),
        "feature_names_sha256": hashlib.sha256(names_json.encode()).hexdigest(),
        "models": model_files,
        "timings": {"total_seconds": round(total_seconds, 3),
                    "fit_seconds_sum": round(float(metrics.drop_duplicates(
                        ["measured_percent", "repeat", "holdout"])["fit_seconds"].sum()), 3)},
        "package_versions": package_versions(),
    }

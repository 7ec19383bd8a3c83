"""Train on simulated (+ a share of measured) segments, test on held-out measured records.

One fit per (measured_percent, repeat, holdout) of a split table: training is every simulated
segment plus the measured segments with role "train" (whole records, or single segments under
segment_share); the test set is the measured segments with role "test". Labels are the
health_state strings. With `feature_selection` (n_features, cv) a sequential backward selection
is fitted on each training set (never on test data) before the classifier.

Simulated validation: the simulated records a split lists with role "simulated_validation"
(hybrid.simulated_validation_share) are left out of that split's training set, and every fitted
model is evaluated on them too: ``fit_and_evaluate`` returns these metrics apart
(``simulated_validation.csv``, ``test_source`` = "simulated_validation"), never in the measured
predictions and metrics.

The measured-only baseline (`run_protocol` without simulated features) fits the same
classifier on the same measured training segments alone, with the same candidate features, so
the report can give the simulation's gain. It is never forced through the backward selection:
with `feature_selection` it chooses by an inner CV over its own training records whether to
select (`selection.SelectionByInnerCV`; too few records for one: all features), and its
metrics (`measured_only.csv`, BASELINE_COLUMNS) record the choice. With one measured class it
predicts that class; with none, it is skipped.

A classifier may train on a subset of the split table (``measured_percent``, ``repeats``: the
CNN, whose fits cost far more than an SVM's). Estimators that request ``feature_names`` /
``groups`` for ``fit`` (sklearn metadata routing: the CNN both, the backward selector the
groups) get the feature names and the record ids; those with
``predict_with_uncertainty`` (the CNN ensemble) fill the optional ``uncertainty`` column of the
predictions, and those with a ``history_`` (per member and epoch) have it written to
``models/history.parquet`` for the tracking job.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from pathlib import Path
from typing import NamedTuple

import joblib
import numpy as np
import pandas as pd
import pyarrow as pa
import sklearn
from sklearn.dummy import DummyClassifier
from sklearn.metrics import accuracy_score, f1_score
from sklearn.utils.metadata_routing import get_routing_for_object

from condmon import classifiers
from condmon.atomic import staging_directory, write_frame, write_table, write_text
from condmon.hybrid import (
    SIMULATED_VALIDATION,
    measured_rows,
    segment_roles,
    simulated_validation_ids,
    validate_splits,
)
from condmon.labels import sorted_holdouts
from condmon.seeds import derive_seed, stable_int
from condmon.selection import (
    ALL_FEATURES,
    BACKWARD,
    SelectionByInnerCV,
    SequentialBackwardSelector,
    select_then_classify,
    selected_features,
)
from condmon.signals import package_versions

log = logging.getLogger(__name__)

PREDICTION_SCHEMA = pa.schema(
    [
        ("protocol", pa.string()),
        ("measured_percent", pa.int32()),
        ("repeat", pa.int32()),
        ("holdout", pa.string()),
        ("record_id", pa.string()),
        ("segment", pa.int32()),
        ("speed_rpm", pa.float64()),
        ("true_label", pa.string()),
        ("predicted_label", pa.string()),
        # optional: spread of an ensemble's members for the predicted class; null for SVM/KNN
        ("uncertainty", pa.float64()),
    ]
)
PREDICTION_COLUMNS = PREDICTION_SCHEMA.names
METRIC_COLUMNS = [
    "classifier",
    "protocol",
    "measured_percent",
    "repeat",
    "holdout",
    "speed_rpm",
    "accuracy",
    "macro_f1",
    "n_train_simulated",
    "n_train_measured",
    "n_test",
    "fit_seconds",
]
# measured_only.csv: the baseline's metrics plus its own selection choice (SelectionByInnerCV):
# "all features" or "backward selection", why, the kept features and the inner CV accuracies
BASELINE_COLUMNS = METRIC_COLUMNS + [
    "selection",
    "selection_reason",
    "selected_features",
    "inner_cv_all_features",
    "inner_cv_backward_selection",
]
# simulated_validation.csv: the metrics of every fit on the held-out simulated records, labelled
SIMULATED_VALIDATION_COLUMNS = METRIC_COLUMNS[:2] + ["test_source"] + METRIC_COLUMNS[2:]
REQUIRED_COLUMNS = ["record_id", "segment", "health_state", "speed_rpm"]
HISTORY_FILE = "history.parquet"  # in models/, beside the model files


def evaluation_metrics(y_true, y_pred) -> dict:
    """Accuracy and macro F1 over the classes present in truth or prediction.

    Classes absent from both would only add F1 = 0 terms and deflate the macro mean (e.g. at a
    speed where a fault was never measured), so they are left out.
    """
    labels = sorted(set(y_true) | set(y_pred))
    return {
        "accuracy": float(accuracy_score(y_true, y_pred)),
        "macro_f1": float(
            f1_score(y_true, y_pred, labels=labels, average="macro", zero_division=0)
        ),
    }


def matching_feature_names(simulated_names, measured_names) -> list[str]:
    """The common feature names; an error naming the first difference if they disagree."""
    simulated_names, measured_names = list(simulated_names), list(measured_names)
    if simulated_names != measured_names:
        only_sim = [n for n in simulated_names if n not in set(measured_names)][:5]
        only_meas = [n for n in measured_names if n not in set(simulated_names)][:5]
        raise ValueError(
            "simulated and measured features differ: "
            f"{len(simulated_names)} vs {len(measured_names)} columns, only simulated "
            f"{only_sim}, only measured {only_meas} (same names in another order "
            "if both are empty)"
        )
    return simulated_names


def _check_columns(frame: pd.DataFrame, feature_names, what: str) -> None:
    missing = [c for c in REQUIRED_COLUMNS + list(feature_names) if c not in frame.columns]
    if missing:
        raise ValueError(
            f"{what} features lack column(s) {missing[:10]}"
            + (f" and {len(missing) - 10} more" if len(missing) > 10 else "")
        )
    if frame.empty:
        raise ValueError(f"{what} features have no rows")


def _split_keys(splits: pd.DataFrame) -> list[tuple[int, int, str]]:
    """(measured_percent, repeat, holdout) of every split, in a stable order."""
    holdout_order = {h: i for i, h in enumerate(sorted_holdouts(splits["holdout"]))}
    keys = splits[["measured_percent", "repeat", "holdout"]].drop_duplicates()
    keys = [(int(p), int(r), str(h)) for p, r, h in keys.itertuples(index=False)]
    return sorted(keys, key=lambda k: (k[0], k[1], holdout_order[k[2]]))


def select_splits(
    splits: pd.DataFrame, classifier_name: str, measured_percent=None, repeats=None
) -> pd.DataFrame:
    """The rows of the split table a classifier trains on: the listed measured percentages
    (None = all) and repeats 0..repeats-1 (None = all). Errors name the config key."""
    key = f"classifiers.{classifier_name}"
    if measured_percent is not None:
        available = sorted(int(p) for p in splits["measured_percent"].unique())
        wanted = sorted({int(p) for p in measured_percent})
        missing = [p for p in wanted if p not in available]
        if missing or not wanted:
            raise ValueError(
                f"{key}.measured_percent: {missing or wanted} not among the split "
                f"table's measured percentages {available} (hybrid.measured_percent)"
            )
        splits = splits[splits["measured_percent"].isin(wanted)]
    if repeats is not None:
        available = int(splits["repeat"].max()) + 1
        if not 1 <= int(repeats) <= available:
            raise ValueError(
                f"{key}.repeats: {repeats} but the split table has {available} "
                "repeat(s) (hybrid.repeats); choose 1.." + str(available)
            )
        splits = splits[splits["repeat"] < int(repeats)]
    return splits


def fit_with_metadata(model, X, y, **metadata):
    """Fit `model` with the metadata its fit requests (sklearn metadata routing; a Pipeline hands
    each item to the steps that request it): the feature names (the CNN finds its sensor
    channels in them) and the record ids (the CNN's validation split and the selector's folds
    keep records whole). Metadata nobody requests is left out."""
    with sklearn.config_context(enable_metadata_routing=True):
        wanted = get_routing_for_object(model).consumes("fit", list(metadata))
        return model.fit(X, y, **{name: metadata[name] for name in wanted})


def build_model(classifier_name, classifier_params, seed, feature_selection=None):
    """The configured classifier, behind a sequential backward selection if one is asked for."""
    model = classifiers.make_classifier(classifier_name, classifier_params, seed)
    if not feature_selection or feature_selection.get("n_features") is None:
        return model
    selector = SequentialBackwardSelector(
        n_features=int(feature_selection["n_features"]),
        cv=int(feature_selection.get("cv", 3)),
        random_state=seed,
    )
    # the names name the columns before selection: no step of the classifier takes them
    steps = [step for _, step in model.steps] if hasattr(model, "steps") else [model]
    with sklearn.config_context(enable_metadata_routing=True):
        for step in steps:
            if get_routing_for_object(step).consumes("fit", ["feature_names"]):
                step.set_fit_request(feature_names=False)
    return select_then_classify(selector, model)


def build_baseline_model(classifier_name, classifier_params, seed, feature_selection=None):
    """The measured-only baseline's estimator: the classifier on every candidate feature, or,
    with a configured selection, `SelectionByInnerCV` between it and the selected pipeline
    (chosen by the baseline's own training records, never forced)."""
    model = classifiers.make_classifier(classifier_name, classifier_params, seed)
    if not feature_selection or feature_selection.get("n_features") is None:
        return model
    selected = build_model(classifier_name, classifier_params, seed, feature_selection)
    return SelectionByInnerCV(model, selected, cv=int(feature_selection.get("cv", 3)))


def baseline_choice(model, feature_names) -> dict:
    """What a fitted baseline estimator chose (BASELINE_COLUMNS' extra columns)."""
    if isinstance(model, SelectionByInnerCV):
        kept = (
            selected_features(model.model_, feature_names)
            if model.choice_ == BACKWARD
            else list(feature_names)
        )
        return {
            "selection": model.choice_,
            "selection_reason": model.reason_,
            "selected_features": ";".join(kept),
            "inner_cv_all_features": model.inner_scores_.get(ALL_FEATURES, np.nan),
            "inner_cv_backward_selection": model.inner_scores_.get(BACKWARD, np.nan),
        }
    reason = (
        "one measured class: predicts it"
        if isinstance(model, DummyClassifier)
        else "no selection configured (features.selection.n_features)"
    )
    return {
        "selection": ALL_FEATURES,
        "selection_reason": reason,
        "selected_features": ";".join(feature_names),
        "inner_cv_all_features": np.nan,
        "inner_cv_backward_selection": np.nan,
    }


def training_set_key(x_train, y_train, groups) -> str:
    """A digest of one split's training data: its features, labels and record ids, in order."""
    digest = hashlib.sha256(np.ascontiguousarray(x_train).tobytes())
    digest.update(repr(x_train.shape).encode())
    for column in (y_train, groups):
        digest.update("\0".join(map(str, column)).encode() + b"\1")
    return digest.hexdigest()


def split_model(
    classifier_name, classifier_params, seed, feature_selection, y_train, measured_only, where
):
    """The unfitted estimator of one split: the configured classifier (the measured-only
    baseline's own choice of selection), or, for a baseline whose measured training records hold
    one class, that class as its constant answer."""
    if measured_only and len(set(y_train)) < 2:
        # what a classifier trained on one class can say: that class
        return DummyClassifier(strategy="constant", constant=y_train[0])
    if len(set(y_train)) < 2:
        raise ValueError(
            f"{where}: training data has only class(es) {sorted(set(y_train))}; "
            "a classifier needs at least two"
        )
    if measured_only:
        return build_baseline_model(classifier_name, classifier_params, seed, feature_selection)
    return build_model(classifier_name, classifier_params, seed, feature_selection)


class ProtocolResult(NamedTuple):
    predictions: pd.DataFrame  # measured test predictions (PREDICTION_COLUMNS)
    metrics: pd.DataFrame  # on the measured test records (METRIC_COLUMNS)
    models: dict  # fitted estimators keyed by (measured_percent, repeat, holdout)
    # on the held-out simulated records (SIMULATED_VALIDATION_COLUMNS)
    simulated_validation: pd.DataFrame


def run_protocol(
    classifier_name: str,
    classifier_params: dict | None,
    simulated_features: pd.DataFrame | None,
    measured_features: pd.DataFrame,
    splits: pd.DataFrame,
    feature_names,
    seed: int,
    measured_percent=None,
    repeats=None,
    feature_selection: dict | None = None,
):
    """(predictions, metrics, models) of ``fit_and_evaluate``: the measured-data results."""
    return fit_and_evaluate(
        classifier_name,
        classifier_params,
        simulated_features,
        measured_features,
        splits,
        feature_names,
        seed,
        measured_percent,
        repeats,
        feature_selection,
    )[:3]


def _predict(model, x) -> tuple[np.ndarray, np.ndarray | float]:
    """Predicted labels (str) and the ensemble's uncertainty where the model gives one (else NaN)."""
    if hasattr(model, "predict_with_uncertainty"):
        y_pred, uncertainty = model.predict_with_uncertainty(x)
        return y_pred.astype(str), uncertainty
    return model.predict(x).astype(str), np.nan


def metric_rows(common: dict, y_true, y_pred, speeds) -> list[dict]:
    """One metrics row over all speeds (speed_rpm NaN) and one per speed, each with `common`."""
    y_true, y_pred, speeds = np.asarray(y_true), np.asarray(y_pred), np.asarray(speeds, float)
    rows = [
        {**common, "speed_rpm": np.nan, **evaluation_metrics(y_true, y_pred), "n_test": len(y_true)}
    ]
    for speed in sorted(set(speeds)):
        at_speed = speeds == speed
        rows.append(
            {
                **common,
                "speed_rpm": speed,
                **evaluation_metrics(y_true[at_speed], y_pred[at_speed]),
                "n_test": int(at_speed.sum()),
            }
        )
    return rows


def fit_and_evaluate(
    classifier_name: str,
    classifier_params: dict | None,
    simulated_features: pd.DataFrame | None,
    measured_features: pd.DataFrame,
    splits: pd.DataFrame,
    feature_names,
    seed: int,
    measured_percent=None,
    repeats=None,
    feature_selection: dict | None = None,
) -> ProtocolResult:
    """Fit and evaluate one classifier on every split of a split table.

    ``measured_percent``/``repeats`` restrict the splits (see select_splits).
    ``simulated_features`` None: the measured-only baseline (see the module docstring; it has no
    simulated validation). Returns predictions and metrics per the train contract, the fitted
    estimators, and the metrics on the split's held-out simulated records (empty without any).
    """
    feature_names = list(feature_names)
    build_model(classifier_name, classifier_params, seed, feature_selection)  # fail early if bad
    validate_splits(splits)
    splits = select_splits(splits, classifier_name, measured_percent, repeats)
    measured_only = simulated_features is None
    if measured_only:
        simulated_features = measured_features.iloc[:0]
    else:
        _check_columns(simulated_features, feature_names, "simulated")
    _check_columns(measured_features, feature_names, "measured")
    protocol = str(splits["protocol"].iloc[0])

    measured_ids = set(measured_features["record_id"].astype(str))
    sim_records = simulated_features["record_id"].astype(str).to_numpy()
    if not measured_only:
        absent = sorted(simulated_validation_ids(splits) - set(sim_records))
        if absent:
            raise ValueError(
                f"split table holds out simulated record(s) {absent[:5]} absent "
                "from the simulated features (hybrid.simulated_validation_share): "
                "is the split table older than the simulated features?"
            )
    unknown = sorted(set(measured_rows(splits)["record_id"]) - measured_ids)
    if unknown:
        raise ValueError(
            f"split table names record(s) {unknown[:5]} absent from the measured features"
        )
    unlisted = sorted(measured_ids - set(measured_rows(splits)["record_id"]))
    if unlisted:
        log.warning("measured record(s) %s are in no split and are never used", unlisted[:5])

    x_sim = simulated_features[feature_names].to_numpy(np.float32)
    y_sim = simulated_features["health_state"].astype(str).to_numpy()
    x_meas = measured_features[feature_names].to_numpy(np.float32)
    y_meas = measured_features["health_state"].astype(str).to_numpy()
    meas_records = measured_features["record_id"].astype(str)
    meas_speed = measured_features["speed_rpm"].to_numpy(float)
    sim_speed = simulated_features["speed_rpm"].to_numpy(float)

    holdout_index = {h: i for i, h in enumerate(sorted_holdouts(splits["holdout"]))}
    predictions, metrics, validation, models = [], [], [], {}
    # a classifier whose fit draws no random numbers fits each distinct training set once (the
    # selection's folds follow the record ids, never a seed); {training_set_key: (model, seconds)}
    seed_free, fitted = classifiers.CLASSIFIERS[classifier_name].seed_free, {}
    for percent, repeat, holdout in _split_keys(splits):
        split = splits[
            (splits["measured_percent"] == percent)
            & (splits["repeat"] == repeat)
            & (splits["holdout"] == holdout)
        ]
        role = segment_roles(measured_rows(split), measured_features)
        train, test = role == "train", role == "test"
        # the simulated records this split holds out (none for the measured-only baseline)
        held_out = np.isin(sim_records, list(simulated_validation_ids(split)))
        where = f"measured_percent={percent} repeat={repeat} holdout={holdout!r}"
        if not test.any():
            log.warning("%s: no test records, skipped", where)
            continue
        x_train = np.concatenate([x_sim[~held_out], x_meas[train]])
        y_train = np.concatenate([y_sim[~held_out], y_meas[train]])
        groups = np.concatenate([sim_records[~held_out], meas_records.to_numpy()[train]])
        fit_seed = derive_seed(seed, stable_int(protocol), percent, repeat, holdout_index[holdout])
        if measured_only and not len(y_train):
            continue  # nothing measured trains: no baseline at this split
        key = training_set_key(x_train, y_train, groups) if seed_free else None
        if key in fitted:
            # e.g. every repeat at 0 % measured, or measured records of classes that never train
            model, fit_seconds = fitted[key]  # the model's own fit time
            log.info("%s: the training set of an earlier split, its model reused", where)
        else:
            model = split_model(
                classifier_name,
                classifier_params,
                fit_seed,
                feature_selection,
                y_train,
                measured_only,
                where,
            )
            start = time.perf_counter()
            fit_with_metadata(model, x_train, y_train, feature_names=feature_names, groups=groups)
            fit_seconds = time.perf_counter() - start
            if key is not None:
                fitted[key] = model, fit_seconds
        y_pred, uncertainty = _predict(model, x_meas[test])
        y_true = y_meas[test]
        models[(percent, repeat, holdout)] = model

        test_rows = measured_features.loc[test]
        predictions.append(
            pd.DataFrame(
                {
                    "protocol": protocol,
                    "measured_percent": percent,
                    "repeat": repeat,
                    "holdout": holdout,
                    "record_id": test_rows["record_id"].astype(str).to_numpy(),
                    "segment": test_rows["segment"].to_numpy(),
                    "speed_rpm": meas_speed[test],
                    "true_label": y_true,
                    "predicted_label": y_pred,
                    "uncertainty": uncertainty,
                }
            )
        )

        common = {
            "classifier": classifier_name,
            "protocol": protocol,
            "measured_percent": percent,
            "repeat": repeat,
            "holdout": holdout,
            "n_train_simulated": int((~held_out).sum()),
            "n_train_measured": int(train.sum()),
            "fit_seconds": fit_seconds,
        }
        if measured_only:
            common.update(baseline_choice(model, feature_names))
        rows = metric_rows(common, y_true, y_pred, meas_speed[test])
        metrics += rows
        log.info(
            "%s: %d simulated + %d measured training segments, %d test segments, "
            "accuracy %.3f, fit %.1f s",
            where,
            (~held_out).sum(),
            train.sum(),
            len(y_true),
            rows[0]["accuracy"],
            fit_seconds,
        )
        if held_out.any():
            sim_pred, _ = _predict(model, x_sim[held_out])
            rows = metric_rows(
                {**common, "test_source": SIMULATED_VALIDATION},
                y_sim[held_out],
                sim_pred,
                sim_speed[held_out],
            )
            validation += rows
            log.info(
                "%s: simulated validation on %d held-out simulated segments, accuracy %.3f",
                where,
                held_out.sum(),
                rows[0]["accuracy"],
            )

    predictions = (
        pd.concat(predictions, ignore_index=True)
        if predictions
        else pd.DataFrame(columns=PREDICTION_COLUMNS)
    )
    predictions = predictions.astype(
        {
            "measured_percent": "int32",
            "repeat": "int32",
            "segment": "int32",
            "speed_rpm": float,
            "uncertainty": float,
        }
    )
    metrics = pd.DataFrame(metrics, columns=BASELINE_COLUMNS if measured_only else METRIC_COLUMNS)
    validation = pd.DataFrame(validation, columns=SIMULATED_VALIDATION_COLUMNS)
    return ProtocolResult(predictions[PREDICTION_COLUMNS], metrics, models, validation)


# -- outputs --------------------------------------------------------------------------------
def model_filename(percent: int, repeat: int, holdout_index: int | None = None) -> str:
    """p<percent:03d>_r<repeat>[_h<holdout index>].joblib (no _h without a holdout)."""
    suffix = "" if holdout_index is None else f"_h{holdout_index}"
    return f"p{percent:03d}_r{repeat}{suffix}.joblib"


def training_history(models: dict) -> pd.DataFrame:
    """Per-epoch curves of the models that have them (``history_``: the CNN members), keyed by
    measured_percent, repeat and holdout; empty for SVM/KNN."""
    frames = []
    for (percent, repeat, holdout), model in models.items():
        history = getattr(model, "history_", None)
        if history:
            frame = pd.DataFrame(history)
            frame.insert(0, "holdout", holdout)
            frame.insert(0, "repeat", repeat)
            frame.insert(0, "measured_percent", percent)
            frames.append(frame)
    if not frames:
        return pd.DataFrame()
    history = pd.concat(frames, ignore_index=True)
    return history.astype(
        {"measured_percent": "int32", "repeat": "int32", "member": "int32", "epoch": "int32"}
    )


def write_models(models: dict, directory, feature_names) -> list[dict]:
    """Dump every fitted model into `directory` (built aside, then renamed into place), plus
    ``history.parquet`` (per member and epoch) if the models have a training history.

    Returns one entry per file: file name, measured_percent, repeat, holdout, holdout_index
    (and, for the CNN ensemble, its members' epochs run and best epochs; with a backward
    selection, the names of the selected features among `feature_names`).
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
            model = models[(percent, repeat, holdout)]
            joblib.dump(model, tmp / name)
            entry = {
                "file": name,
                "measured_percent": percent,
                "repeat": repeat,
                "holdout": holdout,
                "holdout_index": index,
            }
            if hasattr(model, "member_info_"):
                entry["members"] = model.member_info_
            selected = selected_features(model, feature_names)
            if selected is not None:
                entry["selected_features"] = selected
            entries.append(entry)
        history = training_history(models)
        if not history.empty:
            write_frame(history, tmp / HISTORY_FILE)
    return entries


def write_predictions(predictions: pd.DataFrame, path) -> None:
    write_table(
        pa.Table.from_pandas(
            predictions[PREDICTION_COLUMNS], schema=PREDICTION_SCHEMA, preserve_index=False
        ),
        path,
    )


def write_metrics(metrics: pd.DataFrame, path, columns=METRIC_COLUMNS) -> None:
    """metrics.csv (measured_only.csv: columns BASELINE_COLUMNS); speed_rpm is empty on the
    all-speeds rows."""
    write_text(metrics.reindex(columns=columns).to_csv(index=False), path)


def write_simulated_validation(validation: pd.DataFrame, path) -> None:
    """simulated_validation.csv: metrics.csv's columns plus test_source ("simulated_validation");
    n_test counts held-out simulated segments."""
    write_text(validation[SIMULATED_VALIDATION_COLUMNS].to_csv(index=False), path)


class JobCost(NamedTuple):
    """What a train job cost: its wall seconds and peak memory (MB; None: not measured)."""

    total_seconds: float
    peak_memory_mb: float | None = None


def train_info(
    classifier_name: str,
    params: dict | None,
    seed: int,
    protocol: str,
    labels,
    feature_names,
    metrics: pd.DataFrame,
    model_files: list[dict],
    cost: JobCost,
    selection: dict | None = None,
) -> dict:
    """Contents of info.json: what was trained, on which features, and how long it took."""
    total_seconds, peak_memory_mb = cost
    names_json = json.dumps(list(feature_names))
    versions = package_versions()
    if classifier_name == "cnn":
        versions.update(package_versions(("torch",)))
    return {
        "classifier": classifier_name,
        "classifier_params": classifiers.classifier_params(classifier_name, params),
        "seed": int(seed),
        "protocol": protocol,
        "labels": sorted(map(str, labels)),
        "n_features": len(feature_names),
        "feature_names_sha256": hashlib.sha256(names_json.encode()).hexdigest(),
        "models": model_files,
        "selection": {k: v for k, v in (selection or {}).items() if v is not None},
        "timings": {
            "total_seconds": round(total_seconds, 3),
            "fit_seconds_sum": round(
                float(
                    metrics.drop_duplicates(["measured_percent", "repeat", "holdout"])[
                        "fit_seconds"
                    ].sum()
                ),
                3,
            ),
        },
        "peak_memory_mb": None if peak_memory_mb is None else round(peak_memory_mb, 1),
        "package_versions": versions,
    }

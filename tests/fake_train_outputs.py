"""Small but contract-conforming train and calibration outputs for report/tracking tests.

Two classifiers x two protocols (record_split; condition_holdout over two speeds), measured
percentages 0 and 50, two repeats; real fitted sklearn pipelines on a six-feature table.
"""
from __future__ import annotations

import json
from pathlib import Path

import joblib
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import accuracy_score, f1_score
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from condmon.train import model_filename

LABELS = ["healthy", "missing_tooth", "surface_fault"]
SPEEDS = [600.0, 900.0]
PERCENTS = [0, 50]
REPEATS = [0, 1]
CLASSIFIERS = {"knn": {"n_neighbors": 3}, "logreg": {"C": 1.0, "max_iter": 200}}
PROTOCOL_HOLDOUTS = {"record_split": [""],
                     "condition_holdout": ["speed_rpm=600", "speed_rpm=900"]}
FEATURES = [f"fft_A1_x_{f:06.1f}Hz" for f in (10, 20, 30, 40, 50, 60)]
ID_COLUMNS = ["record_id", "segment", "source", "health_state", "speed_rpm", "load", "fs_hz"]


def _features_table(rng, source: str, n_per_stratum: int) -> pd.DataFrame:
    rows = []
    for label_index, label in enumerate(LABELS):
        for speed in SPEEDS:
            for k in range(n_per_stratum):
                for segment in range(2):
                    values = rng.normal(label_index, 1.1, len(FEATURES)).astype(np.float32)
                    rows.append({"record_id": f"{source}_{label}_{speed:g}_{k}",
                                 "segment": segment, "source": source, "health_state": label,
                                 "speed_rpm": speed, "load": 1.0, "fs_hz": 5000.0,
                                 **dict(zip(FEATURES, values))})
    return pd.DataFrame(rows)


def _write_features(frame: pd.DataFrame, path: Path) -> None:
    table = pa.Table.from_pandas(frame, preserve_index=False)
    table = table.replace_schema_metadata({b"condmon.feature_names": json.dumps(FEATURES).encode(),
                                           b"condmon.feature_kind": b"spectrum"})
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, path)


def _make_classifier(name: str):
    params = CLASSIFIERS[name]
    estimator = KNeighborsClassifier(**params) if name.startswith("knn") else LogisticRegression(**params)
    return make_pipeline(StandardScaler(), estimator)


def build(root: Path) -> dict:
    """Write the fake outputs under ``root`` (a results/<run> directory); returns the paths."""
    rng = np.random.default_rng(7)
    simulated = _features_table(rng, "simulated", 3)
    measured = _features_table(rng, "virtual_bench", 3)
    _write_features(simulated, root / "features/simulated.parquet")
    _write_features(measured, root / "features/measured.parquet")
    records = measured["record_id"].unique()

    paths = {"metrics": [], "predictions": [], "models": []}
    for clf in CLASSIFIERS:
        for protocol, holdouts in PROTOCOL_HOLDOUTS.items():
            out = root / "train" / clf / protocol
            (out / "models").mkdir(parents=True, exist_ok=True)
            metric_rows, prediction_frames = [], []
            for percent in PERCENTS:
                for repeat in REPEATS:
                    for h_index, holdout in enumerate(holdouts):
                        split_rng = np.random.default_rng([percent, repeat, h_index])
                        if holdout:
                            held_speed = float(holdout.split("=")[1])
                            test_mask = measured["speed_rpm"] == held_speed
                            candidates = measured.loc[~test_mask, "record_id"].unique()
                        else:
                            test_records = split_rng.choice(records, len(records) // 2,
                                                            replace=False)
                            test_mask = measured["record_id"].isin(test_records)
                            candidates = measured.loc[~test_mask, "record_id"].unique()
                        n_train = int(round(len(candidates) * percent / 100))
                        train_records = split_rng.choice(candidates, n_train, replace=False)
                        train = pd.concat([simulated,
                                           measured[measured["record_id"].isin(train_records)]])
                        test = measured[test_mask]
                        # bare float32 arrays, as the train stage fits them
                        model = _make_classifier(clf).fit(train[FEATURES].to_numpy(np.float32),
                                                          train["health_state"].to_numpy())
                        # named like the train stage names them (zero-padded percent)
                        name = model_filename(percent, repeat, h_index if holdout else None)
                        joblib.dump(model, out / "models" / name)
                        predicted = model.predict(test[FEATURES].to_numpy(np.float32))
                        prediction_frames.append(pd.DataFrame({
                            "protocol": protocol, "measured_percent": np.int32(percent),
                            "repeat": np.int32(repeat), "holdout": holdout,
                            "record_id": test["record_id"].to_numpy(),
                            "segment": test["segment"].to_numpy(np.int32),
                            "speed_rpm": test["speed_rpm"].to_numpy(),
                            "true_label": test["health_state"].to_numpy(),
                            "predicted_label": predicted}))
                        common = {"classifier": clf, "protocol": protocol,
                                  "measured_percent": percent, "repeat": repeat,
                                  "holdout": holdout,
                                  "n_train_simulated": len(simulated),
                                  "n_train_measured": len(train) - len(simulated),
                                  "fit_seconds": 0.01}
                        truth = test["health_state"].to_numpy()
                        metric_rows.append({**common, "speed_rpm": None,
                                            "accuracy": accuracy_score(truth, predicted),
                                            "macro_f1": f1_score(truth, predicted, average="macro"),
                                            "n_test": len(test)})
                        for speed in sorted(test["speed_rpm"].unique()):
                            at = (test["speed_rpm"] == speed).to_numpy()
                            metric_rows.append({
                                **common, "speed_rpm": speed,
                                "accuracy": accuracy_score(truth[at], predicted[at]),
                                "macro_f1": f1_score(truth[at], predicted[at], average="macro"),
                                "n_test": int(at.sum())})
            columns = ["classifier", "protocol", "measured_percent", "repeat", "holdout",
                       "speed_rpm", "accuracy", "macro_f1", "n_train_simulated",
                       "n_train_measured", "n_test", "fit_seconds"]
            pd.DataFrame(metric_rows)[columns].to_csv(out / "metrics.csv", index=False)
            pd.concat(prediction_frames).to_parquet(out / "predictions.parquet", index=False)
            paths["metrics"].append(out / "metrics.csv")
            paths["predictions"].append(out / "predictions.parquet")
            paths["models"].append(out / "models")

    calibration = root / "calibration"
    calibration.mkdir(parents=True, exist_ok=True)
    (calibration / "params.json").write_text(json.dumps({
        "contact_law": "hertz", "parameters": {"stiffness": 1.2e8, "damping": 0.02},
        "cost": 0.031, "evaluations": 40}))
    freqs = np.linspace(5, 2500, 200)
    spectra = []
    for speed in SPEEDS:
        for channel in ("A1_x", "A1_y"):
            base = 1.0 / (1 + freqs / 200) + 0.5 * np.exp(-((freqs - speed / 60 * 23) / 15) ** 2)
            spectra.append(pd.DataFrame({"speed_rpm": speed, "channel": channel, "freq_hz": freqs,
                                         "measured": base * rng.uniform(0.8, 1.2, len(freqs)),
                                         "calibrated": base}))
    pd.concat(spectra).to_parquet(calibration / "spectra.parquet", index=False)
    history = pd.DataFrame({"generation": np.arange(40) // 8, "evaluation": np.arange(40),
                            "contact_law": np.where(np.arange(40) % 2, "hertz", "linear"),
                            "cost": np.abs(rng.normal(1, 0.5, 40)) / (1 + np.arange(40) / 4),
                            "stiffness": rng.uniform(1e7, 1e9, 40)})
    history.loc[5, "cost"] = np.inf  # a failed simulation
    history.to_parquet(calibration / "history.parquet", index=False)
    paths.update(calibration_params=calibration / "params.json",
                 calibration_spectra=calibration / "spectra.parquet",
                 calibration_history=calibration / "history.parquet",
                 features_measured=root / "features/measured.parquet",
                 features_simulated=root / "features/simulated.parquet")
    return paths

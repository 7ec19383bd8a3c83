"""A run's deployable models: every fitted estimator of the train jobs as a `SignalModel` (raw
segments in, labels out), in a folder of its own per config, ``results/<run>/models/<config_hash>/``.

The train jobs' ``train/<classifier>/<protocol>/models/*.joblib`` are rewritten by the next run of
another config; the packaged copies are not (another config, another folder), so an MLflow run's
``model_file`` tag keeps pointing at the model it logged. ``index.json`` lists every model (its key,
file, digest, accuracy, training domain) and names the ``best`` one: the model a user deploys by
default (``condmon predict --model results/<run>``; the registry alias ``best``).

The best model: among the non-leaky protocols' fits that hold no condition out (a deployed model
should have seen every condition), those with the most measured data, repeat 0; of these the
classifier and protocol with the highest mean accuracy over repeats (ties: classifier, then
protocol name).
"""

from __future__ import annotations

import json
from pathlib import Path

import joblib
import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from condmon.atomic import staging_directory
from condmon.hybrid import measured_rows, read_split_table, training_range
from condmon.labels import LEAKY_PROTOCOLS
from condmon.signal_model import SPEED_TOLERANCE, SignalModel

INDEX_FILE = "index.json"
KEY_FIELDS = ("classifier", "protocol", "measured_percent", "repeat", "holdout")


class ModelStoreError(ValueError):
    """A results folder or model store lacks what a model needs."""


def signal_shape(signal_table) -> tuple[float, int]:
    """(fs_hz, samples per segment) of a signal table, from its first row."""
    parquet = pq.ParquetFile(signal_table)
    row = next(parquet.iter_batches(batch_size=1, columns=["fs_hz", "signal"])).to_pylist()[0]
    return float(row["fs_hz"]), len(row["signal"])


def training_speeds(simulated_speeds, measured: pd.DataFrame, split: pd.DataFrame) -> list[float]:
    """Every speed a fit's training data holds: the simulated ones and those of the measured
    records the split trains on."""
    train_ids = set(measured_rows(split).query("role == 'train'")["record_id"])
    measured_speeds = measured.loc[measured["record_id"].isin(train_ids), "speed_rpm"]
    return sorted({float(s) for s in [*simulated_speeds, *measured_speeds]})


def build_store(
    directory,
    train_dirs,
    split_tables,
    measured_signals,
    simulated_features,
    measured_features,
    features: dict,
    healthy_state: str,
    system: dict | None,
    config_hash: str,
) -> dict:
    """Package every model the train jobs wrote into ``directory`` (built aside, renamed into
    place); returns the index (also written as ``index.json``).

    ``features``: kind, channels, spectrum, statistical, defect_orders (the features rules' params);
    ``split_tables``: {protocol: split table}. Each model's accuracy (the best model's choice)
    comes from its train folder's metrics.csv.
    """
    fs_hz, n_samples = signal_shape(measured_signals)
    simulated_speeds = (
        pq.read_table(simulated_features, columns=["speed_rpm"]).column(0).unique().to_pylist()
    )
    names = feature_names(measured_features)
    measured = pq.read_table(
        measured_features, columns=["record_id", "segment", "speed_rpm", *names]
    ).to_pandas()
    simulated = pq.read_table(simulated_features, columns=["record_id", *names]).to_pandas()
    splits = {protocol: read_split_table(path) for protocol, path in split_tables.items()}
    entries = []
    with staging_directory(Path(directory)) as tmp:
        for train_dir in map(Path, train_dirs):
            info = json.loads((train_dir / "info.json").read_text())
            clf, protocol = info["classifier"], info["protocol"]
            if protocol not in splits:
                raise ModelStoreError(f"no split table for protocol {protocol!r} ({train_dir})")
            # holdout is text ("speed_rpm=450"), empty where the protocol holds nothing out
            metrics = pd.read_csv(train_dir / "metrics.csv", dtype={"holdout": str})
            overall = metrics[metrics["speed_rpm"].isna()].fillna({"holdout": ""})
            for model in info["models"]:
                key = {
                    "classifier": clf,
                    "protocol": protocol,
                    "measured_percent": int(model["measured_percent"]),
                    "repeat": int(model["repeat"]),
                    "holdout": model["holdout"] or "",
                }
                table = splits[protocol]
                split = table[
                    (table["measured_percent"] == key["measured_percent"])
                    & (table["repeat"] == key["repeat"])
                    & (table["holdout"] == key["holdout"])
                ]
                row = overall[
                    (overall["measured_percent"] == key["measured_percent"])
                    & (overall["repeat"] == key["repeat"])
                    & (overall["holdout"] == key["holdout"])
                ]
                domain = {
                    "fs_hz": fs_hz,
                    "n_samples": n_samples,
                    "channels": list(features["channels"]),
                    "speeds_rpm": training_speeds(simulated_speeds, measured, split),
                    "speed_tolerance": SPEED_TOLERANCE,
                }
                signal_model = SignalModel(
                    joblib.load(train_dir / "models" / model["file"]),
                    features={**features, "feature_names": names},
                    domain=domain,
                    healthy_state=healthy_state,
                    system=system,
                    info={
                        **key,
                        "config_hash": config_hash,
                        "accuracy": float(row["accuracy"].iloc[0]) if len(row) else None,
                    },
                    training_range=training_range(
                        simulated, measured, split, model.get("selected_features") or names
                    ),
                )
                name = f"{clf}/{protocol}/{model['file']}"
                (tmp / clf / protocol).mkdir(parents=True, exist_ok=True)
                joblib.dump(signal_model, tmp / name)
                entries.append(
                    {
                        **key,
                        "file": name,
                        "digest": signal_model.digest(),
                        "leaky": protocol in LEAKY_PROTOCOLS,
                        "accuracy": signal_model.info["accuracy"],
                        "classes": signal_model.classes,
                        "domain": domain,
                        # where it was fitted: the CNN's device, scikit-learn's CPU
                        "device": getattr(signal_model.estimator, "device_", "cpu"),
                    }
                )
        index = {"config_hash": config_hash, "best": best_model(entries), "models": entries}
        (tmp / INDEX_FILE).write_text(json.dumps(index, indent=1, default=float))
    return index


def feature_names(features_table) -> list[str]:
    meta = pq.ParquetFile(features_table).schema_arrow.metadata or {}
    return json.loads(meta[b"condmon.feature_names"])


def best_model(entries: list[dict]) -> str | None:
    """The file of the model to deploy by default (module docstring); None if no fit qualifies."""
    candidates = [e for e in entries if not e["leaky"] and not e["holdout"]]
    if not candidates:
        return None
    most = max(e["measured_percent"] for e in candidates)
    candidates = [e for e in candidates if e["measured_percent"] == most]
    mean = {}
    for e in candidates:
        mean.setdefault((e["classifier"], e["protocol"]), []).append(e["accuracy"] or 0.0)
    first = min(e["repeat"] for e in candidates)
    chosen = max(sorted(mean), key=lambda k: np.mean(mean[k]))  # the first of equals, by name
    return next(
        e["file"]
        for e in candidates
        if (e["classifier"], e["protocol"]) == chosen and e["repeat"] == first
    )


# -- reading a store ----------------------------------------------------------------------------


def read_index(directory) -> dict:
    path = Path(directory) / INDEX_FILE
    if not path.is_file():
        raise ModelStoreError(f"{directory}: no {INDEX_FILE}; not a model store")
    return json.loads(path.read_text())


def store_of_results(results) -> Path:
    """The model store of a results folder's latest tracked config (``report/mlflow_run.json``
    names its config hash), or its only store."""
    results = Path(results)
    run_info = results / "report" / "mlflow_run.json"
    if run_info.is_file() and (config_hash := json.loads(run_info.read_text()).get("config_hash")):
        if (results / "models" / config_hash / INDEX_FILE).is_file():
            return results / "models" / config_hash
    stores = sorted((results / "models").glob(f"*/{INDEX_FILE}"), key=lambda p: p.stat().st_mtime)
    if not stores:
        raise ModelStoreError(
            f"{results}: no models/<config_hash>/{INDEX_FILE}; has the pipeline "
            "run (its track job packages the models)?"
        )
    return stores[-1].parent


def select(index: dict, **key) -> dict:
    """The index entry matching ``key`` (fields of KEY_FIELDS given as not None); the best model
    when nothing is given."""
    wanted = {k: v for k, v in key.items() if v is not None}
    unknown = sorted(set(wanted) - set(KEY_FIELDS))
    if unknown:
        raise ModelStoreError(f"unknown model key(s) {unknown}; choose among {list(KEY_FIELDS)}")
    if not wanted:
        if index.get("best") is None:
            raise ModelStoreError(
                "the store names no best model; choose one by classifier, protocol, "
                "measured_percent, repeat"
            )
        return next(e for e in index["models"] if e["file"] == index["best"])
    found = [e for e in index["models"] if all(str(e[k]) == str(v) for k, v in wanted.items())]
    if not found:
        raise ModelStoreError(
            f"no model with {wanted}; the store has "
            f"{sorted({(e['classifier'], e['protocol']) for e in index['models']})}"
        )
    # the most measured data and the first repeat among several matches, as for the best model
    return sorted(found, key=lambda e: (-e["measured_percent"], e["repeat"], e["holdout"]))[0]

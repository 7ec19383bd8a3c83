"""MLflow tracking of one pipeline invocation, logged by a single job after training.

Only this job touches the tracking store, so parallel training jobs never race on the SQLite
file. Layout in the store:

- experiment = run name (e.g. "default"); for a SQLite store its artifacts go next to the
  database, ``<db dir>/mlartifacts/<experiment>``;
- one parent run per invocation, tags ``git_commit``, ``git_dirty``, ``config_hash``,
  ``snakemake_run_name``, ``data_source``, ``data_source_synthetic``, ``models_logged``,
  ``superseded``; artifact ``accuracy.csv`` (all metrics rows);
- one nested run per classifier x protocol x measured percentage x repeat (x held-out
  condition): params (``classifier.<name>`` for the classifier's settings, protocol, percent,
  repeat, holdout, training and test sizes), metrics (``accuracy``, ``macro_f1``,
  ``accuracy_<speed>rpm``, ``macro_f1_<speed>rpm``, ``fit_seconds``), artifacts
  ``confusion_matrix.csv`` and ``.png``, and the fitted pipeline as an MLflow sklearn model with a
  signature inferred from two rows of the measured feature table;
- for the CNN ensemble additionally: its training curves from ``models/history.parquet``
  (written by the train job) as metrics with step = epoch, per member
  (``member<k>_train_loss``, ``member<k>_val_loss``, ``..._train_accuracy``,
  ``..._val_accuracy``) and as the mean over the members that ran that epoch (``train_loss``,
  ...); ``epochs_run_mean`` and ``uncertainty_mean`` (mean member spread of the test
  predictions); the ensemble as an MLflow PyTorch model (standardisation folded in: raw
  features in, mean class probabilities out, columns named in ``model_classes.json``).

Rerun semantics: every run is created with tag ``superseded=false``. After a new invocation has
logged everything, the earlier runs of the same experiment with the same ``config_hash`` tag
(parents and their nested runs, finished, failed or left running by a killed job) get
``superseded=true`` and ``superseded_by=<new parent run id>``. Nothing is deleted, so history
stays inspectable, and a comparison that keeps ``superseded=false`` counts each configuration
once. A failed invocation supersedes nothing. Runs with a different config hash are different
configurations and stay current.

A remote tracking server (http/https URI) is probed first with a short timeout, and MLflow's
HTTP retries are capped, so a server that is down fails in seconds with its URI in the message.
"""
from __future__ import annotations

import functools
import json
import logging
import os
import re
import subprocess
import time
import urllib.error
import urllib.request
from importlib import metadata
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import pyarrow.parquet as pq

from condmon import classifiers, plots, report
from condmon.atomic import write_json
from condmon.hybrid import LEAKY_PROTOCOLS, format_speed, sorted_holdouts

log = logging.getLogger(__name__)

DEFAULT_TRACKING_URI = "sqlite:///results/mlflow.db"
FEATURE_NAMES_KEY = b"condmon.feature_names"
MODEL_POLICIES = ("all", "first_repeat", "none")

# Fail fast against a dead server instead of MLflow's default ~4 minutes of retries. Users can
# still override these through the environment.
HTTP_ENV_DEFAULTS = {"MLFLOW_HTTP_REQUEST_MAX_RETRIES": "1",
                     "MLFLOW_HTTP_REQUEST_BACKOFF_FACTOR": "1",
                     "MLFLOW_HTTP_REQUEST_TIMEOUT": "30"}
PROBE_TIMEOUT_S = 5.0


class TrackingError(RuntimeError):
    """The tracking store is unusable or the inputs to log are inconsistent."""


# --------------------------------------------------------------------------- tracking store

def resolve_tracking_uri(uri: str, workdir=".") -> str:
    """Make a relative SQLite path absolute (relative to ``workdir``) and create its directory."""
    prefix = "sqlite:///"
    if not uri.startswith(prefix):
        return uri
    path = Path(uri[len(prefix):])
    if not path.is_absolute():
        path = (Path(workdir) / path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    return f"{prefix}{path}"


def is_remote(uri: str) -> bool:
    return urlparse(uri).scheme in ("http", "https")


def check_tracking_server(uri: str, timeout_s: float = PROBE_TIMEOUT_S) -> None:
    """Raise TrackingError naming ``uri`` if an http(s) tracking server does not answer within
    ``timeout_s`` (refused, unknown host, no answer, or a 502/503/504 from a proxy in front of
    it); any other HTTP answer counts as reachable. Also caps MLflow's HTTP retries
    (HTTP_ENV_DEFAULTS) for the rest of the process.
    """
    if not is_remote(uri):
        return
    for name, value in HTTP_ENV_DEFAULTS.items():
        os.environ.setdefault(name, value)
    try:
        urllib.request.urlopen(uri.rstrip("/") + "/health", timeout=timeout_s).close()
    except urllib.error.HTTPError as exc:
        if exc.code not in (502, 503, 504):
            return  # something answered (an auth proxy, say); MLflow reports any real problem
        reason = f"HTTP {exc.code} {exc.reason}: a proxy or gateway answered for it"
    except (urllib.error.URLError, OSError) as exc:
        reason = getattr(exc, "reason", exc)
    else:
        return
    raise TrackingError(
        f"MLflow tracking server {uri} is unreachable ({reason}). Start the server or set "
        f"the tracking URI to a reachable one (e.g. {DEFAULT_TRACKING_URI})")


def artifact_location(uri: str, experiment: str) -> str | None:
    """For SQLite stores keep artifacts beside the database instead of in ./mlruns."""
    if not uri.startswith("sqlite:///"):
        return None  # a server or file store picks its own artifact root
    db_path = Path(uri[len("sqlite:///"):])
    return (db_path.parent / "mlartifacts" / experiment).as_uri()


def get_or_create_experiment(client, uri: str, name: str) -> str:
    experiment = client.get_experiment_by_name(name)
    if experiment is None:
        return client.create_experiment(name, artifact_location=artifact_location(uri, name))
    if experiment.lifecycle_stage == "deleted":
        # a deleted experiment still owns the name; bring it back rather than fail
        client.restore_experiment(experiment.experiment_id)
    return experiment.experiment_id


# --------------------------------------------------------------------------- inputs

def git_state(cwd=".") -> tuple[str, str]:
    """(commit, dirty) of the working tree, ("unknown", "unknown") outside git."""
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True,
                                text=True, timeout=10, check=True).stdout.strip()
        status = subprocess.run(["git", "status", "--porcelain"], cwd=cwd, capture_output=True,
                                text=True, timeout=10, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return "unknown", "unknown"
    return commit, "true" if status.strip() else "false"


def flatten_params(params: dict, prefix: str) -> dict[str, str]:
    """{"a": {"b": 1}} -> {"<prefix>.a.b": "1"}; lists as JSON."""
    flat = {}
    for key, value in params.items():
        name = f"{prefix}.{key}"
        if isinstance(value, dict):
            flat.update(flatten_params(value, name))
        else:
            flat[name] = json.dumps(value) if isinstance(value, (list, tuple)) else str(value)
    return flat


def effective_classifier_params(name: str, params: dict | None) -> dict:
    """Config params completed with the registered defaults, i.e. what train fitted with."""
    if name in classifiers.CLASSIFIERS:
        return classifiers.classifier_params(name, params)
    return dict(params or {})


def model_directories(paths) -> dict[tuple[str, str], Path]:
    """(classifier, protocol) -> train/<classifier>/<protocol>/models directory."""
    directories = {}
    for path in map(Path, paths):
        if not path.is_dir():
            raise TrackingError(f"{path}: no such model directory")
        directories[(path.parent.parent.name, path.parent.name)] = path
    return directories


MODEL_FILE = re.compile(r"p(\d+)_r(\d+)(?:_h(\d+))?\.joblib")


def model_files(models_dir: Path, holdouts) -> dict[tuple[int, int, str], Path]:
    """(measured_percent, repeat, holdout) -> model file of one train/<clf>/<protocol>/models.

    Files are named p<percent>_r<repeat>[_h<holdout index>].joblib (percent may be
    zero-padded); the index counts the protocol's real holdouts in the order of
    condmon.hybrid.sorted_holdouts, which is how the train stage names them.
    """
    by_index = [h for h in sorted_holdouts(holdouts) if h]
    files = {}
    for path in sorted(models_dir.glob("*.joblib")):
        match = MODEL_FILE.fullmatch(path.name)
        if match is None:
            raise TrackingError(f"{path}: unexpected model file name")
        percent, repeat, index = match.groups()
        if index is None:
            holdout = ""
        elif int(index) < len(by_index):
            holdout = by_index[int(index)]
        else:
            raise TrackingError(f"{path}: holdout index {index} but the metrics list only "
                                f"{by_index}")
        files[(int(percent), int(repeat), holdout)] = path
    return files


def feature_example(path, n_rows: int = 2):
    """The first rows of a features table as a DataFrame of its feature columns (float32)."""
    path = Path(path)
    if not path.exists():
        raise TrackingError(f"{path}: no such features table")
    parquet = pq.ParquetFile(path)
    meta = parquet.schema_arrow.metadata or {}
    if FEATURE_NAMES_KEY not in meta:
        raise TrackingError(f"{path}: no {FEATURE_NAMES_KEY.decode()} metadata; not a features "
                            "table")
    names = json.loads(meta[FEATURE_NAMES_KEY])
    batch = next(parquet.iter_batches(batch_size=n_rows, columns=names), None)
    if batch is None:
        raise TrackingError(f"{path}: features table has no rows")
    return batch.to_pandas().astype(np.float32)


def model_input_example(model, features):
    """Input example in the form the model was fitted on: named DataFrame or bare array."""
    names = getattr(model, "feature_names_in_", None)
    if names is not None:
        missing = [n for n in names if n not in features.columns]
        if missing:
            raise TrackingError(f"model expects feature columns missing from the features "
                                f"table, e.g. {missing[:3]}")
        return features[list(names)]
    n_in = getattr(model, "n_features_in_", features.shape[1])
    if n_in != features.shape[1]:
        raise TrackingError(f"model expects {n_in} features, the features table has "
                            f"{features.shape[1]}")
    return features.to_numpy()


def skops_types_to_trust(model) -> list[str]:
    """Types of ``model`` that skops does not trust by default (KD-trees of k-NN, say).

    MLflow stores sklearn models in the skops format, which refuses unlisted types on load.
    The models are this pipeline's own outputs, so their types are trusted explicitly; the
    list is stored with the model, and loading still rejects anything else.
    """
    import skops.io

    return skops.io.get_untrusted_types(data=skops.io.dumps(model))


@functools.cache
def pip_requirements(extra: tuple[str, ...] = ()) -> tuple[str, ...]:
    """Pinned requirements for logged models; given explicitly because MLflow's inference
    runs a subprocess per model (about 4-5 s each). ``extra``: e.g. ("torch",) for the CNN."""
    pins = []
    for name in ("mlflow", "scikit-learn", "numpy", "scipy", "pandas", "skops", *extra):
        try:
            pins.append(f"{name}=={metadata.version(name)}")
        except metadata.PackageNotFoundError:
            pass
    return tuple(pins)


# --------------------------------------------------------------------------- logging

def evaluation_runs(metrics):
    """Yield (key dict, all-speeds row, per-speed rows) per evaluation of the metrics table."""
    keys = ["classifier", "protocol", "measured_percent", "repeat", "holdout"]
    for values, rows in metrics.groupby(keys, sort=True):
        key = dict(zip(keys, values))
        overall = rows[rows["speed_rpm"].isna()]
        if len(overall) != 1:
            raise TrackingError(f"metrics for {key} need exactly one all-speeds row (empty "
                                f"speed_rpm), found {len(overall)}")
        yield key, overall.iloc[0], rows[rows["speed_rpm"].notna()]


def run_metrics(overall, speed_rows) -> dict[str, float]:
    values = {"accuracy": overall["accuracy"], "macro_f1": overall["macro_f1"]}
    if "fit_seconds" in overall and np.isfinite(overall["fit_seconds"]):
        values["fit_seconds"] = overall["fit_seconds"]
    for row in speed_rows.itertuples(index=False):
        speed = format_speed(row.speed_rpm)
        values[f"accuracy_{speed}rpm"] = row.accuracy
        values[f"macro_f1_{speed}rpm"] = row.macro_f1
    return {name: float(value) for name, value in values.items()}


HISTORY_FILE = "history.parquet"  # in train/<classifier>/<protocol>/models/ (CNN only)
CURVES = ("train_loss", "train_accuracy", "val_loss", "val_accuracy")


def read_histories(directories: dict) -> dict:
    """(classifier, protocol, percent, repeat, holdout) -> per member/epoch training history,
    from the models directories that have a history file (classifiers trained by epochs)."""
    histories = {}
    for (clf, protocol), directory in directories.items():
        path = Path(directory) / HISTORY_FILE
        if not path.exists():
            continue
        frame = pq.read_table(path).to_pandas()
        missing = [c for c in ("measured_percent", "repeat", "holdout", "member", "epoch", *CURVES)
                   if c not in frame.columns]
        if missing:
            raise TrackingError(f"{path}: training history lacks columns {missing}")
        frame["holdout"] = frame["holdout"].fillna("")
        for (percent, repeat, holdout), rows in frame.groupby(
                ["measured_percent", "repeat", "holdout"]):
            histories[(clf, protocol, int(percent), int(repeat), holdout)] = rows
    return histories


def curve_metrics(history, timestamp_ms: int) -> list:
    """MLflow Metric entities for the training curves: per member and the mean over the members
    that ran an epoch, step = epoch (NaN values, e.g. without a validation split, are left out)."""
    from mlflow.entities import Metric

    metrics = []
    for row in history.itertuples(index=False):
        for name in CURVES:
            value = float(getattr(row, name))
            if np.isfinite(value):
                metrics.append(Metric(f"member{int(row.member)}_{name}", value, timestamp_ms,
                                      int(row.epoch)))
    means = history.groupby("epoch")[list(CURVES)].mean()
    for epoch, row in means.iterrows():
        for name in CURVES:
            if np.isfinite(row[name]):
                metrics.append(Metric(name, float(row[name]), timestamp_ms, int(epoch)))
    return metrics


def confusion_csv(counts, labels) -> str:
    lines = ["true\\predicted," + ",".join(labels)]
    lines += [label + "," + ",".join(str(c) for c in row) for label, row in zip(labels, counts)]
    return "\n".join(lines) + "\n"


def supersede_earlier_runs(client, experiment_id: str, config_hash: str,
                           new_parent_id: str) -> list[str]:
    """Tag earlier current runs with the same config hash as superseded; returns their ids."""
    from mlflow.entities import ViewType

    earlier = client.search_runs(
        [experiment_id],
        filter_string=f"tags.config_hash = '{config_hash}' and tags.superseded = 'false'",
        run_view_type=ViewType.ALL, max_results=50000)
    superseded = []
    for run in earlier:
        if new_parent_id in (run.info.run_id, run.data.tags.get("mlflow.parentRunId")):
            continue
        client.set_tag(run.info.run_id, "superseded", "true")
        client.set_tag(run.info.run_id, "superseded_by", new_parent_id)
        superseded.append(run.info.run_id)
    return superseded


def log_pipeline_run(tracking_uri: str, run_name: str, config_hash: str, data_source: str,
                     classifier_params: dict, metrics_paths, predictions_paths, model_dirs,
                     features_measured, features_simulated=None, models: str = "all",
                     workdir=".", healthy_state: str | None = None) -> dict:
    """Log one pipeline invocation (see module docstring); returns the run_info dict.

    ``models``: "all" logs every fitted pipeline, "first_repeat" only repeat 0 of each
    (classifier, protocol, percent, holdout), "none" none; recorded in tag ``models_logged``.
    All inputs are checked before the first MLflow call, so a bad input leaves no failed run.
    """
    if models not in MODEL_POLICIES:
        raise ValueError(f"models={models!r}; expected one of {MODEL_POLICIES}")
    started = time.perf_counter()
    uri = resolve_tracking_uri(tracking_uri, workdir)
    check_tracking_server(uri)

    metrics = report.load_metrics(metrics_paths, extra_columns=("fit_seconds",))
    predictions = report.load_predictions(predictions_paths)
    labels = report.label_order([*predictions["true_label"], *predictions["predicted_label"]], healthy_state)
    unknown = sorted(set(metrics["classifier"]) - set(classifier_params))
    if unknown:
        raise TrackingError(f"classifier_params has no entry for {unknown} "
                            f"(it has {sorted(classifier_params)})")
    directories = model_directories(model_dirs)
    files = {}
    for (clf, protocol), rows in metrics.groupby(["classifier", "protocol"]):
        if (clf, protocol) not in directories:
            raise TrackingError(f"no model directory given for classifier {clf!r} protocol "
                                f"{protocol!r} (given: {sorted(map(str, directories.values()))})")
        files[(clf, protocol)] = model_files(directories[(clf, protocol)], rows["holdout"])
    histories = read_histories(directories)
    features = feature_example(features_measured)
    if features_simulated is not None and not Path(features_simulated).exists():
        raise TrackingError(f"{features_simulated}: no such features table")
    keys = ["classifier", "protocol", "measured_percent", "repeat", "holdout"]
    predictions_by_key = {key: rows for key, rows in predictions.groupby(keys)}

    import mlflow

    mlflow.set_tracking_uri(uri)
    client = mlflow.MlflowClient(uri)
    experiment_id = get_or_create_experiment(client, uri, run_name)
    commit, dirty = git_state(workdir)
    parent_tags = {"git_commit": commit, "git_dirty": dirty, "config_hash": config_hash,
                   "snakemake_run_name": run_name, "data_source": data_source,
                   "data_source_synthetic": str(report.is_synthetic(data_source)).lower(),
                   "models_logged": models, "superseded": "false"}
    model_seconds = []
    with mlflow.start_run(experiment_id=experiment_id, run_name=f"{run_name}-{config_hash[:8]}",
                          tags=parent_tags) as parent:
        mlflow.log_text(metrics.to_csv(index=False), "accuracy.csv")
        # models take a bare float32 array, so the signature has no names: keep them here
        mlflow.log_dict({"feature_names": list(features.columns)}, "feature_names.json")
        runs = list(evaluation_runs(metrics))
        for key, overall, speed_rows in runs:
            chosen = predictions_by_key.get(tuple(key[k] for k in keys))
            if chosen is None:
                raise TrackingError(f"no predictions for {key} although metrics.csv has it")
            counts = report.confusion_counts(chosen["true_label"], chosen["predicted_label"],
                                             labels)
            model_path = None
            if models == "all" or (models == "first_repeat" and key["repeat"] == 0):
                model_path = files[(key["classifier"], key["protocol"])].get(
                    (key["measured_percent"], key["repeat"], key["holdout"]))
                if model_path is None:
                    raise TrackingError(f"{directories[(key['classifier'], key['protocol'])]}: "
                                        f"no model file for {key}")
            seconds = log_evaluation(experiment_id, key, overall, speed_rows, counts, labels,
                                     classifier_params[key["classifier"]], config_hash,
                                     data_source, model_path, features,
                                     history=histories.get(tuple(key[k] for k in keys)),
                                     uncertainty=chosen.get("uncertainty"))
            if seconds is not None:
                model_seconds.append(seconds)
        mlflow.set_tag("n_nested_runs", str(len(runs)))
        parent_id = parent.info.run_id
    superseded = supersede_earlier_runs(client, experiment_id, config_hash, parent_id)
    elapsed = time.perf_counter() - started
    log.info("logged %d nested runs under %s in %.1f s (model logging %.2f s each on average); "
             "superseded %d earlier runs", len(runs), parent_id, elapsed,
             float(np.mean(model_seconds)) if model_seconds else 0.0, len(superseded))
    return {"parent_run_id": parent_id, "experiment_id": experiment_id,
            "experiment_name": run_name, "tracking_uri": uri,
            "tracking_uri_configured": tracking_uri, "n_nested_runs": len(runs),
            "models_logged": models, "n_models_logged": len(model_seconds),
            "superseded_run_ids": superseded, "seconds": round(elapsed, 2)}


def log_evaluation(experiment_id: str, key: dict, overall, speed_rows, counts, labels,
                   classifier_params: dict | None, config_hash: str, data_source: str,
                   model_path: Path | None, features, history=None,
                   uncertainty=None) -> float | None:
    """One nested run under the active parent; returns the seconds spent logging the model.

    ``history``: per member/epoch training curves (CNN); ``uncertainty``: the per-prediction
    member spread of the test predictions (NaN for classifiers without one).
    """
    import joblib
    import mlflow
    import mlflow.sklearn
    from mlflow.models import infer_signature

    clf, protocol = key["classifier"], key["protocol"]
    name = f"{clf}/{protocol}/p{key['measured_percent']}/r{key['repeat']}"
    name += f"/{key['holdout']}" if key["holdout"] else ""
    tags = {"classifier": clf, "protocol": protocol,
            "measured_percent": str(key["measured_percent"]), "repeat": str(key["repeat"]),
            "holdout": key["holdout"], "config_hash": config_hash, "superseded": "false",
            "leaky": str(protocol in LEAKY_PROTOCOLS).lower()}
    params = {"classifier": clf, "protocol": protocol,
              "measured_percent": key["measured_percent"], "repeat": key["repeat"],
              "holdout": key["holdout"] or "none",
              "n_train_simulated": overall["n_train_simulated"],
              "n_train_measured": overall["n_train_measured"], "n_test": overall["n_test"],
              **flatten_params(effective_classifier_params(clf, classifier_params), "classifier")}
    with mlflow.start_run(experiment_id=experiment_id, run_name=name, nested=True,
                          tags=tags) as run:
        mlflow.log_params(params)
        values = run_metrics(overall, speed_rows)
        if uncertainty is not None and np.isfinite(uncertainty.to_numpy(float)).any():
            values["uncertainty_mean"] = float(np.nanmean(uncertainty.to_numpy(float)))
        if history is not None and len(history):
            values["epochs_run_mean"] = float(history.groupby("member")["epoch"].max().mean())
            curves = curve_metrics(history, int(time.time() * 1000))
            client = mlflow.MlflowClient()
            for start in range(0, len(curves), 1000):  # MLflow's limit per batch
                client.log_batch(run.info.run_id, metrics=curves[start:start + 1000])
        mlflow.log_metrics(values)
        mlflow.log_text(confusion_csv(counts, labels), "confusion_matrix.csv")
        figure = plots.confusion_matrix_small(
            counts, labels, f"Confusion matrix (share of true class, count)\n{name}"
            + (" (LEAKY protocol)" if protocol in LEAKY_PROTOCOLS else ""),
            f"Data: {report.data_source_label(data_source)}")
        mlflow.log_figure(figure, "confusion_matrix.png")
        plots.plt.close(figure)
        if model_path is None:
            return None
        started = time.perf_counter()
        model = joblib.load(model_path)
        example = model_input_example(model, features)
        if hasattr(model, "to_torch_module"):
            log_torch_model(model, example)
            return time.perf_counter() - started
        mlflow.sklearn.log_model(
            model, name="model", input_example=example,
            signature=infer_signature(example, model.predict(example)),
            pip_requirements=list(pip_requirements()),
            skops_trusted_types=skops_types_to_trust(model))
        return time.perf_counter() - started


def log_torch_model(model, example) -> None:
    """The CNN ensemble as an MLflow PyTorch model: float32 features (N, F) in, mean class
    probabilities (N, K) out; the class of each column goes to ``model_classes.json``."""
    import mlflow
    import mlflow.pytorch
    import torch
    from mlflow.models import infer_signature

    module = model.to_torch_module()
    example = np.array(example, dtype=np.float32)  # a writable copy: torch wants one
    with torch.no_grad():
        probabilities = module(torch.from_numpy(example)).numpy()
    mlflow.pytorch.log_model(module, name="model", input_example=example,
                             signature=infer_signature(example, probabilities),
                             pip_requirements=list(pip_requirements(("torch",))))
    mlflow.log_dict({"classes": module.classes}, "model_classes.json")


def write_run_info(info: dict, path) -> None:
    write_json(info, path)

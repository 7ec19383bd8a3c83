"""MLflow tracking of one pipeline invocation, logged by the single `track` job after training.

- experiment = run name; a SQLite store keeps the artifacts beside it (``mlartifacts/<name>``) and
  is switched to write-ahead logging on a local disk;
- one parent run per invocation: tags ``git_commit``, ``git_dirty``, ``config_hash``,
  ``snakemake_run_name``, ``data_source``, ``data_source_synthetic``, ``models_logged``,
  ``n_nested_runs``; params: the config flattened (``classifiers.svm.C``); inputs: the signal and
  feature tables as datasets (digest: SHA-256 of the files); metrics
  ``accuracy.<classifier>.<protocol>.p<percent>`` (mean over repeats, held-out conditions averaged
  first), for the compare view; artifact ``accuracy.csv``;
- one nested run per classifier x protocol x measured percentage x repeat (x held-out condition):
  those keys as tags and params, with ``leaky``, ``config_hash`` and ``model_file`` (the model
  that the train job's info.json lists); params: training and test sizes and ``classifier.<name>``
  (the fitted settings, from info.json); metrics: ``accuracy``, ``macro_f1``, per speed
  (``accuracy_<speed>rpm``), ``fit_seconds``; for the CNN ensemble ``uncertainty_mean``,
  ``epochs_run_mean`` and the members' mean training curves with step = epoch (``train_loss``,
  ``val_accuracy``, ...; every member's in the artifact ``training_history.csv``: a SQL store
  writes about 0.1 ms per metric point, and the default run's members have 26000);
  artifact ``confusion_matrix.csv``. One create, one log_batch (MLflow splits it) and one
  terminate each;
- the models ``tracking.log_models`` picks (see ``wants_model``) as LoggedModels of their nested
  run, with a signature, the run's metrics linked to them (``model_id``, on the measured features).

Older runs are never rewritten: a rerun logs a new parent, and queries keep the newest finished
parent per config hash (``condmon.compare``). A remote server (http/https) is probed first and
MLflow's HTTP retries are capped, so a server that is down, or dies mid-way, fails the job in
seconds naming its URI; the parent it leaves unfinished never counts.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import logging
import os
import re
import sqlite3
import subprocess
import time
import urllib.error
import urllib.request
from importlib import metadata
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from condmon import report
from condmon.atomic import write_json
from condmon.hybrid import LEAKY_PROTOCOLS, format_speed

log = logging.getLogger(__name__)

DEFAULT_TRACKING_URI = "sqlite:///results/mlflow.db"
SQLITE = "sqlite:///"
MODEL_POLICIES = ("all", "first_repeat", "none")  # or a filter {key: [values]}, see wants_model
KEYS = ["classifier", "protocol", "measured_percent", "repeat", "holdout"]
CURVES = ("train_loss", "train_accuracy", "val_loss", "val_accuracy")
HISTORY_FILE = "history.parquet"  # beside the models of a classifier trained by epochs (CNN)
# Fail fast against a dead server instead of MLflow's default minutes of retries; the environment
# can still override these.
HTTP_ENV_DEFAULTS = {"MLFLOW_HTTP_REQUEST_MAX_RETRIES": "1",
                     "MLFLOW_HTTP_REQUEST_BACKOFF_FACTOR": "1",
                     "MLFLOW_HTTP_REQUEST_TIMEOUT": "30"}
PROBE_TIMEOUT_S = 5.0


class TrackingError(RuntimeError):
    """The tracking store is unusable or the inputs to log are inconsistent."""


# --------------------------------------------------------------------------- tracking store

def resolve_tracking_uri(uri: str, workdir=".") -> str:
    """Make a relative SQLite path absolute (relative to ``workdir``) and create its directory."""
    if not uri.startswith(SQLITE):
        return uri
    path = Path(uri[len(SQLITE):])
    if not path.is_absolute():
        path = (Path(workdir) / path).resolve()
    path.parent.mkdir(parents=True, exist_ok=True)
    return f"{SQLITE}{path}"


def is_remote(uri: str) -> bool:
    return urlparse(uri).scheme in ("http", "https")


def check_tracking_server(uri: str, timeout_s: float = PROBE_TIMEOUT_S) -> None:
    """Raise TrackingError naming ``uri`` if an http(s) tracking server does not answer within
    ``timeout_s`` (refused, unknown host, no answer, or a 502/503/504 from a proxy in front of
    it); any other HTTP answer counts as reachable. Also caps MLflow's HTTP retries
    (HTTP_ENV_DEFAULTS) for the rest of the process."""
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
    raise TrackingError(f"MLflow tracking server {uri} is unreachable ({reason}). Start the server "
                        f"or set the tracking URI to a reachable one (e.g. {DEFAULT_TRACKING_URI})")


def _sync_at_checkpoints(connection, _record) -> None:
    if isinstance(connection, sqlite3.Connection):
        connection.execute("PRAGMA synchronous=NORMAL")


def use_write_ahead_log(uri: str) -> None:
    """A SQLite store on a local disk: write-ahead logging (kept in the file), commits synced at
    checkpoints only; a few ms per commit instead of tens, never corrupt (a power cut may lose the
    last commits, i.e. an unfinished parent, which a rerun logs again). Network filesystems, where
    SQLite's write-ahead log does not work, keep the default journal."""
    if not uri.startswith(SQLITE):
        return
    path = Path(uri[len(SQLITE):])
    with contextlib.suppress(OSError):  # /proc/mounts: Linux; elsewhere assume a local disk
        mounts = [line.split()[1:3] for line in Path("/proc/mounts").read_text().splitlines()]
        folder = str(path.parent.resolve())
        fstype = max(((m, t) for m, t in mounts if folder == m or folder.startswith(m.rstrip("/") + "/")),
                     key=lambda mount: len(mount[0]), default=("", ""))[1]
        if re.match(r"(nfs|cifs|smb|lustre|gpfs|beegfs|ceph|gluster|fuse)", fstype):
            return
    with contextlib.closing(sqlite3.connect(path, timeout=30)) as db:
        db.execute("PRAGMA journal_mode=WAL")
    from sqlalchemy import event
    from sqlalchemy.engine import Engine

    if not event.contains(Engine, "connect", _sync_at_checkpoints):
        event.listen(Engine, "connect", _sync_at_checkpoints)


def get_or_create_experiment(client, uri: str, name: str) -> str:
    from mlflow.exceptions import MlflowException

    experiment = client.get_experiment_by_name(name)
    if experiment is None:
        location = None  # a server picks its own artifact root
        if uri.startswith(SQLITE):
            location = (Path(uri[len(SQLITE):]).parent / "mlartifacts" / name).as_uri()
        try:
            return client.create_experiment(name, artifact_location=location)
        except MlflowException as exc:  # created meanwhile by another pipeline logging at once
            if exc.error_code != "RESOURCE_ALREADY_EXISTS":
                raise
            experiment = client.get_experiment_by_name(name)
    if experiment.lifecycle_stage == "deleted":  # still owns the name: bring it back
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


def flatten_params(params: dict, prefix: str = "") -> dict[str, str]:
    """{"a": {"b": 1}} -> {"<prefix>.a.b": "1"}; lists as JSON."""
    flat = {}
    for key, value in params.items():
        name = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, dict):
            flat.update(flatten_params(value, name))
        else:
            flat[name] = json.dumps(value) if isinstance(value, (list, tuple)) else str(value)
    return flat


def file_dataset(name: str, paths):
    """An MLflow dataset for files of this run (a table, or a table split into batches): digest =
    SHA-256 of their bytes, source = the file or their common folder."""
    from mlflow.data.meta_dataset import MetaDataset
    from mlflow.data.sources import LocalArtifactDatasetSource

    paths = sorted(Path(p).resolve() for p in paths)
    missing = [str(p) for p in paths if not p.is_file()]
    if not paths or missing:
        raise TrackingError(f"dataset {name}: no such file {missing or '(none given)'}")
    digest = hashlib.sha256()
    for path in paths:
        with path.open("rb") as file:
            digest.update(hashlib.file_digest(file, "sha256").digest())
    profile = {"files": len(paths), "rows": sum(pq.ParquetFile(p).metadata.num_rows for p in paths),
               "bytes": sum(p.stat().st_size for p in paths)}
    source = paths[0] if len(paths) == 1 else Path(os.path.commonpath(paths))

    class FileDataset(MetaDataset):
        def to_dict(self):
            return {**super().to_dict(), "profile": json.dumps(profile)}

    return FileDataset(LocalArtifactDatasetSource(str(source)), name=name,
                       digest=digest.hexdigest()[:16])


def read_train_outputs(train_dirs) -> tuple[pd.DataFrame, pd.DataFrame, dict, dict, dict]:
    """metrics, predictions, {classifier: params it was fitted with}, {run key: model file} (from
    each train/<classifier>/<protocol>/info.json) and {run key: training history} (CNN)."""
    dirs = [Path(d) for d in train_dirs]
    if missing := [str(d / "info.json") for d in dirs if not (d / "info.json").is_file()]:
        raise TrackingError(f"no such train output: {missing}")
    metrics = report.load_metrics([d / "metrics.csv" for d in dirs], extra_columns=("fit_seconds",))
    predictions = report.load_predictions([d / "predictions.parquet" for d in dirs])
    params, files, histories = {}, {}, {}
    for d in dirs:
        info = json.loads((d / "info.json").read_text())
        clf, protocol = info["classifier"], info["protocol"]
        params[clf] = info.get("classifier_params") or {}
        for entry in info["models"]:
            files[(clf, protocol, int(entry["measured_percent"]), int(entry["repeat"]),
                   entry["holdout"] or "")] = d / "models" / entry["file"]
        if (d / "models" / HISTORY_FILE).exists():
            history = pd.read_parquet(d / "models" / HISTORY_FILE)
            history["holdout"] = history["holdout"].fillna("")
            for (percent, repeat, holdout), rows in history.groupby(
                    ["measured_percent", "repeat", "holdout"]):
                histories[(clf, protocol, int(percent), int(repeat), holdout)] = rows
    return metrics, predictions, params, files, histories


def feature_example(path, n_rows: int = 2) -> pd.DataFrame:
    """The first rows of a features table's feature columns (float32): the models' signatures."""
    parquet = pq.ParquetFile(path)
    names = json.loads((parquet.schema_arrow.metadata or {}).get(b"condmon.feature_names", b"null"))
    if not names:
        raise TrackingError(f"{path}: no condmon.feature_names metadata; not a features table")
    return next(parquet.iter_batches(batch_size=n_rows, columns=names)).to_pandas().astype(np.float32)


def wants_model(policy, key: dict) -> bool:
    """``tracking.log_models``: "all", "first_repeat" (repeat 0 of every setting), "none", or a
    filter {classifier/protocol/measured_percent/repeat: [values]} (a key left out matches all)."""
    if isinstance(policy, dict):
        return all(key[name] in values for name, values in policy.items())
    return policy == "all" or (policy == "first_repeat" and key["repeat"] == 0)


@functools.cache
def pip_requirements(*extra: str) -> list[str]:
    """Pinned requirements of logged models: given, as MLflow would infer them in a subprocess
    per model (seconds each)."""
    names = ("mlflow", "scikit-learn", "numpy", "scipy", "pandas", "skops", *extra)
    return [f"{n}=={metadata.version(n)}" for n in names]


# --------------------------------------------------------------------------- logging

def summary_metrics(metrics: pd.DataFrame) -> dict[str, float]:
    """accuracy.<classifier>.<protocol>.p<percent>: mean over repeats of the held-out mean."""
    overall = metrics[metrics["speed_rpm"].isna()]
    per_repeat = overall.groupby(KEYS[:4])["accuracy"].mean()
    means = per_repeat.groupby(level=[0, 1, 2]).mean()
    return {f"accuracy.{c}.{p}.p{int(percent):03d}": float(v) for (c, p, percent), v in means.items()}


def run_metrics(rows: pd.DataFrame, predictions: pd.DataFrame, history) -> dict[str, float]:
    overall = rows[rows["speed_rpm"].isna()].iloc[0]
    values = {"accuracy": overall["accuracy"], "macro_f1": overall["macro_f1"]}
    if np.isfinite(overall.get("fit_seconds", np.nan)):
        values["fit_seconds"] = overall["fit_seconds"]
    for row in rows[rows["speed_rpm"].notna()].itertuples():
        values[f"accuracy_{format_speed(row.speed_rpm)}rpm"] = row.accuracy
        values[f"macro_f1_{format_speed(row.speed_rpm)}rpm"] = row.macro_f1
    uncertainty = predictions["uncertainty"].to_numpy(float)
    if np.isfinite(uncertainty).any():
        values["uncertainty_mean"] = np.nanmean(uncertainty)
    if history is not None:
        values["epochs_run_mean"] = history.groupby("member")["epoch"].max().mean()
    return {name: float(value) for name, value in values.items()}


def curves(history) -> list[tuple[str, float, int]]:
    """(name, value, epoch) of the members' mean training curves (a member that stopped early
    counts until its last epoch)."""
    means = history.groupby("epoch")[list(CURVES)].mean()
    points = [(name, float(row[name]), int(epoch)) for epoch, row in means.iterrows() for name in CURVES]
    return [point for point in points if np.isfinite(point[1])]


def confusion_csv(predictions: pd.DataFrame, labels) -> str:
    counts = report.confusion_counts(predictions["true_label"], predictions["predicted_label"], labels)
    return pd.DataFrame(counts, labels, labels).rename_axis("true\\predicted").to_csv()


def log_pipeline_run(tracking_uri: str, run_name: str, config_hash: str, data_source: str,
                     train_dirs, datasets: dict, config: dict | None = None, log_models="all",
                     healthy_state: str | None = None, workdir=".") -> dict:
    """Log one pipeline invocation (see module docstring); returns the run_info dict.

    ``train_dirs``: the train/<classifier>/<protocol> folders; ``datasets``: name -> files, with
    ``measured_features`` among them (the models' signatures); ``log_models``: see wants_model.
    Every input is read and checked before the first MLflow call.
    """
    if not isinstance(log_models, dict) and log_models not in MODEL_POLICIES:
        raise ValueError(f"log_models={log_models!r}; expected one of {MODEL_POLICIES} or a filter")
    started = time.perf_counter()
    uri = resolve_tracking_uri(tracking_uri, workdir)
    check_tracking_server(uri)
    metrics, predictions, clf_params, files, histories = read_train_outputs(train_dirs)
    inputs = {name: file_dataset(name, paths) for name, paths in datasets.items()}
    example = feature_example(datasets["measured_features"][0])
    labels = report.label_order([*predictions["true_label"], *predictions["predicted_label"]],
                                healthy_state)
    predictions_by_key = dict(list(predictions.groupby(KEYS)))
    runs = []
    for values, rows in metrics.groupby(KEYS):
        key = dict(zip(KEYS, values))
        if rows["speed_rpm"].isna().sum() != 1:
            raise TrackingError(f"metrics for {key} need exactly one all-speeds row (empty "
                                f"speed_rpm), found {rows['speed_rpm'].isna().sum()}")
        if values not in predictions_by_key or values not in files:
            raise TrackingError(f"{key}: in metrics.csv but without "
                                f"{'predictions' if values in files else 'a model in info.json'}")
        runs.append((key, rows))

    import mlflow

    use_write_ahead_log(uri)
    mlflow.set_tracking_uri(uri)
    client = mlflow.MlflowClient(uri)
    commit, dirty = git_state(workdir)
    tags = {"git_commit": commit, "git_dirty": dirty, "config_hash": config_hash,
            "snakemake_run_name": run_name, "data_source": data_source,
            "data_source_synthetic": str(report.is_synthetic(data_source)).lower(),
            "models_logged": json.dumps(log_models), "n_nested_runs": str(len(runs))}
    measured = inputs["measured_features"]
    model_ids, parent_id = [], None
    try:
        experiment_id = get_or_create_experiment(client, uri, run_name)
        parent_id = mlflow.start_run(experiment_id=experiment_id, tags=tags,
                                     run_name=f"{run_name}-{config_hash[:8]}").info.run_id
        mlflow.log_inputs(list(inputs.values()), contexts=[
            "training" if name.startswith("simulated") else "training_and_test" for name in inputs],
            tags_list=[None] * len(inputs))
        mlflow.log_params(flatten_params(config or {}))
        mlflow.log_metrics(summary_metrics(metrics))
        mlflow.log_text(metrics.to_csv(index=False), "accuracy.csv")
        for key, rows in runs:
            values = tuple(key.values())
            model_id = log_nested_run(client, experiment_id, parent_id, key, rows,
                                      predictions_by_key[values], clf_params.get(key["classifier"], {}),
                                      config_hash, labels, files[values], histories.get(values),
                                      measured, example if wants_model(log_models, key) else None)
            model_ids += [model_id] if model_id else []
        mlflow.end_run()
    except Exception as exc:
        with contextlib.suppress(Exception):  # the server may be gone: best effort
            mlflow.end_run("FAILED")
        if is_remote(uri) and not isinstance(exc, TrackingError):
            raise TrackingError(
                f"MLflow tracking server {uri} failed while logging parent run {parent_id} "
                f"({type(exc).__name__}: {str(exc)[:300]}). That run stays unfinished and is never "
                "counted; rerun the track job once the server answers") from exc
        raise
    elapsed = time.perf_counter() - started
    log.info("logged %d nested runs and %d models under %s in %.1f s", len(runs), len(model_ids),
             parent_id, elapsed)
    return {"parent_run_id": parent_id, "experiment_id": experiment_id,
            "experiment_name": run_name, "tracking_uri": uri, "tracking_uri_configured": tracking_uri,
            "n_nested_runs": len(runs), "models_logged": log_models, "n_models_logged": len(model_ids),
            "datasets": {name: dataset.digest for name, dataset in inputs.items()},
            "seconds": round(elapsed, 2)}


def log_nested_run(client, experiment_id: str, parent_id: str, key: dict, rows, predictions,
                   clf_params: dict, config_hash: str, labels, model_file: Path, history, dataset,
                   example) -> str | None:
    """One nested run; logs its model when ``example`` (rows for its signature) is given. Returns the
    LoggedModel's id, or None."""
    from mlflow.entities import Metric, Param

    clf, protocol = key["classifier"], key["protocol"]
    name = f"{clf}/{protocol}/p{key['measured_percent']}/r{key['repeat']}"
    name += f"/{key['holdout']}" if key["holdout"] else ""
    tags = {**{k: str(v) for k, v in key.items()}, "config_hash": config_hash,
            "leaky": str(protocol in LEAKY_PROTOCOLS).lower(), "model_file": str(model_file.resolve()),
            "mlflow.parentRunId": parent_id}
    overall = rows[rows["speed_rpm"].isna()].iloc[0]
    params = {**{k: str(v) for k, v in key.items()}, "holdout": key["holdout"] or "none",
              **{k: str(overall[k]) for k in ("n_train_simulated", "n_train_measured", "n_test")},
              **flatten_params(clf_params, "classifier")}
    run_id = client.create_run(experiment_id, run_name=name, tags=tags).info.run_id
    model_id = None
    if example is not None:
        model_id = log_model(model_file, example, run_id, re.sub(r"[^\w-]+", "-", name), params,
                             {k: v for k, v in tags.items() if not k.startswith("mlflow.")})
    now = int(time.time() * 1000)
    points = [Metric(k, v, now, 0, dataset_name=dataset.name, dataset_digest=dataset.digest,
                     model_id=model_id) for k, v in run_metrics(rows, predictions, history).items()]
    if history is not None:  # the members' mean curves; every member's in an artifact
        points += [Metric(k, v, now, step, model_id=model_id) for k, v, step in curves(history)]
        client.log_text(run_id, history[["member", "epoch", *CURVES]].to_csv(index=False),
                        "training_history.csv")
    client.log_batch(run_id, metrics=points, params=[Param(k, v) for k, v in params.items()])
    client.log_text(run_id, confusion_csv(predictions, labels), "confusion_matrix.csv")
    client.set_terminated(run_id)
    return model_id


def log_model(path: Path, features: pd.DataFrame, run_id: str, name: str, params: dict,
              tags: dict) -> str:
    """The fitted model of ``path`` as a LoggedModel of ``run_id``, with a signature from the
    ``features`` rows (the scikit-learn ones without input example: MLflow would load and run
    each model to check it)."""
    import joblib
    import mlflow
    from mlflow.models import infer_signature

    model = joblib.load(path)
    common = dict(name=name, run_id=run_id, params=params, tags=tags)
    if hasattr(model, "to_torch_module"):  # the CNN ensemble: raw features -> probabilities
        import mlflow.pytorch
        import torch

        module = model.to_torch_module()
        example = features.to_numpy(np.float32).copy()
        with torch.no_grad():
            probabilities = module(torch.from_numpy(example)).numpy()
        # MLflow's default format for it (pt2, a traced graph) needs an input example
        info = mlflow.pytorch.log_model(module, input_example=example,
                                        signature=infer_signature(example, probabilities),
                                        pip_requirements=pip_requirements("torch"), **common)
        mlflow.MlflowClient().log_dict(run_id, {"classes": module.classes}, "model_classes.json")
        return info.model_id
    import mlflow.sklearn
    import skops.io

    names = getattr(model, "feature_names_in_", None)  # fitted on a named frame, or a bare array
    example = features[list(names)] if names is not None else features.to_numpy()
    info = mlflow.sklearn.log_model(
        model, signature=infer_signature(example, model.predict(example)),
        pip_requirements=pip_requirements(),
        # skops refuses types it does not trust on load (k-NN's KD-tree, say): these are the
        # pipeline's own outputs, so their types are listed with the model; others stay refused
        skops_trusted_types=skops.io.get_untrusted_types(data=skops.io.dumps(model)), **common)
    return info.model_id


def write_run_info(info: dict, path) -> None:
    write_json(info, path)

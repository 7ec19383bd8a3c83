"""MLflow tracking of one pipeline invocation, logged by the single `track` job after training.

- experiment = run name; a SQLite store keeps the artifacts beside it (``mlartifacts/<name>``) and
  is switched to write-ahead logging on a local disk;
- one parent run per invocation, named ``<run name> <UTC date and time>`` and, where the
  experiment's newest earlier parent had another config, the keys that differ from it
  (``parent_run_name``); tags ``git_commit``, ``git_dirty``, ``config_hash``,
  ``snakemake_run_name``, ``data_source``, ``data_source_synthetic``, ``models_logged``,
  ``n_nested_runs``; params: the config flattened (``classifiers.svm.C``); inputs: the signal and
  feature tables as datasets (digest: SHA-256 of the files); metrics
  ``accuracy.<classifier>.<protocol>.p<percent>`` (mean over repeats, held-out conditions averaged
  first), for the compare view; artifacts ``accuracy.csv`` and ``confusion_matrices.csv``;
- one nested run per classifier x protocol x measured percentage x repeat (x held-out condition):
  those keys as tags and params, with ``leaky``, ``config_hash`` and ``model_file`` (the model
  that the train job's info.json lists); params: training and test sizes and ``classifier.<name>``
  (the fitted settings, from info.json); metrics: ``accuracy``, ``macro_f1``, per speed
  (``accuracy_<speed>rpm``), ``fit_seconds``; for the CNN ensemble ``uncertainty_mean``,
  ``epochs_run_mean`` and the members' mean training curves with step = epoch (``train_loss``,
  ``val_accuracy``, ...; every member's in the artifact ``training_history.csv``: a SQL store
  writes about 0.1 ms per metric point, and the default run's members have 26000). One create,
  one log_batch (MLflow splits it) and one terminate each; their confusion matrices in the
  parent's ``confusion_matrices.csv``;
- the models ``tracking.log_models`` picks (see ``wants_model``) as LoggedModels of their nested
  run, with a signature, the run's metrics linked to them (``model_id``, on the measured features):
  the run's packaged SignalModels (its model store, ``condmon.model_store``) as pyfunc models that
  take a signal table; one whose digest the experiment already has is linked, not logged again;
  the store's best model is registered (``register_best``: ``condmon-<run>``, aliases ``best`` and
  ``config-<hash>``), the parent tagged ``best_model_id``;
- the report's plots as artifacts of the parent, by the `track_plots` job once the report is
  written (``log_run_artifacts``), so the `track` job runs beside the report.

Older runs are never rewritten: a rerun logs a new parent, and queries keep the newest finished
parent per config hash (``condmon.compare``). A remote server (http/https) is probed first and
MLflow's HTTP retries are capped, so a server that is down, or dies mid-way, fails the job in
seconds naming its URI; the parent it leaves unfinished never counts.
"""

from __future__ import annotations

import contextlib
import datetime
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
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from urllib.parse import urlparse

import numpy as np
import pandas as pd
import pyarrow.parquet as pq

from condmon.atomic import write_json
from condmon.labels import LEAKY_PROTOCOLS, format_speed, is_synthetic, label_order
from condmon.train_tables import load_metrics, load_predictions

log = logging.getLogger(__name__)

DEFAULT_TRACKING_URI = "sqlite:///results/mlflow.db"
SQLITE = "sqlite:///"
MODEL_POLICIES = ("all", "first_repeat", "none")  # or a filter {key: [values]}, see wants_model
KEYS = ["classifier", "protocol", "measured_percent", "repeat", "holdout"]
CURVES = ("train_loss", "train_accuracy", "val_loss", "val_accuracy")
HISTORY_FILE = "history.parquet"  # beside the models of a classifier trained by epochs (CNN)
# Fail fast against a dead server instead of MLflow's default minutes of retries; the environment
# can still override these.
HTTP_ENV_DEFAULTS = {
    "MLFLOW_HTTP_REQUEST_MAX_RETRIES": "1",
    "MLFLOW_HTTP_REQUEST_BACKOFF_FACTOR": "1",
    "MLFLOW_HTTP_REQUEST_TIMEOUT": "30",
}
# A dead server refuses at once; a busy one (a team's, several track jobs logging to it) may take
# seconds to answer its health check, so the probe waits as long as MLflow waits for a request.
PROBE_TIMEOUT_S = float(HTTP_ENV_DEFAULTS["MLFLOW_HTTP_REQUEST_TIMEOUT"])


class TrackingError(RuntimeError):
    """The tracking store is unusable or the inputs to log are inconsistent."""


# --------------------------------------------------------------------------- tracking store


def resolve_tracking_uri(uri: str, workdir=".") -> str:
    """Make a relative SQLite path absolute (relative to ``workdir``) and create its directory."""
    path = sqlite_path(uri, workdir)
    if path is None:
        return uri
    path.parent.mkdir(parents=True, exist_ok=True)
    return f"{SQLITE}{path}"


def existing_store(uri: str, workdir=".") -> str:
    """``uri`` to read from: a SQLite store made absolute, which must exist (MLflow would create
    an empty one, in the working folder, then say the model or experiment is not in it)."""
    path = sqlite_path(uri, workdir)
    if path is None:
        return uri
    if not path.is_file():
        raise TrackingError(f"no MLflow store at {path} ({uri}; a run's track job makes it)")
    return f"{SQLITE}{path}"


def sqlite_path(uri: str, workdir=".") -> Path | None:
    """The absolute file of a SQLite URI (relative to ``workdir``), None for another store."""
    if not uri.startswith(SQLITE):
        return None
    path = Path(uri[len(SQLITE) :])
    return path if path.is_absolute() else (Path(workdir) / path).resolve()


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
    raise TrackingError(
        f"MLflow tracking server {uri} is unreachable ({reason}). Start the server "
        f"or set the tracking URI to a reachable one (e.g. {DEFAULT_TRACKING_URI})"
    )


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
    path = Path(uri[len(SQLITE) :])
    with contextlib.suppress(OSError):  # /proc/mounts: Linux; elsewhere assume a local disk
        mounts = [line.split()[1:3] for line in Path("/proc/mounts").read_text().splitlines()]
        folder = str(path.parent.resolve())
        fstype = max(
            ((m, t) for m, t in mounts if folder == m or folder.startswith(m.rstrip("/") + "/")),
            key=lambda mount: len(mount[0]),
            default=("", ""),
        )[1]
        if re.match(r"(nfs|cifs|smb|lustre|gpfs|beegfs|ceph|gluster|fuse)", fstype):
            return
    with contextlib.closing(sqlite3.connect(path, timeout=30)) as db:
        db.execute("PRAGMA journal_mode=WAL")
    from sqlalchemy import event
    from sqlalchemy.engine import Engine

    if not event.contains(Engine, "connect", _sync_at_checkpoints):
        event.listen(Engine, "connect", _sync_at_checkpoints)


# The experiment type MLflow 3's UI reads (what its "Choose experiment type" sets): "Machine
# learning", so an experiment opens on its training runs, not on the GenAI overview.
EXPERIMENT_KIND = {"mlflow.experimentKind": "custom_model_development"}


def get_or_create_experiment(client, uri: str, name: str) -> str:
    from mlflow.exceptions import MlflowException

    experiment = client.get_experiment_by_name(name)
    if experiment is None:
        location = None  # a server picks its own artifact root
        if uri.startswith(SQLITE):
            location = (Path(uri[len(SQLITE) :]).parent / "mlartifacts" / name).as_uri()
        try:
            return client.create_experiment(name, artifact_location=location, tags=EXPERIMENT_KIND)
        except MlflowException as exc:  # created meanwhile by another pipeline logging at once
            if exc.error_code != "RESOURCE_ALREADY_EXISTS":
                raise
            experiment = client.get_experiment_by_name(name)
    if experiment.lifecycle_stage == "deleted":  # still owns the name: bring it back
        client.restore_experiment(experiment.experiment_id)
    for key, value in EXPERIMENT_KIND.items():  # an older experiment; a type a user chose stays
        if key not in experiment.tags:
            client.set_experiment_tag(experiment.experiment_id, key, value)
    return experiment.experiment_id


def log_inputs(inputs: dict, attempts: int = 3) -> None:
    """Log the datasets as the active run's inputs. Pipelines logging the same table (same name
    and digest) into one experiment at once race to insert it: the loser's insert fails on the
    store's unique constraint, and logging again finds the row the winner wrote."""
    import mlflow
    from mlflow.exceptions import MlflowException

    contexts = [
        "training" if name.startswith("simulated") else "training_and_test" for name in inputs
    ]
    for attempt in range(attempts):
        try:
            mlflow.log_inputs(
                list(inputs.values()), contexts=contexts, tags_list=[None] * len(inputs)
            )
            return
        except MlflowException as exc:
            message = str(exc).lower()
            duplicate = "datasets" in message and ("unique" in message or "duplicate" in message)
            if not duplicate or attempt == attempts - 1:
                raise
            log.info("dataset inserted meanwhile by another pipeline; logging the inputs again")
            time.sleep(0.2 * (attempt + 1))


# --------------------------------------------------------------------------- inputs


def git_state(cwd=".") -> tuple[str, str]:
    """(commit, dirty) of the working tree, ("unknown", "unknown") outside git."""
    try:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        status = subprocess.run(
            ["git", "status", "--porcelain"],
            cwd=cwd,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout
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


def changed_keys(params: dict, earlier: dict, shown: int = 3) -> str:
    """The config keys whose values differ from an `earlier` run's params, for a run's name:
    "classifiers.svm.C=3.0" (long values by key alone), at most `shown`, then "+N more"."""
    keys = sorted(k for k in set(params) | set(earlier) if params.get(k) != earlier.get(k))
    parts = [
        f"{k}={params[k]}" if k in params and len(params[k]) <= 20 else k for k in keys[:shown]
    ]
    if len(keys) > shown:
        parts.append(f"+{len(keys) - shown} more")
    return ", ".join(parts)


def parent_run_name(
    client,
    experiment_id: str,
    run_name: str,
    config_hash: str,
    params: dict,
    now: datetime.datetime | None = None,
) -> str:
    """A parent run's name as the MLflow UI lists it: the run name and the UTC time it was logged,
    and where the experiment's newest earlier parent had another config, the keys that differ
    from it ("smoke 2026-11-25 19:40 (classifiers.svm.C=3.0)"). The config hash stays a tag."""
    now = now or datetime.datetime.now(datetime.timezone.utc)
    name = f"{run_name} {now:%Y-%m-%d %H:%M}"
    # parents only: the nested runs carry no snakemake_run_name
    earlier = client.search_runs(
        [experiment_id],
        f"tags.snakemake_run_name = '{run_name}'",
        order_by=["attributes.start_time DESC"],
        max_results=1,
    )
    previous = earlier[0] if earlier else None
    if previous is not None and previous.data.tags.get("config_hash") != config_hash:
        if changed := changed_keys(params, previous.data.params):
            name += f" ({changed})"
    return name


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
    profile = {
        "files": len(paths),
        "rows": sum(pq.ParquetFile(p).metadata.num_rows for p in paths),
        "bytes": sum(p.stat().st_size for p in paths),
    }
    source = paths[0] if len(paths) == 1 else Path(os.path.commonpath(paths))

    class FileDataset(MetaDataset):
        def to_dict(self):
            return {**super().to_dict(), "profile": json.dumps(profile)}

    return FileDataset(
        LocalArtifactDatasetSource(str(source)), name=name, digest=digest.hexdigest()[:16]
    )


def read_train_outputs(train_dirs) -> tuple[pd.DataFrame, pd.DataFrame, dict, dict, dict]:
    """metrics, predictions, {classifier: params it was fitted with}, {run key: model file} (from
    each train/<classifier>/<protocol>/info.json) and {run key: training history} (CNN)."""
    dirs = [Path(d) for d in train_dirs]
    if missing := [str(d / "info.json") for d in dirs if not (d / "info.json").is_file()]:
        raise TrackingError(f"no such train output: {missing}")
    metrics = load_metrics([d / "metrics.csv" for d in dirs], extra_columns=("fit_seconds",))
    predictions = load_predictions([d / "predictions.parquet" for d in dirs])
    params, files, histories = {}, {}, {}
    for d in dirs:
        info = json.loads((d / "info.json").read_text())
        clf, protocol = info["classifier"], info["protocol"]
        params[clf] = info.get("classifier_params") or {}
        for entry in info["models"]:
            files[
                (
                    clf,
                    protocol,
                    int(entry["measured_percent"]),
                    int(entry["repeat"]),
                    entry["holdout"] or "",
                )
            ] = d / "models" / entry["file"]
        if (d / "models" / HISTORY_FILE).exists():
            history = pd.read_parquet(d / "models" / HISTORY_FILE)
            history["holdout"] = history["holdout"].fillna("")
            for (percent, repeat, holdout), rows in history.groupby(
                ["measured_percent", "repeat", "holdout"]
            ):
                histories[(clf, protocol, int(percent), int(repeat), holdout)] = rows
    return metrics, predictions, params, files, histories


def wants_model(policy, key: dict) -> bool:
    """``tracking.log_models``: "all", "first_repeat" (repeat 0 of every setting), "none", or a
    filter {classifier/protocol/measured_percent/repeat: [values]} (a key left out matches all)."""
    if isinstance(policy, dict):
        return all(key[name] in values for name, values in policy.items())
    return policy == "all" or (policy == "first_repeat" and key["repeat"] == 0)


@functools.cache
def pip_requirements(*extra: str) -> tuple[str, ...]:
    """Pinned requirements of logged models: given, as MLflow would infer them in a subprocess
    per model (seconds each)."""
    names = ("mlflow", "scikit-learn", "numpy", "scipy", "pandas", "skops", *extra)
    return tuple(f"{n}=={metadata.version(n)}" for n in names)


# --------------------------------------------------------------------------- logging


def summary_metrics(metrics: pd.DataFrame) -> dict[str, float]:
    """accuracy.<classifier>.<protocol>.p<percent>: mean over repeats of the held-out mean."""
    overall = metrics[metrics["speed_rpm"].isna()]
    per_repeat = overall.groupby(KEYS[:4])["accuracy"].mean()
    means = per_repeat.groupby(level=[0, 1, 2]).mean()
    return {
        f"accuracy.{c}.{p}.p{int(percent):03d}": float(v) for (c, p, percent), v in means.items()
    }


def nested_runs(
    metrics: pd.DataFrame, predictions: pd.DataFrame, clf_params: dict, histories: dict
) -> list[tuple[dict, dict, dict]]:
    """(key, params, metrics) of every nested run, from the metrics rows (the all-speeds row and
    one per speed) and the predictions (the CNN's uncertainty)."""
    uncertainty = predictions.groupby(KEYS)["uncertainty"].mean()
    runs = {}
    for row in metrics.to_dict("records"):
        values = tuple(row[k] for k in KEYS)
        key, params, run = runs.setdefault(values, (dict(zip(KEYS, values)), {}, {}))
        if pd.isna(row["speed_rpm"]):
            if params:
                raise TrackingError(f"metrics for {key} have more than one all-speeds row")
            params.update(
                {k: str(v) for k, v in key.items()},
                holdout=key["holdout"] or "none",
                **{k: str(row[k]) for k in ("n_train_simulated", "n_train_measured", "n_test")},
                **flatten_params(clf_params.get(key["classifier"], {}), "classifier"),
            )
            run.update(accuracy=row["accuracy"], macro_f1=row["macro_f1"])
            if np.isfinite(row.get("fit_seconds", np.nan)):
                run["fit_seconds"] = row["fit_seconds"]
        else:
            run[f"accuracy_{format_speed(row['speed_rpm'])}rpm"] = row["accuracy"]
            run[f"macro_f1_{format_speed(row['speed_rpm'])}rpm"] = row["macro_f1"]
    for values, (key, params, run) in runs.items():
        if not params or values not in uncertainty.index:
            raise TrackingError(
                f"{key}: {'no all-speeds row in metrics.csv' if not params else 'no predictions'}"
            )
        if np.isfinite(uncertainty[values]):
            run["uncertainty_mean"] = uncertainty[values]
        if values in histories:
            run["epochs_run_mean"] = histories[values].groupby("member")["epoch"].max().mean()
    return [
        (key, params, {k: float(v) for k, v in run.items()}) for key, params, run in runs.values()
    ]


def curves(history) -> list[tuple[str, float, int]]:
    """(name, value, epoch) of the members' mean training curves (a member that stopped early
    counts until its last epoch)."""
    means = history.groupby("epoch")[list(CURVES)].mean()
    points = [
        (name, float(row[name]), int(epoch)) for epoch, row in means.iterrows() for name in CURVES
    ]
    return [point for point in points if np.isfinite(point[1])]


@dataclass(frozen=True)
class TrackedRun:
    """What names a pipeline invocation in MLflow: the run name (the experiment), the config's
    hash and its values (the parent's params), the data source (tags), and the healthy state
    (the confusion matrices' class order)."""

    run_name: str
    config_hash: str
    data_source: str
    config: dict | None = None
    healthy_state: str | None = None


@dataclass
class TrackInputs:
    """Everything `log_pipeline_run` logs, read and checked before the first MLflow call
    (`read_track_inputs`)."""

    metrics: pd.DataFrame
    predictions: pd.DataFrame
    histories: dict  # {run key: training history} (CNN)
    files: dict  # {run key: the packaged model each nested run names}
    datasets: dict  # {name: MLflow dataset}
    runs: list  # (key, params, metrics) of every nested run
    confusion: pd.DataFrame
    store: dict  # the model store's index
    by_key: dict  # {run key: its store entry}


def read_track_inputs(train_dirs, datasets: dict, model_store, healthy_state) -> TrackInputs:
    """The train outputs, datasets and model store of a run, every nested run checked to have
    its model (in info.json and in the store)."""
    from condmon.model_store import read_index

    metrics, predictions, clf_params, files, histories = read_train_outputs(train_dirs)
    inputs = {name: file_dataset(name, paths) for name, paths in datasets.items()}
    runs = nested_runs(metrics, predictions, clf_params, histories)
    if missing := [key for key, _, _ in runs if tuple(key.values()) not in files]:
        raise TrackingError(f"no model file in info.json for {missing[:3]}")
    store = read_index(model_store)
    by_key = {tuple(e[k] for k in KEYS): e for e in store["models"]}
    if missing := [key for key, _, _ in runs if tuple(key.values()) not in by_key]:
        raise TrackingError(f"{model_store}: no packaged model for {missing[:3]}")
    files = {key: Path(model_store) / entry["file"] for key, entry in by_key.items()}
    labels = label_order(
        [*predictions["true_label"], *predictions["predicted_label"]], healthy_state
    )
    confusion = (
        predictions.groupby([*KEYS, "true_label", "predicted_label"])
        .size()
        .unstack(fill_value=0)
        .reindex(columns=labels, fill_value=0)
    )
    return TrackInputs(
        metrics, predictions, histories, files, inputs, runs, confusion, store, by_key
    )


def parent_tags(run: TrackedRun, log_models, n_runs: int, workdir=".") -> dict:
    """The parent run's tags: the commit, the config hash, the run name, the data source."""
    commit, dirty = git_state(workdir)
    return {
        "git_commit": commit,
        "git_dirty": dirty,
        "config_hash": run.config_hash,
        "snakemake_run_name": run.run_name,
        "data_source": run.data_source,
        "data_source_synthetic": str(is_synthetic(run.data_source)).lower(),
        "models_logged": json.dumps(log_models),
        "n_nested_runs": str(n_runs),
    }


def log_parent_contents(data: TrackInputs, params: dict) -> None:
    """The active parent run's inputs, params, summary metrics and tables."""
    import mlflow

    log_inputs(data.datasets)
    mlflow.log_params(params)
    mlflow.log_metrics(summary_metrics(data.metrics))
    mlflow.log_text(data.metrics.to_csv(index=False), "accuracy.csv")
    # counts per run (rows: true label, columns: predicted label)
    mlflow.log_text(data.confusion.reset_index().to_csv(index=False), "confusion_matrices.csv")


def nested_run_model(
    data: TrackInputs,
    run_key: tuple,
    key: dict,
    run_id: str,
    name: str,
    params: dict,
    run_tags: dict,
    log_models,
    logged_digests: dict,
) -> tuple[str | None, bool]:
    """The model a nested run logs (its id, None if the policy logs none) and whether it was
    linked, not logged again: the packaged SignalModel (a digest the experiment has is linked)."""
    if not wants_model(log_models, key):
        return None, False
    digest = data.by_key[run_key]["digest"]
    model_id = logged_digests.get(digest)
    if model_id is not None:  # unchanged models are linked, not logged again
        return model_id, True
    model_id = log_signal_model(
        data.files[run_key],
        run_id,
        re.sub(r"[^\w-]+", "-", name),
        params,
        {**run_tags, "model_digest": digest},
    )
    logged_digests[digest] = model_id
    return model_id, False


def log_nested_run(
    client,
    experiment_id: str,
    parent_id: str,
    data: TrackInputs,
    nested: tuple,
    config_hash: str,
    log_models,
    logged_digests: dict,
) -> tuple[str | None, bool]:
    """One nested run (`nested`: key, params, metrics): created, its model, one log_batch of its
    metrics (linked to the model) and params, terminated; returns (model id, linked)."""
    from mlflow.entities import Metric, Param

    key, params, values = nested
    run_key = tuple(key.values())
    name = f"{key['classifier']}/{key['protocol']}/p{key['measured_percent']}/r{key['repeat']}"
    name += f"/{key['holdout']}" if key["holdout"] else ""
    run_tags = {
        **{k: str(v) for k, v in key.items()},
        "config_hash": config_hash,
        "leaky": str(key["protocol"] in LEAKY_PROTOCOLS).lower(),
        "model_file": str(data.files[run_key].resolve()),
    }
    run_id = client.create_run(
        experiment_id, run_name=name, tags={**run_tags, "mlflow.parentRunId": parent_id}
    ).info.run_id
    # the device it was fitted on (the CNN: cpu or cuda:<n> (<GPU>))
    params = {**params, "device": data.by_key[run_key]["device"]}
    model_id, linked = nested_run_model(
        data, run_key, key, run_id, name, params, run_tags, log_models, logged_digests
    )
    measured, now = data.datasets["measured_features"], int(time.time() * 1000)
    points = [
        Metric(
            k,
            v,
            now,
            0,
            dataset_name=measured.name,
            dataset_digest=measured.digest,
            model_id=model_id,
        )
        for k, v in values.items()
    ]
    if run_key in data.histories:  # the members' mean curves; every member's in an artifact
        history = data.histories[run_key]
        points += [Metric(k, v, now, step, model_id=model_id) for k, v, step in curves(history)]
        client.log_text(
            run_id,
            history[["member", "epoch", *CURVES]].to_csv(index=False),
            "training_history.csv",
        )
    client.log_batch(run_id, metrics=points, params=[Param(k, v) for k, v in params.items()])
    client.set_terminated(run_id)
    return model_id, linked


def tracking_client(uri: str):
    """MLflow pointed at `uri` (a local SQLite store switched to write-ahead logging) and its client."""
    import mlflow

    use_write_ahead_log(uri)
    mlflow.set_tracking_uri(uri)
    return mlflow.MlflowClient(uri)


def log_nested_runs(
    client,
    experiment_id: str,
    parent_id: str,
    data: TrackInputs,
    config_hash: str,
    log_models,
    logged_digests: dict,
) -> tuple[list, int]:
    """Every nested run (`log_nested_run`): the ids of the models logged or linked, and how many
    were linked rather than logged again."""
    model_ids, n_reused = [], 0
    for nested in data.runs:
        model_id, linked = log_nested_run(
            client, experiment_id, parent_id, data, nested, config_hash, log_models, logged_digests
        )
        model_ids += [model_id] if wants_model(log_models, nested[0]) else []
        n_reused += linked
    return model_ids, n_reused


def register_store_best(
    client, data: TrackInputs, logged_digests: dict, run_name: str, config_hash: str
) -> dict:
    """The store's best model registered (`register_best`) and the parent tagged with it, where
    this experiment logged it; {} otherwise."""
    import mlflow

    if data.store["best"] is None:
        return {}
    best = next(e for e in data.store["models"] if e["file"] == data.store["best"])
    best_id = logged_digests.get(best["digest"])
    if best_id is None:
        return {}
    registered = register_best(client, best_id, run_name, config_hash, best)
    mlflow.set_tags(
        {
            "best_model_id": best_id,
            "best_model_file": str(data.files[tuple(best[k] for k in KEYS)].resolve()),
        }
    )
    return registered


def tracking_failure(uri: str, parent_id: str | None, exc: Exception) -> TrackingError | None:
    """After a failure while logging: the parent ended as FAILED (best effort: the server may be
    gone) and, for a remote server, the error that names it and the unfinished parent."""
    import mlflow

    with contextlib.suppress(Exception):
        mlflow.end_run("FAILED")
    if is_remote(uri) and not isinstance(exc, TrackingError):
        return TrackingError(
            f"MLflow tracking server {uri} failed while logging parent run {parent_id} "
            f"({type(exc).__name__}: {str(exc)[:300]}). That run stays unfinished and is never "
            "counted; rerun the track job once the server answers"
        )
    return None


def log_pipeline_run(
    tracking_uri: str,
    run: TrackedRun,
    train_dirs,
    datasets: dict,
    model_store,
    log_models="all",
    workdir=".",
) -> dict:
    """Log one pipeline invocation (see module docstring); returns the run_info dict.

    ``train_dirs``: the train/<classifier>/<protocol> folders; ``datasets``: name -> files, with
    ``measured_features`` among them; ``model_store``: the run's packaged models
    (``condmon.model_store``), logged as those SignalModels (pyfunc, a signal table in), a model
    already logged in the experiment (same digest) linked rather than logged again, the store's
    best model registered (``register_best``); ``log_models``: see wants_model. Every input is
    read and checked before the first MLflow call (the report's plots follow by
    ``log_run_artifacts``).
    """
    if not isinstance(log_models, dict) and log_models not in MODEL_POLICIES:
        raise ValueError(f"log_models={log_models!r}; expected one of {MODEL_POLICIES} or a filter")
    started = time.perf_counter()
    uri = resolve_tracking_uri(tracking_uri, workdir)
    check_tracking_server(uri)
    data = read_track_inputs(train_dirs, datasets, model_store, run.healthy_state)
    import mlflow

    client, parent_id = tracking_client(uri), None
    tags = parent_tags(run, log_models, len(data.runs), workdir)
    try:
        experiment_id = get_or_create_experiment(client, uri, run.run_name)
        params = flatten_params(run.config or {})
        name = parent_run_name(client, experiment_id, run.run_name, run.config_hash, params)
        parent_id = mlflow.start_run(
            experiment_id=experiment_id, tags=tags, run_name=name
        ).info.run_id
        log_parent_contents(data, params)
        logged_digests = logged_model_digests(experiment_id)
        model_ids, n_reused = log_nested_runs(
            client, experiment_id, parent_id, data, run.config_hash, log_models, logged_digests
        )
        registered = register_store_best(
            client, data, logged_digests, run.run_name, run.config_hash
        )
        mlflow.end_run()
    except Exception as exc:
        if (error := tracking_failure(uri, parent_id, exc)) is not None:
            raise error from exc
        raise
    where = {
        "parent_run_id": parent_id,
        "experiment_id": experiment_id,
        "tracking_uri": uri,
        "tracking_uri_configured": tracking_uri,
    }
    return run_info(
        run,
        data,
        log_models,
        where,
        (model_ids, n_reused, registered),
        time.perf_counter() - started,
    )


def run_info(
    run: TrackedRun, data: TrackInputs, log_models, where: dict, models: tuple, elapsed: float
) -> dict:
    """What `log_pipeline_run` returns (and the track job writes as mlflow_run.json); `where`: the
    parent run's and experiment's ids and the store's URI (resolved, configured); `models`: the
    ids of the models logged or linked, how many were linked, the registered best."""
    model_ids, n_reused, registered = models
    log.info(
        "logged %d nested runs and %d models under %s in %.1f s",
        len(data.runs),
        len(model_ids),
        where["parent_run_id"],
        elapsed,
    )
    return {
        "parent_run_id": where["parent_run_id"],
        "experiment_id": where["experiment_id"],
        "experiment_name": run.run_name,
        "tracking_uri": where["tracking_uri"],
        "tracking_uri_configured": where["tracking_uri_configured"],
        "n_nested_runs": len(data.runs),
        "models_logged": log_models,
        "n_models_logged": len(model_ids),
        "config_hash": run.config_hash,
        "n_models_linked_not_logged": n_reused,
        "best_model": registered,
        "datasets": {name: dataset.digest for name, dataset in data.datasets.items()},
        "seconds": round(elapsed, 2),
    }


def logged_model_digests(experiment_id: str) -> dict[str, str]:
    """{model_digest tag: model id} of the signal models already logged in the experiment."""
    import mlflow

    models = mlflow.search_logged_models(experiment_ids=[experiment_id], output_format="list")
    return {
        m.tags["model_digest"]: m.model_id
        for m in sorted(models, key=lambda m: m.creation_timestamp)
        if m.tags.get("model_digest") and m.status == "READY"
    }


def log_signal_model(path: Path, run_id: str, name: str, params: dict, tags: dict) -> str:
    """A packaged SignalModel (``condmon.model_store``) as a pyfunc LoggedModel of ``run_id``:
    a signal table in, per-segment labels and probabilities out, its signature naming the
    columns."""
    import joblib

    from condmon.signal_model import log_pyfunc

    model = joblib.load(path)
    extra = ("torch",) if hasattr(model.estimator, "to_torch_module") else ()
    import mlflow

    # pyfunc's log_model takes no run id: the nested run is resumed for it (the parent stays active)
    with mlflow.start_run(run_id=run_id, nested=True):
        info = log_pyfunc(
            path,
            model,
            name=name,
            params=params,
            tags=tags,
            pip_requirements=list(pip_requirements(*extra)),
        )
    return info.model_id


def registered_model_name(run_name: str) -> str:
    return f"condmon-{run_name}"


def register_best(client, model_id: str, run_name: str, config_hash: str, entry: dict) -> dict:
    """Register the config's best model as a version of ``condmon-<run name>`` (once per model
    digest) with the aliases ``best`` (the latest tracked config's) and ``config-<hash>``."""
    import mlflow
    from mlflow.exceptions import MlflowException

    name = registered_model_name(run_name)
    try:
        client.create_registered_model(
            name,
            description=f"the best model of each config of run {run_name} "
            "(condmon.model_store.best_model)",
        )
    except MlflowException as exc:
        if exc.error_code != "RESOURCE_ALREADY_EXISTS":
            raise
    versions = client.search_model_versions(f"name = '{name}'")
    version = next(
        (v.version for v in versions if v.tags.get("model_digest") == entry["digest"]), None
    )
    if version is None:
        version = mlflow.register_model(
            f"models:/{model_id}",
            name,
            tags={
                "model_digest": entry["digest"],
                "config_hash": config_hash,
                **{k: str(entry[k]) for k in KEYS},
            },
        ).version
    aliases = ["best", f"config-{config_hash[:12]}"]
    for alias in aliases:
        client.set_registered_model_alias(name, alias, version)
    return {
        "name": name,
        "version": str(version),
        "aliases": aliases,
        "model_id": model_id,
        "uri": f"models:/{name}@best",
        **{k: entry[k] for k in KEYS},
    }


def write_run_info(info: dict, path) -> None:
    write_json(info, path)


def log_run_artifacts(info: dict, artifacts: dict) -> list[str]:
    """Log {artifact folder: local file or folder} into the finished parent run of `info` (a
    `log_pipeline_run` result, report/mlflow_run.json); returns the artifact paths logged. Hidden
    files (Snakemake's marks) are left out."""
    uri = info["tracking_uri"]
    check_tracking_server(uri)
    client = tracking_client(uri)
    logged = []
    for folder, path in artifacts.items():
        for file in sorted(Path(path).iterdir()) if Path(path).is_dir() else [Path(path)]:
            if file.is_file() and not file.name.startswith("."):
                client.log_artifact(info["parent_run_id"], str(file), folder)
                logged.append(f"{folder}/{file.name}")
    return logged

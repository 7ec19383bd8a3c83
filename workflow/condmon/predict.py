"""Apply a trained model to new measurements (console script ``condmon predict``; rule ``predict``).

    condmon predict --model results/smoke --input new_records.parquet --output results/predictions/
    condmon predict --model models:/condmon-smoke@best --tracking-uri sqlite:///results/mlflow.db \\
        --input /data/rig-records --output results/predictions/

``--input``: a signal table (Parquet: record_id, segment, speed_rpm, fs_hz, channel, signal;
``health_state``, ``source``, ``load`` and ``params`` may be left out, ``health_state`` may be
``unknown``; where it names a class of the model, the predictions are scored), or a folder or single file of the system's own records (in its own format), read by
the system's reader with the settings the model was trained with. ``--model``: a run's results
folder (its best model, or the one ``--classifier/--protocol/--percent/--repeat`` pick), a model
store folder (``results/<run>/models/<config_hash>``), a packaged model file, or an MLflow model
URI (``models:/<name>@<alias>``, ``models:/<model_id>``, ``runs:/<run_id>``: a parent run gives its
best model).

Writes into ``--output``: ``segments.csv`` (per segment: label and class probabilities),
``records.csv`` (per record: the majority label, vote shares and mean probabilities),
``health_summary.csv`` (per record: healthy or fault, the likeliest fault, confidence),
``predictions.png``, ``model.json`` (which model, trained for what), with health states given
``score.json`` (accuracy, balanced accuracy and recalls per segment, right records) and, with
``--skip-unsupported``, ``refused_records.csv``. Records whose rate, channels, segment length or
speed the model was not trained for are refused by name (exit status 2, nothing written), or
with ``--skip-unsupported`` listed apart.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from condmon.atomic import staging_directory
from condmon.model_store import ModelStoreError, read_index, select, store_of_results
from condmon.signal_model import (
    REQUIRED_COLUMNS,
    UNKNOWN_LABEL,
    SignalModel,
    UnsupportedRecords,
    complete_signal_table,
    health_summary,
    record_predictions,
)
from condmon.signals import SignalTableError, read_unvalidated

log = logging.getLogger(__name__)
MLFLOW_SCHEMES = ("models:/", "runs:/")


class PredictError(ValueError):
    """The model or the input cannot be used; the message says why."""


# -- the model ------------------------------------------------------------------------------------


def load_model(source: str, tracking_uri: str | None = None, **key) -> tuple[SignalModel, dict]:
    """(model, where it came from) of ``source`` (see the module docstring); ``key`` picks a model
    of a results folder or store (classifier, protocol, measured_percent, repeat)."""
    import joblib

    if source.startswith(MLFLOW_SCHEMES):
        return load_mlflow_model(source, tracking_uri)
    path = Path(source)
    if path.is_file():
        model = joblib.load(path)
        if not isinstance(model, SignalModel):
            raise PredictError(
                f"{path}: not a packaged model (a train job's models/*.joblib takes "
                "feature vectors; use the run's results folder or models/<config_hash>/)"
            )
        return model, {"source": str(path)}
    if not path.is_dir():
        raise PredictError(
            f"--model {source}: no such folder or file, and not an MLflow URI "
            f"({', '.join(MLFLOW_SCHEMES)})"
        )
    try:
        store = path if (path / "index.json").is_file() else store_of_results(path)
        entry = select(read_index(store), **key)
    except ModelStoreError as exc:
        raise PredictError(str(exc)) from None
    return joblib.load(store / entry["file"]), {"source": str(store / entry["file"])}


def load_mlflow_model(uri: str, tracking_uri: str | None = None) -> tuple[SignalModel, dict]:
    """The SignalModel behind an MLflow pyfunc model; a ``runs:/<id>`` without a path is the
    parent run's best model (tag ``best_model_id``) or the run's only model."""
    import mlflow

    mlflow.set_tracking_uri(store_of(uri, tracking_uri))
    try:
        if uri.startswith("runs:/") and "/" not in uri[len("runs:/") :].strip("/"):
            uri = model_of_run(uri[len("runs:/") :].strip("/"))
        loaded = mlflow.pyfunc.load_model(uri)
        model = loaded.unwrap_python_model().model
    except PredictError:
        raise
    except Exception as exc:  # MLflow raises several types for a missing run, model or alias
        raise PredictError(
            f"--model {uri}: cannot load it from {mlflow.get_tracking_uri()} "
            f"({type(exc).__name__}: {str(exc)[:300]}); is it the run's store "
            "(--tracking-uri)?"
        ) from exc
    if not isinstance(model, SignalModel):
        raise PredictError(f"--model {uri}: not a condmon signal model")
    return model, {"source": uri, "model_id": loaded.metadata.model_id}


def model_of_run(run_id: str) -> str:
    """``models:/<id>`` of a parent run's best model (tag ``best_model_id``) or a run's only one."""
    import mlflow

    run = mlflow.MlflowClient().get_run(run_id)
    model_id = run.data.tags.get("best_model_id")
    if model_id is None:
        models = mlflow.search_logged_models(
            experiment_ids=[run.info.experiment_id],
            filter_string=f"source_run_id = '{run_id}'",
            output_format="list",
        )
        if len(models) != 1:
            raise PredictError(
                f"run {run_id} has {len(models)} logged models and no best_model_id "
                "tag; name one as models:/<model_id>"
            )
        model_id = models[0].model_id
    return f"models:/{model_id}"


def store_of(source: str, tracking_uri: str | None) -> str:
    """The tracking store ``source`` is looked up in: ``--tracking-uri``, else MLFLOW_TRACKING_URI,
    else the project's own (`tracking.uri`'s default, results/mlflow.db in the working folder);
    a SQLite store that does not exist is an error, never an empty one made here."""
    from condmon.tracking import DEFAULT_TRACKING_URI, TrackingError, existing_store

    if tracking_uri:
        uri, given = tracking_uri, "--tracking-uri"
    elif os.environ.get("MLFLOW_TRACKING_URI"):
        uri, given = os.environ["MLFLOW_TRACKING_URI"], "MLFLOW_TRACKING_URI"
    else:
        uri, given = DEFAULT_TRACKING_URI, "the project's store (tracking.uri's default)"
    try:
        return existing_store(uri)
    except TrackingError as exc:
        raise PredictError(
            f"--model {source}: {exc}, from {given}; run in the project folder of the run "
            "that logged the model, or name its store with --tracking-uri (the run's "
            "tracking.uri, e.g. sqlite:////path/to/condmon/results/mlflow.db)"
        ) from None


# -- the input ------------------------------------------------------------------------------------


def read_input(source, model: SignalModel) -> tuple[pd.DataFrame, pd.DataFrame | None]:
    """(signal table, the reader's record list or None) of a Parquet signal table (only the
    columns of new data needed: `REQUIRED_COLUMNS`), or of a folder or file of the system's own
    records read by the system's reader with the model's settings. Every error names ``source``."""
    path = Path(source)
    if not path.exists():
        raise PredictError(f"--input {source}: no such file or folder")
    if path.is_file() and path.suffix == ".parquet":
        try:
            return complete_signal_table(read_unvalidated(path, REQUIRED_COLUMNS)), None
        except SignalTableError as exc:
            raise PredictError(f"--input {source}: {str(exc).removeprefix(f'{path}: ')}") from None
    if model.system is None:
        raise PredictError(
            f"--input {source}: the model knows no system reader; give a signal table "
            f"(Parquet, columns {REQUIRED_COLUMNS})"
        )
    if path.is_dir():
        return read_system_records(path, model, source)
    with (
        tempfile.TemporaryDirectory() as folder
    ):  # the reader takes a folder: one of the single file
        (Path(folder) / path.name).symlink_to(path.resolve())
        renamed = UserPath(folder, path.name, source)
        handlers = logging.getLogger().handlers
        for handler in handlers:  # the reader's warnings name the file it read: the user's
            handler.addFilter(renamed)
        try:
            return read_system_records(Path(folder), model, source)
        except PredictError as exc:
            raise PredictError(renamed.text(str(exc))) from None
        finally:
            for handler in handlers:
                handler.removeFilter(renamed)


class UserPath(logging.Filter):
    """Says ``source`` (the user's file) where a text names the temporary folder its reader was
    given, or the file's link in it; as a logging filter, in every record it passes."""

    def __init__(self, folder, name: str, source):
        super().__init__()
        self.names = [(str(Path(folder) / name), str(source)), (str(folder), str(source))]

    def text(self, text: str) -> str:
        for old, new in self.names:
            text = text.replace(old, new)
        return text

    def filter(self, record: logging.LogRecord) -> bool:
        record.msg, record.args = self.text(record.getMessage()), None
        return True


def read_system_records(
    folder: Path, model: SignalModel, source
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The records of ``folder`` by the model's system reader; errors name ``source`` (the user's
    input) and what the reader said."""
    from condmon.systems import load_system

    spec = model.system
    config = {**spec["config"], "measured_table": None, "measured_dir": str(folder)}
    system = load_system({**spec, "config": config})
    try:
        files = system.measured_files()
        frame, records = system.read_measured(files, [], list(model.domain["channels"]), "skip")
    except (ValueError, OSError, NotImplementedError) as exc:
        raise PredictError(
            f"--input {source}: the {system.name} system cannot read it ({exc}); "
            f"give a signal table (Parquet, columns {REQUIRED_COLUMNS})"
        ) from None
    if frame.empty:
        raise PredictError(
            f"--input {source}: no records read ({len(records)} left out: "
            f"{records.get('reason', pd.Series(dtype=str)).head(3).tolist()})"
        )
    return complete_signal_table(frame), records


# -- predicting and writing ----------------------------------------------------------------------


def predict(model: SignalModel, frame: pd.DataFrame, skip_unsupported: bool = False) -> dict:
    """{"segments", "records", "summary", "refused"} frames for a signal table."""
    refused = model.problems(frame)
    if len(refused) and not skip_unsupported:
        raise UnsupportedRecords(refused)
    kept = frame[~frame["record_id"].isin(refused["record_id"])]
    if kept.empty:
        raise UnsupportedRecords(refused)
    segments = model.predict_segments(kept)
    records = record_predictions(segments, model.classes, model.healthy_state)
    summary = health_summary(records, model.classes, model.healthy_state)
    return {
        "segments": segments,
        "records": records,
        "summary": summary,
        "refused": refused,
        "score": score(segments, summary, model.classes),
    }


def score(segments: pd.DataFrame, summary: pd.DataFrame, classes) -> dict | None:
    """How the calls compare with the table's own health states, where it gave ones the model
    knows: per segment accuracy, balanced accuracy (the mean of the recalls of the classes
    present) and each class's recall, per record the share of right majority calls; the labels
    the model does not know (not scored) listed. None where no record has a known label."""
    known = segments["true_label"].isin(classes)
    unknown = sorted(set(segments.loc[~known, "true_label"].astype(str)) - {UNKNOWN_LABEL})
    if not known.any():
        return None if not unknown else {"unscored_labels": unknown}
    right = segments.loc[known, "predicted_label"] == segments.loc[known, "true_label"]
    recall = right.groupby(segments.loc[known, "true_label"]).mean()
    scored = summary[summary["correct"].notna()]
    return {
        "segments": int(known.sum()),
        "accuracy": float(right.mean()),
        "balanced_accuracy": float(recall.mean()),
        "recall": recall.round(4).to_dict(),
        "records": len(scored),
        "records_right": int(scored["correct"].astype(bool).sum()),
        "unscored_labels": unknown,
    }


def plot_records(records: pd.DataFrame, classes, healthy_state: str, path, title: str) -> None:
    """One bar per record: the shares of its segments given to each class (healthy first)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    order = [healthy_state, *[c for c in classes if c != healthy_state]]
    records = records.sort_values("record_id")
    height = 1.2 + 0.3 * len(records)
    fig, ax = plt.subplots(figsize=(8, height))
    left = np.zeros(len(records))
    colours = plt.get_cmap("tab10")
    for k, label in enumerate(order):
        share = records[f"vote_{label}"].to_numpy()
        ax.barh(np.arange(len(records)), share, left=left, color=colours(k % 10), label=label)
        left += share
    names = [
        f"{r} ({t})" if t in classes else r
        for r, t in zip(records["record_id"], records["true_label"])
    ]
    ax.set_yticks(np.arange(len(records)), names, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, 1)
    ax.set_xlabel("share of the record's segments")
    ax.set_title(title, fontsize=10, pad=24)
    ax.legend(
        fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=len(order), frameon=False
    )
    fig.tight_layout()
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def write_outputs(
    results: dict, model: SignalModel, origin: dict, output, reader_records=None
) -> None:
    """Every output into ``output`` (built aside, renamed into place)."""
    with staging_directory(Path(output)) as tmp:
        results["segments"].to_csv(tmp / "segments.csv", index=False)
        results["records"].to_csv(tmp / "records.csv", index=False)
        results["summary"].to_csv(tmp / "health_summary.csv", index=False)
        if len(results["refused"]):
            results["refused"].to_csv(tmp / "refused_records.csv", index=False)
        if reader_records is not None:
            reader_records.to_csv(tmp / "input_records.csv", index=False)
        if results.get("score"):
            (tmp / "score.json").write_text(json.dumps(results["score"], indent=1))
        key = {
            k: model.info.get(k)
            for k in ("classifier", "protocol", "measured_percent", "repeat", "holdout")
        }
        title = "{classifier}/{protocol}, {measured_percent} % measured, repeat {repeat}".format(
            **key
        )
        plot_records(
            results["records"],
            model.classes,
            model.healthy_state,
            tmp / "predictions.png",
            f"Predicted health per record ({title})",
        )
        (tmp / "model.json").write_text(
            json.dumps(
                {
                    **origin,
                    **model.info,
                    "classes": model.classes,
                    "healthy_state": model.healthy_state,
                    "has_probabilities": model.has_probabilities,
                    "domain": model.domain,
                    "digest": model.digest(),
                },
                indent=1,
                default=str,
            )
        )


def parse_args(argv=None):
    parser = argparse.ArgumentParser(prog="condmon", description="condmon command-line tools")
    commands = parser.add_subparsers(dest="command", required=True)
    p = commands.add_parser(
        "predict",
        help="apply a trained model to new measurements",
        description=__doc__.split("\n\n")[0],
    )
    p.add_argument(
        "--model",
        required=True,
        help="a results folder, model store, packaged model file or MLflow model URI",
    )
    p.add_argument(
        "--input",
        required=True,
        help="a signal table (.parquet), or a folder or file of the system's own records",
    )
    p.add_argument("--output", required=True, help="folder for the predictions (replaced whole)")
    p.add_argument(
        "--tracking-uri",
        default=None,
        help="MLflow tracking URI for models:/ and runs:/ "
        "(default: MLFLOW_TRACKING_URI, else the "
        "project's sqlite:///results/mlflow.db)",
    )
    p.add_argument("--classifier", default=None)
    p.add_argument("--protocol", default=None)
    p.add_argument("--percent", type=int, default=None, help="the fit's measured percentage")
    p.add_argument("--repeat", type=int, default=None)
    p.add_argument(
        "--skip-unsupported",
        action="store_true",
        help="predict the records the model was trained for, list the others in "
        "refused_records.csv (default: refuse the input)",
    )
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(message)s")
    try:
        model, origin = load_model(
            args.model,
            args.tracking_uri,
            classifier=args.classifier,
            protocol=args.protocol,
            measured_percent=args.percent,
            repeat=args.repeat,
        )
        frame, reader_records = read_input(args.input, model)
        results = predict(model, frame, args.skip_unsupported)
        write_outputs(results, model, origin, args.output, reader_records)
    except (PredictError, UnsupportedRecords) as exc:
        print(f"condmon predict: {exc}", file=sys.stderr)
        return 2
    summary = results["summary"]
    print(
        f"{len(summary)} record(s): {int((summary['status'] == 'fault').sum())} fault, "
        f"{int((summary['status'] == 'healthy').sum())} healthy"
        + (
            f"; {results['refused']['record_id'].nunique()} refused"
            if len(results["refused"])
            else ""
        )
        + f" -> {args.output}"
    )
    print_score(results.get("score"))
    if "outside_training" in summary and (summary["outside_training"] > 0).any():
        away = summary[summary["outside_training"] > 0]
        print(
            f"{len(away)} record(s) have segments outside the model's training range (their calls "
            f"rest on no training example): {', '.join(map(str, away['record_id'][:5]))}"
            + (" ..." if len(away) > 5 else "")
            + " (health_summary.csv outside_training)"
        )
    return 0


def print_score(scored: dict | None) -> None:
    """One line on how the calls compare with the table's health states (nothing without them)."""
    if scored and "accuracy" in scored:
        print(
            f"scored against the input's health_state: {scored['records_right']} of {scored['records']} "
            f"record(s) right; per segment accuracy {scored['accuracy']:.3f}, balanced "
            f"{scored['balanced_accuracy']:.3f} over {scored['segments']} segment(s) (score.json)"
        )
    if scored and scored["unscored_labels"]:
        print(
            f"not scored: health_state {scored['unscored_labels']} is none of the model's classes"
        )


if __name__ == "__main__":
    raise SystemExit(main())

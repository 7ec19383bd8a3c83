"""The train stage's result tables as every later stage reads them: the metrics.csv files
concatenated into the accuracy table, the predictions.parquet files into one table with the
classifier from each file's path. A file that breaks the stage contract raises
ReportInputError naming it. The report and tracking read them alike through this module.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

# accuracy.csv: the contract columns first, then the context of each evaluation.
ACCURACY_COLUMNS = [
    "classifier",
    "protocol",
    "measured_percent",
    "repeat",
    "speed_rpm",
    "accuracy",
    "macro_f1",
    "holdout",
    "n_train_simulated",
    "n_train_measured",
    "n_test",
]
PREDICTION_COLUMNS = [
    "protocol",
    "measured_percent",
    "repeat",
    "holdout",
    "record_id",
    "segment",
    "speed_rpm",
    "true_label",
    "predicted_label",
]
# optional: the CNN ensemble's member spread per prediction (NaN for the other classifiers)
OPTIONAL_PREDICTION_COLUMNS = ["uncertainty"]
SORT_KEYS = ["classifier", "protocol", "measured_percent", "repeat", "holdout", "speed_rpm"]


class ReportInputError(ValueError):
    """A file the report (or tracking) reads breaks the stage contract."""


def read_table(path, required: list[str], what: str) -> pd.DataFrame:
    """A Parquet table of a stage, or an error naming the file: missing, or lacking `required`."""
    path = Path(path)
    if not path.exists():
        raise ReportInputError(f"{path}: no such {what} file")
    frame = pd.read_parquet(path)
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise ReportInputError(f"{path}: {what} file lacks columns {missing}")
    return frame


def load_metrics(paths, extra_columns=()) -> pd.DataFrame:
    """Concatenate train metrics.csv files into the accuracy table (columns ACCURACY_COLUMNS).

    ``speed_rpm`` is NaN on the all-speeds rows; ``holdout`` is "" where nothing is held out.
    ``extra_columns`` (e.g. "fit_seconds") are kept at the end where a file has them.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise ReportInputError("no metrics.csv files given")
    frames = []
    for path in paths:
        if not path.exists():
            raise ReportInputError(f"{path}: no such metrics file")
        frame = pd.read_csv(path, dtype={"classifier": str, "protocol": str, "holdout": str})
        missing = [c for c in ACCURACY_COLUMNS if c not in frame.columns]
        if missing:
            raise ReportInputError(f"{path}: metrics file lacks columns {missing}")
        if frame.empty:
            raise ReportInputError(f"{path}: metrics file has no rows")
        frames.append(frame[ACCURACY_COLUMNS + [c for c in extra_columns if c in frame.columns]])
    table = pd.concat(frames, ignore_index=True)
    table["holdout"] = table["holdout"].fillna("")
    table["speed_rpm"] = pd.to_numeric(table["speed_rpm"], errors="coerce")
    for column in ("measured_percent", "repeat", "n_train_simulated", "n_train_measured", "n_test"):
        table[column] = table[column].astype(int)
    duplicated = table.duplicated(SORT_KEYS)
    if duplicated.any():
        first = table.loc[duplicated].iloc[0]
        raise ReportInputError(
            f"metrics rows repeat for classifier {first.classifier!r} protocol {first.protocol!r} "
            f"percent {first.measured_percent} repeat {first.repeat}; is a metrics file listed twice?"
        )
    # na_position="first": the all-speeds row leads its group.
    return table.sort_values(SORT_KEYS, na_position="first", kind="stable").reset_index(drop=True)


def classifier_of(predictions_path: Path) -> str:
    """The classifier of train/<classifier>/<protocol>/predictions.parquet (the file has no column)."""
    return Path(predictions_path).parent.parent.name


def load_predictions(paths) -> pd.DataFrame:
    """Concatenate predictions.parquet files, adding a ``classifier`` column from the path;
    optional columns (``uncertainty``) are NaN where a file lacks them."""
    paths = [Path(p) for p in paths]
    if not paths:
        raise ReportInputError("no predictions.parquet files given")
    frames = []
    for path in paths:
        frame = read_table(path, PREDICTION_COLUMNS, "predictions")
        if "classifier" not in frame.columns:
            frame.insert(0, "classifier", classifier_of(path))
        protocols = set(frame["protocol"])
        if protocols != {path.parent.name}:
            raise ReportInputError(
                f"{path}: protocol column {sorted(protocols)} does not match "
                f"the directory train/<classifier>/{path.parent.name}/"
            )
        for column in OPTIONAL_PREDICTION_COLUMNS:
            if column not in frame.columns:
                frame[column] = np.nan
        frames.append(frame[["classifier"] + PREDICTION_COLUMNS + OPTIONAL_PREDICTION_COLUMNS])
    table = pd.concat(frames, ignore_index=True)
    table["holdout"] = table["holdout"].fillna("")
    return table

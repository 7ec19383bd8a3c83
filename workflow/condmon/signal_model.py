"""A trained classifier that carries its features: raw signal segments in, health labels out.

`SignalModel` wraps one fitted estimator of a train job (it takes feature vectors) with what it
needs to see a signal table as its training data was seen: the feature extraction (kind,
channels, spectrum or statistical settings, the system's defect orders) and the training domain
(sampling rate, samples per segment, channels, the speeds it was trained at). Records outside
that domain are refused with the reason (`UnsupportedRecords`), never classified: a spectrum at
another rate or speed puts the lines in other bands, and the classifier would still answer.

`SignalModelPyfunc` is its MLflow pyfunc face: `mlflow.pyfunc.load_model(uri).predict(table)`
takes a signal table (long form, the columns of `condmon.signals.SCHEMA`; `source`,
`health_state`, `load` and `params` may be left out) and returns one row per segment with the
label and the class probabilities. Loading it needs condmon, as the train job's joblib files do.
"""

from __future__ import annotations

import hashlib
import json
import logging
import warnings
from contextlib import contextmanager

import numpy as np
import pandas as pd

from condmon.features import FEATURE_FAMILIES, FamilyInputs, family_table
from condmon.reference import nearest_reference, reference_from_table
from condmon.signals import COLUMNS, SignalTableError, validate

# where a packaged model keeps a family's references (`SystemFamily.references`): in that family's
# settings of its packaged features, a format older models share; read back as run-time inputs
PACKAGED_REFERENCES = "reference_patterns"


def packaged_features(
    features: dict,
    defect_orders,
    system_families: dict,
    reference: dict | None = None,
    family_references: pd.DataFrame | None = None,
) -> dict:
    """The feature extraction a packaged model carries (a new dict, `features` untouched).

    Parameters
    ----------
    features : dict
        The features job's settings (kind, channels, each family's section, `families`: the
        system's own families' settings).
    defect_orders : dict or None
        The system's envelope lines (`System.defect_orders`).
    system_families : dict
        `System.feature_families()`: which families take their references themselves.
    reference : dict, optional
        The healthy reference new records are taken against, ``{"condition", "table"}``.
    family_references : DataFrame, optional
        The measured features job's family references (waveforms), packaged into the settings of
        each family that takes them (`PACKAGED_REFERENCES`).

    Returns
    -------
    dict
        `features` with the defect orders, the reference and the families' references.
    """
    packaged = {**features, "defect_orders": defect_orders}
    if reference is not None:
        packaged["reference"] = reference
    if family_references is not None:
        patterns = family_references.to_dict("list")
        packaged["families"] = {
            family: (
                {**settings, PACKAGED_REFERENCES: patterns}
                if family in system_families and system_families[family].references
                else dict(settings)
            )
            for family, settings in (features.get("families") or {}).items()
        }
    return packaged


def unpacked_families(families: dict) -> tuple[dict, FamilyInputs]:
    """({family: settings}, run-time inputs) of a packaged model's `families`: the references
    `packaged_features` put into a family's settings become `FamilyInputs.packaged_references`."""
    settings = {
        family: {k: v for k, v in params.items() if k != PACKAGED_REFERENCES}
        for family, params in families.items()
    }
    references = next(
        (
            params[PACKAGED_REFERENCES]
            for params in families.values()
            if PACKAGED_REFERENCES in params
        ),
        None,
    )
    return settings, FamilyInputs(packaged_references=references)


# Relative distance to the nearest trained speed a record may have (records of one operating point
# differ by a few rpm in some rigs; distinct operating speeds lie hundreds of rpm apart).
SPEED_TOLERANCE = 0.02
UNKNOWN_LABEL = "unknown"  # health_state of a record whose truth is not known
# optional signal-table columns and what a record without them gets
OPTIONAL_COLUMNS = {
    "source": "measured",
    "health_state": UNKNOWN_LABEL,
    "load": np.nan,
    "params": "",
}
# what a table of new records must have: record_id, segment, speed_rpm, fs_hz, channel, signal
REQUIRED_COLUMNS = [c for c in COLUMNS if c not in OPTIONAL_COLUMNS]


class UnsupportedRecords(ValueError):
    """Records the model was not trained for; ``problems`` lists (record_id, reason)."""

    def __init__(self, problems: pd.DataFrame):
        self.problems = problems
        lines = [f"{row.record_id}: {row.reason}" for row in problems.head(10).itertuples()]
        more = f"\n  ... and {len(problems) - 10} more" if len(problems) > 10 else ""
        super().__init__(
            f"{problems['record_id'].nunique()} record(s) outside what the model was "
            "trained for:\n  " + "\n  ".join(lines) + more
        )


def complete_signal_table(frame: pd.DataFrame) -> pd.DataFrame:
    """A signal table with the optional columns filled in (a record of unknown health state gets
    `unknown`), checked against the signal-table contract (segments of several lengths allowed)."""
    if frame.empty:  # else every check below passes vacuously and the refusal reads "0 record(s)"
        raise SignalTableError("the signal table is empty (no rows)")
    frame = frame.copy()
    for column, default in OPTIONAL_COLUMNS.items():
        if column not in frame.columns:
            frame[column] = default
        elif column == "health_state":
            blank = frame[column].isna() | (frame[column].astype(str).str.strip() == "")
            frame.loc[blank, column] = UNKNOWN_LABEL
    if "signal" not in frame.columns:
        validate(frame, "signal table")  # names the missing columns
    frame["signal"] = [np.asarray(s, dtype=np.float32) for s in frame["signal"]]
    # every check of the contract but one length for all: records of another segment length are
    # the model's to refuse by name (SignalModel.problems)
    for _, part in frame.groupby(frame["signal"].map(len)):
        validate(part, "signal table")
    return frame[COLUMNS]


class SignalModel:
    """One fitted estimator plus its feature extraction and training domain.

    ``features``: kind ("spectrum", "statistical", a system's own family or several joined by "+"),
    channels, spectrum, statistical, defect_orders, families (a system family's params),
    feature_names (the estimator's columns, in order), and with features.healthy_reference the
    machine's healthy reference: {"condition": column, "table": {column: [...], feature: [...]}}
    (`condmon.reference`), which every record is taken against at its condition. ``domain``: fs_hz, n_samples, channels,
    speeds_rpm (every speed in its training data), speed_tolerance. ``info``: what it is (classifier,
    protocol, measured_percent, repeat, holdout, config_hash, accuracy, ...), kept for the record.
    ``system``: the system's `job_spec("measured")`, so a folder of the system's own records (its own
    file format) can be read by the system's reader. ``training_range``: {"features", "low",
    "high"}, the range of the training segments over the features the estimator uses
    (`condmon.hybrid.training_range`); a segment outside it rests on no training example,
    and the predictions say so (``outside_training``).
    """

    def __init__(
        self,
        estimator,
        features: dict,
        domain: dict,
        healthy_state: str,
        system: dict | None = None,
        info: dict | None = None,
        training_range: dict | None = None,
    ):
        self.estimator = estimator
        self.features = features
        self.domain = domain
        self.healthy_state = healthy_state
        self.system = system
        self.info = info or {}
        self.training_range = training_range

    @property
    def classes(self) -> list[str]:
        return [str(c) for c in self.estimator.classes_]

    @property
    def has_probabilities(self) -> bool:
        """Whether the estimator gives class probabilities (KNN: the neighbours' vote, the CNN
        ensemble: its members' mean); the SVM has none (SVC without probability estimates)."""
        return hasattr(self.estimator, "predict_proba")

    # -- the training domain ---------------------------------------------------------------
    def problems(self, frame: pd.DataFrame) -> pd.DataFrame:
        """(record_id, reason) of every record outside the training domain (rate, channels,
        samples per segment, speed); empty if all are inside."""
        domain, rows = self.domain, []
        speeds = np.asarray(domain["speeds_rpm"], float)
        tolerance = float(domain.get("speed_tolerance", SPEED_TOLERANCE))
        reference = self.reference()  # built once, not per record
        for record_id, records in frame.groupby("record_id", sort=True):
            fs = float(records["fs_hz"].iloc[0])
            if not np.isclose(fs, domain["fs_hz"], rtol=1e-9):
                rows.append(
                    (
                        record_id,
                        f"sampling rate {fs:g} Hz; the model was trained at {domain['fs_hz']:g} Hz",
                    )
                )
            missing = sorted(set(domain["channels"]) - set(records["channel"]))
            if missing:
                rows.append(
                    (
                        record_id,
                        f"no channel(s) {missing}; the model needs {list(domain['channels'])}",
                    )
                )
            lengths = sorted({len(s) for s in records["signal"]})
            if lengths != [domain["n_samples"]]:
                rows.append(
                    (
                        record_id,
                        f"segments of {lengths} samples; the model was trained on "
                        f"{domain['n_samples']} ({domain['n_samples'] / domain['fs_hz']:g} s)",
                    )
                )
            if reference is not None:
                condition, table = reference
                value = float(records[condition].iloc[0])
                if nearest_reference(table, [value], tolerance)[1]:
                    rows.append(
                        (
                            record_id,
                            f"{condition} {value:g}: the model's healthy reference was "
                            f"taken at {sorted(table.index.tolist())} only",
                        )
                    )
            speed = float(records["speed_rpm"].iloc[0])
            nearest = speeds[np.argmin(np.abs(speeds - speed))]
            if abs(speed - nearest) > tolerance * nearest:
                rows.append(
                    (
                        record_id,
                        f"speed {speed:g} rpm; the model was trained at "
                        f"{sorted({float(f'{s:.6g}') for s in speeds})} rpm "
                        f"(within {tolerance:.0%})",
                    )
                )
        return pd.DataFrame(rows, columns=["record_id", "reason"])

    def reference(self):
        """(condition column, reference table indexed by it) or None without a healthy reference."""
        reference = self.features.get("reference")
        if not reference:
            return None
        condition = reference["condition"]
        return condition, reference_from_table(pd.DataFrame(reference["table"]), condition)

    def check(self, frame: pd.DataFrame) -> None:
        problems = self.problems(frame)
        if len(problems):
            raise UnsupportedRecords(problems)

    # -- features and predictions ----------------------------------------------------------
    def feature_matrix(self, frame: pd.DataFrame) -> tuple[pd.DataFrame, np.ndarray]:
        """(ids, features) of a checked signal table, one row per (record, segment); where a
        feature family locates faults, `ids.attrs["fault_locations"]` holds where on the machine
        each segment's change sits (`condmon.report.fault_location`)."""
        f = self.features
        own = {}  # the system's own families (System.feature_families), loaded only when used
        if any(family not in FEATURE_FAMILIES for family in str(f["kind"]).split("+")):
            from condmon.systems import load_system

            own = load_system(self.system).feature_families()
        families, inputs = unpacked_families(f.get("families") or {})
        params = {"spectrum": f["spectrum"], "statistical": f["statistical"] or {}, **families}
        table = family_table(
            frame, f["channels"], f["kind"], params, f.get("defect_orders"), own, inputs
        )
        missing = [name for name in f["feature_names"] if name not in table.columns]
        if missing:  # a feature-code change since training: never classify other features
            raise ValueError(
                f"the features of this signal table lack {missing[:5]} that the model "
                "was trained on; is condmon newer than the model?"
            )
        ids = table[["record_id", "segment", "health_state", "speed_rpm", "load"]].copy()
        if table.attrs.get("fault_locations") is not None:
            ids.attrs["fault_locations"] = table.attrs["fault_locations"]
        x = table[f["feature_names"]].to_numpy(np.float64, copy=True)
        reference = self.reference()
        if reference is not None:  # the change since the machine was known healthy, as in training
            condition, values = reference
            nearest, _ = nearest_reference(
                values, table[condition], float(self.domain.get("speed_tolerance", SPEED_TOLERANCE))
            )
            # a family that took its reference itself (its columns are not in the table) stays
            referred = [j for j, name in enumerate(f["feature_names"]) if name in values.columns]
            x[:, referred] -= values[[f["feature_names"][j] for j in referred]].to_numpy(
                np.float64
            )[nearest]
        return ids, x.astype(np.float32)

    def predict_segments(self, frame: pd.DataFrame) -> pd.DataFrame:
        """One row per segment: record_id, segment, speed_rpm, load, true_label (the table's
        health_state), predicted_label, p_<class> (NaN without probabilities). Refuses records
        outside the training domain (UnsupportedRecords)."""
        frame = complete_signal_table(frame)
        self.check(frame)
        ids, x = self.feature_matrix(frame)
        labels = self.estimator.predict(x).astype(str)
        out = ids.rename(columns={"health_state": "true_label"}).reset_index(drop=True)
        out["predicted_label"] = labels
        if self.has_probabilities:
            probabilities = self.estimator.predict_proba(x)
        else:
            probabilities = np.full((len(x), len(self.classes)), np.nan)
        for j, label in enumerate(self.classes):
            out[f"p_{label}"] = probabilities[:, j].astype(float)
        outside = self.outside_training(x)
        if outside is not None:
            out["outside_training"] = outside
        located = ids.attrs.get("fault_locations")
        if located is not None:  # per damaged part: where the change sits, and how sure
            for part, rows in located.groupby("part", sort=False):
                at = rows.set_index(["record_id", "segment"])
                keys = pd.MultiIndex.from_frame(out[["record_id", "segment"]])
                out[f"location_{part}"] = at["position"].reindex(keys).to_numpy()
                out[f"location_share_{part}"] = at["share"].reindex(keys).to_numpy()
        out.attrs = {}
        return out

    def outside_training(self, x: np.ndarray) -> np.ndarray | None:
        """Per row of a feature matrix: whether a feature the estimator uses lies outside the
        training range; None for a model packaged without one (before it was kept)."""
        span = getattr(self, "training_range", None)  # models pickled before it existed
        if not span:
            return None
        columns = [self.features["feature_names"].index(name) for name in span["features"]]
        values = x[:, columns]
        return (
            (values < np.asarray(span["low"], np.float32))
            | (values > np.asarray(span["high"], np.float32))
        ).any(axis=1)

    def predict(self, frame: pd.DataFrame) -> np.ndarray:
        """The label of every segment, in the order of ``predict_segments``."""
        return self.predict_segments(frame)["predicted_label"].to_numpy()

    def digest(self) -> str:
        """What the model computes, as a digest: the estimator's pickle, the features and the
        domain (not ``info``: the same model trained in two runs is one model)."""
        import pickle

        digest = hashlib.sha256(pickle.dumps(self.estimator, protocol=4))
        digest.update(
            json.dumps(
                [self.features, self.domain, self.healthy_state], sort_keys=True, default=str
            ).encode()
        )
        return digest.hexdigest()[:16]


# -- per record ------------------------------------------------------------------------------


def record_predictions(segments: pd.DataFrame, classes, healthy_state: str) -> pd.DataFrame:
    """One row per record: the majority label over its segments (a tie goes to the higher mean
    probability, then the fault), each class's vote share (``vote_<class>``) and mean probability
    (``p_<class>``), n_segments, and the true label where the table gave one; with the segments'
    ``outside_training``, its share of the record's segments."""
    classes = list(classes)
    votes = pd.crosstab(
        segments["record_id"], segments["predicted_label"], normalize="index"
    ).reindex(columns=classes, fill_value=0.0)
    probabilities = segments.groupby("record_id")[[f"p_{c}" for c in classes]].mean()
    first = segments.groupby("record_id")[["speed_rpm", "load", "true_label"]].first()
    rows = []
    for record_id, share in votes.iterrows():
        p = probabilities.loc[record_id].to_numpy()
        # ties: higher mean probability, then a fault before the healthy state (a missed fault costs more)
        order = sorted(
            range(len(classes)),
            key=lambda j: (
                -share.iloc[j],
                -np.nan_to_num(p[j], nan=0.0),
                classes[j] == healthy_state,
                classes[j],
            ),
        )
        rows.append(
            {
                "record_id": record_id,
                **first.loc[record_id].to_dict(),
                "n_segments": int((segments["record_id"] == record_id).sum()),
                "predicted_label": classes[order[0]],
                **{f"vote_{c}": float(share[c]) for c in classes},
                **{f"p_{c}": float(v) for c, v in zip(classes, p)},
            }
        )
    records = pd.DataFrame(rows)
    for column in [
        c
        for c in segments.columns
        if c.startswith("location_") and not c.startswith("location_share_")
    ]:
        part = column[len("location_") :]
        named = segments.groupby("record_id")[column].agg(
            lambda v: v.mode().min() if v.notna().any() else np.nan
        )
        agreement = (
            segments.assign(named=segments["record_id"].map(named))
            .groupby("record_id")
            .apply(lambda g: float((g[column] == g["named"]).mean()), include_groups=False)
        )
        records[column] = records["record_id"].map(named)
        records[f"location_agreement_{part}"] = records["record_id"].map(agreement)
        records[f"location_share_{part}"] = records["record_id"].map(
            segments.groupby("record_id")[f"location_share_{part}"].mean()
        )
    if "outside_training" in segments:
        records["outside_training"] = records["record_id"].map(
            segments.groupby("record_id")["outside_training"].mean()
        )
    return records


def health_summary(records: pd.DataFrame, classes, healthy_state: str) -> pd.DataFrame:
    """Per record: status (``healthy`` / ``fault``), the likeliest fault and its vote share,
    the share of segments called healthy, whether the label agrees with a known truth, (where
    the model keeps its training range) the share of segments outside it: a call that rests on
    no training example, and (where a feature family locates faults) for a record called faulty
    where on each damaged part the fault sits (``location_<part>``, in the machine's own frame:
    the system's docs say what a position is), how many of its segments agree and how sure they
    are."""
    faults = [c for c in classes if c != healthy_state]
    rows = []
    for row in records.to_dict("records"):
        likeliest = (
            max(faults, key=lambda c: (row[f"vote_{c}"], np.nan_to_num(row[f"p_{c}"], nan=0.0)))
            if faults
            else None
        )
        known = row["true_label"] in classes
        rows.append(
            {
                "record_id": row["record_id"],
                "speed_rpm": row["speed_rpm"],
                "load": row["load"],
                "status": "healthy" if row["predicted_label"] == healthy_state else "fault",
                "predicted_label": row["predicted_label"],
                "confidence": row[f"vote_{row['predicted_label']}"],
                "healthy_share": row.get(f"vote_{healthy_state}", 0.0),
                "likeliest_fault": likeliest,
                "likeliest_fault_share": row[f"vote_{likeliest}"] if likeliest else np.nan,
                "n_segments": row["n_segments"],
                "true_label": row["true_label"],
                "correct": (row["predicted_label"] == row["true_label"]) if known else None,
                **(
                    {"outside_training": row["outside_training"]}
                    if "outside_training" in row
                    else {}
                ),
                # where a located fault sits on the machine (a record called healthy: none)
                **{
                    key: (value if row["predicted_label"] != healthy_state else np.nan)
                    for key, value in row.items()
                    if key.startswith("location_")
                },
            }
        )
    return pd.DataFrame(rows)


# -- MLflow ------------------------------------------------------------------------------------


def input_schema():
    """The pyfunc signature's inputs: the signal table's columns by name (``signal``: one
    segment's samples of one channel)."""
    from mlflow.types import DataType
    from mlflow.types.schema import Array, ColSpec, Schema

    return Schema(
        [
            ColSpec(DataType.string, "record_id"),
            ColSpec(DataType.long, "segment"),
            ColSpec(DataType.string, "source", required=False),
            ColSpec(DataType.string, "health_state", required=False),
            ColSpec(DataType.double, "speed_rpm"),
            ColSpec(DataType.double, "load", required=False),
            ColSpec(DataType.double, "fs_hz"),
            ColSpec(DataType.string, "channel"),
            ColSpec(Array(DataType.float), "signal"),
            ColSpec(DataType.string, "params", required=False),
        ]
    )


def output_schema(classes):
    from mlflow.types import DataType
    from mlflow.types.schema import ColSpec, Schema

    return Schema(
        [
            ColSpec(DataType.string, "record_id"),
            ColSpec(DataType.long, "segment"),
            ColSpec(DataType.string, "predicted_label"),
            *[ColSpec(DataType.double, f"p_{c}") for c in classes],
        ]
    )


def signature(model: SignalModel):
    from mlflow.models import ModelSignature

    return ModelSignature(inputs=input_schema(), outputs=output_schema(model.classes))


def _pyfunc_class():
    import mlflow.pyfunc

    class SignalModelPyfunc(mlflow.pyfunc.PythonModel):
        """A signal table in, one row per segment out (record_id, segment, predicted_label,
        p_<class>); the SignalModel's joblib file is the artifact ``signal_model``."""

        def load_context(self, context):
            import joblib

            self.model = joblib.load(context.artifacts["signal_model"])

        # typed, as MLflow asks (a DataFrame: it infers nothing from it; the signature is given)
        def predict(
            self, context, model_input: pd.DataFrame, params: dict | None = None
        ) -> pd.DataFrame:
            segments = self.model.predict_segments(pd.DataFrame(model_input))
            columns = [
                "record_id",
                "segment",
                "predicted_label",
                *[f"p_{c}" for c in self.model.classes],
            ]
            return segments[columns].astype({"segment": "int64"})

    return SignalModelPyfunc


def log_pyfunc(model_path, model: SignalModel, **options):
    """Log the SignalModel saved at ``model_path`` as an MLflow pyfunc model (``options``: name,
    run_id, params, tags, pip_requirements); returns the ModelInfo."""
    import mlflow.pyfunc

    with without_mlflow_notices():
        return mlflow.pyfunc.log_model(
            python_model=_pyfunc_class()(),
            artifacts={"signal_model": str(model_path)},
            signature=signature(model),
            **options,
        )


# What MLflow says on every model logged that does not apply here: the signature is given whole
# (`signature`), so an input example adds only a file; and the wrapper is cloudpickled as the
# SignalModel artifact is joblib-pickled, so loading either trusts the store alike (models from
# code would remove no risk). Filtered here only, by their opening words.
MLFLOW_NOTICES = ("An input example was not provided", "Passing a Python object as `python_model`")


class _MlflowNotices(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith(MLFLOW_NOTICES)


@contextmanager
def without_mlflow_notices():
    """MLflow's notices MLFLOW_NOTICES silenced (a UserWarning, a warning of mlflow.pyfunc's log)."""
    logger, notices = logging.getLogger("mlflow.pyfunc"), _MlflowNotices()
    logger.addFilter(notices)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings(
                "ignore", message=f".*{MLFLOW_NOTICES[0]}", category=UserWarning
            )
            yield
    finally:
        logger.removeFilter(notices)

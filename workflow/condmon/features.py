"""Features tables: band-averaged amplitude spectra of every channel, concatenated (the
`spectrum` family), the `statistical` family and a system's own families beside them.

The families are a registry, FEATURE_FAMILIES: {name: FeatureFamily(table function, schema of
its config section features.<name>)}. A new family is one file (its table function) plus one
registry line, ``register_feature_family(name, table, schema)``: the config then accepts
`features.kind: <name>` and `features.<name>` (condmon.config merges the schema in), and the
features stage computes it. A system adds its own beside them (`System.feature_families`).

The spectra are the input of the CFRP study's classifiers (eq. 5: FFT = [FFT_X, FFT_Y] per
sensor). `features.kind` names one family or several joined by "+" (e.g. `spectrum+order`): their
columns side by side, in that order. The features table is wide Parquet: the signal table's id
columns, then one float32 column per feature; its file metadata lists the feature columns in
order (see ARCHITECTURE.md).
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from sklearn.base import BaseEstimator, TransformerMixin

from condmon.atomic import write_table
from condmon.signals import (
    ID_COLUMNS,
    SCHEMA,
    config_hash,
    package_versions,
    read_signal_table,
    to_arrays,
)
from condmon.spectra import amplitude_spectrum, band_values
from condmon.stat_features import statistical_features_from_params

__all__ = [
    "amplitude_spectrum",
    "SpectrumFeatures",
    "compute_feature_table",
    "compute_feature_table_from_files",
    "statistical_feature_table",
    "feature_families",
    "read_feature_table",
    "write_feature_table",
    "FeatureTableError",
    "FEATURE_FAMILIES",
    "FeatureFamily",
    "register_feature_family",
    "FamilyInputs",
    "SystemFamily",
    "family_table",
]

log = logging.getLogger(__name__)

SCALES = ("linear", "log")
LOG_FLOOR = 1e-6  # added before log10 so silent bands stay finite
FEATURE_NAMES_KEY = b"condmon.feature_names"
FEATURE_KIND_KEY = b"condmon.feature_kind"
BAND_STATISTICS = ("mean", "rms")
SPECTRUM_PARAMS = ("f_min_hz", "f_max_hz", "resolution_hz", "scale", "band_statistic")


class FeatureTableError(ValueError):
    """A features table (or the request to build one) breaks the contract."""


class SpectrumFeatures(TransformerMixin, BaseEstimator):
    """Band-averaged amplitude spectra of several channels, concatenated in channel order.

    The band [f_min_hz, f_max_hz) is cut into bands `resolution_hz` wide; each feature is the mean
    amplitude of the FFT bins inside one band (so the feature count does not depend on the segment
    length). `band_statistic="rms"` takes the root mean square of the bins instead: it keeps a
    band's energy when a line is smeared over several bins (a small speed fluctuation), which
    the mean amplitude does not. `scale="log"` gives log10(amplitude + 1e-6). Stateless.
    """

    def __init__(
        self,
        channels=("A1_x", "A1_y"),
        f_min_hz: float = 0.0,
        f_max_hz: float = 1000.0,
        resolution_hz: float = 1.0,
        scale: str = "linear",
        band_statistic: str = "mean",
    ):
        self.channels = channels
        self.f_min_hz = f_min_hz
        self.f_max_hz = f_max_hz
        self.resolution_hz = resolution_hz
        self.scale = scale
        self.band_statistic = band_statistic

    # -- grid ------------------------------------------------------------------------------
    def band_centres(self) -> np.ndarray:
        """Centre frequency of every band, in Hz."""
        self._check_params()
        return self.f_min_hz + self.resolution_hz * (np.arange(self._n_bands()) + 0.5)

    def feature_names(self, fs_hz: float, n_samples: int) -> list[str]:
        """`fft_<channel>_<centre:07.1f>Hz` for every channel and band, in feature order."""
        self._check_grid(fs_hz, n_samples)
        centres = self.band_centres()
        return [
            f"fft_{channel}_{centre:07.1f}Hz" for channel in self.channels for centre in centres
        ]

    # -- sklearn API -----------------------------------------------------------------------
    def fit(self, X=None, y=None, fs_hz: float | None = None):
        self._check_params()
        return self

    def fit_transform(self, X, y=None, fs_hz: float | None = None) -> np.ndarray:
        return self.fit(X).transform(X, fs_hz)

    def transform(self, X, fs_hz: float) -> np.ndarray:
        """(n_segments, n_channels, n_samples) -> (n_segments, n_channels * n_bands) float32."""
        X = np.asarray(X)
        if X.ndim != 3:
            raise ValueError(
                f"expected an array (n_segments, n_channels, n_samples), got shape {X.shape}"
            )
        if X.shape[1] != len(self.channels):
            raise ValueError(
                f"array has {X.shape[1]} channels but SpectrumFeatures has "
                f"{len(self.channels)}: {list(self.channels)}"
            )
        n_samples = X.shape[2]
        self._check_grid(fs_hz, n_samples)
        freqs, amplitudes = amplitude_spectrum(X, fs_hz)
        bands = self._band_means(freqs, amplitudes)  # (n_segments, n_channels, n_bands)
        if self.scale == "log":
            bands = np.log10(bands + LOG_FLOOR)
        return bands.reshape(len(X), -1).astype(np.float32)

    # -- helpers ---------------------------------------------------------------------------
    def _n_bands(self) -> int:
        return int(np.floor((self.f_max_hz - self.f_min_hz) / self.resolution_hz + 1e-9))

    def _band_means(self, freqs: np.ndarray, amplitudes: np.ndarray) -> np.ndarray:
        """Mean (or RMS) amplitude of the FFT bins in every band (bands along the last axis)."""
        return band_values(
            freqs,
            amplitudes,
            self.f_min_hz,
            self.resolution_hz,
            self._n_bands(),
            self.band_statistic,
        )

    def _check_params(self) -> None:
        if len(self.channels) == 0:
            raise ValueError("SpectrumFeatures needs at least one channel")
        if self.scale not in SCALES:
            raise ValueError(f"unknown scale {self.scale!r}; choose one of {list(SCALES)}")
        if self.band_statistic not in BAND_STATISTICS:
            raise ValueError(
                f"unknown band_statistic {self.band_statistic!r}; "
                f"choose one of {list(BAND_STATISTICS)}"
            )
        if not self.resolution_hz > 0:
            raise ValueError(f"resolution_hz must be positive, got {self.resolution_hz}")
        if self.f_min_hz < 0 or self.f_max_hz <= self.f_min_hz:
            raise ValueError(
                f"need 0 <= f_min_hz < f_max_hz, got f_min_hz={self.f_min_hz}, "
                f"f_max_hz={self.f_max_hz}"
            )
        span = (self.f_max_hz - self.f_min_hz) / self.resolution_hz
        if abs(span - round(span)) > 1e-6:
            raise ValueError(
                f"f_max_hz - f_min_hz = {self.f_max_hz - self.f_min_hz} Hz is not a "
                f"whole number of resolution_hz = {self.resolution_hz} Hz bands"
            )

    def _check_grid(self, fs_hz: float, n_samples: int) -> None:
        self._check_params()
        bin_width = fs_hz / n_samples
        if self.resolution_hz < bin_width * (1 - 1e-9):
            raise ValueError(
                f"resolution_hz={self.resolution_hz} is finer than the FFT bin width "
                f"fs/n = {fs_hz}/{n_samples} = {bin_width:g} Hz; use longer segments "
                f"or a coarser resolution"
            )
        if self.f_max_hz > fs_hz / 2 * (1 + 1e-12):
            raise ValueError(
                f"f_max_hz={self.f_max_hz} is above the Nyquist frequency "
                f"{fs_hz / 2:g} Hz (fs_hz={fs_hz})"
            )


def spectrum_features_from_params(channels, spectrum_params: dict) -> SpectrumFeatures:
    """A SpectrumFeatures from the config's `spectrum` section, rejecting unknown keys."""
    unknown = sorted(set(spectrum_params) - set(SPECTRUM_PARAMS))
    if unknown:
        raise ValueError(
            f"unknown spectrum parameter(s) {unknown}; allowed: {list(SPECTRUM_PARAMS)}"
        )
    missing = [key for key in SPECTRUM_PARAMS[:3] if key not in spectrum_params]
    if missing:
        raise ValueError(f"missing spectrum parameter(s) {missing}")
    return SpectrumFeatures(channels=list(channels), **spectrum_params)


def single_sampling_rate(ids: pd.DataFrame, where: str = "signal table") -> float:
    """The one fs_hz of all segments; an error naming the records of each rate otherwise."""
    rates = ids.groupby("fs_hz")["record_id"].unique()
    if len(rates) != 1:
        detail = "; ".join(
            f"{fs:g} Hz: {sorted(map(str, recs))[:5]}" + (" ..." if len(recs) > 5 else "")
            for fs, recs in rates.items()
        )
        raise FeatureTableError(f"{where}: all segments must share one fs_hz, found {detail}")
    return float(rates.index[0])


def compute_feature_table(
    signal_frame: pd.DataFrame, channels, spectrum_params: dict
) -> pd.DataFrame:
    """Wide features table (id columns, then float32 features) of one signal table.

    One row per (record_id, segment), sorted. The feature columns are the columns after the
    ID_COLUMNS, in order (`feature_columns(frame)`).
    """
    extractor = spectrum_features_from_params(channels, spectrum_params)
    present = set(signal_frame["channel"])
    missing = [ch for ch in extractor.channels if ch not in present]
    if missing:
        raise FeatureTableError(
            f"channel(s) {missing} not in the signal table (it has {sorted(present)})"
        )
    fs_hz = single_sampling_rate(signal_frame)
    ids, arrays = to_arrays(signal_frame, extractor.channels)
    names = extractor.feature_names(fs_hz, arrays.shape[2])
    values = pd.DataFrame(extractor.transform(arrays, fs_hz), columns=names)
    return pd.concat([ids.reset_index(drop=True), values], axis=1)


def feature_families(kind: str, system_families=()) -> list[str]:
    """The families of a `features.kind` value: one of FEATURE_FAMILIES or of the system's own
    (`system_families`), or several joined by "+" (`spectrum+order`), each at most once."""
    families = str(kind).split("+")
    known = list(FEATURE_FAMILIES) + list(system_families)
    unknown = [f for f in families if f not in known]
    if unknown:
        raise FeatureTableError(
            f"features.kind {kind!r}: unknown feature famil{'ies' if len(unknown) > 1 else 'y'} "
            f"{unknown}; choose one of {known} or several joined by '+'"
        )
    if len(set(families)) != len(families):
        raise FeatureTableError(f"features.kind {kind!r}: a family appears twice")
    return families


@dataclass(frozen=True)
class FamilyInputs:
    """What a caller hands a system's own feature family at run time, apart from its settings.

    A family's settings (``features.<family>`` and what the system adds,
    `System.feature_family_params`) are the features rule's params: an edit reruns the job.
    These inputs are not settings: where each machine's healthy reference lies and how many
    cores the job has. A family reads the ones its entry declares (`SystemFamily`).

    Attributes
    ----------
    healthy_reference : dict or None
        The features job's `features.healthy_reference` (source, healthy_state, condition,
        reserve, segments_per_sample) when on: each machine's reference segments lie in the
        signal table itself (a simulated sample's healthy twin among them).
    measured_references : DataFrame or None
        The measured records' references as the measured features job wrote them (a simulated
        run's family reads what the measured ones share, e.g. their fixed tones).
    packaged_references : dict or DataFrame or None
        A packaged model's measured references (`condmon.signal_model`): new records are taken
        against them instead of a reference of their own.
    processes : int
        Worker processes the family may spread its segments over.
    """

    healthy_reference: dict | None = None
    measured_references: pd.DataFrame | None = None
    packaged_references: dict | pd.DataFrame | None = None
    processes: int = 1


@dataclass(frozen=True)
class SystemFamily:
    """A system's own feature family (`System.feature_families`): its table function and the
    run-time inputs it takes.

    Attributes
    ----------
    table : callable
        ``table(signal_frame, channels, settings, inputs)`` -> wide features table (the id
        columns, then its float32 feature columns); `settings` is features.<family> with what
        the system adds, `inputs` a `FamilyInputs`.
    references : bool
        Takes every machine against its healthy reference itself (a waveform, not a mean
        feature): the features job reads every record at once (a reference may lie in another
        file) and writes the references it returns; the reference step leaves its columns alone.
    parallel : bool
        Spreads its segments over `FamilyInputs.processes`: the features job gets every core.
    """

    table: Callable[..., pd.DataFrame]
    references: bool = False
    parallel: bool = False


def family_table(
    signal_frame: pd.DataFrame,
    channels,
    kind: str,
    family_params: dict,
    defect_orders: dict | None = None,
    system_families: dict | None = None,
    inputs: FamilyInputs | None = None,
) -> pd.DataFrame:
    """The features table of one signal table: the families of `kind` ("+" joins several,
    columns in that order) side by side, each from FEATURE_FAMILIES or the system's own
    (`system_families` = System.feature_families(): {family: SystemFamily}), each with its
    settings `family_params[family]` (features.<family>; the system's own with what it adds);
    `defect_orders`: the system's envelope lines (the statistical family's); `inputs`: what a
    system family takes at run time (references, processes), never part of its settings."""
    system_families = system_families or {}
    inputs = inputs or FamilyInputs()
    parts = []
    for family in feature_families(kind, tuple(system_families)):
        params = family_params.get(family) or {}
        if family in FEATURE_FAMILIES:
            parts.append(
                FEATURE_FAMILIES[family].table(signal_frame, channels, params, defect_orders)
            )
        else:
            parts.append(system_families[family].table(signal_frame, channels, params, inputs))
    return side_by_side(parts)


def compute_feature_table_from_files(
    paths,
    channels,
    kind: str,
    family_params: dict,
    defect_orders: dict | None = None,
    system_families: dict | None = None,
    inputs: FamilyInputs | None = None,
) -> pd.DataFrame:
    """Features of several signal tables in one table: `family_table` of each (its arguments),
    rows sorted by record and segment. Read one at a time to bound memory, unless a family of
    `kind` takes every segment against its machine's reference itself (`SystemFamily.references`;
    the reference may lie in another file, e.g. a simulated sample's healthy twin), which reads
    every record at once. The table's `attrs` carry what such a family hands on
    (`referenced_columns`, its references)."""
    system_families = system_families or {}
    families = feature_families(kind, tuple(system_families))  # an unknown family: before any read
    if not paths:
        raise FeatureTableError("no signal tables given")
    if any(family in system_families and system_families[family].references for family in families):
        log.info("%s features of %d signal tables at once", kind, len(paths))
        tables = [read_signal_table(path) for path in paths]
        frames = [
            family_table(
                pd.concat(tables, ignore_index=True),
                channels,
                kind,
                family_params,
                defect_orders,
                system_families,
                inputs,
            )
        ]
    else:
        frames = []
        for path in paths:
            log.info("%s features of %s", kind, path)
            frames.append(
                family_table(
                    read_signal_table(path),
                    channels,
                    kind,
                    family_params,
                    defect_orders,
                    system_families,
                    inputs,
                )
            )
    attrs = frames[0].attrs if len(frames) == 1 else {}
    frame = pd.concat([without_attrs(f) for f in frames], ignore_index=True)
    single_sampling_rate(frame, where="signal tables " + ", ".join(map(str, paths)))
    duplicated = frame.duplicated(["record_id", "segment"])
    if duplicated.any():
        first = frame.loc[duplicated].iloc[0]
        raise FeatureTableError(
            f"record {first.record_id!r} segment {first.segment} appears in "
            "more than one signal table"
        )
    frame = frame.sort_values(["record_id", "segment"]).reset_index(drop=True)
    frame.attrs = dict(attrs)
    return frame


def side_by_side(parts: list[pd.DataFrame]) -> pd.DataFrame:
    """The feature columns of several families' tables of one signal table, after its id columns
    (every family's rows come in the same (record_id, segment) order from `to_arrays`)."""
    ids = parts[0][ID_COLUMNS]
    for part in parts[1:]:
        if not part[ID_COLUMNS].equals(ids):  # a guard: to_arrays sorts every family alike
            raise FeatureTableError("feature families disagree on the segments' order")
    attrs = {key: value for part in parts for key, value in part.attrs.items()}
    joined = pd.concat(
        [without_attrs(ids)] + [without_attrs(part[feature_columns(part)]) for part in parts],
        axis=1,
    )
    joined.attrs = attrs
    return joined


def without_attrs(frame: pd.DataFrame) -> pd.DataFrame:
    """`frame` with empty `attrs`: pandas compares the attrs of what it concatenates, and a family's
    references (a table) cannot be compared so."""
    frame = frame.copy(deep=False)
    frame.attrs = {}
    return frame


def feature_columns(frame: pd.DataFrame) -> list[str]:
    """The feature columns of a wide features frame: everything that is not an id column."""
    return [c for c in frame.columns if c not in ID_COLUMNS]


def write_feature_table(
    frame: pd.DataFrame, feature_names, path, config: dict | None = None, kind: str = "spectrum"
) -> None:
    """Write a features table atomically; metadata lists the feature columns in order."""
    feature_names = list(feature_names)
    missing = [c for c in ID_COLUMNS + feature_names if c not in frame.columns]
    if missing:
        raise FeatureTableError(f"{path}: frame lacks column(s) {missing[:10]}")
    id_fields = [SCHEMA.field(c) for c in ID_COLUMNS]
    schema = pa.schema(id_fields + [pa.field(name, pa.float32()) for name in feature_names])
    table = pa.Table.from_pandas(
        frame[ID_COLUMNS + feature_names], schema=schema, preserve_index=False
    )
    meta = {
        FEATURE_NAMES_KEY: json.dumps(feature_names).encode(),
        FEATURE_KIND_KEY: kind.encode(),
        b"condmon.config_hash": config_hash(config or {}).encode(),
        b"condmon.package_versions": json.dumps(package_versions()).encode(),
    }
    write_table(table.replace_schema_metadata({**(table.schema.metadata or {}), **meta}), path)


def read_feature_table(path) -> tuple[pd.DataFrame, list[str]]:
    """Read a features table; returns (frame, feature names in order)."""
    try:
        table = pq.read_table(path)
    except FileNotFoundError:
        raise FeatureTableError(f"{path}: no such features table") from None
    except Exception as exc:  # pyarrow raises several types for corrupt files
        raise FeatureTableError(f"{path}: not a readable Parquet file ({exc})") from exc
    meta = table.schema.metadata or {}
    if FEATURE_NAMES_KEY not in meta:
        raise FeatureTableError(
            f"{path}: no {FEATURE_NAMES_KEY.decode()} metadata; not a features table"
        )
    feature_names = json.loads(meta[FEATURE_NAMES_KEY])
    missing = [c for c in ID_COLUMNS + feature_names if c not in table.column_names]
    if missing:
        raise FeatureTableError(f"{path}: missing column(s) {missing[:10]}")
    return table.to_pandas(), feature_names


def statistical_feature_table(
    signal_frame, channels, params: dict, defect_orders: dict | None = None
):
    """Wide features table of one signal table: per channel, the statistical and envelope
    features (columns `<channel>_<feature>`; envelope lines at the system's `defect_orders`,
    none without), kept to `params["names"]` (feature names without
    the channel prefix; None = all); those in `params["log_names"]` as their natural log
    (columns `<channel>_log_<feature>`, floored at 1e-12). Envelope features use each segment's
    stored speed."""
    present = set(signal_frame["channel"])
    missing = [ch for ch in channels if ch not in present]
    if missing:
        raise FeatureTableError(
            f"channel(s) {missing} not in the signal table (it has {sorted(present)})"
        )
    fs_hz = single_sampling_rate(signal_frame)
    ids, arrays = to_arrays(signal_frame, list(channels))
    wanted = params.get("names")
    logged = set(params.get("log_names") or [])
    columns = {}
    for c, channel in enumerate(channels):
        extractor = statistical_features_from_params(params, fs_hz, defect_orders=defect_orders)
        names = list(extractor.get_feature_names_out())
        unknown = sorted((set(wanted or []) | logged) - set(names))
        if unknown:
            raise FeatureTableError(
                f"features.statistical.names: unknown feature(s) {unknown}; choose among {names}"
            )
        values = extractor.fit_transform(arrays[:, c, :], speed_rpm=ids["speed_rpm"].to_numpy())
        for j, name in enumerate(names):
            if wanted is not None and name not in wanted:
                continue
            if name in logged:
                columns[f"{channel}_log_{name}"] = np.log(np.maximum(values[:, j], 1e-12))
            else:
                columns[f"{channel}_{name}"] = values[:, j]
    return pd.concat([ids.reset_index(drop=True), pd.DataFrame(columns)], axis=1)


# --------------------------------------------------------------------------- the registry


@dataclass(frozen=True)
class FeatureFamily:
    """One registry entry: the family's table function and its config section's schema."""

    # (signal frame, channels, features.<name>, the system's defect orders or None) -> wide
    # features table: the signal table's id columns, then the family's float32 feature columns
    table: Callable[..., pd.DataFrame]
    # JSON schema of features.<name>, with its defaults (None: config/schema.yaml holds the
    # section, as for the built-in spectrum and statistical families)
    schema: dict | None = None


def _spectrum_table(signal_frame, channels, params: dict, defect_orders=None) -> pd.DataFrame:
    return compute_feature_table(signal_frame, channels, params)


FEATURE_FAMILIES: dict[str, FeatureFamily] = {
    "spectrum": FeatureFamily(_spectrum_table),
    "statistical": FeatureFamily(statistical_feature_table),
}


def register_feature_family(
    name: str, table: Callable[..., pd.DataFrame], schema: dict | None = None
) -> FeatureFamily:
    """Add a feature family (an existing name is an error, not a silent override); `schema`:
    its section features.<name> (an object schema with defaults)."""
    if name in FEATURE_FAMILIES:
        raise ValueError(f"feature family {name!r} is already registered")
    if "+" in name or not name:
        raise ValueError(f"feature family {name!r}: a name without '+'")
    FEATURE_FAMILIES[name] = FeatureFamily(table, schema)
    return FEATURE_FAMILIES[name]


def config_schema() -> dict:
    """The schema fragment of the registered families' own sections (features.<name>), to merge
    into the shared schema (condmon.schema.merge_schema)."""
    return {
        "properties": {
            "features": {
                "properties": {
                    name: family.schema
                    for name, family in FEATURE_FAMILIES.items()
                    if family.schema
                }
            }
        }
    }

"""The signal table: one Parquet format for measured and simulated vibration records.

Long form, one row per record segment and channel (see ARCHITECTURE.md, "Signal table").
Writing is atomic (temporary file, then rename) so a killed job never leaves a table that a
later stage could read as complete.
"""

from __future__ import annotations

import hashlib
import json
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from condmon.atomic import write_table

SOURCES = ("measured", "virtual_bench", "simulated")

SCHEMA = pa.schema(
    [
        ("record_id", pa.string()),
        ("segment", pa.int32()),
        ("source", pa.string()),
        ("health_state", pa.string()),
        ("speed_rpm", pa.float64()),
        ("load", pa.float64()),
        ("fs_hz", pa.float64()),
        ("channel", pa.string()),
        ("signal", pa.list_(pa.float32())),
        ("params", pa.string()),
    ]
)
COLUMNS = SCHEMA.names
ID_COLUMNS = ["record_id", "segment", "source", "health_state", "speed_rpm", "load", "fs_hz"]
# Optional columns of a user's measured table: each record's specimen (one physical fault, e.g. a
# damaged part, recorded at every condition) and its group (e.g. the fault size), for specimen_holdout;
# they go to measured/records.csv, not to the signal table the stages read.
SPECIMEN_COLUMNS = ["specimen", "specimen_group"]


class SignalTableError(ValueError):
    """A signal table (or a file claimed to be one) breaks the contract."""


def config_hash(config: dict) -> str:
    """Short stable hash of a (JSON-serialisable) config section."""
    text = json.dumps(config, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def package_versions(names=("numpy", "scipy", "exudyn", "pyarrow", "scikit-learn")) -> dict:
    versions = {}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def make_rows(
    record_id,
    source,
    health_state,
    speed_rpm,
    load,
    fs_hz,
    channels: dict,
    segment_length: int | None = None,
    params: dict | None = None,
    segment_hop: int | None = None,
) -> list[dict]:
    """Rows for one record: `channels` maps channel name to a 1-D signal (m/s^2).

    With `segment_length`, each channel is cut into segments starting every `segment_hop`
    samples (default: the segment length, no overlap; half of it: 50 % overlap); the tail
    shorter than one segment is dropped. Without it the record is one segment.
    """
    params_json = json.dumps(params, sort_keys=True) if params else ""
    rows = []
    for channel, signal in channels.items():
        signal = np.asarray(signal, dtype=np.float32)
        n = segment_length or len(signal)
        hop = segment_hop or n
        n_segments = (len(signal) - n) // hop + 1 if len(signal) >= n else 0
        if n_segments == 0:
            raise SignalTableError(
                f"record {record_id!r} channel {channel!r}: {len(signal)} samples, "
                f"shorter than one segment ({n})"
            )
        for seg in range(n_segments):
            rows.append(
                dict(
                    record_id=record_id,
                    segment=seg,
                    source=source,
                    health_state=health_state,
                    speed_rpm=float(speed_rpm),
                    load=float(load),
                    fs_hz=float(fs_hz),
                    channel=channel,
                    signal=signal[seg * hop : seg * hop + n],
                    params=params_json,
                )
            )
    return rows


def write_signal_table(rows, path, config: dict | None = None) -> None:
    """Validate and write rows (list of dicts or DataFrame) atomically to `path`."""
    frame = pd.DataFrame(rows, columns=COLUMNS) if not isinstance(rows, pd.DataFrame) else rows
    validate(frame, str(path))
    table = pa.Table.from_pandas(frame[COLUMNS], schema=SCHEMA, preserve_index=False)
    meta = {
        b"condmon.config_hash": config_hash(config or {}).encode(),
        b"condmon.package_versions": json.dumps(package_versions()).encode(),
    }
    table = table.replace_schema_metadata({**(table.schema.metadata or {}), **meta})
    write_table(table, path)


def read_signal_table(path, allowed_sources=SOURCES) -> pd.DataFrame:
    """Read and validate a signal table; `signal` comes back as float32 numpy arrays."""
    frame = read_unvalidated(path)
    validate(frame, str(path), allowed_sources)
    return frame


def read_unvalidated(path, required=COLUMNS) -> pd.DataFrame:
    """The rows of a signal-table file, checked only for being one (exists, Parquet, the
    ``required`` columns); `signal` as float32 arrays (empty for a null)."""
    path = Path(path)
    if not path.exists():
        raise SignalTableError(f"{path}: no such signal table")
    try:
        table = pq.read_table(path)
    except Exception as exc:  # pyarrow raises several types for corrupt files
        raise SignalTableError(f"{path}: not a readable Parquet file ({exc})") from exc
    missing = [c for c in required if c not in table.column_names]
    if missing:
        raise SignalTableError(f"{path}: missing signal-table columns {missing}")
    frame = table.to_pandas()
    frame["signal"] = [
        np.asarray([] if s is None else s, dtype=np.float32) for s in frame["signal"]
    ]
    return frame


def validate(frame: pd.DataFrame, where: str, allowed_sources=SOURCES) -> None:
    """Check the contract: columns, sources, labels, rates, equal lengths, finite samples."""
    missing = [c for c in COLUMNS if c not in frame.columns]
    if missing:
        raise SignalTableError(f"{where}: missing columns {missing}")
    if frame.empty:
        raise SignalTableError(f"{where}: the signal table has no rows")
    bad_source = sorted(set(frame["source"]) - set(allowed_sources))
    if bad_source:
        raise SignalTableError(f"{where}: source {bad_source} not in {list(allowed_sources)}")
    for column in ("record_id", "health_state", "channel"):
        empty = frame[column].isna() | (frame[column].astype(str).str.strip() == "")
        if empty.any():
            raise SignalTableError(f"{where}: empty {column} in {int(empty.sum())} rows")
    for column in ("speed_rpm", "fs_hz"):
        values = pd.to_numeric(frame[column], errors="coerce")
        if not (np.isfinite(values) & (values > 0)).all():
            raise SignalTableError(f"{where}: {column} must be a positive number in every row")
    dup = frame.duplicated(["record_id", "segment", "channel"])
    if dup.any():
        first = frame.loc[dup].iloc[0]
        raise SignalTableError(
            f"{where}: duplicate row for record {first.record_id!r} "
            f"segment {first.segment} channel {first.channel!r}"
        )
    for record_id, rows in frame.groupby("record_id", sort=False):
        for column in ("health_state", "speed_rpm", "fs_hz", "source"):
            if rows[column].nunique() != 1:
                raise SignalTableError(f"{where}: record {record_id!r} mixes several {column}")
    lengths = set()
    for row in frame.itertuples(index=False):
        signal = np.asarray(row.signal)
        if signal.ndim != 1 or len(signal) == 0:
            raise SignalTableError(
                f"{where}: record {row.record_id!r} channel {row.channel!r} "
                f"segment {row.segment}: empty signal"
            )
        if not np.isfinite(signal).all():
            raise SignalTableError(
                f"{where}: record {row.record_id!r} channel {row.channel!r} "
                f"segment {row.segment}: non-finite samples (NaN or inf)"
            )
        lengths.add(len(signal))
    if len(lengths) > 1:
        raise SignalTableError(
            f"{where}: segments differ in length {sorted(lengths)}; "
            "all segments of a table must have the same number of samples"
        )


def to_arrays(frame: pd.DataFrame, channels) -> tuple[pd.DataFrame, np.ndarray]:
    """Pivot long rows to one row per (record_id, segment).

    Returns the id frame and a float32 array of shape (n_segments, n_channels, n_samples),
    channels in the given order. Raises if a segment lacks a channel.
    """
    ids = (
        frame[ID_COLUMNS]
        .drop_duplicates(["record_id", "segment"])
        .sort_values(["record_id", "segment"])
        .reset_index(drop=True)
    )
    by_key = {(r.record_id, r.segment, r.channel): r.signal for r in frame.itertuples(index=False)}
    n_samples = len(frame["signal"].iloc[0])
    out = np.empty((len(ids), len(channels), n_samples), dtype=np.float32)
    for i, (rid, seg) in enumerate(zip(ids["record_id"], ids["segment"])):
        for j, ch in enumerate(channels):
            try:
                out[i, j] = by_key[(rid, seg, ch)]
            except KeyError:
                raise SignalTableError(f"record {rid!r} segment {seg}: no channel {ch!r}") from None
    return ids, out

"""Measured stage: a user's own signal table, checked against the system before it is used."""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd

from condmon.signals import (
    COLUMNS,
    SPECIMEN_COLUMNS,
    SignalTableError,
    read_unvalidated,
    validate,
)

log = logging.getLogger(__name__)
# the columns a user's table must have: `params` (a simulated sample's parameters) may be absent
USER_COLUMNS = [column for column in COLUMNS if column != "params"]


ON_BAD_RECORD = ("stop", "skip")
SKIPPED_COLUMNS = ["record_id", "health_state", "speed_rpm", "load", "reason"]


def read_user_table(
    path, health_states, channels, fs_hz: float, segment_seconds: float, on_bad_record: str = "stop"
) -> pd.DataFrame:
    """A user's measured signal table, checked against the run's labels, channels, sampling rate
    and segment length (simulated segments have that length; features must compare alike).

    The kept records only; with `on_bad_record="skip"` the skipped ones are logged as warnings
    (use `read_user_table_checked` to get their list)."""
    frame, skipped = read_user_table_checked(
        path, health_states, channels, fs_hz, segment_seconds, on_bad_record=on_bad_record
    )
    return frame


def read_user_table_checked(
    path, health_states, channels, fs_hz: float, segment_seconds: float, on_bad_record: str = "stop"
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """`read_user_table` plus the records left out: (kept rows, skipped records).

    File-level problems always stop with a `SignalTableError` naming the file: no such file, not
    a readable (or a truncated) Parquet file, missing columns, a source other than `measured`,
    health states outside the config's, duplicate rows. Record-level problems (`record_problems`:
    a required channel missing, NaN/inf or empty samples, a sampling rate other than `fs_hz`,
    segments of another length than `segment_seconds` at `fs_hz` (a record shorter than one
    segment), a constant (dead) channel) stop with the file, the record and the reason, or with
    `on_bad_record="skip"` leave the record out: it is listed in the second frame (columns
    `record_id, health_state, speed_rpm, load, reason`) and logged. No record left is an error.
    """
    if on_bad_record not in ON_BAD_RECORD:
        raise ValueError(f"on_bad_record={on_bad_record!r}; choose one of {list(ON_BAD_RECORD)}")
    frame = read_unvalidated(path, USER_COLUMNS)
    if "params" not in frame:  # a simulated sample's parameters: nothing of a measured record
        frame["params"] = ""
    if frame.empty:
        raise SignalTableError(f"{path}: the signal table has no rows")
    for column in SPECIMEN_COLUMNS:  # optional; where given, one value per record
        mixed = (
            frame.groupby("record_id")[column].nunique(dropna=False) > 1 if column in frame else []
        )
        if any(mixed):
            raise SignalTableError(
                f"{path}: record {mixed[mixed].index[0]!r} mixes several {column} values"
            )
    labels = frame["health_state"].dropna().astype(str)
    unknown = sorted(set(labels) - set(health_states))
    if unknown:
        raise SignalTableError(
            f"{path}: health states {unknown} are not in the config's "
            f"health_states {list(health_states)}"
        )
    problems = record_problems(frame, channels, fs_hz, segment_seconds)
    if problems and on_bad_record == "stop":
        (record_id, reason), more = next(iter(problems.items())), len(problems) - 1
        others = f" (and {more} more bad record(s): {list(problems)[1:6]})" if more else ""
        raise SignalTableError(f"{path}: record {record_id!r}: {reason}{others}")
    kept = frame[~frame["record_id"].isin(list(problems))].reset_index(drop=True)
    if problems and kept.empty:
        raise SignalTableError(
            f"{path}: every record is bad, none left to use: "
            + "; ".join(f"{r!r}: {why}" for r, why in problems.items())
        )
    validate(kept, str(path), allowed_sources=("measured",))  # the contract for what is kept
    first = frame.drop_duplicates("record_id").set_index("record_id")
    skipped = pd.DataFrame(
        [
            dict(
                record_id=r,
                health_state=first.at[r, "health_state"],
                speed_rpm=first.at[r, "speed_rpm"],
                load=first.at[r, "load"],
                reason=why,
            )
            for r, why in problems.items()
        ],
        columns=SKIPPED_COLUMNS,
    )
    for row in skipped.itertuples(index=False):
        log.warning("%s: record %r skipped: %s", path, row.record_id, row.reason)
    return kept, skipped


def record_problems(frame: pd.DataFrame, channels, fs_hz: float, segment_seconds: float) -> dict:
    """record_id -> the reason it cannot be used (first problem found), for the bad records of a
    signal table, in table order."""
    samples = int(round(segment_seconds * fs_hz))
    problems = {}
    for record_id, rows in frame.groupby("record_id", sort=False):
        reason = _record_problem(rows, channels, fs_hz, segment_seconds, samples)
        if reason:
            problems[record_id] = reason
    return problems


def _record_problem(rows, channels, fs_hz, segment_seconds, samples) -> str | None:
    missing = sorted(set(channels) - set(rows["channel"]))
    if missing:
        return f"channels {missing} used by the features are missing"
    rates = sorted(set(pd.to_numeric(rows["fs_hz"], errors="coerce")))
    if rates != [float(fs_hz)]:
        return f"sampling rate {rates} Hz differs from the config's output_rate_hz {fs_hz} Hz"
    for row in rows.itertuples(index=False):
        if row.signal.ndim != 1 or len(row.signal) == 0:
            return f"channel {row.channel!r} segment {row.segment}: empty signal"
        bad = ~np.isfinite(row.signal)
        if bad.any():
            return (
                f"channel {row.channel!r} segment {row.segment}: {int(bad.sum())} non-finite "
                f"samples (NaN or inf), first at index {int(np.flatnonzero(bad)[0])}"
            )
    lengths = sorted({len(s) for s in rows["signal"]})
    if lengths != [samples]:
        short = " (shorter than one segment)" if max(lengths) < samples else ""
        return (
            f"segments have {lengths} samples{short}; rig.segment_seconds = "
            f"{segment_seconds} s at {fs_hz} Hz needs {samples}: cut the records to that length"
        )
    used = rows[rows["channel"].isin(list(channels))]
    segments = {ch: set(r["segment"]) for ch, r in used.groupby("channel")}
    every = set().union(*segments.values())
    for channel in channels:
        if segments[channel] != every:
            return f"channel {channel!r} lacks segment(s) {sorted(every - segments[channel])}"
    for channel, signals in used.groupby("channel", sort=False):
        if max(float(np.ptp(s)) for s in signals["signal"]) == 0.0:
            return f"channel {channel!r} is constant (dead sensor)"
    return None

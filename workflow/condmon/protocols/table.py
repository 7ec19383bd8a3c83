"""A protocol's split table: its splits, with the calibration set and the simulated validation
set around them (see condmon.hybrid for the table's format and the measured layout)."""

from __future__ import annotations

import logging

import pandas as pd

from condmon.hybrid import (
    BLOCK_MARK,
    CALIBRATION,
    RESERVE_KEY,
    SHARE_KEY,
    SIMULATED_VALIDATION,
    SPLIT_COLUMNS,
    WHOLE_RECORD,
    SplitError,
    measured_layout,
    simulated_validation_records,
    typed_splits,
    unique_records,
)
from condmon.labels import holdout_label
from condmon.protocols.base import Protocol
from condmon.protocols.registry import make_protocol

log = logging.getLogger(__name__)

REASON = "reason"  # why a row has its role: make_splits(..., reasons=True) only, never written
KEYS = ["measured_percent", "repeat", "holdout"]


def make_splits(
    records: pd.DataFrame,
    protocol: Protocol | str,
    *,
    simulated_records: pd.DataFrame | None = None,
    simulated_validation_share: float = 0.0,
    reserve: dict | None = None,
    segment_samples: tuple[int, int] | None = None,
    reasons: bool = False,
    **params,
) -> pd.DataFrame:
    """The split table of one protocol (columns SPLIT_COLUMNS, plus `reason` with
    `reasons=True`): one row per record, or per segment for segment_share and records cut in
    time, and split.

    `protocol`: a Protocol, or a registered name with its parameters as `params`
    (make_protocol). `records`: record_id, health_state and the protocol's condition column,
    one or more rows per record (segment_share and `reserve` need the `segment` column).
    `simulated_records` (same columns) and `simulated_validation_share` > 0: the held-out
    simulated records (simulated_validation_records) join every split with role
    "simulated_validation"; with share 0 the table is exactly the measured one.
    `reserve` (calibration.reserve): the calibration set and the time blocks of lone healthy
    records (measured_layout); calibration segments get the role "calibration" and guard gaps
    "unused" in every split, blocks are split like records. `segment_samples`: (segment length,
    hop) of the measured segments in samples: a record split in time is refused where its guard
    gap is shorter than one segment (`time_blocks`). With the protocol's `healthy_state` every
    test set must hold healthy data (check_healthy_tested).
    """
    if isinstance(protocol, str):
        protocol = make_protocol(protocol, **params)
    elif params:
        raise TypeError(f"parameters {sorted(params)} go with a protocol name, not {protocol!r}")
    condition, healthy_state = protocol.condition, protocol.healthy_state
    layout = None
    if reserve is not None:
        if "segment" not in records.columns:
            raise SplitError("calibration.reserve needs the segment column of the measured records")
        layout = measured_layout(records, healthy_state, condition, reserve, segment_samples)
        free = layout[layout["fixed_role"] == ""]
        records = free if protocol.unit == "segment" else free.assign(record_id=free["unit"])
        records = records.rename(columns={"condition": condition})
    units = unique_records(records, condition)
    held_out = []
    if simulated_validation_share:
        if simulated_records is None:
            raise SplitError(
                f"{SHARE_KEY} = {simulated_validation_share} needs the simulated records"
            )
        held_out = simulated_validation_records(
            simulated_records, simulated_validation_share, protocol.seed, condition
        )
        both = sorted(set(held_out) & set(units["record_id"]))
        if both:
            raise SplitError(f"record id(s) {both[:5]} are both measured and simulated")
    rows = [row for split in protocol.split(records) for row in split.rows()]
    splits = _frame(rows, protocol.name)
    if layout is not None:
        splits = with_layout(
            splits, layout, {str(r) for r in reserve.get("records") or []}, condition
        )
    if healthy_state is not None:
        check_healthy_tested(splits, units, healthy_state)
    splits = with_simulated_validation(splits, held_out)
    return splits if reasons else splits.drop(columns=REASON)


def _frame(rows, protocol: str) -> pd.DataFrame:
    """Rows (percent, repeat, holdout, record_id, segment, role, reason) as a split table."""
    splits = pd.DataFrame(rows, columns=SPLIT_COLUMNS[1:] + [REASON])
    splits.insert(0, "protocol", protocol)
    return typed_splits(splits)


def with_layout(
    splits: pd.DataFrame, layout: pd.DataFrame, listed: set, condition: str
) -> pd.DataFrame:
    """Time blocks back to their record's segments, and the calibration and guard segments
    (measured_layout's fixed roles) added to every split."""
    blocks = layout[layout["unit"] != layout["record_id"]]
    segments_of = {u: g for u, g in blocks.groupby("unit")}
    rows = []
    for row in splits.itertuples(index=False):
        if row.record_id in segments_of:
            part = segments_of[row.record_id]
            rows += [
                (
                    row.measured_percent,
                    row.repeat,
                    row.holdout,
                    rid,
                    seg,
                    row.role,
                    f"time block {row.record_id}: {row.reason}",
                )
                for rid, seg in zip(part["record_id"], part["segment"])
            ]
        else:
            rows.append(tuple(row)[1:])
    fixed = layout[layout["fixed_role"] != ""]
    reasons = fixed_reasons(layout, listed, condition)
    keys = splits[KEYS].drop_duplicates()
    rows += [
        (p, r, h, rid, seg, role, why)
        for p, r, h in keys.itertuples(index=False)
        for rid, seg, role, why in zip(
            fixed["record_id"], fixed["segment"], fixed["fixed_role"], reasons
        )
    ]
    return _frame(rows, str(splits["protocol"].iloc[0]))


def fixed_reasons(layout: pd.DataFrame, listed: set, condition: str) -> list[str]:
    """Why each segment with a fixed role (calibration, unused) has it, in layout order
    (`listed`: the records calibration.reserve lists)."""
    cut = set(layout.loc[layout["unit"] != layout["record_id"], "record_id"])
    last_block = layout[layout["unit"] != layout["record_id"]].groupby("record_id")["segment"].max()
    reasons = []
    fixed = layout[layout["fixed_role"] != ""]
    for rid, seg, health, value, role in zip(
        fixed["record_id"],
        fixed["segment"],
        fixed["health_state"],
        fixed["condition"],
        fixed["fixed_role"],
    ):
        if role == CALIBRATION and rid in cut:
            reasons.append(f"calibration block of the lone {health} record ({RESERVE_KEY})")
        elif role == CALIBRATION:
            reasons.append(
                f"calibration record listed in {RESERVE_KEY}.records"
                if rid in listed
                else f"calibration record of {health} at {holdout_label(value, condition)}"
            )
        elif rid in cut and seg > last_block.get(rid, seg):
            reasons.append("left over after the last time block")
        else:
            reasons.append("guard gap before a time block")
    return reasons


def check_healthy_tested(splits: pd.DataFrame, units: pd.DataFrame, healthy_state: str) -> None:
    """Every split tests healthy data, or an error naming the first that does not (a warning
    when no measured record is healthy: false alarms cannot be measured at all)."""
    healthy = {
        r.partition(BLOCK_MARK)[0]
        for r in units.loc[units["health_state"] == healthy_state, "record_id"]
    }
    if not healthy:
        log.warning("no measured %r record: no test set measures false alarms", healthy_state)
        return
    tested = splits[(splits["role"] == "test") & splits["record_id"].isin(healthy)]
    keys = splits[KEYS].drop_duplicates()
    covered = set(tested[KEYS].itertuples(index=False, name=None))
    for key in keys.itertuples(index=False, name=None):
        if key not in covered:
            raise SplitError(
                f"split (measured_percent, repeat, holdout) = {key} of protocol "
                f"{splits['protocol'].iloc[0]!r} tests no {healthy_state!r} data"
            )


def with_simulated_validation(splits: pd.DataFrame, held_out) -> pd.DataFrame:
    """`splits` plus one row per held-out simulated record (whole record, role
    "simulated_validation") in every (measured_percent, repeat, holdout); unchanged without any."""
    held_out = sorted(held_out)
    if not held_out:
        return splits
    keys = splits[KEYS].drop_duplicates()
    rows = [
        (
            percent,
            repeat,
            holdout,
            rid,
            WHOLE_RECORD,
            SIMULATED_VALIDATION,
            f"simulated validation record ({SHARE_KEY})",
        )
        for percent, repeat, holdout in keys.itertuples(index=False)
        for rid in held_out
    ]
    added = _frame(rows, str(splits["protocol"].iloc[0]))
    return typed_splits(pd.concat([splits, added], ignore_index=True))

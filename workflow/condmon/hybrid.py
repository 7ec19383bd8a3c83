"""Hybrid training sets: which measured records join the simulated ones in training.

A split table lists, per (measured_percent, repeat, holdout), the role of every measured record
(see ARCHITECTURE.md, "Split table"), or of every segment (`segment` >= 0) for segment_share;
`segment` = -1 means the whole record. Simulated records always train, except those held out as
the simulated validation set (`simulated_validation_share` > 0): only these are listed, with role
"simulated_validation" (whole records), in every split; an unlisted simulated record trains.

An operating condition is the value of the `condition` column (speed_rpm on the gear bench,
load on the CWRU rig, whose records at one load differ by a few rpm). Strata are
(health_state x condition).

The split table's format (SPLIT_SCHEMA, roles, validate/read/write), the measured layout (the
calibration set, time blocks of a lone healthy record: measured_layout, calibration_frame) and
the simulated validation set live here; the protocols that fill the table, one file each, and
`make_splits` are in condmon.protocols (a Protocol's `split` says why each record is where it is).

The record order within a stratum is a random permutation seeded by (seed, repeat, stratum) only
(condmon.protocols.base.stratum_orders), and the first n_train records of it train. So a higher
percentage's training set contains the lower one's (nested shares), and the protocols draw the
same records from a stratum.

Simulated validation (the CFRP study's 70/30 split of the simulated data): per simulated stratum
(health_state x condition) round(share x n) whole records, drawn by a permutation seeded by
(seed, stratum) only, so the held-out set is the same for every protocol, measured percentage,
repeat and holdout (and a larger share holds out a superset). Every stratum must keep at least
one simulated training record.
"""

from __future__ import annotations

import logging
import math

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from condmon.atomic import write_table
from condmon.labels import format_speed, sorted_holdouts
from condmon.seeds import derive_seed, stable_int

log = logging.getLogger(__name__)

CONDITIONS = ("speed_rpm", "load")
WHOLE_RECORD = -1
# a simulated record held out of training as the simulated validation set (the only role, and the
# only rows, of simulated records in a split table)
SIMULATED_VALIDATION = "simulated_validation"
SHARE_KEY = "hybrid.simulated_validation_share"
# measured segments that calibrate the model: never trained on, never tested
CALIBRATION = "calibration"
ROLES = ("train", "test", "unused", SIMULATED_VALIDATION, CALIBRATION)
SPLIT_SCHEMA = pa.schema(
    [
        ("protocol", pa.string()),
        ("measured_percent", pa.int32()),
        ("repeat", pa.int32()),
        ("holdout", pa.string()),
        ("record_id", pa.string()),
        ("segment", pa.int32()),  # WHOLE_RECORD, or one segment (segment_share)
        ("role", pa.string()),
    ]
)
SPLIT_COLUMNS = SPLIT_SCHEMA.names


class SplitError(ValueError):
    """A split request or split table breaks the contract."""


def n_train_records(n_records: int, percent: float, min_test_records: int) -> int:
    """floor(p/100 * n + 0.5), leaving at least `min_test_records` records (never below 0)."""
    wanted = math.floor(percent / 100.0 * n_records + 0.5)
    return max(0, min(wanted, n_records - min_test_records))


def unique_records(
    records: pd.DataFrame, condition: str = "speed_rpm", what: str = "measured"
) -> pd.DataFrame:
    """One row per record_id (per-segment rows are fine) with its health_state and condition
    (renamed `condition`); each record has one of each. `what` names the records in errors."""
    if condition not in CONDITIONS:
        raise SplitError(f"unknown condition {condition!r}; choose one of {list(CONDITIONS)}")
    missing = [c for c in ("record_id", "health_state", condition) if c not in records.columns]
    if missing:
        raise SplitError(f"{what} records lack column(s) {missing}")
    records = records[["record_id", "health_state", condition]].drop_duplicates()
    mixed = records["record_id"][records["record_id"].duplicated()]
    if len(mixed):
        raise SplitError(
            f"record(s) {sorted(set(mixed))[:5]} have several health_state or {condition} values"
        )
    if records.empty:
        raise SplitError(f"no {what} records to split")
    records = records.rename(columns={condition: "condition"}).astype(
        {"record_id": str, "health_state": str, "condition": float}
    )
    return records.sort_values("record_id").reset_index(drop=True)


# -- the calibration set, time blocks, specimens -------------------------------------------
RESERVE_KEY = "calibration.reserve"
BLOCK_MARK = "@block"  # the split unit of a record's time block: "<record_id>@block<k>"


def measured_layout(
    segments: pd.DataFrame,
    healthy_state: str | None,
    condition: str,
    reserve: dict,
    segment_samples: tuple[int, int] | None = None,
) -> pd.DataFrame:
    """Per measured segment: the split unit it belongs to and a fixed role.

    Columns record_id, segment, health_state, condition, unit, fixed_role: CALIBRATION (the
    calibration set: never trained on, never tested), "unused" (a guard gap) or "" (the
    protocol decides, per unit). `reserve` is calibration.reserve:
    - `records` listed: those healthy records, whole, are the calibration set;
    - none listed, several healthy records: per condition the first `healthy_records` (by id;
      default 1, at most all but one) of several calibrate, whole; where no condition has
      several (CWRU's full set: one per load), the first overall does; every other healthy
      record is a whole split unit, so healthy test data come from records the calibration
      never saw;
    - one healthy record: it is split in time: its first `calibration_segments` segments
      calibrate, then `blocks` blocks of equal length follow, each after a guard gap of
      `guard_segments`; every block is a split unit (a record to the protocols), so healthy
      data can train and test without a segment on both sides. With `segment_samples`
      (length, hop) a guard gap shorter than one segment in samples is refused (`time_blocks`);
    - `each_condition` (every condition takes its segments against calibration records of its
      own: the healthy reference): a condition with one healthy record has that record split
      in time, whatever the other conditions hold, rather than the first overall calibrating.
    - `fault_states` (calibration.per_state.states): per condition the first (by id) of each
      listed fault state's records tunes that state's model, whole; the state needs two records
      or more at every condition it has, so the others test.
    The same table rows in, the same layout out: the calibrate and hybrid jobs agree.
    """
    missing = [
        c for c in ("record_id", "segment", "health_state", condition) if c not in segments.columns
    ]
    if missing:
        raise SplitError(f"{RESERVE_KEY}: the measured records lack column(s) {missing}")
    frame = (
        segments[["record_id", "segment", "health_state", condition]]
        .drop_duplicates(["record_id", "segment"])
        .rename(columns={condition: "condition"})
        .astype({"record_id": str, "segment": int, "health_state": str, "condition": float})
        .sort_values(["record_id", "segment"])
        .reset_index(drop=True)
    )
    frame["unit"] = frame["record_id"]
    frame["fixed_role"] = ""
    _reserve_fault_records(
        frame, [str(s) for s in reserve.get("fault_states") or []], healthy_state
    )
    listed = [str(r) for r in reserve.get("records") or []]
    if listed:
        unknown = sorted(set(listed) - set(frame["record_id"]))
        if unknown:
            raise SplitError(f"{RESERVE_KEY}.records: {unknown} are not measured records")
        labels = frame.drop_duplicates("record_id").set_index("record_id")["health_state"]
        faulty = [r for r in listed if labels[r] != healthy_state]
        if faulty:
            raise SplitError(
                f"{RESERVE_KEY}.records: {faulty} are not {healthy_state!r} "
                "records; only healthy records calibrate"
            )
        frame.loc[frame["record_id"].isin(listed), "fixed_role"] = CALIBRATION
        return frame
    if healthy_state is None:
        raise SplitError(f"{RESERVE_KEY} needs the healthy state")
    healthy = frame[frame["health_state"] == healthy_state]
    ids = sorted(healthy["record_id"].unique())
    # the first `healthy_records` of several healthy records of a condition calibrate (the gear
    # bench: one or two per speed), at least one left to test; with one healthy record per
    # condition (CWRU: one per load), the first overall
    per_condition = int(reserve.get("healthy_records", 1))
    calibrating, lone = [], []
    for _, group in healthy.groupby("condition", sort=True)["record_id"]:
        records = sorted(group.unique())
        calibrating += records[: min(per_condition, len(records) - 1)]
        lone += records if len(records) == 1 else []
    if reserve.get("each_condition"):  # every condition its own calibration block
        splitting = lone
    elif not calibrating and len(ids) > 1:
        calibrating, splitting = ids[:1], []
    else:
        splitting = [] if calibrating else ids[:1]
    # calibrate on whole records, test healthy data on the others
    frame.loc[frame["record_id"].isin(calibrating), "fixed_role"] = CALIBRATION
    for record in splitting:
        rows = healthy.index[healthy["record_id"] == record]  # sorted by segment
        units, roles = time_blocks(
            record,
            len(rows),
            int(reserve["calibration_segments"]),
            int(reserve["guard_segments"]),
            int(reserve["blocks"]),
            segment_samples,
        )
        frame.loc[rows, "unit"] = units
        frame.loc[rows, "fixed_role"] = roles
    return frame


def _reserve_fault_records(
    frame: pd.DataFrame, states: list[str], healthy_state: str | None
) -> None:
    """Give the first record (by id) of each of `states` per condition the calibration role, in place."""
    for state in states:
        if state == healthy_state:
            raise SplitError(
                f"calibration.per_state.states: {state!r} is the healthy state; list fault states"
            )
        rows = frame[frame["health_state"] == state]
        if rows.empty:
            raise SplitError(
                f"calibration.per_state.states: no measured {state!r} records to tune its model on"
            )
        for condition, ids in rows.groupby("condition", sort=True)["record_id"]:
            ids = sorted(ids.unique())
            if len(ids) < 2:
                raise SplitError(
                    f"calibration.per_state.states: {state!r} has one record at condition "
                    f"{condition:g} ({ids[0]}); tuning its model on it would leave none to test"
                )
            frame.loc[frame["record_id"] == ids[0], "fixed_role"] = CALIBRATION


def guard_gap_samples(guard: int, segment_length: int, segment_hop: int) -> int:
    """Samples between the end of the last segment before a guard gap of `guard` segments and
    the start of the first after it: (guard + 1) x hop - length (negative: they overlap)."""
    return (int(guard) + 1) * int(segment_hop) - int(segment_length)


def time_blocks(
    record_id: str,
    n_segments: int,
    calibration: int,
    guard: int,
    blocks: int,
    segment_samples: tuple[int, int] | None = None,
) -> tuple[list[str], list[str]]:
    """(unit, fixed role) of each segment of a lone healthy record, in time order:
    `calibration` segments, then `blocks` equal blocks, each after `guard` unused segments;
    segments left over at the end are unused. With `segment_samples` (length, hop): a guard gap
    shorter than one segment length in samples is an error (a calibration or training block
    would sit within one segment of a test block: the same stretch of signal, nearly)."""
    if segment_samples is not None:
        length, hop = (int(v) for v in segment_samples)
        gap = guard_gap_samples(guard, length, hop)
        if gap < length:
            need = -(-2 * length // hop) - 1
            raise SplitError(
                f"{RESERVE_KEY}.guard_segments {guard}: record {record_id!r} is split in time "
                f"with a guard gap of {gap} samples between its calibration block and the next "
                f"block (segments of {length} samples every {hop}), shorter than one segment; "
                f"use guard_segments >= {need}"
            )
    size = (n_segments - calibration - blocks * guard) // blocks
    if size < 1:
        raise SplitError(
            f"{RESERVE_KEY}: record {record_id!r} has {n_segments} segments, too "
            f"few for {calibration} calibration segments and {blocks} blocks after "
            f"guard gaps of {guard}; lower them, or list reserved records"
        )
    units, roles = [record_id] * calibration, [CALIBRATION] * calibration
    for k in range(blocks):
        units += [record_id] * guard + [f"{record_id}{BLOCK_MARK}{k}"] * size
        roles += ["unused"] * guard + [""] * size
    rest = n_segments - len(units)
    return units + [record_id] * rest, roles + ["unused"] * rest


def calibration_segments(layout: pd.DataFrame) -> pd.DataFrame:
    """record_id, segment of the calibration set."""
    return layout.loc[layout["fixed_role"] == CALIBRATION, ["record_id", "segment"]]


def calibration_frame(
    frame: pd.DataFrame, healthy_state: str, condition: str, reserve: dict, states=None
) -> pd.DataFrame:
    """The rows of a measured table (signals or features) in the calibration set of `states`
    (default the healthy state; per-state calibration adds fault records to the set): all the
    calibrate jobs may see, and what no split ever trains on or tests."""
    layout = measured_layout(frame, healthy_state, condition, reserve)
    layout = layout[layout["health_state"].isin(states or [healthy_state])]
    chosen = pd.MultiIndex.from_frame(calibration_segments(layout))
    keys = pd.MultiIndex.from_arrays([frame["record_id"].astype(str), frame["segment"].astype(int)])
    return frame[keys.isin(chosen)]


def n_validation_records(n_records: int, share: float) -> int:
    """Simulated records of a stratum held out for validation: floor(share x n + 0.5)."""
    return math.floor(share * n_records + 0.5)


def simulated_validation_records(
    records: pd.DataFrame, share: float, seed: int, condition: str = "speed_rpm"
) -> list[str]:
    """The simulated record ids held out of training as the simulated validation set, sorted.

    `records`: record_id, health_state and the `condition` column of the simulated features
    (one or more rows per record). Per stratum (health_state x condition) the first
    n_validation_records of a permutation seeded by (seed, stratum) only: the same set for every
    protocol, percentage, repeat and holdout. A stratum left without a training record is an
    error naming the key and the stratum.
    """
    if isinstance(share, bool) or not 0 <= share < 1:
        raise SplitError(f"{SHARE_KEY} must be a number in [0, 1), got {share!r}")
    if share == 0:
        return []
    unique = unique_records(records, condition, what="simulated")
    held_out = []
    for (health, value), group in unique.groupby(["health_state", "condition"], sort=True):
        ids = sorted(group["record_id"])
        n_held = n_validation_records(len(ids), share)
        stratum = f"health_state={health}, {condition}={format_speed(value)}"
        if n_held >= len(ids):
            raise SplitError(
                f"{SHARE_KEY} = {share} holds out all {len(ids)} simulated "
                f"record(s) of stratum {stratum}: none of them would train; lower "
                "the share or simulate more samples (simulation.samples_per_state)"
            )
        if n_held == 0:
            log.warning(
                "%s = %s: stratum %s (%d simulated records) has no simulated validation record",
                SHARE_KEY,
                share,
                stratum,
                len(ids),
            )
        rng = np.random.default_rng(
            derive_seed(seed, stable_int(SIMULATED_VALIDATION, health, format_speed(value)))
        )
        held_out += [ids[i] for i in rng.permutation(len(ids))[:n_held]]
    return sorted(held_out)


def simulated_validation_ids(splits: pd.DataFrame) -> set[str]:
    """The simulated records a split table (or one split) holds out of training."""
    return set(splits["record_id"][splits["role"] == SIMULATED_VALIDATION])


def measured_rows(splits: pd.DataFrame) -> pd.DataFrame:
    """The rows of a split table that list measured records (all but simulated validation)."""
    return splits[splits["role"] != SIMULATED_VALIDATION]


def segment_roles(split: pd.DataFrame, measured_features: pd.DataFrame) -> np.ndarray:
    """The role of every measured feature row in one split: by record, or by (record, segment)
    where the split lists single segments; rows the split does not name get None."""
    whole = split[split["segment"] < 0]
    roles = (
        measured_features["record_id"]
        .astype(str)
        .map(dict(zip(whole["record_id"], whole["role"])))
        .to_numpy(object)
    )
    single = split[split["segment"] >= 0]
    if len(single):
        keys = pd.MultiIndex.from_arrays(
            [measured_features["record_id"].astype(str), measured_features["segment"].astype(int)]
        )
        by_segment = pd.Series(
            single["role"].to_numpy(),
            index=pd.MultiIndex.from_arrays([single["record_id"], single["segment"].astype(int)]),
        )
        found = keys.isin(by_segment.index)
        roles[found] = by_segment.reindex(keys[found]).to_numpy()
    return roles


def typed_splits(splits: pd.DataFrame) -> pd.DataFrame:
    order = {label: i for i, label in enumerate(sorted_holdouts(splits["holdout"]))}
    if "segment" not in splits.columns:  # split tables written before segment_share
        splits = splits.assign(segment=WHOLE_RECORD)
    splits = (
        splits.assign(_h=splits["holdout"].map(order))
        .sort_values(["measured_percent", "repeat", "_h", "record_id", "segment"])
        .drop(columns="_h")
        .reset_index(drop=True)
    )
    # `reason` (condmon.protocols.make_splits(reasons=True)) is kept, never written
    columns = SPLIT_COLUMNS + [c for c in ("reason",) if c in splits.columns]
    return splits.astype(
        {
            "protocol": str,
            "measured_percent": "int32",
            "repeat": "int32",
            "holdout": str,
            "record_id": str,
            "segment": "int32",
            "role": str,
        }
    )[columns]


def validate_splits(splits: pd.DataFrame, where: str = "split table") -> None:
    """Check columns, roles, one protocol, and one row per record (or segment) per split."""
    missing = [c for c in SPLIT_COLUMNS if c not in splits.columns and c != "segment"]
    if missing:
        raise SplitError(f"{where}: missing column(s) {missing}")
    bad_roles = sorted(set(splits["role"]) - set(ROLES))
    if bad_roles:
        raise SplitError(f"{where}: unknown role(s) {bad_roles}; allowed {list(ROLES)}")
    protocols = sorted(set(splits["protocol"]))
    if len(protocols) != 1:
        raise SplitError(f"{where}: expected one protocol, found {protocols}")
    if "segment" in splits.columns:
        cut = splits[(splits["role"] == SIMULATED_VALIDATION) & (splits["segment"] != WHOLE_RECORD)]
        if len(cut):
            raise SplitError(
                f"{where}: simulated validation record {cut['record_id'].iloc[0]!r} "
                "is listed by segment; it must be a whole record (segment -1)"
            )
    keys = ["measured_percent", "repeat", "holdout", "record_id"]
    dup = splits.duplicated(keys + ["segment"] if "segment" in splits.columns else keys)
    if dup.any():
        first = splits.loc[dup].iloc[0]
        raise SplitError(
            f"{where}: record {first.record_id!r} listed twice in split "
            f"(measured_percent={first.measured_percent}, repeat={first.repeat}, "
            f"holdout={first.holdout!r})"
        )


def write_split_table(splits: pd.DataFrame, path) -> None:
    validate_splits(splits, str(path))
    table = pa.Table.from_pandas(typed_splits(splits), schema=SPLIT_SCHEMA, preserve_index=False)
    write_table(table, path)


def read_split_table(path) -> pd.DataFrame:
    try:
        splits = pq.read_table(path).to_pandas()
    except FileNotFoundError:
        raise SplitError(f"{path}: no such split table") from None
    validate_splits(splits, str(path))
    return typed_splits(splits)


def training_range(
    simulated: pd.DataFrame, measured: pd.DataFrame, split: pd.DataFrame, names
) -> dict:
    """The range (minimum, maximum) of every feature of `names` over a fit's training segments:
    the simulated ones the split does not hold out for validation and the measured ones it
    trains on (`SignalModel.training_range`; the joined method's support). Here beside the split
    table's readers, so a job that needs it imports no MLflow (the model store does)."""
    names = list(names)
    simulated = simulated[~simulated["record_id"].astype(str).isin(simulated_validation_ids(split))]
    trained = measured[segment_roles(measured_rows(split), measured) == "train"]
    rows = pd.concat([simulated[names], trained[names]], ignore_index=True)
    return {
        "features": names,
        "low": rows.min().astype(float).tolist(),
        "high": rows.max().astype(float).tolist(),
    }

"""Hybrid training sets: which measured records join the simulated ones in training.

A split table lists, per (measured_percent, repeat, holdout), the role of every measured record
(see ARCHITECTURE.md, "Split table"), or of every segment (`segment` >= 0) for segment_share;
`segment` = -1 means the whole record. Simulated records always train, except those held out as
the simulated validation set (`simulated_validation_share` > 0): only these are listed, with role
"simulated_validation" (whole records), in every split; an unlisted simulated record trains.

An operating condition is the value of the `condition` column (speed_rpm on the gear bench,
load on the CWRU rig, whose records at one load differ by a few rpm). Strata are
(health_state x condition).

Protocols
- record_split: per stratum a share of whole records trains, the rest tests; at least
  `min_test_records` per stratum stay in the test set.
- condition_holdout: each condition in turn is held out whole as the test set; the training
  share is drawn per stratum from the other conditions' records. Records of the other conditions
  that are not drawn get the role "unused" (neither trained on nor tested), so every record
  still has a row. With `condition_split` ({train: [...], test: [...]}, a benchmark's split such
  as pdm-bench's cwru_cross_load) there is one holdout: the test conditions test, the share
  trains from the train conditions, other conditions are unused; a listed condition the
  measured records lack is an error naming it.
- segment_share: the bearing study's protocol: per health state, a share of all its measured
  segments trains and the rest tests. Segments of one record land on both sides (leaky: the
  report labels its numbers so).
- unseen_fault: only the `measured_classes` (e.g. healthy) have measured records in training:
  per stratum of those classes a share of whole records trains (the healthy state keeps
  `min_test_records` back); every other record tests, so every other class is learnt from
  simulation alone.
- specimen_holdout: each specimen group (CWRU: fault size) in turn tests whole, at every
  condition; the share trains from the other groups; healthy records always test, so no
  specimen is on both sides.

With `healthy_state` every test set holds healthy data (false alarms are measured). With
`reserve` (calibration.reserve) the calibration set is cut out first (measured_layout): role
"calibration" in every split; a lone healthy record's time blocks are split like records.

The record order within a stratum is a random permutation seeded by (seed, repeat, stratum) only,
and the first n_train records of it train. So a higher percentage's training set contains the
lower one's (nested shares), and both protocols draw the same records from a stratum.

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
from condmon.labels import format_speed, holdout_label, sorted_holdouts
from condmon.seeds import derive_seed, stable_int

log = logging.getLogger(__name__)

PROTOCOLS = ("record_split", "condition_holdout", "segment_share", "unseen_fault",
             "specimen_holdout")
CONDITIONS = ("speed_rpm", "load")
WHOLE_RECORD = -1
# a simulated record held out of training as the simulated validation set (the only role, and the
# only rows, of simulated records in a split table)
SIMULATED_VALIDATION = "simulated_validation"
SHARE_KEY = "hybrid.simulated_validation_share"
# measured segments that calibrate the model: never trained on, never tested
CALIBRATION = "calibration"
ROLES = ("train", "test", "unused", SIMULATED_VALIDATION, CALIBRATION)
SPLIT_SCHEMA = pa.schema([
    ("protocol", pa.string()),
    ("measured_percent", pa.int32()),
    ("repeat", pa.int32()),
    ("holdout", pa.string()),
    ("record_id", pa.string()),
    ("segment", pa.int32()),  # WHOLE_RECORD, or one segment (segment_share)
    ("role", pa.string()),
])
SPLIT_COLUMNS = SPLIT_SCHEMA.names


class SplitError(ValueError):
    """A split request or split table breaks the contract."""


def n_train_records(n_records: int, percent: float, min_test_records: int) -> int:
    """floor(p/100 * n + 0.5), leaving at least `min_test_records` records (never below 0)."""
    wanted = math.floor(percent / 100.0 * n_records + 0.5)
    return max(0, min(wanted, n_records - min_test_records))


def unique_records(records: pd.DataFrame, condition: str = "speed_rpm",
                   what: str = "measured") -> pd.DataFrame:
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
        raise SplitError(f"record(s) {sorted(set(mixed))[:5]} have several health_state or "
                         f"{condition} values")
    if records.empty:
        raise SplitError(f"no {what} records to split")
    records = records.rename(columns={condition: "condition"}).astype(
        {"record_id": str, "health_state": str, "condition": float})
    return records.sort_values("record_id").reset_index(drop=True)


def _check_arguments(protocol, measured_percent, repeats, seed, min_test_records) -> list[int]:
    if protocol not in PROTOCOLS:
        raise SplitError(f"unknown protocol {protocol!r}; choose one of {list(PROTOCOLS)}")
    percents = []
    for value in measured_percent:
        try:
            valid = not isinstance(value, bool) and float(value).is_integer() and 0 <= value <= 100
        except (TypeError, ValueError):
            valid = False
        if not valid:
            raise SplitError(f"measured_percent {value!r} is not a whole number in 0..100")
        percents.append(int(value))
    if not percents:
        raise SplitError("measured_percent is empty")
    duplicates = sorted({p for p in percents if percents.count(p) > 1})
    if duplicates:
        raise SplitError(f"measured_percent lists {duplicates} more than once")
    for name, value, low in (("repeats", repeats, 1), ("seed", seed, 0),
                             ("min_test_records", min_test_records, 0)):
        if isinstance(value, bool) or int(value) != value or value < low:
            raise SplitError(f"{name} must be an integer >= {low}, got {value!r}")
    return sorted(percents)


def stratum_orders(records: pd.DataFrame, seed: int, repeat: int) -> dict[tuple, list[str]]:
    """Per stratum (health_state, condition): its record ids in this repeat's random order.

    Seeded by (seed, repeat, stratum) only, so the order is the same at every percentage and
    holdout, and adding a stratum does not reshuffle the others.
    """
    orders = {}
    for (health, value), group in records.groupby(["health_state", "condition"], sort=True):
        ids = sorted(group["record_id"])  # start from a fixed order: input row order is irrelevant
        rng = np.random.default_rng(
            derive_seed(seed, repeat, stable_int(f"{health}|{format_speed(value)}")))
        orders[(health, value)] = [ids[i] for i in rng.permutation(len(ids))]
    return orders


def class_segment_orders(segments: pd.DataFrame, seed: int, repeat: int) -> dict[str, list]:
    """Per health state: its (record_id, segment) pairs in this repeat's random order."""
    orders = {}
    for health, group in segments.groupby("health_state", sort=True):
        pairs = sorted(zip(group["record_id"].astype(str), group["segment"].astype(int)))
        rng = np.random.default_rng(derive_seed(seed, repeat, stable_int(f"segments|{health}")))
        orders[health] = [pairs[i] for i in rng.permutation(len(pairs))]
    return orders


def make_splits(records: pd.DataFrame, protocol: str, measured_percent, repeats: int, seed: int,
                min_test_records: int = 1, condition: str = "speed_rpm",
                measured_classes=None, simulated_records: pd.DataFrame | None = None,
                simulated_validation_share: float = 0.0, healthy_state: str | None = None,
                reserve: dict | None = None,
                specimens: pd.DataFrame | None = None,
                condition_split: dict | None = None,
                segment_samples: tuple[int, int] | None = None) -> pd.DataFrame:
    """The split table for one protocol (columns SPLIT_COLUMNS, one row per record, or per
    segment for segment_share, and split).

    `records`: record_id, health_state and the `condition` column, one or more rows per record
    (segment_share needs the `segment` column, one row per segment). `min_test_records`: records
    per stratum (record_split) or segments per class (segment_share) kept for testing.
    `measured_classes`: the health states with measured training data under unseen_fault.
    `simulated_records` (same columns) and `simulated_validation_share` > 0: the held-out
    simulated records (simulated_validation_records) join every split with role
    "simulated_validation"; with share 0 the table is exactly the measured one.
    `healthy_state`: every test set must hold healthy data (false alarms are always measured):
    each protocol keeps healthy records back for testing, and a split without any is an error.
    `reserve` (calibration.reserve; needs the `segment` column): the calibration set and the time
    blocks of lone healthy records (measured_layout); calibration segments get the role
    "calibration" and guard gaps "unused" in every split, blocks are split like records.
    `specimens`: record_id, specimen, specimen_group of the measured records (specimen_holdout).
    `condition_split`: condition_holdout's fixed sides, {train: [values], test: [values]}.
    `segment_samples`: (segment length, hop) of the measured segments in samples: a record split
    in time is refused where its guard gap is shorter than one segment (`time_blocks`).
    """
    percents = _check_arguments(protocol, measured_percent, repeats, seed, min_test_records)
    layout = None
    if reserve is not None:
        if "segment" not in records.columns:
            raise SplitError("calibration.reserve needs the segment column of the measured records")
        layout = measured_layout(records, healthy_state, condition, reserve, segment_samples)
        free = layout[layout["fixed_role"] == ""]
        records = (free.assign(record_id=free["unit"]) if protocol != "segment_share" else free)
        records = records.rename(columns={"condition": condition})
    unique = unique_records(records, condition)
    held_out = []
    if simulated_validation_share:
        if simulated_records is None:
            raise SplitError(f"{SHARE_KEY} = {simulated_validation_share} needs the simulated "
                             "records")
        held_out = simulated_validation_records(simulated_records, simulated_validation_share,
                                                seed, condition)
        both = sorted(set(held_out) & set(unique["record_id"]))
        if both:
            raise SplitError(f"record id(s) {both[:5]} are both measured and simulated")
    if protocol == "segment_share":
        splits = _segment_share_splits(records, unique, percents, repeats, seed, min_test_records)
        return with_simulated_validation(_finish(splits, layout, unique, healthy_state), held_out)
    conditions = sorted(unique["condition"].unique())
    train_conditions = None
    if protocol == "condition_holdout" and condition_split:
        train_conditions, test_conditions = _check_condition_split(condition_split, conditions,
                                                                   condition)
    if protocol == "condition_holdout" and len(conditions) < 2:
        raise SplitError(f"condition_holdout needs at least two values of {condition}; the "
                         f"measured records have only {condition} "
                         f"{[format_speed(c) for c in conditions]}")
    if protocol == "unseen_fault":
        if not measured_classes:
            raise SplitError("unseen_fault needs measured_classes: the health states whose "
                             "measured records may train (e.g. [normal])")
        absent = sorted(set(measured_classes) - set(unique["health_state"]))
        if absent:
            log.warning("unseen_fault: measured class(es) %s have no measured record", absent)
    sizes = unique.groupby(["health_state", "condition"]).size()
    small = sizes[sizes <= min_test_records]
    if protocol == "record_split" and len(small):
        log.warning("strata with <= min_test_records=%d records never train: %s",
                    min_test_records, [(h, format_speed(s)) for h, s in small.index])

    group_of = _specimen_groups(unique, specimens, healthy_state) \
        if protocol == "specimen_holdout" else {}
    rows = []
    for repeat in range(int(repeats)):
        orders = stratum_orders(unique, seed, repeat)
        for percent in percents:
            if protocol == "record_split":
                rows += _record_split_rows(orders, percent, repeat, min_test_records)
            elif protocol == "unseen_fault":
                rows += _unseen_fault_rows(orders, percent, repeat, set(measured_classes),
                                           healthy_state, min_test_records)
            elif protocol == "specimen_holdout":
                for group in sorted({g for g in group_of.values() if g}):
                    rows += _specimen_rows(orders, percent, repeat, group, group_of)
            else:
                healthy_there = {value for health, value in orders if health == healthy_state}
                tested_conditions = ([test_conditions] if train_conditions is not None else
                                     [[value] for value in conditions])
                for values in tested_conditions:
                    keep = (max(1, min_test_records) if healthy_state is not None
                            and not healthy_there & set(values) else 0)
                    rows += _holdout_rows(orders, percent, repeat, values, condition,
                                          healthy_state, keep, train_conditions)
    splits = _finish(_typed(_frame(rows, protocol)), layout, unique, healthy_state)
    return with_simulated_validation(splits, held_out)


# -- the calibration set, time blocks, specimens -------------------------------------------
RESERVE_KEY = "calibration.reserve"
BLOCK_MARK = "@block"  # the split unit of a record's time block: "<record_id>@block<k>"


def measured_layout(segments: pd.DataFrame, healthy_state: str | None, condition: str,
                    reserve: dict, segment_samples: tuple[int, int] | None = None) -> pd.DataFrame:
    """Per measured segment: the split unit it belongs to and a fixed role.

    Columns record_id, segment, health_state, condition, unit, fixed_role: CALIBRATION (the
    calibration set: never trained on, never tested), "unused" (a guard gap) or "" (the
    protocol decides, per unit). `reserve` is calibration.reserve:
    - `records` listed: those healthy records, whole, are the calibration set;
    - none listed, several healthy records: per condition the first (by id) of several
      calibrates, whole; where no condition has several (CWRU's full set: one per load), the
      first overall does; every other healthy record is a whole split unit, so healthy test
      data come from records the calibration never saw;
    - one healthy record: it is split in time: its first `calibration_segments` segments
      calibrate, then `blocks` blocks of equal length follow, each after a guard gap of
      `guard_segments`; every block is a split unit (a record to the protocols), so healthy
      data can train and test without a segment on both sides. With `segment_samples`
      (length, hop) a guard gap shorter than one segment in samples is refused (`time_blocks`).
    The same table rows in, the same layout out: the calibrate and hybrid jobs agree.
    """
    missing = [c for c in ("record_id", "segment", "health_state", condition)
               if c not in segments.columns]
    if missing:
        raise SplitError(f"{RESERVE_KEY}: the measured records lack column(s) {missing}")
    frame = (segments[["record_id", "segment", "health_state", condition]]
             .drop_duplicates(["record_id", "segment"])
             .rename(columns={condition: "condition"})
             .astype({"record_id": str, "segment": int, "health_state": str,
                      "condition": float})
             .sort_values(["record_id", "segment"]).reset_index(drop=True))
    frame["unit"] = frame["record_id"]
    frame["fixed_role"] = ""
    listed = [str(r) for r in reserve.get("records") or []]
    if listed:
        unknown = sorted(set(listed) - set(frame["record_id"]))
        if unknown:
            raise SplitError(f"{RESERVE_KEY}.records: {unknown} are not measured records")
        labels = frame.drop_duplicates("record_id").set_index("record_id")["health_state"]
        faulty = [r for r in listed if labels[r] != healthy_state]
        if faulty:
            raise SplitError(f"{RESERVE_KEY}.records: {faulty} are not {healthy_state!r} "
                             "records; only healthy records calibrate")
        frame.loc[frame["record_id"].isin(listed), "fixed_role"] = CALIBRATION
        return frame
    if healthy_state is None:
        raise SplitError(f"{RESERVE_KEY} needs the healthy state")
    healthy = frame[frame["health_state"] == healthy_state]
    ids = sorted(healthy["record_id"].unique())
    # the first of several healthy records of a condition calibrates (the gear bench: one per
    # speed); with one healthy record per condition (CWRU: one per load), the first overall
    calibrating = [sorted(group.unique())[0] for _, group in
                   healthy.groupby("condition", sort=True)["record_id"] if group.nunique() > 1]
    if not calibrating and len(ids) > 1:
        calibrating = ids[:1]
    if calibrating:  # calibrate on whole records, test healthy data on the others
        frame.loc[frame["record_id"].isin(calibrating), "fixed_role"] = CALIBRATION
    elif ids:
        rows = healthy.index  # sorted by segment
        units, roles = time_blocks(ids[0], len(rows), int(reserve["calibration_segments"]),
                                   int(reserve["guard_segments"]), int(reserve["blocks"]),
                                   segment_samples)
        frame.loc[rows, "unit"] = units
        frame.loc[rows, "fixed_role"] = roles
    return frame


def guard_gap_samples(guard: int, segment_length: int, segment_hop: int) -> int:
    """Samples between the end of the last segment before a guard gap of `guard` segments and
    the start of the first after it: (guard + 1) x hop - length (negative: they overlap)."""
    return (int(guard) + 1) * int(segment_hop) - int(segment_length)


def time_blocks(record_id: str, n_segments: int, calibration: int, guard: int,
                blocks: int, segment_samples: tuple[int, int] | None = None
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
                f"use guard_segments >= {need}")
    size = (n_segments - calibration - blocks * guard) // blocks
    if size < 1:
        raise SplitError(f"{RESERVE_KEY}: record {record_id!r} has {n_segments} segments, too "
                         f"few for {calibration} calibration segments and {blocks} blocks after "
                         f"guard gaps of {guard}; lower them, or list reserved records")
    units, roles = [record_id] * calibration, [CALIBRATION] * calibration
    for k in range(blocks):
        units += [record_id] * guard + [f"{record_id}{BLOCK_MARK}{k}"] * size
        roles += ["unused"] * guard + [""] * size
    rest = n_segments - len(units)
    return units + [record_id] * rest, roles + ["unused"] * rest


def calibration_segments(layout: pd.DataFrame) -> pd.DataFrame:
    """record_id, segment of the calibration set."""
    return layout.loc[layout["fixed_role"] == CALIBRATION, ["record_id", "segment"]]


def calibration_frame(frame: pd.DataFrame, healthy_state: str, condition: str,
                      reserve: dict) -> pd.DataFrame:
    """The rows of a measured table (signals or features) in the calibration set: all the
    calibrate job may see, and what no split ever trains on or tests."""
    layout = measured_layout(frame, healthy_state, condition, reserve)
    chosen = pd.MultiIndex.from_frame(calibration_segments(layout))
    keys = pd.MultiIndex.from_arrays([frame["record_id"].astype(str),
                                      frame["segment"].astype(int)])
    return frame[keys.isin(chosen)]


def _finish(splits: pd.DataFrame, layout, unique, healthy_state) -> pd.DataFrame:
    """Time blocks back to their record's segments, the calibration and guard segments added
    to every split, then the check that every test set holds healthy data."""
    if layout is not None:
        blocks = layout[layout["unit"] != layout["record_id"]]
        segments_of = {u: g for u, g in blocks.groupby("unit")}
        expanded = []
        for row in splits.itertuples(index=False):
            if row.record_id in segments_of:
                part = segments_of[row.record_id]
                expanded += [(row.measured_percent, row.repeat, row.holdout, rid, seg, row.role)
                             for rid, seg in zip(part["record_id"], part["segment"])]
            else:
                expanded.append(tuple(row)[1:])
        fixed = layout[layout["fixed_role"] != ""]
        keys = splits[["measured_percent", "repeat", "holdout"]].drop_duplicates()
        expanded += [(p, r, h, rid, seg, role) for p, r, h in keys.itertuples(index=False)
                     for rid, seg, role in zip(fixed["record_id"], fixed["segment"],
                                               fixed["fixed_role"])]
        splits = _typed(_frame(expanded, str(splits["protocol"].iloc[0])))
    if healthy_state is not None:
        check_healthy_tested(splits, unique, healthy_state)
    return splits


def check_healthy_tested(splits: pd.DataFrame, unique: pd.DataFrame, healthy_state: str) -> None:
    """Every split tests healthy data, or an error naming the first that does not (a warning
    when no measured record is healthy: false alarms cannot be measured at all)."""
    healthy = {r.partition(BLOCK_MARK)[0]
               for r in unique.loc[unique["health_state"] == healthy_state, "record_id"]}
    if not healthy:
        log.warning("no measured %r record: no test set measures false alarms", healthy_state)
        return
    tested = splits[(splits["role"] == "test") & splits["record_id"].isin(healthy)]
    keys = splits[["measured_percent", "repeat", "holdout"]].drop_duplicates()
    covered = set(tested[["measured_percent", "repeat", "holdout"]].itertuples(index=False,
                                                                              name=None))
    for key in keys.itertuples(index=False, name=None):
        if key not in covered:
            raise SplitError(f"split (measured_percent, repeat, holdout) = {key} of protocol "
                             f"{splits['protocol'].iloc[0]!r} tests no {healthy_state!r} data")


def _specimen_groups(unique: pd.DataFrame, specimens, healthy_state) -> dict[str, str]:
    """{unit: specimen group} for specimen_holdout; healthy units get "" (never held out by
    group: they test in every split)."""
    if specimens is None or not {"record_id", "specimen", "specimen_group"} <= set(specimens):
        raise SplitError("specimen_holdout needs the specimen and specimen_group of every "
                         "measured record (measured/records.csv: the CWRU reader writes them)")
    group = dict(zip(specimens["record_id"].astype(str),
                     specimens["specimen_group"].fillna("").astype(str)))
    groups = {}
    for unit, health in zip(unique["record_id"], unique["health_state"]):
        record = unit.partition(BLOCK_MARK)[0]
        if health == healthy_state:
            groups[unit] = ""
        elif not group.get(record):
            raise SplitError(f"specimen_holdout: record {record!r} has no specimen_group")
        else:
            groups[unit] = group[record]
    if len({g for g in groups.values() if g}) < 2:
        raise SplitError("specimen_holdout needs fault specimens of at least two groups (sizes)")
    return groups


def n_validation_records(n_records: int, share: float) -> int:
    """Simulated records of a stratum held out for validation: floor(share x n + 0.5)."""
    return math.floor(share * n_records + 0.5)


def simulated_validation_records(records: pd.DataFrame, share: float, seed: int,
                                 condition: str = "speed_rpm") -> list[str]:
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
            raise SplitError(f"{SHARE_KEY} = {share} holds out all {len(ids)} simulated "
                             f"record(s) of stratum {stratum}: none of them would train; lower "
                             "the share or simulate more samples (simulation.samples_per_state)")
        if n_held == 0:
            log.warning("%s = %s: stratum %s (%d simulated records) has no simulated validation "
                        "record", SHARE_KEY, share, stratum, len(ids))
        rng = np.random.default_rng(derive_seed(
            seed, stable_int(SIMULATED_VALIDATION, health, format_speed(value))))
        held_out += [ids[i] for i in rng.permutation(len(ids))[:n_held]]
    return sorted(held_out)


def with_simulated_validation(splits: pd.DataFrame, held_out) -> pd.DataFrame:
    """`splits` plus one row per held-out simulated record (whole record, role
    "simulated_validation") in every (measured_percent, repeat, holdout); unchanged without any."""
    held_out = sorted(held_out)
    if not held_out:
        return splits
    keys = splits[["measured_percent", "repeat", "holdout"]].drop_duplicates()
    rows = [(percent, repeat, holdout, rid, WHOLE_RECORD, SIMULATED_VALIDATION)
            for percent, repeat, holdout in keys.itertuples(index=False) for rid in held_out]
    added = _frame(rows, str(splits["protocol"].iloc[0]))
    return _typed(pd.concat([splits, added], ignore_index=True))


def simulated_validation_ids(splits: pd.DataFrame) -> set[str]:
    """The simulated records a split table (or one split) holds out of training."""
    return set(splits["record_id"][splits["role"] == SIMULATED_VALIDATION])


def measured_rows(splits: pd.DataFrame) -> pd.DataFrame:
    """The rows of a split table that list measured records (all but simulated validation)."""
    return splits[splits["role"] != SIMULATED_VALIDATION]


def _frame(rows, protocol) -> pd.DataFrame:
    """Rows (percent, repeat, holdout, record_id, segment, role) as a split table."""
    splits = pd.DataFrame(rows, columns=SPLIT_COLUMNS[1:])
    splits.insert(0, "protocol", protocol)
    return splits


def _record_split_rows(orders, percent, repeat, min_test_records) -> list[tuple]:
    rows = []
    for ids in orders.values():
        n_train = n_train_records(len(ids), percent, min_test_records)
        rows += [(percent, repeat, "", rid, WHOLE_RECORD, "train" if i < n_train else "test")
                 for i, rid in enumerate(ids)]
    return rows


def _unseen_fault_rows(orders, percent, repeat, measured_classes, healthy_state=None,
                       min_test_records=1) -> list[tuple]:
    # At 100 % every record of a measured class trains, but the healthy state keeps
    # min_test_records per stratum back: false alarms are measured at every share.
    rows = []
    for (health, _), ids in orders.items():
        keep = min_test_records if health == healthy_state else 0
        n_train = n_train_records(len(ids), percent, keep) if health in measured_classes else 0
        rows += [(percent, repeat, "", rid, WHOLE_RECORD, "train" if i < n_train else "test")
                 for i, rid in enumerate(ids)]
    return rows


def _holdout_rows(orders, percent, repeat, held_out, condition, healthy_state=None,
                  keep_healthy=0, train_conditions=None) -> list[tuple]:
    # The held-out conditions supply the test set, so no record of the other conditions needs
    # to stay back for testing (at 100 % all of them train), except where they have no healthy
    # record: then `keep_healthy` healthy records per other stratum test, so false alarms are
    # measured (at another condition: the report's protocol label says so). With
    # `train_conditions` only those train; the records of any other condition are unused.
    label = "+".join(holdout_label(value, condition) if i == 0 else format_speed(value)
                     for i, value in enumerate(sorted(held_out)))
    rows = []
    for (health, value), ids in orders.items():
        if value in held_out:
            rows += [(percent, repeat, label, rid, WHOLE_RECORD, "test") for rid in ids]
            continue
        if train_conditions is not None and value not in train_conditions:
            rows += [(percent, repeat, label, rid, WHOLE_RECORD, "unused") for rid in ids]
            continue
        keep = keep_healthy if health == healthy_state else 0
        n_train = n_train_records(len(ids), percent, keep)
        rows += [(percent, repeat, label, rid, WHOLE_RECORD,
                  "train" if i < n_train else "test" if i >= len(ids) - keep else "unused")
                 for i, rid in enumerate(ids)]
    return rows


def _check_condition_split(split: dict, conditions, condition: str) -> tuple[list, list]:
    """(train, test) condition values of hybrid.condition_split, each one measured, or an error
    naming the missing ones (a benchmark's split needs its loads in the folder)."""
    train, test = ([float(v) for v in split.get(side) or []] for side in ("train", "test"))
    if not train or not test:
        raise SplitError(f"hybrid.condition_split needs train and test {condition} values, got "
                         f"{split}")
    both = sorted(set(train) & set(test))
    if both:
        raise SplitError(f"hybrid.condition_split: {condition} {[format_speed(v) for v in both]} "
                         "is on both sides")
    missing = sorted(set(train + test) - set(conditions))
    if missing:
        raise SplitError(
            f"hybrid.condition_split needs measured records at {condition} "
            f"{[format_speed(v) for v in missing]}, which the measured data lack (they have "
            f"{condition} {[format_speed(v) for v in conditions]}): point measured_dir at a "
            "folder with those records, or change the split")
    return train, test


def _specimen_rows(orders, percent, repeat, group, group_of) -> list[tuple]:
    # Every fault specimen of the held-out group (a fault size) tests, at every condition; the
    # share trains from the other groups' records; healthy units (group "") always test, so
    # no specimen is ever on both sides.
    label = f"specimen_group={group}"
    rows = []
    for ids in orders.values():
        rows += [(percent, repeat, label, rid, WHOLE_RECORD, "test")
                 for rid in ids if group_of[rid] in ("", group)]
        others = [rid for rid in ids if group_of[rid] not in ("", group)]
        n_train = n_train_records(len(others), percent, 0)
        rows += [(percent, repeat, label, rid, WHOLE_RECORD, "train" if i < n_train else "unused")
                 for i, rid in enumerate(others)]
    return rows


def _segment_share_splits(records, unique, percents, repeats, seed, min_test) -> pd.DataFrame:
    if "segment" not in records.columns:
        raise SplitError("segment_share needs the segment column of the measured features")
    segments = records[["record_id", "segment"]].drop_duplicates().merge(
        unique[["record_id", "health_state"]], on="record_id")
    rows = []
    for repeat in range(int(repeats)):
        orders = class_segment_orders(segments, seed, repeat)
        for percent in percents:
            for pairs in orders.values():
                n_train = n_train_records(len(pairs), percent, max(1, min_test))
                rows += [(percent, repeat, "", rid, seg, "train" if i < n_train else "test")
                         for i, (rid, seg) in enumerate(pairs)]
    return _typed(_frame(rows, "segment_share"))


def _typed(splits: pd.DataFrame) -> pd.DataFrame:
    order = {label: i for i, label in enumerate(sorted_holdouts(splits["holdout"]))}
    if "segment" not in splits.columns:  # split tables written before segment_share
        splits = splits.assign(segment=WHOLE_RECORD)
    splits = (splits.assign(_h=splits["holdout"].map(order))
              .sort_values(["measured_percent", "repeat", "_h", "record_id", "segment"])
              .drop(columns="_h").reset_index(drop=True))
    return splits.astype({"protocol": str, "measured_percent": "int32", "repeat": "int32",
                          "holdout": str, "record_id": str, "segment": "int32",
                          "role": str})[SPLIT_COLUMNS]


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
            raise SplitError(f"{where}: simulated validation record {cut['record_id'].iloc[0]!r} "
                             "is listed by segment; it must be a whole record (segment -1)")
    keys = ["measured_percent", "repeat", "holdout", "record_id"]
    dup = splits.duplicated(keys + ["segment"] if "segment" in splits.columns else keys)
    if dup.any():
        first = splits.loc[dup].iloc[0]
        raise SplitError(f"{where}: record {first.record_id!r} listed twice in split "
                         f"(measured_percent={first.measured_percent}, repeat={first.repeat}, "
                         f"holdout={first.holdout!r})")


def write_split_table(splits: pd.DataFrame, path) -> None:
    validate_splits(splits, str(path))
    table = pa.Table.from_pandas(_typed(splits), schema=SPLIT_SCHEMA,
                                 preserve_index=False)
    write_table(table, path)


def read_split_table(path) -> pd.DataFrame:
    try:
        splits = pq.read_table(path).to_pandas()
    except FileNotFoundError:
        raise SplitError(f"{path}: no such split table") from None
    validate_splits(splits, str(path))
    return _typed(splits)

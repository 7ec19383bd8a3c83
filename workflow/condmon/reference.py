"""Features taken against each machine's own healthy reference (`features.healthy_reference`).

Condition monitoring compares a machine with itself: the change since it was known healthy, not
the level, tells a fault from the machine's own make-up (its manufacturing errors, its structure,
the noise of its measurement chain). Every feature of a segment becomes its difference from the mean
of its machine's healthy reference at the same operating condition; on the log scale of the
spectra and order features that is a level ratio.

- A measured record is taken against its rig's calibration set at its condition
  (`hybrid.measured_layout`: the healthy records the calibration saw, never a test record). A
  condition without calibration records has no reference: an error names it.
- A simulated sample is taken against its healthy twin (`simulate.simulate_batch` with
  `reference_segments`): the same drawn machine run healthy, whose last segments are its reference
  and are then dropped. A damaged sample whose healthy twin failed has no reference and is left
  out (logged).

The reference itself (mean features per condition) is written beside the measured features, so a
packaged model takes a new record against the same reference (`signal_model.SignalModel`).
"""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd

from condmon.hybrid import calibration_frame
from condmon.simulate import machine_of

log = logging.getLogger(__name__)

KEY = "features.healthy_reference"


class ReferenceError(ValueError):
    """Segments without a healthy reference, or a reference that cannot be built."""


def measured_reference(
    frame: pd.DataFrame, names, healthy_state: str, condition: str, reserve: dict
) -> pd.DataFrame:
    """Mean features of the calibration set per value of `condition` (index `condition`, columns
    `names`); an error names every condition of `frame` that has none."""
    chosen = calibration_frame(frame, healthy_state, condition, reserve)
    reference = chosen.groupby(condition)[list(names)].mean()
    missing = sorted(set(frame[condition].astype(float)) - set(reference.index.astype(float)))
    if missing:
        raise ReferenceError(
            f"{KEY}: no calibration records at {condition} {missing} (calibration records at "
            f"{sorted(reference.index.astype(float))}); every operating condition needs healthy records "
            "the calibration sees, or switch the reference off"
        )
    return reference


def reference_length_mismatches(
    frame: pd.DataFrame, healthy_state: str, condition: str, reserve: dict, simulated_segments: int
) -> list[str]:
    """One message per condition whose calibration set holds another number of segments than a
    simulated twin's reference (`simulated_segments`). A reference averages its segments, so its
    own scatter falls with their number: measured and simulated segments taken against
    references of other lengths lie over other healthy floors (ARCHITECTURE.md, "Simulation")."""
    counts = calibration_frame(frame, healthy_state, condition, reserve).groupby(condition).size()
    return [
        f"{KEY}: the calibration set at {condition} {value:g} holds {int(n)} segment(s), a simulated "
        f"twin's reference {simulated_segments}: set features.healthy_reference.simulated_segments to "
        f"{int(n)} so both are averages of as many segments"
        for value, n in counts.items()
        if int(n) != int(simulated_segments)
    ]


def take_against(frame: pd.DataFrame, names, reference: pd.DataFrame, keys) -> pd.DataFrame:
    """`frame` with every feature in `names` minus the reference row of its key (`keys`: one per
    row of `frame`, an index value of `reference`)."""
    out = frame.copy()
    names = list(names)
    out[names] = frame[names].to_numpy(float) - reference.loc[list(keys), names].to_numpy(float)
    return out


def refer_measured(
    frame: pd.DataFrame, names, reference: pd.DataFrame, condition: str
) -> pd.DataFrame:
    """Measured segments against the reference of their condition (`measured_reference`)."""
    return take_against(frame, names, reference, frame[condition].astype(float))


def refer_simulated(
    frame: pd.DataFrame, names, healthy_state: str, segments_per_sample: int
) -> pd.DataFrame:
    """Simulated segments against their machine's healthy twin: the healthy sample's segments from
    `segments_per_sample` on are the machine's reference (mean), and are dropped."""
    machines = frame["record_id"].map(machine_of)
    is_reference = (frame["health_state"] == healthy_state) & (
        frame["segment"] >= segments_per_sample
    )
    if not is_reference.any():
        raise ReferenceError(
            f"{KEY}: no healthy reference segments in the simulated records (healthy "
            f"samples of more than {segments_per_sample} segments); were they simulated "
            "with the reference on?"
        )
    reference = frame[is_reference].groupby(machines[is_reference])[list(names)].mean()
    keep = ~is_reference & machines.isin(reference.index)
    orphans = sorted(frame.loc[~is_reference & ~keep, "record_id"].unique())
    if orphans:
        log.warning(
            "%d simulated record(s) without a healthy twin (it failed) left out: %s",
            len(orphans),
            ", ".join(orphans[:5]) + (" ..." if len(orphans) > 5 else ""),
        )
    kept = frame[keep]
    return take_against(kept, names, reference, machines[keep]).reset_index(drop=True)


def reference_table(reference: pd.DataFrame, condition: str) -> pd.DataFrame:
    """The reference as a table to write: a `condition` column and the feature columns."""
    return reference.rename_axis(condition).reset_index()


def reference_from_table(table: pd.DataFrame, condition: str) -> pd.DataFrame:
    return table.set_index(condition).astype(float)


def nearest_reference(reference: pd.DataFrame, values, tolerance: float) -> tuple[np.ndarray, list]:
    """(index into `reference` per value, values without a reference within `tolerance` relative)."""
    known = reference.index.to_numpy(float)
    values = np.asarray(values, float)
    distance = np.abs(values[:, None] - known[None, :])
    nearest = np.nan_to_num(distance, nan=np.inf).argmin(axis=1)
    # not within: a value far off, or none (NaN: a record that does not say its condition)
    far = ~(
        np.abs(values - known[nearest]) <= tolerance * np.maximum(np.abs(known[nearest]), 1e-12)
    )
    return nearest, sorted({str(v) for v in values[far]})

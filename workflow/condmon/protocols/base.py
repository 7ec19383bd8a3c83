"""What every evaluation protocol shares: its parameters, `split(records)`, and the draw.

A protocol is a small splitter in scikit-learn's `GroupKFold` shape: the constructor takes its
parameters, `split(records)` yields one `Split` per (measured_percent, repeat, holdout), and each
split says of every unit (a record, a time block `<record>@block<k>`, or a segment for
segment_share) its role and the reason it has it. `records`: record_id, health_state and the
`condition` column, one or more rows per unit (segment_share: one row per segment, with the
`segment` column). The calibration set and the simulated validation set are not a protocol's
business: `condmon.protocols.make_splits` adds them around it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import ClassVar, Iterator

import numpy as np
import pandas as pd

from condmon.hybrid import WHOLE_RECORD, SplitError, n_train_records, unique_records
from condmon.labels import format_speed, holdout_label
from condmon.seeds import derive_seed, stable_int

log = logging.getLogger(__name__)


# What a protocol may need of the measured data, as the config check names it.
MEASURED_NEEDS = {"specimens": "each measured fault record's specimen and specimen_group"}


@dataclass(frozen=True)
class Assignment:
    """One unit's place in one split: its role (train, test, unused) and why."""

    record_id: str
    role: str
    reason: str
    segment: int = WHOLE_RECORD


@dataclass(frozen=True)
class Split:
    """One split of a protocol: every unit once, with its role and the reason."""

    measured_percent: int
    repeat: int
    holdout: str
    assignments: tuple[Assignment, ...]

    def ids(self, role: str) -> list[str]:
        """The record ids (units) with `role`, in the split's order."""
        return [a.record_id for a in self.assignments if a.role == role]

    @property
    def train(self) -> list[str]:
        return self.ids("train")

    @property
    def test(self) -> list[str]:
        return self.ids("test")

    def rows(self) -> list[tuple]:
        """(measured_percent, repeat, holdout, record_id, segment, role, reason) per unit."""
        return [
            (
                self.measured_percent,
                self.repeat,
                self.holdout,
                a.record_id,
                a.segment,
                a.role,
                a.reason,
            )
            for a in self.assignments
        ]


def check_percents(measured_percent) -> list[int]:
    """Whole numbers in 0..100, none twice, at least one; sorted."""
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
    return sorted(percents)


def check_integer(name: str, value, low: int) -> int:
    if isinstance(value, bool) or int(value) != value or value < low:
        raise SplitError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def stratum_orders(records: pd.DataFrame, seed: int, repeat: int) -> dict[tuple, list[str]]:
    """Per stratum (health_state, condition): its record ids in this repeat's random order.

    Seeded by (seed, repeat, stratum) only, so the order is the same at every percentage and
    holdout, and adding a stratum does not reshuffle the others.
    """
    orders = {}
    for (health, value), group in records.groupby(["health_state", "condition"], sort=True):
        ids = sorted(group["record_id"])  # start from a fixed order: input row order is irrelevant
        rng = np.random.default_rng(
            derive_seed(seed, repeat, stable_int(f"{health}|{format_speed(value)}"))
        )
        orders[(health, value)] = [ids[i] for i in rng.permutation(len(ids))]
    return orders


def draw(
    ids, percent: int, keep: int, stratum: str, rest: str = "test", unit: str = "records"
) -> list[tuple[str, str, str]]:
    """(id, role, reason) of a stratum's ids in their random order: the first
    n_train_records(n, percent, keep) train, the others get `rest`; the reason tells a unit the
    share did not draw from one kept back (`keep`: kept for testing)."""
    n = len(ids)
    n_train, wanted = n_train_records(n, percent, keep), n_train_records(n, percent, 0)
    drawn = f"{n_train} of {n} {unit} of {stratum} train"
    out = []
    for i, uid in enumerate(ids):
        if i < n_train:
            out.append((uid, "train", f"in the training share ({drawn})"))
        elif i < wanted:
            out.append(
                (uid, rest, f"kept back for testing (at least {keep} {unit} of {stratum} test)")
            )
        else:
            out.append((uid, rest, f"not drawn for training ({drawn})"))
    return out


class Protocol:
    """An evaluation protocol: which measured units train and which test, per split.

    `measured_percent`: the training shares (whole numbers in 0..100); `repeats`: draws per
    share; `seed`; `min_test_records`: units per stratum kept for testing where the protocol
    keeps any; `condition`: the operating-condition column (speed_rpm, load); `healthy_state`:
    with it every test set holds healthy data (false alarms are always measured).
    """

    name: ClassVar[str]
    # the unit the split table lists: "record" (segment -1: a whole record or time block) or
    # "segment" (segment_share; records cut in time are never its units)
    unit: ClassVar[str] = "record"
    # what the measured data must carry for it beyond the signal table (MEASURED_NEEDS): the
    # config check refuses a protocol whose data lack it (System.measured_offers), before any job
    needs: ClassVar[frozenset[str]] = frozenset()
    # its splits hold out each group (a condition, a specimen) in turn: a fit per group, share
    # and repeat, the most splits of any protocol, so its train jobs are started first (train.smk)
    holds_out_each_group: ClassVar[bool] = False

    def __init__(
        self,
        measured_percent,
        repeats: int,
        seed: int,
        min_test_records: int = 1,
        condition: str = "speed_rpm",
        healthy_state: str | None = None,
    ):
        self.measured_percent = check_percents(measured_percent)
        self.repeats = check_integer("repeats", repeats, 1)
        self.seed = check_integer("seed", seed, 0)
        self.min_test_records = check_integer("min_test_records", min_test_records, 0)
        self.condition = condition
        self.healthy_state = healthy_state

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(measured_percent={self.measured_percent}, "
            f"repeats={self.repeats}, seed={self.seed})"
        )

    def stratum(self, health: str, value: float) -> str:
        """A stratum as reasons name it: "healthy at speed_rpm=450"."""
        return f"{health} at {holdout_label(value, self.condition)}"

    def units(self, records: pd.DataFrame) -> pd.DataFrame:
        """One row per unit: record_id, health_state, condition (a float)."""
        return unique_records(records, self.condition)

    def split(self, records: pd.DataFrame) -> Iterator[Split]:
        """The splits of `records`, by repeat, then share, then holdout."""
        units = self.units(records)
        self.check(units)
        for repeat in range(self.repeats):
            orders = stratum_orders(units, self.seed, repeat)
            for percent in self.measured_percent:
                for holdout, rows in self.assign(orders, percent):
                    yield Split(
                        percent,
                        repeat,
                        holdout,
                        tuple(Assignment(uid, role, reason) for uid, role, reason in rows),
                    )

    def check(self, units: pd.DataFrame) -> None:
        """Refuse (or warn about) units this protocol cannot split; nothing by default."""

    def assign(
        self, orders: dict[tuple, list[str]], percent: int
    ) -> Iterator[tuple[str, list[tuple[str, str, str]]]]:
        """(holdout, [(unit, role, reason), ...]) per split at one share and repeat."""
        raise NotImplementedError

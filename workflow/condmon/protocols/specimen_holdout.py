"""specimen_holdout: each specimen group (e.g. a fault size) in turn tests whole, at every
condition; the share trains from the other groups' records (the rest unused); healthy records
always test, so no specimen is on both sides."""

from __future__ import annotations

import pandas as pd

from condmon.hybrid import BLOCK_MARK, SplitError
from condmon.protocols.base import Protocol, draw

HEALTHY_GROUP = ""  # healthy units: never held out by group, they test in every split


class SpecimenHoldout(Protocol):
    """`specimens`: record_id, specimen, specimen_group of the measured records (the measured
    stage's records.csv)."""

    name = "specimen_holdout"
    holds_out_each_group = True
    needs = frozenset({"specimens"})

    def __init__(
        self,
        measured_percent,
        repeats,
        seed,
        min_test_records=1,
        condition="speed_rpm",
        healthy_state=None,
        specimens: pd.DataFrame | None = None,
    ):
        super().__init__(
            measured_percent, repeats, seed, min_test_records, condition, healthy_state
        )
        if specimens is None or not {"record_id", "specimen", "specimen_group"} <= set(specimens):
            raise SplitError(
                "specimen_holdout needs the specimen and specimen_group of every "
                "measured record (measured/records.csv: the system's measured "
                "stage writes them where it knows them: a system's own record "
                "files, or a measured_table's columns specimen and specimen_group)"
            )
        self.specimens = specimens
        self.group_of: dict[str, str] = {}

    def check(self, units):
        """{unit: specimen group} of every unit; healthy units get HEALTHY_GROUP."""
        group = dict(
            zip(
                self.specimens["record_id"].astype(str),
                self.specimens["specimen_group"].fillna("").astype(str),
            )
        )
        groups = {}
        for unit, health in zip(units["record_id"], units["health_state"]):
            record = unit.partition(BLOCK_MARK)[0]
            if health == self.healthy_state:
                groups[unit] = HEALTHY_GROUP
            elif not group.get(record):
                raise SplitError(f"specimen_holdout: record {record!r} has no specimen_group")
            else:
                groups[unit] = group[record]
        if len({g for g in groups.values() if g}) < 2:
            raise SplitError(
                "specimen_holdout needs fault specimens of at least two groups (sizes)"
            )
        self.group_of = groups

    def assign(self, orders, percent):
        for group in sorted({g for g in self.group_of.values() if g}):
            rows = []
            for (health, value), ids in orders.items():
                for rid in ids:
                    if self.group_of[rid] == group:
                        rows.append((rid, "test", f"held-out specimen group {group}"))
                    elif self.group_of[rid] == HEALTHY_GROUP:
                        rows.append(
                            (rid, "test", f"{health}, the healthy state: tests in every split")
                        )
                others = [rid for rid in ids if self.group_of[rid] not in (HEALTHY_GROUP, group)]
                rows += draw(others, percent, 0, self.stratum(health, value), rest="unused")
            yield f"specimen_group={group}", rows

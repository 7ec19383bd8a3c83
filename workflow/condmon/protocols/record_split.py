"""record_split: per stratum (health_state x condition) a share of whole records trains, the
rest tests; at least `min_test_records` per stratum stay in the test set."""

from __future__ import annotations

from condmon.labels import format_speed
from condmon.protocols.base import Protocol, draw, log


class RecordSplit(Protocol):
    name = "record_split"

    def check(self, units):
        sizes = units.groupby(["health_state", "condition"]).size()
        small = sizes[sizes <= self.min_test_records]
        if len(small):
            log.warning(
                "strata with <= min_test_records=%d records never train: %s",
                self.min_test_records,
                [(h, format_speed(s)) for h, s in small.index],
            )

    def assign(self, orders, percent):
        rows = []
        for (health, value), ids in orders.items():
            rows += draw(ids, percent, self.min_test_records, self.stratum(health, value))
        yield "", rows

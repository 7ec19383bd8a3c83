"""unseen_fault: only the `measured_classes` (e.g. healthy) have measured records in training:
per stratum of those classes a share of whole records trains (the healthy state keeps
`min_test_records` back, so false alarms are measured at every share, 100 % included); every
other record tests, so every other class is learnt from simulation alone."""

from __future__ import annotations

from condmon.hybrid import SplitError
from condmon.protocols.base import Protocol, draw, log


class UnseenFault(Protocol):
    name = "unseen_fault"

    def __init__(
        self,
        measured_percent,
        repeats,
        seed,
        min_test_records=1,
        condition="speed_rpm",
        healthy_state=None,
        measured_classes=None,
    ):
        super().__init__(
            measured_percent, repeats, seed, min_test_records, condition, healthy_state
        )
        if not measured_classes:
            raise SplitError(
                "unseen_fault needs measured_classes: the health states whose "
                "measured records may train (e.g. [normal])"
            )
        self.measured_classes = set(measured_classes)

    def check(self, units):
        absent = sorted(self.measured_classes - set(units["health_state"]))
        if absent:
            log.warning("unseen_fault: measured class(es) %s have no measured record", absent)

    def assign(self, orders, percent):
        rows = []
        for (health, value), ids in orders.items():
            if health not in self.measured_classes:
                rows += [
                    (rid, "test", f"class {health} never measured in training: unseen")
                    for rid in ids
                ]
                continue
            keep = self.min_test_records if health == self.healthy_state else 0
            rows += draw(ids, percent, keep, self.stratum(health, value))
        yield "", rows

"""segment_share: a published study's protocol, kept for comparison: per health state, a share
of all its measured segments trains and the rest tests (at least max(1, min_test_records)). Segments of one record
land on both sides (leaky: the report labels its numbers so)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from condmon.hybrid import SplitError
from condmon.protocols.base import Assignment, Protocol, Split, draw
from condmon.seeds import derive_seed, stable_int


def class_segment_orders(segments: pd.DataFrame, seed: int, repeat: int) -> dict[str, list]:
    """Per health state: its (record_id, segment) pairs in this repeat's random order."""
    orders = {}
    for health, group in segments.groupby("health_state", sort=True):
        pairs = sorted(zip(group["record_id"].astype(str), group["segment"].astype(int)))
        rng = np.random.default_rng(derive_seed(seed, repeat, stable_int(f"segments|{health}")))
        orders[health] = [pairs[i] for i in rng.permutation(len(pairs))]
    return orders


class SegmentShare(Protocol):
    name = "segment_share"
    unit = "segment"

    def split(self, records):
        if "segment" not in records.columns:
            raise SplitError("segment_share needs the segment column of the measured features")
        units = self.units(records)
        segments = (
            records[["record_id", "segment"]]
            .drop_duplicates()
            .merge(units[["record_id", "health_state"]], on="record_id")
        )
        for repeat in range(self.repeats):
            orders = class_segment_orders(segments, self.seed, repeat)
            for percent in self.measured_percent:
                assignments = []
                for health, pairs in orders.items():
                    drawn = draw(
                        pairs,
                        percent,
                        max(1, self.min_test_records),
                        f"class {health} (leaky)",
                        unit="segments",
                    )
                    assignments += [
                        Assignment(rid, role, reason, seg) for (rid, seg), role, reason in drawn
                    ]
                yield Split(percent, repeat, "", tuple(assignments))

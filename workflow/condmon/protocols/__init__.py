"""Evaluation protocols as splitter objects, one file each, and the registry of them.

Protocols (each file says what its test set is):
- record_split: per stratum (health_state x condition) a share of whole records trains;
- condition_holdout: each condition in turn (or hybrid.condition_split's test side) tests whole;
- segment_share: per class a share of segments trains (leaky: segments of one record on both
  sides);
- unseen_fault: only hybrid.measured_classes have measured training records;
- specimen_holdout: each specimen group in turn tests whole, healthy records always test.

`make_protocol(name, **params)` builds one (scikit-learn's GroupKFold shape: parameters in the
constructor, `split(records)` yields one `Split` per (measured_percent, repeat, holdout), each
unit with its role and the reason it has it); `make_splits(records, protocol, ...)` gives its
split table, with the calibration set and the simulated validation set around it, and with
`reasons=True` a `reason` column (kept out of the written table, whose format is fixed). A new
protocol is one file with a `Protocol` subclass and one line in registry.REGISTRY.
"""

from __future__ import annotations

from condmon.protocols.base import Assignment, Protocol, Split
from condmon.protocols.registry import PROTOCOLS, REGISTRY, make_protocol, protocol_from
from condmon.protocols.table import check_healthy_tested, make_splits

__all__ = [
    "Assignment",
    "PROTOCOLS",
    "Protocol",
    "REGISTRY",
    "Split",
    "check_healthy_tested",
    "make_protocol",
    "make_splits",
    "protocol_from",
]

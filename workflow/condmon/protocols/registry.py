"""The protocols by name: one line per protocol (its file holds the class)."""

from __future__ import annotations

import inspect

from condmon.hybrid import SplitError
from condmon.protocols.base import Protocol
from condmon.protocols.condition_holdout import ConditionHoldout
from condmon.protocols.record_split import RecordSplit
from condmon.protocols.segment_share import SegmentShare
from condmon.protocols.specimen_holdout import SpecimenHoldout
from condmon.protocols.unseen_fault import UnseenFault

REGISTRY: dict[str, type[Protocol]] = {
    cls.name: cls
    for cls in (RecordSplit, ConditionHoldout, SegmentShare, UnseenFault, SpecimenHoldout)
}
PROTOCOLS = tuple(REGISTRY)


def make_protocol(name: str, **params) -> Protocol:
    """The protocol `name` with its parameters; an unknown name is an error listing the valid
    ones, a parameter it does not take an error naming the ones it does."""
    if name not in REGISTRY:
        raise SplitError(f"unknown protocol {name!r}; choose one of {list(PROTOCOLS)}")
    unknown = sorted(set(params) - set(parameters(name)))
    if unknown:
        raise SplitError(
            f"protocol {name!r} takes no parameter(s) {unknown}; it takes {list(parameters(name))}"
        )
    return REGISTRY[name](**params)


def protocol_from(name: str, offered: dict) -> Protocol:
    """The protocol `name` built from the parameters of `offered` it takes (the hybrid rule
    offers every protocol's: measured_classes, condition_split, specimens, ...)."""
    if name not in REGISTRY:
        make_protocol(name)  # the error listing the valid names
    return make_protocol(
        name, **{key: value for key, value in offered.items() if key in parameters(name)}
    )


def parameters(name: str) -> tuple[str, ...]:
    """The constructor parameters of protocol `name` (the shared ones and its own)."""
    return tuple(p for p in inspect.signature(REGISTRY[name]).parameters)

"""How every output names things: protocols (leaky ones say so), data sources, operating
conditions, holdouts and class labels.

One small module with no condmon imports, so the report, tracking, plots, evaluation, the model
store and the scripts label alike without importing each other.
"""

from __future__ import annotations

# segments of one record on both sides of the split: never a headline, labelled wherever it appears
LEAKY_PROTOCOLS = ("segment_share",)

# What each protocol's test set is: every number the report gives is labelled with it.
PROTOCOL_LABELS = {
    "record_split": (
        "whole measured records held out; the same fault specimen may be trained "
        "on at another condition (a lone healthy record: its time blocks)"
    ),
    "condition_holdout": (
        "a whole operating condition held out (speed or load never seen); the "
        "same fault specimen may be trained on at another condition; where the "
        "held-out condition has no healthy record, healthy records of another "
        "condition test"
    ),
    "segment_share": (
        "LEAKY (the bearing study's protocol): segments of the same records on "
        "both sides of the split"
    ),
    "unseen_fault": (
        "faults never measured: measured training data holds only the configured "
        "measured classes (healthy records always keep a test share); the other "
        "classes come from simulation alone (never seen by the classifier; the "
        "design may have looked at their specimens: design_records says which)"
    ),
    "specimen_holdout": (
        "whole fault specimens held out: every specimen of one group (fault "
        "size) tests at every condition, the share trains from the other "
        "groups; healthy records only test: no specimen on both sides"
    ),
}

# Data-source kinds that are not real measurements; anything labelled with them must say so.
SYNTHETIC_SOURCES = {"virtual_bench": "virtual bench (synthetic)"}


# --------------------------------------------------------------------------- protocols


def is_leaky(protocol: str) -> bool:
    """Segments of one record on both sides of the protocol's split."""
    return protocol in LEAKY_PROTOCOLS


def protocol_title(protocol: str) -> str:
    """A protocol's name as every output shows it: leaky ones say so."""
    return f"{protocol} (LEAKY)" if is_leaky(protocol) else protocol


def protocol_label(protocol: str) -> str:
    """What the protocol's test set is (PROTOCOL_LABELS; an unknown protocol: its name)."""
    return PROTOCOL_LABELS.get(protocol, protocol)


# --------------------------------------------------------------------------- data source


def is_synthetic(data_source: str) -> bool:
    return data_source in SYNTHETIC_SOURCES


def data_source_label(data_source: str) -> str:
    """Short label for titles and footnotes, e.g. "virtual bench (synthetic)"."""
    if is_synthetic(data_source):
        return SYNTHETIC_SOURCES[data_source]
    if data_source == "measured":
        return "measured (test-bench recordings)"
    return data_source


# --------------------------------------------------------------------------- conditions, holdouts


def format_speed(speed_rpm: float) -> str:
    """775.0 -> "775", 1797.5 -> "1797.5" (for holdout labels)."""
    speed_rpm = float(speed_rpm)
    return str(int(speed_rpm)) if speed_rpm.is_integer() else repr(speed_rpm)


def holdout_label(value: float, condition: str = "speed_rpm") -> str:
    return f"{condition}={format_speed(value)}"


def sorted_holdouts(holdouts) -> list[str]:
    """Distinct holdout labels in a stable order: by held-out speed, "" (none) first.

    The position in this list is the holdout index used in model file names.
    """

    def key(label: str):
        _, _, value = label.partition("=")
        try:
            return (1, float(value), label)
        except ValueError:
            return (0 if label == "" else 2, 0.0, label)

    return sorted(set(holdouts), key=key)


# --------------------------------------------------------------------------- class labels


def label_order(labels, healthy_state: str | None = None) -> list[str]:
    """Class labels sorted, the system's healthy state first so confusion matrices read from it.
    Pass true and predicted labels: a class may be predicted but never tested (a folder without
    healthy records)."""
    labels = sorted(set(labels))
    return sorted(labels, key=lambda label: label != healthy_state)

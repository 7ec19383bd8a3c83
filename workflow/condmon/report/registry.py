"""The report's sections in the order write_report runs them: one line per section (its module
holds its SECTION). The order is the order of summary.json's keys and of its plot list. A new
table is one module with a SECTION and one line here: report.smk's outputs and the report pages'
tables follow from `tables()`."""

from __future__ import annotations

from condmon.report import (
    accuracy,
    calibration,
    calibration_set,
    ceiling,
    conditions,
    evaluation_tables,
    gain,
    headline,
    measured_share,
    physics,
    prediction_shares,
    recall_per_record,
    signatures,
    simulated_ceiling,
    stages,
    timings,
    fault_location,
    shaft_tracking,
)
from condmon.report.section import Section, Table

SECTIONS: list[Section] = [
    accuracy.SECTION,
    prediction_shares.SECTION,
    calibration.SECTION,
    stages.SECTION,
    timings.SECTION,
    evaluation_tables.SECTION,
    calibration_set.SECTION,
    ceiling.SECTION,
    simulated_ceiling.SECTION,
    signatures.SECTION,
    gain.SECTION,
    physics.SECTION,
    conditions.SECTION,
    headline.SECTION,
    recall_per_record.SECTION,
    measured_share.SECTION,
    fault_location.SECTION,
    shaft_tracking.SECTION,
]


def tables() -> list[Table]:
    """Every table of the registered sections, in their order; two of one name are an error."""
    found = [table for section in SECTIONS for table in section.tables]
    names = [table.name for table in found]
    twice = sorted({name for name in names if names.count(name) > 1})
    if twice:
        raise ValueError(f"report tables {twice} are declared by more than one section")
    return found

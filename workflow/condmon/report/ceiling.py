"""The ceiling section: summary.json's `measured_separability`, how well the measured records
separate their classes on their own (condmon.separability: a classifier on the measured records
alone, each record left out, over all records and per condition), on the modelled specimens'
records as the headline; the headline's last row. Conditions where the measured records' own
classifier misses a class are logged (exempt from what simulation is asked)."""

from __future__ import annotations

from condmon.report.section import Section


def write(report) -> dict:
    report.summary["measured_separability"] = report.separability
    return {}


SECTION = Section(
    "ceiling",
    write,
    inputs=("evaluation.measured_features", "evaluation.condition", "evaluation.unmodelled"),
    requires=("evaluation.measured_features",),
    summary_keys=("measured_separability",),
)

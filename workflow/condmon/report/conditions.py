"""The per-condition section (with the measured features): plots of the accuracy per operating
condition (`hybrid.condition`'s value of each record) and, with design records, on design records
against records never used in design."""

from __future__ import annotations

from condmon import evaluation, plots
from condmon.report.section import Section


def write(report) -> dict:
    overall = report.evaluation.overall
    whole = overall["condition"] == evaluation.ALL
    subsets = [
        (
            "condition",
            overall[~whole & (overall["records"] == evaluation.ALL)],
            "Accuracy per operating condition",
            "accuracy_per_condition.png",
        ),
        (
            "records",
            overall[whole & (overall["records"] != evaluation.ALL)],
            "Accuracy on design records vs records never used in design",
            "accuracy_design_vs_evaluation.png",
        ),
    ]
    for column, rows, title, name in subsets:
        if not rows.empty:
            report.save(
                plots.accuracy_per_subset(rows, column, report.chance, report.note(), title), name
            )
    return {}


SECTION = Section(
    "conditions",
    write,
    inputs=("evaluation.measured_features", "evaluation.condition", "evaluation.design_records"),
    requires=("evaluation.measured_features",),
)

"""The fault signatures section: summary.json's `fault_signatures` (condmon.signature: each fault
class's measured and simulated shift from healthy, and how alike their directions are) and its
plot (none without a fault class measured and simulated at one condition), with the measured and
simulated features and a healthy state."""

from __future__ import annotations

import logging

from condmon import plots
from condmon.report.section import Section
from condmon.signature import fault_signatures, signature_table

log = logging.getLogger(__name__)


def write(report) -> dict:
    if not report.compares_signatures:
        return {}
    (measured, names), condition = report.measured, report.condition
    signatures = fault_signatures(
        measured, report.simulated, names, report.run.healthy_state, condition
    )
    report.summary["fault_signatures"] = signatures
    table = signature_table(signatures)
    if not table.empty:
        log.info(
            "fault signatures (shift in simulated healthy spreads, measured / simulated, direction):\n%s",
            table.round(2).to_string(index=False),
        )
        report.save(plots.fault_signatures(table, condition, report.note()), "fault_signatures.png")
    return {}


SECTION = Section(
    "fault_signatures",
    write,
    inputs=(
        "evaluation.measured_features",
        "evaluation.simulated_features",
        "evaluation.condition",
        "run.healthy_state",
    ),
    requires=("evaluation.measured_features", "evaluation.simulated_features", "run.healthy_state"),
    summary_keys=("fault_signatures",),
)

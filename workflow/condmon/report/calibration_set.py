"""The calibration set section: summary.json `calibration_set`, which measured records calibrated
(the calibrate jobs saw them and, with the healthy reference on, every segment was taken against
them, so no split trains on or tests them): those that calibrated whole, and those split in time
(a condition's lone healthy record: its first segments calibrate, blocks after guard gaps test;
`calibration.reserve`)."""

from __future__ import annotations

from condmon.hybrid import CALIBRATION, measured_layout
from condmon.report.section import Section


def calibration_summary(layout) -> dict:
    """{whole: [records calibrating whole], split_in_time: {record: what its segments do}} of a
    measured layout (`condmon.hybrid.measured_layout`)."""
    whole, split = [], {}
    for record, segments in layout.groupby("record_id", sort=True):
        roles = segments["fixed_role"]
        if (roles == CALIBRATION).all():
            whole.append(str(record))
        elif (roles == CALIBRATION).any():
            blocks = segments.loc[roles == "", "unit"].nunique()
            split[str(record)] = (
                f"{int((roles == CALIBRATION).sum())} of {len(segments)} segments calibrate, "
                f"{blocks} time blocks test"
            )
    return {"whole": whole, "split_in_time": split}


def write(report) -> dict:
    spec = report.inputs.evaluation.calibration_set
    frame, _ = report.measured
    layout = measured_layout(frame, spec["healthy_state"], spec["condition"], dict(spec["reserve"]))
    report.summary["calibration_set"] = calibration_summary(layout)
    return {}


SECTION = Section(
    "calibration_set",
    write,
    inputs=("evaluation.calibration_set", "evaluation.measured_features"),
    requires=("evaluation.calibration_set", "evaluation.measured_features"),
    summary_keys=("calibration_set",),
)

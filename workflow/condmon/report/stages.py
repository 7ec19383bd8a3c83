"""The earlier stages' section: summary.json's `simulation` (samples, failures with their
parameters, cost of the simulation jobs), `measured_records` (what the measured stage kept and
left out, from records.csv) and, with hybrid.simulated_validation_share > 0, `simulated_validation`:
the train stage's accuracy on held-out SIMULATED records, aggregated like the measured results but
never mixed into them (nor into accuracy.csv or the plots).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from condmon.hybrid import SIMULATED_VALIDATION
from condmon.report.aggregate import accuracy_entry, over_repeats, per_speed
from condmon.report.section import Section

SIMULATED_VALIDATION_LABEL = (
    "accuracy on SIMULATED records held out of training (hybrid.simulated_validation_share), "
    "not on measured data: never part of the measured results"
)


def write(report) -> dict:
    """The summary keys of the simulation, the measured records and the simulated validation."""
    upstream, validation = report.inputs.upstream, report.simulated_validation
    report.summary["simulation"] = simulation_summary(upstream.simulation_reports)
    if upstream.measured_records is not None:
        report.summary["measured_records"] = measured_records_summary(upstream.measured_records)
    if report.inputs.train.simulated_validation:  # hybrid.simulated_validation_share > 0
        report.summary["simulated_validation"] = (
            simulated_validation_summary(validation)
            if validation is not None
            else {
                "test_source": SIMULATED_VALIDATION,
                "label": SIMULATED_VALIDATION_LABEL,
                "results": [],
                "note": "no simulated record was held out (every stratum's "
                "share rounds to zero records)",
            }
        )
    return {}


SECTION = Section(
    "stages",
    write,
    inputs=(
        "upstream.simulation_reports",
        "upstream.measured_records",
        "train.simulated_validation",
    ),
    summary_keys=("simulation", "measured_records", "simulated_validation"),
)


def simulation_summary(report_paths) -> dict:
    """Samples, failures (with their parameters) and cost of the simulation jobs."""
    reports = [json.loads(Path(p).read_text()) for p in report_paths]
    wall = [s for r in reports for s in r["wall_seconds"]]
    simulated = sum(r["simulated_seconds_per_sample"] * r["samples"] for r in reports)
    return {
        "samples": sum(r["samples"] for r in reports),
        "failed": sum(len(r["failures"]) for r in reports),
        "failures": [f for r in reports for f in r["failures"]],
        "wall_seconds_per_sample": float(np.mean(wall)) if wall else None,
        "wall_seconds_per_simulated_second": sum(wall) / simulated if simulated else None,
    }


def measured_records_summary(records_path) -> dict:
    """What the measured stage kept and left out (file, class, reason) from records.csv."""
    records = pd.read_csv(records_path, dtype=str, keep_default_na=False)
    left_out = records[records["status"] != "kept"]
    columns = [
        c
        for c in ("file", "record_id", "fault", "diameter_in", "load_hp", "reason")
        if c in records.columns
    ]
    return {
        "kept": int((records["status"] == "kept").sum()),
        "left_out": left_out[columns].to_dict(orient="records"),
    }


def simulated_validation_summary(validation: pd.DataFrame) -> dict:
    """summary.json's ``simulated_validation``: per classifier, protocol and measured percent the
    accuracy on the held-out simulated records (mean, spread over repeats, per speed), labelled
    as simulated; ``validation`` is the table of load_simulated_validation."""
    segments = (
        validation[validation["speed_rpm"].isna()]
        .groupby(["classifier", "protocol", "measured_percent"])["n_test"]
        .max()
    )
    speeds = per_speed(validation)
    results = [
        {
            **accuracy_entry(row, speeds),
            "n_validation_segments": int(
                segments[(row.classifier, row.protocol, row.measured_percent)]
            ),
        }
        for row in over_repeats(validation).itertuples(index=False)
    ]
    return {
        "test_source": SIMULATED_VALIDATION,
        "label": SIMULATED_VALIDATION_LABEL,
        "aggregation": "as the measured results: mean and sample std over repeats, "
        "condition_holdout's holdouts averaged within a repeat first",
        "results": results,
    }

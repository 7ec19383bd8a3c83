"""The shaft tracking section: shaft_tracking.csv, per measured record how many of its segments had
their shaft angle from the spectral line a system family follows (its tacholess tracking,
measured_shaft_tracking.csv; the system's docs say which line) and how many fell back on the
nominal speed, with the line's level over its floor. A record on the nominal speed has its high
orders smeared wherever its speed wanders: a sampling rate, geometry or speed that puts the line
elsewhere, or a line lost in noise. summary.json `shaft_tracking`: the counts and the records
that fell back."""

from __future__ import annotations

import pandas as pd

from condmon.report.section import Section, Table

COLUMNS = [
    "record_id",
    "health_state",
    "speed_rpm",
    "segments",
    "nominal_segments",
    "line_to_floor_median",
]


def record_tracking(segments: pd.DataFrame) -> pd.DataFrame:
    """Per record: its segments, those on the nominal speed, the median line-to-floor ratio."""
    grouped = segments.groupby("record_id", sort=True)
    return pd.DataFrame(
        {
            "health_state": grouped["health_state"].first(),
            "speed_rpm": grouped["speed_rpm"].first().astype(float),
            "segments": grouped.size(),
            "nominal_segments": grouped["method"].agg(lambda m: int((m == "nominal").sum())),
            "line_to_floor_median": grouped["line_to_floor"].median(),
        }
    ).reset_index()[COLUMNS]


def write(report) -> dict:
    """The table (empty where no feature family tracks the shafts) and summary.json's
    `shaft_tracking`."""
    path = report.inputs.evaluation.shaft_tracking
    if path is None:
        return {"shaft_tracking": pd.DataFrame(columns=COLUMNS)}
    table = record_tracking(pd.read_csv(path))
    fell_back = table[table["nominal_segments"] > 0]
    report.summary["shaft_tracking"] = {
        "segments": int(table["segments"].sum()),
        "nominal_segments": int(table["nominal_segments"].sum()),
        "records_on_nominal_speed": {
            row.record_id: f"{row.nominal_segments} of {row.segments}"
            for row in fell_back.itertuples()
        },
    }
    return {"shaft_tracking": table}


SECTION = Section(
    "shaft_tracking",
    write,
    inputs=("evaluation.shaft_tracking",),
    tables=(
        Table(
            "shaft_tracking",
            "shaft_tracking.csv",
            "How the shafts were tracked (shaft_tracking.csv)",
            "Per measured record: its segments whose shaft angle came from the tracked line, "
            "those that fell back on the nominal speed (a rate, geometry or speed that puts the "
            "line elsewhere, or a line lost in noise), and the line's median level over its floor.",
        ),
    ),
    summary_keys=("shaft_tracking",),
)

"""The fault location section: fault_location.csv, per measured fault record and damaged part the
position its segments name (a system family's localisation, measured_fault_locations.csv, in a
frame of the machine's own: the same position on every record of it; the system's docs say what a
position is), how many of its segments agree and how sure they are (the share of the change at
that position); where the records carry the truth (a virtual bench), whether it is named right:
the position overlaps the `span` positions from where a damaged one begins. With several located
parts (the system says what a part is), the one whose change is largest holds the fault.
summary.json `fault_location`: the share of the scored records named right, per class, and of the
records whose part holding the change is the damaged one."""

from __future__ import annotations

import json

import pandas as pd

from condmon.report.section import Section, Table


def positions_of(value) -> list[float]:
    """A `true_positions` cell: a list, or its text in a CSV."""
    return json.loads(value) if isinstance(value, str) else list(value)


def named_right(position: int, true_positions, positions: int, span: float) -> bool:
    """Whether position `position` ([position, position + 1)) overlaps what a damaged one reaches:
    from any of `true_positions` for `span` positions, round a part of `positions` positions."""
    return any(0 < (position + 1 - p) % positions < span + 1 for p in true_positions)


def record_locations(located: pd.DataFrame) -> pd.DataFrame:
    """Per record and part: the position most of its segments name, their agreement (share of its
    segments naming it), the mean share of the change there (how sure), and the truth's positions
    and whether it is named right (None where there is no truth); with several located parts,
    the part whose mean `level` is highest holds the change (`holds_change`),
    beside whether the bench damaged it (`true_part`, None without truth)."""
    rows = []
    if "level" not in located:  # a family that gives no levels: every part alone
        located = located.assign(level=float("nan"), true_part=None)
    for (record, part), segments in located.groupby(["record_id", "part"], sort=True):
        named = segments["position"].astype(int)
        position = int(named.mode().min())
        truth = positions_of(segments["true_positions"].iloc[0])
        rows.append(
            {
                "record_id": record,
                "health_state": segments["health_state"].iloc[0],
                "speed_rpm": float(segments["speed_rpm"].iloc[0]),
                "part": part,
                "position": position,
                "agreement": float((named == position).mean()),
                "share": float(segments.loc[named == position, "share"].mean()),
                "true_positions": truth,
                "named_right": (
                    named_right(
                        position,
                        truth,
                        int(segments["positions"].iloc[0]),
                        float(segments["span"].iloc[0]),
                    )
                    if truth
                    else None
                ),
                "level": float(segments["level"].mean()),
                "true_part": _truth_of(segments["true_part"].iloc[0]),
            }
        )
    table = pd.DataFrame(rows)
    highest = table.groupby("record_id")["level"].transform("max")
    return table.assign(holds_change=table["level"] >= highest)


def _truth_of(value):
    """A `true_part` cell (a bool, its text in a CSV, or nothing) as True, False or None."""
    if value is None or (isinstance(value, float) and pd.isna(value)):
        return None
    return value if isinstance(value, bool) else str(value) == "True"


def part_named_right(table: pd.DataFrame) -> float | None:
    """The share of the records of several located parts with the truth whose part holding the
    change is the damaged one (None: no such record)."""
    scored = table.dropna(subset=["true_part"])
    scored = scored[scored.groupby("record_id")["part"].transform("size") > 1]
    held = scored[scored["holds_change"]]
    return float(held["true_part"].astype(bool).mean()) if len(held) else None


COLUMNS = [
    "record_id",
    "health_state",
    "speed_rpm",
    "part",
    "position",
    "agreement",
    "share",
    "true_positions",
    "named_right",
    "level",
    "holds_change",
    "true_part",
]


def write(report) -> dict:
    """The table (empty where no feature family locates faults) and, with located fault records,
    summary.json's `fault_location`."""
    path = report.inputs.evaluation.fault_locations
    located = pd.read_csv(path) if path is not None else pd.DataFrame(columns=["health_state"])
    located = located[located["health_state"] != report.run.healthy_state]
    if located.empty:
        return {"fault_location": pd.DataFrame(columns=COLUMNS)}
    table = record_locations(located)
    scored = table.dropna(subset=["named_right"])
    report.summary["fault_location"] = {
        "records": int(len(table)),
        "scored": int(len(scored)),
        "named_right": float(scored["named_right"].astype(bool).mean()) if len(scored) else None,
        "per_class": {
            state: float(part["named_right"].astype(bool).mean())
            for state, part in scored.groupby("health_state")
        },
        "part_named_right": part_named_right(table),
    }
    return {"fault_location": table.assign(true_positions=table["true_positions"].map(json.dumps))}


SECTION = Section(
    "fault_location",
    write,
    inputs=("evaluation.fault_locations", "run.healthy_state"),
    tables=(
        Table(
            "fault_location",
            "fault_location.csv",
            "Where the fault sits (fault_location.csv)",
            "Per measured fault record and damaged part: the position its segments name (in "
            "the machine's own frame), their agreement and how sure; on a bench whether it is "
            "named right.",
        ),
    ),
    summary_keys=("fault_location",),
)

"""Do the simulated faults move the features as the measured faults do?

A classifier trained on simulation recognises a measured fault only where the fault moves the
features beyond what the simulation calls normal variation, and the way the simulated fault does.
Per operating condition and fault class, both shifts are taken from their own healthy class:
the measured class's mean from the measured healthy segments' mean, the simulated class's from the
simulated healthy's, each feature in units of the simulated healthy segments' spread (the variation
a simulation-trained classifier learns as healthy). Then

- `measured_shift`, `simulated_shift`: the root mean square of the shift over the features;
- `direction_correlation`: the correlation of the two shifts over the features (1: the same
  direction, 0: unrelated).

A measured fault whose shift is well below one spread, or whose direction is unlike the simulated
fault's, cannot be recognised from simulation, whatever the classifier; the measured-only ceiling
(`condmon.separability`) says whether the measured records show it at all. The report gives both
beside the accuracy (summary.json `fault_signatures`). It needs labelled measured fault records:
a bench, or a rig whose faults were recorded.

`outside_simulation` asks it of each measured record, labels aside: how many of its segments lie
where no simulated segment does (recall_per_record.csv).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

METHOD = (
    "per condition and fault class: mean shift from the healthy class, measured and simulated "
    "apart, each feature in units of the simulated healthy spread; shift = rms over features, "
    "direction = correlation of the two shifts over features"
)


def healthy_spread(simulated: pd.DataFrame, names, healthy_state: str) -> pd.Series:
    """Each feature's standard deviation over the simulated healthy segments; features that do not
    vary there (NaN or 0) are left out."""
    spread = simulated.loc[simulated["health_state"] == healthy_state, list(names)].std()
    return spread[spread > 0]


def class_shift(
    frame: pd.DataFrame, state: str, healthy_state: str, spread: pd.Series
) -> pd.Series:
    """The mean of `state`'s segments minus the healthy segments' mean, per feature of `spread`,
    in units of it."""
    columns = list(spread.index)
    mean = frame.loc[frame["health_state"] == state, columns].mean()
    healthy = frame.loc[frame["health_state"] == healthy_state, columns].mean()
    return (mean - healthy) / spread


def compare_shifts(measured: pd.Series, simulated: pd.Series) -> dict:
    """rms of each shift and their correlation over the features both define."""
    both = measured.notna() & simulated.notna()
    measured, simulated = measured[both].to_numpy(float), simulated[both].to_numpy(float)
    correlation = (
        float(np.corrcoef(measured, simulated)[0, 1])
        if len(measured) > 1 and measured.std() > 0 and simulated.std() > 0
        else None
    )
    return {
        "measured_shift": float(np.sqrt(np.mean(measured**2))) if len(measured) else None,
        "simulated_shift": float(np.sqrt(np.mean(simulated**2))) if len(simulated) else None,
        "direction_correlation": correlation,
        "features": int(both.sum()),
    }


def fault_signatures(
    measured: pd.DataFrame, simulated: pd.DataFrame, names, healthy_state: str, condition: str
) -> dict:
    """METHOD for every value of `condition` the measured records have (the simulated rows at the
    nearest simulated value) and every fault class with measured and simulated segments there."""
    per_condition = {}
    simulated_values = np.sort(simulated[condition].unique())
    for value in np.sort(measured[condition].unique()):
        nearest = simulated_values[np.argmin(np.abs(simulated_values - value))]
        here = measured[measured[condition] == value]
        simulated_here = simulated[simulated[condition] == nearest]
        spread = healthy_spread(simulated_here, names, healthy_state)
        if spread.empty or not (here["health_state"] == healthy_state).any():
            continue
        states = sorted(
            set(here["health_state"]) & set(simulated_here["health_state"]) - {healthy_state}
        )
        rows = {}
        for state in states:
            rows[state] = {
                **compare_shifts(
                    class_shift(here, state, healthy_state, spread),
                    class_shift(simulated_here, state, healthy_state, spread),
                ),
                "measured_records": int(
                    here.loc[here["health_state"] == state, "record_id"].nunique()
                ),
            }
        if rows:
            per_condition[f"{value:g}"] = {"simulated_at": float(nearest), "classes": rows}
    return {"method": METHOD, "condition": condition, "per_condition": per_condition}


def outside_simulation(
    measured: pd.DataFrame, simulated: pd.DataFrame, names, listed: int = 5
) -> pd.DataFrame:
    """Per measured record: the share of its segments with a feature outside the range of every
    simulated segment (its minimum to maximum over all classes and conditions), and those
    features. A classifier trained on simulation extrapolates there: its call on such a segment
    rests on no simulated example, however confident it is. Columns `record_id`,
    `outside_simulation`, `features_outside_simulation` (comma-separated, the `listed` features
    out on most of the record's segments first, then how many more)."""
    names = list(names)
    values = measured[names]
    outside = values.lt(simulated[names].min()) | values.gt(simulated[names].max())
    record = measured["record_id"].astype(str)
    share = outside.any(axis=1).groupby(record).mean()
    per_feature = outside.groupby(record).mean()

    def leaving(row: pd.Series) -> str:
        out = row[row > 0].sort_values(ascending=False, kind="stable")
        more = f" (+{len(out) - listed} more)" if len(out) > listed else ""
        return ", ".join(out.index[:listed]) + more

    return pd.DataFrame(
        {
            "record_id": share.index,
            "outside_simulation": share.to_numpy(float),
            "features_outside_simulation": [
                leaving(per_feature.loc[record_id]) for record_id in share.index
            ],
        }
    )


def signature_table(signatures: dict) -> pd.DataFrame:
    """One row per (condition value, fault class) of `fault_signatures`' result."""
    rows = [
        {"condition": value, "health_state": state, **figures}
        for value, entry in signatures["per_condition"].items()
        for state, figures in entry["classes"].items()
    ]
    return pd.DataFrame(
        rows,
        columns=[
            "condition",
            "health_state",
            "measured_shift",
            "simulated_shift",
            "direction_correlation",
            "features",
            "measured_records",
        ],
    )


# A design record is covered by the simulation when at most this share of its segments leaves the
# range the classifier was trained on, on the classifier's own features: one segment in twenty (a
# record of 29 segments may have one out; a finite simulated sample has tails of its own).
COVERAGE_TOLERANCE = 0.05


def pooled_coverage(coverage: pd.DataFrame) -> pd.DataFrame:
    """coverage.csv's rows (condmon.joined.COVERAGE_COLUMNS) pooled over repeats and holdouts per
    (classifier, protocol, measured_percent, record_id): `outside_training` weighted by each
    split's segments, `features_outside_training` the union."""
    keys = ["classifier", "protocol", "measured_percent", "record_id"]
    rows = coverage.assign(
        record_id=coverage["record_id"].astype(str),
        _out=coverage["outside_training"] * coverage["n_segments"],
    )

    def union(values) -> str:
        names = [n.strip() for v in values if isinstance(v, str) for n in v.split(",") if n.strip()]
        return ", ".join(dict.fromkeys(names))

    pooled = rows.groupby(keys, as_index=False).agg(
        n_segments=("n_segments", "sum"),
        _out=("_out", "sum"),
        features_outside_training=("features_outside_training", union),
        features=("features", union),
    )
    pooled["outside_training"] = pooled.pop("_out") / pooled["n_segments"]
    return pooled


def simulation_coverage(
    coverage: pd.DataFrame, design_records, tolerance: float = COVERAGE_TOLERANCE
) -> dict:
    """summary.json `simulation_coverage`: does the simulation cover the design records on the
    features each classifier uses? Per classifier and protocol, at its lowest measured share (0 %:
    trained on simulation alone, so its training range is the simulated one), the design records'
    share of segments outside the training range (`pooled_coverage`), the records above
    `tolerance` and `covers_design_records` (none above it; false without a tested design
    record). Evaluation records are listed beside, never judged."""
    design = set(map(str, design_records))
    entries = []
    for (classifier, protocol), rows in pooled_coverage(coverage).groupby(
        ["classifier", "protocol"], sort=True
    ):
        lowest = int(rows["measured_percent"].min())
        at = rows[rows["measured_percent"] == lowest].set_index("record_id")
        mine = at[at.index.isin(design)]
        out = mine[mine["outside_training"] > tolerance]
        others = at[~at.index.isin(design)]
        entries.append(
            {
                "classifier": classifier,
                "protocol": protocol,
                "measured_percent": lowest,
                "features": sorted(
                    {n.strip() for f in at["features"] for n in f.split(",") if n.strip()}
                ),
                "design_records": int(len(mine)),
                "design_segments_outside": (
                    float(
                        (mine["outside_training"] * mine["n_segments"]).sum()
                        / mine["n_segments"].sum()
                    )
                    if len(mine)
                    else None
                ),
                "design_records_outside": {
                    r: {
                        "share": round(float(row["outside_training"]), 4),
                        "features": row["features_outside_training"],
                    }
                    for r, row in out.iterrows()
                },
                "covers_design_records": bool(len(mine) and out.empty),
                "other_records_outside": {
                    r: round(float(row["outside_training"]), 4)
                    for r, row in others.iterrows()
                    if row["outside_training"] > tolerance
                },
            }
        )
    return {
        "tolerance": tolerance,
        "method": (
            "per classifier and protocol at its lowest measured share: each tested "
            "record's share of segments with a feature (of the fit's own) outside the "
            "fit's training range (coverage.csv of the joined job), pooled over "
            "repeats and holdouts; a design record is covered at or below the "
            "tolerance"
        ),
        "results": entries,
    }

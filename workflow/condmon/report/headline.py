"""The headline section: headline.csv, the report's front-page table (workflow/report/workflow.rst
embeds it): per protocol every classifier's accuracy on held-out measured records at the smallest
and the largest measured share, the baselines on the same test sets, chance, and the ceiling of
the measured records alone; on the evaluation specimens' records where design records are
declared."""

from __future__ import annotations

import numpy as np
import pandas as pd

from condmon import evaluation
from condmon.labels import protocol_title
from condmon.report.aggregate import over_repeats
from condmon.report.section import Section, Table

HEADLINE_NOTE = (
    "Mean over repeats (min-max over repeats where they differ) of the accuracy on "
    "measured records never seen in training, at the smallest and the largest "
    "share of measured data in training, per test protocol; the baselines on the "
    "same test sets below each protocol's classifiers. `records`: all test records, "
    "or the evaluation specimens' (the headline) and the design specimens' apart. "
    "The last row, where the measured records allow it: a classifier on the measured "
    "records alone, each left out in turn, the ceiling for one trained on simulation."
)


def write(report) -> dict:
    if not report.wants("headline"):
        return {}
    tables = report.evaluation
    table, physics_table, baseline_table, physics_overall = (
        (None, None, None, None)
        if tables is None
        else (tables.table, tables.physics_table, tables.baseline_table, tables.physics_overall)
    )
    headline = headline_table(
        report.accuracy,
        report.baseline,
        physics_overall,
        report.chance,
        table,
        physics_table,
        baseline_table,
    )
    return {"headline": with_ceiling(headline, report.separability)}


# not among the pages' tables: report_pages shows it (and embeds it in the front page) on its own
SECTION = Section(
    "headline",
    write,
    inputs=(
        "train.metrics",
        "train.measured_only",
        "train.physics",
        "train.measured_only_predictions",
        "evaluation.measured_features",
        "evaluation.design_records",
        "evaluation.design_specimens",
        "evaluation.unmodelled",
    ),
    tables=(
        Table(
            "headline",
            "headline.csv",
            "Headline: accuracy on held-out measured records",
            HEADLINE_NOTE,
            page=False,
        ),
    ),
)


def _mean_and_range(row) -> str:
    """A headline cell: the mean over repeats, with its min-max where repeats differ."""
    if row is None or not np.isfinite(row["accuracy_mean"]):
        return "-"
    text = f"{row['accuracy_mean']:.3f}"
    if row.get("accuracy_max", np.nan) - row.get("accuracy_min", np.nan) > 0:
        text += f" ({row['accuracy_min']:.3f}-{row['accuracy_max']:.3f})"
    return text


HEADLINE_RECORDS = {
    evaluation.ALL: "all",
    "evaluation": "evaluation specimens",
    "design": "design specimens",
}
NO_EVALUATION_SPECIMEN = (
    "no evaluation specimen in this data: every tested record is of a "
    "design specimen; add records of other specimens (point measured_dir "
    "at a full download of the data set). The design-specimen figures "
    "below are no headline"
)


def records_over_repeats(table: pd.DataFrame, records: str) -> pd.DataFrame:
    """over_repeats of the evaluation table's rows of condition `all` and these `records`
    (design, evaluation): held-out conditions averaged within a repeat first, as accuracy.csv's."""
    rows = table[(table["condition"] == evaluation.ALL) & (table["records"] == records)]
    return over_repeats(rows.assign(speed_rpm=np.nan, macro_f1=np.nan))


def headline_table(
    accuracy: pd.DataFrame,
    baseline: pd.DataFrame | None,
    physics_overall: pd.DataFrame | None,
    chance: float,
    table: pd.DataFrame | None = None,
    physics_table: pd.DataFrame | None = None,
    measured_only_table: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """The report's front-page table: per protocol, every classifier's accuracy on held-out
    measured records at the smallest and the largest measured share in training (0 and 100 %
    in a default run; mean over repeats as accuracy.csv and summary.json give it, with its
    min-max over repeats), then the baselines on the same test sets where the run has them: the
    best measured-only classifier, each physics baseline (training-free), chance.

    `table`, `physics_table`, `measured_only_table`: the evaluation tables (condmon.evaluation)
    of the classifiers, the physics baselines and the measured-only baselines (from their
    predictions; None: that baseline is left out of the design and evaluation rows); where they
    hold design and evaluation rows (design records declared), the headline is on the
    evaluation specimens' records, then the design specimens' follow, each labelled in the
    `records` column; without any evaluation record one row says so (NO_EVALUATION_SPECIMEN).
    Otherwise every row is on all test records (`records` all)."""
    percents = sorted(int(p) for p in accuracy["measured_percent"].unique())
    chosen = sorted({percents[0], percents[-1]})
    columns = {
        p: ("simulation only (0 % measured)" if p == 0 else f"{p} % measured") for p in chosen
    }
    if table is None or not table["records"].isin(["design", "evaluation"]).any():
        alone = over_repeats(baseline) if baseline is not None and not baseline.empty else None
        return _headline_rows(
            evaluation.ALL, over_repeats(accuracy), alone, physics_overall, chance, chosen, columns
        )
    parts = []
    for records in ("evaluation", "design"):
        results = records_over_repeats(table, records)
        if results.empty and records == "design":
            continue
        if results.empty:
            parts.append(
                pd.DataFrame(
                    [
                        {
                            "records": HEADLINE_RECORDS[records],
                            "protocol": "-",
                            "model": NO_EVALUATION_SPECIMEN,
                            **{c: "-" for c in columns.values()},
                        }
                    ]
                )
            )
            continue
        physics = (
            None
            if physics_table is None
            else records_over_repeats(physics_table, records).assign(
                condition=evaluation.ALL, records=evaluation.ALL
            )
        )
        alone = (
            None
            if measured_only_table is None
            else records_over_repeats(measured_only_table, records)
        )
        parts.append(_headline_rows(records, results, alone, physics, chance, chosen, columns))
    return pd.concat(parts, ignore_index=True)


CEILING_PROTOCOL = "measured records alone"
CEILING_MODEL = (
    "ceiling: a classifier on the measured records alone, every record held out once "
    "(balanced accuracy, its permutation chance level in brackets; summary.json "
    "measured_separability)"
)


def with_ceiling(headline: pd.DataFrame, separability: dict | None) -> pd.DataFrame:
    """The headline with a last row, in its largest share's column: how well the measured records
    separate their classes on their own (`measured_separability`'s balanced accuracy over all
    records, with its permutation chance level), the most a classifier trained elsewhere can be
    expected to reach on them; unchanged without that figure (a class with too few records)."""
    ceiling = None if separability is None else separability["all"]["balanced_accuracy"]
    if ceiling is None:
        return headline
    chance = separability["all"]["chance"]
    shares = list(headline.columns[3:])
    row = {
        "records": HEADLINE_RECORDS[evaluation.ALL],
        "protocol": CEILING_PROTOCOL,
        "model": CEILING_MODEL,
        **{column: "-" for column in shares[:-1]},
        shares[-1]: f"{ceiling:.3f} (chance {chance['mean']:.3f}, to {chance['upper']:.3f})",
    }
    return pd.concat([headline, pd.DataFrame([row])], ignore_index=True)


def _headline_rows(
    records: str,
    results: pd.DataFrame,
    alone: pd.DataFrame | None,
    physics_overall: pd.DataFrame | None,
    chance: float,
    chosen: list,
    columns: dict,
) -> pd.DataFrame:
    """headline_table's rows of one set of test records (`results`, `alone`: over_repeats of
    the classifiers' and the measured-only baselines' accuracy on them)."""

    def cells(rows: pd.DataFrame) -> dict:
        by_percent = {int(r["measured_percent"]): r for _, r in rows.iterrows()}
        return {columns[p]: _mean_and_range(by_percent.get(p)) for p in chosen}

    alone = alone if alone is not None and not alone.empty else None
    physics = None
    if physics_overall is not None and not physics_overall.empty:
        physics = physics_overall[
            (physics_overall["condition"] == evaluation.ALL)
            & (physics_overall["records"] == evaluation.ALL)
        ]
    rows = []
    for protocol in sorted(results["protocol"].unique()):
        title = protocol_title(protocol)
        mine = results[results["protocol"] == protocol]
        for classifier in sorted(mine["classifier"].unique()):
            rows.append(
                {
                    "protocol": title,
                    "model": f"{classifier} (simulated + measured)",
                    **cells(mine[mine["classifier"] == classifier]),
                }
            )
        if alone is not None and not alone[alone["protocol"] == protocol].empty:
            # per share, the best measured-only classifier (its name in the cell)
            own = alone[alone["protocol"] == protocol]
            best = own.loc[own.groupby("measured_percent")["accuracy_mean"].idxmax().dropna()]
            row = {"protocol": title, "model": "baseline: measured data only (best classifier)"}
            for p in chosen:
                at = best[best["measured_percent"] == p]
                row[columns[p]] = (
                    "-" if at.empty else f"{_mean_and_range(at.iloc[0])} {at.iloc[0]['classifier']}"
                )
            rows.append(row)
        if physics is not None:
            for rule, own in physics[physics["protocol"] == protocol].groupby("classifier"):
                row = {"protocol": title, "model": f"baseline: physics rule {rule} (no training)"}
                for p in chosen:
                    at = own[own["measured_percent"] == p]
                    row[columns[p]] = (
                        "-"
                        if at.empty or not np.isfinite(at.iloc[0]["accuracy_mean"])
                        else f"{at.iloc[0]['accuracy_mean']:.3f}"
                    )
                rows.append(row)
        rows.append(
            {"protocol": title, "model": "chance", **{columns[p]: f"{chance:.3f}" for p in chosen}}
        )
    return pd.DataFrame(rows, columns=["protocol", "model", *columns.values()]).assign(
        records=HEADLINE_RECORDS[records]
    )[["records", "protocol", "model", *columns.values()]]

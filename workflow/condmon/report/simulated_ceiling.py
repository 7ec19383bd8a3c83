"""The simulation's own ceiling: summary.json's `simulated_separability` and
simulated_separability.csv (condmon.separability: the measured ceiling's classifier on the
simulated records alone, one simulated machine held out at a time), per condition: how well the
simulation tells its classes apart on a machine it never saw. A class it confuses there is the
model's limit (fault forms or sizes that overlap, or hide under the machines' scatter), which
no transfer can lift; logged."""

from __future__ import annotations

import logging

import pandas as pd

from condmon.report.section import Section, Table
from condmon.separability import SHOWN_RECALL, simulated_separability

log = logging.getLogger(__name__)

COLUMNS = ["condition", "health_state", "recall", "balanced_accuracy", "machines", "confused_with"]


def separability_table(separability: dict) -> pd.DataFrame:
    """One row per condition and class: its recall, the condition's balanced accuracy and
    machines, and the classes its records were taken for most (`confused_with`, segments)."""
    rows = []
    for value, entry in separability["per_condition"].items():
        for state, recall in (entry["recall_per_class"] or {}).items():
            wrong = {p: n for p, n in entry["confusion"][state].items() if p != state}
            rows.append(
                {
                    "condition": value,
                    "health_state": state,
                    "recall": recall,
                    "balanced_accuracy": entry["balanced_accuracy"],
                    "machines": entry["machines"],
                    "confused_with": ", ".join(
                        f"{p} {n}" for p, n in sorted(wrong.items(), key=lambda kv: -kv[1])
                    ),
                }
            )
    return pd.DataFrame(rows, columns=COLUMNS)


def write(report) -> dict:
    (_, names), condition = report.measured, report.condition
    separability = simulated_separability(report.simulated, names, condition)
    report.summary["simulated_separability"] = separability
    log.info(
        "simulated records alone, one machine held out: %s per %s",
        {k: v["balanced_accuracy"] for k, v in separability["per_condition"].items()},
        condition,
    )
    table = separability_table(separability)
    for row in table[table["recall"] < SHOWN_RECALL].itertuples():
        log.warning(
            "%s %s: the simulation finds %s on a machine it never saw %.0f %% of the time (taken "
            "for %s): the model's limit, whatever the transfer",
            condition,
            row.condition,
            row.health_state,
            100 * row.recall,
            row.confused_with,
        )
    return {"simulated_separability": table}


SECTION = Section(
    "simulated_ceiling",
    write,
    inputs=(
        "evaluation.measured_features",
        "evaluation.simulated_features",
        "evaluation.condition",
    ),
    requires=("evaluation.measured_features", "evaluation.simulated_features"),
    tables=(
        Table(
            "simulated_separability",
            "simulated_separability.csv",
            "The simulation's own ceiling (simulated_separability.csv)",
            "The measured ceiling's classifier trained on the simulated records alone, one "
            "simulated machine held out at a time with its records of every health state: per "
            "condition and class, how often the simulation finds the class on a machine it never "
            "saw, and what it takes it for otherwise. A class below 0.8 here is the model's "
            "limit (its fault forms or sizes overlap with another class's, or hide under the "
            "machines' scatter), not the transfer's.",
        ),
    ),
    summary_keys=("simulated_separability",),
)

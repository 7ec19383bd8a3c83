"""The simulation gain section: plots/simulation_gain.png, the hybrid accuracy against the
strongest baseline (with the measured features: of chance, majority class, the best measured-only
classifier and the physics baseline, from evaluation_summary's `all` rows) or, without them,
against the same classifier's measured-only baseline (where the run has one)."""

from __future__ import annotations

import pandas as pd

from condmon import evaluation, plots
from condmon.report.aggregate import simulation_gain
from condmon.report.section import Section


def write(report) -> dict:
    if report.evaluation is not None:
        gains, note = (
            gain_against_strongest(report.evaluation.overall),
            report.note(report.design_tested),
        )
    elif report.baseline is not None:
        gains, note = (
            simulation_gain(report.accuracy, report.baseline).rename(
                columns={"measured_only": "strongest"}
            ),
            report.note(),
        )
    else:
        return {}
    report.save(plots.simulation_gain(gains, report.chance, note), "simulation_gain.png")
    return {}


SECTION = Section(
    "simulation_gain",
    write,
    inputs=(
        "evaluation.measured_features",
        "train.measured_only",
        "train.physics",
        "train.measured_only_predictions",
    ),
)


def gain_against_strongest(overall: pd.DataFrame) -> pd.DataFrame:
    """The simulation_gain plot's table from evaluation_summary's `all` rows: per classifier,
    protocol and percent the hybrid accuracy, the strongest baseline's, the gain, and each
    baseline's (best measured-only, physics baseline, majority class)."""
    whole = overall[
        (overall["condition"] == evaluation.ALL) & (overall["records"] == evaluation.ALL)
    ]
    return whole.rename(
        columns={
            "accuracy_mean": "hybrid",
            "strongest_baseline_accuracy_mean": "strongest",
            "gain_vs_strongest_mean": "gain",
            "measured_only_best_mean": "measured_only_best",
            "physics_baseline_accuracy_mean": "physics_baseline_accuracy",
            "majority_class_mean": "majority_class",
        }
    )[
        [
            "classifier",
            "protocol",
            "measured_percent",
            "hybrid",
            "strongest",
            "gain",
            "measured_only_best",
            "physics_baseline_accuracy",
            "majority_class",
        ]
    ]

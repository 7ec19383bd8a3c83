"""A report in the making: the inputs read once, what several sections share, and what the sections
add (summary.json's content, the plot names, the plots' staging folder).

`Report(inputs, staging)` reads the train tables, calibrations and the optional inputs at once
(errors before any section runs); what only some sections need and what costs time is computed
on first use and kept (the evaluation tables, the measured features, the separability ceiling,
which measured segments leave the simulated range).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import pandas as pd

from condmon import evaluation, plots
from condmon.features import read_feature_table
from condmon.hybrid import calibration_frame
from condmon.labels import data_source_label, label_order
from condmon.report.inputs import ReportInputs
from condmon.report.loading import (
    design_record_ids,
    load_calibrations,
    load_fault_lines,
    load_simulated_validation,
    record_conditions,
    unmodelled_records,
    with_condition,
)
from condmon.separability import SHOWN_RECALL, measured_separability
from condmon.signature import outside_simulation
from condmon.train_tables import ReportInputError, load_metrics, load_predictions

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class EvaluationTables:
    """condmon.evaluation's tables of a run with measured features: per evaluation (`table`) and
    over repeats (`overall`); the physics baselines' own (None without physics predictions); the
    measured-only baselines' per evaluation (None without their predictions)."""

    table: pd.DataFrame
    overall: pd.DataFrame
    physics_table: pd.DataFrame | None
    physics_overall: pd.DataFrame | None
    baseline_table: pd.DataFrame | None


def non_empty(paths, read_rows) -> list:
    """The files of `paths` with at least one row (`read_rows(path)`: its rows)."""
    return [p for p in paths if len(read_rows(p))]


class Report:
    """What the sections read (`inputs` and what is loaded from them) and add to (`summary`,
    `plots`, drawn into `staging`)."""

    def __init__(self, inputs: ReportInputs, staging: Path):
        self.inputs, self.staging = inputs, Path(staging)
        self.run, train, chosen = inputs.run, inputs.train, inputs.evaluation
        self.summary: dict = {}
        self.plots: list[str] = []
        self.accuracy = load_metrics(train.metrics)
        # measured-only baselines (empty files where hybrid.measured_only_baseline is off)
        with_rows = non_empty(train.measured_only, pd.read_csv)
        self.baseline = load_metrics(with_rows) if with_rows else None
        self.predictions = load_predictions(train.predictions)
        # the system's physics baselines (empty files where it has none)
        physics = non_empty(train.physics, lambda p: pd.read_parquet(p, columns=["record_id"]))
        self.physics = load_predictions(physics) if physics else None
        self.fault_lines, self.fault_line_rule = load_fault_lines(train.physics_info)
        alone = non_empty(
            train.measured_only_predictions, lambda p: pd.read_parquet(p, columns=["record_id"])
        )
        self.baseline_predictions = load_predictions(alone) if alone else None
        self.simulated_validation = load_simulated_validation(train.simulated_validation)
        self.labels = label_order(
            [*self.predictions["true_label"], *self.predictions["predicted_label"]],
            self.run.healthy_state,
        )
        self.chance = 1.0 / len(self.labels)
        # the per-condition figures and prediction_shares.csv group by the operating condition
        # (hybrid.condition: the speed, or e.g. the load), each record's value from its features
        self.features, self.condition = chosen.measured_features, chosen.condition
        self.grouping = self.condition if self.features is not None else "speed_rpm"
        self.by_condition = (
            with_condition(
                self.predictions, record_conditions(self.features, self.condition), self.condition
            )
            if self.grouping != "speed_rpm"
            else self.predictions
        )
        self.calibrations, self.spectra, self.history = load_calibrations(inputs.calibration)
        # the one the simulated data come from
        self.calibration = (
            next(iter(self.calibrations.values()))
            if inputs.calibration.per_variant
            else self.calibrations
        )
        log.info(
            "%d metrics rows from %d files, %d predictions",
            len(self.accuracy),
            len(train.metrics),
            len(self.predictions),
        )
        self.design_records, self.specimens, self.apart = chosen.design_records, {}, {}
        if self.features is not None:
            self.design_records, self.specimens = design_record_ids(
                self.design_records, chosen.design_specimens, inputs.upstream.measured_records
            )
            self.apart = unmodelled_records(dict(chosen.unmodelled), self.specimens)
            if self.apart:
                log.info(
                    "unmodelled records, reported apart and never in the headline: %s", self.apart
                )
        self.design_tested = bool(
            set(map(str, self.design_records)) & set(self.predictions["record_id"].astype(str))
        )

    def save(self, figure, name: str) -> None:
        """Write a plot into the plots' staging folder and list it (summary.json's `plots`)."""
        plots.save_figure(figure, self.staging / name)
        self.plots.append(name)

    def wants(self, table: str) -> bool:
        """Whether the outputs name the table (ReportOutputs.tables): one left out is not made."""
        return table in self.inputs.outputs.tables

    def note(self, design: bool = False) -> str:
        """Every plot's footnote (plot_note) of this run; `design`: it pools design records."""
        return plot_note(
            self.run.run_name,
            self.run.data_source,
            self.run.bench_differences,
            design,
            self.run.state_models,
        )

    @cached_property
    def percents(self) -> list[int]:
        """report.confusion_percent plus the largest measured percentage, checked."""
        return confusion_percents(self.accuracy, self.inputs.evaluation.confusion_percent)

    @cached_property
    def evaluation(self) -> EvaluationTables | None:
        """The evaluation tables (None without the measured features). `apart` records: rows
        `unmodelled`, never `evaluation`."""
        if self.features is None:
            return None
        conditions = record_conditions(self.features, self.condition)
        labels, healthy, condition, design = (
            self.labels,
            self.run.healthy_state,
            self.condition,
            self.design_records,
        )
        apart = list(self.apart)
        table = evaluation.evaluation_table(
            self.predictions,
            healthy,
            labels,
            conditions,
            condition,
            design,
            self.baseline,
            self.physics,
            self.baseline_predictions,
            apart,
        )
        baseline_table = (
            None
            if self.baseline_predictions is None
            else evaluation.evaluation_table(
                self.baseline_predictions,
                healthy,
                labels,
                conditions,
                condition,
                design,
                apart_records=apart,
            )
        )
        overall = evaluation.summarise(
            table, self.predictions, healthy, conditions, condition, design, apart
        )
        physics_table = physics_overall = None
        if self.physics is not None:
            physics_table = evaluation.evaluation_table(
                self.physics, healthy, labels, conditions, condition, design, apart_records=apart
            )
            physics_overall = evaluation.summarise(
                physics_table, self.physics, healthy, conditions, condition, design, apart
            )
        return EvaluationTables(table, overall, physics_table, physics_overall, baseline_table)

    @cached_property
    def measured(self) -> tuple[pd.DataFrame, list]:
        """(the measured features, their names)."""
        return read_feature_table(self.features)

    @cached_property
    def simulated(self) -> pd.DataFrame:
        """The simulated features, checked to have the measured features' names."""
        path = self.inputs.evaluation.simulated_features
        frame, names = read_feature_table(path)
        return checked_alike(frame, names, self.measured[1], path)

    @cached_property
    def separability(self) -> dict | None:
        """How well the measured records alone separate their classes (None without the measured
        features): on the modelled specimens' records, as the headline."""
        if self.features is None:
            return None
        frame, names = self.measured
        kept = ~frame["record_id"].astype(str).isin(set(map(str, self.apart))) & ~frame.index.isin(
            self.calibration_rows
        )
        separability = measured_separability(frame[kept], names, self.condition)
        log.info(
            "measured records alone, leave one record out: %s over all, %s per %s",
            separability["all"]["balanced_accuracy"],
            {k: v["balanced_accuracy"] for k, v in separability["per_condition"].items()},
            self.condition,
        )
        for value, entry in separability["per_condition"].items():
            if entry[
                "not_shown"
            ]:  # no simulation can be asked to find what its own records do not show
                log.warning(
                    "%s %s: the measured records' own classifier finds %s less than %.0f %% of the "
                    "time (exempt from the simulation-trained figures)",
                    self.condition,
                    value,
                    entry["not_shown"],
                    100 * SHOWN_RECALL,
                )
        return separability

    @cached_property
    def calibration_rows(self) -> pd.Index:
        """The measured features' rows in the calibration set: the calibrate jobs saw them, and
        with the healthy reference on the features were taken against them (near zero against
        themselves), so they are no test of what the records show."""
        spec = self.inputs.evaluation.calibration_set
        if not spec or self.features is None:
            return pd.Index([])
        frame, _ = self.measured
        return calibration_frame(
            frame,
            spec["healthy_state"],
            spec["condition"],
            dict(spec["reserve"]),
            list(spec.get("states") or [spec["healthy_state"]]),
        ).index

    @property
    def compares_signatures(self) -> bool:
        """Whether the simulated faults' shifts are compared with the measured ones (measured
        and simulated features, a healthy state to shift from)."""
        return (
            self.features is not None
            and self.inputs.evaluation.simulated_features is not None
            and self.run.healthy_state is not None
        )

    @cached_property
    def coverage(self) -> pd.DataFrame | None:
        """The joined jobs' coverage.csv pooled (condmon.joined.COVERAGE_COLUMNS): each tested
        record's share of segments outside its classifier's training range; None without them."""
        paths = self.inputs.train.coverage
        return (
            pd.concat(
                [pd.read_csv(p, dtype={"record_id": str, "holdout": str}) for p in paths],
                ignore_index=True,
            )
            if paths
            else None
        )

    @cached_property
    def outside(self) -> pd.DataFrame | None:
        """Each measured record's share of segments outside the simulated range, and which
        features leave it (condmon.signature.outside_simulation); None without the comparison."""
        if not self.compares_signatures:
            return None
        frame, names = self.measured
        return outside_simulation(frame, self.simulated, names)


def checked_alike(simulated: pd.DataFrame, simulated_names, names, path) -> pd.DataFrame:
    """The simulated features, refused where their names differ from the measured features'."""
    if list(simulated_names) != list(names):
        raise ReportInputError(
            f"{path}: its features differ from the measured features' "
            f"({len(simulated_names)} against {len(names)}); rerun the features stage"
        )
    return simulated


def plot_note(
    run_name: str, data_source: str, bench_differences=(), design: bool = False, state_models=()
) -> str:
    """Every plot's footnote: the data source and run (and how far a bench differs from the model;
    the fault states whose model their own records tuned; with design records, that the plot
    pools them with the evaluation records)."""
    note = f"Data: {data_source_label(data_source)} | run {run_name}"
    differences = [row for row in bench_differences if row["handled"] != "same"]
    if differences:
        neither = sum(row["handled"] == "neither" for row in differences)
        note += (
            f" | bench differs from the model in {len(differences)} ways, {neither} neither "
            "calibrated nor randomised (summary.json)"
        )
    if state_models:
        note += (
            f" | PER-STATE CALIBRATION: {', '.join(state_models)} models tuned on their first measured "
            "record per condition (never tested)"
        )
    if design:
        note += (
            " | all test records: design specimens' included (apart: "
            "accuracy_design_vs_evaluation.png, headline.csv)"
        )
    return note


def confusion_percents(accuracy: pd.DataFrame, requested) -> list[int]:
    """The requested measured percentages plus the largest one, checked against the data."""
    available = sorted(int(p) for p in accuracy["measured_percent"].unique())
    requested = [int(p) for p in requested]
    unknown = [p for p in requested if p not in available]
    if unknown:
        raise ReportInputError(
            f"confusion_percent {unknown} not among the trained measured percentages {available}"
        )
    return sorted(set(requested) | {available[-1]})

"""The report stage's inputs as one object: what `condmon.report.write_report` reads and writes.

`ReportInputs` groups them: the run's identity, the train outputs, the calibration outputs, the
evaluation inputs, the earlier stages' own records, and the output paths. The report script
builds it from Snakemake's input, params and output; a test builds it from its own files. Every
optional part has a default that means "not given": the report then leaves out what depends on
it (see each field). Sequences are stored as tuples, so an instance is immutable throughout.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from os import PathLike
from typing import Mapping, Union

Path_ = Union[str, PathLike]


def _tuple(values) -> tuple:
    return tuple(values) if values is not None else ()


class _Frozen:
    """Sequence fields become tuples (a frozen dataclass cannot assign them itself)."""

    _sequences: tuple[str, ...] = ()

    def __post_init__(self):
        for name in self._sequences:
            object.__setattr__(self, name, _tuple(getattr(self, name)))


@dataclass(frozen=True)
class RunIdentity(_Frozen):
    """Whose report it is: summary.json's head and every plot's footnote."""

    run_name: str
    data_source: str  # the measured data's kind (condmon.labels.data_source_label)
    healthy_state: str | None = None  # the class confusion matrices and label orders start from
    bench_differences: tuple[
        dict, ...
    ] = ()  # how the virtual bench differs from the model (System.bench_differences)
    # fault states whose model was tuned on their own measured records (calibration.per_state)
    state_models: tuple[str, ...] = ()
    _sequences = ("bench_differences", "state_models")


@dataclass(frozen=True)
class TrainOutputs(_Frozen):
    """The train stage's files (train/<classifier>/<protocol>/...)."""

    metrics: tuple[Path_, ...]  # metrics.csv: accuracy.csv and the results
    predictions: tuple[Path_, ...]  # predictions.parquet: recalls, confusion, shares
    # measured_only.csv (files without rows, where hybrid.measured_only_baseline is off, skipped):
    # the measured-only accuracy and simulation gain
    measured_only: tuple[Path_, ...] = ()
    # the system's physics baselines' predictions.parquet (files without rows skipped): a
    # candidate of the strongest baseline and summary.json's `physics_baselines`
    physics: tuple[Path_, ...] = ()
    # their info.json: with a rule's `fault_lines` (the envelope rule), whether each fault record
    # shows its defect line: recall_per_record.csv's `shows_line`, summary.json's `fault_lines`
    physics_info: tuple[Path_, ...] = ()
    # simulated_validation.csv, given only with hybrid.simulated_validation_share > 0 (then
    # summary.json's `simulated_validation`, even when no file has a row)
    simulated_validation: tuple[Path_, ...] = ()
    # measured_only_predictions.parquet (files without rows skipped): the measured-only
    # baseline on design and evaluation records apart
    measured_only_predictions: tuple[Path_, ...] = ()
    # the joined jobs' coverage.csv (condmon.joined.COVERAGE_COLUMNS): each tested record's share
    # of segments outside its classifier's training range; recall_per_record.csv's
    # `outside_training`, summary.json's `simulation_coverage` (the design records' verdict)
    coverage: tuple[Path_, ...] = ()
    _sequences = (
        "metrics",
        "predictions",
        "measured_only",
        "physics",
        "physics_info",
        "simulated_validation",
        "measured_only_predictions",
        "coverage",
    )


@dataclass(frozen=True)
class CalibrationOutputs:
    """The calibration files: each a path (one calibration), or {calibration variant: path} of
    one calibration per variant, the simulation's first (summary.json's `calibration`;
    `calibration_by_variant` lists all). The three must name the same variants."""

    params: Path_ | Mapping[str, Path_]  # params.json
    spectra: Path_ | Mapping[str, Path_]  # spectra.parquet: measured vs calibrated spectra
    history: Path_ | Mapping[str, Path_]  # history.parquet: the calibration's convergence
    # {fault state: state_calibration/<state>/params.json} (calibration.per_state; summary.json's
    # `state_calibration`)
    states: Mapping[str, Path_] = field(default_factory=dict)
    # {fault state: its history.parquet}: a convergence plot each
    state_histories: Mapping[str, Path_] = field(default_factory=dict)

    @property
    def per_variant(self) -> bool:
        return isinstance(self.params, Mapping)

    def by_variant(self) -> tuple[dict, dict, dict]:
        """({variant: path} of params, spectra and history; variant None with one calibration)."""
        if self.per_variant:
            return dict(self.params), dict(self.spectra), dict(self.history)
        return {None: self.params}, {None: self.spectra}, {None: self.history}


@dataclass(frozen=True)
class EvaluationInputs(_Frozen):
    """What the evaluation tables and per-condition figures need."""

    # the measured features (each record's value of the operating condition); None: no
    # evaluation tables, per-speed figures only, the gain against the same classifier's
    # measured-only baseline
    measured_features: Path_ | None = None
    # the simulated features: with the measured ones, how each simulated fault's shift compares
    # with the measured fault's (condmon.signature; summary.json fault_signatures); None: not given
    simulated_features: Path_ | None = None
    condition: str = "speed_rpm"  # hybrid.condition: the column figures group by
    design_records: tuple[str, ...] = ()  # report.design_records: results given apart
    # the system's design specimens (System.design_specimens): their records, matched to
    # measured_records' `specimen`, count as design records too; the headline is then on the
    # evaluation records
    design_specimens: tuple[dict, ...] = ()
    # {specimen: reason} of specimens the model does not describe (System.unmodelled_specimens):
    # their records are reported in rows of their own, never in the headline nor as evaluation
    # records
    unmodelled: Mapping[str, str] = field(default_factory=dict)
    # the calibration set (healthy_state, condition, reserve, states: as hybrid.calibration_frame
    # takes them), or None: what the calibrate jobs saw (and, with the healthy reference on, what
    # the features were taken against), so the measured-only ceiling leaves it out
    calibration_set: Mapping | None = None
    # where on the machine each measured segment's change sits (measured_fault_locations.csv, a
    # system family's), or None
    fault_locations: Path_ | None = None
    # how each measured segment's shaft angle was found (measured_shaft_tracking.csv), or None
    shaft_tracking: Path_ | None = None
    confusion_percent: tuple[int, ...] = (0,)  # report.confusion_percent (+ the largest)
    _sequences = ("design_records", "design_specimens", "confusion_percent")


@dataclass(frozen=True)
class StageRecords(_Frozen):
    """What the earlier stages recorded about their own jobs and inputs."""

    simulation_reports: tuple[Path_, ...] = ()  # the simulate jobs' .json: samples, failures, cost
    measured_records: Path_ | None = None  # measured/records.csv: kept and left-out records
    # {rule: the benchmark files of its jobs} of every job before the report; None: no timings
    benchmarks: Mapping[str, tuple] | None = None
    cores: int | None = None  # the run's --cores: its elapsed time against CPU seconds / cores
    _sequences = ("simulation_reports",)


@dataclass(frozen=True)
class ReportOutputs:
    """Where the report writes: summary.json, plots/ (written whole, atomically) and the tables by
    their names in the registry (condmon.report.registry: accuracy, evaluation, headline, ...);
    a table not named is not written."""

    summary: Path_
    plots: Path_
    tables: Mapping[str, Path_] = field(default_factory=dict)


@dataclass(frozen=True)
class ReportInputs:
    """Everything `condmon.report.write_report` reads and writes."""

    run: RunIdentity
    train: TrainOutputs
    calibration: CalibrationOutputs
    outputs: ReportOutputs
    evaluation: EvaluationInputs = field(default_factory=EvaluationInputs)
    upstream: StageRecords = field(default_factory=StageRecords)

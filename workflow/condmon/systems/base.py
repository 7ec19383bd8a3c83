"""The interface every simulated system implements (ARCHITECTURE.md, "Systems").

A system is a rig and its model family: the helical-gear drivetrain, the CWRU ball-bearing rig,
a user's own rig. The stages are the same for all; what differs lives behind this interface:
- its config sections and their schema (`schema_file`, the only home of their defaults) and its
  cross-field checks (`problems`);
- its health states, channels, sampling rate, segment length and simulated speeds;
- its measured data (`measured_files`, `read_measured`; a synthetic bench as `measured_parts`);
- its parameters (nominal, calibrated, the per-sample draw `sample_parameters`) and one sample's
  simulation (`simulate_sample`, raising `SimulationError`);
- its calibration (`calibrate`: target, search; the costs it offers, `calibration_costs`; the
  categorical model variants it searches, `model_variants`) and what its features need
  (`defect_orders`, `shafts`).

A system object is built on a config: the whole validated config in the Snakefile, or the part
`job_config` gives one job (so an edit reruns exactly the jobs it affects). Jobs get it back with
`condmon.systems.load_system(params.system)`. Every method is deterministic given its seed.
"""

from __future__ import annotations

import functools
import hashlib
import inspect
from abc import ABC, abstractmethod
from pathlib import Path
from typing import ClassVar

import numpy as np
import pandas as pd
import yaml

from condmon.models.numerics import SimulationError
from condmon.operating import OperatingPoint
from condmon.signals import SPECIMEN_COLUMNS

__all__ = ["OperatingPoint", "System", "SimulationError"]

# Stages whose jobs build a system object (job_config's `stage`).
STAGES = ("bench", "measured", "calibrate", "simulate", "features", "baselines")
# Stages whose outputs come from the model code: their `system` param carries its digest.
MODEL_STAGES = ("bench", "calibrate", "simulate")


@functools.cache
def source_digest(deep: tuple[Path, ...] = (), flat: tuple[Path, ...] = ()) -> str:
    """SHA-256 over the .py and .yaml files in the `deep` folders (with their subfolders) and the
    `flat` ones (without): their names relative to their folder and their contents, in sorted
    order, so the digest does not depend on where the project lies."""
    files = set()
    for kind, folders, search in (("deep", deep, Path.rglob), ("flat", flat, Path.glob)):
        for number, folder in enumerate(folders):
            for pattern in ("*.py", "*.yaml"):
                for path in search(folder, pattern):
                    name = path.relative_to(folder)
                    if "__pycache__" not in name.parts:
                        files.add((f"{kind}{number}:{name.as_posix()}", path))
    digest = hashlib.sha256()
    for name, path in sorted(files):
        digest.update(name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


class System(ABC):
    """One rig and its model family. Subclasses set the class attributes and implement the
    abstract methods; the rest has defaults that fit most systems."""

    name: ClassVar[str]  # the config's `system` value
    schema_file: ClassVar[Path]  # JSON schema (YAML) of its config sections, with defaults
    sections: ClassVar[tuple[str, ...]]  # the top-level config keys it owns
    default_condition: ClassVar[str] = (
        "speed_rpm"  # hybrid.condition when the config leaves it null
    )
    synthetic_source: ClassVar[str] = "virtual_bench"  # source label of its bench records
    calibrates_on_spectra: ClassVar[bool] = True  # its calibration compares features.spectrum bands

    def __init__(self, config: dict):
        self.config = config

    # -- schema ------------------------------------------------------------------------------
    @classmethod
    def schema(cls) -> dict:
        """Its schema fragment: `properties` of its sections, merged into config/schema.yaml's."""
        return yaml.safe_load(Path(cls.schema_file).read_text())

    # -- what the stages need to know ----------------------------------------------------------
    @property
    @abstractmethod
    def health_states(self) -> list[str]:
        """The classes, in a fixed order."""

    @property
    @abstractmethod
    def healthy_state(self) -> str:
        """The label of the healthy machine (calibration target, false alarms)."""

    @property
    @abstractmethod
    def channels(self) -> list[str]:
        """Every channel the model produces (features use a subset)."""

    @property
    @abstractmethod
    def output_rate_hz(self) -> float:
        """Sampling rate of simulated and measured signals."""

    @property
    @abstractmethod
    def segment_length(self) -> int:
        """Samples per segment (one feature vector)."""

    @property
    def segment_hop(self) -> int:
        """Samples from one measured segment's start to the next (default: no overlap)."""
        return self.segment_length

    @property
    @abstractmethod
    def speeds_rpm(self) -> list[float]:
        """Simulated speeds."""

    @property
    def operating_points(self) -> list[OperatingPoint]:
        """The operating conditions the rig is calibrated and simulated at, by speed: every speed (a
        system whose rig runs several loads per speed lists every (speed, load), by load)."""
        return [OperatingPoint(speed) for speed in sorted(self.speeds_rpm)]

    def operating_point(self, label: str) -> OperatingPoint:
        """The operating point of a job's label (`OperatingPoint.label`)."""
        points = {point.label: point for point in self.operating_points}
        if label not in points:
            raise ValueError(
                f"operating point {label!r}: the {self.name} system runs {sorted(points)}"
            )
        return points[label]

    def measured_points(self, frame: pd.DataFrame, health_state: str) -> list[OperatingPoint]:
        """The operating points at which `frame` (a signal or feature table) holds records of
        `health_state`: those a calibration can target."""
        rows = frame[frame["health_state"] == health_state]
        return [point for point in self.operating_points if point.holds(rows).any()]

    def at_load(self, parameters: dict, load: float | None) -> dict:
        """`parameters` of one run at `load` (an `OperatingPoint.load`; None: as they are)."""
        if load is None:
            return dict(parameters)
        raise ValueError(f"the {self.name} system has no load as an operating condition")

    @property
    def settle_seconds(self) -> float:
        """Simulated before the recorded part of every run (reported with the cost per sample)."""
        return 0.0

    @property
    def calibratable(self) -> tuple[str, ...]:
        """Parameter names `calibration.parameters` may bound."""
        return ()

    def calibration_settings(self, calibration: dict) -> dict:
        """The `calibration` section a calibrate job depends on: all of it by default; a system
        drops the keys that only list its calibration variants (those are wildcards, so editing
        the list never reruns a calibration). `per_state` belongs to the per-state jobs only."""
        return {key: value for key, value in calibration.items() if key != "per_state"}

    def calibration_variants(self) -> list[str]:
        """Names of the calibrations a run makes (one job each, `calibration/<name>/`); the
        first one's parameters make the simulated data."""
        return ["rig"]

    @property
    def measured_table(self) -> str | None:
        return self.config.get("measured_table")

    def measured_parts(self) -> list[str]:
        """Parts of a synthetic bench (one job each) when there is no measured data; none here."""
        return []

    def healthy_parts(self) -> list[str]:
        """The bench parts holding the healthy records: all the calibration reads, so it can start
        before the fault records are made. Every part unless the system says which."""
        return self.measured_parts()

    def measured_files(self) -> list[str]:
        """The measured input files (a signal table by default)."""
        return [self.measured_table] if self.measured_table else []

    def data_source(self) -> str:
        """`measured`, or `synthetic_source` when the records come from a bench."""
        return self.synthetic_source if self.measured_parts() else "measured"

    def bench_differences(self) -> list[dict]:
        """Every way the bench that makes the measured data differs from the model (none for real
        measurements): rows {difference, handled ("calibrated", "randomised", "neither", or "same":
        a part the bench copies from the model), how, within_range (the bench's value inside the
        calibrated or randomised range; None where none)}; the report lists them."""
        return []

    def design_specimens(self) -> list[str]:
        """The specimens (measured/records.csv's `specimen`) whose records the design looked at
        (features, ranges, bands tuned on them): the report gives their records' figures apart
        ("design") from every other specimen's ("evaluation") and its headline on the latter
        (none by default; `report.design_records` names single records)."""
        return []

    def unmodelled_specimens(self) -> dict[str, str]:
        """{specimen (records.csv's `specimen`): reason} of specimens the model does not describe
        (another part: its geometry unknown or different): the report gives their records in
        rows of their own ("unmodelled") and never in the headline nor among the evaluation
        records (none by default)."""
        return {}

    def job_config(self, stage: str, variant: str | None = None) -> dict:
        """The config a job of `stage` ("bench", "measured", "calibrate", "simulate",
        "features") depends on: by default every section the system owns and the measured
        table's path. Override to hide what a stage must not see (a bench's hidden truth from the
        calibration) or need not (so an edit reruns only the jobs it affects)."""
        if stage not in STAGES:
            raise ValueError(f"unknown stage {stage!r}; choose one of {list(STAGES)}")
        keys = [*self.sections, "measured_table"]
        return {key: self.config[key] for key in keys if key in self.config}

    def job_spec(self, stage: str, variant: str | None = None) -> dict:
        """The `system` param of a rule: what `load_system` needs to rebuild this system in a job.
        For the stages that run the model it also carries `model_digest`, so Snakemake reruns
        them when the model's code changes (its code trigger sees only the rule's script)."""
        spec = {
            "name": self.name,
            "modules": list(self.config.get("system_modules") or []),
            "config": self.job_config(stage, variant),
        }
        if stage in MODEL_STAGES:
            spec["model_digest"] = self.model_digest()
        return spec

    def model_digest(self) -> str:
        """Digest of the code the model stages run: the built-in systems and `condmon.models`
        (searched recursively) and the folder of this system's own module (not recursively: a
        system of your own may live in a large folder)."""
        from condmon import models

        built_in = (Path(__file__).parent.resolve(), Path(models.__file__).parent.resolve())
        own = Path(inspect.getfile(type(self))).parent.resolve()
        inside = any(own.is_relative_to(folder) for folder in built_in)
        return source_digest(deep=built_in, flat=() if inside else (own,))

    # -- config checks -----------------------------------------------------------------------
    def problems(self) -> list[str]:
        """Cross-field problems of the whole config that concern this system (messages name the
        key). Subclasses extend this list."""
        config, problems = self.config, []
        problems += self.measured_table_problems()
        unknown = sorted(set(config["features"]["channels"]) - set(self.channels))
        if unknown:
            problems.append(
                f"features.channels: {unknown} are not channels of the {self.name} system "
                f"({self.channels})"
            )
        costs = list(self.calibration_costs())
        if config["calibration"]["cost"] not in costs:
            problems.append(
                f"calibration.cost: {config['calibration']['cost']!r} is not a cost of the "
                f"{self.name} system; choose one of {costs}"
            )
        wrong = sorted(set(config["calibration"]["parameters"]) - set(self.calibratable))
        if wrong:
            problems.append(
                f"calibration.parameters: {wrong} are not parameters of the {self.name} "
                f"system (choose among {sorted(self.calibratable)})"
            )
        if self.healthy_state not in self.health_states:
            problems.append(
                f"the healthy state {self.healthy_state!r} is not among the health states "
                f"{self.health_states} (calibration uses healthy records)"
            )
        for state in config["calibration"]["per_state"]["states"]:
            if state not in self.health_states or state == self.healthy_state:
                problems.append(
                    f"calibration.per_state.states: {state!r} is not a fault state of this run "
                    f"(rig.health_states {self.health_states})"
                )
                continue
            try:
                self.state_calibration_space(state)
            except ValueError as exc:
                problems.append(str(exc))
        classes = config["hybrid"]["measured_classes"]
        if "unseen_fault" in config["hybrid"]["protocols"] and classes is not None:
            unknown = sorted(set(classes) - set(self.health_states))
            if unknown:
                problems.append(
                    f"hybrid.measured_classes: {unknown} are not health states of the "
                    f"{self.name} system ({self.health_states})"
                )
        problems += self.protocol_problems()
        nyquist = self.output_rate_hz / 2
        spectrum = config["features"]["spectrum"]
        from condmon.features import FEATURE_FAMILIES  # the registry's (built-in and registered)

        families = str(config["features"]["kind"]).split("+")
        own = self.feature_families()
        for family in families:
            if family in own:
                problems += self.feature_family_problems(
                    family, config["features"].get(family) or {}
                )
            elif family not in FEATURE_FAMILIES:
                problems.append(
                    f"features.kind: {family!r} is not a feature family of the {self.name} system "
                    f"(built in: {', '.join(FEATURE_FAMILIES)}; its own: {sorted(own) or 'none'})"
                )
        if "spectrum" in families or self.calibrates_on_spectra:
            if spectrum["f_max_hz"] > nyquist:
                problems.append(
                    f"features.spectrum.f_max_hz: {spectrum['f_max_hz']} Hz is above the "
                    f"Nyquist frequency {nyquist:g} Hz of the {self.name} system's rate"
                )
            if spectrum["f_min_hz"] >= spectrum["f_max_hz"]:
                problems.append(
                    "features.spectrum.f_min_hz: must be below features.spectrum.f_max_hz"
                )
        return problems

    def protocol_problems(self) -> list[str]:
        """The protocols of hybrid.protocols whose needs (Protocol.needs) the measured data lack."""
        from condmon.protocols.base import MEASURED_NEEDS
        from condmon.protocols.registry import REGISTRY

        offers = self.measured_offers()
        if offers is None:
            return []
        source = (
            f"the measured_table {self.measured_table} has no columns {SPECIMEN_COLUMNS}"
            if self.measured_table
            else f"the {self.name} system's virtual bench gives none"
        )
        return [
            f"hybrid.protocols: {name} needs {MEASURED_NEEDS[need]}, and {source}"
            + (
                " (add them: one specimen and group per record; healthy records may leave them empty)"
                if self.measured_table
                else "; leave the protocol out"
            )
            for name in self.config["hybrid"]["protocols"]
            if name in REGISTRY
            for need in sorted(REGISTRY[name].needs - offers)
        ]

    def measured_table_columns(self) -> set[str] | None:
        """The columns of the measured_table's file, read from its schema alone; None where
        there is no table or it cannot be read (the measured job names why)."""
        if not self.measured_table:
            return None
        import pyarrow.parquet as pq

        try:
            return set(pq.read_schema(self.measured_table).names)
        except Exception:  # no such file, not Parquet: pyarrow raises several types
            return None

    def measured_table_problems(self) -> list[str]:
        """A measured_table whose file lacks signal-table columns."""
        from condmon.measured import USER_COLUMNS

        columns = self.measured_table_columns()
        missing = [c for c in USER_COLUMNS if columns is not None and c not in columns]
        return (
            [
                f"measured_table: {self.measured_table} lacks the signal-table columns {missing} "
                "(docs/architecture.md, Signal table)"
            ]
            if missing
            else []
        )

    def measured_offers(self) -> set[str] | None:
        """What the measured data carry beyond the signal table, of what protocols may need
        (MEASURED_NEEDS): "specimens" where a measured_table has the SPECIMEN_COLUMNS; a bench's
        records carry none. None where it cannot be known yet (a table that cannot be read: the
        measured job names it)."""
        if not self.measured_table:
            return set()
        columns = self.measured_table_columns()
        if columns is None:
            return None
        return {"specimens"} if set(SPECIMEN_COLUMNS) <= columns else set()

    # -- measured stage ----------------------------------------------------------------------
    def measured_part_rows(self, part: str) -> list[dict]:
        """Signal-table rows of one bench part (`measured_parts`)."""
        raise NotImplementedError(f"the {self.name} system has no synthetic bench")

    def read_measured(
        self, files, parts, channels, on_bad_record: str
    ) -> tuple[pd.DataFrame, pd.DataFrame]:
        """(signal-table frame, records list) of the measured data: the bench parts merged, or the
        user's signal table checked against the system (labels, channels, rate, segment length).
        The records list has `record_id, health_state, speed_rpm, load, status, reason`."""
        from condmon.measured import read_user_table_checked
        from condmon.signals import read_signal_table

        if parts:
            frame = pd.concat(
                [
                    read_signal_table(path, allowed_sources=(self.synthetic_source,))
                    for path in parts
                ],
                ignore_index=True,
            )
            return frame, kept_records(frame)
        if not self.measured_table:
            raise ValueError(f"the {self.name} system has no measured data: set measured_table")
        frame, skipped = read_user_table_checked(
            self.measured_table,
            self.health_states,
            channels,
            self.output_rate_hz,
            self.segment_length / self.output_rate_hz,
            on_bad_record=on_bad_record,
        )
        return frame, pd.concat(
            [kept_records(frame), skipped.assign(status="left out")], ignore_index=True
        )

    # -- calibration -------------------------------------------------------------------------
    @abstractmethod
    def calibrate(
        self,
        frame: pd.DataFrame,
        variant: str,
        calibration: dict,
        spectrum: dict,
        channels,
        processes: int = 1,
    ) -> tuple[dict, pd.DataFrame, pd.DataFrame]:
        """Fit the model to the healthy measured records: (params.json dict with at least
        `model_variant`, `parameters`, `cost`, `nominal_cost`, `evaluations`, `sensor_noise`;
        the history of every evaluation; the spectra frame `speed_rpm, channel, freq_hz,
        measured, calibrated, model_only`). A candidate whose simulation raises SimulationError
        scores `condmon.calibrate.FAILED_COST` and the search goes on."""

    def calibration_costs(self) -> dict:
        """The costs `calibration.cost` may name, {name: cost(simulated, measured) -> float}: the
        spectral ones of `condmon.calibrate` by default; a system adds its own."""
        from condmon.calibrate import SPECTRAL_COSTS

        return dict(SPECTRAL_COSTS)

    def model_variants(self, calibration: dict) -> list[str]:
        """The categorical choices calibration searches with the parameters (a model family's
        variants), given the `calibration` section; by default the one `nominal_variant`."""
        return [self.nominal_variant]

    def simulate_healthy(
        self, variant: str, values: dict, speed_rpm: float, duration_s: float, seed: int
    ) -> dict[str, np.ndarray]:
        """One healthy run of a calibration candidate: model variant `variant` (one of
        `model_variants`), `values` overriding the nominal model. A system with variants
        overrides this; by default there is one."""
        if variant != self.nominal_variant:
            raise ValueError(
                f"the {self.name} system has one model variant, {self.nominal_variant!r}, "
                f"not {variant!r}"
            )
        return self.simulate_sample(dict(values), self.healthy_state, speed_rpm, duration_s, seed)

    # -- per-state calibration (calibration.per_state) -----------------------------------------
    def state_calibration_space(self, state: str):
        """(model variants, [calibrate.Bound]) per-state calibration searches for fault `state`:
        its fault's form and severities. A system without it says so."""
        raise ValueError(
            f"calibration.per_state: the {self.name} system has no per-state calibration"
        )

    def state_parameters(self, variant: str, values: dict) -> dict:
        """Of a per-state calibration's searched `values`, those its model `variant` uses."""
        return dict(values)

    def simulate_state(
        self,
        calibrated: dict,
        state: str,
        state_model: dict | None,
        speed_rpm: float,
        duration_s: float,
        seed: int,
    ) -> dict[str, np.ndarray]:
        """One run of `state` at the healthy calibration `calibrated` (params.json), its fault as
        `state_model` (variant, parameters; None: the fault as the sample draws it) exactly."""
        raise ValueError(
            f"calibration.per_state: the {self.name} system has no per-state calibration"
        )

    # -- parameters and simulation -----------------------------------------------------------
    nominal_variant: ClassVar[str] = "nominal"  # model variant of the nominal model

    @abstractmethod
    def nominal_values(self) -> dict:
        """The nominal (uncalibrated) value of every parameter calibration may tune."""

    def nominal_calibration(self, names=None) -> dict:
        """A calibration result of the nominal model (what `sample_parameters` takes): the
        nominal values of `names` (default: every calibratable parameter), no sensor noise."""
        values = self.nominal_values()
        names = self.calibratable if names is None else names
        return {
            "model_variant": self.nominal_variant,
            "parameters": {name: values[name] for name in names},
            "sensor_noise": 0.0,
        }

    @abstractmethod
    def sample_parameters(
        self, calibrated: dict, health_state: str, rng: np.random.Generator, simulation: dict
    ) -> dict:
        """One sample's parameters (JSON-able; stored with its records): the calibrated values
        drawn by the system's rule (perturbation, domain randomisation) from `rng`, which the
        caller advances in a fixed order."""

    @abstractmethod
    def simulate_sample(
        self,
        parameters: dict,
        health_state: str,
        speed_rpm: float,
        duration_s: float,
        seed: int,
        step_refinement: int = 1,
    ) -> dict[str, np.ndarray]:
        """{channel: signal at output_rate_hz, duration_s long} of one run; `seed` drives any
        randomness of the model, `step_refinement` divides the time step. Raises SimulationError
        when the run fails or diverges, ValueError never (invalid drawn values are a failed run)."""

    @abstractmethod
    def diverging(self, parameters: dict) -> dict:
        """`parameters` changed so the run must diverge (the contract test and calibration
        tests check that this raises SimulationError and is handled)."""

    def sample_load(self, speed_rpm: float, parameters: dict) -> float:
        """The `load` column of a simulated record (its operating condition besides speed)."""
        return 0.0

    def noise_free(self, parameters: dict) -> dict:
        """`parameters` without the noise the model itself adds (sensor noise added after the
        run comes from the calibration, not from here): what a step-convergence check compares."""
        return dict(parameters)

    # -- features ----------------------------------------------------------------------------
    def defect_orders(self) -> dict | None:
        """Envelope lines the statistical features measure, in orders of the shaft speed, or None
        (no envelope features)."""
        return None

    def feature_families(self) -> dict:
        """The system's own feature families beside the built-in ones: {name:
        `condmon.features.SystemFamily`}, whose table is ``table(signal frame, channels,
        settings, inputs) -> wide features table``; `settings` is `features.<name>` (its schema
        in the system's schema file) plus what `feature_family_params` adds, `inputs` the
        run-time `condmon.features.FamilyInputs` (references, processes). None by default."""
        return {}

    def feature_family_params(self, family: str) -> dict:
        """What the system adds to `features.<family>` for its own family's table function (the
        rule's params, so an edit of it reruns the features)."""
        return {}

    def feature_family_problems(self, family: str, params: dict) -> list[str]:
        """What keeps an own family (`features.<family>`) from working on this rig's records."""
        return []

    # -- baselines ---------------------------------------------------------------------------
    # whether the baselines job hands its rules the measured signal table (`physics_baselines`)
    baselines_read_signals = False

    def defect_sidebands(self) -> dict | None:
        """Sideband spacings of the envelope lines ({name of a `defect_orders` line: spacing in
        shaft orders}), or None: the lines a defect modulates (`condmon.envelope.fault_line_sets`)."""
        return None

    def physics_baselines(self, feature_names, signals=None) -> dict:
        """{name: rule} of the training-free physics baselines this system offers on features
        `feature_names` (none by default); `signals`, the measured signal table where the rule
        reads more of it than the features hold. A rule has `fit(frame)`, which sees only the healthy
        calibration segments' feature rows (its thresholds come from them, never from a test
        segment), `predict(frame)` -> labels, and `describe()` -> a JSON-able dict. The
        `baselines` job evaluates each on every split's test set (condmon.baselines)."""
        return {}


def kept_records(frame: pd.DataFrame) -> pd.DataFrame:
    """One line per record of a signal-table frame, marked kept (with its specimen and group
    where a user's table gives them)."""
    columns = [
        "record_id",
        "health_state",
        "speed_rpm",
        "load",
        *[c for c in SPECIMEN_COLUMNS if c in frame],
    ]
    return (
        frame[columns]
        .drop_duplicates("record_id")
        .assign(status="kept", reason="")
        .reset_index(drop=True)
    )

"""The helical-gear drivetrain (`system: gear`): the exudyn model of `condmon.models.gear.drivetrain`
on the virtual bench (`measured_parts`) or on a user's signal table (`measured_table`).

Config sections (schema.yaml beside this file): `rig` (speeds, health states, output rate,
segment length), `model` (geometry, shafts, bearings, housings, mesh, faults and the per-sample
`variability`), `numerics`, `virtual_bench` (hidden truth and the effects the model lacks; never
passed to a calibration job). One
calibration per mesh stiffness model (`calibration.mesh_stiffness_models`), the simulation's
(`model.mesh_stiffness_model`) first; its model variants (searched by each calibration) are the
contact laws of `calibration.contact_laws`, the nominal one `model.contact_law`.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from condmon.calibrate import Bound, calibrate_on_spectra, spectral_problem
from condmon.models.gear.drivetrain import (
    Drivetrain,
    SimulationSettings,
    operating_mesh_stiffness,
    shaft_speeds,
    sensor_channels,
    simulate,
)
from condmon.models.gear.shaft_damage import SHAFT_HEALTH_STATES
from condmon.operating import OperatingPoint
from condmon.systems.base import System
from condmon.systems.gear.mesh_lines import mesh_line_problems
from condmon.systems.gear.parameters import (
    PROFILE_DEFLECTIONS,
    PROFILE_EXPONENTS,
    CALIBRATABLE,
    COMPLIANCE_PARAMETERS,
    STATE_SEVERITY,
    build_parameters,
    deflection_range,
    deflection_profile,
    draw_mesh_compliance,
    measured_fluctuation_fields,
    perturb,
    sample_effects,
    state_model_fields,
    state_variants,
)

# numerics the virtual bench sets for itself (virtual_bench.<key>): it stands for a real machine, so
# its records never move with the model's step, modal reduction or start-up discarded
BENCH_NUMERICS = (
    "oversampling",
    "integrator",
    "steps_per_sensor_sample",
    "modal_cutoff_hz",
    "settle_time",
)

log = logging.getLogger(__name__)


def unlisted_measured_speeds(measured_table, speeds_rpm) -> list[str]:
    """A problem naming the measured table's speeds that rig.speeds_rpm lacks: the rig is
    calibrated and simulated at its listed speeds only, so such records would be tested against
    a model never run at their speed (a table that cannot be read is the measured job's to name)."""
    return unlisted_measured(measured_table, "speed_rpm", speeds_rpm, "rig.speeds_rpm", "rpm")


def unlisted_measured_loads(measured_table, loads, unit) -> list[str]:
    """As `unlisted_measured_speeds`, for the table's loads against rig.loads (in rig.load_unit)."""
    return unlisted_measured(measured_table, "load", loads, "rig.loads", unit)


def unlisted_measured(measured_table, column, listed, key, unit) -> list[str]:
    """A problem naming the measured table's `column` values that the config's `key` (`listed`)
    lacks, with a few of their records."""
    if not measured_table or not Path(measured_table).is_file():
        return []
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(measured_table, columns=["record_id", column]).to_pandas()
    except Exception:  # pyarrow raises several types; the measured job names the file's problem
        return []
    values = table[column].to_numpy(float)
    unlisted = table[~np.isclose(values[:, None], np.asarray(listed, float)[None, :]).any(axis=1)]
    if unlisted.empty:
        return []
    found = sorted(unlisted[column].unique())
    records = sorted(unlisted["record_id"].unique())
    return [
        f"measured_table: records at {[float(f'{v:g}') for v in found]} {unit} ({records[:3]}"
        f"{' ...' if len(records) > 3 else ''}) but {key} is {list(listed)}; add "
        f"those to {key} (calibrated and simulated there) or leave the records out"
    ]


def condition_of_loads_problems(speeds_rpm, loads, condition) -> list[str]:
    """A rig run at several loads needs `hybrid.condition` to be what varies: each condition's
    healthy records are its machine's reference and its stratum, so a speed's reference pooled
    over its loads would miss every load's own mesh level. A grid of several speeds and several
    loads has no single such column (not supported yet)."""
    if len(set(loads)) < 2:
        return []
    if len(set(speeds_rpm)) >= 2:
        return [
            f"rig.loads {list(loads)} at rig.speeds_rpm {list(speeds_rpm)}: a grid of several speeds "
            "and several loads is not supported yet (hybrid.condition takes one of them); run "
            "each speed as its own config with hybrid.condition: load"
        ]
    if condition != "load":
        return [
            f"rig.loads {list(loads)} at one speed: set hybrid.condition: load (it is "
            f"{condition!r}), so each load's healthy records are its own reference and stratum"
        ]
    return []


class GearSystem(System):
    name = "gear"
    schema_file = Path(__file__).with_name("schema.yaml")
    sections = ("rig", "model", "numerics", "virtual_bench")
    default_condition = "speed_rpm"

    # -- layout ------------------------------------------------------------------------------
    @property
    def health_states(self) -> list[str]:
        return list(self.config["rig"]["health_states"])

    @property
    def healthy_state(self) -> str:
        return "healthy"

    @property
    def channels(self) -> list[str]:
        return list(sensor_channels(self.parameters().sensors))

    def parameters(self, **overrides):
        """The drivetrain's GearDrivetrainParameters: the `model` section plus overrides."""
        return build_parameters(self.config["model"], **overrides)

    @property
    def output_rate_hz(self) -> float:
        return float(self.config["rig"]["output_rate_hz"])

    @property
    def segment_length(self) -> int:
        return int(round(self.config["rig"]["segment_seconds"] * self.output_rate_hz))

    @property
    def speeds_rpm(self) -> list[float]:
        return [float(s) for s in self.config["rig"]["speeds_rpm"]]

    @property
    def operating_points(self) -> list[OperatingPoint]:
        rig = self.config["rig"]
        if rig["loads"] is None:
            return super().operating_points
        return [
            OperatingPoint(float(speed), float(load), rig["load_unit"])
            for speed in sorted(self.speeds_rpm)
            for load in sorted(rig["loads"])
        ]

    def load_torque(self, load: float) -> float:
        """The output shaft's torque (N m, the model's `load_torque`) of a load in `rig.load_unit`."""
        if self.config["rig"]["load_unit"] == "percent":
            return float(self.config["model"]["load_torque"]) * float(load) / 100.0
        return float(load)

    def at_load(self, parameters, load):
        if load is None:
            return dict(parameters)
        return dict(parameters, load_torque=self.load_torque(load))

    @property
    def settle_seconds(self) -> float:
        return float(self.config["numerics"]["settle_time"])

    @property
    def calibratable(self) -> tuple[str, ...]:
        return CALIBRATABLE

    @property
    def numerics(self) -> dict:
        return dict(self.config["numerics"], output_rate=self.output_rate_hz)

    def calibration_variants(self) -> list[str]:
        simulated = self.config["model"]["mesh_stiffness_model"]
        return [simulated] + [
            m for m in self.config["calibration"]["mesh_stiffness_models"] if m != simulated
        ]

    def calibration_settings(self, calibration: dict) -> dict:
        return {k: v for k, v in calibration.items() if k != "mesh_stiffness_models"}

    def measured_parts(self) -> list[str]:
        return list(self._bench_parts())

    def healthy_parts(self) -> list[str]:
        return [
            part
            for part, (health, _) in self._bench_parts().items()
            if health == self.healthy_state
        ]

    def _bench_parts(self) -> dict:
        """{part: (health state, operating point)}: the virtual bench's jobs, one per state and
        point (none with a measured table)."""
        if self.measured_table:
            return {}
        return {
            f"{health}_{point.label}": (health, point)
            for health in self.health_states
            for point in self.operating_points
        }

    def job_config(self, stage: str, variant: str | None = None) -> dict:
        config = super().job_config(stage, variant)
        if stage != "simulate" and "model" in config:
            # the per-sample perturbation of the calibrated values concerns the simulation only
            # and so does the drawn mesh compliance (the calibration runs the nominal mesh), but
            # for a calibrated deflection, whose profile the calibration takes
            variability = {
                k: v
                for k, v in config["model"].get("variability", {}).items()
                if k != "perturbation_sigma"
            }
            compliance = config["model"].get("mesh_compliance")
            profiled = stage == "calibrate" and (compliance or {}).get("deflection") == "calibrated"
            config["model"] = {
                k: v
                for k, v in dict(config["model"], variability=variability).items()
                if k != "mesh_compliance" or profiled
            }
        if stage != "bench":
            config.pop("virtual_bench", None)  # the hidden truth reaches the bench jobs only
        if stage == "bench":
            # the bench's mesh is virtual_bench.true_parameters.mesh_stiffness_model, not the model's,
            # and its sensor rate, modal reduction and start-up are virtual_bench's own
            config["model"] = {
                k: v for k, v in config["model"].items() if k != "mesh_stiffness_model"
            }
            config["numerics"] = {
                k: v for k, v in config["numerics"].items() if k not in BENCH_NUMERICS
            }
        elif stage == "calibrate":
            config["model"] = dict(config["model"], mesh_stiffness_model=variant)
        elif stage == "measured":
            config = {key: config[key] for key in ("rig", "measured_table") if key in config}
        elif stage == "features":
            config = {}
        return config

    # -- checks ------------------------------------------------------------------------------
    def problems(self) -> list[str]:
        config = self.config
        problems = super().problems()
        rig, spectrum = config["rig"], config["features"]["spectrum"]
        nyquist = rig["output_rate_hz"] / 2
        span = spectrum["f_max_hz"] - spectrum["f_min_hz"]
        for key, resolution in (
            ("features.spectrum.resolution_hz", spectrum["resolution_hz"]),
            ("calibration.resolution_hz", config["calibration"]["resolution_hz"]),
        ):
            if abs(span / resolution - round(span / resolution)) > 1e-6:
                problems.append(
                    f"{key}: the range f_min_hz..f_max_hz ({span:g} Hz) is not a whole number "
                    f"of {resolution:g} Hz bands"
                )
        segment_resolution = 1.0 / rig["segment_seconds"]
        if spectrum["resolution_hz"] < segment_resolution:
            problems.append(
                f"features.spectrum.resolution_hz: {spectrum['resolution_hz']} Hz is finer than "
                f"the {segment_resolution:g} Hz a {rig['segment_seconds']} s segment resolves"
            )
        for name, ratio, teeth in self.shafts()[::2]:  # each pair's pinion
            gmf = max(rig["speeds_rpm"]) / 60 * ratio * teeth
            if gmf >= nyquist:
                problems.append(
                    f"rig.output_rate_hz: the gear mesh frequency {gmf:.0f} Hz (of {name}) at the "
                    f"highest speed is above the Nyquist frequency {nyquist} Hz"
                )
        problems += self.stage_problems()
        if (
            config["measured_table"] is None
            and config["virtual_bench"]["record_seconds"] < rig["segment_seconds"]
        ):
            problems.append("virtual_bench.record_seconds: shorter than rig.segment_seconds")
        if config["calibration"]["sim_seconds"] < rig["segment_seconds"]:
            problems.append("calibration.sim_seconds: shorter than rig.segment_seconds")
        compliance = config["model"].get("mesh_compliance")
        if compliance:
            problems += [
                f"model.mesh_compliance.{key}: [low, high] with low above high: {value}"
                for key, value in compliance.items()
                if value not in ("auto", "calibrated") and value[0] > value[1]
            ]
            problems += self.compliance_problems(compliance)
            both = sorted(set(COMPLIANCE_PARAMETERS) & set(config["calibration"]["parameters"]))
            if both:
                problems.append(
                    f"calibration.parameters: {both} are drawn per sample by model.mesh_compliance; "
                    "calibrate them or draw them, not both"
                )
        if "condition_holdout" in config["hybrid"]["protocols"]:
            problems += self.condition_holdout_problems()
        problems += unlisted_measured_speeds(config["measured_table"], rig["speeds_rpm"])
        if rig["loads"] is not None:
            problems += unlisted_measured_loads(
                config["measured_table"], rig["loads"], rig["load_unit"]
            )
            problems += condition_of_loads_problems(
                rig["speeds_rpm"], rig["loads"], config["hybrid"]["condition"]
            )
        # a rate the healthy records' mesh lines contradict (a guessed fs_hz), named with the rate they imply
        problems += mesh_line_problems(
            config["measured_table"],
            self.healthy_state,
            int(config["model"]["geometry"]["teeth_pinion"]),
        )
        try:
            Drivetrain(self.parameters())
        except (ValueError, TypeError) as exc:
            problems.append(f"model: {exc}")
        if config["measured_table"] is None:
            from condmon.models.gear.virtual_bench import FAULT_FORMS

            for state, spec in config["virtual_bench"]["faults"].items():
                missing = [key for key in FAULT_FORMS[spec["form"]] if key not in spec]
                if missing:
                    problems.append(
                        f"virtual_bench.faults.{state}: form {spec['form']} needs {missing}"
                    )
                for key in ("profile", "face"):
                    if key in spec and not spec[key][0] < spec[key][1]:
                        problems.append(
                            f"virtual_bench.faults.{state}.{key}: [start, end] with start < end "
                            f"(got {spec[key]})"
                        )
            try:
                self.parameters(**dict(config["virtual_bench"]["model_overrides"]))
            except (ValueError, TypeError) as exc:
                problems.append(f"virtual_bench.model_overrides: {exc}")
        bound = config["calibration"]["parameters"].get("restitution")
        if bound is not None and not (0 < bound["low"] and bound["high"] <= 1):
            problems.append("calibration.parameters.restitution: bounds must lie in (0, 1]")
        return problems

    def compliance_problems(self, compliance: dict) -> list[str]:
        """A configured deflection range that misses ISO 6336-1's estimate at the rig's load by more
        than a factor 2 (a range kept from another load: the simulated faults would be sized
        for that load)."""
        if compliance["deflection"] in ("auto", "calibrated"):
            return []
        low, high = compliance["deflection"]
        if low > high:  # named on its own
            return []
        iso_low, iso_high = deflection_range(dict(compliance, deflection="auto"), self.parameters())
        if high >= iso_low / 2 and low <= 2 * iso_high:
            return []
        return [
            f"model.mesh_compliance.deflection: [{low * 1e6:.3g}, {high * 1e6:.3g}] um, where ISO "
            f"6336-1 puts the first pair at {iso_low * 1e6:.3g}-{iso_high * 1e6:.3g} um under "
            f"load_torque {self.config['model']['load_torque']:g} N m; set the range for this "
            "load, or `auto`"
        ]

    def stage_problems(self) -> list[str]:
        """Pair and shaft numbers the train lacks (`model.faulty_stages`, `model.damaged_shaft`,
        a bench fault's `stage`)."""
        config = self.config
        pairs = 1 + len(config["model"]["stages"])
        problems = [
            f"model.faulty_stages: pair {stage} of a train of {pairs} (0..{pairs - 1})"
            for stage in config["model"]["faulty_stages"]
            if stage >= pairs
        ]
        if config["model"]["damaged_shaft"] > pairs:
            problems.append(
                f"model.damaged_shaft: shaft {config['model']['damaged_shaft']} of a train of "
                f"{pairs + 1} shafts (0..{pairs})"
            )
        if config["measured_table"] is None:
            problems += [
                f"virtual_bench.faults.{state}.stage: pair {spec['stage']} of a train of {pairs} "
                f"(0..{pairs - 1})"
                for state, spec in config["virtual_bench"]["faults"].items()
                if spec.get("stage", 0) >= pairs
            ]
        return problems

    # -- measured: the virtual bench ---------------------------------------------------------
    def measured_part_rows(self, part: str) -> list[dict]:
        from condmon.systems.gear.bench import virtual_bench_rows

        health, point = self._bench_parts()[part]
        bench = self.config["virtual_bench"]
        return virtual_bench_rows(
            self.parameters,
            bench,
            [health],
            [point],
            dict(self.numerics, **{key: bench[key] for key in BENCH_NUMERICS}),
            self.config["rig"]["segment_seconds"],
            load_torque=self.load_torque,
            table_load=self.table_load,
        )

    def bench_differences(self) -> list[dict]:
        """Every way the bench differs from the model, each calibrated, randomised, neither or same
        (`differences.bench_differences`)."""
        from condmon.systems.gear.differences import bench_differences

        if not self.measured_parts():
            return []
        return bench_differences(self.config, self.health_states, self.healthy_state)

    # -- calibration -------------------------------------------------------------------------
    def calibrate(self, frame, variant, calibration, spectrum, channels, processes=1):
        model = self.config["model"]
        compliance = model.get("mesh_compliance") or {}
        problem = spectral_problem(self, frame, calibration, spectrum, channels)
        result, history, spectra = calibrate_on_spectra(
            self,
            frame,
            calibration,
            spectrum,
            channels,
            nominal=model,
            processes=processes,
            problem=problem,
        )
        if compliance.get("deflection") == "calibrated":
            variant, values = result["model_variant"], result["parameters"]
            log.info(
                "mesh deflection profile: %d evaluations of the calibration's cost",
                PROFILE_DEFLECTIONS * PROFILE_EXPONENTS,
            )
            profile = deflection_profile(
                lambda changed: problem(variant, {**values, **changed}),
                compliance,
                self.parameters(contact_law=variant, **values),
            )
            result["mesh_deflection"] = profile
            log.info(
                "mesh deflection profile (um: cost) %s; the simulation draws %.3g-%.3g um",
                {
                    f"{d * 1e6:.3g}": round(c, 4)
                    for d, c in zip(profile["deflection"], profile["cost"])
                },
                *(d * 1e6 for d in profile["range"]),
            )
        # K and n trade off at one load; the stiffness the vibration sees is what the data pin down.
        best = self.parameters(contact_law=result["model_variant"], **result["parameters"])
        result = dict(
            result,
            contact_law=result["model_variant"],
            mesh_stiffness_model=model["mesh_stiffness_model"],
            operating_mesh_stiffness=operating_mesh_stiffness(best),
        )
        if model["variability"]["speed_fluctuation_source"] == "healthy_records":
            result["speed_fluctuation"] = self.measured_speed_fluctuation(frame, channels)
            if not any(result["speed_fluctuation"].values()):
                result["warning"] = (
                    "speed_fluctuation_source healthy_records: no healthy record showed its "
                    "fluctuation; the simulation draws model.variability's ranges"
                )
                log.warning(result["warning"])
        return result, history, spectra

    def measured_speed_fluctuation(self, frame, channels) -> dict:
        """{speed: fluctuation.speed_fluctuation(...)} of the healthy calibration records at every
        measured speed (None where they cannot show it: `speed_fluctuation` says when)."""
        from condmon.signals import to_arrays
        from condmon.systems.gear.fluctuation import speed_fluctuation

        ids, segments = to_arrays(frame, list(channels))
        teeth = self.config["model"]["geometry"]["teeth_pinion"]
        out = {}
        for speed in sorted(ids["speed_rpm"].astype(float).unique()):
            chosen = (ids["speed_rpm"].astype(float) == speed).to_numpy()
            out[f"{speed:g}"] = speed_fluctuation(
                segments[chosen], self.output_rate_hz, speed, teeth
            )
            log.info(
                "speed fluctuation of the healthy records at %g rpm: %s", speed, out[f"{speed:g}"]
            )
        return out

    # -- simulation --------------------------------------------------------------------------
    @property
    def nominal_variant(self) -> str:
        return self.config["model"]["contact_law"]

    def model_variants(self, calibration: dict) -> list[str]:
        return list(calibration["contact_laws"])

    def simulate_healthy(self, variant, values, speed_rpm, duration_s, seed):
        # the model variant is the mesh's contact law
        return self.simulate_sample(
            {**values, "contact_law": variant}, self.healthy_state, speed_rpm, duration_s, seed
        )

    def nominal_calibration(self, names=None) -> dict:
        return dict(super().nominal_calibration(names), contact_law=self.nominal_variant)

    # -- per-state calibration ---------------------------------------------------------------
    def state_calibration_space(self, state):
        model = self.config["model"]
        variants = state_variants(state, model["surface_fault_model"])
        severity = model["fault_severity"]
        names = sorted({name for variant in variants for name in STATE_SEVERITY[variant]})
        return variants, [
            Bound(name, float(severity[name][0]), float(severity[name][1]), False) for name in names
        ]

    def state_parameters(self, variant, values):
        return {name: values[name] for name in STATE_SEVERITY[variant]}

    def simulate_state(self, calibrated, state, state_model, speed_rpm, duration_s, seed):
        parameters = {**calibrated["parameters"], "contact_law": calibrated["contact_law"]}
        if state_model is not None:
            parameters["state_model"] = dict(state_model, spread=0.0)
        if calibrated.get("speed_fluctuation"):
            parameters["measured_speed_fluctuation"] = calibrated["speed_fluctuation"]
        return self.simulate_sample(parameters, state, speed_rpm, duration_s, seed)

    def nominal_values(self) -> dict:
        return {name: self.config["model"][name] for name in CALIBRATABLE}

    def sample_parameters(self, calibrated, health_state, rng, simulation) -> dict:
        values = perturb(
            calibrated["parameters"],
            list(calibrated["parameters"]),
            self.config["model"]["variability"]["perturbation_sigma"],
            rng,
        )
        compliance = self.config["model"].get("mesh_compliance")
        if compliance:  # drawn from the job's stream, so twins share it (healthy reference)
            profile = calibrated.get("mesh_deflection") or {}
            values.update(
                draw_mesh_compliance(
                    compliance, self.parameters(**values), rng, profile.get("range")
                )
            )
        # per-state calibration: the state's tuned severities (drawn in simulate_sample, no draw here)
        state_model = (calibrated.get("state_models") or {}).get(health_state)
        measured = calibrated.get("speed_fluctuation")
        return {
            "contact_law": calibrated["contact_law"],
            **values,
            **({"state_model": state_model} if state_model else {}),
            **({"measured_speed_fluctuation": measured} if measured else {}),
        }

    def simulate_sample(
        self, parameters, health_state, speed_rpm, duration_s, seed, step_refinement=1
    ):
        """One run; `seed` draws this drivetrain's run-out, pitch errors and fluctuations
        (`model.variability`) and its fault's severity (`model.fault_severity`, or a calibrated
        `state_model` of `parameters`: `state_model_fields`)."""
        model = self.config["model"]
        parameters = dict(parameters)
        state_model = parameters.pop("state_model", None)
        measured_fluctuation = parameters.pop("measured_speed_fluctuation", None)
        params = self.parameters(
            speed_rpm=float(speed_rpm), health_state=health_state, **parameters
        )
        effects = sample_effects(model, params.geometry, np.random.default_rng(seed), params.stages)
        if state_model is not None:
            effects.update(state_model_fields(state_model, effects, seed))
        if measured_fluctuation:
            effects.update(
                measured_fluctuation_fields(measured_fluctuation, float(speed_rpm), seed)
            )
        params = params.replace(**effects)
        return simulate(
            params,
            SimulationSettings(
                duration=duration_s, step_refinement=int(step_refinement), **self.numerics
            ),
        )

    def condition_holdout_problems(self) -> list[str]:
        """condition_holdout holds out one value of `hybrid.condition` at a time: the run needs
        two or more (speeds: rig.speeds_rpm; loads: those of the measured table, the bench's
        one load otherwise)."""
        config, condition = self.config, self.config["hybrid"]["condition"]
        if condition == "speed_rpm":
            values = sorted(set(config["rig"]["speeds_rpm"]))
        elif config["measured_table"] is not None:
            import pyarrow.parquet as pq

            try:
                values = sorted(
                    set(
                        pq.read_table(config["measured_table"], columns=[condition])[
                            condition
                        ].to_pylist()
                    )
                )
            except Exception:  # an unreadable table: the measured job names it
                return []
        elif config["rig"]["loads"] is not None:  # the virtual bench runs every listed load
            values = sorted(set(config["rig"]["loads"]))
        else:
            values = [self.table_load(config["model"]["load_torque"])]
        if len(values) >= 2:
            return []
        return [
            f"hybrid.protocols: condition_holdout holds out one hybrid.condition ({condition}) at "
            f"a time and needs two or more; the run has {values}"
        ]

    def diverging(self, parameters: dict) -> dict:
        # a mesh a million times stiffer needs a step far below any physical range: SimulationError
        stiffness = parameters.get("mesh_stiffness", self.config["model"]["mesh_stiffness"])
        return dict(parameters, mesh_stiffness=float(stiffness) * 1e6)

    def sample_load(self, speed_rpm, parameters) -> float:
        """The load in the table's unit (`rig.load_unit`) the run had (`at_load`'s, or the model's)."""
        return self.table_load(parameters.get("load_torque", self.config["model"]["load_torque"]))

    def table_load(self, torque: float) -> float:
        """An output torque (N m) in `rig.load_unit`: `load_torque`'s inverse."""
        if self.config["rig"]["load_unit"] == "percent":
            return 100.0 * float(torque) / float(self.config["model"]["load_torque"])
        return float(torque)

    # -- features ----------------------------------------------------------------------------
    # -- features: the order-domain gear diagnostics (order_features.py) and the residual
    # signatures against each machine's healthy reference (residual_features.py) -------------
    def feature_families(self) -> dict:
        from condmon.features import SystemFamily
        from condmon.systems.gear.order_features import order_feature_table
        from condmon.systems.gear.residual_features import residual_feature_table

        # the residual signatures take every machine against its healthy reference (a waveform)
        # themselves and spread their segments over the job's cores
        return {
            "order": SystemFamily(order_feature_table),
            "residual": SystemFamily(residual_feature_table, references=True, parallel=True),
        }

    def feature_family_params(self, family: str) -> dict:
        shafts = {"shafts": [list(shaft) for shaft in self.shafts()]}
        if family == "residual":  # the shafts whose gear or shaft the simulated faults damage
            shafts["damaged_shafts"] = self.damaged_shafts()
            # how many pitches a tooth meshes over (transverse plus overlap ratio): where a
            # located tooth's change may lie
            shafts["contact_ratio"] = round(
                float(self.parameters().geometry.total_contact_ratio), 3
            )
        return shafts

    def damaged_shafts(self) -> list[str]:
        """The gears (`shafts`) the health states damage: the pinion of each pair the simulated
        tooth faults sit on (`model.faulty_stages`) and, with a shaft fault, a gear on
        `model.damaged_shaft` (0: the input shaft, k: the k-th pair's gear shaft)."""
        model = self.config["model"]
        names = [name for name, _, _ in self.shafts()]
        damaged = (
            {names[2 * stage] for stage in model.get("faulty_stages", [0])}
            if set(self.health_states) - {self.healthy_state} - set(SHAFT_HEALTH_STATES)
            else set()
        )
        if set(self.health_states) & set(SHAFT_HEALTH_STATES):
            shaft = int(model.get("damaged_shaft", 0))
            damaged.add(names[max(2 * shaft - 1, 0)])
        return [name for name in names if name in damaged] or names[:1]

    def feature_family_problems(self, family: str, order: dict) -> list[str]:
        """What keeps the order features (`features.order`) or the residual signatures
        (`features.residual`) from working on this rig's records: no gears, no healthy reference
        (residual), orders above the Nyquist order at the highest speed, a segment shorter than
        one revolution of a shaft or too short for the order bands."""
        shafts = self.shafts()
        problems = []
        if family == "residual":
            if not self.config["features"]["healthy_reference"]["enabled"]:
                problems.append(
                    "features.kind residual: the residual signatures take every machine against "
                    "its own healthy reference; set features.healthy_reference.enabled: true"
                )
            from condmon.systems.gear.residual_features import (
                PASSBAND_SHARE,
                passband_harmonics,
                resolution_problem,
            )

            # the grid against the rate at every speed, for the widest window the rule can give
            widest = order["mesh_harmonics"]
            if widest == "auto":  # the rule's window, bounded by the passband (`window_harmonics`)
                widest = min(
                    passband_harmonics(self.output_rate_hz, max(self.speeds_rpm), teeth, ratio)
                    for _, ratio, teeth in shafts
                )
                if widest < 1:
                    problems.append(
                        f"features.residual.mesh_harmonics: auto finds no mesh harmonic within "
                        f"rig.output_rate_hz / 2.56 ({self.output_rate_hz * PASSBAND_SHARE:g} Hz) at "
                        f"{max(self.speeds_rpm):g} rpm"
                    )
            folding = {
                resolution_problem(
                    self.output_rate_hz,
                    speed,
                    shafts,
                    order["samples_per_revolution"],
                    max(widest, 1),
                )
                for speed in self.speeds_rpm
            }
            problems += sorted(p for p in folding if p)
            return problems + self._order_problems(
                "features.residual",
                shafts,
                1 if order["mesh_harmonics"] == "auto" else order["mesh_harmonics"],
            )
        fastest, slowest = max(self.speeds_rpm) / 60, min(self.speeds_rpm) / 60
        seconds = (self.segment_length - 1) / self.output_rate_hz
        nyquist_order = self.output_rate_hz / 2 / fastest
        if order["order_max"] > nyquist_order:
            problems.append(
                f"features.order.order_max: {order['order_max']} is above the Nyquist order "
                f"{nyquist_order:.1f} at the highest speed {max(self.speeds_rpm):g} rpm"
            )
        if 1 / (seconds * slowest) > order["resolution_orders"]:
            problems.append(
                f"features.order.resolution_orders: {order['resolution_orders']} is finer than the "
                f"{1 / (seconds * slowest):.3g} orders a segment resolves at {min(self.speeds_rpm):g} rpm"
            )
        return problems + self._order_problems("features.order", shafts, order["mesh_harmonics"])

    def _order_problems(self, section: str, shafts, mesh_harmonics: int) -> list[str]:
        """Whole revolutions of every shaft in a segment, its mesh harmonics below the Nyquist order."""
        fastest, slowest = max(self.speeds_rpm) / 60, min(self.speeds_rpm) / 60
        seconds = (self.segment_length - 1) / self.output_rate_hz
        nyquist_order = self.output_rate_hz / 2 / fastest
        problems = []
        for name, ratio, teeth in shafts:
            if seconds * slowest * ratio < 1:
                problems.append(
                    f"rig: a segment holds less than one revolution of the {name} at "
                    f"{min(self.speeds_rpm):g} rpm; the order features average whole revolutions"
                )
            top = (mesh_harmonics * teeth + 1) * ratio
            if top > nyquist_order:
                problems.append(
                    f"{section}.mesh_harmonics: the {name}'s harmonic {mesh_harmonics} "
                    f"and its sideband (input order {top:g}) lie above the Nyquist order "
                    f"{nyquist_order:.1f} at {max(self.speeds_rpm):g} rpm"
                )
        return problems

    def shafts(self) -> list[tuple[str, float, int]]:
        """Each gear with its shaft's speed over the input shaft's and its teeth: the pinion on
        the input shaft (ratio 1) and the gear on the output shaft (ratio teeth_pinion /
        teeth_gear) of `model.geometry`; a train's further pairs (`model.stages`) add theirs,
        `pinion_2` on the previous gear's shaft and `gear_2` on its own, and so on."""
        p = self.parameters()
        ratios = shaft_speeds(p, 1.0)
        gears = []
        for k, g in enumerate([p.geometry] + [stage.geometry for stage in p.stages]):
            suffix = f"_{k + 1}" if k else ""
            gears.append((f"pinion{suffix}", ratios[k], g.teeth_pinion))
            gears.append((f"gear{suffix}", ratios[k + 1], g.teeth_gear))
        return gears

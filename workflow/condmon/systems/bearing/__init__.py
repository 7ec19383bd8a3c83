"""The ball-bearing rig (`system: bearing`): the exudyn rotor on two ball bearings of
`condmon.models.bearing.rig`, calibrated on healthy records and simulated under domain
randomisation. Measured data: the original CWRU `.mat` files of `measured_dir` (cwru.py), or a
user's signal table (`measured_table`) from any bearing rig.

Config sections (schema.yaml beside this file): `bearing` (acquisition, geometry of the tested
and the other bearing, labels and their defects, load-speed table, nominal model, numerics,
randomisation), `cwru` (the task and manifest of the CWRU reader, the design specimens),
`measured_dir`, `rig` (simulated speeds).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np

from condmon.models.bearing.rig import CHANNELS, simulate_rig
from condmon.models.numerics import SimulationError
from condmon.seeds import job_rng
from condmon.systems.base import System
from condmon.systems.bearing.model import (
    SCALES,
    build_rig_parameters,
    defect_of_label,
    feature_orders,
    load_of_speed,
    rig_settings,
    sample_values,
)


log = logging.getLogger(__name__)
# what of features.statistical the envelope rule's own analyses read (the baselines job's config)
RULE_READS = ("band_hz", "highpass_hz", "line_tolerance", "floor_halfwidth_orders", "envelope")


class BearingSystem(System):
    name = "bearing"
    schema_file = Path(__file__).with_name("schema.yaml")
    sections = ("rig", "bearing", "cwru", "measured_dir")
    # CWRU records at one load differ by a few rpm: the operating condition is the load
    default_condition = "load"
    # the envelope rule reads its own analyses of the measured records (line_analyses)
    baselines_read_signals = True

    # -- layout ------------------------------------------------------------------------------
    @property
    def bearing(self) -> dict:
        return self.config["bearing"]

    @property
    def labels(self) -> dict | None:
        """`bearing.health_states` ({label: defect}), or None for the CWRU task's labels."""
        return self.bearing["health_states"]

    @property
    def health_states(self) -> list[str]:
        if self.labels is not None:
            return list(self.labels)
        from condmon.systems.bearing.cwru import task_labels

        return task_labels(self.config["cwru"]["task"])

    @property
    def healthy_state(self) -> str:
        return self.bearing["healthy_state"]

    @property
    def channels(self) -> list[str]:
        return list(CHANNELS)  # the model's sensor; the files may hold more (bearing.channels)

    @property
    def output_rate_hz(self) -> float:
        return float(self.bearing["fs_hz"])

    @property
    def segment_length(self) -> int:
        return int(self.bearing["segment_length"])

    @property
    def segment_hop(self) -> int:
        return int(self.bearing.get("segment_hop") or self.segment_length)

    @property
    def speeds_rpm(self) -> list[float]:
        return [float(s) for s in self.config["rig"]["speeds_rpm"]]

    @property
    def settle_seconds(self) -> float:
        return float(self.bearing["numerics"]["settle_time"])

    @property
    def model(self) -> dict:
        return self.bearing["model"]

    @property
    def calibratable(self) -> tuple[str, ...]:
        return tuple(sorted(set(self.model) | set(SCALES)))

    @property
    def numerics(self) -> dict:
        return dict(self.bearing["numerics"], output_rate_hz=self.output_rate_hz)

    @property
    def geometries(self) -> tuple[dict, dict]:
        return self.bearing["geometry"], self.bearing["fan_end_geometry"]

    def measured_files(self) -> list[str]:
        if self.measured_table:
            return [self.measured_table]
        folder = Path(self.config["measured_dir"])
        files = sorted(folder.glob("*.mat"))
        if not files:
            raise ValueError(f"measured_dir: no .mat files in {folder}")
        manifest = self.config["cwru"]["manifest"]
        if manifest == "auto":
            manifest = folder / "index.csv" if (folder / "index.csv").exists() else None
        return [str(f) for f in files] + ([str(manifest)] if manifest else [])

    def measured_offers(self) -> set[str] | None:
        """The CWRU files' records carry their specimens (the file table); a table, its columns."""
        return super().measured_offers() if self.measured_table else {"specimens"}

    def design_specimens(self) -> list[str]:
        """`cwru.design_specimens` as records.csv names them (a measured_table's records carry
        no CWRU specimen: none)."""
        if self.measured_table:
            return []
        from condmon.systems.bearing.cwru import specimen_name

        return [
            specimen_name(s["fault"], s.get("diameter_in", 0.0), s.get("position"))
            for s in self.config["cwru"]["design_specimens"]
        ]

    def unmodelled_specimens(self) -> dict[str, str]:
        """`cwru.other_bearing` (specimens of another bearing than bearing.geometry) as
        {records.csv specimen name: reason} (a measured_table's records carry no CWRU specimen:
        none)."""
        if self.measured_table:
            return {}
        from condmon.systems.bearing.cwru import specimen_name

        return {
            specimen_name(s["fault"], s.get("diameter_in", 0.0), s.get("position")): s["reason"]
            for s in self.config["cwru"]["other_bearing"]
        }

    def job_config(self, stage: str, variant: str | None = None) -> dict:
        config = super().job_config(stage, variant)
        # the design and other-bearing specimens concern the report alone (its own params): an
        # edit reruns nothing else
        if "cwru" in config:
            config["cwru"] = {
                k: v
                for k, v in config["cwru"].items()
                if k not in ("design_specimens", "other_bearing")
            }
        if stage == "features":
            return {"bearing": {"geometry": self.bearing["geometry"]}}
        if (
            stage == "baselines"
        ):  # the labels, the envelope rule's setting and the analyses it reads
            statistical = self.config.get("features", {}).get("statistical", {})
            return {
                "bearing": {
                    key: self.bearing[key]
                    for key in ("health_states", "healthy_state", "envelope_rule", "geometry")
                },
                "cwru": {"task": self.config["cwru"]["task"]},
                "features": {
                    "statistical": {
                        key: statistical[key] for key in RULE_READS if key in statistical
                    }
                },
            }
        if stage != "measured":
            config.pop("measured_dir", None)
        # the envelope rule's settings concern the baselines job alone: an edit reruns nothing else
        if "bearing" in config:
            config["bearing"] = {k: v for k, v in config["bearing"].items() if k != "envelope_rule"}
        return config

    # -- checks ------------------------------------------------------------------------------
    def problems(self) -> list[str]:
        config, bearing = self.config, self.bearing
        problems = super().problems()
        if not config["measured_table"] and not Path(config["measured_dir"]).is_dir():
            problems.append(
                f"measured_dir: {config['measured_dir']} is not a folder (point it at your CWRU "
                ".mat files with --config measured_dir=PATH, or give a measured_table)"
            )
        extra = sorted(set(config["features"]["channels"]) - set(bearing["channels"]))
        if extra:
            problems.append(
                f"features.channels: {extra} not among the measured bearing.channels "
                f"{bearing['channels']}"
            )
        low, high = config["features"]["statistical"]["band_hz"]
        if not 0 < low < high < self.output_rate_hz / 2:
            problems.append(
                f"features.statistical.band_hz: {[low, high]} must satisfy 0 < low < high < "
                f"bearing.fs_hz / 2 = {self.output_rate_hz / 2:g}"
            )
        for key in ("geometry", "fan_end_geometry"):
            g = bearing[key]
            if not g["ball_diameter"] < g["pitch_diameter"]:
                problems.append(f"bearing.{key}: ball_diameter must be below pitch_diameter")
        if self.labels is not None:
            for label, spec in self.labels.items():
                if spec["defect"] != "none" and "diameter_mm" not in spec:
                    problems.append(
                        f"bearing.health_states.{label}: a {spec['defect']} defect needs "
                        "diameter_mm: [low, high]"
                    )
                elif (
                    "diameter_mm" in spec
                    and not 0 <= spec["diameter_mm"][0] <= spec["diameter_mm"][1]
                ):
                    problems.append(
                        f"bearing.health_states.{label}.diameter_mm: need 0 <= low <= high"
                    )
            if (
                self.healthy_state in self.labels
                and self.labels[self.healthy_state]["defect"] != "none"
            ):
                problems.append(
                    f"bearing.healthy_state: {self.healthy_state!r} has a defect in "
                    "bearing.health_states"
                )
            if not config["measured_table"]:
                problems.append(
                    "bearing.health_states: CWRU files are labelled by cwru.task; own labels "
                    "need a measured_table"
                )
        both = set(self.design_specimens()) & set(self.unmodelled_specimens())
        if both:
            problems.append(
                f"cwru: {sorted(both)} both a design specimen and another bearing "
                "(cwru.other_bearing): a record of another bearing tunes nothing"
            )
        entries = [
            (key, i, specimen)
            for key in ("design_specimens", "other_bearing")
            for i, specimen in enumerate(config["cwru"][key])
        ]
        for key, i, specimen in entries:
            where = f"cwru.{key}[{i}] ({specimen})"
            if (specimen["fault"] == "outer_race") != ("position" in specimen):
                problems.append(
                    f"{where}: an outer-race specimen, and only one, names its position "
                    "(3:00, 6:00 or 12:00)"
                )
            if (specimen["fault"] == "normal") != (not specimen.get("diameter_in")):
                problems.append(f"{where}: a fault specimen, and only one, names its diameter_in")
        hop, length = self.bearing.get("segment_hop"), self.segment_length
        guard = config["calibration"]["reserve"]["guard_segments"]
        if hop is not None and hop > length:
            problems.append(f"bearing.segment_hop {hop} exceeds bearing.segment_length {length}")
        elif hop and guard < math.ceil(2 * length / hop) - 1:
            # the guard gap between a lone healthy record's calibration block and its test
            # blocks must be at least one segment long in samples (hybrid.time_blocks)
            problems.append(
                f"calibration.reserve.guard_segments {guard} leaves a guard gap "
                f"shorter than one segment ({length} samples) with bearing.segment_hop "
                f"{hop}; use at least {math.ceil(2 * length / hop) - 1}"
            )
        if (
            config["hybrid"]["condition"] == "speed_rpm"
            and "condition_holdout" in config["hybrid"]["protocols"]
        ):
            problems.append(
                "hybrid.condition: CWRU records of one load differ by a few rpm; hold out "
                "loads (condition: load)"
            )
        return problems

    # -- measured ----------------------------------------------------------------------------
    def read_measured(self, files, parts, channels, on_bad_record):
        if self.measured_table:
            return super().read_measured(files, parts, channels, on_bad_record)
        import pandas as pd

        from condmon.systems.bearing.cwru import cwru_rows

        ingest = cwru_rows(
            self.config["measured_dir"],
            task=self.config["cwru"]["task"],
            channels=tuple(self.bearing["channels"]),
            fs_hz=self.output_rate_hz,
            segment_length=self.segment_length,
            manifest=self.config["cwru"]["manifest"],
            on_bad_record=on_bad_record,
            segment_hop=self.bearing.get("segment_hop"),
        )
        records = pd.concat(
            [
                ingest.records.assign(status="kept", reason=""),
                ingest.excluded.assign(status="left out"),
            ],
            ignore_index=True,
        )
        return pd.DataFrame(ingest.rows), records

    # -- calibration -------------------------------------------------------------------------
    def calibrate(self, frame, variant, calibration, spectrum, channels, processes=1):
        from condmon.systems.bearing.calibration import calibrate_rig

        return calibrate_rig(self, frame, calibration, spectrum, processes=processes)

    def calibration_costs(self) -> dict:
        from condmon.systems.bearing.calibration import COSTS

        return dict(COSTS)

    def simulate_healthy(self, variant, values, speed_rpm, duration_s, seed):
        if variant != self.nominal_variant:
            raise ValueError(f"the bearing rig has the Hertz contact only, not {variant!r}")
        params = self._parameters(values, self.healthy_state, speed_rpm)
        return simulate_rig(
            params,
            rig_settings(self.numerics, duration=duration_s),
            job_rng(seed, "calibrate", float(speed_rpm)),
        )

    # -- simulation --------------------------------------------------------------------------
    def _parameters(self, values: dict, health_state: str, speed_rpm: float):
        try:
            return build_rig_parameters(
                self.model,
                health_state,
                float(speed_rpm),
                labels=self.labels,
                geometries=self.geometries,
                **values,
            )
        except ValueError as exc:  # a drawn value outside the model's domain
            raise SimulationError(f"invalid parameters: {exc}") from exc

    nominal_variant = "hertz"  # its one model variant: Hertz ball contacts

    def nominal_values(self) -> dict:
        return {**{scale: 1.0 for scale in SCALES}, **self.model}

    def sample_parameters(self, calibrated, health_state, rng, simulation) -> dict:
        # the rig model draws its own domain randomisation (bearing.randomisation) around the calibration
        return sample_values(self.bearing, calibrated, health_state, rng, self.labels)

    def simulate_sample(
        self, parameters, health_state, speed_rpm, duration_s, seed, step_refinement=1
    ):
        numerics = self.numerics
        numerics["steps_per_sensor_sample"] *= int(step_refinement)
        return simulate_rig(
            self._parameters(parameters, health_state, speed_rpm),
            rig_settings(numerics, duration=duration_s),
            np.random.default_rng(seed),
        )

    def noise_free(self, parameters: dict) -> dict:
        # the rig model adds its own sensor noise and machine background
        return {**parameters, "noise_rms": 0.0, "background": []}

    def diverging(self, parameters: dict) -> dict:
        # balls a million times stiffer: a contact mode far beyond what RK44 at this step can hold
        stiffness = parameters.get("contact_stiffness", self.model["contact_stiffness"])
        return dict(parameters, contact_stiffness=float(stiffness) * 1e6)

    def sample_load(self, speed_rpm, parameters) -> float:
        return load_of_speed(speed_rpm, self.bearing["load_speeds"])

    def defect_orders(self) -> dict:
        return feature_orders(self.bearing["geometry"])

    def defect_sidebands(self) -> dict:
        """The inner race's lines at +/- the shaft (the defect turns through the load zone), the
        ball's at +/- the cage (FTF: the cage carries the ball through it)."""
        from condmon.systems.bearing.model import geometry

        ftf = geometry(self.bearing["geometry"]).orders()["ftf"]
        return {"bpfi": 1.0, "bsf": ftf, "bsf_x2": ftf}

    def physics_baselines(self, feature_names, signals=None) -> dict:
        """The envelope rule (baselines.py), where the features hold the line ratios at BPFO,
        BPFI and 2 x BSF and every fault location is one label (the location task; not the
        ten-class or severity labels, which the rule cannot tell apart). With the measured
        `signals` it also reads the analyses `bearing.envelope_rule.line_analyses` of them
        (`baselines.line_table`)."""
        from condmon.systems.bearing.baselines import (
            LINE_OF_DEFECT,
            EnvelopeRule,
            envelope_columns,
            line_table,
        )

        columns = envelope_columns(feature_names)
        if columns is None:
            log.warning(
                "no envelope rule: the features lack the line ratios at %s",
                sorted(LINE_OF_DEFECT.values()),
            )
            return {}
        by_defect = {}
        for label in self.health_states:
            by_defect.setdefault(self.defect(label)[0], []).append(label)
        if self.healthy_state not in self.health_states or any(
            len(by_defect.get(defect, [])) != 1 for defect in LINE_OF_DEFECT
        ):
            log.warning(
                "no envelope rule: it names a fault location, and the labels %s are not "
                "one per location plus %r",
                self.health_states,
                self.healthy_state,
            )
            return {}
        labels = {line: by_defect[defect][0] for defect, line in LINE_OF_DEFECT.items()}
        analyses = list(self.bearing["envelope_rule"].get("line_analyses") or [])
        lines = None
        if signals is not None and analyses:
            channel = next(iter(columns.values()))[0].split("_", 1)[0]
            orders = {line: self.defect_orders()[line] for line in columns}
            sidebands = {line: s for line, s in self.defect_sidebands().items() if line in orders}
            statistical = self.config.get("features", {}).get("statistical", {})
            lines = line_table(signals, channel, orders, sidebands, statistical, analyses)
        return {
            "envelope_rule": EnvelopeRule(
                columns,
                labels,
                self.healthy_state,
                self.bearing["envelope_rule"]["quantile"],
                lines,
            )
        }

    def defect(self, health_state: str):
        """(defect kind, (low, high) diameter in inches) of a label."""
        return defect_of_label(health_state, self.labels)

"""A toy third system in one file: the proof that a new system is one module and one `register`.

A machine on one resilient mount, one degree of freedom: a mass m on a spring k and damper c,
driven by its rotating unbalance (force u Omega^2 cos(Omega t)). Health states: `healthy` and
`loose_mount`, a mount that has lost its preload: above a gap the spring is softer by a fraction
(a bilinear spring), so every revolution the mass runs into the soft zone and the response gains
shaft-order harmonics. One channel `acc` (the mass's acceleration, m/s^2). Its synthetic bench is
the same oscillator at hidden other values with its own noise; the calibration fits k and c.

Use it with `system: toy` and `system_modules: [tests/toy_system.py]` (tests/test_systems.py).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.signal import resample_poly

from condmon.calibrate import calibrate_on_spectra
from condmon.models.numerics import SimulationError, decimation_filter
from condmon.seeds import job_rng
from condmon.signals import make_rows
from condmon.systems import register
from condmon.systems.base import System

OVERSAMPLING = 16  # integration steps per output sample

SCHEMA = {
    "properties": {
        "toy": {
            "type": "object",
            "additionalProperties": False,
            "default": {},
            "properties": {
                "speeds_rpm": {
                    "type": "array",
                    "minItems": 1,
                    "items": {"type": "number", "exclusiveMinimum": 0},
                    "default": [600, 900],
                },
                "health_states": {
                    "type": "array",
                    "items": {"enum": ["healthy", "loose_mount"]},
                    "default": ["healthy", "loose_mount"],
                },
                "output_rate_hz": {"type": "number", "exclusiveMinimum": 0, "default": 2048},
                "segment_seconds": {"type": "number", "exclusiveMinimum": 0, "default": 0.25},
                "settle_seconds": {"type": "number", "minimum": 0, "default": 0.2},
                "mass": {"type": "number", "exclusiveMinimum": 0, "default": 5.0},
                "stiffness": {"type": "number", "exclusiveMinimum": 0, "default": 2.0e5},
                "damping": {"type": "number", "minimum": 0, "default": 60.0},
                "unbalance": {"type": "number", "minimum": 0, "default": 1.0e-3},
                "gap": {"type": "number", "minimum": 0, "default": 2.0e-6},
                "looseness": {
                    "type": "number",
                    "exclusiveMinimum": 0,
                    "exclusiveMaximum": 1,
                    "default": 0.6,
                },
                # its own per-sample draw: a Gaussian factor on each calibrated value
                "perturbation_sigma": {"type": "number", "minimum": 0, "default": 0.03},
                "bench": {
                    "type": "object",
                    "default": {
                        "stiffness": 2.3e5,
                        "damping": 45.0,
                        "noise": 0.02,
                        "records": 2,
                        "seconds": 1.0,
                        "seed": 5,
                    },
                },
            },
        },
        "calibration": {
            "properties": {
                "parameters": {
                    "default": {
                        "stiffness": {"low": 1.0e5, "high": 4.0e5, "log": True},
                        "damping": {"low": 10.0, "high": 200.0, "log": True},
                    }
                }
            }
        },
    },
}


@register
class ToySystem(System):
    name = "toy"
    schema_file = __file__
    sections = ("toy",)

    @classmethod
    def schema(cls) -> dict:
        return SCHEMA

    @property
    def toy(self) -> dict:
        return self.config["toy"]

    health_states = property(lambda self: list(self.toy["health_states"]))
    healthy_state = property(lambda self: "healthy")
    channels = property(lambda self: ["acc"])
    output_rate_hz = property(lambda self: float(self.toy["output_rate_hz"]))
    segment_length = property(
        lambda self: int(round(self.toy["segment_seconds"] * self.output_rate_hz))
    )
    speeds_rpm = property(lambda self: [float(s) for s in self.toy["speeds_rpm"]])
    settle_seconds = property(lambda self: float(self.toy["settle_seconds"]))
    calibratable = property(lambda self: ("stiffness", "damping"))

    def measured_parts(self):
        if self.measured_table:
            return []
        return [
            f"{health}_{speed:g}rpm" for health in self.health_states for speed in self.speeds_rpm
        ]

    def job_config(self, stage, variant=None):
        config = super().job_config(stage, variant)
        if stage != "bench":  # the bench's hidden values never reach calibration or simulation
            config["toy"] = {k: v for k, v in config["toy"].items() if k != "bench"}
        return config

    # -- the model: pure, parameters in, signal out --------------------------------------------
    def _run(
        self,
        values: dict,
        health_state: str,
        speed_rpm: float,
        duration_s: float,
        refinement: int = 1,
    ):
        toy = {**self.toy, **values}
        fs = self.output_rate_hz
        steps_per_sample = OVERSAMPLING * refinement
        h = 1.0 / (fs * steps_per_sample)
        omega = 2 * math.pi * speed_rpm / 60.0
        m, k, c = toy["mass"], toy["stiffness"], toy["damping"]
        soft = k * (1 - toy["looseness"]) if health_state == "loose_mount" else k
        gap, force = toy["gap"], toy["unbalance"] * omega**2
        n = int(round((self.settle_seconds + duration_s) / h))
        x = v = 0.0
        acc = np.empty(n)
        for i in range(n):  # semi-implicit Euler: cheap, and it blows up when k outgrows the step
            spring = k * x if x <= gap else k * gap + soft * (x - gap)
            a = (force * math.cos(omega * i * h) - c * v - spring) / m
            v += h * a
            x += h * v
            acc[i] = a
            if not math.isfinite(x) or abs(x) > 1.0:
                raise SimulationError(
                    f"toy oscillator diverged at t = {i * h:.4f} s (x = {x:.3g} m)"
                )
        # the sensors at the integration rate, low-passed and decimated to the output rate
        out = resample_poly(acc, 1, steps_per_sample, window=decimation_filter(steps_per_sample))
        settle = int(round(self.settle_seconds * fs))
        return out[settle : settle + int(round(duration_s * fs))]

    # -- the interface ---------------------------------------------------------------------------
    def measured_part_rows(self, part):
        health, speed = part.rsplit("_", 1)
        speed = float(speed.removesuffix("rpm"))
        bench = self.toy["bench"]
        rng = job_rng(bench["seed"], "toy bench", health, speed)
        rows = []
        for r in range(bench["records"]):
            signal = self._run(
                {"stiffness": bench["stiffness"], "damping": bench["damping"]},
                health,
                speed,
                bench["seconds"],
            )
            signal = signal + rng.normal(0.0, bench["noise"], size=signal.shape)
            rows += make_rows(
                f"toy-{health}-{speed:g}rpm-r{r}",
                "virtual_bench",
                health,
                speed,
                0.0,
                self.output_rate_hz,
                {"acc": signal},
                segment_length=self.segment_length,
            )
        return rows

    def calibrate(self, frame, variant, calibration, spectrum, channels, processes=1):
        return calibrate_on_spectra(
            self, frame, calibration, spectrum, channels, nominal=self.toy, processes=processes
        )

    def nominal_values(self):
        return {"stiffness": self.toy["stiffness"], "damping": self.toy["damping"]}

    def sample_parameters(self, calibrated, health_state, rng, simulation):
        sigma = self.toy["perturbation_sigma"]
        return {
            name: value * float(rng.normal(1.0, sigma))
            for name, value in sorted(calibrated["parameters"].items())
        }

    def simulate_sample(
        self, parameters, health_state, speed_rpm, duration_s, seed, step_refinement=1
    ):
        values = {k: v for k, v in parameters.items() if k in ("stiffness", "damping")}
        return {"acc": self._run(values, health_state, speed_rpm, duration_s, step_refinement)}

    def diverging(self, parameters):
        return dict(parameters, stiffness=self.toy["stiffness"] * 1e8)

"""Bridge between config sections and the pure gear drivetrain model in `models/`."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from condmon.models.gear_drivetrain import GearDrivetrainParameters, GearGeometry, ShaftLayout, SimulationSettings
from condmon.models.mesh_force import random_pitch_errors

# Parameters that calibration may tune (the contact law is the categorical one).
CALIBRATABLE = ("mesh_stiffness", "restitution", "contact_exponent", "mesh_damping_ratio", "bushing_stiffness",
                "bushing_damping", "bushing_axial_stiffness", "transmission_error")
_FIELDS = {f.name for f in dataclasses.fields(GearDrivetrainParameters)}
_SECTIONS = ("geometry", "variability")  # model keys that are not parameters themselves


def build_parameters(model: dict, **overrides) -> GearDrivetrainParameters:
    """GearDrivetrainParameters from the `model` config section plus overrides.

    `model` holds `geometry` (dict), the shaft layouts (dicts), `variability` (drawn per sample,
    `sample_effects`) and any scalar or list field of GearDrivetrainParameters."""
    values = {k: v for k, v in model.items() if k not in _SECTIONS}
    values.update(overrides)
    unknown = sorted(set(values) - _FIELDS)
    if unknown:
        raise ValueError(f"unknown gear model parameters {unknown}")
    for key in ("input_shaft", "output_shaft"):
        if isinstance(values.get(key), dict):
            values[key] = ShaftLayout(**{k: tuple(v) if isinstance(v, list) else v for k, v in values[key].items()})
    if isinstance(values.get("sensors"), dict):
        values["sensors"] = tuple(values["sensors"].items())
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return GearDrivetrainParameters(geometry=GearGeometry(**model.get("geometry", {})), **values)


def simulation_settings(numerics: dict, duration: float) -> SimulationSettings:
    return SimulationSettings(duration=duration, **numerics)


def perturb(values: dict, names, sigma: float, rng: np.random.Generator) -> dict:
    """Multiply each named parameter by a Gaussian factor N(1, sigma) (CFRP study: +/-3 %).
    Factors are clipped to [1 - 4 sigma, 1 + 4 sigma]; the restitution stays at most 1."""
    out = dict(values)
    for name in names:
        factor = float(np.clip(rng.normal(1.0, sigma), 1.0 - 4 * sigma, 1.0 + 4 * sigma))
        out[name] = values[name] * factor
        if name == "restitution":
            out[name] = min(out[name], 1.0)
    return out


def sample_effects(variability: dict, geometry: GearGeometry, rng: np.random.Generator) -> dict:
    """One drivetrain's manufacturing and operating scatter (`model.variability`): run-out of
    each shaft (amplitude uniform in [0.5, 1.5] x `runout`, random phase), Gaussian single pitch
    errors of every tooth, and slow sinusoidal speed and load fluctuations (amplitude uniform
    up to the configured one, frequency uniform in its range, random phase)."""
    def uniform(low, high):
        return float(rng.uniform(low, high))

    return {
        "runout_pinion": uniform(0.5, 1.5) * variability["runout"],
        "runout_gear": uniform(0.5, 1.5) * variability["runout"],
        "runout_phase_pinion": uniform(0.0, 2 * math.pi),
        "runout_phase_gear": uniform(0.0, 2 * math.pi),
        "pitch_errors_pinion": tuple(random_pitch_errors(rng, geometry.teeth_pinion, variability["pitch_error"])),
        "pitch_errors_gear": tuple(random_pitch_errors(rng, geometry.teeth_gear, variability["pitch_error"])),
        "speed_fluctuation": uniform(0.0, variability["speed_fluctuation"]),
        "speed_fluctuation_hz": uniform(*variability["speed_fluctuation_hz"]),
        "speed_fluctuation_phase": uniform(0.0, 2 * math.pi),
        "load_fluctuation": uniform(0.0, variability["load_fluctuation"]),
        "load_fluctuation_hz": uniform(*variability["load_fluctuation_hz"]),
        "load_fluctuation_phase": uniform(0.0, 2 * math.pi),
    }

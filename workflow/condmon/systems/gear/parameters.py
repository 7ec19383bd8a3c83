"""Bridge between config sections and the pure gear drivetrain model in `models/`."""
from __future__ import annotations

import dataclasses

import numpy as np

from condmon.models.gear_drivetrain import GearDrivetrainParameters, GearGeometry, SimulationSettings

# Parameters that calibration may tune (the contact law is the categorical one).
CALIBRATABLE = ("mesh_stiffness", "restitution", "contact_exponent", "bushing_stiffness",
                "bushing_damping", "housing_stiffness", "housing_damping", "approach_velocity",
                "transmission_error")
_FIELDS = {f.name for f in dataclasses.fields(GearDrivetrainParameters)}


def build_parameters(model: dict, **overrides) -> GearDrivetrainParameters:
    """GearDrivetrainParameters from the `model` config section plus overrides.

    `model` holds `geometry` (dict) and any scalar field of GearDrivetrainParameters.
    """
    values = {k: v for k, v in model.items() if k != "geometry"}
    values.update(overrides)
    unknown = sorted(set(values) - _FIELDS)
    if unknown:
        raise ValueError(f"unknown gear model parameters {unknown}")
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

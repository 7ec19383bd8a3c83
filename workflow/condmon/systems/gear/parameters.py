"""Bridge between config sections and the pure gear drivetrain model in `models/`."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from condmon.models.gear.drivetrain import (
    GearDrivetrainParameters,
    GearGeometry,
    GearStage,
    ShaftLayout,
    SimulationSettings,
    stage_parameters,
)
from condmon.models.gear.errors import pair_errors
from condmon.models.gear.mesh_force import (
    deflection_of,
    iso6336_deflections,
    static_mesh_force,
    stiffness_for_deflection,
)

# Parameters that calibration may tune (the contact law is the categorical one).
CALIBRATABLE = (
    "mesh_stiffness",
    "restitution",
    "contact_exponent",
    "mesh_damping_ratio",
    "bushing_stiffness",
    "bushing_damping",
    "bushing_axial_stiffness",
    "transmission_error",
)
_FIELDS = {f.name for f in dataclasses.fields(GearDrivetrainParameters)}
_SECTIONS = (
    "geometry",
    "variability",
    "gear_errors",
    "fault_severity",
    "mesh_compliance",
    "stages",
    "faulty_stages",
)  # drawn per sample or built apart, not parameters


def build_parameters(model: dict, **overrides) -> GearDrivetrainParameters:
    """GearDrivetrainParameters from the `model` config section plus overrides.

    `model` holds `geometry` (dict), the shaft layouts (dicts), `variability` (drawn per sample,
    `sample_effects`), the further pairs of a train (`stages`) and any scalar or list field of
    GearDrivetrainParameters. A further pair's mesh stiffness scales with the first pair's (what
    calibration or a bench's truth set: the material and contact the pairs share)."""
    values = {k: v for k, v in model.items() if k not in _SECTIONS}
    geometry = dict(model.get("geometry", {}), **overrides.pop("geometry", {}))
    values.update(overrides)
    unknown = sorted(set(values) - _FIELDS)
    if unknown:
        raise ValueError(f"unknown gear model parameters {unknown}")
    for key in ("input_shaft", "output_shaft"):
        if isinstance(values.get(key), dict):
            values[key] = _layout(values[key])
    if isinstance(values.get("sensors"), dict):
        values["sensors"] = tuple(_sensor(name, spec) for name, spec in values["sensors"].items())
    if model.get("stages") and "stages" not in values:
        scale = float(values.get("mesh_stiffness", model["mesh_stiffness"])) / float(
            model["mesh_stiffness"]
        )
        values["stages"] = tuple(_stage(spec, geometry, scale) for spec in model["stages"])
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in values.items()}
    return GearDrivetrainParameters(geometry=GearGeometry(**geometry), **values)


def _layout(spec: dict) -> ShaftLayout:
    return ShaftLayout(**{k: tuple(v) if isinstance(v, list) else v for k, v in spec.items()})


def _stage(spec: dict, first_geometry: dict, stiffness_scale: float) -> GearStage:
    """One `model.stages` entry: its geometry over the first pair's (material, angles and any key
    it does not give), its shaft, masses and mesh stiffness (times `stiffness_scale`)."""
    return GearStage(
        geometry=GearGeometry(**dict(first_geometry, **spec["geometry"])),
        shaft=_layout(spec["shaft"]),
        pinion_mass=float(spec["pinion_mass"]),
        pinion_inertia=float(spec["pinion_inertia"]),
        gear_mass=float(spec["gear_mass"]),
        gear_inertia=float(spec["gear_inertia"]),
        mesh_stiffness=float(spec["mesh_stiffness"]) * stiffness_scale,
    )


def _sensor(name: str, spec) -> tuple:
    """The model's (name, housing[, directions]) of one `model.sensors` entry: a housing (x and
    y) or {housing, directions}."""
    if isinstance(spec, dict):
        return (name, int(spec["housing"]), tuple(spec.get("directions", ("x", "y"))))
    return (name, int(spec))


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


# the parameters a drawn mesh compliance (model.mesh_compliance) sets, so never calibrates
COMPLIANCE_PARAMETERS = ("mesh_stiffness", "contact_exponent")


# `model.mesh_compliance.deflection: auto`: real meshes about ISO 6336-1's estimate, from this
# many times its stiffness at 1 um to this many times softer than its light-load value
ISO_STIFFER, ISO_SOFTER = 1.5, 1.25


def deflection_range(compliance: dict, params: GearDrivetrainParameters) -> tuple[float, float]:
    """The static deflections (m) a drawn mesh compliance spans for the first pair of `params` under
    its own torque: `compliance["deflection"]`, or with `auto` those ISO 6336-1 allows
    (`mesh_force.iso6336_deflections`): every mesh from `ISO_STIFFER` x the standard's stiffness
    at 1 um to `ISO_SOFTER` x softer than its light-load value, at every drawn contact exponent.
    The default rig's 10 N m: 0.39-1.32 um; a gearbox at 133 N/mm: 0.37-1.25 x the standard's."""
    if compliance["deflection"] not in ("auto", "calibrated"):
        low, high = compliance["deflection"]
        return float(low), float(high)
    first_pair = stage_parameters(params)[0]
    linear, light = iso6336_deflections(first_pair)
    force = static_mesh_force(first_pair)
    stiffest = ISO_STIFFER * force / linear  # N/m, a linear mesh's stiffness
    softest = force / (ISO_SOFTER * light)
    deflections = [
        deflection_of(force, stiffness, exponent)
        for stiffness in (stiffest, softest)
        for exponent in compliance["contact_exponent"]
    ]
    return min(deflections), max(deflections)


# `model.mesh_compliance.deflection: calibrated`: the calibration's cost over the first pair's
# static deflection on a log grid of the standard's range, at the drawn contact exponents (each
# grid point the lowest cost over them); the deflections within PROFILE_TOLERANCE above the lowest
# cost are kept, with a grid step either side. The cost of one candidate varies 30-70 % with the
# simulation's seed, its profile far less (the same seed at every point): on the two-stage bench
# 3.2 um against 4.5 um cost 21-53 % more at 4.5 on each of three seeds
# (docs/experiments/2026-12-07-mesh-deflection-profile.md).
PROFILE_DEFLECTIONS, PROFILE_EXPONENTS, PROFILE_TOLERANCE = 9, 3, 0.1


def deflection_profile(cost, compliance: dict, params: GearDrivetrainParameters) -> dict:
    """The calibration's cost over the first pair's static deflection under its torque, for
    `model.mesh_compliance.deflection: calibrated`: on a log grid of the range ISO 6336-1 allows
    (`deflection_range` with `auto`), the lowest cost over the drawn contact exponents, each with
    the `mesh_stiffness` that gives the deflection; `cost(values)`: the cost of the calibrated
    parameters with these `values` changed. Returns {"deflection": grid (m), "cost": profile,
    "range": the deflections kept, `profile_range`}."""
    low, high = deflection_range(dict(compliance, deflection="auto"), params)
    grid = np.geomspace(low, high, PROFILE_DEFLECTIONS)
    exponents = np.linspace(*compliance["contact_exponent"], PROFILE_EXPONENTS)
    first_pair = stage_parameters(params)[0]
    profile = np.array(
        [
            min(
                cost(
                    {
                        "mesh_stiffness": stiffness_for_deflection(first_pair, d, n),
                        "contact_exponent": float(n),
                    }
                )
                for n in exponents
            )
            for d in grid
        ]
    )
    return {
        "deflection": grid.tolist(),
        "cost": profile.tolist(),
        "range": list(profile_range(grid, profile)),
    }


def profile_range(grid, profile, tolerance: float = PROFILE_TOLERANCE) -> tuple[float, float]:
    """(low, high): the grid points whose cost lies within `tolerance` (a share) above the lowest,
    widened by one grid step on either side (the grid's resolution), within the grid."""
    profile = np.asarray(profile, dtype=float)
    kept = np.flatnonzero(profile <= (1.0 + tolerance) * profile.min())
    first, last = max(int(kept[0]) - 1, 0), min(int(kept[-1]) + 1, len(grid) - 1)
    return float(grid[first]), float(grid[last])


def draw_mesh_compliance(
    compliance: dict,
    params: GearDrivetrainParameters,
    rng: np.random.Generator,
    calibrated_range=None,
) -> dict:
    """One drivetrain's mesh compliance (`model.mesh_compliance`): its contact exponent uniform in
    `contact_exponent`, its first pair's static deflection under the rig's load log-uniform in
    `deflection` (m, `deflection_range`), and the `mesh_stiffness` that gives that deflection
    (`stiffness_for_deflection`; a train's further pairs scale with it, `build_parameters`).

    Why drawn, not calibrated: a fault's change of the transmission error scales with the mesh's
    static deflection (a pit deeper than the deflection leaves the contact, the load moves to the
    other pairs), while the healthy spectra at a light load hardly depend on it: calibrated on
    four draws of the default bench (true deflection 0.45 um), CMA-ES put it at 1.19, 0.31, 0.48
    and 0.23 um at costs within 0.22-0.26, and the simulated faults grew or shrank with it. The
    standard's estimate (ISO 6336-1's mesh stiffness, with and without its light-load reduction)
    bounds the deflection better than the healthy records do, so every deflection it allows is
    simulated. At a gearbox's load they do: `calibrated` draws within the range the calibration's
    profile keeps (`calibrated_range`, `deflection_profile`)."""
    exponent = float(rng.uniform(*compliance["contact_exponent"]))
    if compliance["deflection"] == "calibrated":
        if calibrated_range is None:
            raise ValueError(
                "model.mesh_compliance.deflection: calibrated, but the calibration holds no "
                "mesh_deflection (run the calibration with this config)"
            )
        deflections = calibrated_range
    else:
        deflections = deflection_range(compliance, params)
    low, high = (np.log(value) for value in deflections)
    deflection = float(np.exp(rng.uniform(low, high)))
    # the first pair under its own torque (a train's output torque through the later ratios)
    first_pair = stage_parameters(params)[0]
    return {
        "contact_exponent": exponent,
        "mesh_stiffness": stiffness_for_deflection(first_pair, deflection, exponent),
    }


def sample_effects(
    model: dict, geometry: GearGeometry, rng: np.random.Generator, stages: tuple = ()
) -> dict:
    """One drivetrain's manufacturing and operating scatter, drawn per sample:
    - its gears (`model.gear_errors`): an ISO 1328-1 grade uniform in `grade`, deviations a share
      of its tolerances uniform in `deviation_share`, a misalignment uniform in `misalignment`
      (`condmon.models.gear.errors.draw_gear_errors`: pitch pattern, eccentricity, profile and helix slopes);
    - slow sinusoidal speed and load fluctuations (`model.variability`: amplitude uniform up to
      the configured one, frequency uniform in its range, random phase);
    - the severity of its faults (`model.fault_severity`: the wear depth, the pits' depth, pitted
      area, how many teeth pitted and how far beyond the contact-fatigue band, the spall's depth
      and its width (at a uniform place across the face), the root crack's depth and the share of
      a broken tooth's profile that is gone, each uniform in its range) and the damaged surfaces'
      seed;
    - the mesh phase the run starts at, uniform over the gear pair's full cycle (a measurement
      starts at any shaft angle: where the damaged tooth passes within a segment varies);
    - a train's further pairs (`stages`, GearStage): each its own gears of the same grade and
      share and its own start phase, and the pair a gear fault sits on, uniform over
      `model.faulty_stages` (drawn after the first pair's, whose draws stay as a one-pair
      drivetrain's)."""

    def uniform(low, high):
        return float(rng.uniform(low, high))

    errors, variability, severity = (
        model["gear_errors"],
        model["variability"],
        model["fault_severity"],
    )
    grade, share = uniform(*errors["grade"]), uniform(*errors["deviation_share"])

    def misalignment():
        return uniform(*errors["misalignment"])

    fields = pair_errors(rng, grade, share, geometry, misalignment)
    effects = dict(
        fields,
        speed_fluctuation=uniform(0.0, variability["speed_fluctuation"]),
        speed_fluctuation_hz=uniform(*variability["speed_fluctuation_hz"]),
        speed_fluctuation_phase=uniform(0.0, 2 * math.pi),
        load_fluctuation=uniform(0.0, variability["load_fluctuation"]),
        load_fluctuation_hz=uniform(*variability["load_fluctuation_hz"]),
        load_fluctuation_phase=uniform(0.0, 2 * math.pi),
        wear_depth=uniform(*severity["wear_depth"]),
        pit_depth=uniform(*severity["pit_depth"]),
        pitted_area=uniform(*severity["pitted_area"]),
        spall_depth=uniform(*severity["spall_depth"]),
        crack_depth=uniform(*severity["crack_depth"]),
        wear_seed=int(rng.integers(2**31)),
        # the record starts at any shaft angle of both gears (drawn last: the draws above stay as they were)
        start_mesh_phase=uniform(0.0, math.lcm(geometry.teeth_pinion, geometry.teeth_gear)),
        missing_share=uniform(*severity["missing_share"]),
        spall_face=_spall_face(
            uniform(*severity["spall_width"]), rng
        ),  # drawn last, as the line above
        surface_fault_teeth=int(
            rng.integers(severity["pitted_teeth"][0], severity["pitted_teeth"][1] + 1)
        ),
        pitting_growth=uniform(*severity["pitting_growth"]),
    )
    if stages:
        effects["stages"] = tuple(
            dataclasses.replace(
                stage,
                **pair_errors(rng, grade, share, stage.geometry, misalignment),
                start_mesh_phase=uniform(
                    0.0, math.lcm(stage.geometry.teeth_pinion, stage.geometry.teeth_gear)
                ),
            )
            for stage in stages
        )
        effects["faulty_stage"] = int(rng.choice(model["faulty_stages"]))
    return effects


def measured_fluctuation_fields(measured: dict, speed_rpm: float, seed: int) -> dict:
    """The speed fluctuation of one sample when the calibration read it from the healthy records
    (`model.variability.speed_fluctuation_source: healthy_records`; `measured`: {speed: estimate
    or None}, `systems/gear/fluctuation.py`): amplitude and frequency uniform over the range the
    calibration segments gave at this speed, or at the nearest speed that has an estimate, from a
    stream of its own (the run seed's), so twins' draws stay aligned; its phase stays the sample's
    draw. {} when no speed has one: the configured ranges stand (the calibration warned)."""
    known = {float(speed): estimate for speed, estimate in measured.items() if estimate}
    if not known:
        return {}
    estimate = known[min(known, key=lambda speed: abs(speed - speed_rpm))]
    rng = np.random.default_rng([int(seed), 0x5FEED])
    return {
        "speed_fluctuation": float(rng.uniform(*estimate["amplitude"])),
        "speed_fluctuation_hz": float(rng.uniform(*estimate["frequency_hz"])),
    }


# Per-state calibration (calibration.per_state): the severities each fault state's model tunes,
# by model variant (a surface fault's form is its variant; the other states have one, their name).
STATE_SEVERITY = {
    "wear": ("wear_depth",),
    "pitting": ("pit_depth", "pitted_area"),
    "missing_tooth": ("missing_share",),
    "spall": ("spall_depth", "spall_width"),
    "root_crack": ("crack_depth",),
}
SHARES = ("pitted_area", "missing_share", "spall_width", "crack_depth")  # fractions: at most 1


def state_variants(state: str, surface_fault_model: str) -> list[str]:
    """The model variants per-state calibration searches for `state` (ValueError: none)."""
    if state == "surface_fault":
        if surface_fault_model != "pitting":
            raise ValueError(
                f"calibration.per_state: surface_fault_model {surface_fault_model} removes no "
                "material; per-state calibration tunes the depths of pitting"
            )
        return ["pitting"]
    if state not in STATE_SEVERITY:
        raise ValueError(
            f"calibration.per_state.states: {state!r} has no severity to tune; the gear model "
            f"tunes surface_fault, {', '.join(k for k in STATE_SEVERITY if k != 'pitting')}"
        )
    return [state]


def state_model_fields(state_model: dict, drawn: dict, seed: int) -> dict:
    """The fields a calibrated fault state's model sets on one sample (`state_model`: variant,
    parameters, spread; `drawn`: the sample's `sample_effects`): each severity of the variant
    times a factor uniform in 1 +/- spread, from a stream of its own (the run seed's), so twins'
    draws stay aligned; a spall's width about the centre the sample drew; the surface fault's form."""
    rng = np.random.default_rng([int(seed), 0x57A7E])
    spread = float(state_model.get("spread", 0.0))
    variant = state_model["variant"]
    fields = {"surface_fault_model": variant} if variant == "pitting" else {}
    for name in STATE_SEVERITY[variant]:
        value = float(state_model["parameters"][name]) * float(
            rng.uniform(1.0 - spread, 1.0 + spread)
        )
        value = min(value, 1.0) if name in SHARES else value
        if name == "spall_width":
            centre = 0.5 * (drawn["spall_face"][0] + drawn["spall_face"][1])
            start = float(np.clip(centre - value / 2, 0.0, 1.0 - value))
            fields["spall_face"] = (start, start + value)
        else:
            fields[name] = value
    return fields


def _spall_face(width: float, rng: np.random.Generator) -> tuple[float, float]:
    """[start, end] of a spall `width` wide (share of the face width) at a uniform place across it."""
    start = float(rng.uniform(0.0, 1.0 - width))
    return start, start + width

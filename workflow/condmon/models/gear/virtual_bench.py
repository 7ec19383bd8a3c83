"""The virtual bench: a synthetic stand-in for a measured helical-gear rig.

It differs from the calibrated model in *form*, not only in its hidden parameters, so the pipeline
meets a real gap between simulation and "measurement" (ARCHITECTURE.md lists the effects; the
report labels them):
- housings are rigid blocks on four feet (rocking modes) with their own mount stiffness, where
  the model has point masses; the shafts may be flexible (`shaft_model`);
- rolling bearings with their own tones: a radial force at each bearing's defect-free passing
  orders (`bearing_orders` x its shaft frequency);
- the motor's torque ripple at twice the line frequency;
- its own gears: one pair of ISO 1328-1 accuracy `gear_grade` (`errors.draw_gear_errors`, drawn
  once from the bench seed: the same physical gears in every record) with its own misalignment;
- its own damage (`faults`): a surface fault as pitting (pits around the pitch line), a missing
  tooth as a tooth broken off above a height, a spall as a crater with a rough floor, built here as
  flank geometry; the model's fault code is never called for a state that has a bench form;
- slow speed and load fluctuations of its own amplitude and frequency; every record starts at its
  own angle of both shafts;
- coloured (low-frequency weighted) sensor noise on top of white noise.
Its records are always labelled `virtual_bench`, never `measured`.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from condmon.models.gear.drivetrain import (
    GearDrivetrainParameters,
    PeriodicLoad,
    SimulationSettings,
    shaft_speeds,
    simulate,
    stage_parameters,
)
from condmon.models.gear.errors import FlankMap, pair_errors
from condmon.models.gear.mesh_force import mesh_phase_at


@dataclass(frozen=True)
class BenchForm:
    """What the bench has that the model lacks (see the module docstring); amplitudes in SI."""

    housing_model: str = "block"
    shaft_model: str = "rigid"
    housing_stiffness: tuple = (5.0e7, 1.5e8, 8.0e7)
    sensor_noise: float = 0.001  # white, m/s^2 rms
    coloured_noise: float = 0.002  # m/s^2 rms
    gear_grade: float = 5.0  # ISO 1328-1 accuracy grade of both gears
    gear_deviation_share: float = 0.8  # their deviations as a share of the grade's tolerances
    misalignment: float = 8.0e-6  # mesh misalignment across the face, m
    speed_fluctuation: float = 0.002
    speed_fluctuation_hz: float = 1.5
    load_fluctuation: float = 0.05
    load_fluctuation_hz: float = 0.7
    bearing_tone_force: float = 3.0  # N per bearing and order
    bearing_orders: tuple = (3.585, 5.415)
    line_frequency_hz: float = 50.0
    motor_ripple: float = 0.1  # N m at 2 x line frequency


def bench_gears(form: BenchForm, geometry, seed: int, stages: tuple = ()) -> dict:
    """The bench's own gears: each pair's pinion and gear of ISO grade `form.gear_grade`, fixed by
    `seed` (the same physical gears in every record), as GearDrivetrainParameters fields (a train's
    further pairs, `stages`, with theirs in `stages`); perfect gears (no fields) with
    `gear_deviation_share` 0."""
    if not form.gear_deviation_share and not form.misalignment:
        return {}
    rng = np.random.default_rng([seed, 0xBE7C4])

    def pair(g):
        return pair_errors(
            rng, form.gear_grade, form.gear_deviation_share, g, lambda: form.misalignment
        )

    fields = pair(geometry)
    if stages:
        fields["stages"] = tuple(
            dataclasses.replace(stage, **pair(stage.geometry)) for stage in stages
        )
    return fields


# The bench's own fault forms: health state -> form; each form's keys (`virtual_bench.faults`).
FAULT_FORMS = {
    "pitting": ("teeth", "pit_depth", "pitted_area"),
    "broken_tooth": ("broken_height",),
    "spall": ("depth", "profile", "face"),
}


def pitting_map(
    rng: np.random.Generator,
    pit_depth: float,
    pitted_area: float,
    rows: int = 41,
    columns: int = 21,
) -> FlankMap:
    """Pitting of one flank: round pits, each up to `pit_depth` deep, around the pitch line (roll
    fraction 0.3-0.6, where rolling contact fatigue starts) until `pitted_area` of that band is
    pitted."""
    roll, face = np.meshgrid(np.linspace(0, 1, rows), np.linspace(0, 1, columns), indexing="ij")
    removed = np.zeros_like(roll)
    band = (roll >= 0.3) & (roll <= 0.6)
    for _ in range(200):
        if (removed[band] > 0).mean() >= pitted_area:
            break
        centre = (rng.uniform(0.3, 0.6), rng.uniform(0.0, 1.0))
        radius = rng.uniform(0.03, 0.08)
        inside = ((roll - centre[0]) ** 2 + ((face - centre[1]) * 0.5) ** 2) < radius**2
        removed[inside] = np.maximum(removed[inside], pit_depth * rng.uniform(0.5, 1.0))
    return FlankMap.of(removed)


def broken_tooth_map(broken_height: float, rows: int = 41) -> FlankMap:
    """A tooth broken off above `1 - broken_height` of its active profile (towards the tip): the
    part that is gone never touches (1 mm of material removed)."""
    roll = np.linspace(0.0, 1.0, rows)[:, None]
    return FlankMap.of(np.where(roll >= 1.0 - broken_height, 1.0e-3, 0.0))


def spall_map(
    rng: np.random.Generator, depth: float, profile, face, rows: int = 41, columns: int = 21
) -> FlankMap:
    """A spall of one flank: the crater pits leave when they join and flake off, over `profile` x
    `face` ([start, end] fractions of the active profile and of the face width), its floor rough:
    0.7-1.0 of `depth` below the flank, cell by cell."""
    roll, across = np.meshgrid(np.linspace(0, 1, rows), np.linspace(0, 1, columns), indexing="ij")
    inside = (roll >= profile[0]) & (roll <= profile[1]) & (across >= face[0]) & (across <= face[1])
    return FlankMap.of(np.where(inside, depth * rng.uniform(0.7, 1.0, roll.shape), 0.0))


def bench_fault(
    health_state: str, faults: dict, teeth: int, faulty_tooth: int, rng: np.random.Generator
):
    """(the health state the model runs, per-tooth flank maps) of the bench's own form of
    `health_state` (`faults`: health state -> {form, its keys}); a state without a bench form
    runs the model's own fault (the report says so)."""
    spec = faults.get(health_state)
    if spec is None:
        return health_state, ()
    form = spec["form"]
    if form not in FAULT_FORMS:
        raise ValueError(
            f"virtual_bench.faults.{health_state}.form: unknown form {form!r}; "
            f"choose one of {list(FAULT_FORMS)}"
        )
    maps = [None] * teeth
    if form == "pitting":
        for k in range(int(spec["teeth"])):
            maps[(faulty_tooth + k) % teeth] = pitting_map(
                rng, spec["pit_depth"], spec["pitted_area"]
            )
    elif form == "spall":
        maps[faulty_tooth % teeth] = spall_map(rng, spec["depth"], spec["profile"], spec["face"])
    else:
        maps[faulty_tooth % teeth] = broken_tooth_map(spec["broken_height"])
    return "healthy", tuple(maps)


def bench_record(
    true_params: GearDrivetrainParameters,
    form: BenchForm,
    settings: SimulationSettings,
    rng: np.random.Generator,
    gears: dict,
    fault_maps: tuple = (),
) -> tuple[dict[str, np.ndarray], float]:
    """One acquisition of the bench at `true_params` (speed and health state the model runs
    included) with its own gears (`bench_gears`) and damage (`fault_maps`, `bench_fault`): random
    phases of the fluctuations and bearing tones, a random start angle of the shafts, then white
    plus coloured sensor noise. (signals, the mesh phase of the pair `faulty_stage` names at the
    record's first sample: which teeth stand where, the truth a located tooth is scored against)."""
    g = true_params.geometry
    shaft_hz = true_params.speed_rpm / 60.0
    # two housings a shaft
    shaft_frequencies = [speed for speed in shaft_speeds(true_params, shaft_hz) for _ in range(2)]
    loads = (
        [
            PeriodicLoad(
                ("motor", None),
                form.motor_ripple,
                2 * form.line_frequency_hz,
                float(rng.uniform(0, 2 * math.pi)),
            )
        ]
        if form.motor_ripple
        else []
    )
    if form.bearing_tone_force:
        for housing, frequency in enumerate(shaft_frequencies):
            for order in form.bearing_orders:
                loads.append(
                    PeriodicLoad(
                        ("housing", housing),
                        form.bearing_tone_force,
                        order * frequency,
                        float(rng.uniform(0, 2 * math.pi)),
                    )
                )
    params = true_params.replace(
        housing_model=form.housing_model,
        shaft_model=form.shaft_model,
        housing_stiffness=tuple(form.housing_stiffness),
        speed_fluctuation=form.speed_fluctuation,
        speed_fluctuation_hz=form.speed_fluctuation_hz,
        speed_fluctuation_phase=float(rng.uniform(0, 2 * math.pi)),
        load_fluctuation=form.load_fluctuation,
        load_fluctuation_hz=form.load_fluctuation_hz,
        load_fluctuation_phase=float(rng.uniform(0, 2 * math.pi)),
        # an acquisition starts at any angle of both shafts: which gear teeth the damaged tooth
        # meets within a segment differs from record to record, as on a real rig
        start_mesh_phase=float(rng.uniform(0, math.lcm(g.teeth_pinion, g.teeth_gear))),
        **dict(gears, damage_maps_pinion=tuple(fault_maps)),
    )
    if params.stages:  # each further pair at its own start angle too
        params = params.replace(
            stages=tuple(
                dataclasses.replace(
                    stage,
                    start_mesh_phase=float(
                        rng.uniform(
                            0, math.lcm(stage.geometry.teeth_pinion, stage.geometry.teeth_gear)
                        )
                    ),
                )
                for stage in params.stages
            )
        )
    signals = simulate(params, settings, extra_loads=loads)
    return (
        {name: signal + sensor_noise(len(signal), form, rng) for name, signal in signals.items()},
        mesh_phase_at(stage_parameters(params)[params.faulty_stage], settings.settle_time),
    )


def sensor_noise(n: int, form: BenchForm, rng: np.random.Generator) -> np.ndarray:
    """White noise of rms `sensor_noise` plus coloured noise of rms `coloured_noise`: white noise
    through a first-order low-pass (pole 0.95), which weights low frequencies like the drift and
    structure-borne background of a real accelerometer chain."""
    noise = rng.normal(0.0, form.sensor_noise, n) if form.sensor_noise else np.zeros(n)
    if form.coloured_noise:
        coloured = lfilter([1.0], [1.0, -0.95], rng.normal(0.0, 1.0, n))
        noise += coloured / coloured.std() * form.coloured_noise
    return noise

"""The virtual bench: a synthetic stand-in for a measured helical-gear rig.

It differs from the calibrated model in *form*, not only in its hidden parameters, so the pipeline
meets a real gap between simulation and "measurement" (ARCHITECTURE.md lists the effects; the
report labels them):
- housings are rigid blocks on four feet (rocking modes) with their own mount stiffness, where
  the model has point masses; the shafts may be flexible (`shaft_model`);
- rolling bearings with their own tones: a radial force at each bearing's defect-free passing
  orders (`bearing_orders` x its shaft frequency);
- the motor's torque ripple at twice the line frequency;
- pitch errors of its own gears: a fixed pattern (drawn once from the bench seed) with a
  cumulative, once-per-revolution part, where the model draws independent errors per sample;
- run-out, slow speed and load fluctuations of its own amplitude and frequency;
- coloured (low-frequency weighted) sensor noise on top of white noise.
Its records are always labelled `virtual_bench`, never `measured`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from condmon.models.gear_drivetrain import GearDrivetrainParameters, PeriodicLoad, SimulationSettings, simulate

EFFECTS = {
    "housing_model": "housings as rigid blocks on four feet (rocking modes)",
    "shaft_model": "flexible (Timoshenko) shafts",
    "housing_stiffness": "housing mounts of their own stiffness",
    "bearing_tone_force": "rolling-bearing tones at the bearings' passing orders",
    "motor_ripple": "motor torque ripple at twice the line frequency",
    "cumulative_pitch_error": "a fixed pitch-error pattern with a once-per-revolution part",
    "coloured_noise": "coloured (low-frequency weighted) sensor noise",
}


@dataclass(frozen=True)
class BenchForm:
    """What the bench has that the model lacks (see the module docstring); amplitudes in SI."""
    housing_model: str = "block"
    shaft_model: str = "rigid"
    housing_stiffness: tuple = (5.0e7, 1.5e8, 8.0e7)
    sensor_noise: float = 0.001          # white, m/s^2 rms
    coloured_noise: float = 0.002        # m/s^2 rms
    runout: float = 1.5e-6
    pitch_error: float = 5.0e-8          # single pitch deviations, rms
    cumulative_pitch_error: float = 3.0e-7  # once-per-revolution amplitude
    speed_fluctuation: float = 0.002
    speed_fluctuation_hz: float = 1.5
    load_fluctuation: float = 0.05
    load_fluctuation_hz: float = 0.7
    bearing_tone_force: float = 3.0      # N per bearing and order
    bearing_orders: tuple = (3.585, 5.415)
    line_frequency_hz: float = 50.0
    motor_ripple: float = 0.1            # N m at 2 x line frequency

    def active_effects(self) -> list[str]:
        """Descriptions of the effects this bench switches on (the report lists them)."""
        on = []
        for key, text in EFFECTS.items():
            value = getattr(self, key)
            if (key == "housing_model" and value == "block") or (key == "shaft_model" and value == "flexible") \
                    or (key == "housing_stiffness") or (isinstance(value, float) and value > 0):
                on.append(text)
        return on


def bench_gears(form: BenchForm, teeth_pinion: int, teeth_gear: int, seed: int) -> dict:
    """The bench's own gears: pitch errors fixed by `seed` (the same physical gears in every
    record), single deviations plus a sinusoidal cumulative error over one revolution."""
    rng = np.random.default_rng([seed, 0xBE7C4])
    errors = {}
    for name, teeth in (("pinion", teeth_pinion), ("gear", teeth_gear)):
        phase = rng.uniform(0.0, 2 * math.pi)
        cumulative = form.cumulative_pitch_error * np.sin(2 * math.pi * np.arange(teeth) / teeth + phase)
        errors[f"pitch_errors_{name}"] = tuple((rng.normal(0.0, form.pitch_error, teeth) + cumulative).tolist())
    return errors


def bench_record(true_params: GearDrivetrainParameters, form: BenchForm, settings: SimulationSettings,
                 rng: np.random.Generator, gears: dict) -> dict[str, np.ndarray]:
    """One acquisition of the bench at `true_params` (speed and health included): random phases of
    run-out, fluctuations and bearing tones, then white plus coloured sensor noise."""
    g = true_params.geometry
    shaft_hz = true_params.speed_rpm / 60.0
    shaft_frequencies = (shaft_hz, shaft_hz, shaft_hz * g.teeth_pinion / g.teeth_gear,
                         shaft_hz * g.teeth_pinion / g.teeth_gear)
    loads = [PeriodicLoad(("motor", None), form.motor_ripple, 2 * form.line_frequency_hz,
                          float(rng.uniform(0, 2 * math.pi)))] if form.motor_ripple else []
    if form.bearing_tone_force:
        for housing, frequency in enumerate(shaft_frequencies):
            for order in form.bearing_orders:
                loads.append(PeriodicLoad(("housing", housing), form.bearing_tone_force, order * frequency,
                                          float(rng.uniform(0, 2 * math.pi))))
    params = true_params.replace(
        housing_model=form.housing_model, shaft_model=form.shaft_model,
        housing_stiffness=tuple(form.housing_stiffness),
        runout_pinion=form.runout, runout_gear=form.runout,
        runout_phase_pinion=float(rng.uniform(0, 2 * math.pi)), runout_phase_gear=float(rng.uniform(0, 2 * math.pi)),
        speed_fluctuation=form.speed_fluctuation, speed_fluctuation_hz=form.speed_fluctuation_hz,
        speed_fluctuation_phase=float(rng.uniform(0, 2 * math.pi)),
        load_fluctuation=form.load_fluctuation, load_fluctuation_hz=form.load_fluctuation_hz,
        load_fluctuation_phase=float(rng.uniform(0, 2 * math.pi)), **gears)
    signals = simulate(params, settings, extra_loads=loads)
    return {name: signal + sensor_noise(len(signal), form, rng) for name, signal in signals.items()}


def sensor_noise(n: int, form: BenchForm, rng: np.random.Generator) -> np.ndarray:
    """White noise of rms `sensor_noise` plus coloured noise of rms `coloured_noise`: white noise
    through a first-order low-pass (pole 0.95), which weights low frequencies like the drift and
    structure-borne background of a real accelerometer chain."""
    noise = rng.normal(0.0, form.sensor_noise, n) if form.sensor_noise else np.zeros(n)
    if form.coloured_noise:
        coloured = lfilter([1.0], [1.0, -0.95], rng.normal(0.0, 1.0, n))
        noise += coloured / coloured.std() * form.coloured_noise
    return noise

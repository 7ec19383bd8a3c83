"""The virtual bench: a synthetic stand-in for a measured rig.

It runs the gear drivetrain model at hidden "true" parameters (with the high-fidelity
potential-energy mesh by default: `true_params.mesh_stiffness_model`, whichever mesh the calibrated
model uses) and adds what the calibrated model leaves out: a slow speed fluctuation, shaft run-out
and sensor noise. Its records are synthetic and are always labelled `virtual_bench`, never
`measured`.
"""
from __future__ import annotations

import numpy as np

from condmon.models.gear_drivetrain import GearDrivetrainParameters, SimulationSettings, simulate


def bench_record(true_params: GearDrivetrainParameters, settings: SimulationSettings,
                 sensor_noise: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """One acquisition: a model run with a random run-out phase, plus white sensor noise
    of RMS `sensor_noise` (m/s^2) on every channel."""
    params = true_params.replace(runout_phase=float(rng.uniform(0.0, 2.0 * np.pi)))
    signals = simulate(params, settings)
    return {name: signal + rng.normal(0.0, sensor_noise, size=signal.shape)
            for name, signal in signals.items()}

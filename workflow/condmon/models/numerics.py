"""What every exudyn model here shares: the one simulation error, explicit RK44 at a fixed step,
and the FIR filter that decimates the sensors to the output rate."""

from __future__ import annotations

from contextlib import contextmanager

import numpy as np
from scipy.signal import firwin, kaiserord


class SimulationError(RuntimeError):
    """A model run failed: the solver stopped, or the solution diverged (non-finite states,
    deflections beyond the model's limits). Every model raises this one class, so the pipeline
    retries, scores or reports a failed run the same way for every system."""


def decimation_filter(
    factor: int, passband: float = 0.8, attenuation_db: float = 80.0
) -> np.ndarray:
    """FIR low-pass for decimation by `factor`: flat to `passband` x the output Nyquist and
    `attenuation_db` down (Kaiser's estimate) from the output Nyquist on, so no harmonic above it
    folds back into the band (scipy's default decimation filter lets them through at -20 dB)."""
    transition = (1.0 - passband) / factor  # as a fraction of the input Nyquist
    numtaps, beta = kaiserord(attenuation_db, transition)
    # odd length (type I): a delay of whole input samples, which resample_poly takes off
    return firwin(numtaps | 1, (1.0 + passband) / 2.0 / factor, window=("kaiser", beta))


@contextmanager
def exudyn_system():
    """A new exudyn system (`mbs`) whose container is reset on exit. exudyn frees a container's
    items and stored sensor data only through Reset(): without it every run stays in memory
    (measured: 10-15 MB per 0.35-s CFRP run), and a calibration worker or a batch job grows
    until the machine runs out of memory."""
    import exudyn as exu  # imported here so the models' pure helpers work without exudyn

    container = exu.SystemContainer()
    try:
        yield container.AddSystem()
    finally:
        container.Reset()


def solve_rk44(
    mbs,
    sensor_rate: float,
    steps_per_sensor_sample: int,
    end_time: float,
    sparse: bool = False,
    sensed_accelerations: bool = True,
    solver: str = "RK44",
) -> None:
    """Integrate the assembled system `mbs` with RK44 at h = 1 / (sensor_rate x
    steps_per_sensor_sample) up to `end_time` (rounded to whole steps).

    Sensors record once per sensor period, a whole multiple of the step (they record at step
    ends); no solution file, which parallel jobs would otherwise share. Solver errors propagate:
    the caller names its model and parameters. sparse: the system's matrices are sparse
    containers (factorised with Eigen's sparse LU). sensed_accelerations: sensors record
    accelerations, which then cost a fifth right-hand-side evaluation per step at its end; a model
    that records velocities passes False and runs 20 % fewer force calls, with the same results.
    solver: "RK44", or "VelocityVerlet" (one force call per step, accelerations at step ends
    included; exudyn evaluates velocity-dependent forces at the half-step velocity, so the model
    must add h/2 x its damping matrix to its mass matrix to make it the central difference
    method, second order: `bearing.rig.central_difference_mass`). exudyn 1.13.6 prints "WARNING:
    VelocityVerlet: still under development" once per process (SuppressWarnings does not stop it);
    the bearing tests check the scheme's convergence.
    """
    import exudyn as exu  # imported here so the models' pure helpers work without exudyn

    step = 1.0 / (sensor_rate * steps_per_sensor_sample)
    sim = exu.SimulationSettings()
    sim.timeIntegration.numberOfSteps = int(round(end_time / step))
    sim.timeIntegration.endTime = sim.timeIntegration.numberOfSteps * step
    sim.timeIntegration.verboseMode = 0
    sim.solution.file.write = False
    sim.solution.sensors.writePeriod = 1.0 / sensor_rate
    sim.timeIntegration.explicit.computeEndOfStepAccelerations = sensed_accelerations
    if sparse:
        sim.linearSolver.solverType = exu.LinearSolverType.EigenSparse
    mbs.SolveDynamic(sim, solverType=getattr(exu.DynamicSolverType, solver))

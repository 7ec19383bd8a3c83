"""The time integration every exudyn model here uses: explicit RK44 at a fixed step."""
from __future__ import annotations


def solve_rk44(mbs, sensor_rate: float, steps_per_sensor_sample: int, end_time: float) -> None:
    """Integrate the assembled system `mbs` with RK44 at h = 1 / (sensor_rate x
    steps_per_sensor_sample) up to `end_time` (rounded to whole steps).

    Sensors record once per sensor period, a whole multiple of the step (they record at step
    ends); no solution file, which parallel jobs would otherwise share. Solver errors propagate:
    the caller names its model and parameters.
    """
    import exudyn as exu  # imported here so the models' pure helpers work without exudyn

    step = 1.0 / (sensor_rate * steps_per_sensor_sample)
    sim = exu.SimulationSettings()
    sim.timeIntegration.numberOfSteps = int(round(end_time / step))
    sim.timeIntegration.endTime = sim.timeIntegration.numberOfSteps * step
    sim.timeIntegration.verboseMode = 0
    sim.solution.file.write = False
    sim.solution.sensors.writePeriod = 1.0 / sensor_rate
    mbs.SolveDynamic(sim, solverType=exu.DynamicSolverType.RK44)

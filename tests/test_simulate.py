"""Simulation jobs: reproducible streams, retry at a smaller step, tolerated failures."""
import numpy as np
import pytest

import condmon.simulate as simulate_module
from condmon.simulate import TooManyFailures, simulate_batch, simulate_with_retry
from models.gear_drivetrain import GearDrivetrainParameters, SimulationError, SimulationSettings

MODEL = {"geometry": {}}
NUMERICS = {"settle_time": 0.02, "oversampling": 10, "steps_per_sensor_sample": 1, "output_rate": 5120.0}
CALIBRATED = {"contact_law": "flores", "sensor_noise": 0.01,
              "parameters": {"mesh_stiffness": 4e8, "contact_exponent": 1.4, "bushing_stiffness": 2e8}}


def batch(seed=1, calibrated=CALIBRATED, samples=2, max_failed_share=0.0):
    return simulate_batch(MODEL, calibrated, "healthy", 775.0, 0, samples=samples,
                          perturbation={"sigma": 0.03, "parameters": list(calibrated["parameters"])},
                          numerics=NUMERICS, segment_seconds=0.1, segments_per_sample=1, seed=seed,
                          max_failed_share=max_failed_share)


def signals_of(rows):
    return np.concatenate([r["signal"] for r in rows])


def test_same_seed_same_records_other_seed_other_draws():
    rows_a, report = batch(seed=1)
    rows_b, _ = batch(seed=1)
    rows_c, _ = batch(seed=2)
    assert np.array_equal(signals_of(rows_a), signals_of(rows_b))
    assert [r["params"] for r in rows_a] == [r["params"] for r in rows_b]
    assert [r["params"] for r in rows_a] != [r["params"] for r in rows_c]
    assert report["succeeded"] == 2 and report["failures"] == [] and len(report["wall_seconds"]) == 2


def test_a_diverging_simulation_is_retried_at_half_the_step(monkeypatch):
    steps = []
    real = simulate_module.simulate

    def first_attempt_diverges(params, settings):
        steps.append(settings.steps_per_sensor_sample)
        if len(steps) == 1:
            raise SimulationError("diverged")
        return real(params, settings)

    monkeypatch.setattr(simulate_module, "simulate", first_attempt_diverges)
    signals, errors = simulate_with_retry(GearDrivetrainParameters(speed_rpm=775.0),
                                          SimulationSettings(duration=0.05, settle_time=0.01))
    assert steps == [1, 2] and signals is not None and len(errors) == 1


def test_failures_beyond_the_tolerated_share_stop_the_job_naming_the_run():
    broken = dict(CALIBRATED, parameters=dict(CALIBRATED["parameters"], mesh_stiffness=1.0))
    with pytest.raises(TooManyFailures, match=r"2 of 2 simulations of healthy at 775 rpm batch 0.*mesh_stiffness"):
        batch(calibrated=broken)
    rows, report = batch(calibrated=dict(CALIBRATED, parameters=dict(CALIBRATED["parameters"])),
                         max_failed_share=0.5)
    assert report["failures"] == [] and rows

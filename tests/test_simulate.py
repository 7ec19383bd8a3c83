"""Simulation jobs: reproducible streams, retry at a smaller step, tolerated failures."""

import numpy as np
import pandas as pd
import pytest

from conftest import system_of
from condmon.background import Background
from condmon.models.numerics import SimulationError
from condmon.simulate import TooManyFailures, simulate_batch, simulate_with_retry

CALIBRATED = {
    "contact_law": "flores",
    "sensor_noise": 0.01,
    "parameters": {"mesh_stiffness": 4e8, "contact_exponent": 1.4, "bushing_stiffness": 2e8},
}


SHORT = {
    "rig": {"segment_seconds": 0.1},
    "numerics": {"settle_time": 0.02},
    "features": {"spectrum": {"resolution_hz": 10.0}},
}


@pytest.fixture(scope="module")
def gear():
    """The smoke config's gear system at short segments, its mesh the calibrated one (CALIBRATED)."""
    return system_of(".test/config/smoke.yaml", {**SHORT, "model": {"mesh_compliance": None}})


def batch(system, seed=1, calibrated=CALIBRATED, samples=2, max_failed_share=0.0, background=None):
    return simulate_batch(
        system,
        calibrated,
        "healthy",
        775.0,
        0,
        samples=samples,
        simulation={"segments_per_sample": 1, "seed": seed, "max_failed_share": max_failed_share},
        background=background,
    )


def signals_of(rows):
    return np.concatenate([r["signal"] for r in rows])


def test_same_seed_same_records_other_seed_other_draws(gear):
    rows_a, report = batch(gear, seed=1)
    rows_b, _ = batch(gear, seed=1)
    rows_c, _ = batch(gear, seed=2)
    assert np.array_equal(signals_of(rows_a), signals_of(rows_b))
    assert [r["params"] for r in rows_a] == [r["params"] for r in rows_b]
    assert [r["params"] for r in rows_a] != [r["params"] for r in rows_c]
    assert (
        report["succeeded"] == 2 and report["failures"] == [] and len(report["wall_seconds"]) == 2
    )
    assert report["simulated_seconds_per_sample"] == pytest.approx(0.02 + 0.1)


def test_a_diverging_simulation_is_retried_at_half_the_step(gear, monkeypatch):
    refinements = []
    real = type(gear).simulate_sample

    def first_attempt_diverges(self, parameters, health, speed, duration, seed, step_refinement=1):
        refinements.append(step_refinement)
        if len(refinements) == 1:
            raise SimulationError("diverged")
        return real(self, parameters, health, speed, duration, seed, step_refinement)

    monkeypatch.setattr(type(gear), "simulate_sample", first_attempt_diverges)
    signals, errors = simulate_with_retry(
        gear, {"contact_law": "flores"}, "healthy", 775.0, 0.05, seed=1
    )
    assert refinements == [1, 2] and signals is not None and len(errors) == 1


def test_failures_beyond_the_tolerated_share_stop_the_job_naming_the_run(gear):
    broken = dict(CALIBRATED, parameters=dict(CALIBRATED["parameters"], mesh_stiffness=1.0))
    with pytest.raises(
        TooManyFailures,
        match=r"2 of 2 gear simulations of healthy at 775 rpm batch 0.*mesh_stiffness",
    ):
        batch(gear, calibrated=broken)
    rows, report = batch(
        gear,
        calibrated=dict(CALIBRATED, parameters=dict(CALIBRATED["parameters"])),
        max_failed_share=0.5,
    )
    assert report["failures"] == [] and rows


def test_the_calibrated_background_replaces_the_white_noise_reproducibly(gear):
    """A background of flat PSD on every channel: the same seed gives the same records; against the
    run without it (same draws, white `sensor_noise` of 0.01 instead) the records differ by the
    background's RMS."""
    freqs = np.fft.rfftfreq(gear.segment_length, 1 / gear.output_rate_hz)
    level = 0.5**2 / (gear.output_rate_hz / 2)  # 0.5 m/s^2 RMS
    background = Background(
        pd.DataFrame(
            [
                dict(
                    speed_rpm=775.0,
                    channel=channel,
                    freq_hz=f,
                    measured_psd=level,
                    model_psd=0.0,
                    background_psd=level,
                )
                for channel in gear.channels
                for f in freqs
            ]
        )
    )
    plain, _ = batch(gear)
    with_background, _ = batch(gear, background=background)
    again, _ = batch(gear, background=background)
    assert np.array_equal(signals_of(with_background), signals_of(again))
    assert [r["params"] for r in with_background] == [r["params"] for r in plain]
    difference = signals_of(with_background) - signals_of(plain)
    assert difference.std() == pytest.approx(0.5, rel=0.1)


def test_with_a_healthy_reference_every_health_state_draws_the_same_machines(gear):
    """features.healthy_reference: sample i of (speed, batch) is one machine in every health state
    (the same parameters and run seed), with its own measurement noise per state; the healthy
    sample runs the reference segments longer. Without it the states draw apart."""

    def run(state, reference_segments):
        return simulate_batch(
            gear,
            CALIBRATED,
            state,
            775.0,
            0,
            samples=2,
            simulation={"segments_per_sample": 1, "seed": 1, "max_failed_share": 0.0},
            reference_segments=reference_segments,
        )[0]

    healthy, damaged = run("healthy", 1), run("surface_fault", 1)
    assert [r["params"] for r in healthy if r["segment"] == 0] == [r["params"] for r in damaged]
    assert {r["segment"] for r in healthy} == {0, 1} and {r["segment"] for r in damaged} == {0}
    assert sorted({r["record_id"] for r in damaged}) == [
        "sim-surface_fault-775rpm-b000-s000",
        "sim-surface_fault-775rpm-b000-s001",
    ]
    # the twins' noise differs: the first segments (same time window) are not equal
    first = [r for r in healthy if r["segment"] == 0]
    assert not np.array_equal(signals_of(first), signals_of(damaged))
    apart = [r["params"] for r in run("surface_fault", 0)]
    assert apart != [r["params"] for r in run("healthy", 0) if r["segment"] == 0]


def test_a_drawn_mesh_compliance_sets_each_machine_deflection_within_its_range(gear):
    """model.mesh_compliance: every sample's mesh carries the rig's load at a static deflection
    inside the range, with an exponent inside its range; twins (one machine, healthy and damaged)
    share it; without the key the calibrated mesh stands, perturbed by a few per cent."""
    import json

    from condmon.models.gear.mesh_force import operating_deflection

    compliance = {"deflection": [4.0e-7, 1.2e-6], "contact_exponent": [1.0, 1.5]}
    drawn = system_of(
        ".test/config/smoke.yaml", {**SHORT, "model": {"mesh_compliance": compliance}}
    )

    def machines(system, state):
        rows = simulate_batch(
            system,
            CALIBRATED,
            state,
            775.0,
            0,
            samples=3,
            simulation={"segments_per_sample": 1, "seed": 1, "max_failed_share": 0.0},
            reference_segments=1,
        )[0]
        return {
            r["record_id"].split("-", 2)[2]: json.loads(r["params"])
            for r in rows
            if r["segment"] == 0
        }

    healthy, damaged = machines(drawn, "healthy"), machines(drawn, "missing_tooth")
    assert healthy == damaged
    deflections = [
        operating_deflection(
            drawn.parameters(
                mesh_stiffness=p["mesh_stiffness"], contact_exponent=p["contact_exponent"]
            )
        )
        for p in healthy.values()
    ]
    assert all(4.0e-7 <= d <= 1.2e-6 for d in deflections) and len(set(deflections)) == 3
    assert all(1.0 <= p["contact_exponent"] <= 1.5 for p in healthy.values())
    nominal = machines(gear, "healthy")
    assert all(
        abs(p["mesh_stiffness"] / 4e8 - 1) < 0.13 and abs(p["contact_exponent"] / 1.4 - 1) < 0.13
        for p in nominal.values()
    )


def test_a_mesh_both_calibrated_and_drawn_or_a_reversed_range_is_refused_by_name():
    from condmon.config import ConfigError

    with pytest.raises(
        ConfigError,
        match=r"calibration.parameters: \['mesh_stiffness'\] are drawn per sample by "
        r"model.mesh_compliance",
    ):
        system_of(
            ".test/config/smoke.yaml",
            {
                "calibration": {
                    "parameters": {"mesh_stiffness": {"low": 1e8, "high": 1e9, "log": True}}
                }
            },
        )
    with pytest.raises(
        ConfigError, match=r"model.mesh_compliance.deflection: \[low, high\] with low above high"
    ):
        system_of(
            ".test/config/smoke.yaml",
            {
                "model": {
                    "mesh_compliance": {"deflection": [1e-6, 4e-7], "contact_exponent": [1.0, 1.5]}
                }
            },
        )

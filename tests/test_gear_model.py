"""Physics checks of the gear drivetrain model and its contact laws."""
import math

import numpy as np
import pytest
from scipy.signal import resample_poly

from models.contact_laws import CONTACT_LAWS, contact_force, hysteresis_factor
from models.gear_drivetrain import (GearDrivetrainParameters, GearGeometry, MeshForce, SimulationError,
                                    SimulationSettings, decimation_filter, simulate)


def test_all_eight_table1_laws_with_their_factors():
    assert len(CONTACT_LAWS) == 8
    cr = 0.8
    expected = {"gharib_hurmuzlu": 1 / cr, "herbert_mcwhannel": 6 * 0.2 / ((2 * cr - 1) ** 2 + 3),
                "flores": 8 * 0.2 / (5 * cr), "lee_wang": 3 * 0.2 / 4, "hunt_crossley": 3 * 0.2 / 2,
                "lankarani_nikravesh": 3 * (1 - cr ** 2) / 4,
                "zhiying_qishao": 3 * (1 - cr ** 2) * math.exp(2 * 0.2) / 4, "gonthier": (1 - cr ** 2) / cr}
    for law, value in expected.items():
        assert hysteresis_factor(law, cr) == pytest.approx(value)
    # Every law but Gharib-Hurmuzlu dissipates nothing for a perfectly elastic contact.
    assert all(hysteresis_factor(law, 1.0) == 0 for law in CONTACT_LAWS if law != "gharib_hurmuzlu")


def test_unknown_law_and_bad_restitution_are_named():
    with pytest.raises(ValueError, match="unknown contact law 'hertz'"):
        hysteresis_factor("hertz", 0.9)
    with pytest.raises(ValueError, match="restitution"):
        hysteresis_factor("flores", 1.5)


def test_contact_force_never_pulls():
    assert contact_force(-1e-6, 0.0, 1e9, 1.5, 0.1, 0.02) == 0.0
    assert contact_force(1e-6, -10.0, 1e9, 1.5, 0.5, 0.02) == 0.0
    assert contact_force(1e-6, 0.0, 1e9, 1.0, 0.5, 0.02) == pytest.approx(1e3)


def test_geometry_matches_the_study_rig():
    g = GearGeometry()
    # Table 2 of the helical-gear study: pitch diameters 72.7 and 110.3 mm.
    assert 2 * g.pitch_radius(29) == pytest.approx(72.7e-3, abs=0.2e-3)
    assert 2 * g.pitch_radius(44) == pytest.approx(110.3e-3, abs=0.2e-3)
    assert 1.2 < g.contact_ratio < 2.0


def test_decimation_filter_removes_what_would_alias():
    fs_sensor, factor = 51200.0, 10
    t = np.arange(int(fs_sensor)) / fs_sensor
    lowpass = decimation_filter(factor)
    in_band = resample_poly(np.sin(2 * np.pi * 1000.0 * t), 1, factor, window=lowpass)[500:-500]
    above = resample_poly(np.sin(2 * np.pi * 2700.0 * t), 1, factor, window=lowpass)[500:-500]
    assert np.abs(in_band).max() == pytest.approx(1.0, abs=0.01)
    assert np.abs(above).max() < 1e-3  # would fold to 2420 Hz


def test_mesh_force_missing_tooth_removes_one_pair_and_neighbours_catch_the_gear():
    healthy = MeshForce(GearDrivetrainParameters(speed_rpm=600.0))
    missing = MeshForce(GearDrivetrainParameters(speed_rpm=600.0, health_state="missing_tooth"))
    ratio = healthy.contact_ratio
    period = 1.0 / healthy.mesh_frequency
    # Middle of the single-contact zone of pair 0 (the missing tooth), static deflection 1 um.
    t = (ratio - 1.0 + (1.0 - (ratio - 1.0)) / 2) * period
    assert healthy(t, 1e-6, 0.0) > 0
    assert missing(t, 1e-6, 0.0) == 0.0
    # Far larger deflection: the neighbouring pairs' extended contact carries the load.
    assert missing(t, 60e-6, 0.0) > 0
    # One pinion revolution later the same tooth is missing again; a tooth away it is not.
    assert missing(t + 29 * period, 1e-6, 0.0) == 0.0
    assert missing(t + period, 1e-6, 0.0) == pytest.approx(healthy(t + period, 1e-6, 0.0))


def test_surface_fault_lowers_the_stiffness_of_the_affected_teeth_by_15_percent():
    p = GearDrivetrainParameters(speed_rpm=600.0, health_state="surface_fault", contact_exponent=1.0,
                                 transmission_error=0.0)
    faulty, healthy = MeshForce(p), MeshForce(p.replace(health_state="healthy"))
    period = 1.0 / healthy.mesh_frequency
    t = 0.5 * (1 + healthy.contact_ratio - 1) * period  # single contact of pair 0
    assert faulty(t, 1e-6, 0.0) == pytest.approx(0.85 * healthy(t, 1e-6, 0.0))


@pytest.fixture(scope="module")
def healthy_run():
    params = GearDrivetrainParameters(speed_rpm=1100.0)
    return params, simulate(params, SimulationSettings(duration=0.5, settle_time=0.1))


def test_simulation_output_is_finite_at_the_output_rate(healthy_run):
    _, signals = healthy_run
    assert sorted(signals) == ["A1_x", "A1_y", "A2_x", "A2_y"]
    for signal in signals.values():
        assert len(signal) == 2560 and np.isfinite(signal).all() and signal.std() > 0


def test_healthy_spectrum_peaks_at_gear_mesh_harmonics(healthy_run):
    params, signals = healthy_run
    gmf = params.speed_rpm / 60 * 29
    x = signals["A1_y"]
    freqs = np.fft.rfftfreq(len(x), 1 / 5120)
    amplitude = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(len(x))))
    top = freqs[np.argsort(amplitude)[-5:]]
    orders = top / gmf
    assert np.all(np.abs(orders - np.round(orders)) < 0.02), orders


def test_divergence_is_an_error_that_names_the_run():
    params = GearDrivetrainParameters(speed_rpm=450.0, mesh_stiffness=1.0)
    with pytest.raises(SimulationError, match="450"):
        simulate(params, SimulationSettings(duration=0.2, settle_time=0.05))

"""Physics checks of the gear drivetrain model and its contact laws."""
import math

import numpy as np
import pytest
from scipy.signal import resample_poly

from condmon.models.contact_laws import CONTACT_LAWS, contact_force, hysteresis_factor
from condmon.models.gear_drivetrain import (HEALTH_STATES, GearDrivetrainParameters, GearGeometry, MeshForce,
                                    SimulationError, SimulationSettings, TVMSMeshForce, decimation_filter,
                                    simulate)

SIMPLE = "simple"


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


def test_simple_mesh_force_missing_tooth_removes_one_pair_and_neighbours_catch_the_gear():
    healthy = MeshForce(GearDrivetrainParameters(speed_rpm=600.0, mesh_stiffness_model=SIMPLE))
    missing = MeshForce(GearDrivetrainParameters(speed_rpm=600.0, health_state="missing_tooth",
                                                 mesh_stiffness_model=SIMPLE))
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


def test_simple_surface_fault_lowers_the_stiffness_of_the_affected_teeth_by_15_percent():
    p = GearDrivetrainParameters(speed_rpm=600.0, health_state="surface_fault", contact_exponent=1.0,
                                 transmission_error=0.0, mesh_stiffness_model=SIMPLE)
    faulty, healthy = MeshForce(p), MeshForce(p.replace(health_state="healthy"))
    period = 1.0 / healthy.mesh_frequency
    t = 0.5 * (1 + healthy.contact_ratio - 1) * period  # single contact of pair 0
    assert faulty(t, 1e-6, 0.0) == pytest.approx(0.85 * healthy(t, 1e-6, 0.0))


def test_mesh_stiffness_model_switch():
    assert type(MeshForce(GearDrivetrainParameters())) is TVMSMeshForce  # the default
    assert type(MeshForce(GearDrivetrainParameters(mesh_stiffness_model=SIMPLE))) is MeshForce
    with pytest.raises(ValueError, match="mesh_stiffness_model"):
        MeshForce(GearDrivetrainParameters(mesh_stiffness_model="fem"))
    with pytest.raises(ValueError, match="unknown health state 'cracked'"):
        MeshForce(GearDrivetrainParameters(health_state="cracked"))


@pytest.mark.parametrize("model", ["potential_energy", SIMPLE])
def test_both_mesh_models_carry_the_same_mean_load(model):
    """mesh_stiffness is the mean mesh stiffness at 1 um in both models: over a mesh cycle at a fixed
    deflection the mean force is the same."""
    p = GearDrivetrainParameters(speed_rpm=600.0, transmission_error=0.0, mesh_stiffness_model=model)
    mesh = MeshForce(p)
    times = (5.0 + np.arange(400) / 400) / mesh.mesh_frequency
    mean = np.mean([mesh(t, 1e-6, 0.0) for t in times])
    if model == SIMPLE:  # its extended contact near the window edges adds a few per cent
        assert 1.0 <= mean / (p.mesh_stiffness * 1e-6) < 1.05
    else:  # the helical pairs enter and leave slice by slice: no extended contact
        assert mean == pytest.approx(p.mesh_stiffness * 1e-6, rel=1e-3)


def test_tvms_mesh_force_missing_tooth_removes_its_pair_once_per_revolution():
    p = GearDrivetrainParameters(speed_rpm=600.0, transmission_error=0.0)
    healthy, missing = MeshForce(p), MeshForce(p.replace(health_state="missing_tooth"))
    period = 1.0 / healthy.mesh_frequency
    window = healthy.window  # eps_alpha + eps_beta: pinion tooth 0 meshes for phase in [0, window)
    for revolution in (0, 1, 2):
        for phase in (0.5, 1.0, 1.5, 2.0, 2.5):
            t = (29 * revolution + phase) * period
            lost = healthy(t, 1e-6, 0.0) - missing(t, 1e-6, 0.0)
            # Exactly tooth 0's pair: the TVMS pair stiffness at u = phase, at 1 um.
            pair = healthy.tvms.pair_stiffness(phase) * 1e-6 * p.mesh_stiffness / healthy.tvms.mean_stiffness
            assert lost == pytest.approx(float(pair), rel=1e-6)
            assert 0 < lost < healthy(t, 1e-6, 0.0)  # the neighbours still carry
        for phase in (window + 0.05, 10.0, 28.5):
            t = (29 * revolution + phase) * period
            assert missing(t, 1e-6, 0.0) == pytest.approx(healthy(t, 1e-6, 0.0), rel=1e-12)


def test_every_health_state_runs_in_both_models():
    for model in ("potential_energy", SIMPLE):
        p = GearDrivetrainParameters(speed_rpm=775.0, mesh_stiffness_model=model, transmission_error=0.0)
        healthy = MeshForce(p)
        t = np.arange(29 * 40) / 40 / healthy.mesh_frequency  # one pinion revolution
        reference = np.array([healthy(x, 1e-6, 0.0) for x in t])
        for state in HEALTH_STATES[1:]:
            faulty = MeshForce(p.replace(health_state=state))
            force = np.array([faulty(x, 1e-6, 0.0) for x in t])
            assert np.all(force <= reference + 1e-9) and force.sum() < reference.sum(), (model, state)


@pytest.mark.parametrize("speed", [450.0, 775.0, 1100.0])
def test_missing_tooth_is_numerically_sound_at_every_speed(speed):
    """Helical rig with the potential-energy TVMS: the neighbouring pairs carry the load over the
    missing tooth, so the teeth never separate; the run is finite and the deflection bounded."""
    params = GearDrivetrainParameters(speed_rpm=speed, health_state="missing_tooth")
    diagnostics = {}
    signals = simulate(params, SimulationSettings(duration=60.0 / speed + 0.01, settle_time=0.05), diagnostics)
    deflection = diagnostics["deflection"]
    assert all(np.isfinite(s).all() for s in signals.values())
    assert 0.0 < deflection.min() and deflection.max() < 5e-6


def test_spur_missing_tooth_reengages_within_backlash():
    """Spur gears (helix 0): the gear flies free over the missing tooth and the next pair's extended
    contact catches it: no flight beyond the backlash, no NaN, a bounded impact."""
    params = GearDrivetrainParameters(geometry=GearGeometry(helix_angle_deg=0.0), helix_slices=1,
                                      speed_rpm=1100.0, health_state="missing_tooth")
    diagnostics = {}
    signals = simulate(params, SimulationSettings(duration=0.12, settle_time=0.05), diagnostics)
    deflection = diagnostics["deflection"]
    assert all(np.isfinite(s).all() for s in signals.values())
    assert deflection.min() > -params.backlash   # never on the back flank
    assert deflection.min() < 0.0                 # it did lose contact ...
    assert deflection.max() < 50e-6               # ... and the re-engagement impact stays bounded


def test_tvms_mesh_force_costs_less_than_twice_the_simple_one():
    """The cost of a simulated second is the mesh function's: ~200k calls. Same calls, both models."""
    import time

    costs = {}
    for model in ("potential_energy", SIMPLE):
        mesh = MeshForce(GearDrivetrainParameters(speed_rpm=1100.0, mesh_stiffness_model=model))
        t = (np.arange(20000) / 204800.0).tolist()
        d = (0.63e-6 + 0.05e-6 * np.sin(np.arange(20000) * 0.02)).tolist()
        best = math.inf
        for _ in range(3):
            start = time.process_time()
            for x, y in zip(t, d):
                mesh(x, y, 0.0)
            best = min(best, time.process_time() - start)
        costs[model] = best
    assert costs["potential_energy"] < 2.0 * costs[SIMPLE], costs


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


@pytest.mark.parametrize("model", ["potential_energy", SIMPLE])
def test_divergence_is_an_error_that_names_the_run(model):
    params = GearDrivetrainParameters(speed_rpm=450.0, mesh_stiffness=1.0, mesh_stiffness_model=model)
    with pytest.raises(SimulationError, match="450"):
        simulate(params, SimulationSettings(duration=0.2, settle_time=0.05))

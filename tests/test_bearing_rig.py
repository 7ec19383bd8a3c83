"""The bearing-rig model (models/bearing/rig.py): kinematics, envelope-spectrum lines of the
defects at the kinematic frequencies, reproducibility, divergence."""

import numpy as np
import pytest
from scipy.signal import welch

from condmon.stat_features import envelope_line_ratio, envelope_spectrum
from condmon.models.bearing.rig import (
    SKF_6203,
    SKF_6205,
    BearingRigParameters,
    RigSettings,
    SimulationError,
    _DefectProfile,
    ball_strike_probability,
    contact_half_width,
    ball_deflection_at,
    clock_angle,
    de_clearance,
    effective_defect_depth,
    most_loaded_ball_load,
    outer_race_strike,
    preload_deflection,
    simulate_rig,
)

SPEED = 1797.0
SHAFT_HZ = SPEED / 60.0
FS = 12000.0


def test_6205_orders_match_the_cwru_table():
    orders = SKF_6205.orders()
    for name, value in dict(bpfo=3.5848, bpfi=5.4152, bsf=2.3567, ftf=0.39828).items():
        assert orders[name] == pytest.approx(value, rel=0.005), name
    fe = SKF_6203.orders()  # fan end: 8 balls, 0.2656 / 1.122 in
    assert fe["bpfo"] == pytest.approx(4 * (1 - 0.2656 / 1.122), rel=1e-9)
    assert fe["bpfo"] + fe["bpfi"] == pytest.approx(8.0)


def test_effective_depth_is_limited_by_the_ball():
    small = BearingRigParameters(defect_kind="outer_race", defect_width=0.007 * 0.0254)
    large = small.replace(defect_width=0.021 * 0.0254)
    assert 0.5e-6 < effective_defect_depth(small) < 2e-6  # ~1 um, far below the 0.28 mm pit
    assert effective_defect_depth(large) == pytest.approx(
        9 * effective_defect_depth(small), rel=1e-9
    )
    assert effective_defect_depth(large.replace(defect_depth=1e-6)) == 1e-6


def test_a_ball_defect_sinks_deeper_into_the_convex_inner_race_than_into_the_outer_race():
    ball = BearingRigParameters(defect_kind="ball", defect_width=0.014 * 0.0254)
    rb, g = SKF_6205.ball_diameter / 2, SKF_6205
    ratio = (1 / rb + 1 / g.inner_race_radius) / (1 / rb - 1 / g.outer_race_radius)
    assert effective_defect_depth(ball, "inner") == pytest.approx(
        ratio * effective_defect_depth(ball, "outer")
    )
    assert 1.4 < ratio < 1.6
    with pytest.raises(ValueError, match="name the race"):
        effective_defect_depth(ball)
    # passages alternate: outer race on even ones, inner race on odd ones
    profile = _DefectProfile(ball, hash_seed=1.0)
    assert profile.depth == effective_defect_depth(ball, "outer")
    assert profile.depth + profile.inner_extra == pytest.approx(
        effective_defect_depth(ball, "inner")
    )


def test_a_ball_pit_strikes_on_the_share_of_turns_it_crosses_the_rolling_track():
    # Hertz: the track's half-width grows as the load^(1/3); at the CWRU rig's loads it is a few
    # tenths of a mm, so a pit on a 7.9 mm ball meets the races on about a tenth to a fifth of the turns
    assert contact_half_width(SKF_6205, 80.0, "inner") == pytest.approx(
        2 * contact_half_width(SKF_6205, 10.0, "inner"), rel=1e-9
    )
    assert 0.2e-3 < contact_half_width(SKF_6205, 22.0, "outer") < 0.6e-3
    small = BearingRigParameters(defect_kind="ball", defect_width=0.007 * 0.0254)
    shares = [
        ball_strike_probability(small),
        ball_strike_probability(small.replace(defect_width=0.021 * 0.0254)),
        ball_strike_probability(small.replace(radial_load=150.0)),
    ]
    assert 0.05 < shares[0] < shares[1] < 0.3 and shares[0] < shares[2] < 0.3
    # an axial preload presses the balls harder: a wider track, more strikes
    assert shares[0] < ball_strike_probability(small.replace(axial_preload=125.0)) < 0.3
    # the most loaded ball carries Stribeck's 4.37 F_r / Z without clearance, more with one (fewer
    # balls share the load)
    journal = small.rotor_mass * small.de_mass_share * small.gravity
    factor = most_loaded_ball_load(small.replace(radial_clearance=0.0)) * SKF_6205.n_balls / journal
    assert factor == pytest.approx(4.37, abs=0.02)
    assert most_loaded_ball_load(small) * SKF_6205.n_balls / journal > factor + 1
    assert _DefectProfile(small, hash_seed=1.0).strike == shares[0]  # None: from the contact
    assert _DefectProfile(small.replace(defect_strike_probability=0.5), hash_seed=1.0).strike == 0.5
    race = BearingRigParameters(defect_kind="outer_race", defect_width=0.007 * 0.0254)
    assert _DefectProfile(race, hash_seed=1.0).strike == 1.0  # a race pit: every passage


# Clean signals for the kinematic checks: no background, little noise, every passage strikes.
CLEAN = dict(
    noise_rms=0.05,
    background=(),
    slip_std=0.005,
    defect_width=0.014 * 0.0254,
    defect_strike_probability=1.0,
    defect_depth_variation=0.1,
)
CLEAN_CLEARANCE = BearingRigParameters().radial_clearance


@pytest.fixture(scope="module")
def runs():
    settings = RigSettings(duration=1.0, settle_time=0.1)
    out = {}
    for kind in ("none", "outer_race", "inner_race", "ball"):
        params = BearingRigParameters(speed_rpm=SPEED, defect_kind=kind, **CLEAN)
        out[kind] = simulate_rig(params, settings, np.random.default_rng(3))["DE"]
    return out


def _line(signal, order, search=0.05):
    """(frequency of the largest envelope line within +/- search of order x shaft, its ratio over
    the local floor at that frequency)."""
    freqs, amps = envelope_spectrum(signal, FS)
    f0 = order * SHAFT_HZ
    window = np.abs(freqs - f0) <= search * f0
    peak = freqs[window][np.argmax(amps[window])]
    ratio = envelope_line_ratio(
        freqs, amps, f0, tolerance=0.015, floor_halfwidth_hz=0.5 * SHAFT_HZ
    )[0]
    return peak, ratio


@pytest.mark.slow
def test_outputs_are_finite_and_of_the_requested_length(runs):
    for kind, signal in runs.items():
        assert signal.shape == (12000,), kind
        assert np.isfinite(signal).all(), kind


@pytest.mark.slow
@pytest.mark.parametrize(
    "kind, order",
    [
        ("outer_race", SKF_6205.orders()["bpfo"]),
        ("inner_race", SKF_6205.orders()["bpfi"]),
        ("ball", 2 * SKF_6205.orders()["bsf"]),
    ],
)
def test_defect_line_at_the_kinematic_frequency(runs, kind, order):
    peak, ratio = _line(runs[kind], order)
    assert peak == pytest.approx(order * SHAFT_HZ, rel=0.015), kind
    assert ratio > 4.0, f"{kind}: envelope line only {ratio:.2f} x its floor"
    healthy_peak, healthy_ratio = _line(runs["none"], order)
    assert healthy_ratio < 3.0, (
        f"healthy rig shows a line at the {kind} frequency ({healthy_ratio:.2f})"
    )


@pytest.mark.slow
def test_a_shallow_ball_defect_strikes_the_races_in_turn_so_its_envelope_shows_bsf():
    # drops below the contact deflection: each strike's strength follows its race's curvature, so
    # the outer/inner alternation leaves a line at BSF beside 2 x BSF (equal strikes: ratio < 2)
    params = BearingRigParameters(
        speed_rpm=SPEED, defect_kind="ball", **(CLEAN | dict(defect_drop_scale=0.15))
    )
    signal = simulate_rig(
        params, RigSettings(duration=1.0, settle_time=0.1), np.random.default_rng(4)
    )["DE"]
    peak, ratio = _line(signal, SKF_6205.orders()["bsf"])
    assert peak == pytest.approx(SKF_6205.orders()["bsf"] * SHAFT_HZ, rel=0.015)
    assert ratio > 3.0, f"no BSF line ({ratio:.2f} x its floor): the strikes do not alternate"


@pytest.mark.slow
def test_inner_race_has_shaft_speed_sidebands(runs):
    """The inner-race defect turns with the shaft through the load zone: BPFI +/- 1 x shaft."""
    bpfi = SKF_6205.orders()["bpfi"]
    for side in (bpfi - 1.0, bpfi + 1.0):
        peak, ratio = _line(runs["inner_race"], side, search=0.02)
        assert peak == pytest.approx(side * SHAFT_HZ, rel=0.015)
        assert ratio > 2.0, f"no sideband at {side:.3f} orders ({ratio:.2f})"


@pytest.mark.slow
def test_outer_race_defect_is_impulsive_and_healthy_is_not(runs):
    def kurtosis(x):
        d = x - x.mean()
        return np.mean(d**4) / np.mean(d**2) ** 2

    assert kurtosis(runs["none"]) < 3.5
    assert kurtosis(runs["outer_race"]) > 4.0
    assert np.std(runs["outer_race"]) > 3 * np.std(runs["none"])


def test_same_seed_gives_identical_arrays_and_another_seed_differs():
    params = BearingRigParameters(defect_kind="inner_race", slip_std=0.02, defect_roughness=2.0)
    settings = RigSettings(duration=0.05, settle_time=0.02)
    a = simulate_rig(params, settings, np.random.default_rng(11))["DE"]
    b = simulate_rig(params, settings, np.random.default_rng(11))["DE"]
    c = simulate_rig(params, settings, np.random.default_rng(12))["DE"]
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_divergence_raises_simulation_error_naming_the_parameters():
    params = BearingRigParameters(defect_kind="outer_race", contact_stiffness=1e14)
    with pytest.raises(SimulationError, match="contact_stiffness=1e\\+14"):
        simulate_rig(params, RigSettings(duration=0.05, settle_time=0.02), np.random.default_rng(0))


def test_invalid_parameters_are_rejected():
    with pytest.raises(ValueError, match="defect_kind"):
        simulate_rig(BearingRigParameters(defect_kind="cage"), RigSettings(duration=0.01))
    with pytest.raises(ValueError, match="slip_std"):
        simulate_rig(BearingRigParameters(slip_std=0.5), RigSettings(duration=0.01))
    with pytest.raises(ValueError, match="defect_clock"):
        simulate_rig(BearingRigParameters(defect_clock=13.0), RigSettings(duration=0.01))


def _outer_race(clock=6.0, slip=0.005, duration=0.3, seed=3, diagnostics=None, **changes):
    """A clean outer-race run; `changes` override other parameters."""
    params = BearingRigParameters(
        speed_rpm=SPEED,
        defect_kind="outer_race",
        defect_clock=clock,
        **{**CLEAN, "slip_std": slip, **changes},
    )
    return simulate_rig(
        params,
        RigSettings(duration=duration, settle_time=0.1),
        np.random.default_rng(seed),
        diagnostics,
    )["DE"]


def test_outer_race_line_weakens_as_the_defect_leaves_the_load_zone():
    """The load presses the journal down: at 6:00 the balls over the defect carry the most load;
    at 4:30 less, at 12:00 none (no strike, no line)."""
    bpfo = SKF_6205.orders()["bpfo"]
    ratios = {clock: _line(_outer_race(clock), bpfo)[1] for clock in (6.0, 4.5, 12.0)}
    assert ratios[6.0] > 2 * ratios[4.5] and ratios[4.5] > 4.0, ratios
    assert ratios[12.0] < 3.0, ratios


def _strike(clock, **changes):
    """The strike of an outer-race defect at `clock` in the simulation: the largest force of the DE
    bearing on its housing along the defect's direction that the defect takes away (the run less
    the same run without the defect; no modes, no slip, every passage alike)."""
    clean = dict(CLEAN, slip_std=0.0, defect_depth_variation=0.0, resonances=(), **changes)
    forces = []
    for kind in ("none", "outer_race"):
        diagnostics = {}
        params = BearingRigParameters(
            speed_rpm=SPEED, defect_kind=kind, defect_clock=clock, **clean
        )
        simulate_rig(
            params,
            RigSettings(duration=0.15, settle_time=0.05),
            np.random.default_rng(1),
            diagnostics,
        )
        forces.append(diagnostics["de_force"])
    along = np.array([np.cos(clock_angle(clock)), np.sin(clock_angle(clock))])
    return float(np.percentile(np.abs((forces[1] - forces[0]) @ along), 99.5)), params


def test_a_defect_beside_the_load_zone_strikes_weaker_by_the_load_zone_law():
    """A radial load at 6:00 (1000 N on the journal) and SKF's lighter spring preload (125 N): a
    ball over an outer-race defect stops carrying the load the load-zone law gives it at the
    defect's angle (Harris: deflection s cos(psi) - c from the static sag s and the running
    clearance c, less the depth it sinks into the defect). The simulated strike at 3:00 is that
    law's share of the strike at 6:00 (about 0.4), at 4:30 about 0.87; without the preload 3:00 lies
    outside the load zone and does not strike at all."""
    loaded = dict(radial_load=1000.0, axial_preload=125.0)
    bottom, params = _strike(6.0, **loaded)
    assert (
        ball_deflection_at(params, 6.0)
        > ball_deflection_at(params, 4.5)
        > ball_deflection_at(params, 3.0)
        > 0
    )
    law = {
        clock: outer_race_strike(params, clock) / outer_race_strike(params, 6.0)
        for clock in (4.5, 3.0)
    }
    assert 0.3 < law[3.0] < 0.5 and 0.8 < law[4.5] < 0.95, law
    for clock, share in law.items():
        assert _strike(clock, **loaded)[0] / bottom == pytest.approx(share, rel=0.1), clock
    # without the preload: the running clearance leaves 3:00 outside the load zone
    free = dict(radial_load=1000.0)
    beside, params = _strike(3.0, **free)
    assert outer_race_strike(params, 3.0) == 0.0 and beside < 0.01 * _strike(6.0, **free)[0]
    assert most_loaded_ball_load(params) == pytest.approx(
        params.contact_stiffness * ball_deflection_at(params, 6.0) ** 1.5
    )


TILTED = ((2900.0, 0.04, 0.6, 40.0), (3400.0, 0.03, 1.0, -40.0), (3700.0, 0.04, 0.5, 40.0))


def test_an_axial_preload_takes_up_the_clearance_and_presses_every_ball():
    """The preload deflection solves Z K delta^1.5 sin(alpha) = F_a with the contact angle of the
    shifted rings, cos alpha = A cos alpha_0 / (A + delta); SKF's spring preload for the 6205
    (125-250 N) presses every ball by a few um, more with more force, and less with a larger
    clearance (a steeper contact angle carries the same force with less deflection)."""
    base = BearingRigParameters(radial_clearance=4e-6)
    assert (
        preload_deflection(base) == 0.0 and de_clearance(base) == 4e-6
    )  # no spring: the clearance stays
    light, heavy = (preload_deflection(base.replace(axial_preload=f)) for f in (125.0, 250.0))
    assert 3e-6 < light < heavy < 7e-6, (light, heavy)
    assert de_clearance(base.replace(axial_preload=125.0)) == -light
    assert preload_deflection(base.replace(axial_preload=125.0, radial_clearance=8e-6)) < light
    a = (2 * 0.52 - 1) * SKF_6205.ball_diameter
    cos_alpha = a * (1 - 4e-6 / a) / (a + light)
    axial = SKF_6205.n_balls * base.contact_stiffness * light**1.5 * np.sqrt(1 - cos_alpha**2)
    assert axial == pytest.approx(125.0, rel=1e-6)
    with pytest.raises(ValueError, match="axial_preload"):
        _outer_race(axial_preload=-1.0)


def test_a_preload_and_tilted_modes_show_defects_above_and_beside_the_load_zone():
    """An axial preload (SKF's lighter spring, 125 N) keeps the balls at 12:00 pressed, so a
    defect there strikes; a strike at 3:00 is horizontal and reaches the 12 o'clock sensor mostly
    through modes whose motion at the sensor is tilted (real CWRU records at 3:00 and 12:00 show
    the line)."""
    bpfo = SKF_6205.orders()["bpfo"]
    preload = dict(axial_preload=125.0)
    top = _line(_outer_race(12.0, resonances=TILTED, **preload), bpfo)[1]
    assert top > 4.0, top  # without the preload: no line (the test above)
    beside_vertical_modes = _line(_outer_race(3.0, **preload), bpfo)[1]
    beside = _line(_outer_race(3.0, resonances=TILTED, **preload), bpfo)[1]
    # vertical modes see a 3:00 strike only through the journal's coupling (a line about 4x the
    # floor at 125 N, none with a heavier preload); tilted modes carry it several times stronger
    assert beside > 4.0 and beside > 3 * beside_vertical_modes, (beside_vertical_modes, beside)
    # a mode must never be tilted past horizontal
    with pytest.raises(ValueError, match="tilt"):
        _outer_race(resonances=((3000.0, 0.02, 0.5, 120.0),))


def _line_spread(signal, harmonic=3):
    """Relative std of the envelope power around harmonic x BPFO (+/- 8 %, floor removed)."""
    freqs, amps = envelope_spectrum(signal, FS)
    f0 = harmonic * SKF_6205.orders()["bpfo"] * SHAFT_HZ
    window = np.abs(freqs - f0) <= 0.08 * f0
    power = np.clip(amps[window] ** 2 - np.median(amps[window] ** 2), 0, None)
    centre = (freqs[window] * power).sum() / power.sum()
    return float(np.sqrt(((freqs[window] - centre) ** 2 * power).sum() / power.sum()) / f0)


@pytest.mark.slow
def test_slip_is_cumulative_and_spreads_the_line_by_about_the_slip():
    profile = _DefectProfile(BearingRigParameters(defect_kind="outer_race", slip_std=0.02), 42.0)
    t = np.linspace(0.0, 10.0, 200_001)
    psi = profile.phase(t, np.sin)
    rate = np.gradient(psi, t) / profile.psi_rate - 1  # the slip rate
    assert np.std(rate) == pytest.approx(0.02, rel=0.15)
    # integrated: the passages drift by a good part of a period, not a jitter about fixed times
    assert np.abs(psi - (t * profile.psi_rate + profile.psi0)).max() > 0.2
    exact, slipping = (_line_spread(_outer_race(slip=s, duration=1.0)) for s in (0.0, 0.02))
    assert exact < 0.005
    assert 0.01 < slipping < 0.04, slipping


def _band_power(signal, low, high, fs=FS):
    freqs, power = welch(signal, fs=fs, nperseg=1024)
    return float(power[(freqs >= low) & (freqs < high)].sum())


@pytest.mark.slow
def test_structural_modes_are_bodies_the_bearing_force_excites():
    """A housing mode is a modal mass in the model: the impacts ring it at its frequency (and
    nowhere else), and moving the mode moves the ringing; without modes the band stays quiet."""
    bare = _outer_race(resonances=())
    at_3k = _outer_race(resonances=((3000.0, 0.02, 0.5),))
    at_4k = _outer_race(resonances=((4000.0, 0.02, 0.5),))
    assert _band_power(at_3k, 2800, 3200) > 100 * _band_power(bare, 2800, 3200)
    assert _band_power(at_4k, 3800, 4200) > 100 * _band_power(bare, 3800, 4200)
    assert _band_power(at_3k, 3800, 4200) < 0.1 * _band_power(at_4k, 3800, 4200)
    freqs, power = welch(at_3k, fs=FS, nperseg=2048)
    search = (freqs > 1500) & (freqs < 5500)
    # the modal mass rides on the moving housing: its peak sits within 2 % of the tuned frequency
    assert freqs[search][np.argmax(power[search])] == pytest.approx(3000.0, rel=0.02)
    # and it acts back: a heavier mode absorbs the housing's motion in its band, so the bearing
    # deflection there drops (a filter applied after the run could not change it)
    deflection = {}
    for name, resonances in (("bare", ()), ("mode", ((3000.0, 0.02, 0.5),))):
        diagnostics = {}
        _outer_race(diagnostics=diagnostics, modal_mass_share=0.1, resonances=resonances)
        deflection[name] = _band_power(diagnostics["de_displacement"][:, 1], 2850, 3150, fs=4 * FS)
    assert deflection["mode"] < 0.7 * deflection["bare"], deflection


def test_rough_running_is_a_force_in_the_model_gated_by_the_passages():
    """With a defect too shallow to strike, the rough-running force alone rings the modes, and its
    gating by the passages puts the BPFO line in the envelope; same seed, same force."""
    quiet = dict(defect_drop_scale=1e-6, defect_roughness_modulation=1.0)
    smooth = _outer_race(defect_roughness=0.0, **quiet)
    rough = _outer_race(defect_roughness=5.0, **quiet)
    assert np.std(rough) > 20 * np.std(smooth)
    assert _line(rough, SKF_6205.orders()["bpfo"])[1] > 4.0
    np.testing.assert_array_equal(rough, _outer_race(defect_roughness=5.0, **quiet))


def test_a_mode_the_step_cannot_resolve_is_rejected():
    with pytest.raises(ValueError, match="omega h <= 0.5 for central_difference"):
        simulate_rig(
            BearingRigParameters(resonances=((9000.0, 0.02, 0.5),)), RigSettings(duration=0.01)
        )
    with pytest.raises(ValueError, match="omega h <= 1.0 for rk44"):
        simulate_rig(
            BearingRigParameters(resonances=((9000.0, 0.02, 0.5),)),
            RigSettings(duration=0.01, integrator="rk44", steps_per_sensor_sample=1),
        )
    with pytest.raises(ValueError, match="modal_mass_share"):
        simulate_rig(BearingRigParameters(modal_mass_share=0.5), RigSettings(duration=0.01))


@pytest.mark.slow  # four runs of 0.25 s, two of them RK44 at four steps a sample
def test_central_difference_matches_rk44_at_a_quarter_step():
    """The default integrator (exudyn's velocity Verlet with the damping mass correction: the
    central difference, one force call a step at h = 10.4 us) against RK44 at 5.2 us, on a
    preloaded healthy run and an outer-race run: RMS, kurtosis and the 50-Hz band levels within
    40 dB of the strongest agree (measured 2026-12-01: RMS within 0.1 %, bands within 0.1 dB)."""
    quiet = dict(noise_rms=0.0, background=())
    for changes in (dict(axial_preload=190.0), dict(defect_kind="outer_race", radial_load=300.0)):
        params = BearingRigParameters(**quiet, **changes)
        runs = [
            simulate_rig(
                params,
                RigSettings(duration=0.2, settle_time=0.05, **settings),
                np.random.default_rng(2),
            )["DE"]
            for settings in ({}, dict(integrator="rk44", steps_per_sensor_sample=4))
        ]
        (cd, rk) = runs
        assert abs(np.std(cd) / np.std(rk) - 1) < 0.01
        kurt = [np.mean((x - x.mean()) ** 4) / np.var(x) ** 2 for x in runs]
        assert abs(kurt[0] / kurt[1] - 1) < 0.05
        levels = [10 * np.log10(welch(x, fs=12000.0, nperseg=240)[1]) for x in runs]
        near = levels[1] > levels[1].max() - 40
        assert np.abs(levels[0] - levels[1])[near].max() < 0.5

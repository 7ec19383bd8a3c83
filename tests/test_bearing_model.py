"""The bearing system (workflow/condmon/systems/bearing): labels, randomisation, batches,
calibration spectra, another rig's geometry and labels."""

import json

import numpy as np
import pandas as pd
import pytest

from conftest import system_of
from condmon.calibrate import SpectrumModel, measured_spectra
from condmon.systems.bearing.cwru import task_labels
from condmon.systems.bearing.model import (
    bearing_defaults,
    build_rig_parameters,
    defect_of_label,
    draw_defect_diameter,
    feature_orders,
    load_of_speed,
    randomise,
)
from condmon.seeds import job_rng
from condmon.signals import make_rows, validate
from condmon.simulate import TooManyFailures, simulate_batch

DEFAULT_BEARING = bearing_defaults()
CWRU_LOADS = DEFAULT_BEARING["load_speeds"]

SPECTRUM = {"f_min_hz": 0.0, "f_max_hz": 6000.0}


@pytest.mark.parametrize("task", ["location", "severity", "ten_class"])
def test_every_task_label_maps_to_a_defect(task):
    for label in task_labels(task):
        kind, (low, high) = defect_of_label(label)
        if label == "normal":
            assert kind == "none"
        else:
            assert label.startswith(kind)
            assert 0.007 <= low <= high <= 0.021


def test_label_mapping_values_and_unknown_label():
    assert defect_of_label("outer_race") == ("outer_race", (0.007, 0.021))
    assert defect_of_label("ball_0.014in") == ("ball", (0.014, 0.014))
    assert defect_of_label("inner_race_0.021in") == ("inner_race", (0.021, 0.021))
    for bad in ("healthy", "cage", "outer_race_big", "ball_0.000in"):
        with pytest.raises(ValueError, match="unknown bearing health label"):
            defect_of_label(bad)


def test_defect_diameter_draws():
    rng = np.random.default_rng(0)
    pooled = [draw_defect_diameter("ball", 0.1, rng) for _ in range(200)]
    assert 0.007 <= min(pooled) and max(pooled) <= 0.021 and np.ptp(pooled) > 0.01
    fixed = [draw_defect_diameter("outer_race_0.014in", 0.1, rng) for _ in range(200)]
    assert 0.014 * 0.9 <= min(fixed) and max(fixed) <= 0.014 * 1.1
    assert draw_defect_diameter("normal", 0.1, rng) is None


def test_randomise_draws_within_ranges():
    spec = DEFAULT_BEARING["randomisation"]
    base = DEFAULT_BEARING["model"]
    rng = np.random.default_rng(1)
    draws = [randomise(spec, rng, base) for _ in range(300)]
    for name, s in spec.items():
        if name in ("resonances", "background"):
            level = "gain" if name == "resonances" else "rms"
            for d in draws:
                assert s["count"][0] <= len(d[name]) <= s["count"][1]
                for f, z, g, *tilt in d[name]:
                    assert s["frequency_hz"][0] <= f <= s["frequency_hz"][1]
                    assert s["damping_ratio"][0] <= z <= s["damping_ratio"][1]
                    assert s[level][0] <= g <= s[level][1]
                    assert len(tilt) == ("tilt_deg" in s)
                    assert not tilt or s["tilt_deg"][0] <= tilt[0] <= s["tilt_deg"][1]
            if "tilt_deg" in s:  # tilted both ways, over most of the range
                tilts = [mode[3] for d in draws for mode in d[name]]
                assert np.ptp(tilts) > 0.9 * (s["tilt_deg"][1] - s["tilt_deg"][0])
            continue
        values = np.array([d[name] for d in draws])
        factor = base.get(name, 1.0) if s.get("relative") else 1.0
        assert (values >= s["low"] * factor * (1 - 1e-12)).all() and (
            values <= s["high"] * factor * (1 + 1e-12)
        ).all()
        # wide, not a 3 % spread: the draws cover most of the range
        assert np.ptp(values) > 0.7 * (s["high"] - s["low"]) * factor, name
    # same seed, same draws; key order of the config does not matter
    a = randomise(spec, np.random.default_rng(5), base)
    b = randomise(dict(reversed(list(spec.items()))), np.random.default_rng(5), base)
    assert a == b


def test_build_rig_parameters():
    p = build_rig_parameters(
        DEFAULT_BEARING["model"], "outer_race_0.007in", 1772.0, radial_load=30.0
    )
    assert p.defect_kind == "outer_race" and p.speed_rpm == 1772.0 and p.radial_load == 30.0
    assert p.defect_width == pytest.approx(0.007 * 0.0254)
    scaled = build_rig_parameters(
        {}, "normal", 1797.0, resonance_frequency_scale=2.0, resonance_gain_scale=0.5
    )
    nominal = build_rig_parameters({}, "normal", 1797.0)
    assert scaled.resonances[0][0] == pytest.approx(2 * nominal.resonances[0][0])
    assert scaled.resonances[0][2] == pytest.approx(0.5 * nominal.resonances[0][2])
    ball = build_rig_parameters(
        {}, "ball", 1797.0, ball_defect_strike_probability=0.3, ball_drop_scale=0.5
    )
    race = build_rig_parameters(
        {}, "inner_race", 1797.0, ball_defect_strike_probability=0.3, ball_drop_scale=0.5
    )
    assert ball.defect_strike_probability == 0.3 and ball.defect_drop_scale == 0.5
    assert (
        race.defect_strike_probability is None and race.defect_drop_scale == 1.0
    )  # the ball's stay its own
    with pytest.raises(ValueError, match="unknown bearing model parameters"):
        build_rig_parameters({}, "normal", 1797.0, rotor_colour=1.0)


def test_load_of_speed():
    assert load_of_speed(1797, CWRU_LOADS) == 0.0 and load_of_speed(1772, CWRU_LOADS) == 1.0
    assert load_of_speed(1730, CWRU_LOADS) == 3.0 and load_of_speed(
        1500, [[5, 1400], [9, 1600]]
    ) in (5.0, 9.0)


def bearing_system(segment_length=1024, model=None):
    return system_of(
        ".test/config/cwru-smoke.yaml",
        {
            "bearing": {
                "segment_length": segment_length,
                "numerics": {"settle_time": 0.02},
                "model": model or {},
            }
        },
    )


def simulate_bearing_batch(
    system,
    calibrated,
    health,
    speed,
    batch,
    samples,
    segments_per_sample,
    seed,
    max_failed_share=0.0,
):
    return simulate_batch(
        system,
        calibrated or {"parameters": {}},
        health,
        speed,
        batch,
        samples,
        {
            "seed": seed,
            "segments_per_sample": segments_per_sample,
            "max_failed_share": max_failed_share,
        },
    )


def test_simulate_bearing_batch_rows_and_report():
    rows, report = simulate_bearing_batch(
        bearing_system(),
        None,
        "inner_race",
        1772.0,
        batch=2,
        samples=2,
        segments_per_sample=2,
        seed=4,
    )
    assert set(report) == {
        "health_state",
        "speed_rpm",
        "batch",
        "samples",
        "succeeded",
        "failures",
        "simulated_seconds_per_sample",
        "wall_seconds",
    }
    assert (
        report["succeeded"] == 2 and report["failures"] == [] and len(report["wall_seconds"]) == 2
    )
    assert report["simulated_seconds_per_sample"] == pytest.approx(0.02 + 2048 / 12000)
    frame = pd.DataFrame(rows)
    validate(frame, "test")
    assert sorted(frame["record_id"].unique()) == [
        "sim-inner_race-1772rpm-b002-s000",
        "sim-inner_race-1772rpm-b002-s001",
    ]
    assert set(frame["source"]) == {"simulated"} and set(frame["channel"]) == {"DE"}
    assert set(frame["fs_hz"]) == {12000.0} and set(frame["load"]) == {1.0} and len(frame) == 4
    params = json.loads(frame["params"].iloc[0])
    assert 0.007 <= params["defect_diameter_in"] <= 0.021 and "sensor_gain" in params
    again, _ = simulate_bearing_batch(
        bearing_system(),
        None,
        "inner_race",
        1772.0,
        batch=2,
        samples=2,
        segments_per_sample=2,
        seed=4,
    )
    for r1, r2 in zip(rows, again):
        np.testing.assert_array_equal(r1["signal"], r2["signal"])


def test_failed_samples_are_reported_and_too_many_stop_the_job():
    system = bearing_system(segment_length=256, model={"contact_stiffness": 1e17})
    rows, report = simulate_bearing_batch(
        system,
        {"parameters": {}},
        "outer_race",
        1797.0,
        batch=0,
        samples=1,
        segments_per_sample=1,
        seed=1,
        max_failed_share=1.0,
    )
    assert rows == [] and report["succeeded"] == 0
    assert len(report["failures"][0]["errors"]) == 2  # retried once with half the step
    with pytest.raises(TooManyFailures, match="contact_stiffness"):
        simulate_bearing_batch(
            system,
            None,
            "outer_race",
            1797.0,
            batch=0,
            samples=1,
            segments_per_sample=1,
            seed=1,
            max_failed_share=0.0,
        )


def test_calibration_spectra_shapes():
    model = SpectrumModel(
        bearing_system(segment_length=600),
        [1797.0, 1772.0],
        ["DE"],
        SPECTRUM,
        resolution_hz=100.0,
        sim_seconds=0.1,
    )
    simulated = model("hertz", {"contact_stiffness": 6e9, "noise_rms": 0.2})
    assert simulated.shape == (2, 1, 60) and np.isfinite(simulated).all()
    np.testing.assert_array_equal(
        simulated, model("hertz", {"contact_stiffness": 6e9, "noise_rms": 0.2})
    )
    with pytest.raises(ValueError, match="Hertz"):
        model("kelvin_voigt", {})
    rng = job_rng(0, "test")
    rows = []
    for rid, speed in (("a", 1796.0), ("b", 1772.0)):
        rows += make_rows(
            rid,
            "measured",
            "normal",
            speed,
            0.0,
            12000.0,
            {"DE": rng.normal(size=1200)},
            segment_length=600,
        )
    target = measured_spectra(
        pd.DataFrame(rows),
        [1797.0, 1772.0],
        ["DE"],
        SPECTRUM,
        100.0,
        12000.0,
        label="normal",
        tolerance_rpm=5.0,
    )
    assert target.shape == simulated.shape
    with pytest.raises(ValueError, match="no measured"):
        measured_spectra(
            pd.DataFrame(rows),
            [1730.0],
            ["DE"],
            SPECTRUM,
            100.0,
            12000.0,
            label="normal",
            tolerance_rpm=5.0,
        )


def test_another_rig_geometry_labels_and_loads():
    """A non-CWRU bearing: its labels with their defects, its geometry's defect orders, its loads."""
    labels = {
        "ok": {"defect": "none"},
        "or_small": {"defect": "outer_race", "diameter_mm": [0.2, 0.4]},
        "ir": {"defect": "inner_race", "diameter_mm": [0.5, 0.5]},
    }
    geometry = {
        "n_balls": 12,
        "ball_diameter": 6.0e-3,
        "pitch_diameter": 40.0e-3,
        "contact_angle_deg": 15.0,
    }
    system = system_of(
        ".test/config/cwru-smoke.yaml",
        {
            "measured_table": "signals.parquet",
            "hybrid": {"protocols": ["record_split"]},
            "bearing": {
                "health_states": labels,
                "healthy_state": "ok",
                "geometry": geometry,
                "load_speeds": [[10.0, 1500.0], [20.0, 1450.0]],
            },
            "rig": {"speeds_rpm": [1500, 1450]},
        },
    )
    assert system.health_states == ["ok", "or_small", "ir"] and system.healthy_state == "ok"
    assert system.defect("or_small") == ("outer_race", (0.2 / 25.4, 0.4 / 25.4))
    r = 6.0 / 40.0 * np.cos(np.radians(15.0))
    assert system.defect_orders()["bpfo"] == pytest.approx(6 * (1 - r)) and feature_orders(
        geometry
    )["bpfi"] == pytest.approx(6 * (1 + r))
    assert system.sample_load(1490.0, {}) == 10.0 and system.sample_load(1455.0, {}) == 20.0
    params = system.sample_parameters({"parameters": {}}, "or_small", np.random.default_rng(0), {})
    assert 0.2 / 25.4 * 0.999 <= params["defect_diameter_in"] <= 0.4 / 25.4 * 1.001
    rig = system._parameters(params, "or_small", 1500.0)
    assert rig.de_geometry.n_balls == 12 and rig.defect_kind == "outer_race"


@pytest.mark.slow
def test_another_geometry_puts_the_simulated_lines_and_the_rules_at_its_own_orders():
    """Any bearing from its config alone (issue 49): a 12-ball bearing of d/D cos(alpha) 0.145
    (BPFO 5.13 orders, the 6205's 3.58) simulates its outer-race strikes at its own BPFO, the
    features measure the lines at its own orders, and the envelope rule, its threshold from the
    healthy simulated segments, names the outer race there; at the 6205's orders no line stands
    out."""
    from condmon.stat_features import StatisticalFeatures

    labels = {
        "ok": {"defect": "none"},
        "or": {"defect": "outer_race", "diameter_mm": [0.3, 0.3]},
        "ir": {"defect": "inner_race", "diameter_mm": [0.3, 0.3]},
        "b": {"defect": "ball", "diameter_mm": [0.3, 0.3]},
    }
    geometry = {
        "n_balls": 12,
        "ball_diameter": 6.0e-3,
        "pitch_diameter": 40.0e-3,
        "contact_angle_deg": 15.0,
    }
    system = system_of(
        ".test/config/cwru-smoke.yaml",
        {
            "measured_table": "signals.parquet",
            "hybrid": {"protocols": ["record_split"]},
            "bearing": {
                "health_states": labels,
                "healthy_state": "ok",
                "geometry": geometry,
                "load_speeds": [[10.0, 1500.0]],
            },
            "rig": {"speeds_rpm": [1500]},
        },
    )
    own, cwru = system.defect_orders(), feature_orders(DEFAULT_BEARING["geometry"])
    assert own["bpfo"] == pytest.approx(5.1307, abs=1e-4) and abs(own["bpfo"] - cwru["bpfo"]) > 1.0

    def segments(label):
        values = system.sample_parameters({"parameters": {}}, label, np.random.default_rng(0), {})
        # the defect in the load zone, the rig's own noise and background off: the lines alone
        signal = system.simulate_sample(
            system.noise_free(dict(values, defect_clock=6.0)), label, 1500.0, 0.6, 1
        )["DE"]
        return signal.reshape(2, -1)

    def features(orders, x):
        names = StatisticalFeatures(defect_orders=orders, prefix="DE_").get_feature_names_out()
        values = StatisticalFeatures(
            fs_hz=system.output_rate_hz, defect_orders=orders, prefix="DE_"
        ).fit_transform(x, speed_rpm=1500.0)
        return pd.DataFrame(values, columns=names)

    healthy, outer = segments("ok"), segments("or")
    at_own = features(own, outer)
    ratios = at_own[["DE_env_ratio_bpfo", "DE_env_ratio_bpfi", "DE_env_ratio_bsf_x2"]]
    assert (ratios.idxmax(axis=1) == "DE_env_ratio_bpfo").all() and (
        ratios["DE_env_ratio_bpfo"] > 10
    ).all(), ratios
    assert (features(cwru, outer)["DE_env_ratio_bpfo"] < at_own["DE_env_ratio_bpfo"] / 3).all()
    rule = system.physics_baselines(list(at_own.columns))["envelope_rule"]
    rule.fit(features(own, healthy))
    assert list(rule.predict(at_own)) == ["or", "or"]


def test_noise_free_drops_the_rigs_own_noise_and_background():
    """The benchmark's step check compares noise-free runs: the rig model adds its own sensor noise
    and machine background, so `noise_free` removes them, and what is left converges with the step."""
    system = system_of(".test/config/cwru-smoke.yaml")
    parameters = system.sample_parameters(
        system.nominal_calibration(), "normal", np.random.default_rng(0), {}
    )
    quiet = system.noise_free(parameters)
    assert quiet["noise_rms"] == 0.0 and quiet["background"] == [] and parameters["noise_rms"] > 0
    speed = system.speeds_rpm[0]
    noisy = system.simulate_sample(parameters, "normal", speed, 0.1, seed=11)["DE"]
    coarse, fine = (
        system.simulate_sample(quiet, "normal", speed, 0.1, seed=11, step_refinement=r)["DE"]
        for r in (1, 2)
    )
    assert np.std(noisy - coarse) > 10 * np.std(coarse - fine)
    assert np.std(coarse - fine) < 0.01 * np.std(coarse)


# The data centre's published drive-end defect frequencies (SKF 6205-2RS JEM), in shaft orders.
CWRU_DE_ORDERS = dict(bpfi=5.4152, bpfo=3.5848, ftf=0.39828, bsf=2.3567)


def test_the_default_geometry_gives_the_cwru_defect_orders():
    from condmon.systems.bearing.model import geometry

    orders = geometry(bearing_defaults()["geometry"]).orders()
    for name, published in CWRU_DE_ORDERS.items():
        assert orders[name] == pytest.approx(published, abs=1e-4), name
    features = feature_orders(bearing_defaults()["geometry"])
    assert list(features) == ["bpfo", "bpfi", "bsf", "bsf_x2"]
    assert features["bsf_x2"] == pytest.approx(2 * orders["bsf"])


def test_defect_orders_relations_and_contact_angle():
    from condmon.models.bearing.rig import BearingGeometry

    o = BearingGeometry(8, 10.0, 50.0).orders()
    assert o["bpfo"] + o["bpfi"] == pytest.approx(8)  # n/2 (1 - r) + n/2 (1 + r)
    assert o["bpfo"] == pytest.approx(8 * o["ftf"])
    tilted = BearingGeometry(8, 10.0, 50.0, contact_angle_deg=60.0).orders()  # r halves
    assert tilted["bpfo"] == pytest.approx(4 * (1 - 0.1))

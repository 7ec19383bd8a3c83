"""Calibration: cost functions, bounds, and recovery of the virtual bench's hidden parameters."""

import numpy as np
import pandas as pd
import pytest

from condmon.calibrate import (
    Bound,
    Calibrator,
    SpectralProblem,
    SpectrumModel,
    estimate_sensor_noise,
    measured_spectra,
    cfrp_eq4,
    spectrum_cost,
    variant_check,
    with_sensor_noise,
)
from condmon.models.gear.drivetrain import operating_mesh_stiffness
from condmon.models.numerics import SimulationError
from condmon.systems import get_system
from condmon.operating import OperatingPoint
from condmon.systems.gear.bench import virtual_bench_rows
from condmon.systems.gear.parameters import build_parameters

from conftest import config_of


def test_costs_are_zero_for_identical_spectra_and_grow_with_the_error():
    measured = np.random.default_rng(0).random((2, 4, 50)) + 0.1
    assert spectrum_cost(measured, measured) == 0.0
    assert spectrum_cost(measured, measured, "helical_eq14") == 0.0
    assert spectrum_cost(1.1 * measured, measured) == pytest.approx(0.01)
    assert spectrum_cost(1.2 * measured, measured) > spectrum_cost(1.1 * measured, measured)
    with pytest.raises(ValueError, match="unknown calibration cost 'l1'"):
        spectrum_cost(measured, measured, "l1")


def test_a_model_variant_the_records_cannot_see_is_reported_as_the_searchs_draw(caplog):
    """Two variants that give the same spectra at the picked parameters (a gear's contact laws on
    a healthy mesh that never opens) are said to be unseen, naming both; variants that change the
    spectra are seen; a system of one variant has nothing to compare."""
    target = np.ones((2, 3, 8))

    def blind(variant, values):
        return np.full((2, 3, 8), values["gain"])

    def seeing(variant, values):
        return np.full((2, 3, 8), values["gain"] * (1.5 if variant == "flores" else 1.0))

    def problem(spectrum_model):
        return SpectralProblem([], target, spectrum_model, cfrp_eq4)

    best = {"model_variant": "gonthier", "parameters": {"gain": 1.2}}
    best["cost"] = cfrp_eq4(blind("gonthier", best["parameters"]), target)
    variants = ["flores", "hunt_crossley", "gonthier"]

    with caplog.at_level("WARNING", logger="condmon.calibrate"):
        unseen = variant_check(problem(blind), best, variants, "flores")
    assert unseen == {
        "model_variant_seen": False,
        "model_variant_compared": {"flores": best["cost"]},
    }
    assert "flores" in caplog.text and "gonthier is the search's draw" in caplog.text

    seen = variant_check(problem(seeing), best, variants, "flores")
    assert seen["model_variant_seen"] is True
    assert seen["model_variant_compared"]["flores"] > best["cost"]
    # the nominal variant picked itself: the first other one is compared
    nominal = dict(best, model_variant="flores")
    assert list(
        variant_check(problem(seeing), nominal, variants, "flores")["model_variant_compared"]
    ) == ["hunt_crossley"]
    assert variant_check(problem(blind), best, ["gonthier"], "gonthier") == {}

    def diverging(variant, values):
        if variant == "flores":
            raise SimulationError("mesh deflection 0.004 m: the simulation diverged")
        return blind(variant, values)

    failed = variant_check(problem(diverging), best, variants, "flores")
    assert failed == {"model_variant_seen": None, "model_variant_compared": {"flores": None}}


def test_log_bounds_round_trip_and_clip():
    bound = Bound("mesh_stiffness", 1e8, 1e9, log=True)
    assert bound.from_unit(bound.to_unit(3e8)) == pytest.approx(3e8)
    assert bound.from_unit(0.5) == pytest.approx(np.sqrt(1e8 * 1e9))
    assert bound.from_unit(1.7) == pytest.approx(1e9)
    # a start outside the range (a nominal 0 under a log range) starts at the nearest bound
    assert bound.to_unit(0.0) == 0.0 and bound.to_unit(5e9) == 1.0


def _quadratic_spectra(law, values):
    """A cheap stand-in for a simulation: spectra that match the target at x = 0.3."""
    return np.full((1, 1, 4), 1.0 + (values["x"] - 0.3) ** 2)


def _spectra_unless_the_worker_stops_on_sigterm(law, values):
    import signal

    if signal.getsignal(signal.SIGTERM) is not signal.SIG_DFL:
        raise AssertionError("a calibration worker inherited a SIGTERM handler")
    return _quadratic_spectra(law, values)


def _spectra_or_a_dying_worker(law, values):
    import os

    if values["x"] > 0.5:
        os._exit(1)  # as a crash in native code would
    return _quadratic_spectra(law, values)


def test_calibration_workers_end_at_once_on_sigterm_even_when_the_script_catches_it():
    """The scripts turn SIGTERM into SystemExit for cleanup; the forked workers must not, or
    stopping the pool can leave one waiting for ever on the task queue's lock."""
    import signal

    previous = signal.signal(signal.SIGTERM, lambda signum, frame: None)
    try:
        calibrator = Calibrator(
            [Bound("x", 0.0, 1.0, False)],
            ["hertz"],
            strategy="per_law",
            population=4,
            generations=3,
            processes=2,
        )
        best, history = calibrator.run(
            _spectra_unless_the_worker_stops_on_sigterm, np.ones((1, 1, 4))
        )
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert len(history) == 12 and (history["error"] == "").all()
    assert best["parameters"]["x"] == pytest.approx(0.3, abs=0.15)


def test_a_calibration_worker_that_dies_fails_the_calibration_instead_of_hanging_it():
    calibrator = Calibrator(
        [Bound("x", 0.0, 1.0, False)],
        ["hertz"],
        strategy="per_law",
        population=6,
        generations=3,
        sigma0=0.5,
        processes=2,
        initial={"x": 0.9},
    )
    with pytest.raises(RuntimeError, match="calibration generation 0: a worker process died"):
        calibrator.run(_spectra_or_a_dying_worker, np.ones((1, 1, 4)))


MESH_MODELS = ("potential_energy", "simple")


# The bench's effects the model lacks, switched off: a bench of the model's own form (white noise
# only), on which calibration must find the hidden parameters.
SAME_FORM = dict(
    housing_model="point",
    shaft_model="rigid",
    coloured_noise=0.0,
    bearing_tone_force=0.0,
    motor_ripple=0.0,
    gear_deviation_share=0.0,
    misalignment=0.0,
    speed_fluctuation=0.0,
    load_fluctuation=0.0,
    faults={},
)
NO_VARIABILITY = dict(speed_fluctuation=0.0, load_fluctuation=0.0)
PERFECT_GEARS = dict(grade=[5, 5], deviation_share=[0.0, 0.0], misalignment=[0.0, 0.0])


def _bench_spectra(config, bench, speeds, channels):
    numerics = dict(config["numerics"], output_rate=config["rig"]["output_rate_hz"])
    frame = pd.DataFrame(
        virtual_bench_rows(
            lambda **overrides: build_parameters(config["model"], **overrides),
            bench,
            ["healthy"],
            [OperatingPoint(speed) for speed in speeds],
            numerics,
            0.5,
        )
    )
    spectrum, resolution = config["features"]["spectrum"], config["calibration"]["resolution_hz"]
    return measured_spectra(frame, speeds, channels, spectrum, resolution, 5120.0)


@pytest.fixture(scope="module")
def bench():
    """Healthy records at two speeds of a bench of the model's own form (the potential-energy
    mesh at the hidden truth, white sensor noise; the bench's other effects off), and the pieces
    calibration needs: a spectrum model per mesh stiffness model, without per-sample scatter
    (half-second segments, as these tests were sized: the default run's 1.5 s triples their cost)."""
    config = config_of("config/config.yaml", {"rig": {"segment_seconds": 0.5}})
    assert config["virtual_bench"]["true_parameters"]["mesh_stiffness_model"] == "potential_energy"
    speeds, channels = [450.0, 1100.0], config["features"]["channels"]
    config["model"] = dict(
        config["model"],
        variability=dict(config["model"]["variability"], **NO_VARIABILITY),
        gear_errors=PERFECT_GEARS,
    )
    same_form = dict(
        config["virtual_bench"],
        records_per_state=1,
        record_seconds=2.0,
        housing_stiffness=config["model"]["housing_stiffness"],
        **SAME_FORM,
    )
    target = _bench_spectra(config, same_form, speeds, channels)
    spectrum, resolution = config["features"]["spectrum"], config["calibration"]["resolution_hz"]
    systems = {
        m: get_system(dict(config, model=dict(config["model"], mesh_stiffness_model=m)))
        for m in MESH_MODELS
    }
    models = {
        m: SpectrumModel(systems[m], speeds, channels, spectrum, resolution, 0.5)
        for m in MESH_MODELS
    }
    return config, target, models


def true_values(config):
    """The bench's hidden parameters without its mesh model and law: (law, values)."""
    true = dict(config["virtual_bench"]["true_parameters"])
    true.pop("mesh_stiffness_model")
    return true.pop("contact_law"), true


def nominal_values(config, names):
    return {name: config["model"][name] for name in names}


@pytest.mark.slow
def test_the_true_parameters_explain_a_bench_of_the_models_form_but_not_the_virtual_bench(bench):
    """On a bench of the model's own form the model at the hidden truth, with the bench's white
    noise added to its spectra (`with_sensor_noise`), reproduces the bench's spectra, and the
    nominal model stays off. The default virtual bench differs in form (block housings, bearing
    tones, motor ripple, its own gears, coloured noise): there even the truth leaves a gap, the
    one the pipeline's measured data have to close."""
    config, target, models = bench
    model, noise = models["potential_energy"], config["virtual_bench"]["sensor_noise"]
    law, values = true_values(config)
    truth = model(law, values)
    nominal = model(config["model"]["contact_law"], nominal_values(config, values))

    def noisy(spectra):
        return with_sensor_noise(spectra, noise, model.segment_length)

    full_bench = dict(config["virtual_bench"], records_per_state=1, record_seconds=2.0)
    real = _bench_spectra(config, full_bench, [450.0, 1100.0], config["features"]["channels"])
    costs = dict(
        truth_noisy=spectrum_cost(noisy(truth), target),
        nominal_noisy=spectrum_cost(noisy(nominal), target),
        truth_on_virtual_bench=spectrum_cost(noisy(truth), real),
    )
    print(costs)
    assert costs["truth_noisy"] < 0.02
    assert costs["nominal_noisy"] > 1.5 * costs["truth_noisy"]
    assert costs["truth_on_virtual_bench"] > 3.0 * costs["truth_noisy"]


@pytest.mark.slow
@pytest.mark.parametrize("mesh_model", MESH_MODELS)
def test_calibration_recovers_the_hidden_mesh_stiffness(bench, mesh_model):
    """A bench of the model's form hides mesh stiffness 5.5e8 N/m at exponent 1.3 (nominal 4.0e8,
    1.5) behind the potential-energy mesh. K and n trade off at one load, so the check is on the
    mesh stiffness under the operating load (dF/d delta): CMA-ES over K, n and the bushing
    stiffness (a nuisance here), with the true contact law, 48 evaluations, despite the noise.
    The cost compares the noise-free model with the noisy bench, so the honest yardsticks are the
    truth's own cost and the cost once the bench's noise is added to the model's spectra. The
    simple mesh cannot explain this bench (its rectangular stiffness windows excite the mesh
    harmonics far more than the helical pair's smooth TVMS): only its gain over nominal is
    checked."""
    config, target, models = bench
    model, noise = models[mesh_model], config["virtual_bench"]["sensor_noise"]
    law, true = true_values(config)
    bounds = [
        Bound("mesh_stiffness", 1e8, 1.5e9, True),
        Bound("contact_exponent", 1.0, 2.2, False),
        Bound("bushing_stiffness", 5e7, 8e8, True),
    ]
    calibrator = Calibrator(
        bounds,
        [law],
        strategy="per_law",
        population=6,
        generations=8,
        sigma0=0.3,
        seed=3,
        processes=2,
        initial=nominal_values(config, [b.name for b in bounds]),
    )
    best, history = calibrator.run(model, target)
    nominal_spectra = model(
        config["model"]["contact_law"], nominal_values(config, [b.name for b in bounds])
    )
    best_spectra = model(law, best["parameters"])
    truth_spectra = models["potential_energy"](law, true)

    def noisy_cost(spectra):
        return spectrum_cost(with_sensor_noise(spectra, noise, model.segment_length), target)

    nominal, truth = spectrum_cost(nominal_spectra, target), spectrum_cost(truth_spectra, target)

    def stiffness(values):
        return operating_mesh_stiffness(
            build_parameters(config["model"], mesh_stiffness_model=mesh_model, **values)
        )

    found = stiffness(best["parameters"])
    expected = stiffness({k: true[k] for k in ("mesh_stiffness", "contact_exponent")})
    print(
        f"{mesh_model}: calibrated {best}, nominal cost {nominal:.4g}, truth's cost {truth:.4g}; with "
        f"the bench noise: best {noisy_cost(best_spectra):.4g}, nominal {noisy_cost(nominal_spectra):.4g}, "
        f"truth {noisy_cost(truth_spectra):.4g}; operating mesh stiffness {found:.4g} (truth {expected:.4g})"
    )
    assert len(history) == 48 and (history["error"] == "").all()
    assert best["cost"] < nominal
    if mesh_model == "potential_energy":  # the bench's own mesh: close to the truth
        # measured: cost 0.0067 (nominal 0.0177, truth 0.0019); with the bench noise 0.0048 (nominal
        # 0.0159); operating stiffness 5.19e8 against the truth's 5.63e8 (nominal 4.8e8). The
        # bushing stiffness, a nuisance here, trades against the 3-D structure, so 48 evaluations
        # do not reach the truth's own cost.
        assert best["cost"] < 0.5 * nominal
        assert noisy_cost(best_spectra) < 0.7 * noisy_cost(nominal_spectra)
        assert found == pytest.approx(expected, rel=0.1)
    else:
        assert best["cost"] < 0.2 * nominal


@pytest.mark.slow
def test_sensor_noise_estimate_is_close_to_the_bench_noise(bench):
    """On a bench of the model's form the noise floor is the bench's white noise (0.001 m/s^2).
    A low quantile of noise-only bands lies below their mean power, so the estimate reads low:
    0.78 of the truth since the sensors stopped folding mesh harmonics into the quiet bands
    (it was 1.0 with that alias under the floor). A chi-square correction of the quantile is
    future work; the band below catches an estimator that loses the floor or takes signal for it."""
    config, target, models = bench
    estimate = estimate_sensor_noise(target, models["potential_energy"].segment_length)
    assert 0.7 < estimate / config["virtual_bench"]["sensor_noise"] < 1.2


@pytest.mark.slow
def test_sensor_noise_estimate_does_not_take_the_form_gap_for_noise(bench):
    """On the default virtual bench the model lacks housing modes, bearing tones, motor ripple
    and coloured noise. Those raise the measured spectra above the model's in most bands but
    not the floor: the estimate stays near the bench's white plus coloured noise (1 and
    2 mm/s^2, most of the coloured below the floor's bands), not the several times larger excess
    the old median-of-excess estimate returned (6.3 mm/s^2 in the default run). The bench's gears
    are perfect here: a real pair's errors put lines at every shaft order, in every band, which is
    machine content and no floor at all (12.8 mm/s^2 with the default bench's grade-5 gears); the
    gear configs take the background the healthy records carry instead (calibration.background)."""
    config, _, models = bench
    full_bench = dict(
        config["virtual_bench"],
        records_per_state=1,
        record_seconds=2.0,
        gear_deviation_share=0.0,
        misalignment=0.0,
    )
    real = _bench_spectra(config, full_bench, [450.0, 1100.0], config["features"]["channels"])
    estimate = estimate_sensor_noise(real, models["potential_energy"].segment_length)
    print(f"noise floor on the virtual bench: {estimate:.4g} m/s^2")
    # the quantile of noise-only bands reads low (0.78 of white noise alone: estimate_sensor_noise)
    assert 0.7 * config["virtual_bench"]["sensor_noise"] <= estimate < 2.5e-3


def test_sensor_noise_estimate_names_a_bad_quantile():
    with pytest.raises(ValueError, match="noise_floor_quantile"):
        estimate_sensor_noise(np.ones((1, 1, 4)), 256, floor_quantile=1.0)

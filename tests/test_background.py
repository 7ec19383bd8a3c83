"""The background healthy records carry and the model lacks: its estimates (the part of each channel
no other channel explains; measured minus model PSD, clipped at zero) and its synthesis (a
random-phase Gaussian realisation of a stored PSD)."""

import numpy as np
import pandas as pd
import pytest
from scipy.signal import lfilter

from conftest import ROOT, config_of
from condmon.background import (
    Background,
    background_psd,
    estimate_background,
    incoherent_psd,
    segment_psd,
    synthesise,
)
from condmon.seeds import job_rng
from condmon.signals import make_rows
from condmon.systems import get_system

FS, N = 2048.0, 512  # the toy system's rate and segment length: 4 Hz bins
TOY = {
    "run_name": "toy-background",
    "system": "toy",
    "system_modules": [str(ROOT / "tests" / "toy_system.py")],
    "features": {
        "channels": ["acc"],
        "spectrum": {
            "f_min_hz": 0.0,
            "f_max_hz": 1000.0,
            "resolution_hz": 8.0,
            "scale": "log",
            "band_statistic": "rms",
        },
    },
    "calibration": {"resolution_hz": 8.0},
}


def band_powers(freqs, psd, edges):
    """Power (integral of the PSD) in each band [edges[i], edges[i + 1])."""
    df = freqs[1] - freqs[0]
    return np.array(
        [psd[(freqs >= lo) & (freqs < hi)].sum() * df for lo, hi in zip(edges[:-1], edges[1:])]
    )


def db(ratio):
    return 10 * np.log10(ratio)


def coloured_psd(freqs, white_rms, pole):
    """One-sided PSD of white noise of RMS `white_rms` through 1 / (1 - pole z^-1)."""
    return 2 * white_rms**2 / FS / np.abs(1 - pole * np.exp(-2j * np.pi * freqs / FS)) ** 2


def test_the_synthesised_noise_has_the_stored_psd():
    """A coloured floor with a bump and a tone-like peak: the Welch PSD of a long realisation,
    cut into segments, matches the stored PSD within 1 dB in every 64 Hz band and in total power."""
    freqs = np.fft.rfftfreq(N, 1 / FS)
    psd = coloured_psd(freqs, 0.01, 0.9) + 1e-6 * np.exp(-(((freqs - 600) / 40) ** 2))
    psd[np.argmin(abs(freqs - 300))] += 1e-4
    signal = synthesise(freqs, psd, 256 * N, FS, np.random.default_rng(7))
    got_freqs, got = segment_psd(signal.reshape(-1, 1, N), FS)
    edges = np.arange(0.0, FS / 2 + 1, 64.0)
    error = db(band_powers(got_freqs, got[0], edges) / band_powers(freqs, psd, edges))
    print(np.round(error, 2))
    assert np.abs(error).max() < 1.0
    assert db(signal.var() / (psd.sum() * (freqs[1] - freqs[0]))) == pytest.approx(0.0, abs=0.5)


def test_a_realisation_on_another_length_keeps_the_density():
    """A sample of 2.5 segments (the PSD interpolated onto its own grid) has the stored total power."""
    freqs = np.fft.rfftfreq(N, 1 / FS)
    psd = coloured_psd(freqs, 0.01, 0.5)
    powers = [
        synthesise(freqs, psd, int(2.5 * N), FS, np.random.default_rng(seed)).var()
        for seed in range(200)
    ]
    assert db(np.mean(powers) / (psd.sum() * (freqs[1] - freqs[0]))) == pytest.approx(0.0, abs=0.3)


def test_same_stream_same_realisation_other_batch_other_realisation():
    table = pd.DataFrame(
        dict(
            speed_rpm=600.0,
            channel="acc",
            freq_hz=np.fft.rfftfreq(N, 1 / FS),
            measured_psd=1e-5,
            model_psd=0.0,
            background_psd=1e-5,
        )
    )
    background = Background(table)
    zeros = {"acc": np.zeros(2 * N)}

    def realisation(batch, sample_seed):
        # the simulate job's order: the job's stream gives the sample seed, the sample seed the noise
        seed = (
            int(job_rng(1, "simulate", "healthy", 600.0, batch).integers(2**32))
            if sample_seed is None
            else sample_seed
        )
        return background.add(zeros, 600.0, FS, job_rng(seed, "background"))[0]["acc"]

    assert np.array_equal(realisation(0, None), realisation(0, None))
    assert not np.allclose(realisation(0, None), realisation(1, None))
    assert np.corrcoef(realisation(0, None), realisation(1, None))[0, 1] < 0.2


def test_the_nearest_measured_speed_gives_a_simulated_speed_its_background_and_bare_channels_are_named():
    freqs = np.fft.rfftfreq(N, 1 / FS)
    table = pd.concat(
        [
            pd.DataFrame(
                dict(
                    speed_rpm=speed,
                    channel="acc",
                    freq_hz=freqs,
                    measured_psd=level,
                    model_psd=0.0,
                    background_psd=level,
                )
            )
            for speed, level in ((450.0, 1e-6), (1100.0, 1e-3))
        ]
    )
    background = Background(table)
    assert background.source_speed(775.0) == 450.0 and background.source_speed(800.0) == 1100.0
    out, bare = background.add(
        {"acc": np.zeros(N), "other": np.ones(N)}, 900.0, FS, np.random.default_rng(0)
    )
    assert bare == ["other"] and np.array_equal(out["other"], np.ones(N))
    assert out["acc"].std() == pytest.approx(np.sqrt(1e-3 * FS / 2), rel=0.2)


def test_clipped_at_zero_where_the_model_has_more_power():
    measured, model = np.array([[1.0, 2.0, 3.0]]), np.array([[0.5, 2.5, 3.0]])
    assert background_psd(measured, model).tolist() == [[0.5, 0.0, 0.0]]


@pytest.fixture(scope="module")
def toy():
    return get_system(config_of(TOY))


def toy_frame(toy, extra, records=16, seconds=1.0, scale=1.0):
    """Healthy 600 rpm records of the toy's nominal model (`scale` times its signal) plus
    `extra(rng, n)`: what a bench with a background the model lacks would record."""
    rng = np.random.default_rng(11)
    rows = []
    for r in range(records):
        signal = scale * toy.simulate_sample({}, "healthy", 600.0, seconds, seed=r)["acc"]
        rows += make_rows(
            f"bench-{r}",
            "virtual_bench",
            "healthy",
            600.0,
            0.0,
            FS,
            {"acc": signal + extra(rng, len(signal))},
            segment_length=toy.segment_length,
        )
    return pd.DataFrame(rows)


def test_a_coloured_noise_and_a_tone_the_model_lacks_are_recovered(toy):
    """Records of the toy's own model plus white noise, a coloured floor and a tone at 317 Hz:
    the background is that floor (within 1.5 dB per 64 Hz band away from the tone, the model's
    own 10 Hz line cancelled) and the tone's power (within 2 dB over its band)."""
    white, coloured, pole, tone = 0.003, 0.02, 0.95, 0.05

    def extra(rng, n):
        t = np.arange(n) / FS
        noise = rng.normal(0, white, n) + lfilter([1.0], [1.0, -pole], rng.normal(0, coloured, n))
        return noise + tone * np.sin(2 * np.pi * 317.0 * t + rng.uniform(0, 2 * np.pi))

    frame = toy_frame(toy, extra)
    calibrated = {"model_variant": toy.nominal_variant, "parameters": {}}
    table = estimate_background(
        toy,
        frame,
        calibrated,
        ["acc"],
        runs=2,
        sim_seconds=1.0,
        seed=3,
        processes=2,
        method="deficit",
    )
    assert sorted(table["speed_rpm"].unique()) == [600.0]  # the only speed with healthy records
    freqs, got = table["freq_hz"].to_numpy(), table["background_psd"].to_numpy()
    truth = 2 * white**2 / FS + coloured_psd(freqs, coloured, pole)
    in_tone = np.abs(freqs - 317.0) <= 20.0
    edges = np.arange(0.0, FS / 2 + 1, 64.0)
    away = band_powers(freqs, np.where(in_tone, 0.0, got), edges) / band_powers(
        freqs, np.where(in_tone, 0.0, truth), edges
    )
    tone_band = got[in_tone].sum() * 4.0 / (tone**2 / 2 + truth[in_tone].sum() * 4.0)
    print(np.round(db(away), 2), round(float(db(tone_band)), 2))
    assert np.abs(db(away)).max() < 1.5  # the 0-64 Hz band holds the model's 10 Hz line: it cancels
    assert abs(db(tone_band)) < 2.0
    again = estimate_background(
        toy,
        frame,
        calibrated,
        ["acc"],
        runs=2,
        sim_seconds=1.0,
        seed=3,
        processes=1,
        method="deficit",
    )
    pd.testing.assert_frame_equal(table, again)  # any core count, the same numbers


def test_the_background_is_zero_where_the_model_is_louder_than_the_measurement(toy):
    """Records at half the model's amplitude: at its 10 Hz line the model has more power than
    the measurement, and the background there is zero, not negative."""
    frame = toy_frame(toy, lambda rng, n: rng.normal(0, 1e-4, n), records=2, scale=0.5)
    table = estimate_background(
        toy,
        frame,
        {"model_variant": toy.nominal_variant, "parameters": {}},
        ["acc"],
        runs=1,
        sim_seconds=1.0,
        seed=3,
        method="deficit",
    )
    line = (table["freq_hz"] - 10.0).abs() <= 4.0
    assert (table.loc[line, "model_psd"] > table.loc[line, "measured_psd"]).all()
    assert (table.loc[line, "background_psd"] == 0.0).all() and (table["background_psd"] >= 0).all()


def test_no_healthy_record_at_a_simulated_speed_gives_no_background(toy):
    frame = toy_frame(toy, lambda rng, n: 0.0, records=1).assign(speed_rpm=700.0)
    table = estimate_background(
        toy,
        frame,
        {"model_variant": toy.nominal_variant, "parameters": {}},
        ["acc"],
        runs=1,
        sim_seconds=1.0,
        seed=3,
        method="deficit",
    )
    assert table.empty and not Background(table)


def test_the_part_no_other_channel_explains_is_the_sensor_noise_whatever_the_structure_does():
    """Four channels of one structural source (gains g, 100x the noise) plus independent white
    noise N_i: the incoherent PSD of channel i is N_i + g_i^2 / sum_(j != i) g_j^2 / N_j (the
    source's estimate from the other channels errs by that), within 1 dB over 128 Hz bands. Three
    times the structural vibration (a model that quiet would leave a deficit of 8x its power)
    moves it by less than 0.3 dB."""
    gains, sigma = np.array([1.0, 0.5, 2.0, 1.5]), np.array([0.003, 0.01, 0.002, 0.005])
    n, fs = 2560, 5120.0

    def segments(level, seed=4):
        rng = np.random.default_rng(seed)
        source = level * rng.normal(0, 1.0, (12, 1, n))
        return gains[None, :, None] * source + sigma[None, :, None] * rng.normal(0, 1.0, (12, 4, n))

    freqs, got = incoherent_psd(segments(1.0), fs, 512)
    noise = 2 * sigma**2 / fs
    expected = noise + gains**2 / np.array(
        [np.sum(np.delete(gains**2 / noise, i)) for i in range(4)]
    )
    edges = np.arange(0.0, fs / 2 + 1, 128.0)
    for i in range(4):
        bands = band_powers(freqs, got[i], edges) / band_powers(
            freqs, np.full_like(freqs, expected[i]), edges
        )
        assert np.abs(db(bands[1:])).max() < 1.0, (i, np.round(db(bands), 2))
    _, louder = incoherent_psd(segments(3.0), fs, 512)
    assert np.abs(db(louder[:, 1:].sum(1) / got[:, 1:].sum(1))).max() < 0.3
    with pytest.raises(ValueError, match="two or more channels"):
        incoherent_psd(segments(1.0)[:, :1], fs, 512)


def test_the_incoherent_background_of_one_channel_is_refused_before_any_run(toy):
    from condmon.config import ConfigError

    with pytest.raises(ConfigError, match="calibration.background_method: incoherent"):
        config_of(TOY, {"calibration": {"background": True}})
    assert config_of(TOY, {"calibration": {"background": True, "background_method": "deficit"}})
    frame = toy_frame(toy, lambda rng, n: 0.0, records=1)
    with pytest.raises(ValueError, match="background_method incoherent.*two or more channels"):
        estimate_background(
            toy,
            frame,
            {"model_variant": toy.nominal_variant, "parameters": {}},
            ["acc"],
            runs=1,
            sim_seconds=1.0,
            seed=3,
        )

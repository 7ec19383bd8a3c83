"""Known-answer tests of the statistical and envelope features; their check on real CWRU data."""

import numpy as np
import pandas as pd
import pytest

from conftest import CWRU
from condmon import stat_features as sf
from condmon.stat_features import StatisticalFeatures
from condmon.systems.bearing.model import bearing_defaults, feature_orders

FS = 1000.0
N = 1000
T = np.arange(N) / FS


# The envelope lines the bearing system gives its features (its default drive-end bearing): the
# extractor itself has none of its own (tests/test_bearing_model.py checks the orders).
ORDERS = feature_orders(bearing_defaults()["geometry"])


def test_without_defect_orders_there_are_no_envelope_features():
    X = np.random.default_rng(3).normal(size=(2, 2048))
    for orders in (None, {}):
        est = StatisticalFeatures(defect_orders=orders)
        assert list(est.get_feature_names_out()) == list(sf.STUDY_FEATURES)
        assert est.fit_transform(X).shape == (2, 15)  # and no speed needed


# -- time domain -----------------------------------------------------------------------------
def test_time_features_of_a_sine():
    a = 2.0
    x = a * np.cos(2 * np.pi * 10 * T)  # whole periods, the peak is sampled
    assert sf.mean(x) == pytest.approx(0.0, abs=1e-12)
    assert sf.std(x) == pytest.approx(a / np.sqrt(2))
    assert sf.rms(x) == pytest.approx(a / np.sqrt(2))
    assert sf.peak(x) == pytest.approx(a)
    assert sf.kurtosis(x) == pytest.approx(1.5)
    assert sf.skewness(x) == pytest.approx(0.0, abs=1e-9)
    assert sf.crest_factor(x) == pytest.approx(np.sqrt(2))
    # mean |x| of 100 samples per period is within 1e-3 of the continuous 2 A / pi
    assert sf.impulse_factor(x) == pytest.approx(np.pi / 2, rel=1e-3)
    assert sf.shape_factor(x) == pytest.approx(np.pi / (2 * np.sqrt(2)), rel=1e-3)


def test_moments_of_a_two_point_distribution():
    p = 0.1  # x = 1 with probability p, else 0: closed-form moments
    x = np.zeros(1000)
    x[:100] = 1.0
    q = p * (1 - p)
    assert sf.mean(x) == pytest.approx(p)
    assert sf.std(x) == pytest.approx(np.sqrt(q))
    assert sf.skewness(x) == pytest.approx((1 - 2 * p) / np.sqrt(q))
    assert sf.kurtosis(x) == pytest.approx((1 - 6 * q) / q + 3)
    assert sf.impulse_factor(x) == pytest.approx(1 / p)


def test_square_wave_and_gaussian_noise():
    square = np.where(np.arange(N) % 20 < 10, 3.0, -3.0)
    for f in (sf.kurtosis, sf.crest_factor, sf.impulse_factor, sf.shape_factor):
        assert f(square) == pytest.approx(1.0)
    noise = np.random.default_rng(1).normal(0, 1, 200_000)
    assert sf.kurtosis(noise) == pytest.approx(3.0, abs=0.05)
    assert sf.skewness(noise) == pytest.approx(0.0, abs=0.03)
    assert sf.shape_factor(noise) == pytest.approx(np.sqrt(np.pi / 2), rel=1e-2)


def test_talaf_and_thikat_formulas():
    a, r0 = 2.0, 0.5
    x = a * np.cos(2 * np.pi * 10 * T)
    rms, kurt, cf = a / np.sqrt(2), 1.5, np.sqrt(2)
    assert sf.talaf(x, r0) == pytest.approx(np.log(kurt + rms / r0))
    assert sf.thikat(x, r0) == pytest.approx(np.log(kurt**cf + (rms / r0) ** a))
    # A large peak would overflow the direct formula; the log-space form stays finite.
    big = 400.0 * np.cos(2 * np.pi * 10 * T)
    value = sf.thikat(big, 1e-3)
    assert np.isfinite(value)
    assert value == pytest.approx(400.0 * np.log(400 / np.sqrt(2) / 1e-3), rel=1e-9)


def test_features_work_on_stacks():
    x = np.stack([np.cos(2 * np.pi * 10 * T), 3 * np.cos(2 * np.pi * 10 * T)])
    assert sf.rms(x) == pytest.approx([1 / np.sqrt(2), 3 / np.sqrt(2)])
    assert sf.kurtosis(x) == pytest.approx([1.5, 1.5])
    assert sf.frequency_centre(x, FS) == pytest.approx([10.0, 10.0])


# -- frequency domain ------------------------------------------------------------------------
def test_frequency_features_of_a_sine_at_a_bin():
    # Hann: a bin-centred line of amplitude A shows as A/2, A, A/2 on three bins (df = 1 Hz).
    a, f0, df = 2.0, 100.0, FS / N
    x = a * np.sin(2 * np.pi * f0 * T)
    k = N // 2 + 1
    assert sf.mean_frequency(x, FS) == pytest.approx(2 * a / k, rel=1e-6)
    assert sf.frequency_centre(x, FS) == pytest.approx(f0, rel=1e-9)
    assert sf.rms_frequency(x, FS) == pytest.approx(np.sqrt(f0**2 + df**2 / 2), rel=1e-9)
    assert sf.std_frequency(x, FS) == pytest.approx(df / np.sqrt(2), rel=1e-6)


def test_frequency_centre_of_two_lines():
    x = 1.0 * np.sin(2 * np.pi * 50 * T) + 3.0 * np.sin(2 * np.pi * 250 * T)
    assert sf.frequency_centre(x, FS) == pytest.approx((50 + 3 * 250) / 4, rel=1e-9)
    fc = sf.frequency_centre(x, FS)
    assert sf.rms_frequency(x, FS) ** 2 == pytest.approx(fc**2 + sf.std_frequency(x, FS) ** 2)


# -- filters ---------------------------------------------------------------------------------
def test_highpass_removes_offset_and_drift_and_keeps_the_band():
    fs, n = 12000.0, 4096
    t = np.arange(n) / fs
    rng = np.random.default_rng(2)
    content = np.sin(2 * np.pi * 500 * t) + 0.3 * rng.normal(size=n)
    x = content + 0.25 + 0.5 * np.sin(2 * np.pi * 1.0 * t)  # DC offset and a 1 Hz drift
    y = sf.highpass(x, fs, 10.0)
    assert abs(y.mean()) < 1e-3
    assert sf.rms(y) == pytest.approx(sf.rms(content - content.mean()), rel=0.01)
    # no edge transients (the default short odd padding raised the RMS at the edges)
    assert sf.rms(y[:200]) == pytest.approx(sf.rms(content[:200]), rel=0.1)
    assert sf.highpass(x, fs, None).mean() == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError):
        sf.highpass(x, fs, 7000.0)


# -- envelope --------------------------------------------------------------------------------
def am_signal(mod_hz, m=0.5, fs=12000.0, n=4096, carrier_hz=3500.0, noise=0.05, seed=3):
    t = np.arange(n) / fs
    rng = np.random.default_rng(seed)
    return (1 + m * np.cos(2 * np.pi * mod_hz * t)) * np.sin(
        2 * np.pi * carrier_hz * t
    ) + noise * rng.normal(size=n)


def test_envelope_spectrum_line_amplitude_and_band_energy():
    fs, m, fm = 12000.0, 0.5, 107.3
    x = am_signal(fm, m)
    freqs, amps = sf.envelope_spectrum(x, fs)
    line = amps[np.abs(freqs - fm) < 1.5].max()
    assert line == pytest.approx(m, rel=0.05)  # envelope 1 + m cos: line of amplitude m
    assert sf.envelope_band_energy(x, fs, fm) == pytest.approx(m**2 / 2, rel=0.05)
    assert sf.envelope_band_energy(x, fs, 1.7 * fm) < 1e-3 * m**2


def test_band_power_sums_the_band_at_least_two_bins_either_side():
    freqs = np.arange(0.0, 101.0)  # 1 Hz bins
    density = np.ones((2, len(freqs)))
    # 50 Hz +/- 10 %: 45..55 Hz, 11 bins; at 10 Hz +/- 1 Hz is narrower than the main lobe: 8..12 Hz
    assert sf.band_power(freqs, density, [50.0, 10.0], 0.1) == pytest.approx([11.0, 5.0])
    assert sf.band_power(freqs, density, 10.0, 0.015) == pytest.approx([5.0, 5.0])


def test_envelope_line_ratio_known_spectrum():
    freqs = np.arange(0, 200, 0.5)
    amps = np.ones_like(freqs)
    amps[np.abs(freqs - 100) < 0.3] = 10.0
    assert sf.envelope_line_ratio(freqs, amps, 100.0) == pytest.approx([10.0])
    assert sf.envelope_line_ratio(freqs, amps, 60.0) == pytest.approx([1.0])
    # one line window per segment
    both = np.stack([amps, amps])
    assert sf.envelope_line_ratio(freqs, both, [100.0, 60.0]) == pytest.approx([10.0, 1.0])


def test_transformer_names_the_modulated_defect_order():
    speed_rpm = 1796.0
    shaft = speed_rpm / 60
    orders = ORDERS
    X = np.stack([am_signal(orders[k] * shaft, seed=i) for i, k in enumerate(["bpfo", "bpfi"])])
    est = StatisticalFeatures(defect_orders=ORDERS)
    frame = pd.DataFrame(
        est.fit_transform(X, speed_rpm=speed_rpm), columns=est.get_feature_names_out()
    )
    ratios = frame[["env_ratio_bpfo", "env_ratio_bpfi", "env_ratio_bsf_x2"]]
    assert list(ratios.idxmax(axis=1)) == ["env_ratio_bpfo", "env_ratio_bpfi"]
    assert ratios.max(axis=1).min() > 50
    assert frame.loc[0, "env_energy_bpfo"] > 100 * frame.loc[0, "env_energy_bpfi"]


def test_transformer_contract():
    est = StatisticalFeatures(prefix="DE_", defect_orders=ORDERS)
    names = list(est.get_feature_names_out())
    assert names[:15] == ["DE_" + n for n in sf.STUDY_FEATURES]
    assert len(names) == 15 + 2 * 4
    rng = np.random.default_rng(4)
    X = rng.normal(size=(3, 4096))
    speeds = np.array([1796.0, 1772.0, 1750.0])
    out = est.fit_transform(X, speed_rpm=speeds)
    assert out.shape == (3, len(names)) and np.isfinite(out).all()
    # a DC offset (differs between CWRU records) changes nothing after the high-pass
    shifted = est.transform(X + 0.3, speeds)
    assert shifted == pytest.approx(out, rel=1e-6, abs=1e-9)
    # study features only
    plain = StatisticalFeatures(envelope=False).fit_transform(X)
    assert plain.shape == (3, 15)
    assert plain == pytest.approx(out[:, :15])
    with pytest.raises(ValueError, match="speed"):
        est.transform(X)
    with pytest.raises(ValueError, match="positive"):
        est.transform(X, [1796.0, -1.0, 1750.0])
    with pytest.raises(ValueError, match="n_segments, n_samples"):
        est.transform(X[0], 1796.0)
    with pytest.raises(ValueError, match="band_hz"):
        StatisticalFeatures(band_hz=(2000.0, 7000.0)).fit(X)
    with pytest.raises(ValueError, match="NaN"):
        est.transform(np.where(X > 2, np.nan, X), speeds)


def test_transformer_pandas_output():
    est = StatisticalFeatures(envelope=False).set_output(transform="pandas")
    frame = est.fit_transform(np.random.default_rng(5).normal(size=(2, 1024)))
    assert list(frame.columns) == list(sf.STUDY_FEATURES)


# -- real data -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cwru_features():
    if not CWRU.is_dir():
        pytest.skip(f"CWRU data folder {CWRU} not present")
    from condmon.systems.bearing.cwru import cwru_rows
    from condmon.signals import to_arrays

    ingest = cwru_rows(CWRU, task="ten_class")
    ids, arrays = to_arrays(pd.DataFrame(ingest.rows), ["DE"])
    est = StatisticalFeatures(defect_orders=ORDERS)
    values = est.fit_transform(arrays[:, 0], speed_rpm=ids["speed_rpm"].to_numpy())
    frame = pd.concat([ids, pd.DataFrame(values, columns=est.get_feature_names_out())], axis=1)
    ratios = frame[["env_ratio_bpfo", "env_ratio_bpfi", "env_ratio_bsf_x2"]].to_numpy()
    frame["named"] = np.array(["outer_race", "inner_race", "ball"])[ratios.argmax(axis=1)]
    frame["location"] = frame["health_state"].str.replace(r"_0\.\d+in$", "", regex=True)
    return frame


def test_envelope_ratios_name_the_location_on_real_data(cwru_features):
    frame = cwru_features
    strong = frame["health_state"].isin(
        [
            "inner_race_0.007in",
            "inner_race_0.014in",
            "inner_race_0.021in",
            "outer_race_0.007in",
            "outer_race_0.021in",
        ]
    )
    assert strong.sum() >= 200
    wrong = frame.loc[
        strong & (frame["named"] != frame["location"]),
        ["record_id", "segment", "health_state", "named"],
    ]
    assert wrong.empty, f"envelope ratios name the wrong location:\n{wrong}"
    # the winning line stands above the floor on every segment (the squared envelope spectrum's
    # line over its local median: 2.7 on the weakest segment, 4-27 per record)
    winner = frame.loc[strong, ["env_ratio_bpfo", "env_ratio_bpfi"]].max(axis=1)
    assert winner.min() > 2.5 and winner.median() > 5
    # ball faults are weak (not asserted beyond being computed); report the hit rates
    hits = (frame["named"] == frame["location"]).groupby(frame["health_state"]).mean()
    print("\nenvelope-ratio location hit rate per class:\n" + hits.round(3).to_string())


def test_study_features_on_real_data_match_the_readme(cwru_features):
    frame = cwru_features
    per_record = frame.groupby("record_id")[["rms", "kurtosis"]].median()
    g = 9.80665
    assert per_record.loc["cwru-97", "rms"] / g == pytest.approx(0.072, rel=0.05)
    assert per_record.loc["cwru-131", "rms"] / g == pytest.approx(0.58, rel=0.1)
    assert per_record.loc["cwru-198", "rms"] / g == pytest.approx(0.095, rel=0.1)
    assert per_record.loc["cwru-235", "rms"] / g == pytest.approx(0.56, rel=0.1)
    for rid in ("cwru-130", "cwru-131"):
        assert 7.0 < per_record.loc[rid, "kurtosis"] < 8.5
    for rid in ("cwru-197", "cwru-198"):
        assert 2.6 < per_record.loc[rid, "kurtosis"] < 4.0
    for rid in ("cwru-234", "cwru-235"):
        assert 17 < per_record.loc[rid, "kurtosis"] < 24
    # README: segment kurtosis spans about 3 to 33 across the faults
    assert 2.5 < frame["kurtosis"].min() and frame["kurtosis"].max() < 40
    # the high-pass removes the records' DC offsets (0.03-0.23 m/s^2 = 0.003-0.023 g): what is
    # left of a segment mean is slow content the filter attenuates, below 0.01 m/s^2
    assert frame["mean"].abs().max() < 0.01


def test_statistical_feature_table_keeps_names_logs_and_prefixes_channels():
    from condmon.features import FeatureTableError
    from condmon.signals import make_rows
    from condmon.features import statistical_feature_table

    rng = np.random.default_rng(0)
    fs, n = 12000.0, 4096
    rows = []
    for rec, speed in (("a", 1797.0), ("b", 1772.0)):
        rows += make_rows(
            rec,
            "measured",
            "normal",
            speed,
            0.0,
            fs,
            {"DE": rng.normal(size=2 * n), "FE": 3 * rng.normal(size=2 * n)},
            segment_length=n,
        )
    frame = pd.DataFrame(rows)
    params = {"names": ["rms", "kurtosis", "env_ratio_bpfo"], "log_names": ["kurtosis"]}
    table = statistical_feature_table(frame, ["DE", "FE"], params, ORDERS)
    features = [c for c in table.columns if c.startswith(("DE_", "FE_"))]
    assert features == [
        "DE_rms",
        "DE_log_kurtosis",
        "DE_env_ratio_bpfo",
        "FE_rms",
        "FE_log_kurtosis",
        "FE_env_ratio_bpfo",
    ]
    assert len(table) == 4 and list(table.record_id) == ["a", "a", "b", "b"]
    assert table["FE_rms"].mean() == pytest.approx(3 * table["DE_rms"].mean(), rel=0.1)
    # Gaussian noise: kurtosis 3, so its log is log(3)
    assert table["DE_log_kurtosis"].to_numpy() == pytest.approx(np.log(3.0), abs=0.15)
    with pytest.raises(FeatureTableError, match=r"unknown feature\(s\) \['loudness'\]"):
        statistical_feature_table(frame, ["DE"], {"names": ["rms", "loudness"]})
    with pytest.raises(FeatureTableError, match="BA"):
        statistical_feature_table(frame, ["BA"], {})


def test_the_envelope_analysis_comes_from_the_config_section():
    from condmon.stat_features import statistical_features_from_params

    params = {
        "band_hz": [1000.0, 4000.0],
        "envelope": {
            "band": "kurtogram",
            "prewhiten": True,
            "harmonics": 2,
            "kurtogram_max_level": 3,
        },
        "line_sidebands": {"bpfi": 1.0},
    }
    est = statistical_features_from_params(
        params, 12000.0, defect_orders={"bpfo": 3.585, "bpfi": 5.415}
    )
    assert est.analysis() == "prewhitened_kurtogram"
    assert est.envelope_analysis == {
        "band": "kurtogram",
        "prewhiten": True,
        "harmonics": 2,
        "kurtogram_max_level": 3,
        "sidebands": {"bpfi": 1.0},
    }
    assert est.band_hz == (1000.0, 4000.0)
    X = np.random.default_rng(1).normal(size=(3, 4096))
    values = est.fit_transform(X, speed_rpm=1797.0)
    assert values.shape == (3, 19) and np.isfinite(values).all()
    with pytest.raises(ValueError, match="envelope_analysis band 'cepstrum'"):
        StatisticalFeatures(
            envelope_analysis={"band": "cepstrum"}, defect_orders={"bpfo": 3.0}
        ).fit(X)
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['bands'\]"):
        StatisticalFeatures(envelope_analysis={"bands": "fixed"}, defect_orders={"bpfo": 3.0}).fit(
            X
        )

"""Order-domain gear diagnostics: condition indicators against their published values, tacholess
angular resampling and the TSA on a gear-model record, the feature family in the pipeline.

The record: `condmon.models.gear.drivetrain.simulate` at its default (healthy) parameters, 1100 rpm,
with a 0.2 % speed fluctuation at 1.5 Hz, 1.5 s (three 0.5 s segments as the default rig's), about 5 s
of CPU once per module. Patterns are added to it at the shaft angle the model itself turns by (the
mesh phase of `speed_fluctuation`, `speed_fluctuation_hz`, `speed_fluctuation_phase`), so the test
knows the truth the tracking has to find.
"""

import logging

import numpy as np
import pandas as pd
import pytest

from condmon.features import (
    FeatureTableError,
    SystemFamily,
    compute_feature_table_from_files,
    feature_families,
)
from condmon.systems.gear.order_features import (
    INDICATORS,
    OrderFeatures,
    angular_resample,
    condition_indicators,
    difference_signal,
    energy_ratio,
    fm0,
    fm4,
    keep_orders,
    m6a,
    m8a,
    na4,
    order_feature_table,
    regular_signal,
    residual_signal,
    shaft_angle,
    sideband_level_factor,
    time_synchronous_average,
)
from condmon.signals import make_rows, write_signal_table
from conftest import config_of, system_of

FS = 5120.0
SPEED_RPM = 1100.0
SHAFT_HZ = SPEED_RPM / 60
TEETH_PINION, TEETH_GEAR = 29, 44
SHAFTS = [("pinion", 1.0, TEETH_PINION), ("gear", TEETH_PINION / TEETH_GEAR, TEETH_GEAR)]
CHANNELS = ["A1_x", "A1_y", "A2_x", "A2_y"]
FLUCTUATION, FLUCTUATION_HZ, FLUCTUATION_PHASE = 0.002, 1.5, 0.7
SEGMENT = 2560  # 0.5 s
P = 1024


@pytest.fixture(scope="module")
def record():
    """(signals (channels, samples), pinion angle in revolutions at every sample)."""
    from condmon.models.gear.drivetrain import (
        GearDrivetrainParameters,
        SimulationSettings,
        simulate,
    )

    params = GearDrivetrainParameters(
        speed_rpm=SPEED_RPM,
        speed_fluctuation=FLUCTUATION,
        speed_fluctuation_hz=FLUCTUATION_HZ,
        speed_fluctuation_phase=FLUCTUATION_PHASE,
    )
    settings = SimulationSettings(duration=1.5)
    signals = simulate(params, settings)
    n = len(signals["A1_x"])
    # the model's shaft angle: speed f0 (1 + a sin(w t + phase)), t from the start of the settling
    t = settings.settle_time + np.arange(n) / FS
    w = 2 * np.pi * FLUCTUATION_HZ
    angle = SHAFT_HZ * (
        t + FLUCTUATION * (np.cos(FLUCTUATION_PHASE) - np.cos(w * t + FLUCTUATION_PHASE)) / w
    )
    return np.stack([signals[c] for c in CHANNELS]).astype(np.float64), angle


def segments(signals):
    return np.stack(
        [signals[:, i * SEGMENT : (i + 1) * SEGMENT] for i in range(signals.shape[1] // SEGMENT)]
    )


# -- indicators: published values ----------------------------------------------------------------
def test_moment_indicators_of_gaussian_noise_match_the_normal_moments():
    """FM4 and NA4 are kurtoses (3 for Gaussian noise, Zakrajsek et al. 1993); M6A and M8A the 6th
    and 8th normalised moments (15 and 105)."""
    noise = np.random.default_rng(0).normal(size=400_000)
    assert fm4(noise) == pytest.approx(3.0, abs=0.05)
    assert na4(noise) == pytest.approx(3.0, abs=0.05)
    assert m6a(noise) == pytest.approx(15.0, rel=0.05)
    assert m8a(noise) == pytest.approx(105.0, rel=0.12)


def test_fm4_and_na4_of_a_noise_tsa_stay_near_three():
    """Through the whole path: the TSA of noise (64 revolutions), its difference and residual
    signals are Gaussian again."""
    rng = np.random.default_rng(1)
    values = []
    for _ in range(20):
        tsa = time_synchronous_average(rng.normal(size=64 * P), P)
        values.append((fm4(difference_signal(tsa, 29)), na4(residual_signal(tsa, 29))))
    assert np.mean(values, axis=0) == pytest.approx([3.0, 3.0], abs=0.1)


def test_fm0_energy_ratio_and_sideband_level_factor_of_known_signals():
    theta = np.arange(P) / P
    mesh, sidebands, other = 2.0, (0.3, 0.1), 0.5
    tsa = (
        mesh * np.cos(2 * np.pi * 29 * theta)
        + sidebands[0] * np.cos(2 * np.pi * 28 * theta)
        + sidebands[1] * np.cos(2 * np.pi * 30 * theta + 1.0)
        + other * np.sin(2 * np.pi * 7 * theta)
    )
    # SLF = (A_28 + A_30) / sigma
    assert sideband_level_factor(tsa, 29) == pytest.approx(0.4 / tsa.std(), rel=1e-9)
    # regular: the mesh line only (orders 1, 2 absent); difference: order 7 only
    assert regular_signal(tsa, 29) == pytest.approx(mesh * np.cos(2 * np.pi * 29 * theta), abs=1e-9)
    difference = difference_signal(tsa, 29)
    assert difference == pytest.approx(other * np.sin(2 * np.pi * 7 * theta), abs=1e-9)
    assert energy_ratio(difference, regular_signal(tsa, 29)) == pytest.approx(
        other / mesh, rel=1e-9
    )
    # FM0 of a pure mesh tone: peak-to-peak 2A over the mesh amplitude A
    assert fm0(mesh * np.cos(2 * np.pi * 29 * theta), 29) == pytest.approx(2.0, rel=1e-9)
    # a sine's kurtosis is 1.5
    assert fm4(difference) == pytest.approx(1.5, rel=1e-9)
    values = condition_indicators(tsa, 29)
    assert list(values) == list(INDICATORS)
    assert values["residual_RMS"] == pytest.approx(
        np.sqrt((0.3**2 + 0.1**2 + 0.5**2) / 2), rel=1e-9
    )


# -- angular resampling and the TSA on a gear-model record ----------------------------------------
def peak_order(resampled, near, pad=16):
    """The order of the highest line near `near` (zero-padded Hann spectrum, parabolic peak)."""
    m = len(resampled)
    spectrum = np.abs(np.fft.rfft((resampled - resampled.mean()) * np.hanning(m), n=pad * m))
    orders = np.fft.rfftfreq(pad * m, 1 / P)
    window = np.flatnonzero(np.abs(orders - near) < 0.5)
    k = window[np.argmax(spectrum[window])]
    a, b, c = np.log(spectrum[k - 1 : k + 2])
    return orders[k] + 0.5 * (a - c) / (a - 2 * b + c) * (orders[1] - orders[0])


def test_tacholess_resampling_puts_the_mesh_line_at_its_order(record):
    signals, _ = record
    tracked, nominal = [], []
    for segment in segments(signals):
        x = segment[0]
        angle, method, _ = shaft_angle(x, FS, SHAFT_HZ, TEETH_PINION)
        assert method == "mesh_phase"
        tracked.append(peak_order(angular_resample(x, FS, angle, P), TEETH_PINION))
        fixed, method, _ = shaft_angle(x, FS, SHAFT_HZ, TEETH_PINION, phase_min_snr=np.inf)
        assert method == "nominal"
        nominal.append(peak_order(angular_resample(x, FS, fixed, P), TEETH_PINION))
    assert np.abs(np.array(tracked) - TEETH_PINION).max() < 0.01
    # on the nominal speed, the fluctuation moves the line (the test could fail)
    assert np.abs(np.array(nominal) - TEETH_PINION).max() > 0.03


def test_tracked_angle_follows_the_models_shaft(record):
    signals, true_angle = record
    for i, segment in enumerate(segments(signals)):
        truth = true_angle[i * SEGMENT : (i + 1) * SEGMENT]
        truth = truth - truth[0]
        angle, _, _ = shaft_angle(segment[0], FS, SHAFT_HZ, TEETH_PINION)
        error = angle - truth
        assert np.abs(error - error.mean()).max() < 2e-3  # revolutions; nominal: 4e-3


def tooth_pattern(angle, amplitudes, width=0.25):
    """A pulse on every tooth pass (Gaussian, `width` pitches), tooth j's of height amplitudes[j]."""
    position = (np.asarray(angle) % 1.0) * len(amplitudes)
    out = np.zeros_like(position)
    for j, height in enumerate(amplitudes):
        offset = (position - j + len(amplitudes) / 2) % len(amplitudes) - len(amplitudes) / 2
        out += height * np.exp(-0.5 * (offset / width) ** 2)
    return out


def test_tsa_recovers_a_per_tooth_pattern_injected_into_a_model_record(record):
    """A once-per-revolution pattern (one pulse per tooth, each tooth its own height) added at the
    model's shaft angle: the difference signal of the TSA of each 0.5 s segment correlates with the
    pattern's own difference signal at >= 0.9 (the mesh harmonics and sidebands, which the healthy
    record fills, are what the difference signal removes)."""
    signals, angle = record
    heights = 1 + 0.5 * np.random.default_rng(3).normal(size=TEETH_PINION)
    pattern = tooth_pattern(angle, heights)
    gain = 0.2 * signals[0].std() / pattern.std()
    x = signals[0] + gain * pattern
    for i in range(len(x) // SEGMENT):
        segment = x[i * SEGMENT : (i + 1) * SEGMENT]
        tracked, method, _ = shaft_angle(segment, FS, SHAFT_HZ, TEETH_PINION)
        resampled = angular_resample(segment, FS, tracked, P)
        tsa = time_synchronous_average(resampled, P)
        expected = gain * tooth_pattern(angle[i * SEGMENT] + np.arange(P) / P, heights)
        correlation = np.corrcoef(
            difference_signal(tsa, TEETH_PINION), difference_signal(expected, TEETH_PINION)
        )[0, 1]
        assert method == "mesh_phase" and correlation >= 0.9
        # the pattern's low orders (below the mesh) come back with their amplitude
        low = np.arange(1, 15)
        assert keep_orders(tsa, low).std() == pytest.approx(
            keep_orders(expected, low).std(), rel=0.05
        )


def missing_tooth_like(signals, angle, gain):
    """Signals plus a ringing burst (1.2 kHz, 3 ms decay) each time the pinion passes 0.3 rev."""
    passes = np.flatnonzero(np.diff(np.floor(angle - 0.3)) > 0) + 1
    t = np.arange(int(0.02 * FS)) / FS
    burst = np.exp(-t / 0.003) * np.sin(2 * np.pi * 1200 * t)
    impulses = np.zeros(signals.shape[1])
    for k in passes:
        m = min(len(burst), len(impulses) - k)
        impulses[k : k + m] += burst[:m]
    return signals + gain * signals[0].std() * impulses


def test_a_missing_tooth_like_impulse_raises_fm4_and_na4(record):
    signals, angle = record
    extractor = OrderFeatures(shafts=SHAFTS, channels=CHANNELS, scale="linear")
    names = extractor.feature_names()
    healthy = extractor.fit_transform(segments(signals), fs_hz=FS, speed_rpm=SPEED_RPM)
    faulty = extractor.transform(segments(missing_tooth_like(signals, angle, 0.5)), FS, SPEED_RPM)
    for indicator in ("FM4", "NA4", "M6A", "M8A"):
        column = names.index(f"ci_A1_x_pinion_{indicator}")
        assert faulty[:, column].min() > 4 * healthy[:, column].max(), indicator
    # healthy (noise-free model): a few residual lines, kurtosis of sines about 1.5
    assert healthy[:, names.index("ci_A1_x_pinion_FM4")] == pytest.approx(1.5, abs=0.3)
    # the burst is locked to the pinion: its TSA shows it, the gear's (non-synchronous) much less
    assert (
        faulty[:, names.index("ci_A1_x_pinion_FM4")]
        > 2 * faulty[:, names.index("ci_A1_x_gear_FM4")]
    ).all()


def test_weak_mesh_line_falls_back_to_the_nominal_speed(caplog):
    noise = np.random.default_rng(5).normal(size=(1, 1, SEGMENT))
    extractor = OrderFeatures(shafts=SHAFTS, channels=["A1_x"])
    with caplog.at_level(logging.DEBUG, logger="condmon.systems.gear.order_features"):
        values = extractor.fit_transform(noise, fs_hz=FS, speed_rpm=SPEED_RPM)
    assert extractor.phase_methods_ == ["nominal"]
    assert (
        "from the nominal speed" in caplog.text
        and "1 of 1 segments on the nominal speed" in caplog.text
    )
    assert np.isfinite(values).all()


# -- names, counts and the features table ---------------------------------------------------------
def test_feature_names_and_counts():
    extractor = OrderFeatures(shafts=SHAFTS, channels=["A1_x", "A2_y"])
    names = extractor.feature_names()
    bands = 120  # orders 1..120, one wide
    assert len(names) == 2 * bands + 2 * len(SHAFTS) * len(INDICATORS) == len(set(names))
    assert names[28] == "ord_A1_x_029.0x" and names[bands] == "ord_A2_y_001.0x"
    assert names[2 * bands] == "ci_A1_x_pinion_FM0"
    assert "ci_A2_y_gear_SLF" in names and "ci_A1_x_pinion_FM4" in names
    segment = np.random.default_rng(0).normal(size=(3, 2, SEGMENT))
    assert extractor.fit_transform(segment, fs_hz=FS, speed_rpm=SPEED_RPM).shape == (3, len(names))


def test_orders_above_nyquist_and_too_short_segments_are_refused():
    too_high = OrderFeatures(shafts=SHAFTS, channels=["A1_x"], order_max=150.5)
    with pytest.raises(ValueError, match="above the Nyquist order 139.6"):
        too_high.fit_transform(np.zeros((1, 1, SEGMENT)), fs_hz=FS, speed_rpm=SPEED_RPM)
    with pytest.raises(ValueError, match="less than one to average"):
        OrderFeatures(shafts=SHAFTS, channels=["A1_x"], resolution_orders=4.0).fit_transform(
            np.zeros((1, 1, 256)), fs_hz=FS, speed_rpm=SPEED_RPM
        )


def signal_table(tmp_path, signals):
    rows = []
    for k, speed in enumerate((450.0, 1100.0)):
        channels = {c: signals[j, : 2 * SEGMENT] for j, c in enumerate(CHANNELS)}
        rows += make_rows(
            f"rec{k}", "measured", "healthy", speed, 10.0, FS, channels, segment_length=SEGMENT
        )
    path = tmp_path / "signals.parquet"
    write_signal_table(rows, path)
    return path


def test_spectrum_and_order_families_side_by_side(tmp_path, record):
    signals, _ = record
    path = signal_table(tmp_path, signals)
    spectrum = {
        "f_min_hz": 0.0,
        "f_max_hz": 2000.0,
        "resolution_hz": 2.0,
        "scale": "log",
        "band_statistic": "rms",
    }
    params = {"spectrum": spectrum, "order": {"shafts": SHAFTS}}
    order = {"order": SystemFamily(order_feature_table)}  # the gear system's own family
    both = compute_feature_table_from_files(
        [path], CHANNELS, "spectrum+order", params, system_families=order
    )
    alone = compute_feature_table_from_files(
        [path], CHANNELS, "order", params, system_families=order
    )
    columns = [c for c in both.columns if c.startswith(("fft_", "ord_", "ci_"))]
    assert columns[0].startswith("fft_A1_x") and columns[4000].startswith("ord_A1_x")
    assert len(columns) == 4 * 1000 + 4 * 120 + 4 * 2 * len(INDICATORS)
    pd.testing.assert_frame_equal(both[alone.columns], alone)
    assert len(both) == 4 and both["speed_rpm"].tolist() == [450.0, 450.0, 1100.0, 1100.0]


def test_unknown_family_and_missing_shafts_are_refused(tmp_path, record):
    with pytest.raises(FeatureTableError, match=r"unknown feature family \['wavelet'\]"):
        feature_families("spectrum+wavelet")
    with pytest.raises(FeatureTableError, match=r"unknown feature family \['order'\]"):
        feature_families("spectrum+order")  # a system's own family, unknown without it
    with pytest.raises(FeatureTableError, match="appears twice"):
        feature_families("order+order", ("order",))
    assert feature_families("spectrum+order", ("order",)) == ["spectrum", "order"]
    path = signal_table(tmp_path, record[0])
    with pytest.raises(FeatureTableError, match=r"unknown feature family \['orders'\]"):
        compute_feature_table_from_files([path], CHANNELS, "orders", {})
    frame = pd.read_parquet(path)
    with pytest.raises(FeatureTableError, match=r"System.shafts\(\) is None"):
        order_feature_table(frame, CHANNELS, {})
    with pytest.raises(
        FeatureTableError, match=r"unknown features.order parameter\(s\) \['teeth'\]"
    ):
        order_feature_table(frame, CHANNELS, {"teeth": 3, "shafts": SHAFTS})


# -- system, config, classifiers ---------------------------------------------------------------------
def test_gear_systems_name_their_shafts_and_only_they_have_the_order_family():
    assert system_of("config/config.yaml").shafts() == SHAFTS
    cfrp = system_of("config/cfrp.yaml")
    geometry = cfrp.config["model"]["geometry"]
    assert cfrp.shafts() == [
        ("pinion", 1.0, geometry["teeth_pinion"]),
        ("gear", geometry["teeth_pinion"] / geometry["teeth_gear"], geometry["teeth_gear"]),
    ]
    assert "order" in cfrp.feature_families()
    assert system_of(".test/config/cwru-smoke.yaml").feature_families() == {}


def test_config_takes_the_order_family_and_names_what_cannot_work():
    from condmon.config import ConfigError

    config = config_of("config/config.yaml", {"features": {"kind": "spectrum+order"}})
    assert config["features"]["order"]["resolution_orders"] == 1.0
    with pytest.raises(ConfigError, match="'wavelet' is not a feature family of the gear system"):
        config_of("config/config.yaml", {"features": {"kind": "spectrum+wavelet"}})
    with pytest.raises(ConfigError, match="does not match"):
        config_of("config/config.yaml", {"features": {"kind": "spectrum, order"}})
    assert config_of("config/config.yaml", {"features": {"kind": "order"}})["classifiers"]["cnn"][
        "enabled"
    ]
    with pytest.raises(ConfigError, match="order_max: 200.5 is above the Nyquist order 139.6"):
        config_of(
            "config/config.yaml",
            {"features": {"kind": "spectrum+order", "order": {"order_max": 200.5}}},
        )
    with pytest.raises(ConfigError, match="'order' is not a feature family of the bearing system"):
        config_of(".test/config/cwru-smoke.yaml", {"features": {"kind": "statistical+order"}})


def test_cnn_reads_the_spectra_and_leaves_the_order_features_out():
    from condmon.cnn import CNNEnsembleClassifier

    rng = np.random.default_rng(2)
    labels = np.repeat(["healthy", "missing_tooth"], 24)
    spectra = rng.normal(-3, 0.3, (48, 2, 16))
    spectra[labels == "missing_tooth", :, 5] += 2.0
    fft = [f"fft_{c}_{2.0 * b:07.1f}Hz" for c in ("A1_x", "A2_y") for b in range(16)]
    others = ["ord_A1_x_001.0x", "ci_A1_x_pinion_FM4", "ci_A1_x_gear_FM4"]
    x = spectra.reshape(48, -1).astype(np.float32)
    mixed = np.hstack([x, rng.normal(size=(48, 3)).astype(np.float32)])
    small = {
        "members": 2,
        "epochs": 2,
        "batch_size": 16,
        "conv_channels": [4],
        "input_pool": 1,
        "dense_units": [8],
        "random_state": 0,
    }
    alone = CNNEnsembleClassifier(**small).fit(x, labels, feature_names=fft)
    beside = CNNEnsembleClassifier(**small).fit(mixed, labels, feature_names=fft + others)
    assert beside.input_shape_ == alone.input_shape_ == (2, 16)
    np.testing.assert_array_equal(beside.feature_columns_, np.arange(32))
    np.testing.assert_allclose(beside.predict_proba(mixed), alone.predict_proba(x), atol=1e-6)
    module = beside.to_torch_module()
    np.testing.assert_allclose(
        module(mixed).detach().numpy(), beside.predict_proba(mixed), atol=1e-5
    )


def test_without_hz_spectra_the_cnn_reads_the_order_bands_and_leaves_the_indicators_out():
    from condmon.cnn import CNNEnsembleClassifier

    rng = np.random.default_rng(3)
    labels = np.repeat(["healthy", "missing_tooth"], 24)
    spectra = rng.normal(-3, 0.3, (48, 2, 12))
    spectra[labels == "missing_tooth", :, 4] += 2.0
    orders = [f"ord_{c}_{b + 1:05.1f}x" for c in ("A1_x", "A2_y") for b in range(12)]
    indicators = ["ci_A1_x_pinion_FM4", "ci_A2_y_gear_FM4"]
    x = np.hstack([spectra.reshape(48, -1), rng.normal(size=(48, 2))]).astype(np.float32)
    cnn = CNNEnsembleClassifier(
        members=2,
        epochs=2,
        batch_size=16,
        conv_channels=[4],
        input_pool=1,
        dense_units=[8],
        random_state=0,
    ).fit(x, labels, feature_names=orders + indicators)
    assert cnn.input_shape_ == (2, 12)
    np.testing.assert_array_equal(cnn.feature_columns_, np.arange(24))

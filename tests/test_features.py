"""Known-answer tests for the spectrum features and the features table."""

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from condmon.features import (
    FeatureTableError,
    SpectrumFeatures,
    amplitude_spectrum,
    compute_feature_table,
    feature_columns,
    read_feature_table,
    write_feature_table,
)
from condmon.signals import ID_COLUMNS, SignalTableError, make_rows

FS = 1000.0
N = 1000  # 1 s segments: FFT bins every 1 Hz
T = np.arange(N) / FS


def sine(amplitude, freq_hz, n=N, fs=FS):
    return amplitude * np.sin(2 * np.pi * freq_hz * np.arange(n) / fs)


# -- amplitude_spectrum ----------------------------------------------------------------------
def test_sine_at_bin_frequency_gives_its_amplitude():
    freqs, amps = amplitude_spectrum(3.0 * np.sin(2 * np.pi * 100 * T + 0.7), FS)
    assert freqs[100] == pytest.approx(100.0)
    assert amps[100] == pytest.approx(3.0, rel=1e-9)
    # Hann window: the neighbours get half the amplitude, everything else nothing.
    assert amps[[99, 101]] == pytest.approx([1.5, 1.5], rel=1e-9)
    others = np.delete(amps, [99, 100, 101])
    assert others.max() < 1e-9


def test_spectrum_removes_mean_and_has_single_sided_grid():
    freqs, amps = amplitude_spectrum(sine(1.0, 50) + 7.0, FS)
    assert len(freqs) == N // 2 + 1
    assert freqs[-1] == pytest.approx(FS / 2)
    assert amps[0] < 1e-9
    assert amps[50] == pytest.approx(1.0, rel=1e-9)


def test_spectrum_works_on_stacks():
    stack = np.stack([sine(1.0, 10), sine(2.0, 20)])
    _, amps = amplitude_spectrum(stack, FS)
    assert amps.shape == (2, N // 2 + 1)
    assert amps[1, 20] == pytest.approx(2.0)
    assert amps[0, 20] < 1e-9


# -- SpectrumFeatures ------------------------------------------------------------------------
def test_sine_lands_in_the_right_band_with_the_band_mean():
    extractor = SpectrumFeatures(channels=["x"], f_min_hz=0, f_max_hz=500, resolution_hz=10)
    features = extractor.transform(sine(2.0, 123)[None, None, :], FS)[0]
    assert features.shape == (50,)
    assert features.dtype == np.float32
    assert extractor.band_centres()[features.argmax()] == pytest.approx(125.0)
    # Band [120, 130) holds bins 122, 123, 124 with 1.0, 2.0, 1.0: mean over 10 bins = 0.4.
    assert features[12] == pytest.approx(0.4, rel=1e-5)
    assert np.delete(features, 12).max() < 1e-6


def test_band_averaging_equals_spectrum_when_resolution_is_the_bin_width():
    rng = np.random.default_rng(0)
    signal = rng.normal(size=N)
    extractor = SpectrumFeatures(channels=["x"], f_min_hz=100, f_max_hz=200, resolution_hz=1)
    features = extractor.transform(signal[None, None, :], FS)[0]
    _, amps = amplitude_spectrum(signal, FS)
    np.testing.assert_allclose(features, amps[100:200], rtol=1e-5)


def test_band_averaging_of_two_bins_with_an_offset_grid():
    rng = np.random.default_rng(1)
    signal = rng.normal(size=N)
    extractor = SpectrumFeatures(channels=["x"], f_min_hz=3, f_max_hz=13, resolution_hz=2)
    features = extractor.transform(signal[None, None, :], FS)[0]
    _, amps = amplitude_spectrum(signal, FS)
    expected = amps[3:13].reshape(5, 2).mean(axis=1)  # bands [3,5), [5,7), ... [11,13)
    np.testing.assert_allclose(features, expected, rtol=1e-5)


def test_channels_are_concatenated_in_the_given_order():
    extractor = SpectrumFeatures(
        channels=["A1_y", "A1_x"], f_min_hz=0, f_max_hz=500, resolution_hz=5
    )
    x_channel, y_channel = sine(1.0, 40), sine(1.0, 300)
    features = extractor.transform(np.stack([y_channel, x_channel])[None], FS)[0]
    names = extractor.feature_names(FS, N)
    assert len(names) == features.shape[0] == 200
    assert names[features[:100].argmax()] == "fft_A1_y_00302.5Hz"
    assert names[100 + features[100:].argmax()] == "fft_A1_x_00042.5Hz"


def test_log_scale():
    linear = SpectrumFeatures(channels=["x"], f_min_hz=0, f_max_hz=500, resolution_hz=10)
    log = SpectrumFeatures(channels=["x"], f_min_hz=0, f_max_hz=500, resolution_hz=10, scale="log")
    X = sine(2.0, 123)[None, None, :]
    np.testing.assert_allclose(
        log.transform(X, FS), np.log10(linear.transform(X, FS) + 1e-6), rtol=1e-5
    )
    assert log.transform(X, FS)[0, 0] == pytest.approx(-6.0, abs=1e-3)  # silent band


def test_feature_names_format():
    extractor = SpectrumFeatures(channels=["A1_x", "DE"], f_min_hz=0, f_max_hz=20, resolution_hz=4)
    assert extractor.feature_names(12000, 12000) == [
        "fft_A1_x_00002.0Hz",
        "fft_A1_x_00006.0Hz",
        "fft_A1_x_00010.0Hz",
        "fft_A1_x_00014.0Hz",
        "fft_A1_x_00018.0Hz",
        "fft_DE_00002.0Hz",
        "fft_DE_00006.0Hz",
        "fft_DE_00010.0Hz",
        "fft_DE_00014.0Hz",
        "fft_DE_00018.0Hz",
    ]


def test_resolution_finer_than_bin_width_is_an_error():
    extractor = SpectrumFeatures(channels=["x"], f_min_hz=0, f_max_hz=100, resolution_hz=0.5)
    with pytest.raises(ValueError, match=r"resolution_hz=0\.5 .*bin width.*1 Hz"):
        extractor.transform(np.zeros((1, 1, N)), FS)


def test_f_max_above_nyquist_is_an_error():
    extractor = SpectrumFeatures(channels=["x"], f_min_hz=0, f_max_hz=600, resolution_hz=10)
    with pytest.raises(ValueError, match=r"f_max_hz=600 .*Nyquist.*500"):
        extractor.transform(np.zeros((1, 1, N)), FS)


@pytest.mark.parametrize(
    "params, culprit",
    [
        (dict(scale="db"), "'db'"),
        (dict(f_min_hz=50, f_max_hz=10), "f_min_hz=50"),
        (dict(resolution_hz=3), "resolution_hz = 3"),
        (dict(resolution_hz=0), "got 0"),
    ],
)
def test_bad_parameters_name_the_culprit(params, culprit):
    settings = dict(channels=["x"], f_min_hz=0, f_max_hz=100, resolution_hz=10)
    settings.update(params)
    with pytest.raises(ValueError, match=culprit):
        SpectrumFeatures(**settings).transform(np.zeros((1, 1, N)), FS)


def test_wrong_channel_count_is_an_error():
    extractor = SpectrumFeatures(channels=["x", "y"], f_min_hz=0, f_max_hz=100, resolution_hz=10)
    with pytest.raises(ValueError, match="1 channels .* 2"):
        extractor.transform(np.zeros((1, 1, N)), FS)


# -- features table --------------------------------------------------------------------------
SPECTRUM = {"f_min_hz": 0, "f_max_hz": 500, "resolution_hz": 10, "scale": "linear"}


def signal_frame(records=(("r1", 125.0), ("r2", 235.0)), fs=FS, channels=("A1_x", "A1_y")):
    """Records of two segments: A1_x a unit sine at the record's frequency, A1_y 0.5 at +100 Hz."""
    rows = []
    for record_id, freq in records:
        n = int(2 * fs)
        signals = {
            ch: (sine(1.0, freq, n, fs) if ch == "A1_x" else sine(0.5, freq + 100, n, fs))
            for ch in channels
        }
        rows += make_rows(
            record_id, "measured", "healthy", 775, 1.0, fs, signals, segment_length=int(fs)
        )
    return pd.DataFrame(rows)


def test_feature_table_layout_and_values():
    frame = compute_feature_table(signal_frame(), ["A1_x", "A1_y"], SPECTRUM)
    names = feature_columns(frame)
    assert list(frame.columns[: len(ID_COLUMNS)]) == ID_COLUMNS
    assert len(names) == 100 and names[0] == "fft_A1_x_00005.0Hz"
    assert list(zip(frame.record_id, frame.segment)) == [("r1", 0), ("r1", 1), ("r2", 0), ("r2", 1)]
    assert (frame[names].dtypes == np.float32).all()
    r2 = frame[frame.record_id == "r2"].iloc[0]
    # 235 Hz: bins 234, 235, 236 hold 0.5, 1, 0.5, all in band [230, 240): mean 2/10.
    assert r2["fft_A1_x_00235.0Hz"] == pytest.approx(0.2, rel=1e-4)
    assert r2["fft_A1_y_00335.0Hz"] == pytest.approx(0.1, rel=1e-4)
    assert r2["fft_A1_x_00335.0Hz"] < 1e-6


def test_mixed_sampling_rates_name_the_records():
    frame = pd.concat(
        [signal_frame([("slow", 100.0)], fs=1000.0), signal_frame([("fast", 100.0)], fs=2000.0)]
    )
    frame["signal"] = [s[:1000] for s in frame["signal"]]
    with pytest.raises(FeatureTableError, match=r"1000 Hz: \['slow'\].*2000 Hz: \['fast'\]"):
        compute_feature_table(frame, ["A1_x"], SPECTRUM)


def test_missing_channel_is_named():
    with pytest.raises(FeatureTableError, match=r"\['A2_x'\]"):
        compute_feature_table(signal_frame(), ["A1_x", "A2_x"], SPECTRUM)


def test_channel_missing_in_one_record_is_named():
    frame = signal_frame()
    frame = frame[~((frame.record_id == "r2") & (frame.channel == "A1_y"))]
    with pytest.raises(SignalTableError, match="r2.*A1_y"):
        compute_feature_table(frame, ["A1_x", "A1_y"], SPECTRUM)


def test_unknown_spectrum_parameter_is_named():
    with pytest.raises(ValueError, match="window"):
        compute_feature_table(signal_frame(), ["A1_x"], {**SPECTRUM, "window": "hann"})


def test_write_read_roundtrip(tmp_path):
    frame = compute_feature_table(signal_frame(), ["A1_x", "A1_y"], SPECTRUM)
    names = feature_columns(frame)
    path = tmp_path / "features" / "measured.parquet"
    write_feature_table(frame, names, path)
    back, back_names = read_feature_table(path)
    assert back_names == names
    pd.testing.assert_frame_equal(back, frame[ID_COLUMNS + names], check_dtype=False)
    assert (back[names].dtypes == np.float32).all()
    meta = pq.read_schema(path).metadata
    assert meta[b"condmon.feature_kind"] == b"spectrum"
    assert list(path.parent.iterdir()) == [path]  # no temporary file left behind


def test_reading_a_plain_parquet_is_an_error(tmp_path):
    path = tmp_path / "plain.parquet"
    pd.DataFrame({"a": [1]}).to_parquet(path)
    with pytest.raises(FeatureTableError, match="condmon.feature_names"):
        read_feature_table(path)

"""Known-answer tests of the bearing envelope analysis (condmon.envelope): the kurtogram finds the
band where a synthetic impulse train rings in coloured noise, prewhitening keeps an impulse
train's envelope line and removes a gear-mesh line, and a ball fault's 2 x BSF with its cage
sidebands is read on a signal of a bearing of another geometry than the CWRU rig's."""

import numpy as np
import pytest

from condmon import envelope as ev
from condmon.models.bearing.rig import BearingGeometry

FS = 12000.0


def impulse_train(rate_hz, n, resonance_hz, rng, damping=0.03, amplitude=None, jitter=0.0):
    """Impacts at `rate_hz` (each an exponentially decaying ring at `resonance_hz`), amplitudes
    `amplitude(t)` (default 1), arrival times jittered by `jitter` of a period (slip)."""
    t = np.arange(n) / FS
    out = np.zeros(n)
    ring_t = np.arange(int(0.02 * FS)) / FS
    ring = np.exp(-damping * 2 * np.pi * resonance_hz * ring_t) * np.sin(
        2 * np.pi * resonance_hz * ring_t
    )
    period = 1.0 / rate_hz
    for k in range(int(t[-1] / period) + 1):
        start = k * period + jitter * period * rng.normal()
        i = int(round(start * FS))
        if 0 <= i < n:
            gain = 1.0 if amplitude is None else amplitude(start)
            stop = min(n, i + len(ring))
            out[i:stop] += gain * ring[: stop - i]
    return out


def coloured_noise(n, rng, level=1.0):
    """Noise whose power falls with frequency (first-order low-pass, corner near 300 Hz)."""
    white = rng.normal(size=n)
    alpha = np.exp(-2 * np.pi * 300.0 / FS)
    out = np.empty(n)
    acc = 0.0
    for i, w in enumerate(white):
        acc = alpha * acc + (1 - alpha) * w
        out[i] = acc
    return level * out / out.std()


# -- the kurtogram ----------------------------------------------------------------------------
def test_kurtogram_bands_are_antonis_one_third_binary_tree():
    bands = np.asarray(ev.kurtogram_bands(FS, 3))
    levels = sorted(set(np.round(bands[:, 0], 3)))
    assert levels == [0.0, 1.0, 1.585, 2.0, 2.585, 3.0]
    for level, count in ((0.0, 1), (1.0, 2), (1.585, 3), (2.0, 4), (2.585, 6), (3.0, 8)):
        chosen = bands[np.isclose(bands[:, 0], level, atol=1e-3)]
        assert len(chosen) == count
        assert np.allclose(chosen[:, 2] - chosen[:, 1], FS / 2 / count)
        assert chosen[0, 1] == 0.0 and chosen[-1, 2] == pytest.approx(FS / 2)
    with pytest.raises(ValueError, match="max_level"):
        ev.kurtogram_bands(FS, -1)


def test_kurtogram_finds_the_band_of_an_impulse_train_in_coloured_noise():
    rng = np.random.default_rng(1)
    n = 16384
    # impacts ringing at 4.2 kHz, buried in low-frequency noise five times their RMS and a
    # white floor
    impacts = impulse_train(97.0, n, 4200.0, rng, jitter=0.01)
    x = (
        coloured_noise(n, rng, level=5 * impacts.std())
        + 0.2 * impacts.std() * rng.normal(size=n)
        + impacts
    )
    result = ev.kurtogram(x, FS, max_level=5)
    low, high = result.best()[0]
    assert low < 4200.0 < high
    assert high - low <= FS / 2 / 4  # a band, not the whole spectrum
    # the whole signal's spectral kurtosis does not show the impacts; the band's does
    whole = result.kurtosis[0, np.argmax(result.bands[:, 2] - result.bands[:, 1])]
    assert result.kurtosis.max() > 1.0 > 10 * whole


def test_kurtogram_keeps_bands_wide_enough_for_the_lines():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(2, 4096))
    result = ev.kurtogram(x, FS, max_level=4, min_bandwidth_hz=[0.0, 1000.0])
    widths = result.bands[:, 2] - result.bands[:, 1]
    assert np.isfinite(result.kurtosis[0, widths < 1000.0]).all()
    assert np.isneginf(result.kurtosis[1, widths < 1000.0]).all()
    assert (np.diff(result.best(), axis=1)[1] >= 1000.0).all()


# -- prewhitening -----------------------------------------------------------------------------
def test_prewhitening_gives_a_flat_spectrum_in_the_signals_unit():
    rng = np.random.default_rng(3)
    x = coloured_noise(4096, rng, level=2.0) + 3.0
    white = ev.prewhiten(x)
    magnitude = np.abs(np.fft.rfft(white))[1:]
    assert magnitude.std() / magnitude.mean() < 1e-6
    assert white.std() == pytest.approx(x.std())
    assert abs(white.mean()) < 1e-9


def test_prewhitening_keeps_an_impulse_trains_envelope_line_and_removes_a_gear_mesh_line():
    rng = np.random.default_rng(4)
    n, shaft, rate = 24000, 25.0, 3.7 * 25.0
    t = np.arange(n) / FS
    # a gear mesh at 29 teeth, its amplitude modulated once a turn, a hundred times the impacts
    impacts = impulse_train(rate, n, 3500.0, rng, jitter=0.01)
    mesh = (
        100
        * impacts.std()
        * (1 + 0.5 * np.cos(2 * np.pi * shaft * t))
        * np.sin(2 * np.pi * 29 * shaft * t)
    )
    x = mesh + impacts + 0.2 * impacts.std() * rng.normal(size=n)
    whole = (0.0, FS / 2)
    lines = {"mesh": [29.0], "impacts": [3.7, 7.4]}
    speed_rpm = shaft * 60

    def spectrum_ratio(signal, order):
        freqs, amps = ev.amplitude_spectrum(signal[None, :] - signal.mean(), FS)
        return ev.line_ratio(freqs, amps, [order * shaft], floor_halfwidth_hz=0.5 * shaft)[0]

    # the raw spectrum is the mesh line; the prewhitened spectrum has none
    assert spectrum_ratio(x, 29.0) > 100
    assert spectrum_ratio(ev.prewhiten(x), 29.0) < 5
    raw = ev.line_ratios(x[None, :], FS, speed_rpm, lines, "fixed", whole)
    white = ev.line_ratios(x[None, :], FS, speed_rpm, lines, "prewhitened_fixed", whole)
    # in the whole band the mesh's modulation hides the impacts' envelope line; prewhitened it shows
    assert white["impacts"][0] > 5 and white["impacts"][0] > 2 * raw["impacts"][0]


# -- lines with harmonics and sidebands -------------------------------------------------------
def test_line_sets_carry_harmonics_and_sidebands_and_drop_what_two_defects_share():
    orders = {"bpfo": 3.585, "bpfi": 5.415, "bsf_x2": 4.714}
    sets = ev.fault_line_sets(orders, {"bpfi": 1.0, "bsf_x2": 0.398}, harmonics=2)
    assert sets["bpfo"] == [3.585, 7.17]
    assert sets["bpfi"][0] == 5.415 and {6.415, 10.83}.issubset(np.round(sets["bpfi"], 3))
    assert sets["bsf_x2"][0] == 4.714 and {5.112, 9.428}.issubset(np.round(sets["bsf_x2"], 3))
    # lines of two defects within twice the tolerance cannot be told apart: neither set reads
    # them (BPFI - 1 = 4.415 and 2 x BSF - FTF = 4.316; 2 x BPFI - 1 = 9.830 and 4 x BSF + FTF
    # = 9.826)
    for line in (4.415, 4.316, 9.83, 9.826):
        assert not any(abs(kept - line) < 0.005 for kept in sets["bpfi"] + sets["bsf_x2"])
    with pytest.raises(ValueError, match="bsf"):
        ev.fault_line_sets(orders, {"bsf": 0.4})
    with pytest.raises(ValueError, match="harmonics"):
        ev.fault_line_sets(orders, harmonics=0)


def test_line_ratio_is_near_one_on_noise_and_large_on_a_line():
    rng = np.random.default_rng(5)
    noise = rng.normal(size=(20, 8192))
    freqs, amps = ev.amplitude_spectrum(noise, FS)
    ratios = ev.line_ratio(freqs, amps, [100.0, 200.0, 330.0], floor_halfwidth_hz=15.0)
    assert 1.0 < np.median(ratios) < 3.0
    tone = np.sin(2 * np.pi * 100.0 * np.arange(8192) / FS)
    freqs, amps = ev.amplitude_spectrum(noise[:1] + tone, FS)
    assert ev.line_ratio(freqs, amps, [100.0], floor_halfwidth_hz=15.0)[0] > 10


def test_a_ball_faults_twice_bsf_with_cage_sidebands_is_read_on_another_geometry():
    # not the CWRU rig's SKF 6205: 13 balls of 8 mm on a 52 mm pitch circle, 20 degrees contact
    geometry = BearingGeometry(13, 8e-3, 52e-3, 20.0)
    orders = geometry.orders()
    shaft = 1500 / 60
    rng = np.random.default_rng(6)
    n = 4 * 4096
    # a ball defect strikes a race twice a ball turn, harder in the load zone the cage carries
    # it through once a cage turn
    ftf_hz = orders["ftf"] * shaft
    strikes = impulse_train(
        2 * orders["bsf"] * shaft,
        n,
        3000.0,
        rng,
        jitter=0.005,
        amplitude=lambda t: (1.2 + np.cos(2 * np.pi * ftf_hz * t)) ** 2,
    )
    x = strikes + 0.6 * strikes.std() * rng.normal(size=n)
    defect = {"bpfo": orders["bpfo"], "bpfi": orders["bpfi"], "bsf_x2": 2 * orders["bsf"]}
    sets = ev.fault_line_sets(defect, {"bpfi": 1.0, "bsf_x2": orders["ftf"]}, harmonics=2)
    for sideband in (-orders["ftf"], orders["ftf"]):
        assert any(abs(line - (2 * orders["bsf"] + sideband)) < 1e-9 for line in sets["bsf_x2"])
    for analysis in ("kurtogram", "prewhitened_kurtogram"):
        ratios = ev.line_ratios(x[None, :], FS, 1500.0, sets, analysis, max_level=4)
        assert ratios["bsf_x2"][0] > 4
        assert ratios["bsf_x2"][0] > 2 * max(ratios["bpfo"][0], ratios["bpfi"][0])
        assert ratios["band_low_hz"][0] < 3000.0 < ratios["band_high_hz"][0]
    # the cage's modulation shows as the sidebands at 2 x BSF +/- FTF, which stand out on their own
    sidebands = {
        "sidebands": [2 * orders["bsf"] - orders["ftf"], 2 * orders["bsf"] + orders["ftf"]]
    }
    assert ev.line_ratios(x[None, :], FS, 1500.0, sidebands, "kurtogram")["sidebands"][0] > 3


def test_errors_name_the_culprit():
    x = np.zeros((1, 4096))
    with pytest.raises(ValueError, match="unknown envelope analysis 'cepstrum'"):
        ev.demodulation_bands(x, FS, "cepstrum", (2000.0, 5000.0))
    with pytest.raises(ValueError, match="band"):
        ev.analytic_band(x, FS, (5000.0, 2000.0))
    with pytest.raises(ValueError, match="shaft speed"):
        ev.line_ratios(x + 1e-3, FS, 0.0, {"bpfo": [3.5]})
    with pytest.raises(ValueError, match="NaN"):
        ev.prewhiten(np.full(64, np.nan))

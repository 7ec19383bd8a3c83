"""The input shaft's slow speed fluctuation, read from healthy records
(`model.variability.speed_fluctuation_source: healthy_records`).

A machine's speed wanders with its drive and load (a motor's slip, a belt, a controller), and how
much is a property of the rig, not of its gears' health: healthy records show it. The mesh-phase
tracking the order features use (`order_features.segment_angle`) gives the shaft's angle at every
sample; its derivative is the instantaneous speed. Low-passed below `LOWPASS_HZ` (the slow
fluctuation, not the tooth-to-tooth velocity ripple) and relative to the mean, its largest
spectral line is the fluctuation's frequency and sqrt(2) x its standard deviation the amplitude of
a sinusoid with that variance: the model's form (`speed_fluctuation` x sin(2 pi f t + phase)).

The tracking band is +/- `phase_band_orders` of the shaft frequency around the mesh line, so a
fluctuation faster than that is cut: at 450 rpm and 0.3 orders, above 2.25 Hz. Each speed's
estimate says how far it can see (`band_hz`); one outside its band is not used.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfiltfilt

from condmon.systems.gear.order_features import segment_angle

LOWPASS_HZ = 8.0
EDGE_SECONDS = 0.1  # the filter's start and end transients, left out


def relative_speed(angle, fs_hz: float) -> np.ndarray:
    """The instantaneous speed over its mean (0 = steady), low-passed below LOWPASS_HZ, without
    the first and last EDGE_SECONDS."""
    speed = np.gradient(np.asarray(angle, dtype=float)) * fs_hz
    relative = speed / speed.mean() - 1.0
    sos = butter(4, LOWPASS_HZ, fs=fs_hz, output="sos")
    edge = int(EDGE_SECONDS * fs_hz)
    return sosfiltfilt(sos, relative)[edge : len(relative) - edge]


def fluctuation_of(relative, fs_hz: float) -> tuple[float, float]:
    """(amplitude, frequency in Hz) of the sinusoid with the variance and the strongest line of
    `relative` (Hann window, zero-padded eightfold)."""
    relative = np.asarray(relative, dtype=float)
    n = len(relative) * 8
    spectrum = np.abs(np.fft.rfft((relative - relative.mean()) * np.hanning(len(relative)), n=n))
    frequencies = np.fft.rfftfreq(n, 1.0 / fs_hz)
    return float(np.sqrt(2.0) * relative.std()), float(frequencies[1:][np.argmax(spectrum[1:])])


def speed_fluctuation(
    segments,
    fs_hz: float,
    speed_rpm: float,
    mesh_order: float,
    phase_band_orders: float = 0.3,
    phase_min_snr: float = 5.0,
) -> dict | None:
    """The fluctuation of healthy segments (n_segments, n_channels, n_samples) at one speed:
    {amplitude: [low, high], frequency_hz: [low, high]} over the segments whose mesh line could be
    followed (on the channel where it stands highest), `segments` used and the tracking band
    `band_hz`; None when no segment could be followed, the fluctuation lies outside the band, or
    a segment holds less than one period of it (too short to tell a fluctuation from a drift)."""
    segments = np.asarray(segments, dtype=float)
    shaft_hz = speed_rpm / 60.0
    usable_seconds = segments.shape[-1] / fs_hz - 2 * EDGE_SECONDS
    if usable_seconds <= 0:
        return None
    estimates = []
    for segment in segments:
        angle, method, _ = segment_angle(
            segment, fs_hz, shaft_hz, mesh_order, phase_band_orders, phase_min_snr
        )
        if method == "mesh_phase":
            estimates.append(fluctuation_of(relative_speed(angle, fs_hz), fs_hz))
    band_hz = phase_band_orders * shaft_hz
    if not estimates:
        return None
    amplitudes, frequencies = np.array(estimates).T
    if not 1.0 / usable_seconds <= np.median(frequencies) <= band_hz:
        return None
    return {
        "amplitude": [float(amplitudes.min()), float(amplitudes.max())],
        "frequency_hz": [float(frequencies.min()), float(frequencies.max())],
        "segments": len(estimates),
        "band_hz": round(float(band_hz), 3),
    }

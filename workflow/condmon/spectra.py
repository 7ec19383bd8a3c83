"""The amplitude spectrum every feature and calibration cost is built on."""

from __future__ import annotations

import numpy as np
from scipy.signal import get_window


def amplitude_spectrum(signal, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Single-sided amplitude spectrum of `signal` (along its last axis).

    The mean is removed and a (periodic) Hann window applied; amplitudes are corrected for the
    window's coherent gain, so a sine of amplitude A at a bin frequency gives A at that bin.
    Returns (freqs_hz, amplitudes); works on one signal or a stack of them.
    """
    x = np.asarray(signal, dtype=np.float64)
    if x.shape[-1] < 2:
        raise ValueError(f"amplitude_spectrum needs at least 2 samples, got {x.shape[-1]}")
    if not fs_hz > 0:
        raise ValueError(f"fs_hz must be positive, got {fs_hz}")
    n = x.shape[-1]
    x = x - x.mean(axis=-1, keepdims=True)
    window = get_window("hann", n)  # periodic: sums to exactly n/2
    amplitudes = np.abs(np.fft.rfft(x * window, axis=-1)) * (2.0 / window.sum())
    # DC and (even n) Nyquist have no mirror image in the two-sided spectrum: no factor 2.
    amplitudes[..., 0] /= 2.0
    if n % 2 == 0:
        amplitudes[..., -1] /= 2.0
    return np.fft.rfftfreq(n, d=1.0 / fs_hz), amplitudes


def band_values(
    freqs, amplitudes, low: float, width: float, n_bands: int, statistic: str = "mean"
) -> np.ndarray:
    """Per band of `width` over [low, low + n_bands x width), the mean ("mean") or root mean square
    ("rms") of the amplitudes of the bins inside it (bands along the last axis).

    The RMS keeps a band's energy when a line is smeared over several bins (a small speed
    fluctuation), which the mean amplitude does not. Raises if a band holds no bin.
    """
    # The small epsilon keeps a bin sitting exactly on a band edge in the upper band, whatever
    # rounding the two float grids carry.
    band_of_bin = np.floor((np.asarray(freqs) - low) / width + 1e-9).astype(int)
    inside = np.flatnonzero((band_of_bin >= 0) & (band_of_bin < n_bands))
    band_of_bin = band_of_bin[inside]  # non-decreasing: each band is a contiguous run
    starts = np.searchsorted(band_of_bin, np.arange(n_bands))
    counts = np.diff(np.append(starts, len(band_of_bin)))
    if (counts == 0).any():
        empty = low + width * (np.flatnonzero(counts == 0) + 0.5)
        raise ValueError(f"bands without spectrum bins at {empty[:5]} (band centres)")
    amplitudes = np.asarray(amplitudes)
    if statistic == "rms":
        return np.sqrt(np.add.reduceat(amplitudes[..., inside] ** 2, starts, axis=-1) / counts)
    if statistic == "mean":
        return np.add.reduceat(amplitudes[..., inside], starts, axis=-1) / counts
    raise ValueError(f"unknown band statistic {statistic!r}; choose mean or rms")

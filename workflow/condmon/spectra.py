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

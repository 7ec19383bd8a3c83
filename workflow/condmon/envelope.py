"""Envelope analysis as the field does it for impacting defects: cepstral prewhitening, the
demodulation band chosen by spectral kurtosis (a fast kurtogram), the squared envelope spectrum
(SES), and lines read with their harmonics and sidebands.

Every function works along the last axis of an array (one segment or a stack of segments) and is
pure: arrays and numbers in, arrays out. Which lines to read (the defect orders and the sideband
spacings that modulate them) is the system's to say (`System.defect_orders`,
`System.defect_sidebands`).

- `prewhiten`: cepstral prewhitening (Sawalhi & Randall 2011; Randall & Antoni 2011, MSSP 25,
  485-520): the real cepstrum set to zero but for its zero quefrency, which is the spectrum
  divided by its own magnitude, x_w = IFFT(X / |X|). Discrete lines (the harmonics of rotating
  parts) and resonances are flattened alike, so the impulsive part of a signal stands out.
- `kurtogram`: the spectral kurtosis of the complex envelope in every band of Antoni's 1/3-binary
  tree (J. Antoni, "Fast computation of the kurtogram for the detection of transient faults",
  MSSP 21 (2007) 108-124): level k holds 2^k bands of width fs / 2^(k+1), the level k + 0.6
  between k and k + 1 holds 3 * 2^(k-1) bands of width fs / (3 * 2^k). The band filters here
  are frequency-domain filters on the analytic signal (the band's FFT bins with raised-cosine
  edges), not Antoni's quasi-analytic FIR cascade: the same bands, one FFT per segment and one
  short inverse FFT per band. The band of largest kurtosis is where the defect's impacts ring.
- `squared_envelope_spectrum`: |analytic band-passed signal|^2, mean removed, its amplitude
  spectrum (Hann, amplitude corrected, zero-padded).
- `fault_line_sets` and `line_ratio`: the lines of a defect (its order's harmonics, with
  sidebands where the defect is modulated, e.g. as a rotating defect passes through a load zone
  once a turn of the part that carries it), and the summed line heights over the summed local
  floors of an SES.

Smith & Randall (2015, MSSP 64-65, 100-131) benchmark this on a public data set of rolling
element defects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# the analyses the config can name: the band (fixed or by kurtogram), with or without prewhitening
ANALYSES = ("fixed", "kurtogram", "prewhitened_fixed", "prewhitened_kurtogram")


def _x(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape[-1] < 16:
        raise ValueError(f"envelope analysis needs at least 16 samples, got {x.shape[-1]}")
    if not np.isfinite(x).all():
        raise ValueError("envelope analysis: the signal contains NaN or inf")
    return x


# -- prewhitening -------------------------------------------------------------------------------
def prewhiten(x) -> np.ndarray:
    """Cepstral prewhitening: the signal with a unit-magnitude spectrum and its own phase.

    Parameters
    ----------
    x : array_like, (..., n)
        Signal(s) along the last axis; the mean is removed first.

    Returns
    -------
    numpy.ndarray, (..., n)
        IFFT(X / |X|) (bins of zero magnitude stay zero), scaled to the input's standard
        deviation so levels stay in the signal's unit.
    """
    x = _x(x)
    x = x - x.mean(axis=-1, keepdims=True)
    spectrum = np.fft.rfft(x, axis=-1)
    magnitude = np.abs(spectrum)
    unit = np.divide(spectrum, magnitude, out=np.zeros_like(spectrum), where=magnitude > 0)
    unit[..., 0] = 0.0
    white = np.fft.irfft(unit, n=x.shape[-1], axis=-1)
    scale = np.divide(
        x.std(axis=-1, keepdims=True),
        white.std(axis=-1, keepdims=True),
        out=np.zeros(x.shape[:-1] + (1,)),
        where=white.std(axis=-1, keepdims=True) > 0,
    )
    return white * scale


# -- band filters on the analytic signal ---------------------------------------------------------
def _band_weights(freqs, low, high, edge=0.1):
    """Weights of the FFT bins `freqs` in the band [low, high]: 1 inside, raised-cosine edges
    `edge` x the bandwidth wide inside the band, 0 outside (broadcasts low and high)."""
    low, high = np.asarray(low, dtype=float)[..., None], np.asarray(high, dtype=float)[..., None]
    width = np.maximum(edge * (high - low), 1e-12)
    rise = np.clip((freqs - low) / width, 0.0, 1.0)
    fall = np.clip((high - freqs) / width, 0.0, 1.0)
    return 0.5 * (1 - np.cos(np.pi * rise)) * 0.5 * (1 - np.cos(np.pi * fall))


def analytic_band(x, fs_hz: float, band_hz) -> np.ndarray:
    """The complex (analytic) band-passed signal, at the input's rate.

    Parameters
    ----------
    x : array_like, (n_segments, n) or (n,)
    fs_hz : float
        Sampling rate.
    band_hz : array_like, (2,) or (n_segments, 2)
        One band for every segment, or a band per segment, within [0, fs / 2].

    Returns
    -------
    numpy.ndarray of complex, the shape of `x`
        IFFT of the positive-frequency bins in the band (raised-cosine edges), doubled: its
        modulus is the envelope of the band-passed signal.
    """
    x = _x(x)
    band = np.asarray(band_hz, dtype=float)
    if (
        band.shape[-1] != 2
        or not (
            (0 <= band[..., 0]) & (band[..., 0] < band[..., 1]) & (band[..., 1] <= fs_hz / 2)
        ).all()
    ):
        raise ValueError(
            f"envelope band(s) {band.tolist()} must satisfy 0 <= low < high <= fs/2 "
            f"= {fs_hz / 2:g} Hz"
        )
    n = x.shape[-1]
    freqs = np.fft.fftfreq(n, d=1.0 / fs_hz)
    weights = _band_weights(np.where(freqs >= 0, freqs, -1.0), band[..., 0], band[..., 1])
    return np.fft.ifft(2.0 * np.fft.fft(x, axis=-1) * weights, axis=-1)


# -- the kurtogram --------------------------------------------------------------------------------
def kurtogram_bands(fs_hz: float, max_level: int) -> list[tuple[float, float, float]]:
    """The bands of the 1/3-binary tree to `max_level`, as (level, low Hz, high Hz).

    Level k (0..max_level) splits [0, fs/2] into 2^k bands of width fs / 2^(k+1); the level
    k + log2(3) - 1 (about k + 0.6, k = 1..max_level - 1) between k and k + 1 into 3 * 2^(k-1)
    bands of width fs / (3 * 2^k) (Antoni 2007: levels 0, 1, 1.6, 2, 2.6, ...).
    """
    if not (isinstance(max_level, (int, np.integer)) and max_level >= 0):
        raise ValueError(f"kurtogram: max_level must be a whole number >= 0, got {max_level!r}")
    nyquist = fs_hz / 2
    bands = []
    for k in range(max_level + 1):
        counts = [(float(k), 2**k)]
        if 1 <= k < max_level:
            counts.append((k + float(np.log2(3)) - 1, 3 * 2 ** (k - 1)))
        for level, count in counts:
            width = nyquist / count
            bands += [(level, i * width, (i + 1) * width) for i in range(count)]
    return sorted(bands)


@dataclass(frozen=True)
class Kurtogram:
    """Spectral kurtosis per band of the 1/3-binary tree, for a stack of segments.

    Attributes
    ----------
    bands : numpy.ndarray, (n_bands, 3)
        (level, low Hz, high Hz) of every band.
    kurtosis : numpy.ndarray, (n_segments, n_bands)
        Spectral kurtosis of each band's complex envelope, E|c|^4 / (E|c|^2)^2 - 2 (0 for
        Gaussian noise, large where impacts ring); -inf where a band was not allowed.
    """

    bands: np.ndarray
    kurtosis: np.ndarray

    def best(self) -> np.ndarray:
        """(n_segments, 2): the band (low, high Hz) of largest kurtosis of every segment."""
        return self.bands[np.argmax(self.kurtosis, axis=1), 1:]


def kurtogram(x, fs_hz: float, max_level: int = 4, min_bandwidth_hz=0.0) -> Kurtogram:
    """Spectral kurtosis of a stack of segments in the bands of the 1/3-binary tree.

    Parameters
    ----------
    x : array_like, (n_segments, n) or (n,)
    fs_hz : float
    max_level : int
        The finest level: its bands are fs / 2^(max_level + 1) wide.
    min_bandwidth_hz : float or array_like (n_segments,)
        Bands narrower than this are left out (kurtosis -inf) for that segment: the band must
        be wider than the highest envelope line to be read, or the squared envelope cannot hold
        it. A segment for which no band is wide enough keeps the widest band.

    Returns
    -------
    Kurtogram
    """
    x = np.atleast_2d(_x(x))
    n = x.shape[-1]
    bands = np.asarray(kurtogram_bands(fs_hz, max_level))
    spectrum = np.fft.rfft(x - x.mean(axis=-1, keepdims=True), axis=-1)
    freqs = np.fft.rfftfreq(n, d=1.0 / fs_hz)
    values = np.full((len(x), len(bands)), -np.inf)
    for j, (_, low, high) in enumerate(bands):
        inside = (freqs >= low) & (freqs <= high)
        if inside.sum() < 8:
            continue
        weights = _band_weights(freqs[inside], low, high)
        envelope = np.fft.ifft(spectrum[:, inside] * weights, axis=-1)  # decimated complex envelope
        power = np.abs(envelope) ** 2
        mean_power = power.mean(axis=-1)
        values[:, j] = (
            np.divide(
                (power**2).mean(axis=-1),
                mean_power**2,
                out=np.full(len(x), 2.0),
                where=mean_power > 0,
            )
            - 2.0
        )
    minimum = np.broadcast_to(np.asarray(min_bandwidth_hz, dtype=float), (len(x),))
    narrow = (bands[:, 2] - bands[:, 1])[None, :] < minimum[:, None]
    values = np.where(narrow, -np.inf, values)
    widest = np.argmax(bands[:, 2] - bands[:, 1])
    values[~np.isfinite(values).any(axis=1), widest] = 0.0
    return Kurtogram(bands, values)


# -- the squared envelope spectrum ----------------------------------------------------------------
def squared_envelope(x, fs_hz: float, band_hz) -> np.ndarray:
    """|analytic band-passed x|^2 (`analytic_band`), mean removed: the squared envelope."""
    power = np.abs(analytic_band(x, fs_hz, band_hz)) ** 2
    return power - power.mean(axis=-1, keepdims=True)


def amplitude_spectrum(signal, fs_hz: float, pad_factor: int = 4):
    """(freqs, amplitudes) of a mean-free signal: periodic Hann window, amplitude corrected (a
    sinusoid of amplitude A shows as A), zero-padded to `pad_factor` x n points so a line is
    sampled near its top wherever it falls between bins."""
    signal = np.asarray(signal, dtype=np.float64)
    n = signal.shape[-1]
    window = np.hanning(n + 1)[:-1]
    nfft = int(pad_factor) * n
    amps = np.abs(np.fft.rfft(signal * window, n=nfft, axis=-1)) * (2.0 / window.sum())
    amps[..., 0] /= 2.0
    return np.fft.rfftfreq(nfft, d=1.0 / fs_hz), amps


def squared_envelope_spectrum(x, fs_hz: float, band_hz, pad_factor: int = 4):
    """The squared envelope spectrum (SES) of the band `band_hz` (one for all segments or one per
    segment): `amplitude_spectrum` of `squared_envelope`. Returns (freqs, amplitudes)."""
    return amplitude_spectrum(squared_envelope(x, fs_hz, band_hz), fs_hz, pad_factor)


def demodulation_bands(
    x, fs_hz: float, analysis: str, fixed_band_hz, max_level: int = 4, min_bandwidth_hz=0.0
):
    """The signal an analysis demodulates and its band per segment.

    Parameters
    ----------
    x : array_like, (n_segments, n)
    analysis : str
        One of `ANALYSES`: `fixed` (the band `fixed_band_hz`), `kurtogram` (each segment's band
        of largest spectral kurtosis), and either after cepstral prewhitening (`prewhitened_`).
    fixed_band_hz : (low, high)
    max_level, min_bandwidth_hz
        Of `kurtogram`.

    Returns
    -------
    (numpy.ndarray (n_segments, n), numpy.ndarray (n_segments, 2))
        The (prewhitened) signal and the band of every segment.
    """
    if analysis not in ANALYSES:
        raise ValueError(f"unknown envelope analysis {analysis!r}; choose one of {list(ANALYSES)}")
    x = np.atleast_2d(_x(x))
    if analysis.startswith("prewhitened_"):
        x = prewhiten(x)
    if analysis.endswith("kurtogram"):
        bands = kurtogram(x, fs_hz, max_level, min_bandwidth_hz).best()
    else:
        bands = np.broadcast_to(np.asarray(fixed_band_hz, dtype=float), (len(x), 2))
    return x, bands


# -- lines with harmonics and sidebands -----------------------------------------------------------
def fault_line_sets(
    orders: dict, sidebands: dict | None = None, harmonics: int = 2, tolerance: float = 0.015
) -> dict:
    """The lines (in shaft orders) read for each defect order.

    Parameters
    ----------
    orders : dict
        {name: order of the defect's line}, e.g. {"a": 3.585, "b": 5.415, "c": 4.713}.
    sidebands : dict, optional
        {name: sideband spacing in orders} for defects whose lines are modulated (by the shaft:
        1; by a part turning at another order: that order); the others carry none.
    harmonics : int
        Harmonics 1..harmonics of each order, each with its sidebands at +/- the spacing.
    tolerance : float
        Relative half-width of a line's window: a harmonic or sideband within twice this of a line
        of another defect is left out of both sets (it cannot tell the two apart); a defect's own
        order is never left out.

    Returns
    -------
    dict
        {name: sorted list of orders}, the defect's own order first.
    """
    if not (isinstance(harmonics, (int, np.integer)) and harmonics >= 1):
        raise ValueError(f"harmonics must be a whole number >= 1, got {harmonics!r}")
    sidebands = dict(sidebands or {})
    unknown = sorted(set(sidebands) - set(orders))
    if unknown:
        raise ValueError(
            f"sidebands for {unknown}, which are not among the defect orders {sorted(orders)}"
        )
    candidates = {}
    for name, order in orders.items():
        order = float(order)
        if not order > 0:
            raise ValueError(f"defect order {name!r}: {order} must be positive")
        spacing = float(sidebands.get(name, 0.0))
        lines = []
        for h in range(1, harmonics + 1):
            lines.append(h * order)
            if spacing > 0:
                lines += [h * order - spacing, h * order + spacing]
        candidates[name] = [line for line in lines if line > 0]

    def clash(line, name):
        return any(
            abs(line - other) <= 2 * tolerance * max(line, other)
            for other_name, others in candidates.items()
            if other_name != name
            for other in others
        )

    return {
        name: [float(orders[name])] + sorted(line for line in lines[1:] if not clash(line, name))
        for name, lines in candidates.items()
    }


def line_ratio(
    freqs, amps, lines_hz, tolerance: float = 0.015, floor_halfwidth_hz=15.0
) -> np.ndarray:
    """Summed line heights over summed local floors of envelope spectra, per segment.

    Parameters
    ----------
    freqs : numpy.ndarray, (n_freqs,)
    amps : numpy.ndarray, (n_segments, n_freqs)
        Envelope (or squared envelope) amplitude spectra.
    lines_hz : array_like, (n_lines,) or (n_segments, n_lines)
        The lines read (a defect's harmonics and sidebands), in Hz.
    tolerance : float
        A line's height is the largest amplitude within its frequency (1 +/- tolerance).
    floor_halfwidth_hz : float or array_like (n_segments,)
        Its floor is the median amplitude within +/- this of the line, outside the line's window.

    Returns
    -------
    numpy.ndarray, (n_segments,)
        sum of heights / sum of floors: about 1-3 where no line stands out, whatever the number of
        lines; one line alone gives the classic line-to-floor ratio.
    """
    amps = np.atleast_2d(amps)
    lines = np.asarray(lines_hz, dtype=float)
    lines = np.broadcast_to(
        lines if lines.ndim == 2 else lines[None, :], (len(amps), lines.shape[-1])
    )
    half = np.broadcast_to(np.asarray(floor_halfwidth_hz, dtype=float), (len(amps),))
    top = freqs[-1]
    out = np.empty(len(amps))
    for i in range(len(amps)):
        heights = floors = 0.0
        for f0 in lines[i]:
            if f0 * (1 + tolerance) + half[i] > top:
                continue  # beyond the spectrum: not read
            in_line = np.abs(freqs - f0) <= tolerance * f0
            if not in_line.any():  # window narrower than the grid: the nearest bin
                in_line = np.zeros_like(in_line)
                in_line[np.argmin(np.abs(freqs - f0))] = True
            around = (np.abs(freqs - f0) <= half[i]) & ~in_line
            if not around.any():
                raise ValueError(f"no envelope-spectrum bins around {f0:g} Hz for the floor")
            heights += amps[i, in_line].max()
            floors += np.median(amps[i, around])
        if heights == 0.0 and floors == 0.0:
            raise ValueError(
                f"no line of {lines[i].tolist()} Hz lies inside the envelope spectrum "
                f"(up to {top:g} Hz)"
            )
        out[i] = heights / max(floors, np.finfo(float).tiny)
    return out


def min_bandwidth_hz(
    line_sets: dict, shaft_hz, tolerance: float = 0.015, floor_halfwidth_orders: float = 0.5
):
    """The narrowest demodulation band whose squared envelope holds every line of `line_sets`
    ({name: orders}) with its floor: (highest order x (1 + tolerance) + the floor's half-width)
    x the shaft speed (Hz; `shaft_hz` a scalar or one per segment)."""
    highest = max(max(orders) for orders in line_sets.values())
    return (highest * (1 + tolerance) + floor_halfwidth_orders) * np.asarray(shaft_hz, dtype=float)


def line_ratios(
    x,
    fs_hz: float,
    speed_rpm,
    line_sets: dict,
    analysis: str = "fixed",
    fixed_band_hz=(2000.0, 5000.0),
    max_level: int = 4,
    tolerance: float = 0.015,
    floor_halfwidth_orders: float = 0.5,
    pad_factor: int = 4,
) -> dict:
    """The line ratio (`line_ratio`) of every line set, per segment, by one analysis.

    Parameters
    ----------
    x : array_like, (n_segments, n)
    fs_hz : float
    speed_rpm : float or array_like (n_segments,)
        The shaft speed of every segment: the lines are orders of it.
    line_sets : dict
        {name: list of orders} (`fault_line_sets`).
    analysis : str
        One of `ANALYSES` (`demodulation_bands`).
    fixed_band_hz, max_level
        The fixed band; the kurtogram's finest level. The kurtogram's bands are at least as wide
        as the highest line read plus its floor's half-width, so the SES holds every line.
    tolerance, floor_halfwidth_orders
        Of `line_ratio` (the floor's half-width in shaft orders).

    Returns
    -------
    dict
        {name: (n_segments,) ratios, "band_low_hz": ..., "band_high_hz": ...}.
    """
    x = np.atleast_2d(_x(x))
    shaft_hz = np.broadcast_to(np.asarray(speed_rpm, dtype=float), (len(x),)) / 60.0
    if not (np.isfinite(shaft_hz) & (shaft_hz > 0)).all():
        raise ValueError("envelope lines need a positive shaft speed for every segment")
    if not line_sets:
        raise ValueError("envelope lines: no line set to read")
    min_width = min_bandwidth_hz(line_sets, shaft_hz, tolerance, floor_halfwidth_orders)
    signal, bands = demodulation_bands(x, fs_hz, analysis, fixed_band_hz, max_level, min_width)
    freqs, amps = squared_envelope_spectrum(signal, fs_hz, bands, pad_factor)
    out = {
        name: line_ratio(
            freqs, amps, np.outer(shaft_hz, orders), tolerance, floor_halfwidth_orders * shaft_hz
        )
        for name, orders in line_sets.items()
    }
    out["band_low_hz"], out["band_high_hz"] = bands[:, 0].copy(), bands[:, 1].copy()
    return out

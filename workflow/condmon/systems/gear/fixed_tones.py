"""Fixed tones: narrow lines a machine's healthy records show at one frequency whatever its speed
(a motor's torque ripple at twice the line frequency, a mains hum picked up by the sensor chain).

They are no part of the gears, yet a synchronous average keeps one wherever it falls on an order of
a shaft: 120 Hz ripple of a 60 Hz motor is order 16 of a 450 rpm pinion, and with a phase of its
own in every record it leaves every record's residual a line no simulated machine has (a bench
with such a motor, config/benches/heavier-housings.yaml: its residual band of pinion orders 15-22
stood 0.5 decades above the simulated healthy ones at 450 rpm, and its pitting was found in 2 of
5 records there, at 775 and 1100 rpm, where 120 Hz falls between the orders, in all). Where it
falls between them, the average takes it out already.

- `fixed_tones`: from the healthy reference records at two or more speeds, the lines present at
  every speed at one frequency with like amplitude (a shaft-locked line moves with the speed);
- `remove_fixed_tones`: each segment less its least-squares sinusoid at each such tone that lies
  within one frequency bin of a shaft order line at the segment's speed (where the average would
  keep it); every segment, measured or simulated, so both lose the same orders.
With one speed a fixed tone cannot be told from a shaft order: none is found (logged).
"""

from __future__ import annotations

import numpy as np

# a line: a local maximum of the mean power spectrum this many times its local floor (20 dB)
LINE_PROMINENCE = 100.0
# the local floor: median power over this many bins either side
FLOOR_BINS = 25
# one tone at every speed: lines within this share of a bin, amplitudes within this ratio
SAME_FREQUENCY_BINS = 0.5
SAME_AMPLITUDE_RATIO = 3.0


def spectrum_lines(segments: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies in Hz, amplitudes) of the narrow lines of segments (n_segments, n_channels, n):
    local maxima of the Hann-windowed power spectrum averaged over segments and channels that
    stand `LINE_PROMINENCE` above the median of their `FLOOR_BINS` neighbours either side, each
    frequency refined by a parabola through the log power of its bin and the two beside it."""
    x = np.asarray(segments, dtype=float)
    x = x - x.mean(axis=-1, keepdims=True)
    n = x.shape[-1]
    window = np.hanning(n)
    power = np.mean(np.abs(np.fft.rfft(x * window, axis=-1)) ** 2, axis=(0, 1))
    padded = np.pad(power, FLOOR_BINS, mode="edge")
    neighbours = np.lib.stride_tricks.sliding_window_view(padded, 2 * FLOOR_BINS + 1)
    floor = np.median(neighbours, axis=-1)
    inner = np.arange(2, len(power) - 1)
    peaks = inner[
        (power[inner] > power[inner - 1])
        & (power[inner] >= power[inner + 1])
        & (power[inner] > LINE_PROMINENCE * np.maximum(floor[inner], 1e-300))
    ]
    log = np.log(np.maximum(power, 1e-300))
    left, centre, right = log[peaks - 1], log[peaks], log[peaks + 1]
    curvature = left - 2 * centre + right
    offset = np.where(
        curvature < 0, 0.5 * (left - right) / np.where(curvature < 0, curvature, -1.0), 0.0
    )
    amplitudes = 2.0 * np.sqrt(power[peaks]) / window.sum()
    return (peaks + offset) * fs_hz / n, amplitudes


def fixed_tones(segments_by_speed: dict, fs_hz: float) -> list[float]:
    """The frequencies (Hz) of the lines the healthy segments show at every speed at one frequency
    (within `SAME_FREQUENCY_BINS` of a bin) and with like amplitude (within
    `SAME_AMPLITUDE_RATIO`): `segments_by_speed` {speed: (n_segments, n_channels, n)}. Empty with
    fewer than two speeds."""
    if len(segments_by_speed) < 2:
        return []
    found = [
        spectrum_lines(segments, fs_hz) + (fs_hz / np.shape(segments)[-1],)
        for segments in segments_by_speed.values()
    ]
    (first, first_amplitudes, _), others = found[0], found[1:]
    tones = []
    for frequency, amplitude in zip(first, first_amplitudes):
        matches = []
        for lines, amplitudes, bin_hz in others:
            near = np.flatnonzero(np.abs(lines - frequency) <= SAME_FREQUENCY_BINS * bin_hz)
            if not len(near):
                break
            matches.append((lines[near[0]], amplitudes[near[0]]))
        else:
            levels = [amplitude] + [a for _, a in matches]
            if max(levels) <= SAME_AMPLITUDE_RATIO * min(levels):
                tones.append(float(np.mean([frequency] + [f for f, _ in matches])))
    return tones


def kept_by_the_average(tone_hz: float, speed_rpm: float, seconds: float, shafts) -> bool:
    """Whether a tone lies within one frequency bin (1 / `seconds`) of an order line of one of the
    `shafts` ([(name, speed ratio to the input shaft, teeth)]) at `speed_rpm`: there a segment's
    synchronous average keeps it (its main lobe); elsewhere the average takes it out."""
    for _, ratio, _ in shafts:
        shaft_hz = float(ratio) * speed_rpm / 60.0
        if abs(tone_hz - round(tone_hz / shaft_hz) * shaft_hz) * seconds < 1.0:
            return True
    return False


def remove_fixed_tones(
    segment: np.ndarray, fs_hz: float, speed_rpm: float, shafts, tones
) -> tuple[np.ndarray, list]:
    """(segment less the tones the average would keep, those tones): one segment (n_channels, n),
    each channel less its least-squares fit of a constant and a sinusoid at each such tone."""
    x = np.asarray(segment, dtype=float)
    seconds = x.shape[-1] / fs_hz
    kept = [float(f) for f in tones if kept_by_the_average(float(f), speed_rpm, seconds, shafts)]
    if not kept:
        return x, []
    t = np.arange(x.shape[-1]) / fs_hz
    basis = np.column_stack(
        [np.ones_like(t)] + [fn(2 * np.pi * f * t) for f in kept for fn in (np.cos, np.sin)]
    )
    coefficients, *_ = np.linalg.lstsq(basis, x.T, rcond=None)
    coefficients[0] = 0.0  # the mean stays: only the tones go
    return x - (basis @ coefficients).T, kept

"""Residual signatures in the angle domain: each record's synchronous average against its own
machine's healthy one, subtracted as a waveform before any level or log.

Why: at a light load the gear pair's own manufacturing errors (a pitch pattern of several um)
dwarf the mesh deflection (about 0.5 um), so a few damaged teeth barely move the *levels* of the
order bands, and how they move them depends on the pair. Their change of the *waveform* at the
damaged teeth is the same on every pair. Condition monitoring compares a machine with itself:
take each shaft's time-synchronous average (TSA), align it to the machine's healthy TSA (a record
starts at any shaft angle; the pitch pattern is the fingerprint the circular cross-correlation
finds, on the orders the features read) and subtract it. What remains is the change since the
machine was healthy (McFadden 1987; Randall 2011, ch. 5-6; ../shared/notes/gear-residuals.md).

Per segment: the input shaft's angle by tacholess tracking of the mesh phase
(`order_features.segment_angle`), then each shaft's residual pattern R, the shafts kept apart.
Each pinion tooth meets every gear tooth only over the pair's hunting cycle (29/44 teeth: 44
pinion revolutions, 5.9 s at 450 rpm), and load sharing is each tooth pair's own, so a record
is no sum of two shaft patterns.
- Where the machine's healthy reference records cover the cycle: the reference is their average
  over the cycle (`hunting_cycle`), the segment less that average where it lies in the cycle
  (`cycle_residual`) is split into the shafts' residual patterns (`shaft_patterns`), and each
  shaft's reference pattern is the cycle's own orders of that shaft (`cycle_shaft_patterns`).
- Where they are shorter, the mating gear's pattern stays in a shaft's plain TSA, so the
  patterns are estimated jointly (alternating projections: each shaft's TSA of the signal less
  the other shafts' patterns, `SEPARATION_ITERATIONS` times; the orders common to both shafts,
  the mesh harmonics, go to the first), each aligned to its reference and subtracted: R =
  aligned TSA - reference TSA (`residual_features`).
From R (`residual_signatures`):
- `b<k>`: R's order spectrum in bands (orders of that shaft), over the reference's own level in
  the band (a ratio, so the transfer path from mesh to sensor, which scales both, cancels); with
  `reference_level: without_mesh_lines` the reference's level leaves its mesh harmonics out:
  a band's RMS is then the level of its sidebands and pitch-error orders, which the path scales,
  not of the one mesh line, whose size is the mesh's transmission error (its compliance and
  load), which healthy records do not identify;
- `rms_ratio`: R's RMS over the reference's;
- `FM4`, `NA4`: kurtosis of R's difference signal (R less shaft orders, mesh harmonics and their
  sidebands) and of its residual signal over the reference's residual variance (NA4 as defined,
  against the healthy run: Zakrajsek, Townsend, Decker 1993, NASA TM-105950);
- `tooth_peak1`, `tooth_peak3`: the largest energy of R's residual signal over one (three) tooth
  pitch(es), sliding round the revolution, over the median: a localised fault stands out on its
  own teeth, wear of every tooth does not.
Before any of this every segment loses the machine's fixed tones where its average would keep
them (`fixed_tones`: lines its healthy records show at one frequency at every speed, e.g. a
motor's ripple, found on the measured calibration records and packaged with the references).
All features are log10. Names `res_<channel>_<shaft>_<feature>`. With `magnitudes: false` the two
that grow with the fault's size (`rms_ratio`, `NA4`) are left out and the bands are given as their
shape (less their mean over the bands): that size follows the mesh's compliance, which healthy
records do not identify.
"""

from __future__ import annotations

import json
import logging
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
import pandas as pd
from scipy.interpolate import CubicSpline
from scipy.signal import resample_poly

from condmon.features import FamilyInputs, FeatureTableError, single_sampling_rate
from condmon.hybrid import calibration_frame
from condmon.signals import to_arrays
from condmon.simulate import machine_of
from condmon.systems.gear.fixed_tones import fixed_tones, remove_fixed_tones
from condmon.systems.gear.order_features import difference_signal, residual_signal, segment_angle

log = logging.getLogger(__name__)

SEPARATION_ITERATIONS = 40
CYCLE_UPSAMPLING = 4
TINY = 1e-12
FEATURES = ("rms_ratio", "FM4", "NA4", "tooth_peak1", "tooth_peak3")
# per damaged shaft, every channel together (`damaged_pitches`): how the change is spread over the
# teeth, whatever its size (`teeth_features`)
TEETH_FEATURES = ("participation", "share1", "share3")
# the features that grow with the fault's size (and the machine's mesh compliance, which healthy
# records do not identify); `magnitudes: false` leaves them out and gives the bands as a shape
SIZED_FEATURES = ("rms_ratio", "NA4")


# -- synchronous patterns ----------------------------------------------------------------------
def resample_at(
    x: np.ndarray, angle: np.ndarray, samples_per_revolution: int, upsampling: int = 1
) -> np.ndarray:
    """Channels x (n_channels, n_samples) at the angles 0, 1/P, 2/P, ... of a shaft whose angle
    (revolutions, increasing from 0) is `angle` at every sample: cubic spline in time, every whole
    grid step within the segment. No anti-alias filter: on a grid coarser than the samples,
    content above its Nyquist order folds, and `check_resolution` keeps that above every order
    the features use. With `upsampling` the samples are first interpolated that many times finer
    (polyphase, `scipy.signal.resample_poly`): a spline through three samples a period (the third
    mesh harmonic at 1100 rpm) errs by a few per cent between them, through twelve it does not."""
    if upsampling > 1:
        x = resample_poly(x, int(upsampling), 1, axis=-1)
        angle = np.interp(np.arange(x.shape[-1]) / upsampling, np.arange(len(angle)), angle)
    n = x.shape[-1]
    steps = int(np.floor((angle[-1] - angle[0]) * samples_per_revolution + 1e-9)) + 1
    grid = angle[0] + np.arange(steps) / samples_per_revolution
    instants = np.interp(grid, angle, np.arange(n, dtype=np.float64))
    return CubicSpline(np.arange(n), x, axis=-1)(instants)


def synchronous_average(
    x: np.ndarray, angle: np.ndarray, samples_per_revolution: int
) -> np.ndarray:
    """TSA (n_channels, P) over the whole revolutions of a shaft at `angle`: the plain TSA, which
    keeps what another shaft leaves in a short record (`shaft_patterns` keeps it out)."""
    resampled = resample_at(x, angle, samples_per_revolution)
    revolutions = resampled.shape[-1] // samples_per_revolution
    if revolutions < 1:
        raise ValueError("less than one revolution of a shaft to average")
    return fold(resampled[..., : revolutions * samples_per_revolution], samples_per_revolution)


# pattern_at's interpolation grid: the pattern upsampled this many times (its DFT's own
# interpolant, read linearly in between)
PATTERN_UPSAMPLING = 8


def pattern_grid(samples_per_revolution: int) -> np.ndarray:
    """`pattern_at`'s grid over one revolution of a pattern of that many samples (in samples)."""
    return np.arange(samples_per_revolution * PATTERN_UPSAMPLING + 1) / PATTERN_UPSAMPLING


def interpolation_points(angle: np.ndarray, samples_per_revolution: int) -> tuple:
    """(index, offset) of the shaft angles `angle` (revolutions) on `pattern_grid`: found once
    for angles at which many patterns are read (`shaft_patterns` reads every iteration's
    patterns at the same angles)."""
    p = samples_per_revolution
    grid = pattern_grid(p)
    position = np.mod(angle, 1.0) * p
    position = np.where(position >= p, position - p, position)  # mod of a tiny negative angle
    index = np.clip(np.searchsorted(grid, position, side="right") - 1, 0, len(grid) - 2)
    return index, position - grid[index]


def pattern_at(pattern: np.ndarray, angle=None, points=None) -> np.ndarray:
    """A periodic pattern (n_channels, P samples over one revolution) at the shaft angles `angle`
    (revolutions), or at their `interpolation_points`: band-limited interpolation (its DFT
    evaluated there), so a pattern put back in time is the pattern, whatever the angles."""
    p = pattern.shape[-1]
    index, offset = interpolation_points(angle, p) if points is None else points
    # linear interpolation on a finely upsampled copy, as np.interp computes it (the same
    # numbers), without its search for every angle of every channel
    fine = PATTERN_UPSAMPLING
    spectrum = np.fft.rfft(pattern, axis=-1)
    upsampled = np.fft.irfft(spectrum, n=p * fine, axis=-1) * fine
    grid = pattern_grid(p)
    wrapped = np.concatenate([upsampled, upsampled[..., :1]], axis=-1)
    slopes = (wrapped[..., 1:] - wrapped[..., :-1]) / (grid[1:] - grid[:-1])
    return np.take(slopes, index, axis=-1) * offset + np.take(wrapped, index, axis=-1)


def without_orders(pattern: np.ndarray, period_orders: int) -> np.ndarray:
    """The pattern less its components at multiples of `period_orders` (and its mean)."""
    spectrum = np.fft.rfft(pattern, axis=-1)
    spectrum[..., ::period_orders] = 0.0
    return np.fft.irfft(spectrum, n=pattern.shape[-1], axis=-1)


def shaft_patterns(
    segment: np.ndarray,
    angle: np.ndarray,
    shafts,
    samples_per_revolution: int,
    iterations: int = SEPARATION_ITERATIONS,
) -> list[np.ndarray]:
    """Each shaft's synchronous pattern (n_channels, P) in one segment (n_channels, n_samples),
    the shafts kept apart: alternating projections, each shaft's TSA of the segment less the other
    shafts' patterns. An order common to two shafts (a mesh harmonic: teeth x the shaft's order)
    cannot be told apart, so it stays with the first shaft and is taken out of the others'.
    `shafts`: [(name, speed ratio to the input shaft, teeth)]; `angle`: the input shaft's.

    The segment is resampled once per shaft; another shaft's pattern is then evaluated at the
    angles it has on this shaft's grid (its speed ratio times the grid's angles), so an
    iteration costs no resampling. Two gears on one shaft (a train's intermediate shaft: the same
    ratio) are one pattern, the first's (its mesh's orders taken out as above), given to both."""
    owners = [
        next(j for j, other in enumerate(shafts) if float(other[1]) == float(ratio))
        for _, ratio, _ in shafts
    ]
    if owners != list(range(len(shafts))):
        distinct = sorted(set(owners))
        patterns = shaft_patterns(
            segment, angle, [shafts[k] for k in distinct], samples_per_revolution, iterations
        )
        return [patterns[distinct.index(owner)] for owner in owners]
    x = np.asarray(segment, dtype=np.float64)
    x = x - x.mean(axis=-1, keepdims=True)
    P = samples_per_revolution
    resampled, grids = [], []
    for _, ratio, _ in shafts:
        on_grid = resample_at(x, angle * float(ratio), P)
        whole = (on_grid.shape[-1] // P) * P
        if whole < P:
            raise ValueError("less than one revolution of a shaft to average")
        resampled.append(on_grid[..., :whole])
        grids.append(np.arange(whole) / P)  # this shaft's angle at its grid points, revolutions
    patterns = [np.zeros((x.shape[0], P)) for _ in shafts]
    # where each other shaft's pattern is read on this shaft's grid: the same every iteration
    points = {
        (k, j): interpolation_points(grids[k] * float(shafts[j][1]) / float(shafts[k][1]), P)
        for k in range(len(shafts))
        for j in range(len(shafts))
        if j != k
    }
    for _ in range(iterations if len(shafts) > 1 else 1):
        for k, (_, _, teeth) in enumerate(shafts):
            others = sum(
                (
                    pattern_at(patterns[j], points=points[k, j])
                    for j in range(len(shafts))
                    if j != k
                ),
                np.zeros_like(resampled[k]),
            )
            pattern = fold(resampled[k] - others, P)
            patterns[k] = (
                without_orders(pattern, int(teeth))
                if k > 0
                else pattern - pattern.mean(axis=-1, keepdims=True)
            )
    return patterns


def fold(on_grid: np.ndarray, samples_per_revolution: int) -> np.ndarray:
    """Mean over the whole revolutions of a signal on a shaft's angular grid: its TSA."""
    return on_grid.reshape(*on_grid.shape[:-1], -1, samples_per_revolution).mean(axis=-2)


# -- alignment -----------------------------------------------------------------------------------
def alignment_shift(
    tsa: np.ndarray,
    reference: np.ndarray,
    teeth: int,
    top_order: int | None = None,
    start: float | None = None,
) -> float:
    """The shift s (samples, fractional) that best aligns `tsa` to `reference` (both (n_channels,
    P)): tsa(i + s) ~ reference(i). Circular cross-correlation summed over the channels, of both
    less their mesh harmonics (periodic with the tooth pitch, they would make every whole-tooth
    shift look alike; what is left, the pitch pattern and eccentricity, is the fingerprint): its
    peak, then refined on the correlation of the whole patterns as a continuous function of the
    shift (Newton steps on its DFT form), since a residue of the strong mesh harmonics would
    otherwise remain. With `top_order` only the orders up to it take part: above the orders the
    features read, a short record at a low speed holds more noise than pattern (the pattern's
    acceleration falls with the speed squared, the sensor's noise does not), and their
    correlation could pick a wrong whole-tooth shift. With `start`, the refinement starts there
    instead of at the fingerprint's peak."""
    a = np.fft.rfft(np.atleast_2d(tsa), axis=-1)
    b = np.fft.rfft(np.atleast_2d(reference), axis=-1)
    p = np.atleast_2d(tsa).shape[-1]
    if top_order is not None:
        a[..., int(top_order) + 1 :] = 0.0
    fingerprint = (a * np.conj(b)).sum(axis=0)
    fingerprint[::teeth] = 0.0
    shift = float(np.argmax(np.fft.irfft(fingerprint, n=p))) if start is None else float(start) % p
    # the correlation c(s) = sum_m w_m Re(A_m conj(B_m) e^{2 pi i m s / P}); maximise near the peak
    cross = (a * np.conj(b)).sum(axis=0) * np.where(np.arange(p // 2 + 1) % (p // 2) == 0, 1.0, 2.0)
    omega = 2 * np.pi * np.arange(p // 2 + 1) / p
    for _ in range(4):
        turned = cross * np.exp(1j * omega * shift)
        slope, curvature = -np.sum(omega * turned.imag), -np.sum(omega**2 * turned.real)
        if curvature >= 0:
            break
        shift -= float(np.clip(slope / curvature, -0.5, 0.5))
    return shift - p if shift > p / 2 else shift


# A pitch of a segment's residual (less shaft orders and mesh harmonics) holding over this many
# times the median pitch's energy carries a fault, not the healthy pitch pattern the alignment
# reads: a healthy segment's residual, noise and alignment error, stays below it (a pure-noise
# residual on the bands' orders passed 3 x in a third of the draws, never 5 x:
# tests/test_residual_features.py).
FAULT_PITCH_EXCESS = 5.0


def fault_masked_shift(
    tsa: np.ndarray,
    reference: np.ndarray,
    teeth: int,
    top_order: int | None = None,
    rounds: int = 3,
) -> float:
    """`alignment_shift` with the pitches that hold a localised fault left out of the fingerprint.
    A strong fault (pitting at a gearbox's load: a residual 80 times the healthy one) dominates
    the pattern less its mesh harmonics, and its correlation with the reference's pitch pattern
    picks the same wrong whole-tooth shift on every record: the damaged teeth named where they
    are not. So: align, find the pitches of the residual above FAULT_PITCH_EXCESS (and their
    neighbours, which the contact ratio shares the change with), take the peak of the rest's
    correlation with the reference, up to `rounds` times, on the orders that tell the teeth apart
    under a mask (above the shaft orders 1-2, up to `top_order`, less the mesh harmonics: strong
    and smooth, those would leak into every order when cut); then refine on the whole pattern
    from there (the mask's edges would pull the fraction). Without such a pitch the shift is
    `alignment_shift`'s."""
    shift = alignment_shift(tsa, reference, teeth, top_order)
    p = np.atleast_2d(tsa).shape[-1]
    top = p // 2 if top_order is None else int(top_order)
    pitch = p / teeth
    fingerprint = band_limited(np.atleast_2d(tsa), 1, top, teeth, lowest_order=3)
    reference_print = np.conj(
        np.fft.rfft(band_limited(np.atleast_2d(reference), 1, top, teeth, lowest_order=3), axis=-1)
    )
    # the samples of `tsa` (its own frame: the fault stays put while the shift moves) left out
    kept = np.ones(p)
    for _ in range(rounds):
        residual = band_limited(np.atleast_2d(shifted(tsa, shift) - reference), 1, top)
        excess = damaged_pitches(residual_signal(residual, teeth), teeth)  # over the median, less 1
        found = np.zeros(p, dtype=bool)
        for k in np.flatnonzero(excess > FAULT_PITCH_EXCESS - 1.0):
            # pitch k of the residual and its neighbours, where they lie in `tsa`
            first = int(np.floor((k - 1) * pitch + shift))
            found[np.arange(first, first + int(np.ceil(3 * pitch))) % p] = True
        if not np.any(found & (kept > 0)):
            break
        kept[found] = 0.0
        cross = (np.fft.rfft(fingerprint * kept, axis=-1) * reference_print).sum(axis=0)
        shift = float(np.argmax(np.fft.irfft(cross, n=p)))
    if kept.all():
        return shift
    return alignment_shift(tsa, reference, teeth, top_order, start=shift)


def shifted(pattern: np.ndarray, shift: float) -> np.ndarray:
    """pattern(i + shift), circularly, by the DFT's shift theorem (any fractional shift)."""
    p = pattern.shape[-1]
    spectrum = np.fft.rfft(pattern, axis=-1) * np.exp(
        2j * np.pi * np.arange(p // 2 + 1) * shift / p
    )
    return np.fft.irfft(spectrum, n=p, axis=-1)


def aligned(
    tsa: np.ndarray, reference: np.ndarray, teeth: int, top_order: int | None = None
) -> np.ndarray:
    """`tsa` shifted onto `reference` (`alignment_shift`)."""
    return shifted(tsa, alignment_shift(tsa, reference, teeth, top_order))


def fault_aligned(
    tsa: np.ndarray, reference: np.ndarray, teeth: int, top_order: int | None = None
) -> np.ndarray:
    """`tsa` shifted onto `reference` with a localised fault's pitches left out of the alignment
    (`fault_masked_shift`): how a test segment meets its healthy reference."""
    return shifted(tsa, fault_masked_shift(tsa, reference, teeth, top_order))


def reference_pattern(patterns, teeth: int, top_order: int | None = None) -> np.ndarray:
    """The healthy reference of one shaft from several segments' patterns (each (n_channels, P)):
    each aligned to the first (on the orders up to `top_order`), then their mean."""
    first = np.asarray(patterns[0], dtype=np.float64)
    return np.mean(
        [first]
        + [aligned(np.asarray(p, dtype=np.float64), first, teeth, top_order) for p in patterns[1:]],
        axis=0,
    )


def top_band_order(band_orders: float, n_bands: int) -> int:
    """The highest shaft order `band_levels`' bands hold (band k: orders from 0.5 + k x
    `band_orders`): the orders the alignment reads."""
    return int(np.ceil(0.5 + n_bands * band_orders)) - 1


# -- the hunting cycle ---------------------------------------------------------------------------
def hunting_revolutions(shafts) -> int:
    """Revolutions of the input shaft after which every shaft is back at its starting angle: the
    pair's hunting cycle (29/44 teeth: 44), over which each tooth has met every mating tooth."""
    return int(
        np.lcm.reduce(
            [Fraction(float(ratio)).limit_denominator(100000).denominator for _, ratio, _ in shafts]
        )
    )


def hunting_cycle(
    record: np.ndarray, angle: np.ndarray, revolutions: int, samples_per_revolution: int
):
    """The synchronous average of a record (n_channels, n_samples) over the hunting cycle
    (`revolutions` of the input shaft, whose angle is `angle`): (n_channels, revolutions x P),
    every point of the cycle the mean over the cycles the record's middle covers there (its
    ends, where the tracked angle settles, left out as far as the record is longer than a
    cycle); None where the record covers less than one cycle."""
    x = np.asarray(record, dtype=np.float64)
    # the cycle's values come back at other instants of other records (`cycle_residual`), so
    # between samples they must be the signal's, not the spline's
    on_grid = resample_at(
        x - x.mean(axis=-1, keepdims=True), angle, samples_per_revolution, CYCLE_UPSAMPLING
    )
    length = int(revolutions) * samples_per_revolution
    if on_grid.shape[-1] < length:
        return None
    edge = cycle_start(on_grid.shape[-1], length, samples_per_revolution)
    on_grid = on_grid[..., edge : on_grid.shape[-1] - edge]
    position = np.arange(on_grid.shape[-1]) % length
    counts = np.bincount(position, minlength=length)
    return (
        np.stack([np.bincount(position, weights=channel, minlength=length) for channel in on_grid])
        / counts
    )


def cycle_start(n_grid: int, length: int, samples_per_revolution: int) -> int:
    """Grid samples of a record (n_grid on its input shaft's grid) left out before its hunting
    cycle average begins (`hunting_cycle`; a cycle `length` samples long): the record's middle,
    up to half a revolution left out at either end, where the tracked angle settles (its phase
    filter's edges), so the cycle's two ends do not mix them in."""
    return min((n_grid - length) // 2, samples_per_revolution // 2)


def cycle_shaft_patterns(
    cycle: np.ndarray, shafts, revolutions: int, samples_per_revolution: int
) -> list:
    """Each shaft's synchronous pattern (n_channels, P) from a hunting-cycle average: the cycle's
    orders at multiples of the shaft's turns per cycle, exact, since over a whole cycle every other
    shaft's pattern averages out. The mesh harmonics stay with the first shaft, as in
    `shaft_patterns`."""
    P = samples_per_revolution
    spectrum = np.fft.rfft(cycle, axis=-1)
    patterns = []
    for k, (_, ratio, teeth) in enumerate(shafts):
        own = spectrum[..., :: int(round(revolutions * float(ratio)))][..., : P // 2 + 1]
        orders = np.zeros((cycle.shape[0], P // 2 + 1), complex)
        orders[..., : own.shape[-1]] = own
        pattern = np.fft.irfft(orders, n=P, axis=-1) * P / cycle.shape[-1]
        patterns.append(
            without_orders(pattern, int(teeth))
            if k > 0
            else pattern - pattern.mean(axis=-1, keepdims=True)
        )
    return patterns


def band_limited(
    x: np.ndarray,
    turns: int,
    top_order: int,
    without_multiples_of: int = 0,
    lowest_order: int = 0,
) -> np.ndarray:
    """`x` (n_channels, n: `turns` revolutions of the input shaft on its grid) without its orders
    above `top_order` (and below `lowest_order`) and, with `without_multiples_of` (a tooth
    count), without the mesh harmonics."""
    spectrum = np.fft.rfft(x, axis=-1)
    bins = np.arange(spectrum.shape[-1])
    spectrum[..., (bins > top_order * turns) | (bins < lowest_order * turns)] = 0.0
    if without_multiples_of:
        spectrum[..., bins % (int(without_multiples_of) * turns) == 0] = 0.0
    return np.fft.irfft(spectrum, n=x.shape[-1], axis=-1)


def cycle_offset(
    on_grid: np.ndarray, cycle: np.ndarray, samples_per_revolution: int, teeth: int, top_order: int
) -> float:
    """Where in the hunting cycle (n_channels, L) a record lies (n_channels, n: whole input
    revolutions on the same grid): the offset o (grid samples, fractional) with on_grid(i) ~
    cycle(i + o). First the peak of the fingerprint's correlation (the orders up to `top_order`
    less the mesh harmonics, which repeat every tooth): it tells which teeth of both gears meet.
    Then the whole band-limited correlation's maximum within half a tooth of it, refined by a
    parabola through its neighbours: the mesh harmonics fix the angle within the tooth."""
    P, length, n = samples_per_revolution, cycle.shape[-1], on_grid.shape[-1]
    turns, cycle_turns = n // P, length // P

    def correlation(without_mesh: int) -> np.ndarray:
        # the record wrapped onto the cycle (a record longer than a cycle adds on itself)
        limited = band_limited(on_grid, turns, top_order, without_mesh)
        padded = np.zeros((on_grid.shape[0], -(-n // length) * length))
        padded[..., :n] = limited
        record = padded.reshape(on_grid.shape[0], -1, length).sum(axis=1)
        reference = band_limited(cycle, cycle_turns, top_order, without_mesh)
        # c(o) = sum_i record(i) cycle(i + o), summed over the channels
        return np.fft.irfft(
            (np.conj(np.fft.rfft(record, axis=-1)) * np.fft.rfft(reference, axis=-1)).sum(axis=0),
            n=length,
        )

    coarse = int(np.argmax(correlation(teeth)))
    whole = correlation(0)
    half_tooth = max(1, P // (2 * int(teeth)))
    near = (coarse + np.arange(-half_tooth, half_tooth + 1)) % length
    peak = int(near[np.argmax(whole[near])])
    left, centre, right = whole[(peak - 1) % length], whole[peak], whole[(peak + 1) % length]
    curvature = left - 2 * centre + right
    return float(peak + (0.5 * (left - right) / curvature if curvature < 0 else 0.0))


def cycle_residual(
    segment: np.ndarray,
    angle: np.ndarray,
    cycle: np.ndarray,
    samples_per_revolution: int,
    teeth: int,
    top_order: int,
    with_offset: bool = False,
):
    """A segment (n_channels, n_samples; input-shaft angle `angle`) less its machine's healthy
    hunting-cycle average where it lies in the cycle (`cycle_offset`), in time: what is left is
    the change since the machine was healthy, with neither gear's pattern in it, whichever part
    of the cycle the segment covers. With `with_offset`, (residual, where the segment's first
    sample lies in the cycle: grid samples)."""
    x = np.asarray(segment, dtype=np.float64)
    x = x - x.mean(axis=-1, keepdims=True)
    P = samples_per_revolution
    on_grid = resample_at(x, angle, P)
    whole = (on_grid.shape[-1] // P) * P
    if whole < P:
        raise ValueError("less than one revolution of a shaft to average")
    offset = cycle_offset(on_grid[..., :whole], cycle, P, teeth, top_order)
    residual = x - pattern_at(cycle, ((angle - angle[0]) * P + offset) / cycle.shape[-1])
    return (residual, offset) if with_offset else residual


# -- features of a residual ----------------------------------------------------------------------
def band_levels(
    pattern: np.ndarray, band_orders: float, n_bands: int, without_multiples_of: int = 0
) -> np.ndarray:
    """RMS order amplitude of a one-revolution pattern (n_channels, P) in bands `band_orders` wide
    from order 0.5: (n_channels, n_bands). Bin m of its DFT is shaft order m exactly. With
    `without_multiples_of` (a tooth count) the orders at its multiples, the mesh harmonics, are
    left out of every band."""
    amplitudes = 2.0 * np.abs(np.fft.rfft(pattern, axis=-1)) / pattern.shape[-1]
    orders = np.arange(amplitudes.shape[-1])
    band = np.floor((orders - 0.5) / band_orders).astype(int)
    if without_multiples_of:
        band[orders % int(without_multiples_of) == 0] = -1
    out = np.zeros((pattern.shape[0], n_bands))
    for k in range(n_bands):
        inside = band == k
        out[:, k] = np.sqrt(np.mean(amplitudes[:, inside] ** 2, axis=-1)) if inside.any() else 0.0
    return out


def tooth_peak(signal: np.ndarray, teeth: int, pitches: int) -> np.ndarray:
    """Largest energy of `signal` (n_channels, P, one revolution) over `pitches` tooth pitches,
    sliding round the revolution, over the median such energy: near 1 for a change spread over
    every tooth, large for one on a few teeth."""
    p = signal.shape[-1]
    window = max(1, int(round(pitches * p / teeth)))
    energy = np.concatenate([signal, signal[..., :window]], axis=-1) ** 2
    cumulative = np.concatenate(
        [np.zeros((energy.shape[0], 1)), np.cumsum(energy, axis=-1)], axis=-1
    )
    sliding = cumulative[:, window : window + p] - cumulative[:, :p]
    return sliding.max(axis=-1) / np.maximum(np.median(sliding, axis=-1), TINY)


def pitch_energies(signal: np.ndarray, teeth: int) -> np.ndarray:
    """Energy of `signal` (n_channels, P: one revolution from a tooth pitch's start) in each of
    the `teeth` tooth pitches, over the channel's median pitch: (n_channels, teeth)."""
    p = signal.shape[-1]
    edges = np.round(np.arange(teeth + 1) * p / teeth).astype(int)
    energy = np.add.reduceat(np.asarray(signal, dtype=np.float64) ** 2, edges[:-1], axis=-1)
    return energy / np.maximum(np.median(energy, axis=-1, keepdims=True), TINY)


def damaged_pitches(signal: np.ndarray, teeth: int) -> np.ndarray:
    """How a residual signal's change is spread over the teeth, every channel together: the
    channels' median of `pitch_energies` less the floor (1, the median pitch), at least 0:
    (teeth,). Every sensor sees the same teeth through its own path; the median keeps what most
    of them agree on."""
    return np.maximum(np.median(pitch_energies(signal, teeth), axis=0) - 1.0, 0.0)


def teeth_participation(excess: np.ndarray) -> float:
    """How many tooth pitches a change is spread over: (sum x)^2 / sum x^2 of the pitches' excess
    energy x (1: a single tooth, as a broken one; a few: pitting of neighbouring teeth; near the
    count of teeth: every tooth alike, or nothing but noise)."""
    total = float(np.sum(excess))
    return total**2 / float(np.sum(excess**2)) if total > TINY else float(len(excess))


def tooth_share(excess: np.ndarray, pitches: int) -> float:
    """The largest share of the excess within `pitches` neighbouring pitches (round the gear)."""
    total = float(np.sum(excess))
    if total <= TINY:
        return pitches / len(excess)
    window = np.convolve(
        np.concatenate([excess, excess[: pitches - 1]]), np.ones(pitches), mode="valid"
    )
    return float(window.max() / total)


def teeth_features(excess: np.ndarray) -> dict:
    """TEETH_FEATURES of a shaft's `damaged_pitches` (linear; the caller takes logs)."""
    return {
        "participation": teeth_participation(excess),
        "share1": tooth_share(excess, 1),
        "share3": tooth_share(excess, 3),
    }


def located_tooth(excess: np.ndarray) -> tuple[int, float]:
    """(the pitch holding the most excess energy, its share of the excess): where a localised
    fault sits, and how sure (1: all the change on that tooth)."""
    return int(np.argmax(excess)), tooth_share(excess, 1)


def in_reference_frame(residual: np.ndarray, turns: float) -> np.ndarray:
    """A shaft's residual pattern (n_channels, P) whose first sample lies `turns` revolutions of
    the shaft into its machine's reference frame (`reference_frames`), turned so that its first
    sample is the frame's: pitch k is then the same tooth on every record of the machine."""
    return shifted(residual, -(float(turns) % 1.0) * residual.shape[-1])


def reference_frames(references: dict, shafts, top_orders) -> dict:
    """{condition: the turns of each shaft from the first condition's reference to its own}: one
    frame for the machine's teeth at every condition. Each condition's reference starts where its
    own calibration record did; its pattern aligned to the first condition's (`alignment_shift`,
    the pitch pattern as the fingerprint) says how far apart they lie. The pitch pattern changes
    with the load and speed (what a tooth's deviation does depends on how far the mesh deflects),
    so the steps from each condition to the next (`frame_shift`) check it: where they put the
    condition a whole tooth elsewhere, theirs is the tooth."""
    keys = sorted(references)
    shifts = {keys[0]: np.zeros(len(shafts))}
    for previous, key in zip(keys, keys[1:]):
        shifts[key] = np.array(
            [
                frame_shift(
                    references[key][k],
                    references[keys[0]][k],
                    references[previous][k],
                    shifts[previous][k],
                    teeth,
                    top_orders[k],
                )
                for k, (_, _, teeth) in enumerate(shafts)
            ]
        )
    return {
        key: -shift / np.array([references[key][k].shape[-1] for k in range(len(shafts))])
        for key, shift in shifts.items()
    }


def frame_shift(pattern, first, previous, previous_shift: float, teeth: int, top_order) -> float:
    """The shift (samples) of one condition's reference `pattern` onto the `first` condition's:
    aligned to it directly where that agrees within half a tooth with the steps through the
    `previous` condition (whose own shift onto the first is `previous_shift`), else the steps'
    whole tooth, refined on the first's pattern. On the two-stage bench the 150 and 450 N m
    patterns correlated nearly as well at a wrong whole tooth as at the right one (0.88 of the
    peak), each beside 300 N m clearly (0.40 and 0.50): the direct alignment named the pitted
    teeth 7 pitches off at 450 N m."""
    direct = alignment_shift(pattern, first, teeth, top_order)
    steps = previous_shift + alignment_shift(pattern, previous, teeth, top_order)
    p = np.shape(pattern)[-1]
    if abs((direct - steps + p / 2) % p - p / 2) <= p / teeth / 2:
        return direct
    return alignment_shift(pattern, first, teeth, top_order, start=steps)


def residual_features(
    pattern: np.ndarray,
    reference: np.ndarray,
    teeth: int,
    band_orders: float,
    n_bands: int,
    shaft_orders: int = 2,
    mesh_harmonics: int = 3,
    reference_level: str = "whole",
) -> dict:
    """The residual features of one shaft's pattern against its healthy reference (both
    (n_channels, P)): {feature: (n_channels,)}, linear (the caller takes logs). `reference_level`
    (REFERENCE_LEVELS): what the bands are taken over. Module docstring."""
    residual = (
        fault_aligned(pattern, reference, teeth, top_band_order(band_orders, n_bands)) - reference
    )
    return residual_signatures(
        residual,
        reference,
        teeth,
        band_orders,
        n_bands,
        shaft_orders,
        mesh_harmonics,
        reference_level,
    )


def residual_signatures(
    residual: np.ndarray,
    reference: np.ndarray,
    teeth: int,
    band_orders: float,
    n_bands: int,
    shaft_orders: int = 2,
    mesh_harmonics: int = 3,
    reference_level: str = "whole",
) -> dict:
    """`residual_features` of a shaft's residual pattern R (already taken against its healthy
    reference, both (n_channels, P)); the reference gives the levels the features are taken over.
    R and the reference are first cut to the orders the bands hold (`top_band_order`), as the
    alignment reads them: above them a record at a low speed holds more of its tracked angle's
    error than pattern (the error's phase grows with the order, and there lie the high mesh
    harmonics and the housings' modes: at 450 rpm on the default bench 70 % of a record's energy
    lies above order 87, 650 Hz), and a healthy record's residual signal there peaked on a few
    teeth 20-60 times its median (bench seed 8 and the heavier-housings bench, 450 rpm: 2 of 8
    healthy segments called faulty, 1 of 8 on the bands' orders)."""
    top = top_band_order(band_orders, n_bands)
    residual, reference = band_limited(residual, 1, top), band_limited(reference, 1, top)
    levels = band_levels(residual, band_orders, n_bands)
    reference_levels = band_levels(
        reference, band_orders, n_bands, teeth if reference_level == "without_mesh_lines" else 0
    )
    reference_rms = np.sqrt(
        np.mean((reference - reference.mean(axis=-1, keepdims=True)) ** 2, axis=-1)
    )
    local = residual_signal(residual, teeth, shaft_orders, mesh_harmonics)
    reference_local = residual_signal(reference, teeth, shaft_orders, mesh_harmonics)
    difference = difference_signal(residual, teeth, shaft_orders, mesh_harmonics)
    centred = difference - difference.mean(axis=-1, keepdims=True)
    fm4 = np.mean(centred**4, axis=-1) / np.maximum(np.mean(centred**2, axis=-1), TINY) ** 2
    na4 = (
        np.mean((local - local.mean(axis=-1, keepdims=True)) ** 4, axis=-1)
        / np.maximum(np.var(reference_local, axis=-1), TINY) ** 2
    )
    out = {
        f"b{k:02d}": levels[:, k] / np.maximum(reference_levels[:, k], TINY) for k in range(n_bands)
    }
    out.update(
        rms_ratio=np.sqrt(np.mean(residual**2, axis=-1)) / np.maximum(reference_rms, TINY),
        FM4=fm4,
        NA4=na4,
        tooth_peak1=tooth_peak(local, teeth, 1),
        tooth_peak3=tooth_peak(local, teeth, 3),
    )
    return out


def band_names(n_bands: int) -> list[str]:
    return [f"b{k:02d}" for k in range(n_bands)]


def input_angle(segment: np.ndarray, fs_hz: float, speed_rpm: float, shafts, phase: tuple):
    """(input-shaft angle, phase method, the mesh line's level over its floor) of a segment
    (n_channels, n_samples): tacholess tracking of the first shaft's mesh phase
    (`order_features.segment_angle`: "mesh_phase", or "nominal" where no line can be followed);
    `phase`: (harmonic, band orders, minimum SNR)."""
    phase_harmonic, phase_band_orders, phase_min_snr = phase
    _, ratio, teeth = shafts[0]
    return segment_angle(
        segment,
        fs_hz,
        speed_rpm / 60.0,
        phase_harmonic * teeth * ratio,
        phase_band_orders,
        phase_min_snr,
    )


def segment_patterns(
    segment: np.ndarray,
    fs_hz: float,
    speed_rpm: float,
    shafts,
    samples_per_revolution: int,
    phase_harmonic: int = 1,
    phase_band_orders: float = 0.3,
    phase_min_snr: float = 5.0,
    cycle: np.ndarray | None = None,
    top_order: int | None = None,
):
    """(patterns per shaft, (phase method, line to floor), origin) of one segment (n_channels, n_samples): its
    angle (`input_angle`), then `shaft_patterns`. With its machine's healthy hunting-cycle average
    (`cycle`), the patterns of its residual against it (`cycle_residual`, on the orders up to
    `top_order`): the shafts' residual patterns, and `origin`, where their first sample lies in
    the cycle (input-shaft revolutions from the cycle's start: the same frame on every record of
    the machine); None without a cycle."""
    angle, *tracking = input_angle(
        segment, fs_hz, speed_rpm, shafts, (phase_harmonic, phase_band_orders, phase_min_snr)
    )
    origin = None
    if cycle is not None:
        residual, offset = cycle_residual(
            segment, angle, cycle, samples_per_revolution, shafts[0][2], top_order, with_offset=True
        )
        start = float(angle[0])
        # a revolution of the input shaft left out at either end: there the tracked angle settles
        # (its phase filter's edges), and against a cycle that holds no such error, the residual
        # would show it
        edge = int(np.ceil(np.searchsorted(angle, angle[0] + 1.0)))
        if angle[-1] - angle[0] > 2.0 + 1.0:
            residual, angle = (
                residual[..., edge : residual.shape[-1] - edge],
                angle[edge : len(angle) - edge],
            )
        segment = residual
        # the patterns start at the (trimmed) segment's first angle, the segment at `offset` in the cycle
        origin = offset / samples_per_revolution + float(angle[0]) - start
    return shaft_patterns(segment, angle, shafts, samples_per_revolution), tuple(tracking), origin


# the hunting-cycle averages of the machines, {key: (n_channels, L)}, for the worker processes:
# set before they fork, so no task carries one
_CYCLES: dict = {}


def _patterns_of(task):
    segment, fs_hz, speed, shafts, samples_per_revolution, phase, key, top_order = task
    patterns, tracking, origin = segment_patterns(
        segment,
        fs_hz,
        speed,
        shafts,
        samples_per_revolution,
        *phase,
        cycle=_CYCLES.get(key),
        top_order=top_order,
    )
    return patterns, origin, tracking


def every_segments_patterns(
    arrays,
    speeds,
    fs_hz: float,
    shafts,
    samples_per_revolution: int,
    phase: tuple,
    processes: int = 1,
    keys=None,
    cycles: dict | None = None,
    top_order: int | None = None,
) -> list:
    """`segment_patterns` of every segment (arrays (n_segments, n_channels, n_samples)) at its
    speed, against its key's hunting cycle where `cycles` holds one, in `processes` worker
    processes: the costly part of the family, and each segment's patterns depend on that segment
    alone, so the split changes no number. [(patterns per shaft, origin in the cycle or None,
    (phase method, line to floor))]."""
    keys = [None] * len(arrays) if keys is None else list(keys)
    tasks = [
        (segment, fs_hz, float(speed), shafts, samples_per_revolution, phase, key, top_order)
        for segment, speed, key in zip(arrays, speeds, keys)
    ]
    _CYCLES.clear()
    _CYCLES.update(cycles or {})
    try:
        if processes <= 1 or len(tasks) < 2:
            return [_patterns_of(task) for task in tasks]
        with ProcessPoolExecutor(
            min(processes, len(tasks)), mp_context=multiprocessing.get_context("fork")
        ) as pool:
            return list(
                pool.map(_patterns_of, tasks, chunksize=max(1, len(tasks) // (4 * processes)))
            )
    finally:
        _CYCLES.clear()


def record_cycles(
    ids: pd.DataFrame,
    arrays,
    rows,
    fs_hz: float,
    shafts,
    samples_per_revolution: int,
    phase: tuple,
    top_order: int,
):
    """The healthy hunting-cycle average of one machine from its reference segments (`rows`, of
    one or more records): each record's segments joined in order (a record's segments follow one
    another), its average over the cycle (`hunting_cycle`), the records' averages aligned to the
    first on the cycle and averaged. None when a record covers less than one cycle: that machine
    then falls back on the shafts' separated patterns."""
    revolutions, P, teeth = hunting_revolutions(shafts), samples_per_revolution, shafts[0][2]
    cycles = []
    chosen = ids.loc[list(rows)].sort_values(["record_id", "segment"])
    for _, record in chosen.groupby("record_id", sort=True):
        joined = np.concatenate([arrays[i] for i in record.index], axis=-1)
        angle, _, _ = input_angle(joined, fs_hz, float(record["speed_rpm"].iloc[0]), shafts, phase)
        cycle = hunting_cycle(joined, angle, revolutions, P)
        if cycle is None:
            return None
        cycles.append(
            cycle
            if not cycles
            else aligned(cycle, cycles[0], teeth * revolutions, top_order * revolutions)
        )
    return np.mean(cycles, axis=0)


# -- the window: the orders the bands reach -------------------------------------------------------
# the share of the sampling rate a vibration analyser reads: its anti-alias filter leaves fs / 2.56
# usable (5120 Hz for a 2000 Hz range, the convention of analysers and of this rig's spectra);
# above it a line's level is the filter's and the chain's, not the machine's. (0.45, where a
# sigma-delta converter's own filter is flat, gave the default rig's 29-tooth pinion a fourth mesh
# harmonic, orders 88-116, that the model's records and the bench's disagree on: on bench seed 7
# KNN 0.767 and the CNN 0.906 balanced against 1.000 and 0.889 at three; the SVM 1.000 either way)
PASSBAND_SHARE = 1 / 2.56
# the share of a healthy record's power (at the rig's lowest speed) the bands reach up to
WINDOW_ENERGY_SHARE = 0.95
# the row of a references table that holds the window (mesh harmonics, then the energy's order
# and the passband's, for the log) the measured job chose
WINDOW_ROW = "window"


def passband_harmonics(fs_hz: float, fastest_rpm: float, teeth: int, ratio: float = 1.0) -> int:
    """The most mesh harmonics of a shaft (`teeth`, speed `ratio` to the input shaft) whose
    highest harmonic and its first sideband lie in the measurement chain's usable band
    (PASSBAND_SHARE x `fs_hz`) at the highest speed: beyond it the bands of the fastest records
    would read the anti-alias filter or nothing."""
    top_order = PASSBAND_SHARE * fs_hz / (float(ratio) * fastest_rpm / 60.0)
    return int(np.floor((top_order - 1.0) / int(teeth)))


def energy_order(
    healthy: np.ndarray, fs_hz: float, speed_rpm: float, share: float = WINDOW_ENERGY_SHARE
) -> float:
    """The input-shaft order below which `share` of the healthy segments' power lies
    (segments (n_segments, n_channels, n_samples) at `speed_rpm`; their power spectra summed over
    segments and channels, each channel's mean removed): where the rig's vibration lives."""
    x = np.asarray(healthy, dtype=np.float64)
    x = x - x.mean(axis=-1, keepdims=True)
    power = (np.abs(np.fft.rfft(x, axis=-1)) ** 2).reshape(-1, x.shape[-1] // 2 + 1).sum(axis=0)
    frequencies = np.fft.rfftfreq(x.shape[-1], 1.0 / fs_hz)
    cumulative = np.cumsum(power) / max(power.sum(), TINY)
    return float(
        frequencies[min(np.searchsorted(cumulative, share), len(frequencies) - 1)]
        / (speed_rpm / 60.0)
    )


def window_harmonics(healthy_by_speed: dict, fs_hz: float, shafts) -> tuple[int, float, int]:
    """The residual window from the rig's healthy records ({speed_rpm: segments (n_segments,
    n_channels, n_samples)}, the calibration records): (mesh harmonics the bands reach, the order
    where the energy rule puts them, the passband's limit). The bands reach the mesh harmonic at
    or above the order below which WINDOW_ENERGY_SHARE of the power lies at the lowest speed
    (the orders there are the highest the rig's vibration reaches: its housings' and shafts'
    modes stay at their frequencies), bounded by the passband at the highest speed
    (`passband_harmonics`, on every shaft)."""
    slowest, fastest = min(healthy_by_speed), max(healthy_by_speed)
    _, ratio, teeth = shafts[0]
    order = energy_order(healthy_by_speed[slowest], fs_hz, slowest)
    limit = min(passband_harmonics(fs_hz, fastest, t, r) for _, r, t in shafts)
    if limit < 1:
        raise FeatureTableError(
            f"{KEY}: the first mesh harmonic of the {shafts[0][0]} lies above "
            f"the usable band, sampling rate / 2.56 ({fs_hz * PASSBAND_SHARE:g} Hz), at {fastest:g} rpm"
        )
    return max(1, min(int(np.ceil(order / (int(teeth) * float(ratio)))), limit)), order, limit


def window_from_table(table) -> int | None:
    """The mesh harmonics a `patterns_table` holds (None in one written before it held them)."""
    if table is None:
        return None
    table = pd.DataFrame(table)
    rows = table.loc[table["shaft"] == WINDOW_ROW, "pattern"]
    return int(rows.iloc[0][0]) if len(rows) else None


def resolved_window(mesh_harmonics, table, source: str) -> int:
    """The mesh harmonics the bands reach: the config's count, or with `auto` the one the measured
    job chose and `table` (a references table) holds, so every features table has the measured
    one's columns."""
    if mesh_harmonics != "auto":
        return int(mesh_harmonics)
    chosen = window_from_table(table)
    if chosen is None:
        raise FeatureTableError(
            f"{KEY}.mesh_harmonics: auto takes the window the measured records' job chose, "
            f"and {source} hold none (written before the window rule? rerun the measured "
            "features job)"
        )
    return chosen


# -- the truth a located tooth is scored against (a virtual bench's records) -----------------------
def record_truth(signal_frame: pd.DataFrame, record_id: str) -> dict:
    """The params a record's rows carry (a virtual bench's: the mesh phase at its first sample,
    the pinion teeth it damaged); {} for a user's records, which carry none."""
    rows = (
        signal_frame.loc[signal_frame["record_id"] == record_id, "params"]
        if "params" in signal_frame
        else []
    )
    text = next((str(value) for value in rows if value), "")
    return json.loads(text) if text else {}


def frame_origin_phase(
    signal_frame: pd.DataFrame,
    ids: pd.DataFrame,
    arrays,
    rows,
    fs_hz: float,
    shafts,
    samples_per_revolution: int,
    phase: tuple,
    has_cycle: bool,
) -> float | None:
    """The mesh phase (mesh periods; pair j, pinion tooth j mod z1, enters mesh at phase j) at the
    start of a condition's reference (`rows`, its calibration segments): where the machine's
    tooth frame begins, from the record's truth; None where its records carry none. Against a
    hunting cycle the reference begins `cycle_start` into the first calibration record's first
    segment, else at the first reference segment's start."""
    chosen = ids.loc[list(rows)]
    if has_cycle:
        chosen = chosen.sort_values(["record_id", "segment"])
        chosen = chosen[chosen["record_id"] == chosen["record_id"].iloc[0]]
    else:
        chosen = ids.loc[[list(rows)[0]]]
    truth = record_truth(signal_frame, chosen["record_id"].iloc[0])
    if "mesh_phase" not in truth:
        return None
    _, _, teeth = shafts[0]
    speed, P = float(chosen["speed_rpm"].iloc[0]), samples_per_revolution
    origin = (
        truth["mesh_phase"]
        + speed / 60.0 * teeth * int(chosen["segment"].iloc[0]) * arrays.shape[-1] / fs_hz
    )
    if has_cycle:
        joined = np.concatenate([arrays[i] for i in chosen.index], axis=-1)
        angle, _, _ = input_angle(joined, fs_hz, speed, shafts, phase)
        n_grid = int(np.floor((angle[-1] - angle[0]) * P + 1e-9)) + 1
        origin += teeth * cycle_start(n_grid, hunting_revolutions(shafts) * P, P) / P
    return float(origin)


def true_positions(signal_frame: pd.DataFrame, origin_phase: float | None, teeth: int) -> dict:
    """{record: where its damaged pinion teeth begin in the machine's tooth frame (pitches from
    the frame's start; `frame_origin_phase`)} of a bench's records that carry the truth; {}
    without a frame's truth (a user's records, a simulated table)."""
    if origin_phase is None:
        return {}
    truths = {
        record: record_truth(signal_frame, record) for record in signal_frame["record_id"].unique()
    }
    return {
        record: [float((tooth - origin_phase) % teeth) for tooth in truth["damaged_teeth"]]
        for record, truth in truths.items()
        # a train's further pair has a tooth frame of its own, which the records do not give
        if truth.get("damaged_teeth") and not truth.get("damaged_stage", 0)
    }


def true_parts(signal_frame: pd.DataFrame, shafts) -> dict:
    """{record: the gear (`shafts` name) its damaged teeth are on} of a bench's records that
    carry the truth: the pinion of the pair `damaged_stage` names (the first without one)."""
    truths = {
        record: record_truth(signal_frame, record) for record in signal_frame["record_id"].unique()
    }
    return {
        record: shafts[2 * int(truth.get("damaged_stage", 0))][0]
        for record, truth in truths.items()
        if truth.get("damaged_teeth")
    }


# -- the feature family --------------------------------------------------------------------------
RESIDUAL_PARAMS = (
    "samples_per_revolution",
    "bands_per_mesh",
    "mesh_harmonics",
    "shaft_orders",
    "phase_harmonic",
    "phase_band_orders",
    "phase_min_snr",
    "magnitudes",
    "reference_level",
)
# the reference's level in a band the bands are taken over: all its orders, or all but the mesh
# harmonics (`residual_features`)
REFERENCE_LEVELS = ("whole", "without_mesh_lines")
KEY = "features.residual"


def kept_features(magnitudes: bool = True) -> list[str]:
    """FEATURES, less SIZED_FEATURES without `magnitudes`."""
    return [f for f in FEATURES if magnitudes or f not in SIZED_FEATURES]


def feature_names(channels, shafts, n_bands: int, magnitudes: bool = True) -> list[str]:
    """`res_<channel>_<shaft>_<feature>`: per channel and shaft its bands, then the kept FEATURES
    (each channel and shaft a block of bands, as the CNN reads band spectra)."""
    return [
        f"res_{channel}_{shaft}_{feature}"
        for channel in channels
        for shaft, _, _ in shafts
        for feature in band_names(n_bands) + kept_features(magnitudes)
    ] + teeth_names(shafts)


def teeth_names(shafts) -> list[str]:
    """`res_teeth_<shaft>_<feature>`: TEETH_FEATURES per shaft, after the channels' blocks."""
    return [f"res_teeth_{shaft}_{feature}" for shaft, _, _ in shafts for feature in TEETH_FEATURES]


def band_shape(log_levels: np.ndarray) -> np.ndarray:
    """Log band levels (..., n_bands) less their mean over the bands: the residual spectrum's shape,
    whatever its size (the fault's size and the mesh's compliance scale every band alike)."""
    return log_levels - log_levels.mean(axis=-1, keepdims=True)


def reference_rows(ids: pd.DataFrame, against: dict) -> dict:
    """{reference key: row positions of its reference segments} and each row's key: a measured
    segment's key is its condition (the calibration set there), a simulated one's its machine (its
    healthy twin's last segments), as `condmon.reference` takes the features."""
    if against["source"] == "measured":
        chosen = calibration_frame(
            ids, against["healthy_state"], against["condition"], dict(against["reserve"])
        )
        keys = ids[against["condition"]].astype(float).to_numpy()
        positions = {}
        for position in chosen.index:
            positions.setdefault(float(ids.at[position, against["condition"]]), []).append(position)
        return positions, list(keys)
    machines = ids["record_id"].map(machine_of)
    is_reference = (ids["health_state"] == against["healthy_state"]) & (
        ids["segment"] >= int(against["segments_per_sample"])
    )
    positions = {}
    for position in np.flatnonzero(is_reference.to_numpy()):
        positions.setdefault(machines.iat[position], []).append(position)
    return positions, list(machines)


# the `shaft` of a references table's rows that hold a condition's hunting-cycle average
CYCLE_ROW = "hunting_cycle"


# ... and the row (one per condition, first channel) that lists the machine's fixed tones in Hz
TONES_ROW = "fixed_tones"


def patterns_table(
    references: dict,
    condition: str,
    shafts,
    channels,
    cycles: dict | None = None,
    tones=(),
    window=None,
) -> pd.DataFrame:
    """The measured references as a table to write and package: one row per condition, shaft and
    channel, the pattern (one revolution) as a list; where a condition has a hunting-cycle
    average (`cycles`), one row per channel with shaft `CYCLE_ROW`, the cycle as a list; per
    condition one row with shaft `TONES_ROW`, the fixed tones (Hz) as a list; and with `window`
    ((mesh harmonics, energy order, passband limit): `window_harmonics`) one row per condition
    with shaft `WINDOW_ROW`, it as a list."""
    rows = [
        {condition: key, "shaft": name, "channel": channel, "pattern": reference[k][c].tolist()}
        for key, reference in references.items()
        for k, (name, _, _) in enumerate(shafts)
        for c, channel in enumerate(channels)
    ]
    rows += [
        {condition: key, "shaft": CYCLE_ROW, "channel": channel, "pattern": cycle[c].tolist()}
        for key, cycle in (cycles or {}).items()
        for c, channel in enumerate(channels)
    ]
    rows += [
        {
            condition: key,
            "shaft": TONES_ROW,
            "channel": channels[0],
            "pattern": [float(f) for f in tones],
        }
        for key in references
    ]
    if window is not None:
        rows += [
            {
                condition: key,
                "shaft": WINDOW_ROW,
                "channel": channels[0],
                "pattern": [float(v) for v in window],
            }
            for key in references
        ]
    return pd.DataFrame(rows)


def patterns_from_table(table, shafts, channels) -> tuple[str, dict, dict, list]:
    """(condition column, {condition value: [per shaft (n_channels, P)]}, {condition value:
    hunting-cycle average (n_channels, L)}, fixed tones in Hz) of `patterns_table`."""
    table = pd.DataFrame(table)
    condition = next(c for c in table.columns if c not in ("shaft", "channel", "pattern"))
    references, cycles = {}, {}
    for value, rows in table.groupby(condition):
        indexed = rows.set_index(["shaft", "channel"])["pattern"]
        references[float(value)] = [
            np.array([np.asarray(indexed[(name, channel)], float) for channel in channels])
            for name, _, _ in shafts
        ]
        if (CYCLE_ROW, channels[0]) in indexed.index:
            cycles[float(value)] = np.array(
                [np.asarray(indexed[(CYCLE_ROW, channel)], float) for channel in channels]
            )
    return condition, references, cycles, tones_from_table(table)


def tones_from_table(table) -> list[float]:
    """The fixed tones (Hz) a `patterns_table` lists (none in a table written before they were)."""
    table = pd.DataFrame(table)
    rows = table.loc[table["shaft"] == TONES_ROW, "pattern"]
    return [float(f) for f in rows.iloc[0]] if len(rows) else []


def without_fixed_tones(
    ids: pd.DataFrame, arrays: np.ndarray, fs_hz: float, shafts, tones
) -> np.ndarray:
    """Every segment less the fixed tones its synchronous average would keep
    (`fixed_tones.remove_fixed_tones`), logged per speed."""
    if not len(tones):
        return arrays
    cleaned, removed = arrays, {}
    for i, speed in enumerate(ids["speed_rpm"].astype(float)):
        segment, kept = remove_fixed_tones(arrays[i], fs_hz, speed, shafts, tones)
        if kept:  # a copy only where a tone goes
            if cleaned is arrays:
                cleaned = np.array(arrays, dtype=float)
            cleaned[i] = segment
            removed.setdefault(speed, set()).update(round(f, 2) for f in kept)
    log.info(
        "fixed tones %s Hz; removed where on a shaft order: %s",
        [round(f, 2) for f in tones],
        {f"{speed:g} rpm": sorted(found) for speed, found in removed.items()} or "nowhere",
    )
    return cleaned


@dataclass(frozen=True)
class ResidualSettings:
    """`features.residual` with what the gear system adds, read and checked once
    (`residual_settings`)."""

    shafts: list  # [(name, speed ratio, teeth)], the input shaft first
    damaged: list  # the shafts whose features the table gives
    contact_ratio: float  # the pair's, for the located teeth
    samples_per_revolution: int
    bands_per_mesh: int
    magnitudes: bool
    reference_level: str
    shaft_orders: int
    phase: tuple  # (harmonic, band in orders, least SNR) of the mesh phase
    mesh_harmonics: int | str  # a count, or "auto": the window from the calibration records


def residual_settings(params: dict) -> ResidualSettings:
    """The residual family's settings of `params` (`features.residual` with the rig's `shafts`,
    the `damaged_shafts` whose features it gives, default every shaft, and the pair's
    `contact_ratio`); an unknown or invalid one is refused by name."""
    params = dict(params)
    shafts = [(str(n), float(r), int(t)) for n, r, t in params.pop("shafts")]
    contact_ratio = float(params.pop("contact_ratio", 2.0))
    damaged = [
        str(name) for name in params.pop("damaged_shafts", None) or [name for name, _, _ in shafts]
    ]
    if not set(damaged) <= {name for name, _, _ in shafts}:
        raise FeatureTableError(
            f"{KEY}: damaged shafts {damaged} are not all among the rig's {[n for n, _, _ in shafts]}"
        )
    unknown = sorted(set(params) - set(RESIDUAL_PARAMS))
    if unknown:
        raise FeatureTableError(
            f"{KEY}: unknown parameter(s) {unknown}; allowed: {list(RESIDUAL_PARAMS)}"
        )
    reference_level = str(params.get("reference_level", "whole"))
    if reference_level not in REFERENCE_LEVELS:
        raise FeatureTableError(
            f"{KEY}.reference_level: {reference_level!r} is none of {list(REFERENCE_LEVELS)}"
        )
    return ResidualSettings(
        shafts=shafts,
        damaged=damaged,
        contact_ratio=contact_ratio,
        samples_per_revolution=int(params["samples_per_revolution"]),
        bands_per_mesh=int(params["bands_per_mesh"]),
        magnitudes=bool(params.get("magnitudes", True)),
        reference_level=reference_level,
        shaft_orders=int(params["shaft_orders"]),
        phase=(
            int(params["phase_harmonic"]),
            float(params["phase_band_orders"]),
            float(params["phase_min_snr"]),
        ),
        mesh_harmonics=params["mesh_harmonics"],
    )


@dataclass
class MachineReferences:
    """Where each segment's healthy reference comes from, and the segments without the fixed
    tones (`packaged_machine`, `own_machine`)."""

    keys: list  # each row's reference key: its condition (measured, packaged) or its machine
    mesh_harmonics: int  # the bands reach this mesh harmonic
    tones: list  # the machine's fixed tones in Hz, removed from `arrays`
    arrays: np.ndarray  # (n_segments, n_channels, n_samples)
    positions: dict | None = None  # the job's own: {key: rows of its reference segments}
    cycles: dict = field(default_factory=dict)  # {key: hunting-cycle average}
    references: dict | None = None  # {key: [pattern per shaft]}
    window: tuple | None = None  # (mesh harmonics, energy order, passband limit) chosen here


def packaged_machine(
    ids, arrays, fs_hz: float, s: ResidualSettings, packaged, channels
) -> MachineReferences:
    """A packaged model's references (`patterns_table`): each segment against the nearest
    condition's."""
    condition, references, cycles, tones = patterns_from_table(packaged, s.shafts, list(channels))
    known = np.array(sorted(references))
    keys = [float(known[np.argmin(np.abs(known - v))]) for v in ids[condition].astype(float)]
    mesh_harmonics = resolved_window(s.mesh_harmonics, packaged, "the packaged model's references")
    arrays = without_fixed_tones(ids, arrays, fs_hz, s.shafts, tones)
    return MachineReferences(
        keys, mesh_harmonics, tones, arrays, cycles=cycles, references=references
    )


def own_machine(
    ids, arrays, fs_hz: float, s: ResidualSettings, against: dict, measured_references
) -> MachineReferences:
    """The features job's references in the signal table itself (`against`: the healthy-reference
    spec): the calibration set per condition, or each simulated sample's healthy twin, which loses
    the fixed tones the measured records (`measured_references`) lost."""
    positions, keys = reference_rows(ids, against)
    window = None
    if (
        against["source"] == "measured"
    ):  # the calibration records' lines at one frequency at every speed
        chosen = sorted(i for rows in positions.values() for i in rows)
        by_speed = {
            speed: arrays[list(rows)]
            for speed, rows in ids.loc[chosen].groupby("speed_rpm").groups.items()
        }
        tones = fixed_tones(by_speed, fs_hz)
        if (
            s.mesh_harmonics == "auto"
        ):  # the window from the calibration records (`window_harmonics`)
            window = window_harmonics(by_speed, fs_hz, s.shafts)
            log.info(
                "residual window: up to mesh harmonic %d (%d orders of the %s); the healthy records' "
                "%.0f %% energy order at %g rpm %.0f, the passband's limit %d harmonics",
                window[0],
                window[0] * s.shafts[0][2],
                s.shafts[0][0],
                100 * WINDOW_ENERGY_SHARE,
                min(by_speed),
                window[1],
                window[2],
            )
        mesh_harmonics = window[0] if window else int(s.mesh_harmonics)
    else:  # a simulated machine has none, but loses the same orders as the measured records
        tones = tones_from_table(measured_references) if measured_references is not None else []
        mesh_harmonics = resolved_window(
            s.mesh_harmonics, measured_references, "the measured records' references"
        )
    arrays = without_fixed_tones(ids, arrays, fs_hz, s.shafts, tones)
    return MachineReferences(
        keys, mesh_harmonics, tones, arrays, positions=positions, window=window
    )


def own_cycles(
    ids, machine: MachineReferences, fs_hz: float, s: ResidualSettings, top: int
) -> dict:
    """A machine whose reference records cover the hunting cycle is taken against its average
    over the cycle; one whose records are shorter, against its shafts' separated patterns."""
    cycles = {
        key: record_cycles(
            ids, machine.arrays, rows, fs_hz, s.shafts, s.samples_per_revolution, s.phase, top
        )
        for key, rows in machine.positions.items()
    }
    cycles = {key: cycle for key, cycle in cycles.items() if cycle is not None}
    shorter = sorted(str(key) for key in set(machine.positions) - set(cycles))
    if shorter:
        log.info(
            "%d of %d healthy references cover less than the hunting cycle (%d input revolutions): "
            "their shafts' patterns are separated instead (%s)",
            len(shorter),
            len(machine.positions),
            hunting_revolutions(s.shafts),
            ", ".join(shorter[:5]) + (" ..." if len(shorter) > 5 else ""),
        )
    return cycles


def own_references(
    patterns, machine: MachineReferences, s: ResidualSettings, n_bands: int, against: dict
) -> dict:
    """{key: [pattern per shaft]}: the hunting cycle's shaft patterns where it is covered, else the
    reference segments' patterns averaged; a measured condition without calibration records is
    refused by name."""
    revolutions = hunting_revolutions(s.shafts)
    references = {
        key: (
            cycle_shaft_patterns(
                machine.cycles[key], s.shafts, revolutions, s.samples_per_revolution
            )
            if key in machine.cycles
            else [
                reference_pattern(
                    [patterns[i][k] for i in rows],
                    teeth,
                    top_band_order(teeth / s.bands_per_mesh, n_bands),
                )
                for k, (_, _, teeth) in enumerate(s.shafts)
            ]
        )
        for key, rows in machine.positions.items()
    }
    missing = sorted({str(k) for k in machine.keys} - {str(k) for k in references})
    if against["source"] == "measured" and missing:
        raise FeatureTableError(
            f"{KEY}: no calibration records at {against['condition']} {missing}"
        )
    return references


def tooth_frames(
    signal_frame,
    ids,
    machine: MachineReferences,
    fs_hz: float,
    s: ResidualSettings,
    tops: list,
    measured: bool,
    packaged: bool,
) -> tuple[dict, dict]:
    """One tooth frame for the machine (measured or packaged references; a simulated machine's
    locations go nowhere): {key: each shaft's turns from the frame's start}, and where its damaged
    teeth begin on a bench whose records carry the truth ({record: positions})."""
    references = machine.references
    frames = (
        reference_frames(references, s.shafts, tops)
        if packaged or measured
        else {key: np.zeros(len(s.shafts)) for key in references}
    )
    origin_phase = None
    if not packaged and measured:
        first = min(machine.positions)
        origin_phase = frame_origin_phase(
            signal_frame,
            ids,
            machine.arrays,
            machine.positions[first],
            fs_hz,
            s.shafts,
            s.samples_per_revolution,
            s.phase,
            first in machine.cycles,
        )
    return frames, true_positions(signal_frame, origin_phase, s.shafts[0][2])


def segment_residual_features(
    i: int,
    patterns,
    origins,
    machine: MachineReferences,
    s: ResidualSettings,
    frames: dict,
    n_bands: int,
    tops: list,
) -> tuple[np.ndarray, list]:
    """One segment's residual signatures (the names' order: channel, shaft, feature; then how the
    change is spread over each damaged shaft's teeth) and each damaged shaft's excess per tooth."""
    key, references = machine.keys[i], machine.references
    chosen = [(k, shaft) for k, shaft in enumerate(s.shafts) if shaft[0] in s.damaged]
    # against the hunting cycle the patterns are already residuals; else aligned and subtracted
    residuals = [
        patterns[i][k]
        if key in machine.cycles
        else fault_aligned(
            patterns[i][k],
            references[key][k],
            teeth,
            top_band_order(teeth / s.bands_per_mesh, n_bands),
        )
        - references[key][k]
        for k, (_, _, teeth) in chosen
    ]
    found = [
        residual_signatures(
            residual,
            references[key][k],
            teeth,
            teeth / s.bands_per_mesh,
            n_bands,
            s.shaft_orders,
            machine.mesh_harmonics,
            s.reference_level,
        )
        for residual, (k, (_, _, teeth)) in zip(residuals, chosen)
    ]
    # (shaft, feature, channel) -> the names' order: channel, shaft, feature
    kept = band_names(n_bands) + kept_features(s.magnitudes)
    block = np.log10(np.array([[shaft[feature] for feature in kept] for shaft in found]) + TINY)
    if (
        not s.magnitudes
    ):  # (shaft, feature, channel): the bands as their shape per shaft and channel
        block[:, :n_bands] = band_shape(block[:, :n_bands].transpose(0, 2, 1)).transpose(0, 2, 1)
    # how the change is spread over each shaft's teeth, in its reference's frame
    spread = [
        damaged_pitches(
            residual_signal(
                in_reference_frame(
                    band_limited(residual, 1, tops[k]), (origins[i] or 0.0) * ratio + frames[key][k]
                ),
                teeth,
                s.shaft_orders,
                machine.mesh_harmonics,
            ),
            teeth,
        )
        for residual, (k, (_, ratio, teeth)) in zip(residuals, chosen)
    ]
    teeth_block = [
        np.log10(teeth_features(excess)[f] + TINY) for excess in spread for f in TEETH_FEATURES
    ]
    return np.concatenate([block.transpose(2, 0, 1).ravel(), teeth_block]), spread


def segment_locations(
    i: int, ids, spread: list, s: ResidualSettings, truths: dict, parts: dict
) -> list[dict]:
    """Where one segment's change sits on each damaged shaft (`located_tooth`) and how much of it
    concentrates on its teeth there (`level`: the excess over the floor, summed over its pitches;
    a fault repeats with its own gear's shaft and averages out on the others'), beside the truth
    (`true_positions`; `true_part`: whether the bench damaged this gear, None without truth)."""
    record = ids.at[i, "record_id"]
    truth = truths.get(record, [])
    chosen = [(k, shaft) for k, shaft in enumerate(s.shafts) if shaft[0] in s.damaged]
    return [
        {
            "row": i,
            "part": name,
            "positions": teeth,
            "span": s.contact_ratio,
            "position": tooth,
            "share": share,
            "true_positions": truth if k == 0 else [],
            "level": float(np.sum(excess)),
            "true_part": (parts[record] == name) if record in parts else None,
        }
        for excess, (k, (name, _, teeth)) in zip(spread, chosen)
        for tooth, share in [located_tooth(excess)]
    ]


def residual_feature_table(
    signal_frame: pd.DataFrame, channels, params: dict, inputs: FamilyInputs | None = None
) -> pd.DataFrame:
    """Wide features table of one signal table: every segment's residual signatures against its
    machine's healthy reference (module docstring).

    `params`: the settings (`residual_settings`). `inputs` (`condmon.features.FamilyInputs`):
    either `healthy_reference` (the features job's spec: measured segments against the
    calibration set per condition, simulated ones against their healthy twins; with a
    simulated one, `measured_references` gives the fixed tones every segment loses as the
    measured ones do) or `packaged_references` (a packaged model's); the segments' patterns in
    `processes` worker processes. Measured, the references go in `attrs["references"]` to be
    written and packaged; `attrs["fault_locations"]`: where each segment's change sits."""
    s, inputs = residual_settings(params), inputs or FamilyInputs()
    against, packaged = inputs.healthy_reference, inputs.packaged_references
    if against is None and packaged is None:
        raise FeatureTableError(
            f"{KEY}: residual signatures take each machine against its healthy reference; "
            "switch features.healthy_reference on"
        )
    fs_hz = single_sampling_rate(signal_frame)
    ids, arrays = to_arrays(signal_frame, list(channels))
    ids = ids.reset_index(drop=True)
    machine = (
        packaged_machine(ids, arrays, fs_hz, s, packaged, channels)
        if packaged is not None
        else own_machine(ids, arrays, fs_hz, s, against, inputs.measured_references)
    )
    return residual_frame(
        signal_frame,
        ids,
        machine,
        fs_hz,
        s,
        channels,
        against,
        inputs.processes,
        packaged is not None,
    )


def residual_frame(
    signal_frame,
    ids,
    machine: MachineReferences,
    fs_hz: float,
    s: ResidualSettings,
    channels,
    against: dict | None,
    processes: int,
    packaged: bool,
) -> pd.DataFrame:
    """`residual_feature_table`'s table once the references' source is known (`machine`)."""
    speeds = ids["speed_rpm"].to_numpy(float)
    n_bands = s.bands_per_mesh * machine.mesh_harmonics
    for speed in np.unique(speeds):
        check_resolution(
            fs_hz, float(speed), s.shafts, s.samples_per_revolution, machine.mesh_harmonics
        )
    top = top_band_order(s.shafts[0][2] / s.bands_per_mesh, n_bands)
    if not packaged:
        machine.cycles = own_cycles(ids, machine, fs_hz, s, top)
    patterns, origins, tracking = map(
        list,
        zip(
            *every_segments_patterns(
                machine.arrays,
                speeds,
                fs_hz,
                s.shafts,
                s.samples_per_revolution,
                s.phase,
                processes,
                machine.keys,
                machine.cycles,
                top,
            )
        ),
    )
    if not packaged:
        machine.references = own_references(patterns, machine, s, n_bands, against)
    measured = against is not None and against["source"] == "measured"
    tops = [top_band_order(teeth / s.bands_per_mesh, n_bands) for _, _, teeth in s.shafts]
    frames, truths = tooth_frames(signal_frame, ids, machine, fs_hz, s, tops, measured, packaged)
    parts = true_parts(signal_frame, s.shafts) if measured and not packaged else {}
    # features of the shafts whose gears the modelled faults damage; every shaft's pattern is
    # still estimated, to keep the others out of theirs
    names = feature_names(
        channels, [shaft for shaft in s.shafts if shaft[0] in s.damaged], n_bands, s.magnitudes
    )
    values, locations = np.full((len(ids), len(names)), np.nan), []
    for i, key in enumerate(machine.keys):
        if (
            key not in machine.references
        ):  # a simulated sample whose healthy twin failed: left out later
            continue
        values[i], spread = segment_residual_features(
            i, patterns, origins, machine, s, frames, n_bands, tops
        )
        locations += segment_locations(i, ids, spread, s, truths, parts)
    frame = pd.concat([ids, pd.DataFrame(values.astype(np.float32), columns=names)], axis=1)
    frame.attrs["referenced_columns"] = names
    frame.attrs["fault_locations"] = fault_locations(ids, locations)
    frame.attrs["shaft_tracking"] = shaft_tracking(ids, tracking)
    if measured:
        frame.attrs["references"] = patterns_table(
            machine.references,
            against["condition"],
            s.shafts,
            list(channels),
            machine.cycles,
            machine.tones,
            machine.window or (machine.mesh_harmonics, np.nan, np.nan),
        )
    return frame


def shaft_tracking(ids: pd.DataFrame, tracking: list[tuple]) -> pd.DataFrame:
    """How each segment's shaft angle was found, beside its ids: `method` "mesh_phase" (the mesh
    line followed) or "nominal" (no line to follow: the nominal speed, which smears the high
    orders of a speed that wanders), and the line's level over its floor. The segments on the
    nominal speed are counted per record in the job's log."""
    table = pd.concat(
        [
            ids[["record_id", "segment", "source", "health_state", "speed_rpm"]].reset_index(
                drop=True
            ),
            pd.DataFrame(tracking, columns=["method", "line_to_floor"]),
        ],
        axis=1,
    )
    counts = table.groupby("record_id", sort=True)["method"].agg(
        nominal=lambda m: int((m == "nominal").sum()), segments="size"
    )
    fell_back = counts[counts["nominal"] > 0]
    if len(fell_back):
        listed = ", ".join(
            f"{record} ({row.nominal} of {row.segments})"
            for record, row in fell_back.iloc[:10].iterrows()
        )
        log.warning(
            "shaft tracking fell back to the nominal speed on %d of %d segments, in %d records: "
            "%s%s (no mesh line where rate, speed and teeth put it, or one lost in noise)",
            int(fell_back["nominal"].sum()),
            len(table),
            len(fell_back),
            listed,
            ", ..." if len(fell_back) > 10 else "",
        )
    return table


def fault_locations(ids: pd.DataFrame, locations: list[dict]) -> pd.DataFrame:
    """The shared layer's table of where each segment's change sits (`condmon.report.fault_location`),
    per segment and damaged shaft (`part`): the tooth where the change concentrates (`position`,
    `located_tooth`: a pitch of the machine's tooth frame, the same tooth on every record of the
    machine) of the shaft's `positions` teeth, its share of the change (how sure), how many
    pitches a tooth meshes over (`span`, the pair's total contact ratio) and, on a bench, where
    its damaged teeth enter mesh (`true_positions`); how much change concentrates on the shaft's
    teeth (`level`: the part holding the most is where the fault is) and, on a bench, whether it
    damaged this part (`true_part`), beside the segment's ids."""
    table = pd.DataFrame(
        locations,
        columns=[
            "row",
            "part",
            "positions",
            "span",
            "position",
            "share",
            "true_positions",
            "level",
            "true_part",
        ],
    )
    located = ids.iloc[table["row"].to_numpy()].reset_index(drop=True)
    return pd.concat([located, table.drop(columns="row").reset_index(drop=True)], axis=1)


def resolution_problem(
    fs_hz: float, speed_rpm: float, shafts, samples_per_revolution: int, mesh_harmonics: int
) -> str | None:
    """Why an angular grid folds content into the orders kept, or None. `resample_at` has no
    anti-alias filter: on a grid coarser than the samples (P x shaft frequency < fs) content up
    to fs / 2 folds down to P - fs / (2 x shaft frequency) orders, which must lie above every
    order the features keep (the mesh harmonics and their sideband)."""
    for name, ratio, teeth in shafts:
        shaft_hz = float(ratio) * speed_rpm / 60.0
        lowest_folded = samples_per_revolution - fs_hz / (2 * shaft_hz)
        top = mesh_harmonics * int(teeth) + 1
        if lowest_folded < top:
            return (
                f"{KEY}.samples_per_revolution: {samples_per_revolution} per revolution of the {name} at "
                f"{speed_rpm:g} rpm folds {fs_hz:g} Hz content down to order {lowest_folded:.0f}, below its "
                f"order {top}; raise it to at least {int(np.ceil(top + fs_hz / (2 * shaft_hz)))}"
            )
    return None


def check_resolution(
    fs_hz: float, speed_rpm: float, shafts, samples_per_revolution: int, mesh_harmonics: int
) -> None:
    """Refuse an angular grid that folds content into the orders kept (`resolution_problem`)."""
    problem = resolution_problem(fs_hz, speed_rpm, shafts, samples_per_revolution, mesh_harmonics)
    if problem:
        raise FeatureTableError(problem)

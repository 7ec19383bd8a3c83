"""Order-domain gear diagnostics: tacholess angular resampling, the time-synchronous average
(TSA) per shaft with its regular, residual and difference signals, the classic gear condition
indicators, and amplitude spectra in shaft orders.

Small pure functions in the style of tsfresh's feature calculators, and `OrderFeatures`, a
stateless sklearn transformer that computes all of them for a stack of multi-channel segments.

Angles are in revolutions, orders in multiples of a shaft's rotation frequency. The *input shaft*
is the one whose speed the records carry (`speed_rpm`); every other shaft turns at a fixed
*speed ratio* to it (a gear pair: teeth of the driver / teeth of the driven gear).

Order tracking without a tachometer: a record's speed fluctuates slowly (0.2 % at about 1 Hz on the
benches), so a TSA or order spectrum built on the nominal speed smears the high orders: over half a
second, a 0.2 % error of the mean speed moves the 29th order (a mesh line) by 0.06 orders and slides
a tooth's pattern by a fifth of a pitch from the first revolution to the last. The shaft's phase is
read instead from the vibration's strongest synchronous line, the gear mesh: band-pass a mesh
harmonic (h x teeth x shaft frequency) around its nominal frequency, take the phase of its analytic
signal (`band_phase`: by complex demodulation), unwrap it and divide by h x teeth: the shaft's
angle sample by sample
(Bonnardot, Randall, Guillet 2005, "Extraction of second-order cyclostationary sources -
application to vibration analysis", MSSP 19, 1230-1244, sec. 2: angular resampling from the
acceleration signal with limited speed fluctuation). When that line is too weak to follow
(line-to-floor ratio below `phase_min_snr`), or its phase does not advance like a shaft near the
nominal speed, the nominal speed is used (constant); which of the two a segment used is logged.

Signals derived from the TSA of one shaft (x its TSA, N samples over one revolution, z the shaft's
teeth, H mesh harmonics, k shaft orders; Lebold, McClintic, Campbell, Byington, Maynard 2000,
"Review of vibration analysis methods for gearbox diagnostics and prognostics", Proc. 54th Meeting
of the Society for Machinery Failure Prevention Technology, 623-634):
- regular signal: the TSA's shaft orders 1..k and mesh harmonics h z (h = 1..H);
- residual signal: the TSA minus the regular signal;
- difference signal: the TSA minus the regular meshing components: shaft orders 1..k, mesh
  harmonics and their first-order sidebands h z +/- 1.
Components are removed in the TSA's discrete Fourier transform: one revolution long, its bin m is
shaft order m exactly.

The indicators cite their definitions: Zakrajsek, Townsend, Decker 1993, "An analysis of gear
fault detection methods as applied to pitting fatigue failure data", NASA TM-105950 (FM0, FM4,
NA4, M6A, M8A); Lebold et al. 2000 (energy ratio, sideband level factor, and all of them again).
"""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt
from sklearn.base import BaseEstimator, TransformerMixin

from condmon.features import FeatureTableError, single_sampling_rate
from condmon.signals import to_arrays
from condmon.spectra import amplitude_spectrum, band_values
from condmon.stat_features import crest_factor, kurtosis, rms

log = logging.getLogger(__name__)

INDICATORS = (
    "FM0",
    "FM4",
    "NA4",
    "M6A",
    "M8A",
    "ER",
    "SLF",
    "TSA_RMS",
    "TSA_kurtosis",
    "TSA_crest",
    "residual_RMS",
    "residual_crest",
)
SCALES = ("linear", "log")
BAND_STATISTICS = ("mean", "rms")
LOG_FLOOR = 1e-6  # as the spectrum family: added before log10 so silent bands stay finite
# A phase whose mean rate is further than this from the nominal speed followed another line.
MAX_SPEED_DEVIATION = 0.05
FLOOR_HALFWIDTH_ORDERS = 5.0  # the line-to-floor ratio's floor: bins within +/- this many orders
ORDER_PARAMS = (
    "order_min",
    "order_max",
    "resolution_orders",
    "band_statistic",
    "scale",
    "samples_per_revolution",
    "shaft_orders",
    "mesh_harmonics",
    "phase_harmonic",
    "phase_band_orders",
    "phase_min_snr",
)


# -- shaft angle -----------------------------------------------------------------------------
def line_to_floor(
    x, fs_hz: float, line_hz: float, half_width_hz: float, floor_halfwidth_hz: float
) -> float:
    """Amplitude of the strongest bin within line_hz +/- half_width_hz over the median amplitude of
    the bins within line_hz +/- floor_halfwidth_hz outside that band (Hann amplitude spectrum).
    About 1-3 where there is no line."""
    freqs, amps = amplitude_spectrum(x, fs_hz)
    return spectrum_line_to_floor(freqs, amps, line_hz, half_width_hz, floor_halfwidth_hz)


def spectrum_line_to_floor(
    freqs, spectrum, line_hz: float, half_width_hz: float, floor_halfwidth_hz: float, gap_hz=None
) -> float:
    """`line_to_floor` of a spectrum already taken (amplitudes, or powers for a power ratio): the
    strongest bin within line_hz +/- half_width_hz over the median of the bins within
    line_hz +/- floor_halfwidth_hz farther than `gap_hz` (default half_width_hz) from it; 0 where
    either holds no bin."""
    offset = np.abs(freqs - line_hz)
    in_line = offset <= half_width_hz
    around = (offset <= floor_halfwidth_hz) & (
        offset > (half_width_hz if gap_hz is None else gap_hz)
    )
    if not in_line.any() or not around.any():
        return 0.0
    return float(spectrum[in_line].max() / max(np.median(spectrum[around]), np.finfo(float).tiny))


def band_phase(x, fs_hz: float, line_hz: float, half_width_hz: float) -> np.ndarray:
    """Unwrapped phase (rad) of x's component within line_hz +/- half_width_hz, sample by sample.

    Complex demodulation: x shifted down by line_hz (times exp(-i 2 pi line_hz t)), low-passed to
    half_width_hz (zero-phase Butterworth, order 4, even extension of three periods of the
    cut-off), its phase plus 2 pi line_hz t. This is the phase of the analytic signal of x
    band-passed around the line, but the extension mirrors a slowly turning phasor rather than the
    tone itself: on a gear-model record at 1100 rpm with a 0.2 % speed fluctuation it follows the
    shaft to 1e-3 revolutions up to the segment's ends, where a band-pass and Hilbert transform
    erred by 7e-3 (the nominal speed: 4e-3).
    """
    x = np.asarray(x, dtype=np.float64)
    if not 0 < half_width_hz < line_hz < fs_hz / 2 - half_width_hz:
        raise ValueError(
            f"phase band {line_hz:g} +/- {half_width_hz:g} Hz must lie in "
            f"(0, fs/2 = {fs_hz / 2:g} Hz)"
        )
    t = np.arange(x.shape[-1]) / fs_hz
    baseband = (x - x.mean()) * np.exp(-2j * np.pi * line_hz * t)
    sos = butter(4, half_width_hz, btype="lowpass", fs=fs_hz, output="sos")
    padlen = min(x.shape[-1] - 1, int(np.ceil(3 * fs_hz / half_width_hz)))
    smooth = sosfiltfilt(sos, baseband.real, padtype="even", padlen=padlen) + 1j * sosfiltfilt(
        sos, baseband.imag, padtype="even", padlen=padlen
    )
    return np.unwrap(np.angle(smooth)) + 2 * np.pi * line_hz * t


def shaft_angle(
    x,
    fs_hz: float,
    shaft_hz: float,
    mesh_order: float,
    phase_band_orders: float = 0.3,
    phase_min_snr: float = 5.0,
) -> tuple[np.ndarray, str, float]:
    """Angle of the input shaft (revolutions since the first sample) at every sample of x.

    `mesh_order` is the line followed, in orders of the input shaft (a mesh harmonic: h x teeth x
    speed ratio of a geared shaft). Its phase, unwrapped and divided by 2 pi x mesh_order, is the
    shaft's angle (tacholess order tracking; module docstring). `phase_band_orders` is the band's
    half-width in input-shaft orders: wide enough for the speed fluctuation's frequency
    modulation, narrow enough to keep out the shafts' sidebands of the line (at +/- the
    shafts' speed ratios). Falls back to the nominal speed (angle = shaft_hz x t) when the line's
    line-to-floor ratio is below `phase_min_snr`, the band does not fit below fs/2, or the phase
    goes backwards or runs more than 5 % from the nominal speed.

    Returns (angle, method, line-to-floor ratio) with method "mesh_phase" or "nominal".
    """
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[-1]
    nominal = shaft_hz * np.arange(n) / fs_hz
    line_hz, half_hz = mesh_order * shaft_hz, phase_band_orders * shaft_hz
    if line_hz + half_hz >= fs_hz / 2 or line_hz - half_hz <= 0:
        return nominal, "nominal", 0.0
    snr = line_to_floor(x, fs_hz, line_hz, half_hz, FLOOR_HALFWIDTH_ORDERS * shaft_hz)
    if snr < phase_min_snr:
        return nominal, "nominal", snr
    phase = band_phase(x, fs_hz, line_hz, half_hz)
    angle = (phase - phase[0]) / (2 * np.pi * mesh_order)
    mean_rate = angle[-1] / ((n - 1) / fs_hz)
    if np.any(np.diff(angle) <= 0) or abs(mean_rate / shaft_hz - 1) > MAX_SPEED_DEVIATION:
        return nominal, "nominal", snr
    return angle, "mesh_phase", snr


def segment_angle(
    segment,
    fs_hz: float,
    shaft_hz: float,
    mesh_order: float,
    phase_band_orders: float = 0.3,
    phase_min_snr: float = 5.0,
) -> tuple[np.ndarray, str, float]:
    """`shaft_angle` of a multi-channel segment (n_channels, n_samples), read on the channel where
    the mesh line stands highest above its floor (one angle for all channels: they see the same
    shafts); the nominal speed only when no channel's line can be followed."""
    candidates = [
        shaft_angle(channel, fs_hz, shaft_hz, mesh_order, phase_band_orders, phase_min_snr)
        for channel in segment
    ]
    tracked = [c for c in candidates if c[1] == "mesh_phase"]
    return max(tracked or candidates, key=lambda c: c[2])


def angular_resample(
    x, fs_hz: float, angle, samples_per_revolution: int, n_out: int | None = None
) -> np.ndarray:
    """x at the angles 0, 1/P, 2/P, ... revolutions (P = samples_per_revolution) of a shaft whose
    angle at every sample is `angle` (revolutions, increasing, angle[0] = 0).

    Cubic-spline interpolation in time at the instants the shaft passes each grid angle. When the
    angle grid is coarser than the time grid (fewer than fs samples per second at the mean speed),
    x is first low-passed to 80 % of the grid's Nyquist frequency (zero-phase Butterworth, order
    8), so content above it does not fold into the orders kept. `n_out` grid points (default: every
    whole grid step within the segment).
    """
    x = np.asarray(x, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    n = x.shape[-1]
    span = angle[-1] - angle[0]
    available = int(np.floor(span * samples_per_revolution + 1e-9)) + 1
    n_out = available if n_out is None else int(n_out)
    if n_out > available:
        raise ValueError(
            f"{n_out} grid points at {samples_per_revolution} per revolution need "
            f"{(n_out - 1) / samples_per_revolution:g} revolutions; the segment has {span:g}"
        )
    grid_rate_hz = samples_per_revolution * span / ((n - 1) / fs_hz)
    if grid_rate_hz < fs_hz:
        sos = butter(8, 0.4 * grid_rate_hz, btype="lowpass", fs=fs_hz, output="sos")
        x = sosfiltfilt(
            sos,
            x,
            padtype="even",
            padlen=min(n - 1, int(np.ceil(3 * fs_hz / (0.4 * grid_rate_hz)))),
        )
    grid = angle[0] + np.arange(n_out) / samples_per_revolution
    instants = np.interp(grid, angle, np.arange(n, dtype=np.float64))  # in samples
    return CubicSpline(np.arange(n), x)(instants)


def time_synchronous_average(resampled, samples_per_revolution: int) -> np.ndarray:
    """Mean over the whole revolutions of an angularly resampled signal: one revolution, P
    samples. Components locked to the shaft add up; everything else averages towards zero (its
    amplitude falls as 1 / sqrt(revolutions) for noise)."""
    resampled = np.asarray(resampled, dtype=np.float64)
    revolutions = resampled.shape[-1] // samples_per_revolution
    if revolutions < 1:
        raise ValueError(
            f"{resampled.shape[-1]} samples at {samples_per_revolution} per revolution: "
            "less than one revolution to average"
        )
    return (
        resampled[..., : revolutions * samples_per_revolution]
        .reshape(*resampled.shape[:-1], revolutions, samples_per_revolution)
        .mean(axis=-2)
    )


# -- signals derived from the TSA ---------------------------------------------------------------
def regular_orders(
    teeth: int, shaft_orders: int, mesh_harmonics: int, sidebands: bool, n_samples: int
) -> np.ndarray:
    """Shaft orders 1..shaft_orders and the mesh harmonics h x teeth (h = 1..mesh_harmonics), with
    their first-order sidebands h x teeth +/- 1 if `sidebands`; those below the Nyquist order of a
    TSA of n_samples (the orders its DFT holds, sorted)."""
    orders = set(range(1, shaft_orders + 1))
    for h in range(1, mesh_harmonics + 1):
        orders |= {h * teeth - 1, h * teeth, h * teeth + 1} if sidebands else {h * teeth}
    return np.array(sorted(o for o in orders if 0 < o < (n_samples + 1) // 2), dtype=int)


def keep_orders(tsa, orders) -> np.ndarray:
    """The TSA's components at the given shaft orders only (its DFT bins; one revolution long,
    bin m is order m)."""
    tsa = np.asarray(tsa, dtype=np.float64)
    spectrum = np.fft.rfft(tsa, axis=-1)
    kept = np.zeros_like(spectrum)
    kept[..., orders] = spectrum[..., orders]
    return np.fft.irfft(kept, n=tsa.shape[-1], axis=-1)


def regular_signal(tsa, teeth: int, shaft_orders: int = 2, mesh_harmonics: int = 3) -> np.ndarray:
    """Regular signal: the TSA's shaft orders 1..k and mesh harmonics (Lebold et al. 2000)."""
    tsa = np.asarray(tsa, dtype=np.float64)
    return keep_orders(
        tsa, regular_orders(teeth, shaft_orders, mesh_harmonics, False, tsa.shape[-1])
    )


def residual_signal(tsa, teeth: int, shaft_orders: int = 2, mesh_harmonics: int = 3) -> np.ndarray:
    """Residual signal: the TSA minus shaft orders 1..k and the mesh harmonics (and its mean);
    a damaged tooth's short event stays (Lebold et al. 2000)."""
    tsa = np.asarray(tsa, dtype=np.float64)
    centred = tsa - tsa.mean(axis=-1, keepdims=True)
    return centred - regular_signal(tsa, teeth, shaft_orders, mesh_harmonics)


def difference_signal(
    tsa, teeth: int, shaft_orders: int = 2, mesh_harmonics: int = 3
) -> np.ndarray:
    """Difference signal: the TSA minus its regular meshing components, shaft orders 1..k, mesh
    harmonics and their first-order sidebands (and its mean) (Zakrajsek et al. 1993; Lebold et
    al. 2000)."""
    tsa = np.asarray(tsa, dtype=np.float64)
    centred = tsa - tsa.mean(axis=-1, keepdims=True)
    orders = regular_orders(teeth, shaft_orders, mesh_harmonics, True, tsa.shape[-1])
    return centred - keep_orders(tsa, orders)


def order_amplitude(tsa, order: int) -> np.ndarray:
    """Amplitude of shaft order `order` in the TSA (a sine of amplitude A at that order gives A)."""
    tsa = np.asarray(tsa, dtype=np.float64)
    return 2.0 * np.abs(np.fft.rfft(tsa, axis=-1)[..., order]) / tsa.shape[-1]


# -- condition indicators ----------------------------------------------------------------------
def _normalised_moment(x, k: int) -> np.ndarray:
    """N^(k/2 - 1) sum (x - mean)^k / [sum (x - mean)^2]^(k/2): the k-th moment over the variance
    to the power k/2 (4: the kurtosis, 3 for Gaussian noise)."""
    x = np.asarray(x, dtype=np.float64)
    centred = x - x.mean(axis=-1, keepdims=True)
    variance = np.mean(centred**2, axis=-1)
    return np.mean(centred**k, axis=-1) / np.maximum(variance, np.finfo(float).tiny) ** (k / 2)


def fm0(tsa, teeth: int, mesh_harmonics: int = 3) -> np.ndarray:
    """FM0 = PP_x / sum_{h=1}^{H} P_h: peak-to-peak of the TSA over the sum of the amplitudes of the
    mesh harmonics h x teeth (Zakrajsek et al. 1993, eq. 1; Lebold et al. 2000). A heavy fault
    (a missing tooth, wear) raises the peak-to-peak but not the mesh lines."""
    tsa = np.asarray(tsa, dtype=np.float64)
    harmonics = [
        h * teeth for h in range(1, mesh_harmonics + 1) if h * teeth < (tsa.shape[-1] + 1) // 2
    ]
    mesh = sum(order_amplitude(tsa, o) for o in harmonics)
    return np.ptp(tsa, axis=-1) / np.maximum(mesh, np.finfo(float).tiny)


def fm4(difference) -> np.ndarray:
    """FM4 = N sum (d_i - dbar)^4 / [sum (d_i - dbar)^2]^2: the kurtosis of the difference signal d
    (Zakrajsek et al. 1993, eq. 2; Stewart 1977). About 3 for a healthy gear (Gaussian d); a
    damaged tooth's local peak raises it."""
    return _normalised_moment(difference, 4)


def na4(residual) -> np.ndarray:
    """NA4 = N sum (r_i - rbar)^4 / {1/M sum_j sum_i (r_ij - rbar_j)^2}^2 over the residual signal r,
    here in its single-record form, M = 1: the denominator is the record's own variance, so NA4 is
    the residual's kurtosis (Zakrajsek et al. 1993, eq. 3, whose M records form the run ensemble;
    Lebold et al. 2000). About 3 for a healthy gear."""
    return _normalised_moment(residual, 4)


def m6a(difference) -> np.ndarray:
    """M6A = N^2 sum (d_i - dbar)^6 / [sum (d_i - dbar)^2]^3: the sixth normalised moment of the
    difference signal (Martin 1989 in Zakrajsek et al. 1993, eq. 5; Lebold et al. 2000). 15 for
    Gaussian d; more sensitive to peaks than FM4."""
    return _normalised_moment(difference, 6)


def m8a(difference) -> np.ndarray:
    """M8A = N^3 sum (d_i - dbar)^8 / [sum (d_i - dbar)^2]^4: the eighth normalised moment of the
    difference signal (Martin 1989 in Zakrajsek et al. 1993, eq. 6; Lebold et al. 2000). 105 for
    Gaussian d."""
    return _normalised_moment(difference, 8)


def energy_ratio(difference, regular) -> np.ndarray:
    """ER = RMS_d / RMS_r: RMS of the difference signal over RMS of the regular signal (Swansson
    1980 in Lebold et al. 2000). Rises as heavy, spread damage moves energy out of the regular
    meshing components."""
    return rms(difference) / np.maximum(rms(regular), np.finfo(float).tiny)


def sideband_level_factor(tsa, teeth: int) -> np.ndarray:
    """SLF = (A_{z-1} + A_{z+1}) / sigma_x: the first-order sidebands about the fundamental mesh
    order z (the teeth) over the standard deviation of the TSA (Lebold et al. 2000). Shaft
    damage or eccentricity modulates the mesh and raises it."""
    tsa = np.asarray(tsa, dtype=np.float64)
    sidebands = order_amplitude(tsa, teeth - 1) + order_amplitude(tsa, teeth + 1)
    return sidebands / np.maximum(tsa.std(axis=-1), np.finfo(float).tiny)


def condition_indicators(tsa, teeth: int, shaft_orders: int = 2, mesh_harmonics: int = 3) -> dict:
    """Every indicator of INDICATORS for the TSA of one shaft (the residual's kurtosis is NA4 in its
    single-record form and is not repeated)."""
    regular = regular_signal(tsa, teeth, shaft_orders, mesh_harmonics)
    residual = residual_signal(tsa, teeth, shaft_orders, mesh_harmonics)
    difference = difference_signal(tsa, teeth, shaft_orders, mesh_harmonics)
    return {
        "FM0": fm0(tsa, teeth, mesh_harmonics),
        "FM4": fm4(difference),
        "NA4": na4(residual),
        "M6A": m6a(difference),
        "M8A": m8a(difference),
        "ER": energy_ratio(difference, regular),
        "SLF": sideband_level_factor(tsa, teeth),
        "TSA_RMS": rms(tsa - np.mean(tsa)),
        "TSA_kurtosis": kurtosis(tsa),
        "TSA_crest": crest_factor(tsa - np.mean(tsa)),
        "residual_RMS": rms(residual),
        "residual_crest": crest_factor(residual),
    }


# -- order spectrum ----------------------------------------------------------------------------
def order_spectrum(resampled, samples_per_revolution: int) -> tuple[np.ndarray, np.ndarray]:
    """(orders, amplitudes) of an angularly resampled signal: `amplitude_spectrum` with the
    angular sampling rate in samples per revolution, so the axis is in shaft orders."""
    return amplitude_spectrum(resampled, float(samples_per_revolution))


# -- the transformer ---------------------------------------------------------------------------
class OrderFeatures(TransformerMixin, BaseEstimator):
    """Order-domain features of a stack of multi-channel segments: per channel, order-spectrum
    bands of the input shaft, then per shaft the condition indicators of its TSA.

    `shafts`: [(name, speed ratio to the input shaft, teeth)] (`System.shafts()`); the first
    shaft's mesh (teeth x ratio input orders, harmonic `phase_harmonic`) gives the phase of every
    segment, read on the channel where that line stands highest above its floor (one angle for
    all channels: they see the same shafts). Bands: the input shaft's order spectrum (Hann window
    over the segment's whole angular span) in bands `resolution_orders` wide over
    [order_min, order_max), the RMS (or mean) amplitude of their bins, named
    `ord_<channel>_<centre:05.1f>x`. Indicators: `ci_<channel>_<shaft>_<indicator>` for INDICATORS,
    from the TSA over the segment's whole revolutions of that shaft, `samples_per_revolution`
    samples each (`shaft_orders`, `mesh_harmonics`: what the regular, residual and difference
    signals remove). `scale="log"` gives log10(value + 1e-6) of every feature. Stateless.

    transform(X, fs_hz, speed_rpm): X (n_segments, n_channels, n_samples), speed_rpm of the input
    shaft, scalar or one per segment -> (n_segments, n_features) float32, columns
    `feature_names()`. After a transform, `phase_methods_` says per segment whether the angle came
    from the mesh phase or the nominal speed.
    """

    def __init__(
        self,
        shafts=(("pinion", 1.0, 29),),
        channels=("A1_x",),
        order_min: float = 0.5,
        order_max: float = 120.5,
        resolution_orders: float = 1.0,
        band_statistic: str = "rms",
        scale: str = "log",
        samples_per_revolution: int = 1024,
        shaft_orders: int = 2,
        mesh_harmonics: int = 3,
        phase_harmonic: int = 1,
        phase_band_orders: float = 0.3,
        phase_min_snr: float = 5.0,
    ):
        self.shafts = shafts
        self.channels = channels
        self.order_min = order_min
        self.order_max = order_max
        self.resolution_orders = resolution_orders
        self.band_statistic = band_statistic
        self.scale = scale
        self.samples_per_revolution = samples_per_revolution
        self.shaft_orders = shaft_orders
        self.mesh_harmonics = mesh_harmonics
        self.phase_harmonic = phase_harmonic
        self.phase_band_orders = phase_band_orders
        self.phase_min_snr = phase_min_snr

    # -- names ---------------------------------------------------------------------------------
    def band_centres(self) -> np.ndarray:
        """Centre of every order band, in input-shaft orders."""
        self._check_params()
        return self.order_min + self.resolution_orders * (np.arange(self._n_bands()) + 0.5)

    def feature_names(self) -> list[str]:
        """Band features of every channel, then the indicators of every channel and shaft."""
        centres = self.band_centres()
        names = [
            f"ord_{channel}_{centre:05.1f}x" for channel in self.channels for centre in centres
        ]
        names += [
            f"ci_{channel}_{shaft}_{indicator}"
            for channel in self.channels
            for shaft, _, _ in self._shafts()
            for indicator in INDICATORS
        ]
        return names

    # -- sklearn API ---------------------------------------------------------------------------
    def fit(self, X=None, y=None, fs_hz=None, speed_rpm=None):
        self._check_params()
        return self

    def fit_transform(self, X, y=None, fs_hz=None, speed_rpm=None):
        return self.fit(X).transform(X, fs_hz, speed_rpm)

    def transform(self, X, fs_hz: float, speed_rpm) -> np.ndarray:
        self._check_params()
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 3:
            raise ValueError(
                f"expected an array (n_segments, n_channels, n_samples), got shape {X.shape}"
            )
        if X.shape[1] != len(self.channels):
            raise ValueError(
                f"array has {X.shape[1]} channels but OrderFeatures has "
                f"{len(self.channels)}: {list(self.channels)}"
            )
        if not np.isfinite(X).all():
            raise ValueError("segments contain NaN or inf")
        speeds = np.broadcast_to(np.asarray(speed_rpm, dtype=np.float64), X.shape[:1])
        if not (np.isfinite(speeds) & (speeds > 0)).all():
            raise ValueError("speed_rpm must be a positive number for every segment")
        rows, self.phase_methods_ = [], []
        for segment, speed in zip(X, speeds):
            row, method = self._segment_features(segment, float(fs_hz), float(speed))
            rows.append(row)
            self.phase_methods_.append(method)
        nominal = self.phase_methods_.count("nominal")
        if nominal:
            log.info(
                "order features: %d of %d segments on the nominal speed (mesh line too weak or "
                "not followed)",
                nominal,
                len(X),
            )
        values = np.array(rows, dtype=np.float64).reshape(len(X), -1)
        if self.scale == "log":
            values = np.log10(np.maximum(values, 0.0) + LOG_FLOOR)
        return values.astype(np.float32)

    # -- one segment ---------------------------------------------------------------------------
    def _segment_features(self, segment: np.ndarray, fs_hz: float, speed_rpm: float):
        shaft_hz = speed_rpm / 60.0
        n = segment.shape[-1]
        self._check_segment(fs_hz, shaft_hz, n, speed_rpm)
        first_name, first_ratio, first_teeth = self._shafts()[0]
        mesh_order = self.phase_harmonic * first_teeth * first_ratio
        # the phase from the channel where the mesh line stands highest above its floor
        angle, method, snr = segment_angle(
            segment, fs_hz, shaft_hz, mesh_order, self.phase_band_orders, self.phase_min_snr
        )
        log.debug(
            "order features: shaft angle from %s (mesh order %g, line/floor %.1f)",
            "the mesh phase" if method == "mesh_phase" else "the nominal speed",
            mesh_order,
            snr,
        )
        P = int(self.samples_per_revolution)
        bands, indicators = [], []
        for channel in segment:
            resampled = angular_resample(channel, fs_hz, angle, P)
            orders, amps = order_spectrum(resampled, P)
            bands.append(
                band_values(
                    orders,
                    amps,
                    self.order_min,
                    self.resolution_orders,
                    self._n_bands(),
                    self.band_statistic,
                )
            )
            for _, ratio, teeth in self._shafts():
                revolutions = int(np.floor(angle[-1] * ratio + 1e-9))
                tsa_input = (
                    resampled
                    if ratio == 1.0
                    else angular_resample(channel, fs_hz, angle * ratio, P)
                )
                tsa = time_synchronous_average(tsa_input[: revolutions * P], P)
                values = condition_indicators(
                    tsa, int(teeth), int(self.shaft_orders), int(self.mesh_harmonics)
                )
                indicators += [float(values[name]) for name in INDICATORS]
        return np.concatenate([np.ravel(bands), indicators]), method

    # -- checks --------------------------------------------------------------------------------
    def _shafts(self) -> list[tuple[str, float, int]]:
        return [(str(name), float(ratio), int(teeth)) for name, ratio, teeth in self.shafts]

    def _n_bands(self) -> int:
        return int(np.floor((self.order_max - self.order_min) / self.resolution_orders + 1e-9))

    def _check_params(self) -> None:
        if len(self.channels) == 0:
            raise ValueError("OrderFeatures needs at least one channel")
        if not self.shafts:
            raise ValueError(
                "OrderFeatures needs at least one shaft (name, speed ratio, teeth); "
                "the system has no gears (System.shafts() is None)"
            )
        for shaft in self.shafts:
            if len(shaft) != 3:
                raise ValueError(f"shaft {shaft!r}: expected (name, speed ratio, teeth)")
            name, ratio, teeth = shaft
            if not (
                isinstance(name, str)
                and name
                and float(ratio) > 0
                and int(teeth) >= 2
                and int(teeth) == teeth
            ):
                raise ValueError(
                    f"shaft {shaft!r}: needs a name, a positive speed ratio and at least 2 teeth"
                )
        if self.scale not in SCALES:
            raise ValueError(f"unknown scale {self.scale!r}; choose one of {list(SCALES)}")
        if self.band_statistic not in BAND_STATISTICS:
            raise ValueError(
                f"unknown band_statistic {self.band_statistic!r}; choose one of {list(BAND_STATISTICS)}"
            )
        if not self.resolution_orders > 0:
            raise ValueError(f"resolution_orders must be positive, got {self.resolution_orders}")
        if self.order_min < 0 or self.order_max <= self.order_min:
            raise ValueError(
                f"need 0 <= order_min < order_max, got {self.order_min}, {self.order_max}"
            )
        span = (self.order_max - self.order_min) / self.resolution_orders
        if abs(span - round(span)) > 1e-6:
            raise ValueError(
                f"order_max - order_min = {self.order_max - self.order_min} is not a whole "
                f"number of resolution_orders = {self.resolution_orders} bands"
            )
        largest_order = max((self.mesh_harmonics * teeth + 1) for _, _, teeth in self._shafts())
        if int(self.samples_per_revolution) < 2 * max(self.order_max, largest_order) + 2:
            raise ValueError(
                f"samples_per_revolution={self.samples_per_revolution} cannot hold order "
                f"{max(self.order_max, largest_order):g} (needs more than twice it)"
            )
        for key in ("shaft_orders", "mesh_harmonics", "phase_harmonic"):
            if int(getattr(self, key)) < (0 if key == "shaft_orders" else 1):
                raise ValueError(f"{key} must be a positive whole number, got {getattr(self, key)}")
        if not 0 < self.phase_band_orders < 0.5:
            raise ValueError(
                f"phase_band_orders must lie in (0, 0.5), got {self.phase_band_orders}"
            )
        if not self.phase_min_snr > 0:
            raise ValueError(f"phase_min_snr must be positive, got {self.phase_min_snr}")

    def _check_segment(self, fs_hz: float, shaft_hz: float, n: int, speed_rpm: float) -> None:
        seconds = (n - 1) / fs_hz
        nyquist_order = fs_hz / 2 / shaft_hz
        if self.order_max > nyquist_order:
            raise ValueError(
                f"order_max={self.order_max} is above the Nyquist order {nyquist_order:.1f} "
                f"of a {fs_hz:g} Hz record at {speed_rpm:g} rpm"
            )
        for name, ratio, _ in self._shafts():
            if seconds * shaft_hz * ratio < 1:
                raise ValueError(
                    f"a {n / fs_hz:g} s segment at {speed_rpm:g} rpm holds "
                    f"{seconds * shaft_hz * ratio:.2f} revolutions of the {name}: less than "
                    "one to average"
                )
        if 1.0 / (seconds * shaft_hz) > self.resolution_orders * (1 + 1e-9):
            raise ValueError(
                f"resolution_orders={self.resolution_orders} is finer than the "
                f"{1 / (seconds * shaft_hz):.3g} orders a {n / fs_hz:g} s segment at "
                f"{speed_rpm:g} rpm resolves; use longer segments or a coarser resolution"
            )


def order_features_from_params(channels, shafts, order_params: dict) -> OrderFeatures:
    """An OrderFeatures from the config's `features.order` section, rejecting unknown keys."""
    unknown = sorted(set(order_params) - set(ORDER_PARAMS))
    if unknown:
        raise ValueError(
            f"unknown features.order parameter(s) {unknown}; allowed: {list(ORDER_PARAMS)}"
        )
    if not shafts:
        raise ValueError(
            "order features need the rig's geared shafts, and this system has none "
            "(System.shafts() is None)"
        )
    return OrderFeatures(shafts=[tuple(s) for s in shafts], channels=list(channels), **order_params)


def order_feature_table(signal_frame, channels, params: dict, inputs=None) -> pd.DataFrame:
    """Wide features table of one signal table: order-spectrum bands and gear condition indicators
    per channel (`condmon.order_features.OrderFeatures`, configured by `params` = the config's
    `features.order` with the rig's `shafts` [(name, speed ratio, teeth)], `GearSystem.shafts()`),
    with each segment's stored input-shaft speed. `inputs` (`condmon.features.FamilyInputs`):
    unused, the order features take no reference and run in one process."""
    params = dict(params)
    shafts = params.pop("shafts", None)
    try:
        extractor = order_features_from_params(channels, shafts, params)
    except ValueError as exc:
        raise FeatureTableError(f"features.order: {exc}") from exc
    present = set(signal_frame["channel"])
    missing = [ch for ch in extractor.channels if ch not in present]
    if missing:
        raise FeatureTableError(
            f"channel(s) {missing} not in the signal table (it has {sorted(present)})"
        )
    fs_hz = single_sampling_rate(signal_frame)
    ids, arrays = to_arrays(signal_frame, extractor.channels)
    try:
        values = extractor.transform(arrays, fs_hz, ids["speed_rpm"].to_numpy())
    except ValueError as exc:
        raise FeatureTableError(f"order features: {exc}") from exc
    return pd.concat(
        [ids.reset_index(drop=True), pd.DataFrame(values, columns=extractor.feature_names())],
        axis=1,
    )

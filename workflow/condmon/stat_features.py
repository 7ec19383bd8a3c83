"""Statistical condition indicators of vibration segments (the 15 features of the study behind
the rolling-element system) and envelope-spectrum indicators at defect orders the caller gives
(a system's `defect_orders()`; none: no envelope indicators).

Small pure functions, each computing one indicator along the last axis of an array (one segment
or a stack of segments), in the style of tsfresh's feature calculators, and `StatisticalFeatures`,
a stateless sklearn transformer computing all of them for a stack of segments.

Notation: x_n, n = 1..N, the samples of a segment; mu the mean; sigma the standard deviation
(population, 1/N); s_k the single-sided amplitude spectrum at frequencies f_k, k = 1..K
(`condmon.features.amplitude_spectrum`: Hann window, amplitude corrected, mean removed).

Time domain: Lei, He, Zi (2008), "A new approach to intelligent fault diagnosis of rotating
machinery", Expert Syst. Appl. 35, 1593-1600, Table 1; Caesarendra, Tjahjowidodo (2017),
"A review of feature extraction methods in vibration-based condition monitoring ...", Machines
5(4) 21. TALAF and THIKAT: Sassi, Badri, Thomas (2007), "A numerical model to predict damaged
bearing vibrations", J. Vib. Control 13(11), 1603-1628 (both named there). Frequency domain:
Lei et al. (2008), Table 1 (mean of the spectrum, frequency centre, root-mean-square frequency,
standard deviation frequency). Envelope analysis: Randall, Antoni (2011), "Rolling element bearing
diagnostics - a tutorial", MSSP 25, 485-520; Smith, Randall (2015), MSSP 64-65, 100-131 (CWRU).
"""

from __future__ import annotations

import numpy as np
import scipy.stats
from scipy.signal import butter, hilbert, periodogram, sosfiltfilt
from sklearn.base import BaseEstimator, TransformerMixin

from condmon import envelope as envelope_analysis
from condmon.spectra import amplitude_spectrum


# -- filters ---------------------------------------------------------------------------------
def highpass(x, fs_hz: float, cutoff_hz: float = 10.0, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth high-pass (removes DC offsets and drift); cutoff None/0: only the
    mean is removed.

    Forward-backward filtering of a mirrored (even) extension of 3 cutoff periods (at most the
    segment): the default short odd extension leaves edge transients that raise the RMS of
    impulsive segments by up to 35 % (a measured record of impacts).
    """
    x = np.asarray(x, dtype=np.float64)
    if not cutoff_hz:
        return x - x.mean(axis=-1, keepdims=True)
    if not 0 < cutoff_hz < fs_hz / 2:
        raise ValueError(f"high-pass cutoff {cutoff_hz} Hz must lie in (0, fs/2 = {fs_hz / 2} Hz)")
    sos = butter(order, cutoff_hz, btype="highpass", fs=fs_hz, output="sos")
    padlen = min(x.shape[-1] - 1, int(np.ceil(3 * fs_hz / cutoff_hz)))
    return sosfiltfilt(
        sos, x - x.mean(axis=-1, keepdims=True), axis=-1, padtype="even", padlen=padlen
    )


def bandpass(x, fs_hz: float, band_hz=(2000.0, 5000.0), order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth band-pass (even extension of 3 periods of the low edge)."""
    low, high = map(float, band_hz)
    if not 0 < low < high < fs_hz / 2:
        raise ValueError(f"band {band_hz} Hz must satisfy 0 < low < high < fs/2 = {fs_hz / 2} Hz")
    sos = butter(order, [low, high], btype="bandpass", fs=fs_hz, output="sos")
    x = np.asarray(x, dtype=np.float64)
    padlen = min(x.shape[-1] - 1, max(3 * (2 * len(sos) + 1), int(np.ceil(3 * fs_hz / low))))
    return sosfiltfilt(sos, x, axis=-1, padtype="even", padlen=padlen)


# -- time domain -----------------------------------------------------------------------------
def _x(x) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.shape[-1] < 2:
        raise ValueError(f"need at least 2 samples, got {x.shape[-1]}")
    return x


def mean(x):
    """mu = 1/N sum x_n."""
    return _x(x).mean(axis=-1)


def std(x):
    """sigma = sqrt(1/N sum (x_n - mu)^2) (population standard deviation)."""
    return _x(x).std(axis=-1)


def rms(x):
    """RMS = sqrt(1/N sum x_n^2)."""
    return np.sqrt(np.mean(_x(x) ** 2, axis=-1))


def peak(x):
    """Peak = max |x_n|."""
    return np.max(np.abs(_x(x)), axis=-1)


def skewness(x):
    """Skewness = 1/N sum (x_n - mu)^3 / sigma^3 (0 for any symmetric distribution)."""
    return scipy.stats.skew(_x(x), axis=-1, bias=True)


def kurtosis(x):
    """Kurtosis = 1/N sum (x_n - mu)^4 / sigma^4 (not the excess: 3 for Gaussian noise, 1.5 for
    a sine)."""
    return scipy.stats.kurtosis(_x(x), axis=-1, fisher=False, bias=True)


def crest_factor(x):
    """CF = Peak / RMS (sqrt 2 for a sine)."""
    return peak(x) / rms(x)


def impulse_factor(x):
    """IF = Peak / (1/N sum |x_n|) (pi/2 for a sine)."""
    return peak(x) / np.mean(np.abs(_x(x)), axis=-1)


def shape_factor(x):
    """SF = RMS / (1/N sum |x_n|) (pi / (2 sqrt 2) for a sine)."""
    return rms(x) / np.mean(np.abs(_x(x)), axis=-1)


def talaf(x, rms_ref: float = 1.0):
    """TALAF = ln(Kurtosis + RMS / RMS_0)  (Sassi et al. 2007).

    RMS_0 (`rms_ref`) is the RMS of the healthy machine, in the signal's unit. Sassi et al. write
    "log" without a base; the natural log is used here.
    """
    return np.log(kurtosis(x) + rms(x) / rms_ref)


def thikat(x, rms_ref: float = 1.0):
    """THIKAT = ln(Kurtosis^CF + (RMS / RMS_0)^Peak)  (Sassi et al. 2007).

    Evaluated in log space (logaddexp of CF ln K and Peak ln(RMS/RMS_0)) so large exponents do
    not overflow. Peak enters as an exponent, so THIKAT depends on the signal's unit (here the
    unit of x, m/s^2 in the signal table) and on RMS_0.
    """
    k, c, r, p = kurtosis(x), crest_factor(x), rms(x), peak(x)
    return np.logaddexp(c * np.log(k), p * np.log(r / rms_ref))


# -- frequency domain ------------------------------------------------------------------------
def _spectrum(x, fs_hz):
    freqs, amps = amplitude_spectrum(_x(x), fs_hz)
    return freqs, amps


def mean_frequency(x, fs_hz: float):
    """Mean frequency (Lei et al. 2008) MF = 1/K sum s_k: the mean amplitude of the
    spectrum, a level, not a frequency, despite the name used in this literature."""
    return _spectrum(x, fs_hz)[1].mean(axis=-1)


def frequency_centre(x, fs_hz: float):
    """Frequency centre FC = sum f_k s_k / sum s_k (Hz): the amplitude-weighted mean frequency."""
    f, s = _spectrum(x, fs_hz)
    return (s * f).sum(axis=-1) / s.sum(axis=-1)


def rms_frequency(x, fs_hz: float):
    """RMS frequency RMSF = sqrt(sum f_k^2 s_k / sum s_k) (Hz)."""
    f, s = _spectrum(x, fs_hz)
    return np.sqrt((s * f**2).sum(axis=-1) / s.sum(axis=-1))


def std_frequency(x, fs_hz: float):
    """Standard deviation frequency STDF = sqrt(sum (f_k - FC)^2 s_k / sum s_k) (Hz).

    (Some tables divide by K instead of sum s_k, which makes it depend on the level; the
    weighted standard deviation is used here, so RMSF^2 = FC^2 + STDF^2.)
    """
    f, s = _spectrum(x, fs_hz)
    fc = (s * f).sum(axis=-1, keepdims=True) / s.sum(axis=-1, keepdims=True)
    return np.sqrt((s * (f - fc) ** 2).sum(axis=-1) / s.sum(axis=-1))


# -- envelope spectrum -----------------------------------------------------------------------
def envelope(x, fs_hz: float, band_hz=(2000.0, 5000.0)) -> np.ndarray:
    """Envelope of the band-passed signal: |analytic signal of bandpass(x)| (Hilbert transform),
    mean removed."""
    env = np.abs(hilbert(bandpass(_x(x), fs_hz, band_hz), axis=-1))
    return env - env.mean(axis=-1, keepdims=True)


def envelope_spectrum(x, fs_hz: float, band_hz=(2000.0, 5000.0), pad_factor: int = 4):
    """Amplitude spectrum of the envelope of the band-passed signal (`envelope`).

    Hann window, amplitude corrected (a sinusoidal envelope modulation of amplitude A shows as A),
    zero-padded to `pad_factor` x N points so a line is sampled near its top wherever it falls
    between bins. Returns (freqs_hz, amplitudes).
    """
    return _amplitude_spectrum_padded(envelope(x, fs_hz, band_hz), fs_hz, pad_factor)


def _amplitude_spectrum_padded(env, fs_hz, pad_factor=4):
    n = env.shape[-1]
    window = np.hanning(n + 1)[:-1]  # periodic Hann
    nfft = int(pad_factor) * n
    amps = np.abs(np.fft.rfft(env * window, n=nfft, axis=-1)) * (2.0 / window.sum())
    amps[..., 0] /= 2.0
    return np.fft.rfftfreq(nfft, d=1.0 / fs_hz), amps


def _speed_hz(speed_rpm, shape) -> np.ndarray:
    speed = np.broadcast_to(np.asarray(speed_rpm, dtype=np.float64), shape) / 60.0
    if not (np.isfinite(speed) & (speed > 0)).all():
        raise ValueError("shaft speed must be a positive number for every segment")
    return speed


def envelope_line_ratio(freqs, amps, line_hz, tolerance: float = 0.015, floor_halfwidth_hz=15.0):
    """Line-over-local-floor ratio of an envelope spectrum at `line_hz` (per segment).

    line  = max amplitude within line_hz (1 +/- tolerance);
    floor = median amplitude within line_hz +/- floor_halfwidth_hz, outside the line window.
    Dimensionless; about 1-3 where there is no line. `line_hz` and `floor_halfwidth_hz` are
    scalars or one value per segment.
    """
    amps = np.atleast_2d(amps)
    line_hz = np.broadcast_to(np.asarray(line_hz, dtype=np.float64), amps.shape[:1])
    half = np.broadcast_to(np.asarray(floor_halfwidth_hz, dtype=np.float64), amps.shape[:1])
    out = np.empty(len(amps))
    for i, (f0, h) in enumerate(zip(line_hz, half, strict=True)):
        in_line = np.abs(freqs - f0) <= tolerance * f0
        if not in_line.any():  # window narrower than the grid: take the nearest bin
            in_line = np.zeros_like(in_line)
            in_line[np.argmin(np.abs(freqs - f0))] = True
        around = (np.abs(freqs - f0) <= h) & ~in_line
        if not around.any():
            raise ValueError(f"no envelope-spectrum bins around {f0:g} Hz for the floor")
        out[i] = amps[i, in_line].max() / max(np.median(amps[i, around]), np.finfo(float).tiny)
    return out


def envelope_band_energy(
    x, fs_hz: float, line_hz, band_hz=(2000.0, 5000.0), tolerance: float = 0.015
):
    """Power of the envelope (`envelope`) within line_hz (1 +/- tolerance), widened to at least
    +/- 2 FFT bins (the Hann main lobe), per segment: the envelope's periodogram (Hann, density
    scaling, single-sided) summed over the band times the bin width. A sinusoidal envelope
    modulation of amplitude A inside the band gives A^2 / 2; unit (signal unit)^2.
    """
    x = _x(x)
    freqs, density = envelope_periodogram(np.atleast_2d(envelope(x, fs_hz, band_hz)), fs_hz)
    out = band_power(freqs, density, line_hz, tolerance)
    return out if x.ndim > 1 else out[0]


def envelope_periodogram(env, fs_hz):
    """(freqs, power spectral density) of envelopes: periodic Hann window, no detrending (the
    envelope's mean is already removed)."""
    return periodogram(env, fs_hz, window="hann", detrend=False, axis=-1)


def band_power(freqs, density, line_hz, tolerance):
    """Per row of `density`, its sum times the bin width within line_hz (1 +/- tolerance), the
    band at least +/- 2 bins wide; line_hz is a scalar or one value per row."""
    df = freqs[1] - freqs[0]
    line_hz = np.broadcast_to(np.asarray(line_hz, dtype=np.float64), density.shape[:1])
    out = np.empty(len(density))
    for i, f0 in enumerate(line_hz):
        half = max(tolerance * f0, 2.0 * df)
        out[i] = density[i, np.abs(freqs - f0) <= half].sum() * df
    return out


# -- the transformer -------------------------------------------------------------------------
TIME_FEATURES = (
    "rms",
    "peak",
    "kurtosis",
    "crest_factor",
    "skewness",
    "impulse_factor",
    "shape_factor",
    "mean",
    "std",
    "talaf",
    "thikat",
)
FREQUENCY_FEATURES = ("mean_frequency", "rms_frequency", "frequency_centre", "std_frequency")
STUDY_FEATURES = TIME_FEATURES + FREQUENCY_FEATURES  # the study's 15
# the envelope analysis of `StatisticalFeatures` (features.statistical.envelope's defaults, and the
# sidebands the system gives: none)
ENVELOPE_DEFAULTS = {
    "band": "fixed",
    "prewhiten": False,
    "harmonics": 1,
    "kurtogram_max_level": 3,
    "sidebands": None,
}


class StatisticalFeatures(TransformerMixin, BaseEstimator):
    """The study's 15 time- and frequency-domain indicators plus envelope features at the
    `defect_orders` ({name: order of the shaft speed}; None or {}: no envelope features), for a
    stack of single-channel segments.

    Every segment is high-pass filtered first (`highpass_hz`, default 10 Hz: no DC offset or
    drift, which differ between sensors and records and would let a classifier learn the record).
    Envelope features per defect order o (line at o x shaft speed of the segment), by the
    envelope analysis `envelope_analysis` (a dict, `ENVELOPE_DEFAULTS` for what it leaves out):
    `band` (`fixed`: the band `band_hz`; `kurtogram`: each segment's band of largest spectral
    kurtosis, levels to `kurtogram_max_level`), after cepstral prewhitening where `prewhiten`
    (`condmon.envelope`); `env_ratio_<name>`: the squared envelope spectrum's summed line heights
    over their summed local floors (`condmon.envelope.line_ratio`, floor over +/-
    `floor_halfwidth_orders` x shaft speed) at the defect's harmonics 1..`harmonics`, each with
    sidebands at +/- the spacing `sidebands` gives the defect ({name: order}: the system's
    `defect_sidebands()`); `env_energy_<name>`: the power of the (plain) envelope of that band within
    the fundamental's window (`band_power`).
    Parameters are constructor arguments; stateless (fit only checks them).

    transform(X, speed_rpm): X (n_segments, n_samples), speed_rpm scalar or (n_segments,) ->
    (n_segments, n_features) float64, columns `get_feature_names_out()` (prefixed by `prefix`).
    fit_transform(X, speed_rpm=...): pass the speed by keyword (the second positional is y).
    `rms_ref` is RMS_0 of TALAF/THIKAT in the signal's unit.
    """

    def __init__(
        self,
        fs_hz: float = 12000.0,
        band_hz=(2000.0, 5000.0),
        highpass_hz: float | None = 10.0,
        defect_orders: dict | None = None,
        line_tolerance: float = 0.015,
        floor_halfwidth_orders: float = 0.5,
        rms_ref: float = 1.0,
        envelope: bool = True,
        prefix: str = "",
        envelope_analysis: dict | None = None,
    ):
        self.fs_hz = fs_hz
        self.band_hz = band_hz
        self.highpass_hz = highpass_hz
        self.defect_orders = defect_orders
        self.line_tolerance = line_tolerance
        self.floor_halfwidth_orders = floor_halfwidth_orders
        self.rms_ref = rms_ref
        self.envelope = envelope
        self.prefix = prefix
        self.envelope_analysis = envelope_analysis

    def _orders(self) -> dict:
        return dict(self.defect_orders or {})

    def get_feature_names_out(self, input_features=None) -> np.ndarray:
        names = list(STUDY_FEATURES)
        if self.envelope and self._orders():
            orders = self._orders()
            names += [f"env_energy_{k}" for k in orders] + [f"env_ratio_{k}" for k in orders]
        return np.asarray([f"{self.prefix}{n}" for n in names], dtype=object)

    def fit(self, X=None, y=None, speed_rpm=None):
        self._check_params()
        self.n_features_out_ = len(self.get_feature_names_out())
        return self

    def fit_transform(self, X, y=None, speed_rpm=None):
        return self.fit(X).transform(X, speed_rpm)

    def transform(self, X, speed_rpm=None) -> np.ndarray:
        self._check_params()
        X = np.asarray(X, dtype=np.float64)
        if X.ndim != 2:
            raise ValueError(f"expected an array (n_segments, n_samples), got shape {X.shape}")
        if not np.isfinite(X).all():
            raise ValueError("segments contain NaN or inf")
        fs = float(self.fs_hz)
        x = highpass(X, fs, self.highpass_hz)
        columns = [
            rms(x),
            peak(x),
            kurtosis(x),
            crest_factor(x),
            skewness(x),
            impulse_factor(x),
            shape_factor(x),
            mean(x),
            std(x),
            talaf(x, self.rms_ref),
            thikat(x, self.rms_ref),
        ]
        columns += [
            mean_frequency(x, fs),
            rms_frequency(x, fs),
            frequency_centre(x, fs),
            std_frequency(x, fs),
        ]
        if self.envelope and self._orders():
            if speed_rpm is None:
                raise ValueError(
                    "envelope features need the shaft speed of every segment (speed_rpm)"
                )
            shaft_hz = _speed_hz(speed_rpm, X.shape[:1])
            orders = self._orders()
            options = self._envelope()
            sets = envelope_analysis.fault_line_sets(
                orders, options["sidebands"], options["harmonics"], self.line_tolerance
            )
            signal, bands = envelope_analysis.demodulation_bands(
                x,
                fs,
                self.analysis(),
                self.band_hz,
                options["kurtogram_max_level"],
                envelope_analysis.min_bandwidth_hz(
                    sets, shaft_hz, self.line_tolerance, self.floor_halfwidth_orders
                ),
            )
            freqs, amps = envelope_analysis.squared_envelope_spectrum(signal, fs, bands)
            env = np.abs(envelope_analysis.analytic_band(signal, fs, bands))
            psd_freqs, density = envelope_periodogram(env - env.mean(axis=-1, keepdims=True), fs)
            energies = [
                band_power(psd_freqs, density, o * shaft_hz, self.line_tolerance)
                for o in orders.values()
            ]
            ratios = [
                envelope_analysis.line_ratio(
                    freqs,
                    amps,
                    np.outer(shaft_hz, sets[name]),
                    self.line_tolerance,
                    self.floor_halfwidth_orders * shaft_hz,
                )
                for name in orders
            ]
            columns += energies + ratios
        return np.column_stack(columns)

    def _envelope(self) -> dict:
        """`envelope_analysis` over `ENVELOPE_DEFAULTS`; an unknown key is an error naming it."""
        given = dict(self.envelope_analysis or {})
        unknown = sorted(set(given) - set(ENVELOPE_DEFAULTS))
        if unknown:
            raise ValueError(
                f"envelope_analysis: unknown key(s) {unknown}; choose among {sorted(ENVELOPE_DEFAULTS)}"
            )
        return {**ENVELOPE_DEFAULTS, **given}

    def analysis(self) -> str:
        """The envelope analysis's name (`condmon.envelope.ANALYSES`)."""
        options = self._envelope()
        return ("prewhitened_" if options["prewhiten"] else "") + str(options["band"])

    def _check_params(self) -> None:
        options = self._envelope()
        if self.analysis() not in envelope_analysis.ANALYSES:
            raise ValueError(
                f"envelope_analysis band {options['band']!r}: choose fixed or kurtogram"
            )
        if not (isinstance(options["harmonics"], (int, np.integer)) and options["harmonics"] >= 1):
            raise ValueError(
                f"envelope_analysis harmonics must be a whole number >= 1, got {options['harmonics']!r}"
            )
        if not self.fs_hz > 0:
            raise ValueError(f"fs_hz must be positive, got {self.fs_hz}")
        low, high = self.band_hz
        if not 0 < low < high < self.fs_hz / 2:
            raise ValueError(f"band_hz {self.band_hz} must satisfy 0 < low < high < fs/2")
        if self.highpass_hz and not 0 < self.highpass_hz < self.fs_hz / 2:
            raise ValueError(f"highpass_hz {self.highpass_hz} must lie in (0, fs/2)")
        if not 0 < self.line_tolerance < 0.5:
            raise ValueError(f"line_tolerance must be in (0, 0.5), got {self.line_tolerance}")
        if not self.floor_halfwidth_orders > 0:
            raise ValueError("floor_halfwidth_orders must be positive")
        if not self.rms_ref > 0:
            raise ValueError(f"rms_ref must be positive, got {self.rms_ref}")
        for name, order in self._orders().items():
            if not (isinstance(name, str) and name and float(order) > 0):
                raise ValueError(f"defect order {name!r}: {order} must be a positive number")


# -- features tables -------------------------------------------------------------------------
def statistical_features_from_params(
    params: dict, fs_hz: float, prefix: str = "", defect_orders: dict | None = None
) -> StatisticalFeatures:
    """The extractor a `features.statistical` config section describes (band_hz, highpass_hz,
    line_tolerance, floor_halfwidth_orders, rms_ref; its `envelope` analysis: band, prewhiten,
    harmonics, kurtogram_max_level; `line_sidebands`, the system's, in the rules' settings: `statistical_feature_params`),
    with envelope lines at `defect_orders` (the system's; None: none)."""
    keys = ("band_hz", "highpass_hz", "line_tolerance", "floor_halfwidth_orders", "rms_ref")
    kwargs = {k: params[k] for k in keys if k in params}
    if "band_hz" in kwargs:
        kwargs["band_hz"] = tuple(kwargs["band_hz"])
    analysis = dict(params.get("envelope") or {})
    if params.get("line_sidebands"):
        analysis["sidebands"] = dict(params["line_sidebands"])
    kwargs["envelope_analysis"] = analysis
    if defect_orders is not None:
        kwargs["defect_orders"] = dict(defect_orders)
    return StatisticalFeatures(fs_hz=fs_hz, prefix=prefix, **kwargs)

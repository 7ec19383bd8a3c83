"""The background healthy records reveal and the model lacks: its estimate (calibration) and its
synthesis (simulation).

Two estimates (`calibration.background_method`), per channel at one speed:
- `incoherent` (default): the part of each channel's power spectral density that no other channel
  explains, measured minus model, clipped at zero. That part is the conditioned spectrum of the
  channel given all the others, 1 / [G^-1(f)]_ii of the cross-spectral matrix G (Bendat & Piersol,
  "Random Data", multiple-input systems: the output noise spectrum): sensor noise, white or
  coloured, independent in each accelerometer chain. Vibration of the structure reaches every
  channel and is coherent across them, so a model that is quieter than the machine, or has other
  structural modes, does not turn its shortfall into noise. (On a virtual bench with 0.002 m/s^2 of
  sensor noise and 0.2-7 m/s^2 of machine vibration, `deficit` took the model's shortfall for 0.16-6
  m/s^2 of noise and buried the simulated faults under it; `incoherent` finds 0.003-0.023 m/s^2.)
  Needs two or more channels.
- `deficit`: the PSD of the measured healthy segments minus the mean PSD of the calibrated model's
  healthy runs: whatever the measurement carries that the model does not make (noise, tones of
  parts the model lacks, a motor's ripple), but also any shortfall of the model's own vibration.
  For a model that reproduces the machine's level, or a single channel.

The simulation adds a random-phase Gaussian realisation of the background to every simulated
sample (independently per channel), so a classifier trained on simulation sees the floor a healthy
measured record has.

PSDs are one-sided Welch densities ((m/s^2)^2/Hz for accelerations). `deficit`: over segments of
the system's segment length at its output rate (Hann window, no overlap: one periodogram per
segment, averaged), on the grid `numpy.fft.rfftfreq(segment_length, 1 / rate)`. `incoherent`: Hann
windows of `coherence_window` samples, half overlapping, within each segment (enough averages for
the cross-spectral matrix to be inverted), on that window's grid.
"""

from __future__ import annotations

import logging
import multiprocessing
import signal
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pandas as pd
from scipy.signal import welch

from condmon.models.numerics import SimulationError
from condmon.signals import to_arrays

log = logging.getLogger(__name__)
COLUMNS = ["speed_rpm", "channel", "freq_hz", "measured_psd", "model_psd", "background_psd"]


def segment_psd(segments: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies, mean one-sided Welch PSD) of segments shaped (n_segments, n_channels, n):
    one Hann-windowed periodogram per segment (mean removed), averaged over the segments; the
    PSD is shaped (n_channels, n // 2 + 1)."""
    segments = np.asarray(segments, dtype=float)
    if segments.ndim != 3 or segments.shape[0] == 0:
        raise ValueError(
            f"segment_psd needs segments shaped (n_segments, n_channels, n), got {segments.shape}"
        )
    n = segments.shape[-1]
    freqs, psd = welch(
        segments, fs=fs_hz, window="hann", nperseg=n, noverlap=0, scaling="density", axis=-1
    )
    return freqs, psd.mean(0)


METHODS = ("incoherent", "deficit")


def coherence_window(segment_length: int) -> int:
    """The Welch window of the `incoherent` estimate: the largest power of two within a quarter
    segment (512 samples of a 2560-sample segment: 9 half-overlapping windows a segment)."""
    return 2 ** int(np.floor(np.log2(max(segment_length // 4, 2))))


def incoherent_psd(
    segments: np.ndarray, fs_hz: float, window: int
) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies, per channel the part of its PSD no other channel explains) of segments shaped
    (n_segments, n_channels, n): 1 / [G^-1(f)]_ii of the cross-spectral matrix G averaged over
    half-overlapping Hann windows of `window` samples (mean removed), times d / (d - q) for d
    averages and q other channels (the estimate's bias). Shaped (n_channels, window // 2 + 1)."""
    segments = np.asarray(segments, dtype=float)
    if segments.ndim != 3 or segments.shape[0] == 0:
        raise ValueError(
            f"incoherent_psd needs segments shaped (n_segments, n_channels, n), got {segments.shape}"
        )
    channels, n = segments.shape[1], segments.shape[2]
    if channels < 2:
        raise ValueError(
            "incoherent_psd: the part no other channel explains needs two or more channels"
        )
    if n < window:
        raise ValueError(
            f"incoherent_psd: segments of {n} samples are shorter than the {window}-sample window"
        )
    taper = np.hanning(window)
    starts = range(0, n - window + 1, window // 2)
    pieces = np.stack(
        [segment[:, start : start + window] for segment in segments for start in starts]
    )
    pieces = pieces - pieces.mean(axis=-1, keepdims=True)
    spectra = np.fft.rfft(pieces * taper, axis=-1)  # (d, channels, f)
    averages = len(pieces)
    if averages <= channels:
        raise ValueError(
            f"incoherent_psd: {averages} windows cannot resolve {channels} channels; "
            "the background needs more healthy segments"
        )
    # one-sided density scaling of a Hann periodogram (as scipy.signal.welch's)
    scale = 2.0 / (fs_hz * (taper**2).sum())
    cross = np.einsum("dif,djf->fij", spectra, spectra.conj()) / averages * scale
    conditioned = 1.0 / np.real(np.einsum("fii->if", np.linalg.inv(cross)))
    conditioned *= averages / (averages - (channels - 1))
    conditioned[:, 0] = 0.0  # the mean was removed
    return np.fft.rfftfreq(window, 1.0 / fs_hz), np.maximum(conditioned, 0.0)


def background_psd(measured: np.ndarray, model: np.ndarray) -> np.ndarray:
    """Measured minus model PSD, clipped at zero: where the model has more power than the
    measurement there is nothing to add."""
    return np.maximum(np.asarray(measured, dtype=float) - np.asarray(model, dtype=float), 0.0)


def synthesise(
    freqs: np.ndarray, psd: np.ndarray, n: int, fs_hz: float, rng: np.random.Generator
) -> np.ndarray:
    """A Gaussian signal of `n` samples whose one-sided PSD is `psd` on `freqs` (linearly
    interpolated onto the signal's own frequency grid): complex Gaussian Fourier coefficients
    (Rayleigh amplitudes, uniform phases) of variance fs n S(f) / 2, no mean."""
    grid = np.fft.rfftfreq(n, 1.0 / fs_hz)
    density = np.interp(grid, freqs, psd, left=0.0, right=0.0)
    scale = np.sqrt(density * fs_hz * n / 2.0)
    coefficients = (
        scale
        * (rng.standard_normal(len(grid)) + 1j * rng.standard_normal(len(grid)))
        / np.sqrt(2.0)
    )
    coefficients[0] = 0.0
    if n % 2 == 0:  # the Nyquist coefficient of a real signal is real, and holds its power once
        coefficients[-1] = scale[-1] * np.sqrt(2.0) * rng.standard_normal()
    return np.fft.irfft(coefficients, n=n)


# -- estimate (calibrate job) -------------------------------------------------------------------
_WORKER = {}


def _init_worker(system, variant, values, duration_s):
    # as the calibration's workers: SIGTERM ends a worker at once (it writes no file)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _WORKER.update(system=system, variant=variant, values=values, duration=duration_s)


def _model_run(task):
    point, seed = task
    w = _WORKER
    try:
        return w["system"].simulate_healthy(
            w["variant"],
            w["system"].at_load(w["values"], point.load),
            point.speed_rpm,
            w["duration"],
            seed,
        ), ""
    except SimulationError as exc:
        return None, str(exc)


def run_seeds(seed: int, runs: int) -> list[int]:
    """The run seeds of the model's healthy runs (the calibration seed's own stream)."""
    return [int(s) for s in np.random.SeedSequence([int(seed), 0xBAC6]).generate_state(runs)]


def estimate_background(
    system,
    frame: pd.DataFrame,
    calibrated: dict,
    channels,
    runs: int,
    sim_seconds: float,
    seed: int,
    processes: int = 1,
    method: str = "incoherent",
) -> pd.DataFrame:
    """Per speed of the measured healthy records (those among the system's simulated speeds) and
    channel: the measured, the model's and the background PSD (`COLUMNS`, long form; with
    `method` incoherent, measured and model are the parts no other channel explains). The model's
    PSD is the mean over `runs` healthy runs of the calibrated model (`calibrated`: model_variant,
    parameters), each `sim_seconds` long with its own seed (so the model's per-run variability is
    in the mean), cut into whole segments. No healthy record at a simulated speed: an empty frame.
    A rig run at several loads: each operating point's records against the model at its load,
    the speed's PSDs the mean over its points (what the model lacks is the machine's at any load)."""
    fs, n = system.output_rate_hz, system.segment_length
    channels = list(channels)
    if method not in METHODS:
        raise ValueError(f"calibration.background_method: {method!r} is not one of {list(METHODS)}")
    if method == "incoherent":
        if len(channels) < 2:
            raise ValueError(
                f"calibration.background_method incoherent: the part no other channel explains "
                f"needs two or more channels (features.channels: {channels}); use deficit"
            )
        window = coherence_window(n)

        def spectrum(segments):
            return incoherent_psd(segments, fs, window)
    else:

        def spectrum(segments):
            return segment_psd(segments, fs)

    healthy = frame[frame["health_state"] == system.healthy_state]
    points = system.measured_points(healthy, system.healthy_state)
    if not points:
        return pd.DataFrame(
            {c: pd.Series(dtype=object if c == "channel" else float) for c in COLUMNS}
        )
    if int(sim_seconds * fs + 1e-9) < n:
        raise ValueError(
            f"calibration.sim_seconds: {sim_seconds} s is shorter than one segment "
            f"({n} samples at {fs:g} Hz)"
        )
    tasks = [(point, s) for point in points for s in run_seeds(seed, runs)]
    pool = ProcessPoolExecutor(
        max(1, min(processes, len(tasks))),
        mp_context=multiprocessing.get_context("fork"),
        initializer=_init_worker,
        initargs=(
            system,
            calibrated["model_variant"],
            dict(calibrated["parameters"]),
            float(sim_seconds),
        ),
    )
    try:
        results = list(pool.map(_model_run, tasks))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    by_point = {}
    for point in points:
        done = [
            signals
            for (p, _), (signals, _) in zip(tasks, results)
            if p == point and signals is not None
        ]
        for (p, run_seed), (signals, error) in zip(tasks, results):
            if p == point and signals is None:
                log.warning(
                    "background: the model's healthy run at %s (seed %d) failed: %s",
                    point.describe(),
                    run_seed,
                    error,
                )
        if not done:
            raise SimulationError(
                f"background: every healthy run of the calibrated model at {point.describe()} failed"
            )
        model_segments = np.concatenate([_segments(signals, channels, n) for signals in done])
        freqs, model = spectrum(model_segments)
        _, measured_segments = to_arrays(healthy[point.holds(healthy)], channels)
        _, measured = spectrum(measured_segments)
        by_point[point] = (measured, model, background_psd(measured, model))
        log.info(
            "background (%s) at %s from %d measured and %d model segments",
            method,
            point.describe(),
            len(measured_segments),
            len(model_segments),
        )
    parts = []
    for speed in sorted({point.speed_rpm for point in points}):
        measured, model, background = (
            np.mean(
                [psds[k] for point, psds in by_point.items() if point.speed_rpm == speed], axis=0
            )
            for k in range(3)
        )
        for j, channel in enumerate(channels):
            parts.append(
                pd.DataFrame(
                    dict(
                        speed_rpm=speed,
                        channel=channel,
                        freq_hz=freqs,
                        measured_psd=measured[j],
                        model_psd=model[j],
                        background_psd=background[j],
                    )
                )
            )
        log.info(
            "background (%s) at %g rpm: rms %s m/s^2",
            method,
            speed,
            {
                c: round(float(np.sqrt(background[j].sum() * (freqs[1] - freqs[0]))), 6)
                for j, c in enumerate(channels)
            },
        )
    return pd.concat(parts, ignore_index=True)[COLUMNS]


def _segments(signals: dict, channels, n: int) -> np.ndarray:
    count = len(signals[channels[0]]) // n
    return np.stack(
        [[np.asarray(signals[c][k * n : (k + 1) * n]) for c in channels] for k in range(count)]
    )


def background_rms(table: pd.DataFrame) -> dict:
    """{speed: {channel: RMS of the background}} (params.json's summary, m/s^2)."""
    out = {}
    for (speed, channel), rows in table.groupby(["speed_rpm", "channel"], sort=True):
        df = float(np.diff(rows["freq_hz"].to_numpy()[:2])[0])
        out.setdefault(f"{speed:g}", {})[channel] = float(
            np.sqrt(rows["background_psd"].sum() * df)
        )
    return out


# -- synthesis (simulate job) -------------------------------------------------------------------
class Background:
    """The stored background (`estimate_background`'s table): per speed and channel a PSD to
    realise. A speed without measured healthy records takes the nearest measured speed's
    background as it is (no rescaling of its shaft-synchronous lines; see ARCHITECTURE.md)."""

    def __init__(self, table: pd.DataFrame):
        missing = sorted(set(COLUMNS) - set(table.columns))
        if missing:
            raise ValueError(f"background table: missing columns {missing}")
        self.psd = {
            (float(speed), channel): (rows["freq_hz"].to_numpy(), rows["background_psd"].to_numpy())
            for (speed, channel), rows in table.groupby(["speed_rpm", "channel"], sort=True)
        }
        self.speeds = sorted({speed for speed, _ in self.psd})

    def __bool__(self) -> bool:
        return bool(self.psd)

    def source_speed(self, speed_rpm: float) -> float:
        """The measured speed whose background a simulated speed takes: the nearest."""
        return min(self.speeds, key=lambda s: (abs(s - float(speed_rpm)), s))

    def add(
        self, signals: dict, speed_rpm: float, fs_hz: float, rng: np.random.Generator
    ) -> tuple[dict, list]:
        """`signals` plus a realisation of the background of each channel (channels in a fixed
        order, so the draw is reproducible); returns (signals, channels without a background)."""
        source = self.source_speed(speed_rpm)
        out, bare = {}, []
        for name in sorted(signals):
            signal_ = signals[name]
            if (source, name) in self.psd:
                freqs, psd = self.psd[(source, name)]
                out[name] = signal_ + synthesise(freqs, psd, len(signal_), fs_hz, rng)
            else:
                out[name] = signal_
                bare.append(name)
        return {name: out[name] for name in signals}, bare


def read_background(path) -> Background:
    """The Background of a stored table (the calibrate job's `background.parquet`)."""
    return Background(pd.read_parquet(path))

"""Calibration stage: CMA-ES tunes a system's model (its parameters and, where the system offers
a choice, its model variant) so its healthy spectra match the measured healthy spectra.

The spectral costs every system may use (`SPECTRAL_COSTS`): `cfrp_eq4` (CFRP study, eq. 4), the
normalised least-squares error between simulated and measured amplitude spectra, sum over
frequency bins of (a_sim - a_meas)^2 / sum of a_meas^2, averaged over every (speed, channel);
`helical_eq14` (the helical study's eq. 14), the sum over locations of the Euclidean spectral
distance. A system declares the costs its calibration offers (`System.calibration_costs`: these,
and any of its own); this module knows none but these.

The model variant is categorical (`System.model_variants`): `catcma` searches it jointly with the
continuous parameters (CatCMA), `per_law` runs one CMA-ES per variant and keeps the best.
"""

from __future__ import annotations

import logging
import math
import multiprocessing
import signal
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Callable

import numpy as np
import pandas as pd
from cmaes import CMA, CatCMA

from condmon.features import SpectrumFeatures
from condmon.signals import to_arrays
from condmon.models.numerics import SimulationError
from condmon.operating import as_point

log = logging.getLogger(__name__)
FAILED_COST = 1.0e3  # a diverged candidate is a bad candidate, not a crash of the search


def cfrp_eq4(simulated: np.ndarray, measured: np.ndarray) -> float:
    """Normalised least squares per (speed, channel), averaged: arrays (n_speeds, n_channels, n_bins)."""
    return float(np.mean(((simulated - measured) ** 2).sum(-1) / (measured**2).sum(-1)))


def helical_eq14(simulated: np.ndarray, measured: np.ndarray) -> float:
    """Euclidean spectral distance summed over channels, averaged over speeds."""
    return float(np.mean(np.sqrt(((simulated - measured) ** 2).sum(-1)).sum(-1)))


# name -> cost(simulated, measured): the costs on spectra every system may offer
SPECTRAL_COSTS = {"cfrp_eq4": cfrp_eq4, "helical_eq14": helical_eq14}


def cost_function(kind, costs: dict | None = None):
    """The cost called `kind` among `costs` (default `SPECTRAL_COSTS`), or `kind` itself when it
    is a callable (simulated, measured) -> float."""
    if callable(kind):
        return kind
    costs = SPECTRAL_COSTS if costs is None else costs
    if kind not in costs:
        raise ValueError(f"unknown calibration cost {kind!r}; choose one of {list(costs)}")
    return costs[kind]


def spectrum_cost(
    simulated: np.ndarray, measured: np.ndarray, kind="cfrp_eq4", costs: dict | None = None
) -> float:
    """Cost `kind` (a name among `costs`, default the spectral ones, or a callable) between
    arrays of shape (n_speeds, n_channels, n_bins)."""
    return float(cost_function(kind, costs)(simulated, measured))


def estimate_sensor_noise(
    measured: np.ndarray, segment_length: int, floor_quantile: float = 0.1
) -> float:
    """RMS (m/s^2) of white sensor noise: the floor of the measured spectra.

    White noise lies under every band at one level, so a low quantile (`floor_quantile`) of the
    measured band power over all speeds, channels and bands is set by the noise, not by the
    machine's lines. Noise-only bands scatter about their mean, so the quantile reads somewhat
    low (0.78 of a model-form bench's white noise at the default 0.1). The power the measured
    spectra carry above the model's is no measure of it, because
    that excess is mostly what the model lacks (a bench's structural modes and tones): taken as noise,
    it buries the fault sidebands of the simulated records. A Hann-windowed, amplitude-corrected
    spectrum of white noise of RMS sigma has E|X_k|^2 = 6 sigma^2 / N per bin.
    """
    if not 0.0 < floor_quantile < 1.0:
        raise ValueError(
            f"calibration.noise_floor_quantile must lie in (0, 1), got {floor_quantile}"
        )
    floor_power = np.quantile(measured**2, floor_quantile)
    return float(np.sqrt(floor_power * segment_length / 6.0))


def with_sensor_noise(spectra: np.ndarray, sensor_noise: float, segment_length: int) -> np.ndarray:
    """The expected RMS band spectra of a model's signals plus white sensor noise of RMS
    `sensor_noise`: powers add, and the noise puts 6 sigma^2 / N in every bin (see
    `estimate_sensor_noise`). What a noise-free model's spectra look like once measured."""
    return np.sqrt(spectra**2 + 6.0 * sensor_noise**2 / segment_length)


@dataclass
class Bound:
    name: str
    low: float
    high: float
    log: bool

    def to_unit(self, value: float) -> float:
        # a value outside the range (a nominal 0 under a log range) maps to the nearest bound
        value = min(max(value, self.low), self.high)
        if self.log:
            return (math.log(value) - math.log(self.low)) / (
                math.log(self.high) - math.log(self.low)
            )
        return (value - self.low) / (self.high - self.low)

    def from_unit(self, z: float) -> float:
        z = min(max(z, 0.0), 1.0)
        if self.log:
            return math.exp(math.log(self.low) + z * (math.log(self.high) - math.log(self.low)))
        return self.low + z * (self.high - self.low)


def calibration_spectrum(spectrum: dict, resolution_hz: float) -> dict:
    """The features' frequency range in coarser, energy-keeping (RMS) bands of linear amplitude:
    eq. 4 compares amplitudes, and coarse RMS bands keep it robust to the small speed changes
    of a real bench."""
    return {**spectrum, "resolution_hz": resolution_hz, "scale": "linear", "band_statistic": "rms"}


class SpectrumModel:
    """Mean spectra of a system's healthy runs at the calibration's operating points (speeds, or
    `OperatingPoint`s with their loads) for one candidate, the callable `Calibrator` evaluates:
    __call__(variant, values) -> (n_points, n_channels, n_bands), RMS bands of
    `calibration_spectrum`. Every run is `sim_seconds` long and cut into the system's segments;
    `seed` makes a model with randomness repeatable."""

    def __init__(
        self,
        system,
        points,
        channels,
        spectrum: dict,
        resolution_hz: float,
        sim_seconds: float,
        seed: int = 1,
    ):
        self.system, self.channels = system, list(channels)
        self.points = [as_point(point) for point in points]
        self.speeds = [point.speed_rpm for point in self.points]
        self.sim_seconds, self.seed = float(sim_seconds), int(seed)
        self.output_rate = system.output_rate_hz
        self.segment_length = system.segment_length
        if int(round(self.sim_seconds * self.output_rate)) < self.segment_length:
            raise ValueError(
                f"calibration.sim_seconds: {sim_seconds} s is shorter than one segment "
                f"({self.segment_length} samples at {self.output_rate:g} Hz)"
            )
        self.spectrum = SpectrumFeatures(
            channels=self.channels, **calibration_spectrum(spectrum, resolution_hz)
        )

    def mean_spectra(self, signals_by_speed) -> np.ndarray:
        out = []
        for signals in signals_by_speed:
            n_seg = len(signals[self.channels[0]]) // self.segment_length
            stack = np.stack(
                [
                    [
                        signals[c][k * self.segment_length : (k + 1) * self.segment_length]
                        for c in self.channels
                    ]
                    for k in range(n_seg)
                ]
            )
            features = self.spectrum.transform(stack, self.output_rate)
            out.append(features.mean(0).reshape(len(self.channels), -1))
        return np.stack(out)

    def __call__(self, variant: str, values: dict) -> np.ndarray:
        return self.mean_spectra(
            [
                self.system.simulate_healthy(
                    variant,
                    self.system.at_load(values, point.load),
                    point.speed_rpm,
                    self.sim_seconds,
                    self.seed,
                )
                for point in self.points
            ]
        )


def measured_spectra(
    frame: pd.DataFrame,
    points,
    channels,
    spectrum: dict,
    resolution_hz: float,
    fs_hz: float,
    label: str = "healthy",
    tolerance_rpm: float = 0.0,
) -> np.ndarray:
    """Mean amplitude spectra of the measured `label` segments per operating point (speeds, or
    `OperatingPoint`s: records within `tolerance_rpm` of its speed, at its load where it has one):
    (points, channels, bands), the calibration target."""
    transformer = SpectrumFeatures(
        channels=list(channels), **calibration_spectrum(spectrum, resolution_hz)
    )
    out = []
    for point in map(as_point, points):
        at = (frame["speed_rpm"] - point.speed_rpm).abs() <= tolerance_rpm
        if point.load is not None:
            at &= np.isclose(frame["load"].astype(float), point.load)
        rows = frame[(frame["health_state"] == label) & at]
        if rows.empty:
            raise ValueError(f"no measured {label!r} records at {point.describe()} to calibrate on")
        _, arrays = to_arrays(rows, list(channels))
        out.append(transformer.transform(arrays, fs_hz).mean(0).reshape(len(channels), -1))
    return np.stack(out)


@dataclass(frozen=True)
class SpectralProblem:
    """What a spectral calibration compares: the operating points, the measured healthy mean
    spectra there (`target`), the model's (`spectrum_model`) and the `cost` between them."""

    points: list
    target: np.ndarray
    spectrum_model: SpectrumModel
    cost: Callable

    def __call__(self, variant: str, values: dict) -> float:
        """The cost of one candidate (a model variant and its parameter values)."""
        return float(self.cost(self.spectrum_model(variant, values), self.target))


def spectral_problem(
    system, frame: pd.DataFrame, calibration: dict, spectrum: dict, channels
) -> SpectralProblem:
    """The spectral calibration's problem on a system's healthy measured records at its
    simulated operating points (every point without records left out; none at all refused)."""
    fs = system.output_rate_hz
    points = system.measured_points(frame, system.healthy_state)
    if not points:
        raise ValueError(
            f"no measured {system.healthy_state!r} records at the simulated operating points "
            f"{[point.describe() for point in system.operating_points]} to calibrate on"
        )
    target = measured_spectra(
        frame,
        points,
        channels,
        spectrum,
        calibration["resolution_hz"],
        fs,
        label=system.healthy_state,
    )
    spectrum_model = SpectrumModel(
        system,
        points,
        channels,
        spectrum,
        calibration["resolution_hz"],
        calibration["sim_seconds"],
        seed=calibration["seed"],
    )
    cost = cost_function(calibration["cost"], system.calibration_costs())
    return SpectralProblem(points, target, spectrum_model, cost)


def variant_check(problem: SpectralProblem, best: dict, variants, nominal_variant) -> dict:
    """Whether the records see the model variant the search picked: the `problem`'s cost of
    another variant at the picked parameters (the nominal variant, else the first other one).
    {} with one variant.

    `model_variant_seen` is False when both costs agree to 1e-9: the healthy runs never reach
    what the variants change (a variant that acts on rare events only), so the picked variant is
    the search's draw, not a finding; a warning says so. None when the other variant's run
    fails."""
    picked = best["model_variant"]
    others = [variant for variant in variants if variant != picked]
    if not others:
        return {}
    other = nominal_variant if nominal_variant in others else others[0]
    try:
        other_cost = problem(other, best["parameters"])
    except SimulationError as exc:  # a diagnostic: the calibration stands without it
        log.warning(
            "the calibrated parameters with %s failed (%s): variant not compared", other, exc
        )
        return {"model_variant_seen": None, "model_variant_compared": {other: None}}
    seen = not np.isclose(other_cost, best["cost"], rtol=1e-9, atol=0.0)
    if not seen:
        log.warning(
            "the healthy records do not tell the model variants apart: %s costs %.6g at the "
            "calibrated parameters, as %s does; %s is the search's draw, not a finding",
            *(other, other_cost, picked, picked),
        )
    return {"model_variant_seen": seen, "model_variant_compared": {other: other_cost}}


def calibrate_on_spectra(
    system,
    frame: pd.DataFrame,
    calibration: dict,
    spectrum: dict,
    channels,
    nominal: dict,
    processes: int = 1,
    problem: SpectralProblem | None = None,
):
    """The spectral calibration of a system on its healthy measured records at its simulated
    speeds: CMA-ES over `calibration.parameters` (and the system's `model_variants()`) from the
    `nominal` values and its `nominal_variant`, by the system's cost `calibration.cost`, then the
    white sensor noise the model lacks. Returns (result, history, spectra frame) as
    `System.calibrate` does; `problem`: the `spectral_problem`, if the caller has it."""
    start = time.perf_counter()
    if problem is None:
        problem = spectral_problem(system, frame, calibration, spectrum, channels)
    points, target = problem.points, problem.target
    spectrum_model, cost = problem.spectrum_model, problem.cost
    speeds = sorted({point.speed_rpm for point in points})
    bounds = [
        Bound(name, b["low"], b["high"], b.get("log", False))
        for name, b in calibration["parameters"].items()
    ]
    calibrator = Calibrator(
        bounds,
        system.model_variants(calibration),
        strategy=calibration["strategy"],
        population=calibration["population"],
        generations=calibration["generations"],
        sigma0=calibration["sigma0"],
        seed=calibration["seed"],
        processes=processes,
        initial={b.name: nominal[b.name] for b in bounds},
    )
    log.info(
        "calibrating %s of the %s system on its healthy records at %s, %d processes",
        [b.name for b in bounds],
        system.name,
        [point.describe() for point in points],
        processes,
    )
    best, history = calibrator.run(spectrum_model, target, cost)
    variants = variant_check(
        problem, best, system.model_variants(calibration), system.nominal_variant
    )
    nominal_values = {b.name: nominal[b.name] for b in bounds}
    nominal_cost = cost(spectrum_model(system.nominal_variant, nominal_values), target)
    calibrated = spectrum_model(best["model_variant"], best["parameters"])
    freqs = spectrum_model.spectrum.band_centres()
    sensor_noise = estimate_sensor_noise(
        target, spectrum_model.segment_length, calibration["noise_floor_quantile"]
    )
    # What simulated records look like: the model plus the estimated sensor noise (6 sigma^2 / N per bin).
    with_noise = with_sensor_noise(calibrated, sensor_noise, spectrum_model.segment_length)
    rows = [
        pd.DataFrame(
            dict(
                speed_rpm=point.speed_rpm,
                **({} if point.load is None else {"load": point.load}),
                channel=channel,
                freq_hz=freqs,
                measured=target[i, j],
                calibrated=with_noise[i, j],
                model_only=calibrated[i, j],
            )
        )
        for i, point in enumerate(points)
        for j, channel in enumerate(channels)
    ]
    result = dict(
        best,
        **variants,
        nominal_cost=nominal_cost,
        sensor_noise=sensor_noise,
        strategy=calibration["strategy"],
        cost_function=calibration["cost"],
        speeds_rpm=speeds,
        **(
            {}
            if all(point.load is None for point in points)
            else {"operating_points": [point.label for point in points]}
        ),
        seconds=round(time.perf_counter() - start, 1),
        seconds_per_evaluation=float(history["seconds"].mean()),
        failed_evaluations=int((history["error"] != "").sum()),
    )
    log.info(
        "best %s cost %.4g (nominal %.4g) after %d evaluations: %s; sensor noise %.3g",
        best["model_variant"],
        best["cost"],
        nominal_cost,
        best["evaluations"],
        best["parameters"],
        sensor_noise,
    )
    return result, history, pd.concat(rows, ignore_index=True)


# -- per-state calibration (calibration.per_state) -------------------------------------------
SPECTRUM_FLOOR = 1e-12  # added before the log: a silent band stays finite


def fault_change_cost(simulated_change: np.ndarray, measured_change: np.ndarray) -> float:
    """Mean squared difference (in decades, over speeds, channels and bands) of two changes of a
    spectrum, each a fault state's mean RMS band spectrum over its healthy one: what the fault
    adds, compared where the transfer path and background (in both) cancel."""
    return float(np.mean((np.log10(simulated_change) - np.log10(measured_change)) ** 2))


def change_fit(simulated_change: np.ndarray, measured_change: np.ndarray) -> dict:
    """How far a fault model's change of the spectrum explains the measured one:
    - `no_change_cost`: `fault_change_cost` of a model that changes nothing (the fault adds no line);
    - `explained_share`: 1 - cost / no_change_cost; at or below 0 the model fits no better than no
      fault at all;
    - `change_correlation`: correlation of the two log changes over speeds, channels and bands.
    The records identify the state's model (`identified`) when that correlation is one chance
    would not give two unrelated changes: above 3 / sqrt(values), about 3 standard deviations. A
    model of the measured change's form can still explain less than none of it (its other lines
    vary with the manufacturing errors, which the records' machine and the model's draw do not share)."""
    no_change = fault_change_cost(np.ones_like(measured_change), measured_change)
    cost = fault_change_cost(simulated_change, measured_change)
    simulated, measured = np.log10(simulated_change).ravel(), np.log10(measured_change).ravel()
    flat = np.std(simulated) == 0 or np.std(measured) == 0
    correlation = 0.0 if flat else float(np.corrcoef(simulated, measured)[0, 1])
    explained = 1.0 - cost / no_change if no_change > 0 else 0.0
    return {
        "no_change_cost": no_change,
        "explained_share": explained,
        "change_correlation": correlation,
        "identified": bool(correlation > 3.0 / math.sqrt(measured.size)),
    }


class StateSpectrumModel(SpectrumModel):
    """For one fault `state` and a candidate (variant, severities): its mean spectra over those of
    its healthy twin (the same seed: the same manufacturing scatter and fluctuations), per
    operating point. The model runs at the healthy calibration `calibrated` (params.json)."""

    def __init__(
        self,
        system,
        state,
        calibrated,
        points,
        channels,
        spectrum,
        resolution_hz,
        sim_seconds,
        seed=1,
    ):
        super().__init__(system, points, channels, spectrum, resolution_hz, sim_seconds, seed)
        self.state, self.calibrated = state, calibrated
        self.healthy = self._spectra(system.healthy_state, None)

    def _spectra(self, state, state_model) -> np.ndarray:
        return (
            self.mean_spectra(
                [
                    self.system.simulate_state(
                        dict(
                            self.calibrated,
                            parameters=self.system.at_load(
                                self.calibrated["parameters"], point.load
                            ),
                        ),
                        state,
                        state_model,
                        point.speed_rpm,
                        self.sim_seconds,
                        self.seed,
                    )
                    for point in self.points
                ]
            )
            + SPECTRUM_FLOOR
        )

    def __call__(self, variant: str, values: dict) -> np.ndarray:
        return self._spectra(self.state, {"variant": variant, "parameters": values}) / self.healthy


def calibrate_state(
    system,
    frame: pd.DataFrame,
    state: str,
    calibrated: dict,
    calibration: dict,
    spectrum: dict,
    channels,
    processes: int = 1,
):
    """Per-state calibration (the CFRP study's "optimal damaged MBD models"): CMA-ES over the
    fault's form and severities (`System.state_calibration_space`) so that the model's change of
    the spectrum from healthy to `state` matches the measured one, `frame` holding the calibration
    set: the state's calibration records and the healthy ones (`fault_change_cost`). The healthy
    model stays as calibrated. Returns (result, history) as `calibrate_on_spectra`."""
    start = time.perf_counter()
    settings = calibration["per_state"]
    fs = system.output_rate_hz
    at = {label: system.measured_points(frame, label) for label in (state, system.healthy_state)}
    points = [point for point in at[state] if point in at[system.healthy_state]]
    if not points:
        raise ValueError(
            f"calibration.per_state: no operating point of "
            f"{[point.describe() for point in system.operating_points]} has both calibration "
            f"records of {state!r} ({[p.describe() for p in at[state]]}) and healthy ones "
            f"({[p.describe() for p in at[system.healthy_state]]})"
        )
    resolution = calibration["resolution_hz"]
    target = (
        measured_spectra(frame, points, channels, spectrum, resolution, fs, label=state)
        + SPECTRUM_FLOOR
    ) / (
        measured_spectra(
            frame, points, channels, spectrum, resolution, fs, label=system.healthy_state
        )
        + SPECTRUM_FLOOR
    )
    variants, bounds = system.state_calibration_space(state)
    model = StateSpectrumModel(
        system,
        state,
        calibrated,
        points,
        channels,
        spectrum,
        resolution,
        calibration["sim_seconds"],
        seed=calibration["seed"],
    )
    calibrator = Calibrator(
        bounds,
        variants,
        strategy="catcma",
        population=settings["population"],
        generations=settings["generations"],
        sigma0=calibration["sigma0"],
        seed=calibration["seed"],
        processes=processes,
    )
    log.info(
        "calibrating the %s model (%s; %s) at %s, %d processes",
        state,
        variants,
        [b.name for b in bounds],
        [point.describe() for point in points],
        processes,
    )
    best, history = calibrator.run(model, target, fault_change_cost)
    records = sorted(frame.loc[frame["health_state"] == state, "record_id"].astype(str).unique())
    parameters = system.state_parameters(best["model_variant"], best["parameters"])
    # the same seed: the best candidate's change again, to say how much of the measured one it explains
    fit = change_fit(model(best["model_variant"], best["parameters"]), target)
    at_bounds = sorted(
        b.name
        for b in bounds
        if b.name in parameters  # the chosen variant's only
        and not 0.01 < b.to_unit(best["parameters"][b.name]) < 0.99
    )
    result = dict(
        state=state,
        model_variant=best["model_variant"],
        parameters=parameters,
        cost=best["cost"],
        cost_function="fault_change_cost (decades^2)",
        spread=float(settings["spread"]),
        speeds_rpm=sorted({point.speed_rpm for point in points}),
        **(
            {}
            if all(point.load is None for point in points)
            else {"operating_points": [point.label for point in points]}
        ),
        records=records,
        evaluations=best["evaluations"],
        bounds={b.name: [b.low, b.high] for b in bounds},
        **fit,
        at_bounds=at_bounds,
        seconds=round(time.perf_counter() - start, 1),
    )
    log.info(
        "%s: %s %s, cost %.4g after %d evaluations (records %s); no fault: %.4g, explained share %.2f, "
        "correlation %.2f",
        state,
        best["model_variant"],
        parameters,
        best["cost"],
        best["evaluations"],
        records,
        fit["no_change_cost"],
        fit["explained_share"],
        fit["change_correlation"],
    )
    if not fit["identified"]:
        bound_note = f" ({', '.join(at_bounds)} at a bound of its range)" if at_bounds else ""
        result["warning"] = (
            f"the {state} model's change of the spectrum is not its records' (correlation "
            f"{fit['change_correlation']:.2f}, it explains {fit['explained_share']:.0%} of it): the records do "
            f"not identify its severities, the search settles where the model changes least{bound_note}; "
            "its simulated samples take them all the same"
        )
        log.warning("%s", result["warning"])
    return result, history


# Worker state for the process pool (set once per process; fork copies it).
_WORKER = {}


def _init_worker(spectrum_model, target, cost):
    # fork copies the script's SIGTERM handler (SystemExit for cleanup); a worker writes no file,
    # and stopping the pool relies on SIGTERM ending a worker at once, even while it waits on a lock
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _WORKER.update(model=spectrum_model, target=target, cost=cost)


def _evaluate(task):
    variant, values = task
    start = time.perf_counter()
    try:
        cost = float(_WORKER["cost"](_WORKER["model"](variant, values), _WORKER["target"]))
        error = ""
    except SimulationError as exc:
        cost, error = FAILED_COST, str(exc)
    return cost, error, time.perf_counter() - start


class Calibrator:
    """CMA-ES over the unit cube of the bounded parameters (log scale where configured) and the
    categorical model `variants` (a system's model_variants)."""

    def __init__(
        self,
        bounds: list[Bound],
        variants,
        strategy="catcma",
        population=8,
        generations=10,
        sigma0=0.3,
        seed=1,
        processes=1,
        initial=None,
    ):
        if strategy not in ("catcma", "per_law"):
            raise ValueError(f"unknown calibration strategy {strategy!r}; choose catcma or per_law")
        self.bounds, self.variants = bounds, list(variants)
        self.strategy, self.population, self.generations = strategy, population, generations
        self.sigma0, self.seed, self.processes = sigma0, seed, processes
        self.initial = initial or {}

    def _values(self, z) -> dict:
        return {b.name: b.from_unit(float(zi)) for b, zi in zip(self.bounds, z)}

    def _mean0(self) -> np.ndarray:
        return np.array(
            [
                b.to_unit(self.initial[b.name]) if b.name in self.initial else 0.5
                for b in self.bounds
            ]
        )

    def run(self, spectrum_model, target, cost="cfrp_eq4"):
        """Returns (best dict, history DataFrame). `cost`: a name of `SPECTRAL_COSTS` or a
        callable (simulated, measured) -> float (a system's own)."""
        cost = cost_function(cost)
        history = []
        unit_bounds = np.tile([0.0, 1.0], (len(self.bounds), 1))
        # an executor, not multiprocessing.Pool: a worker that dies breaks it with an error
        # instead of leaving its task unanswered for ever
        pool = ProcessPoolExecutor(
            self.processes,
            mp_context=multiprocessing.get_context("fork"),
            initializer=_init_worker,
            initargs=(spectrum_model, target, cost),
        )
        try:

            def evaluate(generation, candidates):
                tasks = [(variant, self._values(z)) for variant, z in candidates]
                try:
                    results = list(pool.map(_evaluate, tasks))
                except BrokenProcessPool as exc:
                    raise RuntimeError(
                        f"calibration generation {generation}: a worker process died "
                        f"while evaluating {len(tasks)} candidates ({exc})"
                    ) from None
                for (variant, values), (cost, error, seconds) in zip(tasks, results):
                    history.append(
                        dict(
                            generation=generation,
                            evaluation=len(history),
                            model_variant=variant,
                            cost=cost,
                            seconds=seconds,
                            error=error,
                            **values,
                        )
                    )
                return [r[0] for r in results]

            started = time.perf_counter()

            def progress(done, total, costs, variant=None):
                best = min(h["cost"] for h in history)
                left = (time.perf_counter() - started) / done * (total - done)
                log.info(
                    "%sgeneration %d of %d: best %.4g (so far %.4g), %d evaluations, about %.0f s left",
                    f"{variant} " if variant else "",
                    done,
                    total,
                    min(costs),
                    best,
                    len(history),
                    left,
                )

            if self.strategy == "catcma" and len(self.variants) > 1:
                optimizer = CatCMA(
                    mean=self._mean0(),
                    sigma=self.sigma0,
                    cat_num=np.array([len(self.variants)]),
                    bounds=unit_bounds,
                    seed=self.seed,
                    population_size=self.population,
                )
                for generation in range(self.generations):
                    asked = [optimizer.ask() for _ in range(optimizer.population_size)]
                    candidates = [(self.variants[int(np.argmax(c[0]))], x) for x, c in asked]
                    costs = evaluate(generation, candidates)
                    optimizer.tell([(a, cost) for a, cost in zip(asked, costs)])
                    progress(generation + 1, self.generations, costs)
            else:
                for variant_index, variant in enumerate(self.variants):
                    optimizer = CMA(
                        mean=self._mean0(),
                        sigma=self.sigma0,
                        bounds=unit_bounds,
                        seed=self.seed + variant_index,
                        population_size=self.population,
                    )
                    for generation in range(self.generations):
                        asked = [optimizer.ask() for _ in range(optimizer.population_size)]
                        costs = evaluate(generation, [(variant, x) for x in asked])
                        optimizer.tell(list(zip(asked, costs)))
                        progress(
                            variant_index * self.generations + generation + 1,
                            len(self.variants) * self.generations,
                            costs,
                            variant,
                        )
        finally:
            # after an error or SIGTERM only the evaluations already running finish
            pool.shutdown(wait=True, cancel_futures=True)
        frame = pd.DataFrame(history)
        best = frame.loc[frame["cost"].idxmin()]
        if best["cost"] >= FAILED_COST:
            raise SimulationError(
                "calibration: every candidate simulation failed; first error: "
                + frame["error"].iloc[0]
            )
        return {
            "model_variant": best["model_variant"],
            "cost": float(best["cost"]),
            "parameters": {b.name: float(best[b.name]) for b in self.bounds},
            "evaluations": len(frame),
        }, frame

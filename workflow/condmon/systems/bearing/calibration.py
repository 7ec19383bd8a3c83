"""Calibration of the bearing rig (`condmon.models.bearing.rig`) on the measured healthy records.

CMA-ES (`condmon.calibrate.Calibrator`, one model variant: Hertz contacts) tunes the `calibration.parameters`
of the rig (contact stiffness, clearance, damping, the transfer path's resonance scales, gain,
noise) so the simulated healthy drive-end signal matches the measured one, by either cost:
- a spectral cost (`cfrp_eq4`, `helical_eq14`: RMS band spectra, as on the gear rig), or
- `features_eq6`, the bearing study's feature cost (eq. 6: ||sf - mf||^2 between simulated and
  measured features), here with each feature relative to its measured value so that features
  of different units weigh alike: sum_i ((sf_i - mf_i) / mf_i)^2 over `CALIBRATION_FEATURES`.
Only healthy records calibrate: the defect parameters stay under domain randomisation, since
the user has no record of the faults the model must produce. A folder without a healthy record
keeps the nominal parameters, and the result says so.
"""

from __future__ import annotations

import logging
import time

import numpy as np
import pandas as pd

from condmon.calibrate import SPECTRAL_COSTS, Bound, Calibrator, SpectrumModel, measured_spectra
from condmon.systems.bearing.model import CHANNEL
from condmon.signals import to_arrays
from condmon.stat_features import StatisticalFeatures

log = logging.getLogger(__name__)

# Dimension-bearing statistics of the healthy signal: level, shape and spectral balance.
CALIBRATION_FEATURES = (
    "rms",
    "kurtosis",
    "crest_factor",
    "shape_factor",
    "mean_frequency",
    "frequency_centre",
    "std_frequency",
)


def features_eq6(simulated: np.ndarray, measured: np.ndarray) -> float:
    """The bearing study's eq. 6 on feature vectors (not spectra), each feature relative to its
    measured value so that features of different units weigh alike."""
    return float(np.mean((((simulated - measured) / np.abs(measured)) ** 2).sum(-1)))


# the costs this system's calibration offers (`BearingSystem.calibration_costs`)
COSTS = {**SPECTRAL_COSTS, "features_eq6": features_eq6}


class RigFeatureModel(SpectrumModel):
    """Mean `CALIBRATION_FEATURES` of the simulated healthy segments per speed, shape
    (n_speeds, 1, n_features): what `features_eq6` compares."""

    def mean_spectra(self, signals_by_speed) -> np.ndarray:
        return np.stack(
            [
                segment_features(signals[CHANNEL], self.segment_length, self.output_rate)
                .mean(0)
                .reshape(1, -1)
                for signals in signals_by_speed
            ]
        )


def segment_features(signal, segment_length: int, fs_hz: float) -> np.ndarray:
    """CALIBRATION_FEATURES of every whole segment of one signal (n_segments, n_features)."""
    n = len(signal) // segment_length
    segments = np.asarray(signal[: n * segment_length], dtype=float).reshape(n, segment_length)
    extractor = StatisticalFeatures(fs_hz=fs_hz, envelope=False)
    names = list(extractor.get_feature_names_out())
    return extractor.fit_transform(segments)[:, [names.index(f) for f in CALIBRATION_FEATURES]]


def measured_features(
    frame: pd.DataFrame, speeds, fs_hz: float, label: str, tolerance_rpm: float = 5.0
):
    """Mean CALIBRATION_FEATURES of the measured healthy (`label`) segments near each speed."""
    out = []
    for speed in speeds:
        rows = frame[
            (frame["health_state"] == label)
            & ((frame["speed_rpm"] - float(speed)).abs() <= tolerance_rpm)
        ]
        _, arrays = to_arrays(rows, [CHANNEL])
        values = np.concatenate(
            [segment_features(x, arrays.shape[-1], fs_hz) for x in arrays[:, 0]]
        )
        out.append(values.mean(0).reshape(1, -1))
    return np.stack(out)


def healthy_speeds(frame: pd.DataFrame, label: str, tolerance_rpm: float = 5.0) -> list[float]:
    """One calibration speed per group of healthy (`label`) records within `tolerance_rpm` of each
    other."""
    speeds = []
    for speed in sorted(frame.loc[frame["health_state"] == label, "speed_rpm"].unique()):
        if not speeds or speed - speeds[-1] > tolerance_rpm:
            speeds.append(float(speed))
    return speeds


def calibrate_rig(
    system,
    frame: pd.DataFrame,
    calibration: dict,
    spectrum: dict,
    processes: int = 1,
    fallback_speeds=(1797.0,),
):
    """Calibrate the rig of `system` (a BearingSystem) on the healthy records of a measured
    signal table.

    Returns (result dict for params.json, history frame, spectra frame with speed_rpm, channel,
    freq_hz, measured, calibrated, model_only). Without a healthy record: the nominal
    parameters, `calibrated: false` and the reason; the spectra then show the nominal model at
    `fallback_speeds` with no measured line."""
    start = time.perf_counter()
    cost_kind, variant = calibration["cost"], system.nominal_variant
    if cost_kind not in COSTS:
        raise ValueError(
            f"calibration.cost: {cost_kind!r} is not a cost of the bearing rig; "
            f"choose one of {list(COSTS)}"
        )
    model = system.model
    unknown = sorted(set(calibration["parameters"]) - set(model))
    if unknown:
        raise ValueError(
            f"calibration.parameters: {unknown} are not bearing.model parameters "
            f"(choose among {sorted(model)})"
        )
    bounds = [
        Bound(name, b["low"], b["high"], b.get("log", False))
        for name, b in calibration["parameters"].items()
    ]
    nominal = {b.name: float(model[b.name]) for b in bounds}
    fs, healthy = system.output_rate_hz, system.healthy_state
    speeds = healthy_speeds(frame, healthy)
    spectrum_args = dict(
        channels=[CHANNEL],
        spectrum=spectrum,
        resolution_hz=calibration["resolution_hz"],
        sim_seconds=calibration["sim_seconds"],
        seed=calibration["seed"],
    )
    plot_model = SpectrumModel(system, speeds or list(fallback_speeds), **spectrum_args)
    freqs = plot_model.spectrum.band_centres()
    if not speeds:
        log.warning("no measured %r record: the rig keeps its nominal parameters", healthy)
        model_only = plot_model(variant, nominal)
        result = dict(
            model_variant=variant,
            parameters=nominal,
            cost=None,
            nominal_cost=None,
            evaluations=0,
            calibrated=False,
            reason=f"no measured {healthy!r} record to calibrate on",
            cost_function=cost_kind,
            speeds_rpm=[],
            sensor_noise=0.0,
            seconds=round(time.perf_counter() - start, 1),
        )
        history = pd.DataFrame(
            [
                dict(
                    generation=0,
                    evaluation=0,
                    model_variant=variant,
                    cost=np.nan,
                    seconds=0.0,
                    error="not calibrated",
                    **nominal,
                )
            ]
        )
        return result, history, _spectra_frame(list(fallback_speeds), freqs, None, model_only)

    measured = measured_spectra(
        frame,
        speeds,
        [CHANNEL],
        spectrum,
        calibration["resolution_hz"],
        fs,
        label=healthy,
        tolerance_rpm=5.0,
    )
    if cost_kind == "features_eq6":
        evaluated = RigFeatureModel(system, speeds, **spectrum_args)
        target = measured_features(frame, speeds, fs, healthy)
    else:
        evaluated, target = plot_model, measured
    calibrator = Calibrator(
        bounds,
        [variant],
        strategy="per_law",
        population=calibration["population"],
        generations=calibration["generations"],
        sigma0=calibration["sigma0"],
        seed=calibration["seed"],
        processes=processes,
        initial=nominal,
    )
    log.info(
        "calibrating the rig (%s) on healthy speeds %s: %s",
        cost_kind,
        speeds,
        [b.name for b in bounds],
    )
    cost = COSTS[cost_kind]
    best, history = calibrator.run(evaluated, target, cost)
    nominal_cost = cost(evaluated(variant, nominal), target)
    calibrated_spectra = plot_model(variant, best["parameters"])
    result = dict(
        best,
        nominal_cost=nominal_cost,
        calibrated=True,
        cost_function=cost_kind,
        speeds_rpm=speeds,
        sensor_noise=0.0,
        strategy="per_law",
        seconds=round(time.perf_counter() - start, 1),
        seconds_per_evaluation=float(history["seconds"].mean()),
        failed_evaluations=int((history["error"] != "").sum()),
    )
    return result, history, _spectra_frame(speeds, freqs, measured, calibrated_spectra)


def _spectra_frame(speeds, freqs, measured, calibrated) -> pd.DataFrame:
    rows = []
    for i, speed in enumerate(speeds):
        rows.append(
            pd.DataFrame(
                dict(
                    speed_rpm=speed,
                    channel=CHANNEL,
                    freq_hz=freqs,
                    measured=np.nan if measured is None else measured[i, 0],
                    calibrated=calibrated[i, 0],
                    model_only=calibrated[i, 0],
                )
            )
        )
    return pd.concat(rows, ignore_index=True)

"""Bridge between the `bearing` config section and the pure bearing-rig model
(`models/bearing_rig.py`): CWRU labels to defects, domain randomisation, simulation batches in the
signal-table format, and the calibration spectrum model.

The `bearing` config section (defaults in `DEFAULT_BEARING`):
- `model`: nominal values of `BearingRigParameters` fields (scalars; `resonances` and `background`
  as lists of [frequency Hz, damping ratio, gain (m/s^2 per N) / rms (m/s^2)]), plus the
  calibration scales `resonance_frequency_scale`, `resonance_damping_scale`, `resonance_gain_scale`,
  `background_level_scale` (1 = as listed);
- `randomisation`: what every simulated sample draws (see `randomise`);
- `defect_size_spread`: relative spread of the defect diameter of a fixed-size label.
Calibrated values (`calibrated["parameters"]`) override `model`; the randomisation is applied over
them (absolute ranges) or around them (`relative: true`, a factor on the calibrated value).
"""
from __future__ import annotations

import copy
import dataclasses
import logging
import math
import re
import time

import numpy as np
import pandas as pd

from condmon.seeds import job_rng
from condmon.signals import make_rows, to_arrays
from condmon.simulate import batch_report
from models.bearing_rig import (INCH, BearingRigParameters, RigSettings, SimulationError, simulate_rig)

log = logging.getLogger(__name__)

CHANNEL = "DE"
FS_HZ = 12000.0
NOMINAL_RPM_HP = {0: 1797.0, 1: 1772.0, 2: 1750.0, 3: 1730.0}  # CWRU motor load (HP) -> speed
SIZES_IN = (0.007, 0.014, 0.021)
_FIELDS = {f.name for f in dataclasses.fields(BearingRigParameters)} - {"de_geometry", "fe_geometry"}
SCALES = ("resonance_frequency_scale", "resonance_damping_scale", "resonance_gain_scale",
          "background_level_scale")

# The `bearing` config section's defaults (documented in config/README.md).
DEFAULT_BEARING = {
    "model": {
        "rotor_mass": 8.0, "de_mass_share": 0.5, "shaft_stiffness": 5.0e7, "shaft_damping_ratio": 0.02,
        "gravity": 9.81, "radial_load": 0.0, "unbalance": 2.0e-5,
        "contact_stiffness": 8.0e9, "radial_clearance": 5.0e-6, "bearing_damping": 300.0,
        "housing_mass": 3.0, "housing_stiffness": 1.5e8, "housing_damping_ratio": 0.05,
        "defect_depth": 0.011 * INCH, "defect_drop_scale": 1.0, "defect_clock": 6.0, "defect_entry": 0.3, "defect_exit": 0.1,
        "defect_depth_variation": 0.2, "defect_strike_probability": 1.0, "slip_std": 0.01,
        "defect_roughness": 0.0, "defect_roughness_modulation": 0.5,
        "resonances": [[2900.0, 0.04, 0.6], [3400.0, 0.03, 1.0], [3700.0, 0.04, 0.5]],
        "housing_path_gain": 1.0, "sensor_gain": 1.0, "noise_rms": 0.3,
        "background": [[4150.0, 0.01, 0.45], [650.0, 0.15, 0.25]],
        "resonance_frequency_scale": 1.0, "resonance_damping_scale": 1.0, "resonance_gain_scale": 1.0,
        "background_level_scale": 1.0,
    },
    "defect_size_spread": 0.1,
    "randomisation": {
        "sensor_gain": {"low": 0.5, "high": 2.0, "log": True, "relative": True},
        "noise_rms": {"low": 0.3, "high": 3.0, "log": True, "relative": True},
        "radial_load": {"low": 0.0, "high": 150.0},
        "radial_clearance": {"low": 0.3, "high": 2.0, "log": True, "relative": True},
        "slip_std": {"low": 0.005, "high": 0.03},
        "defect_entry": {"low": 0.1, "high": 1.0},
        "defect_exit": {"low": 0.05, "high": 1.0},
        "defect_depth_variation": {"low": 0.0, "high": 0.6},
        "defect_drop_scale": {"low": 0.3, "high": 1.5, "log": True},
        "ball_defect_strike_probability": {"low": 0.05, "high": 0.6},
        "defect_roughness": {"low": 0.2, "high": 5.0, "log": True},
        "ball_defect_roughness": {"low": 1.0, "high": 30.0, "log": True},
        "defect_roughness_modulation": {"low": 0.0, "high": 1.0},
        "ball_defect_roughness_modulation": {"low": 0.0, "high": 0.3},
        "ball_drop_scale": {"low": 0.05, "high": 0.5, "log": True},
        "defect_phase": {"low": 0.0, "high": 6.283185307179586},
        "resonances": {"count": [2, 4], "frequency_hz": [2000.0, 5000.0], "damping_ratio": [0.01, 0.08],
                       "gain": [0.03, 0.6]},
        "background": {"count": [1, 4], "frequency_hz": [100.0, 5500.0], "damping_ratio": [0.005, 0.2],
                       "rms": [0.05, 1.0]},
    },
}


# -- labels ---------------------------------------------------------------------------------------
def defect_of_label(label: str) -> tuple[str, tuple[float, float]]:
    """(defect kind, (low, high) defect diameter in inches) of a CWRU task label
    (`condmon.cwru.task_labels`): `normal` -> ("none", (0, 0)); a location label (`inner_race`,
    `ball`, `outer_race`) pools the sizes, (0.007, 0.021); `<kind>_<size>in` is that size."""
    if label == "normal":
        return "none", (0.0, 0.0)
    if label in ("inner_race", "ball", "outer_race"):
        return label, (SIZES_IN[0], SIZES_IN[-1])
    match = re.fullmatch(r"(inner_race|ball|outer_race)_(\d+\.\d+)in", str(label))
    if match and float(match.group(2)) > 0:
        size = float(match.group(2))
        return match.group(1), (size, size)
    raise ValueError(f"unknown bearing health label {label!r}: use normal, inner_race, ball, outer_race or "
                     f"<inner_race|ball|outer_race>_<size>in (e.g. outer_race_0.007in)")


def load_of_speed(speed_rpm: float) -> float:
    """The `load` column of simulated rows: the CWRU motor load (HP) whose nominal speed is nearest
    the simulated speed (the model has no torque; this keeps simulated and measured rows on one
    operating-condition axis for `hybrid.condition: load`)."""
    return float(min(NOMINAL_RPM_HP, key=lambda hp: abs(NOMINAL_RPM_HP[hp] - float(speed_rpm))))


# -- parameters ------------------------------------------------------------------------------------
def _merged_model(model: dict) -> dict:
    merged = copy.deepcopy(DEFAULT_BEARING["model"])
    merged.update(copy.deepcopy(model or {}))
    return merged


def build_rig_parameters(model: dict, health_state: str, speed_rpm: float, **overrides) -> BearingRigParameters:
    """BearingRigParameters from a `bearing.model` section (missing keys take DEFAULT_BEARING's),
    the health label (defect kind; a pooled or fixed size's mid diameter unless `defect_width` or
    `defect_diameter_in` is overridden), the speed and overrides (calibrated or drawn values).

    Extra keys besides the model fields: the four calibration scales (`SCALES`),
    `defect_diameter_in` (defect width in inches), and for ball labels only (ignored otherwise):
    `ball_<field>` replaces `<field>` (e.g. `ball_defect_strike_probability`: the spin axis of a
    real ball wanders, so its defect meets the races on a fraction of the turns;
    `ball_defect_roughness`), and `ball_drop_scale` multiplies `defect_drop_scale` (a pit on the
    ball meets the race obliquely and rarely in the middle of the rolling track, so it releases
    less contact deflection than a race pit)."""
    values = _merged_model(model)
    values.update(overrides)
    kind, (low, high) = defect_of_label(health_state)
    diameter = values.pop("defect_diameter_in", 0.5 * (low + high))
    ball_drop = float(values.pop("ball_drop_scale", 1.0))
    ball_only = {k[len("ball_"):]: values.pop(k) for k in list(values) if k.startswith("ball_")}
    scales = {name: float(values.pop(name, 1.0)) for name in SCALES}
    unknown = sorted((set(values) | set(ball_only)) - _FIELDS)
    if unknown:
        raise ValueError(f"unknown bearing model parameters {unknown}; choose among {sorted(_FIELDS | set(SCALES))}")
    values["resonances"] = tuple((float(f) * scales["resonance_frequency_scale"],
                                  min(float(z) * scales["resonance_damping_scale"], 0.9),
                                  float(g) * scales["resonance_gain_scale"]) for f, z, g in values["resonances"])
    values["background"] = tuple((float(f), float(z), float(r) * scales["background_level_scale"])
                                 for f, z, r in values["background"])
    if kind != "none":
        values.setdefault("defect_width", float(diameter) * INCH)
        if kind == "ball":
            values.update(ball_only)
            values["defect_drop_scale"] = float(values.get("defect_drop_scale", 1.0)) * ball_drop
    return BearingRigParameters(speed_rpm=float(speed_rpm), defect_kind=kind, **values)


def _draw(spec, rng: np.random.Generator) -> float:
    low, high = float(spec["low"]), float(spec["high"])
    if high < low:
        raise ValueError(f"randomisation range {spec}: high < low")
    if spec.get("log", False):
        if low <= 0:
            raise ValueError(f"randomisation range {spec}: log needs low > 0")
        return float(math.exp(rng.uniform(math.log(low), math.log(high))))
    return float(rng.uniform(low, high))


def _draw_modes(spec: dict, level_key: str, rng) -> list:
    count = int(rng.integers(int(spec["count"][0]), int(spec["count"][1]) + 1))
    modes = []
    for _ in range(count):
        f = rng.uniform(*map(float, spec["frequency_hz"]))
        z = math.exp(rng.uniform(*np.log(np.asarray(spec["damping_ratio"], dtype=float))))
        g = math.exp(rng.uniform(*np.log(np.asarray(spec[level_key], dtype=float))))
        modes.append([round(float(f), 3), float(z), float(g)])
    return modes


def randomise(randomisation: dict, rng: np.random.Generator, base: dict | None = None) -> dict:
    """One draw of the domain randomisation: {parameter: value}.

    Scalar entries `{low, high, log: false, relative: false}`: uniform (log-uniform with `log`)
    over [low, high]; with `relative` the draw is a factor on `base[name]` (the calibrated or
    nominal value). `resonances` and `background` entries `{count: [lo, hi], frequency_hz: [lo, hi],
    damping_ratio: [lo, hi], gain|rms: [lo, hi]}` draw a new list of modes (count uniform integer,
    frequency uniform, damping and gain/rms log-uniform). Keys are drawn in sorted order so the
    stream does not depend on the config's key order."""
    base = _merged_model(base or {})
    out = {}
    for name in sorted(randomisation or {}):
        spec = randomisation[name]
        if name == "resonances":
            out[name] = _draw_modes(spec, "gain", rng)
        elif name == "background":
            out[name] = _draw_modes(spec, "rms", rng)
        else:
            value = _draw(spec, rng)
            if spec.get("relative", False):
                if name not in base:
                    raise ValueError(f"randomisation {name!r} is relative but has no base value")
                value *= float(base[name])
            out[name] = value
    return out


def draw_defect_diameter(health_state: str, spread: float, rng: np.random.Generator) -> float | None:
    """Defect diameter (in) of one sample: uniform over a pooled label's sizes, or a fixed size
    times a uniform factor 1 +/- spread. None for `normal`."""
    kind, (low, high) = defect_of_label(health_state)
    if kind == "none":
        return None
    if high > low:
        return float(rng.uniform(low, high))
    return float(low * rng.uniform(1 - spread, 1 + spread))


def rig_settings(numerics: dict | None, duration: float) -> RigSettings:
    numerics = dict(numerics or {})
    unknown = sorted(set(numerics) - {f.name for f in dataclasses.fields(RigSettings)})
    if unknown:
        raise ValueError(f"unknown bearing numerics {unknown}")
    return RigSettings(duration=duration, **numerics)


# -- simulation batch --------------------------------------------------------------------------
def simulate_with_retry(params: BearingRigParameters, settings: RigSettings, rng_seed: int):
    """Run the rig; if it fails, retry once with half the time step. Returns (signals or None,
    errors). Both attempts use the same random stream (same seed)."""
    errors = []
    for attempt in (settings, dataclasses.replace(settings,
                                                  steps_per_sensor_sample=2 * settings.steps_per_sensor_sample)):
        try:
            return simulate_rig(params, attempt, np.random.default_rng(rng_seed)), errors
        except SimulationError as exc:
            rate = attempt.output_rate_hz * attempt.oversampling * attempt.steps_per_sensor_sample
            errors.append(f"h = 1/{rate:g} s: {exc}")
    return None, errors


def sample_values(bearing: dict, calibrated: dict | None, health_state: str, rng) -> dict:
    """The drawn values of one sample (everything that differs from `bearing.model`)."""
    base = {**(bearing.get("model") or {}), **((calibrated or {}).get("parameters") or {})}
    spec = bearing.get("randomisation", DEFAULT_BEARING["randomisation"])
    values = dict((calibrated or {}).get("parameters") or {})
    values.update(randomise(spec, rng, base))
    diameter = draw_defect_diameter(health_state, float(bearing.get("defect_size_spread", 0.1)), rng)
    if diameter is not None:
        values["defect_diameter_in"] = diameter
    return values


def simulate_bearing_batch(model: dict, calibrated: dict | None, health_state: str, speed_rpm: float, batch: int,
                           samples: int, numerics: dict | None, segment_length: int, segments_per_sample: int,
                           seed: int, max_failed_share: float = 0.0):
    """Signal-table rows for `samples` randomised rig runs of one (health label, speed, batch) and
    a report, as `condmon.simulate.simulate_batch` (same report keys).

    `model` is the whole `bearing` config section (`model`, `randomisation`,
    `defect_size_spread`); `calibrated` a calibration result ({"parameters": {...}}) or None.
    Every sample draws its randomisation, defect size and a run seed from the job's stream
    (seed, "simulate", health, speed, batch); channel `DE`, 12 kHz, `load` = `load_of_speed`,
    `params` the JSON of the drawn values. A sample failing twice is left out and reported; more
    than `max_failed_share` of the batch failing raises TooManyFailures."""
    bearing = model if "model" in model or "randomisation" in model else {"model": model}
    rng = job_rng(seed, "simulate", health_state, float(speed_rpm), batch)
    fs = float((numerics or {}).get("output_rate_hz", FS_HZ))
    settings = rig_settings(numerics, duration=segment_length * segments_per_sample / fs)
    rows, failures, seconds = [], [], []
    for i in range(samples):
        values = sample_values(bearing, calibrated, health_state, rng)
        run_seed = int(rng.integers(2 ** 32))  # drawn for every sample, failed or not: streams stay aligned
        record_id = f"sim-{health_state}-{speed_rpm:g}rpm-b{batch:03d}-s{i:03d}"
        start = time.perf_counter()
        try:
            params = build_rig_parameters(bearing.get("model") or {}, health_state, float(speed_rpm), **values)
            signals, errors = simulate_with_retry(params, settings, run_seed)
        except ValueError as exc:  # a drawn value outside the model's domain
            signals, errors = None, [f"invalid parameters: {exc}"]
        seconds.append(time.perf_counter() - start)
        for error in errors:
            log.warning("%s: %s", record_id, error)
        if signals is None:
            failures.append({"record_id": record_id, "errors": errors, "params": values})
            continue
        log.info("%s: %.2f s", record_id, seconds[-1])
        rows += make_rows(record_id, "simulated", health_state, speed_rpm, load_of_speed(speed_rpm), fs, signals,
                          segment_length=int(segment_length), params={**values, "run_seed": run_seed})
    report = batch_report(health_state, speed_rpm, batch, samples, failures, seconds,
                          settings.settle_time + settings.duration, max_failed_share,
                          what="bearing simulations")
    return rows, report


# -- calibration --------------------------------------------------------------------------------
def _spectrum_transformer(spectrum: dict, resolution_hz: float):
    from condmon.calibrate import calibration_spectrum
    from condmon.features import SpectrumFeatures
    return SpectrumFeatures(channels=[CHANNEL], **calibration_spectrum(spectrum, resolution_hz))


class RigSpectrumModel:
    """Mean healthy DE spectra of the rig at the calibration speeds for one parameter set, the
    callable `condmon.calibrate.Calibrator` evaluates: __call__(contact_law, values) ->
    (n_speeds, 1, n_bands). The contact law is Hertz (`contact_laws: [hertz]`) and only named.
    Deterministic: every speed runs with a fixed seed; `sim_seconds` keeps it cheap (0.5 s is
    about 0.7 s of CPU per speed)."""

    def __init__(self, model: dict, numerics: dict | None, speeds, spectrum: dict, resolution_hz: float,
                 sim_seconds: float = 0.5, segment_length: int = 4096, seed: int = 1):
        self.model = (model.get("model") or {}) if ("model" in model or "randomisation" in model) else model
        self.speeds = [float(s) for s in speeds]
        self.settings = rig_settings(numerics, duration=sim_seconds)
        self.segment_length = int(segment_length)
        self.seed = int(seed)
        self.spectrum = _spectrum_transformer(spectrum, resolution_hz)
        if int(sim_seconds * self.settings.output_rate_hz) < self.segment_length:
            raise ValueError("sim_seconds is shorter than one segment")

    def mean_spectra(self, signals_by_speed) -> np.ndarray:
        out = []
        for signal in signals_by_speed:
            n_seg = len(signal) // self.segment_length
            stack = signal[:n_seg * self.segment_length].reshape(n_seg, 1, self.segment_length)
            out.append(self.spectrum.transform(stack, self.settings.output_rate_hz).mean(0).reshape(1, -1))
        return np.stack(out)

    def __call__(self, contact_law: str, values: dict) -> np.ndarray:
        if contact_law not in ("hertz",):
            raise ValueError(f"the bearing rig has the Hertz contact only, not {contact_law!r}")
        runs = []
        for speed in self.speeds:
            params = build_rig_parameters(self.model, "normal", speed, **values)
            runs.append(simulate_rig(params, self.settings, job_rng(self.seed, "calibrate", speed))[CHANNEL])
        return self.mean_spectra(runs)


def measured_rig_spectra(frame: pd.DataFrame, speeds, spectrum: dict, resolution_hz: float,
                         fs_hz: float = FS_HZ, label: str = "normal", tolerance_rpm: float = 5.0) -> np.ndarray:
    """Mean amplitude spectra of the measured healthy (`label`) DE segments per speed, (speeds, 1,
    bands): the calibration target. A speed takes the records within `tolerance_rpm` of it (CWRU
    records at one load differ by a few rpm)."""
    transformer = _spectrum_transformer(spectrum, resolution_hz)
    out = []
    for speed in speeds:
        rows = frame[(frame["health_state"] == label) & ((frame["speed_rpm"] - float(speed)).abs() <= tolerance_rpm)]
        if rows.empty:
            raise ValueError(f"no measured {label!r} records within {tolerance_rpm} rpm of {speed} rpm to calibrate on")
        _, arrays = to_arrays(rows, [CHANNEL])
        out.append(transformer.transform(arrays, fs_hz).mean(0).reshape(1, -1))
    return np.stack(out)

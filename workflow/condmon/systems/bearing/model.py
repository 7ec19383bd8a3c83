"""Bridge between the `bearing` config section and the pure bearing-rig model
(`condmon.models.bearing.rig`): labels to defects, domain randomisation, rig parameters.

The `bearing` config section (schema.yaml beside this file holds its defaults, `bearing_defaults()`
reads them):
- `model`: nominal values of `BearingRigParameters` fields (scalars; `resonances` and `background`
  as lists of [frequency Hz, damping ratio, gain (m/s^2 per N) / rms (m/s^2)]), plus the
  calibration scales `resonance_frequency_scale`, `resonance_damping_scale`, `resonance_gain_scale`,
  `background_level_scale` (1 = as listed);
- `randomisation`: what every simulated sample draws (see `randomise`);
- `defect_size_spread`: relative spread of the defect diameter of a fixed-size label;
- `geometry`, `fan_end_geometry`: the two bearings; `health_states`, `healthy_state`: the labels
  and their defects; `load_speeds`: the load of a simulated speed.
Calibrated values (`calibrated["parameters"]`) override `model`; the randomisation is applied over
them (absolute ranges) or around them (`relative: true`, a factor on the calibrated value).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import re
from pathlib import Path

import numpy as np

from condmon.schema import load_schema, schema_defaults
from condmon.models.bearing.rig import INCH, BearingGeometry, BearingRigParameters, RigSettings

CHANNEL = "DE"
SIZES_IN = (0.007, 0.014, 0.021)
_FIELDS = {f.name for f in dataclasses.fields(BearingRigParameters)} - {
    "de_geometry",
    "fe_geometry",
}
SCALES = (
    "resonance_frequency_scale",
    "resonance_damping_scale",
    "resonance_gain_scale",
    "background_level_scale",
)


@functools.cache
def _schema_defaults() -> dict:
    schema = load_schema(Path(__file__).with_name("schema.yaml"))
    return schema_defaults(schema["properties"]["bearing"])


def bearing_defaults() -> dict:
    """The `bearing` section with every default of its schema (a fresh copy)."""
    return copy.deepcopy(_schema_defaults())


# -- labels ---------------------------------------------------------------------------------------
def defect_of_label(label: str, labels: dict | None = None) -> tuple[str, tuple[float, float]]:
    """(defect kind, (low, high) defect diameter in inches) of a health label.

    `labels`: the `bearing.health_states` mapping {label: {defect, diameter_mm: [low, high]}};
    None: the CWRU labels (`condmon.systems.bearing.cwru.task_labels`): `normal` -> ("none",
    (0, 0)); a location label (`inner_race`, `ball`, `outer_race`) pools the sizes, (0.007,
    0.021); `<kind>_<size>in` is that size."""
    if labels is not None:
        if label not in labels:
            raise ValueError(
                f"unknown bearing health label {label!r}; bearing.health_states has {sorted(labels)}"
            )
        spec = labels[label]
        if spec["defect"] == "none":
            return "none", (0.0, 0.0)
        low, high = spec["diameter_mm"]
        return spec["defect"], (low / 25.4, high / 25.4)
    if label == "normal":
        return "none", (0.0, 0.0)
    if label in ("inner_race", "ball", "outer_race"):
        return label, (SIZES_IN[0], SIZES_IN[-1])
    match = re.fullmatch(r"(inner_race|ball|outer_race)_(\d+\.\d+)in", str(label))
    if match and float(match.group(2)) > 0:
        size = float(match.group(2))
        return match.group(1), (size, size)
    raise ValueError(
        f"unknown bearing health label {label!r}: use normal, inner_race, ball, outer_race or "
        f"<inner_race|ball|outer_race>_<size>in (e.g. outer_race_0.007in)"
    )


def load_of_speed(speed_rpm: float, load_speeds) -> float:
    """The `load` column of simulated rows: the load whose nominal speed (`bearing.load_speeds`,
    [load, rpm] pairs) is nearest the simulated speed (the model has no torque; this keeps
    simulated and measured rows on one operating-condition axis for `hybrid.condition: load`)."""
    load, _ = min(load_speeds, key=lambda pair: abs(float(pair[1]) - float(speed_rpm)))
    return float(load)


def geometry(spec: dict) -> BearingGeometry:
    """A BearingGeometry from a `bearing.geometry` entry (lengths in m)."""
    return BearingGeometry(
        int(spec["n_balls"]),
        float(spec["ball_diameter"]),
        float(spec["pitch_diameter"]),
        float(spec.get("contact_angle_deg", 0.0)),
    )


def feature_orders(spec: dict) -> dict:
    """The envelope lines the features measure: BPFO, BPFI, BSF and 2 x BSF of a bearing."""
    orders = geometry(spec).orders()
    return dict(
        bpfo=orders["bpfo"], bpfi=orders["bpfi"], bsf=orders["bsf"], bsf_x2=2 * orders["bsf"]
    )


# -- parameters ------------------------------------------------------------------------------------
def _merged_model(model: dict) -> dict:
    merged = bearing_defaults()["model"]
    merged.update(copy.deepcopy(model or {}))
    return merged


def build_rig_parameters(
    model: dict,
    health_state: str,
    speed_rpm: float,
    labels: dict | None = None,
    geometries: tuple[dict, dict] | None = None,
    **overrides,
) -> BearingRigParameters:
    """BearingRigParameters from a `bearing.model` section (missing keys take the schema's
    defaults), the health label (its defect by `defect_of_label(label, labels)`; a pooled or fixed
    size's mid diameter unless `defect_width` or `defect_diameter_in` is overridden), the speed and
    overrides (calibrated or drawn values).

    Extra keys besides the model fields: the four calibration scales (`SCALES`),
    `defect_diameter_in` (defect width in inches), and for ball labels only (ignored otherwise):
    `ball_<field>` replaces `<field>` (e.g. `ball_defect_roughness`: a ball pit rubbing
    obliquely), and `ball_drop_scale` multiplies `defect_drop_scale` (a pit on the
    ball meets the race obliquely and rarely in the middle of the rolling track, so it releases
    less contact deflection than a race pit)."""
    values = _merged_model(model)
    values.update(overrides)
    kind, (low, high) = defect_of_label(health_state, labels)
    diameter = values.pop("defect_diameter_in", 0.5 * (low + high))
    ball_drop = float(values.pop("ball_drop_scale", 1.0))
    ball_only = {k[len("ball_") :]: values.pop(k) for k in list(values) if k.startswith("ball_")}
    scales = {name: float(values.pop(name, 1.0)) for name in SCALES}
    unknown = sorted((set(values) | set(ball_only)) - _FIELDS)
    if unknown:
        raise ValueError(
            f"unknown bearing model parameters {unknown}; choose among {sorted(_FIELDS | set(SCALES))}"
        )
    values["resonances"] = tuple(
        (
            float(f) * scales["resonance_frequency_scale"],
            min(float(z) * scales["resonance_damping_scale"], 0.9),
            float(g) * scales["resonance_gain_scale"],
            *map(float, tilt),
        )
        for f, z, g, *tilt in values["resonances"]
    )
    values["background"] = tuple(
        (float(f), float(z), float(r) * scales["background_level_scale"])
        for f, z, r in values["background"]
    )
    if kind != "none":
        values.setdefault("defect_width", float(diameter) * INCH)
        if kind == "ball":
            values.update(ball_only)
            values["defect_drop_scale"] = float(values.get("defect_drop_scale", 1.0)) * ball_drop
    if geometries is not None:  # (tested bearing, other bearing) as `bearing.geometry` entries
        values["de_geometry"], values["fe_geometry"] = (geometry(g) for g in geometries)
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
        if "tilt_deg" in spec:  # drawn after the others, so a spec without it draws as before
            modes[-1].append(float(rng.uniform(*map(float, spec["tilt_deg"]))))
    return modes


def randomise(randomisation: dict, rng: np.random.Generator, base: dict | None = None) -> dict:
    """One draw of the domain randomisation: {parameter: value}.

    Scalar entries `{low, high, log: false, relative: false}`: uniform (log-uniform with `log`)
    over [low, high]; with `relative` the draw is a factor on `base[name]` (the calibrated or
    nominal value). `resonances` and `background` entries `{count: [lo, hi], frequency_hz: [lo, hi],
    damping_ratio: [lo, hi], gain|rms: [lo, hi]}` draw a new list of modes (count uniform integer,
    frequency uniform, damping and gain/rms log-uniform; a `resonances` entry with `tilt_deg:
    [lo, hi]` draws each mode's tilt from vertical too, uniform). Keys are drawn in sorted order so the
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


def draw_defect_diameter(
    health_state: str, spread: float, rng: np.random.Generator, labels: dict | None = None
) -> float | None:
    """Defect diameter (in) of one sample: uniform over a pooled label's sizes, or a fixed size
    times a uniform factor 1 +/- spread. None for `normal`."""
    kind, (low, high) = defect_of_label(health_state, labels)
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


# -- one sample's draw ---------------------------------------------------------------------
def sample_values(
    bearing: dict, calibrated: dict | None, health_state: str, rng, labels: dict | None = None
) -> dict:
    """The drawn values of one sample (everything that differs from `bearing.model`)."""
    base = {**(bearing.get("model") or {}), **((calibrated or {}).get("parameters") or {})}
    spec = bearing.get("randomisation", bearing_defaults()["randomisation"])
    values = dict((calibrated or {}).get("parameters") or {})
    values.update(randomise(spec, rng, base))
    diameter = draw_defect_diameter(
        health_state, float(bearing.get("defect_size_spread", 0.1)), rng, labels
    )
    if diameter is not None:
        values["defect_diameter_in"] = diameter
    return values

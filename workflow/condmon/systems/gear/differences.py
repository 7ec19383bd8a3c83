"""Every way the virtual bench differs from the model, and what the pipeline does about each.

A model earns trust only against a bench that differs from it; a user reading the report should
see where, and which of the differences the pipeline can close. Each row says:

- `calibrated`: healthy records tune it (the calibrated parameters and contact law, the background
  that healthy records carry and the model lacks, a fault state's model under per-state
  calibration);
- `randomised`: the simulation draws it per sample over a stated range (gear errors, speed and
  load fluctuation, fault severities); `within_range` says whether the bench's value lies inside
  (the report may say so: the bench's truth is synthetic and never reaches the pipeline's jobs);
- `neither`: the model keeps its own form or value, and the classifier has to live with it;
- `same`: no difference in form: a fault state without a bench form runs the model's own fault
  code at the model's values, so it does not test the model there.

Everything is read from the config: a changed key changes the rows.
"""

from __future__ import annotations

import numpy as np

from condmon.models.gear.drivetrain import stage_parameters
from condmon.models.gear.mesh_force import operating_deflection
from condmon.models.gear.virtual_bench import BenchForm
from condmon.systems.gear.bench import bench_form
from condmon.systems.gear.parameters import (
    COMPLIANCE_PARAMETERS,
    build_parameters,
    deflection_range,
)

CALIBRATED, RANDOMISED, NEITHER, SAME = "calibrated", "randomised", "neither", "same"

# The model's severity ranges (model.fault_severity) each bench fault form is drawn against:
# bench key -> model key, per (bench form, the model's form of the state).
SEVERITY_OF_FORM = {
    ("pitting", "pitting"): {
        "pit_depth": "pit_depth",
        "pitted_area": "pitted_area",
        "teeth": "pitted_teeth",
    },
    ("broken_tooth", "missing_tooth"): {"broken_height": "missing_share"},
    ("spall", "spall"): {"depth": "spall_depth"},
}


def row(difference: str, handled: str, how: str, within_range: bool | None = None) -> dict:
    return {"difference": difference, "handled": handled, "how": how, "within_range": within_range}


def bench_differences(config: dict, health_states, healthy_state: str) -> list[dict]:
    """Rows {difference, handled, how, within_range} for the config's `virtual_bench` against its
    `model`, given the `calibration` section (what it tunes, its background)."""
    model, bench, calibration = config["model"], config["virtual_bench"], config["calibration"]
    rows = _parameter_rows(model, bench, calibration)
    rows += _form_rows(model, bench_form(bench), calibration)
    rows += _fault_rows(model, bench, calibration, health_states, healthy_state)
    return rows


def _differs(a, b) -> bool:
    if isinstance(a, (int, float)) and isinstance(b, (int, float)):
        return not np.isclose(float(a), float(b), rtol=1e-9, atol=0.0)
    return a != b


def _parameter_rows(model: dict, bench: dict, calibration: dict) -> list[dict]:
    rows = []
    searched = calibration["parameters"]
    truth = {**bench.get("model_overrides", {}), **bench["true_parameters"]}
    compliance = model.get("mesh_compliance")
    if compliance and any(
        _differs(truth.get(name, model[name]), model[name]) for name in COMPLIANCE_PARAMETERS
    ):
        rows.append(_compliance_row(model, truth, compliance))
        truth = {name: value for name, value in truth.items() if name not in COMPLIANCE_PARAMETERS}
    for name, value in truth.items():
        nominal = model.get(name)
        if not _differs(value, nominal):
            continue
        text = f"{name} {_number_or_range(value)} (model {_number_or_range(nominal)})"
        if name == "contact_law":
            laws = calibration["contact_laws"]
            rows.append(
                row(text, CALIBRATED, "calibration searches calibration.contact_laws", True)
                if value in laws
                else row(text, NEITHER, f"not among calibration.contact_laws {list(laws)}")
            )
        elif name == "mesh_stiffness_model":
            rows.append(row(text, NEITHER, "the simulation runs model.mesh_stiffness_model"))
        elif name in searched:
            low, high = searched[name]["low"], searched[name]["high"]
            inside = bool(low <= value <= high)
            rows.append(
                row(text, CALIBRATED, f"calibration.parameters range [{low:g}, {high:g}]", inside)
            )
        else:
            rows.append(row(text, NEITHER, "not a calibrated parameter: the model keeps its value"))
    return rows


def _compliance_row(model: dict, truth: dict, compliance: dict) -> dict:
    """The bench's mesh against the drawn mesh compliance: its static deflection under the load."""
    mesh = {name: truth.get(name, model[name]) for name in COMPLIANCE_PARAMETERS}
    rig = build_parameters(model, **mesh)
    # the first pair under its own torque, as the drawn deflection is (a train: the later ratios)
    deflection = operating_deflection(stage_parameters(rig)[0])
    low, high = deflection_range(compliance, rig)
    exponents = compliance["contact_exponent"]
    inside = low <= deflection <= high and exponents[0] <= mesh["contact_exponent"] <= exponents[1]
    calibrated = compliance["deflection"] == "calibrated"
    return row(
        f"mesh_stiffness {mesh['mesh_stiffness']:g} at contact_exponent {mesh['contact_exponent']:g}: a static "
        f"deflection of {deflection * 1e6:.2f} um",
        CALIBRATED if calibrated else RANDOMISED,
        "model.mesh_compliance, drawn per sample: deflection "
        + ("calibrated within " if calibrated else "")
        + f"[{low * 1e6:.3g}, {high * 1e6:.3g}] um, contact_exponent {_number_or_range(exponents)}",
        bool(inside),
    )


def _background_rows(form: BenchForm, calibration: dict) -> list[dict]:
    background, method = calibration["background"], calibration["background_method"]
    estimated = f"the {method} background of the healthy records"
    rows = []
    if form.sensor_noise:
        rows.append(
            row(
                f"white sensor noise {form.sensor_noise:g} m/s^2 rms",
                CALIBRATED,
                estimated
                if background
                else "the sensor noise from the floor of the healthy spectra",
            )
        )
    if form.coloured_noise:
        rows.append(
            row(
                f"coloured sensor noise {form.coloured_noise:g} m/s^2 rms",
                CALIBRATED if background else NEITHER,
                estimated if background else "calibration.background off: white noise only",
            )
        )
    # tones reach every channel through the structure: only the `deficit` background takes them
    tones = [
        (
            form.bearing_tone_force,
            f"rolling-bearing tones ({form.bearing_tone_force:g} N at orders "
            f"{', '.join(f'{o:g}' for o in form.bearing_orders)} of each shaft)",
        ),
        (
            form.motor_ripple,
            f"motor torque ripple ({form.motor_ripple:g} N m at {2 * form.line_frequency_hz:g} Hz)",
        ),
    ]
    for amplitude, text in tones:
        if not amplitude:
            continue
        if background and method == "deficit":
            rows.append(row(text, CALIBRATED, "the deficit background of the healthy records"))
        else:
            rows.append(
                row(
                    text,
                    NEITHER,
                    "coherent across channels: the incoherent background leaves it out"
                    if background
                    else "calibration.background off",
                )
            )
    return rows


def _form_rows(model: dict, form: BenchForm, calibration: dict) -> list[dict]:
    rows = []
    if form.housing_model == "block":
        rows.append(
            row(
                "housings as rigid blocks on four feet (rocking modes)",
                NEITHER,
                "the model's housings are point masses; the calibrated bushings fit the transfer path "
                "as far as they can",
            )
        )
    if form.shaft_model != model.get("shaft_model", "rigid"):
        rows.append(
            row(
                f"{form.shaft_model} shafts (model {model.get('shaft_model', 'rigid')})",
                NEITHER,
                "the simulation runs model.shaft_model",
            )
        )
    if _differs(list(form.housing_stiffness), list(model["housing_stiffness"])):
        rows.append(
            row(
                f"housing mounts {_number_or_range(form.housing_stiffness)} N/m "
                f"(model {_number_or_range(model['housing_stiffness'])})",
                NEITHER,
                "not a calibrated parameter: the model keeps its value",
            )
        )
    rows += _background_rows(form, calibration)
    errors = model["gear_errors"]
    if form.gear_deviation_share or form.misalignment:
        grade, share, misalignment = (
            errors["grade"],
            errors["deviation_share"],
            errors["misalignment"],
        )
        inside = (
            grade[0] <= form.gear_grade <= grade[1]
            and share[0] <= form.gear_deviation_share <= share[1]
            and misalignment[0] <= form.misalignment <= misalignment[1]
        )
        rows.append(
            row(
                f"its own gears: ISO grade {form.gear_grade:g} at {form.gear_deviation_share:g} of the "
                f"tolerances, misalignment {form.misalignment:g} m (one fixed pattern)",
                RANDOMISED,
                f"model.gear_errors: grade {grade}, share {share}, misalignment {misalignment}, a new pair "
                "per sample",
                bool(inside),
            )
        )
    variability = model["variability"]
    for name in ("speed_fluctuation", "load_fluctuation"):
        amplitude, frequency = getattr(form, name), getattr(form, f"{name}_hz")
        if not amplitude:
            continue
        text = f"{name.replace('_', ' ')} {amplitude:g} at {frequency:g} Hz"
        if variability.get(f"{name}_source") == "healthy_records":
            rows.append(
                row(
                    text,
                    CALIBRATED,
                    "read off the healthy records' tracked speed (params.json "
                    f"{name}), drawn within it per sample",
                )
            )
            continue
        span = variability[f"{name}_hz"]
        inside = amplitude <= variability[name] and span[0] <= frequency <= span[1]
        rows.append(
            row(
                text,
                RANDOMISED,
                f"model.variability: up to {variability[name]:g} at {span} Hz",
                bool(inside),
            )
        )
    return rows


def _model_form(model: dict, state: str) -> str:
    if state == "surface_fault":
        return model["surface_fault_model"]
    return state


def _fault_rows(
    model: dict, bench: dict, calibration: dict, health_states, healthy_state: str
) -> list[dict]:
    rows = []
    per_state = calibration.get("per_state", {}).get("states", [])
    severity = model["fault_severity"]
    for state in health_states:
        if state == healthy_state:
            continue
        spec = bench["faults"].get(state)
        if spec is None:
            rows.append(
                row(
                    f"{state}: no form of its own",
                    SAME,
                    "the bench runs the model's fault code at the model's values: not a test of its form",
                )
            )
            continue
        form = spec["form"]
        details = ", ".join(f"{k} {_number_or_range(v)}" for k, v in spec.items() if k != "form")
        text = f"{state} as its own {form.replace('_', ' ')} ({details})"
        if state in per_state:
            rows.append(
                row(text, CALIBRATED, "per-state calibration on its first record per speed")
            )
            continue
        model_form = _model_form(model, state)
        keys = SEVERITY_OF_FORM.get((form, model_form))
        if keys is None:
            rows.append(
                row(
                    text,
                    NEITHER,
                    f"the model's {state} is {model_form.replace('_', ' ')}, "
                    f"not the bench's {form.replace('_', ' ')}",
                )
            )
            continue
        inside = all(severity[m][0] <= spec[b] <= severity[m][1] for b, m in keys.items())
        ranges = ", ".join(f"{m} {severity[m]}" for m in keys.values())
        rows.append(
            row(
                text,
                RANDOMISED,
                f"model {model_form.replace('_', ' ')}, drawn per sample: {ranges}",
                bool(inside),
            )
        )
    return rows


def _number_or_range(value) -> str:
    """A value as the report lists it: 3e-05, [0.3, 0.6] for a range, a name as it is."""
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_number_or_range(v) for v in value) + "]"
    return (
        f"{value:g}"
        if isinstance(value, (int, float)) and not isinstance(value, bool)
        else str(value)
    )

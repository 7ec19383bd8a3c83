"""Config validation before any job runs: the JSON schema (types, ranges, defaults, no unknown
keys) and the cross-field checks a schema cannot express. Every message names the key path."""
from __future__ import annotations

import copy
from pathlib import Path

import jsonschema
import yaml


class ConfigError(ValueError):
    """The config breaks the schema or a cross-field rule."""


def _key_path(path) -> str:
    return ".".join(str(p) for p in path) or "<top level>"


def _describe(error: jsonschema.ValidationError) -> str:
    key = _key_path(error.absolute_path)
    if error.validator == "additionalProperties":
        allowed = sorted(error.schema.get("properties", {}))
        extra = sorted(set(error.instance) - set(allowed))
        where = f"{key}." if error.absolute_path else ""
        return f"unknown key {', '.join(where + e for e in extra)}; allowed keys here: {allowed}"
    if error.validator == "enum":
        return f"{key}: {error.instance!r} is not allowed; allowed values: {error.validator_value}"
    if error.validator == "type" and isinstance(error.instance, str) and _is_number(error.instance):
        return (f"{key}: {error.instance!r} is text, not a number; YAML reads exponents without a sign "
                f"as text, write e.g. 4.0e+8")
    if error.validator == "oneOf" and "gamma" in key:
        return f"{key}: {error.instance!r} must be 'scale', 'auto' or a positive number"
    return f"{key}: {error.message}"


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False


def _with_defaults(validator_class):
    """A validator that fills in schema defaults as it validates (as snakemake.utils.validate)."""
    validate_properties = validator_class.VALIDATORS["properties"]

    def set_defaults(validator, properties, instance, schema):
        if isinstance(instance, dict):
            for name, sub in properties.items():
                if "default" in sub and name not in instance:
                    instance[name] = copy.deepcopy(sub["default"])
        yield from validate_properties(validator, properties, instance, schema)

    return jsonschema.validators.extend(validator_class, {"properties": set_defaults})


def load_schema(path) -> dict:
    return yaml.safe_load(Path(path).read_text())


def validate_config(config: dict, schema: dict) -> dict:
    """Validate `config` in place (defaults filled in) and return it; raise ConfigError listing
    every problem."""
    validator = _with_defaults(jsonschema.Draft202012Validator)(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: list(map(str, e.absolute_path)))
    if errors:
        raise ConfigError("invalid config:\n  " + "\n  ".join(_describe(e) for e in errors))
    problems = cross_field_problems(config)
    if problems:
        raise ConfigError("invalid config:\n  " + "\n  ".join(problems))
    return config


def cross_field_problems(config: dict) -> list[str]:
    problems = []
    for name, bound in config["calibration"]["parameters"].items():
        if not bound["low"] < bound["high"]:
            problems.append(f"calibration.parameters.{name}: low ({bound['low']}) must be below "
                            f"high ({bound['high']})")
        if bound.get("log") and bound["low"] <= 0:
            problems.append(f"calibration.parameters.{name}: a log-scaled bound needs low > 0")
        if name == "restitution" and not (0 < bound["low"] and bound["high"] <= 1):
            problems.append("calibration.parameters.restitution: bounds must lie in (0, 1]")
    if config["system"] == "bearing":
        problems += _bearing_problems(config)
    else:
        problems += _gear_problems(config)
    if not any(c["enabled"] for c in config["classifiers"].values()):
        problems.append("classifiers: enable at least one classifier")
    return problems


def _gear_problems(config: dict) -> list[str]:
    problems = []
    if set(config["features"]["channels"]) - {"A1_x", "A1_y", "A2_x", "A2_y"}:
        problems.append(f"features.channels: {config['features']['channels']}: the gear rig has "
                        "channels A1_x, A1_y, A2_x, A2_y")
    nyquist = config["rig"]["output_rate_hz"] / 2
    spectrum = config["features"]["spectrum"]
    if spectrum["f_max_hz"] > nyquist:
        problems.append(f"features.spectrum.f_max_hz: {spectrum['f_max_hz']} Hz is above the Nyquist "
                        f"frequency {nyquist} Hz of rig.output_rate_hz")
    if spectrum["f_min_hz"] >= spectrum["f_max_hz"]:
        problems.append("features.spectrum.f_min_hz: must be below features.spectrum.f_max_hz")
    span = spectrum["f_max_hz"] - spectrum["f_min_hz"]
    for key, resolution in (("features.spectrum.resolution_hz", spectrum["resolution_hz"]),
                            ("calibration.resolution_hz", config["calibration"]["resolution_hz"])):
        if abs(span / resolution - round(span / resolution)) > 1e-6:
            problems.append(f"{key}: the range f_min_hz..f_max_hz ({span:g} Hz) is not a whole number "
                            f"of {resolution:g} Hz bands")
    segment_resolution = 1.0 / config["rig"]["segment_seconds"]
    if spectrum["resolution_hz"] < segment_resolution:
        problems.append(f"features.spectrum.resolution_hz: {spectrum['resolution_hz']} Hz is finer than "
                        f"the {segment_resolution:g} Hz a {config['rig']['segment_seconds']} s segment resolves")
    gmf = max(config["rig"]["speeds_rpm"]) / 60 * config["model"]["geometry"]["teeth_pinion"]
    if gmf >= nyquist:
        problems.append(f"rig.output_rate_hz: the gear mesh frequency {gmf:.0f} Hz at the highest speed "
                        f"is above the Nyquist frequency {nyquist} Hz")
    bench = config["virtual_bench"]
    if config["measured_table"] is None and bench["record_seconds"] < config["rig"]["segment_seconds"]:
        problems.append("virtual_bench.record_seconds: shorter than rig.segment_seconds")
    if config["calibration"]["sim_seconds"] < config["rig"]["segment_seconds"]:
        problems.append("calibration.sim_seconds: shorter than rig.segment_seconds")
    if "condition_holdout" in config["hybrid"]["protocols"] and len(config["rig"]["speeds_rpm"]) < 2:
        problems.append("hybrid.protocols: condition_holdout needs at least two rig.speeds_rpm")
    gear_names = set(config["model"]) - {"geometry"}
    wrong = sorted(set(config["calibration"]["parameters"]) - gear_names)
    if wrong:
        problems.append(f"calibration.parameters: {wrong} are not gear model parameters")
    if config["calibration"]["cost"] == "features_eq6":
        problems.append("calibration.cost: features_eq6 is the bearing rig's cost; the gear model "
                        "uses cfrp_eq4 or helical_eq14")
    if "healthy" not in config["rig"]["health_states"]:
        problems.append("rig.health_states: must contain 'healthy' (calibration uses healthy records)")
    return problems


def _bearing_problems(config: dict) -> list[str]:
    from condmon.cwru import task_labels

    problems = []
    cwru, features = config["cwru"], config["features"]
    folder = Path(config["measured_dir"])
    if not folder.is_dir():
        problems.append(f"measured_dir: {folder} is not a folder (point it at your CWRU .mat files "
                        "with --config measured_dir=PATH)")
    extra = sorted(set(features["channels"]) - set(cwru["channels"]))
    if extra:
        problems.append(f"features.channels: {extra} not among the ingested cwru.channels "
                        f"{cwru['channels']}")
    low, high = features["statistical"]["band_hz"]
    if not 0 < low < high < cwru["fs_hz"] / 2:
        problems.append(f"features.statistical.band_hz: {[low, high]} must satisfy 0 < low < high < "
                        f"cwru.fs_hz / 2 = {cwru['fs_hz'] / 2:g}")
    if features["kind"] == "spectrum" and features["spectrum"]["f_max_hz"] > cwru["fs_hz"] / 2:
        problems.append("features.spectrum.f_max_hz: above the Nyquist frequency of cwru.fs_hz")
    labels = task_labels(cwru["task"])
    unknown = sorted(set(config["hybrid"]["measured_classes"]) - set(labels))
    if "unseen_fault" in config["hybrid"]["protocols"] and unknown:
        problems.append(f"hybrid.measured_classes: {unknown} are not classes of cwru.task "
                        f"{cwru['task']!r} ({labels})")
    names = features["statistical"]["names"]
    n_features = features["selection"]["n_features"]
    if n_features is not None and names is not None and n_features >= len(names) * len(features["channels"]):
        problems.append(f"features.selection.n_features: {n_features} must be below the number of "
                        f"candidate features ({len(names) * len(features['channels'])})")
    model_names = set(config["bearing"]["model"])
    wrong = sorted(set(config["calibration"]["parameters"]) - model_names)
    if wrong:
        problems.append(f"calibration.parameters: {wrong} are not parameters of the bearing rig "
                        f"(bearing.model: {sorted(model_names)})")
    if config["hybrid"]["condition"] == "speed_rpm" and "condition_holdout" in config["hybrid"]["protocols"]:
        problems.append("hybrid.condition: CWRU records of one load differ by a few rpm; hold out "
                        "loads (condition: load)")
    return problems

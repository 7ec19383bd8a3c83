"""Config validation before any job runs: the JSON schema (types, ranges, defaults, no unknown
keys) and the cross-field checks a schema cannot express. Every message names the key path."""

from __future__ import annotations

import copy
import re
from pathlib import Path

import jsonschema

# the schema helpers live apart (condmon.schema) so the systems need not import this module
from condmon.schema import load_schema, merge_schema, schema_defaults  # noqa: F401


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
        hint = (
            "YAML 1.1 reads an exponent without a sign as text, write e.g. 4.0e+8"
            if re.search(r"[eE]\d", error.instance)
            else "write it without quotes"
        )
        return f"{key}: {error.instance!r} is text, not a number; {hint}"
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


def system_schema(config: dict, schema: dict) -> tuple[dict, type]:
    """The whole schema of the config's system (base + the registries' fragments: every
    classifier's section, every feature family's own; + the system's fragment) and the
    system's class."""
    from condmon.classifiers import config_schema as classifier_schema
    from condmon.features import config_schema as family_schema
    from condmon.systems import system_class

    name = config.get("system", schema["properties"]["system"]["default"])
    modules = config.get("system_modules") or []
    if not isinstance(name, str) or not isinstance(modules, list):
        raise ConfigError("invalid config:\n  system: must be a name, system_modules a list")
    try:
        cls = system_class(name, modules)
    except ValueError as exc:
        raise ConfigError(f"invalid config:\n  {exc}") from None
    registries = merge_schema(merge_schema(schema, classifier_schema()), family_schema())
    return merge_schema(registries, cls.schema()), cls


def validate_config(config: dict, schema: dict) -> dict:
    """Validate `config` in place (defaults filled in, the system's choices for the keys left
    null) and return it; raise ConfigError listing every problem."""
    schema, cls = system_schema(config, schema)
    validator = _with_defaults(jsonschema.Draft202012Validator)(schema)
    errors = sorted(validator.iter_errors(config), key=lambda e: list(map(str, e.absolute_path)))
    if errors:
        raise ConfigError("invalid config:\n  " + "\n  ".join(_describe(e) for e in errors))
    system = cls(config)
    if config["features"]["channels"] is None:
        config["features"]["channels"] = list(system.channels)
    if config["hybrid"]["condition"] is None:
        config["hybrid"]["condition"] = system.default_condition
    if config["hybrid"]["measured_classes"] is None:
        config["hybrid"]["measured_classes"] = [system.healthy_state]
    reserve = config["calibration"]["reserve"]
    if reserve["each_condition"] is None:  # a per-condition reference needs per-condition data
        reserve["each_condition"] = bool(config["features"]["healthy_reference"]["enabled"])
    problems = cross_field_problems(config) + system.problems()
    if problems:
        raise ConfigError("invalid config:\n  " + "\n  ".join(problems))
    return config


def cross_field_problems(config: dict) -> list[str]:
    """The checks every system shares (each system adds its own: `System.problems`)."""
    problems = []
    if "parameters" not in config["calibration"]:
        problems.append("calibration.parameters: bound at least one parameter to calibrate")
    for name, bound in config["calibration"].get("parameters", {}).items():
        if not bound["low"] < bound["high"]:
            problems.append(
                f"calibration.parameters.{name}: low ({bound['low']}) must be below "
                f"high ({bound['high']})"
            )
        if bound.get("log") and bound["low"] <= 0:
            problems.append(f"calibration.parameters.{name}: a log-scaled bound needs low > 0")
    calibration = config["calibration"]
    if (
        calibration.get("background")
        and calibration.get("background_method") == "incoherent"
        and len(config["features"]["channels"]) < 2
    ):
        problems.append(
            "calibration.background_method: incoherent (the part of each channel no other channel "
            "explains) needs two or more features.channels; use deficit with one"
        )
    if not any(c["enabled"] for c in config["classifiers"].values()):
        problems.append("classifiers: enable at least one classifier")
    disabled = [
        c
        for c in config["joined"]["classifiers"]
        if not config["classifiers"].get(c, {}).get("enabled")
    ]
    if disabled:
        problems.append(f"joined.classifiers: {disabled} not among the enabled classifiers")
    families = config["features"]["kind"].split("+")
    if len(set(families)) != len(families):
        problems.append(f"features.kind: {config['features']['kind']!r} names a family twice")
    if (
        config["classifiers"]["cnn"]["enabled"]
        and not {"spectrum", "order", "residual"} & set(families)
        and families != ["statistical"]
    ):
        problems.append(
            f"classifiers.cnn: the CNN reads band spectra (Hz, orders or residual orders) and features.kind "
            f"{config['features']['kind']!r} has none; add spectrum (e.g. spectrum+{families[0]}) "
            "or disable the CNN"
        )
    names = config["features"]["statistical"]["names"]
    n_features = config["features"]["selection"]["n_features"]
    n_channels = len(config["features"]["channels"])
    if (
        config["features"]["kind"] == "statistical"
        and n_features is not None
        and names is not None
        and n_features >= len(names) * n_channels
    ):
        problems.append(
            f"features.selection.n_features: {n_features} must be below the number of "
            f"candidate features ({len(names) * n_channels})"
        )
    return problems


# -- typed --config overrides -------------------------------------------------------------------
# Snakemake reads a nested `--config classifiers='{svm: {C: 3}}'` with YAML's BaseLoader: every
# value inside it is text ("3", "true", "null"). The schema says what each key is, so such text is
# read as the schema's type here, before validation; values of config files are never touched.


def _schemas_at(schema: dict, root: dict) -> list[dict]:
    """The schema alternatives a value must match ($ref resolved, oneOf/anyOf flattened)."""
    if "$ref" in schema:
        target = root
        for part in schema["$ref"].lstrip("#/").split("/"):
            target = target[part]
        return _schemas_at({**target, **{k: v for k, v in schema.items() if k != "$ref"}}, root)
    alternatives = schema.get("oneOf") or schema.get("anyOf")
    if alternatives:
        return [s for alt in alternatives for s in _schemas_at(alt, root)]
    return [schema]


def _types(schemas: list[dict]) -> set[str]:
    types = set()
    for schema in schemas:
        kind = schema.get("type")
        types.update(kind if isinstance(kind, list) else [kind] if kind else [])
    return types


def _typed(text: str, schemas: list[dict]):
    """``text`` as the first schema type it reads as (YAML 1.2 numbers: 4e8 is a number); the
    text itself when none fits (validation then names the key)."""
    if any("string" in _types([s]) and text in s.get("enum", [text]) for s in schemas):
        return text  # text the key takes as it is (a name, or one of its words: gamma "scale")
    types = _types(schemas)
    word = text.strip().lower()
    if "null" in types and word in ("null", "~", "none", ""):
        return None
    if "boolean" in types and word in ("true", "false"):
        return word == "true"
    if "integer" in types:
        try:
            return int(word)
        except ValueError:
            pass
    if "number" in types:
        try:
            number = float(word)
            return (
                int(number)
                if number.is_integer() and "." not in word and "e" not in word
                else number
            )
        except ValueError:
            pass
    return text


def _coerce(value, schema: dict, root: dict):
    schemas = _schemas_at(schema, root)
    if isinstance(value, str):
        return _typed(value, schemas)
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            sub = next(
                (s["properties"][key] for s in schemas if key in s.get("properties", {})), None
            )
            if sub is None:
                sub = next(
                    (
                        s["additionalProperties"]
                        for s in schemas
                        if isinstance(s.get("additionalProperties"), dict)
                    ),
                    None,
                )
            out[key] = item if sub is None else _coerce(item, sub, root)
        return out
    if isinstance(value, list):
        items = next((s["items"] for s in schemas if isinstance(s.get("items"), dict)), None)
        return value if items is None else [_coerce(item, items, root) for item in value]
    return value


def apply_typed_overrides(config: dict, overrides: dict, schema: dict) -> dict:
    """Read the text values of the command line's ``--config`` overrides (already merged into
    ``config``) as the types the schema (with the system's fragment) gives their keys; in place."""
    full, _ = system_schema(config, schema)

    def walk(target: dict, override: dict, where: dict):
        for key, value in override.items():
            sub = where.get("properties", {}).get(key)
            if sub is None or key not in target:
                continue
            if isinstance(value, dict) and isinstance(target[key], dict):
                resolved = _schemas_at(sub, full)
                merged = {k: v for s in resolved for k, v in s.items()}
                walk(target[key], value, merged)
            else:
                target[key] = _coerce(target[key], sub, full)

    walk(config, overrides or {}, full)
    return config


# -- dotted --config overrides ------------------------------------------------------------------
# `--config set=classifiers.svm.C=3` names a key as config/README.md and MLflow's parameters do.
# Snakemake takes only an identifier before a --config entry's "=" and keeps one value per key,
# so the dotted assignments ride on one key, `set`, several in one value separated by spaces:
# set='classifiers.svm.C=3 hybrid.repeats=2'. Each value is YAML (a list: [0, 100]), typed by
# the schema as the nested form's text is.
SET_KEY = "set"
DOTTED_KEY = r"[A-Za-z_][\w-]*(?:\.[A-Za-z_][\w-]*)*"
NEXT_ASSIGNMENT = re.compile(rf"\s+(?={DOTTED_KEY}=)")  # a space before "key=" starts the next one
SET_EXAMPLE = "e.g. set=classifiers.svm.C=3, several: set='classifiers.svm.C=3 hybrid.repeats=2'"


def dotted_overrides(text) -> dict:
    """The nested dict of `set`'s dotted assignments (values as YAML read them: text)."""
    import yaml

    nested = {}
    for assignment in NEXT_ASSIGNMENT.split(str(text).strip()):
        key, _, value = assignment.partition("=")
        if not re.fullmatch(DOTTED_KEY, key) or "=" not in assignment:
            raise ConfigError(
                f"invalid config:\n  set: {assignment!r} is no dotted key=value ({SET_EXAMPLE})"
            )
        *sections, leaf = key.split(".")
        target = nested
        for section in sections:
            target = target.setdefault(section, {})
            if not isinstance(target, dict):
                raise ConfigError(f"invalid config:\n  set: {key} lies inside a key set to a value")
        target[leaf] = yaml.load(value, Loader=yaml.BaseLoader)
    return nested


def _merge(config: dict, changes: dict) -> None:
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(config.get(key), dict):
            _merge(config[key], value)
        else:
            config[key] = value


def apply_dotted_overrides(config: dict, schema: dict) -> dict:
    """Merge the `set` key's dotted assignments into ``config`` (and drop `set`, which no job
    sees), their text read as the schema's types; in place. Unknown keys are validation's to name."""
    if SET_KEY not in config:
        return config
    changes = dotted_overrides(config.pop(SET_KEY))
    _merge(config, changes)
    return apply_typed_overrides(config, changes, schema)


# -- which run `snakemake --report` reports ------------------------------------------------------
CONFIG_FOLDERS = ("config", ".test/config")  # where the project's run configs live


def asks_for_report(argv) -> bool:
    """Whether the command line is `snakemake --report`: Snakemake tells a Snakefile nothing else
    of it, and reports a run never made by its first missing file."""
    return any(arg == "--report" or arg.startswith("--report=") for arg in argv)


def missing_run_message(run_name: str, results="results", project=".") -> str:
    """What to say when `snakemake --report` finds no finished run ``run_name``: the runs there
    are and the config files that name each one (its --configfile)."""
    import yaml

    runs = sorted(p.parent.parent.name for p in Path(results).glob("*/report/pages"))
    files = {}
    for folder in CONFIG_FOLDERS:
        for path in sorted((Path(project) / folder).rglob("*.yaml")):
            try:
                name = (yaml.safe_load(path.read_text()) or {}).get("run_name")
            except (yaml.YAMLError, AttributeError):
                continue  # not a run config (the schema is a dict too, without run_name)
            files.setdefault(name, []).append(str(path.relative_to(project)))
    made = "; ".join(
        f"{run} (the run_name of {', '.join(files[run])})" if run in files else run for run in runs
    )
    return (
        f"no finished run {run_name!r} to report ({Path(results) / run_name / 'report' / 'pages'} "
        "is missing): give the --configfile(s) the run was made with, e.g. snakemake --report "
        "report.html --configfile .test/config/smoke.yaml"
        + (f"; finished runs: {made}" if runs else "; no run has finished here yet")
    )


# -- layered config files ------------------------------------------------------------------------
# A config file may state only how a run differs from another: `base: config/config.yaml` (a path
# from the project folder) and its own keys, merged over the base's as Snakemake merges several
# --configfile (dicts key by key, anything else replaced). So `--configfile .test/config/smoke.yaml`
# alone is the whole smoke run, and an edit of the base reaches it.
BASE_KEY = "base"
DEFAULT_CONFIG = "config/config.yaml"  # the run of a command line that names no --configfile
SCHEMA_FILE = "config/schema.yaml"


def read_config(paths, overrides: dict | None = None, project=".") -> dict:
    """The unvalidated config of a run, as Snakemake and the Snakefile build it.

    Parameters
    ----------
    paths : list of str or Path
        Config files, merged in order (dicts key by key, anything else replaced), as several
        ``--configfile`` are; a relative path is taken from ``project``.
    overrides : dict, optional
        The ``--config`` entries (or a caller's changes), merged over the files.
    project : str or Path
        The project folder, from which a relative path and a file's `base` are read.

    Returns
    -------
    dict
        The merged files and overrides over the `base` they name (`base` dropped); no defaults,
        no typing, no checks: :func:`load_config` adds those.
    """
    import yaml

    config: dict = {}
    for path in paths:
        path = Path(project) / path
        if not path.is_file():
            raise ConfigError(f"invalid config:\n  --configfile: no config file {path}")
        _merge(config, yaml.safe_load(path.read_text()) or {})
    _merge(config, copy.deepcopy(overrides or {}))
    return apply_base(config, project)


def load_config(
    paths,
    overrides: dict | None = None,
    project=".",
    schema: dict | None = None,
    changes: dict | None = None,
) -> dict:
    """The validated config of a run, exactly as the workflow sees it (the Snakefile calls this).

    Parameters
    ----------
    paths : list of str or Path
        Config files, merged in order as several ``--configfile`` are (each may name its `base`;
        the Snakefile passes ``DEFAULT_CONFIG`` when the command line names none).
    overrides : dict, optional
        ``--config`` entries: nested dicts merged key by key, text read as the schema's types,
        dotted keys under ``set`` (``{"set": "classifiers.svm.C=3"}``).
    project : str or Path
        The project folder (config files, bases and the schema are read from it).
    schema : dict, optional
        The shared schema, if the caller has it loaded; else ``config/schema.yaml``.
    changes : dict, optional
        A caller's own values, merged last as they are (not read as text), before validation.

    Returns
    -------
    dict
        The config with every default filled in and every check passed.

    Raises
    ------
    ConfigError
        A missing file or base, or a key that breaks the schema or a cross-field rule, by name.
    """
    schema = load_schema(Path(project) / SCHEMA_FILE) if schema is None else schema
    config = read_config(paths, overrides, project)
    apply_typed_overrides(config, overrides or {}, schema)
    apply_dotted_overrides(config, schema)
    _merge(config, copy.deepcopy(changes or {}))
    return validate_config(config, schema)


def apply_base(config: dict, project=".") -> dict:
    """``config`` merged over the config file its `base` names (that file's own base first), and
    `base` dropped; in place (Snakemake's config object stays the same)."""
    name = config.pop(BASE_KEY, None)
    if name is None:
        return config
    import yaml

    path = Path(project) / str(name)
    if not path.is_file():
        raise ConfigError(
            f"invalid config:\n  base: no config file {path} (a path from the project folder)"
        )
    layer = copy.deepcopy(config)
    config.clear()
    config.update(apply_base(yaml.safe_load(path.read_text()) or {}, project))
    _merge(config, layer)
    return config

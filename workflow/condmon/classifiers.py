"""Classifiers by name: a registry of estimators that standardise their inputs first, each entry
carrying its config section's schema (the only home of its parameters' defaults).

The CFRP study's classifier is an RBF SVM (C=1.2, gamma="scale") on standardised FFT inputs;
SVM and KNN are Pipelines (a scaler, then the classifier; `standardize`: every feature on its
own, or each channel's band spectrum as one block, ``condmon.bands.BandScaler``). The helical-gear
study's ensemble of 1D-CNNs is ``condmon.cnn.CNNEnsembleClassifier``, which standardises inside
(so its exported PyTorch model takes the same raw features); its sizes are the study's training
on a network small enough for CPU training (config/README.md).

A new classifier is one file (a builder taking (complete params, seed) and the JSON schema of its
parameters, each with its default) plus one registry line: ``register_classifier(name, build,
params_schema)``. The config then accepts ``classifiers.<name>`` (``condmon.config`` merges every
entry's section schema into the shared one, as it does a system's) and the train stage builds it
by name.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any, Callable

import jsonschema

from condmon.schema import schema_defaults

# keys of a classifier section that choose what it trains on, not how it is built
SELECTION_KEYS = ("enabled", "measured_percent", "repeats")
# the shared schema's definitions the parameter schemas may $ref (config/schema.yaml has them too)
DEFINITIONS = {"positive": {"type": "number", "exclusiveMinimum": 0}}
# train on fewer measured percentages and repeats than hybrid lists (a costly classifier); null = all
SUBSET_PROPERTIES = {
    "measured_percent": {
        "type": ["array", "null"],
        "minItems": 1,
        "uniqueItems": True,
        "items": {"type": "integer", "minimum": 0, "maximum": 100},
        "default": None,
    },
    "repeats": {"type": ["integer", "null"], "minimum": 1, "default": None},
}


@dataclass(frozen=True)
class ClassifierSpec:
    """One registry entry: how to build the classifier and what its config section accepts."""

    build: Callable[[dict, int], Any]  # (complete params, seed) -> unfitted estimator
    params_schema: dict  # {parameter: JSON schema with its default}
    enabled: bool = True  # classifiers.<name>.enabled's default
    subset: bool = False  # classifiers.<name> may name measured_percent / repeats
    # its fit draws no random numbers: the same training data give the same model whatever the
    # seed, so the train stage fits a training set that recurs across splits only once
    seed_free: bool = False

    @property
    def defaults(self) -> dict:
        """Every accepted parameter with its default (a copy: the schema's lists stay as they are)."""
        return copy.deepcopy(schema_defaults({"properties": self.params_schema}))

    def section_schema(self) -> dict:
        """The JSON schema of the config section classifiers.<name>."""
        properties = {
            "enabled": {"type": "boolean", "default": self.enabled},
            **(SUBSET_PROPERTIES if self.subset else {}),
            **self.params_schema,
        }
        return {
            "type": "object",
            "additionalProperties": False,
            "default": {},
            "properties": properties,
        }


def _scaler(standardize: str):
    """Every feature standardised on its own (sklearn's StandardScaler), or each channel's band
    spectrum as one block (`condmon.bands.BandScaler`)."""
    from sklearn.preprocessing import StandardScaler

    from condmon.bands import BandScaler

    return StandardScaler() if standardize == "feature" else BandScaler(standardize)


def _svm(params: dict, seed: int):
    from sklearn.pipeline import Pipeline
    from sklearn.svm import SVC

    # No probability estimates: predict() does not need them, and SVC(probability=...) is
    # deprecated from scikit-learn 1.9 on. random_state then has no effect; kept for clarity.
    svc = SVC(
        kernel="rbf",
        C=params["C"],
        gamma=params["gamma"],
        class_weight=params["class_weight"],
        random_state=seed,
    )
    return Pipeline([("scale", _scaler(params["standardize"])), ("svm", svc)])


def _knn(params: dict, seed: int):
    from sklearn.neighbors import KNeighborsClassifier
    from sklearn.pipeline import Pipeline

    knn = KNeighborsClassifier(n_neighbors=params["n_neighbors"], weights=params["weights"])
    return Pipeline([("scale", _scaler(params["standardize"])), ("knn", knn)])


def _cnn(params: dict, seed: int):
    # imported here: PyTorch costs a second or two and memory that SVM/KNN jobs do not need
    from condmon.cnn import CNNEnsembleClassifier

    return CNNEnsembleClassifier(**params, random_state=seed)


SVM_PARAMS = {
    "C": {"$ref": "#/definitions/positive", "default": 1.2},
    "gamma": {
        "oneOf": [
            {"type": "string", "enum": ["scale", "auto"]},
            {"$ref": "#/definitions/positive"},
        ],
        "default": "scale",
    },
    # balanced: weights inversely proportional to class frequencies (sklearn's SVC)
    "class_weight": {"type": ["string", "null"], "enum": ["balanced", None], "default": None},
    # feature: every feature on its own; channel: each channel's band spectrum as one block
    "standardize": {"type": "string", "enum": ["feature", "channel"], "default": "feature"},
}
KNN_PARAMS = {
    "n_neighbors": {"type": "integer", "minimum": 1, "default": 5},
    "weights": {"type": "string", "enum": ["uniform", "distance"], "default": "uniform"},
    "standardize": {"type": "string", "enum": ["feature", "channel"], "default": "feature"},
}
_COUNT = {"type": "integer", "minimum": 1}
_SHARE = {"type": "number", "minimum": 0, "exclusiveMaximum": 1}
CNN_PARAMS = {
    "members": {**_COUNT, "default": 10},
    "epochs": {**_COUNT, "default": 25},
    "batch_size": {**_COUNT, "default": 64},
    "learning_rate": {"$ref": "#/definitions/positive", "default": 0.002},
    "conv_channels": {"type": "array", "minItems": 1, "items": dict(_COUNT), "default": [4, 8]},
    "kernel_size": {**_COUNT, "default": 7},
    "pool_size": {**_COUNT, "default": 4},
    "input_pool": {**_COUNT, "default": 2},
    "dense_units": {"type": "array", "items": dict(_COUNT), "default": [16]},
    "dropout": {**_SHARE, "default": 0.3},
    "batch_norm": {"type": "boolean", "default": True},
    "standardize": {"type": "string", "enum": ["channel", "feature"], "default": "channel"},
    "side_features": {"type": "boolean", "default": False},
    "validation_fraction": {**_SHARE, "default": 0.2},
    "patience": {**_COUNT, "default": 5},
    "input_channels": {
        "oneOf": [{"type": "string", "enum": ["auto"]}, dict(_COUNT)],
        "default": "auto",
    },
    "device": {"type": "string", "enum": ["auto", "cpu", "cuda"], "default": "auto"},
    "threads": {**_COUNT, "default": 1},
}

CLASSIFIERS: dict[str, ClassifierSpec] = {
    "svm": ClassifierSpec(_svm, SVM_PARAMS, seed_free=True),
    "knn": ClassifierSpec(_knn, KNN_PARAMS, seed_free=True),
    "cnn": ClassifierSpec(_cnn, CNN_PARAMS, enabled=False, subset=True),
}


def register_classifier(
    name: str,
    build: Callable[[dict, int], Any],
    params_schema: dict,
    enabled: bool = False,
    subset: bool = False,
    seed_free: bool = False,
) -> ClassifierSpec:
    """Add a classifier to the registry (an existing name is an error, not a silent override).
    ``params_schema``: {parameter: JSON schema with its default}; ``enabled``: whether a config
    that does not mention it trains it; ``seed_free``: its fit draws no random numbers (the
    train stage then reuses the model of a training set it has already fitted)."""
    if name in CLASSIFIERS:
        raise ValueError(f"classifier {name!r} is already registered")
    missing = sorted(key for key, schema in params_schema.items() if "default" not in schema)
    if missing:
        raise ValueError(f"classifier {name!r}: parameter(s) {missing} have no default")
    CLASSIFIERS[name] = ClassifierSpec(build, dict(params_schema), enabled, subset, seed_free)
    return CLASSIFIERS[name]


def config_schema() -> dict:
    """The schema fragment of every registered classifier's section, to merge into the shared
    schema (condmon.schema.merge_schema)."""
    return {
        "properties": {
            "classifiers": {
                "properties": {name: spec.section_schema() for name, spec in CLASSIFIERS.items()}
            }
        }
    }


# a tuple is as good an array as a list (scikit-learn's and PyTorch's own parameters are tuples)
_VALIDATOR = jsonschema.validators.extend(
    jsonschema.Draft202012Validator,
    type_checker=jsonschema.Draft202012Validator.TYPE_CHECKER.redefine(
        "array", lambda checker, instance: isinstance(instance, (list, tuple))
    ),
)


def classifier_params(name: str, params: dict | None = None) -> dict:
    """The complete parameters of classifier `name`: defaults overridden by `params`, checked
    against its schema (an error names the classifier and the parameter)."""
    if name not in CLASSIFIERS:
        raise ValueError(f"unknown classifier {name!r}; choose one of {sorted(CLASSIFIERS)}")
    spec = CLASSIFIERS[name]
    unknown = sorted(set(params or {}) - set(spec.params_schema))
    if unknown:
        raise ValueError(
            f"unknown parameter(s) {unknown} for classifier {name!r}; "
            f"allowed: {sorted(spec.params_schema)}"
        )
    complete = {**spec.defaults, **(params or {})}
    schema = {"definitions": DEFINITIONS, "type": "object", "properties": spec.params_schema}
    errors = sorted(_VALIDATOR(schema).iter_errors(complete), key=lambda e: list(map(str, e.path)))
    if errors:
        raise ValueError(
            "; ".join(
                f"classifiers.{name}.{'.'.join(map(str, e.path))}: {e.message}" for e in errors
            )
        )
    return complete


def make_classifier(name: str, params: dict | None = None, seed: int = 0):
    """An unfitted estimator for the named classifier (Pipeline StandardScaler + classifier,
    or the CNN ensemble, which standardises inside)."""
    complete = classifier_params(name, params)  # raises for unknown names and bad parameters
    return CLASSIFIERS[name].build(complete, int(seed))

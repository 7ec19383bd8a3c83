"""Classifiers by name: sklearn estimators that standardise their inputs first.

The CFRP study's classifier is an RBF SVM (C=1.2, gamma="scale") on standardised FFT inputs;
SVM and KNN are Pipelines (StandardScaler + classifier). The helical-gear study's ensemble of
1D-CNNs is ``condmon.cnn.CNNEnsembleClassifier``, which standardises inside (so its exported
PyTorch model takes the same raw features). More classifiers join by adding an entry to
CLASSIFIERS or calling register_classifier: a builder taking (params, seed) and the parameter
defaults.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from condmon.config import load_schema, schema_defaults


@dataclass(frozen=True)
class ClassifierSpec:
    build: Callable[[dict, int], Pipeline]  # (complete params, seed) -> unfitted estimator
    defaults: dict                          # every accepted parameter with its default


def _svm(params: dict, seed: int) -> Pipeline:
    # No probability estimates: predict() does not need them, and SVC(probability=...) is
    # deprecated from scikit-learn 1.9 on. random_state then has no effect; kept for clarity.
    svc = SVC(kernel="rbf", C=params["C"], gamma=params["gamma"],
              class_weight=params["class_weight"], random_state=seed)
    return Pipeline([("scale", StandardScaler()), ("svm", svc)])


def _knn(params: dict, seed: int) -> Pipeline:
    knn = KNeighborsClassifier(n_neighbors=params["n_neighbors"], weights=params["weights"])
    return Pipeline([("scale", StandardScaler()), ("knn", knn)])


def _cnn(params: dict, seed: int):
    # imported here: PyTorch costs a second or two and memory that SVM/KNN jobs do not need
    from condmon.cnn import CNNEnsembleClassifier

    return CNNEnsembleClassifier(**params, random_state=seed)


# config/schema.yaml is the only home of the classifiers' defaults (the CNN's sizes are the
# helical-gear study's training on a network small enough for CPU training; config/README.md).
SCHEMA_PATH = Path(__file__).resolve().parents[2] / "config" / "schema.yaml"
# keys of a classifier section that choose what it trains on, not how it is built
SELECTION_KEYS = ("enabled", "measured_percent", "repeats")


_DEFAULTS = {name: {key: value for key, value in section.items() if key not in SELECTION_KEYS}
             for name, section in schema_defaults(load_schema(SCHEMA_PATH)["properties"]["classifiers"]).items()}
CLASSIFIERS: dict[str, ClassifierSpec] = {
    "svm": ClassifierSpec(_svm, _DEFAULTS["svm"]),
    "knn": ClassifierSpec(_knn, _DEFAULTS["knn"]),
    "cnn": ClassifierSpec(_cnn, _DEFAULTS["cnn"]),
}


def register_classifier(name: str, build: Callable[[dict, int], Pipeline], defaults: dict) -> None:
    """Add a classifier to the registry (an existing name is an error, not a silent override)."""
    if name in CLASSIFIERS:
        raise ValueError(f"classifier {name!r} is already registered")
    CLASSIFIERS[name] = ClassifierSpec(build, dict(defaults))


def classifier_params(name: str, params: dict | None = None) -> dict:
    """The complete parameters of classifier `name`: defaults overridden by `params`."""
    if name not in CLASSIFIERS:
        raise ValueError(f"unknown classifier {name!r}; choose one of {sorted(CLASSIFIERS)}")
    defaults = CLASSIFIERS[name].defaults
    unknown = sorted(set(params or {}) - set(defaults))
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for classifier {name!r}; "
                         f"allowed: {sorted(defaults)}")
    return {**defaults, **(params or {})}


def make_classifier(name: str, params: dict | None = None, seed: int = 0) -> Pipeline:
    """An unfitted estimator for the named classifier (Pipeline StandardScaler + classifier,
    or the CNN ensemble, which standardises inside)."""
    complete = classifier_params(name, params)  # raises for unknown names and parameters
    return CLASSIFIERS[name].build(complete, int(seed))

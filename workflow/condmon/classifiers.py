"""Classifiers by name: each a sklearn Pipeline that standardises its inputs first.

The CFRP study's classifier is an RBF SVM (C=1.2, gamma="scale") on standardised FFT inputs.
More classifiers (a CNN later) join by adding an entry to CLASSIFIERS or calling
register_classifier: a builder taking (params, seed) and the parameter defaults.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC


@dataclass(frozen=True)
class ClassifierSpec:
    build: Callable[[dict, int], Pipeline]  # (complete params, seed) -> unfitted pipeline
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


CLASSIFIERS: dict[str, ClassifierSpec] = {
    "svm": ClassifierSpec(_svm, {"C": 1.2, "gamma": "scale", "class_weight": None}),
    "knn": ClassifierSpec(_knn, {"n_neighbors": 5, "weights": "uniform"}),
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
    """An unfitted Pipeline (StandardScaler + classifier) for the named classifier."""
    complete = classifier_params(name, params)  # raises for unknown names and parameters
    return CLASSIFIERS[name].build(complete, int(seed))

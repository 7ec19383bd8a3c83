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
from typing import Callable

from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC


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


# The helical-gear study's training (10 members, 25 epochs, Adam at 0.002, cross-entropy) on a
# network small enough for CPU training: about 0.6 s per member on ~300 spectra of 4 x 1000
# bands (see config/README.md for the measurements behind these choices).
CNN_DEFAULTS = {"members": 10, "epochs": 25, "batch_size": 64, "learning_rate": 0.002,
                "conv_channels": [4, 8], "kernel_size": 7, "pool_size": 4, "input_pool": 2,
                "dense_units": [16], "dropout": 0.3, "batch_norm": True,
                "standardize": "channel", "validation_fraction": 0.2, "patience": 5,
                "input_channels": "auto", "device": "auto", "threads": 1}


CLASSIFIERS: dict[str, ClassifierSpec] = {
    "svm": ClassifierSpec(_svm, {"C": 1.2, "gamma": "scale", "class_weight": None}),
    "knn": ClassifierSpec(_knn, {"n_neighbors": 5, "weights": "uniform"}),
    "cnn": ClassifierSpec(_cnn, CNN_DEFAULTS),
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

"""Sequential backward selection (SBS) of features, as a step inside a training Pipeline.

The bearing study reduces its 15 indicators to the 3 that best separate the operating modes by
SBS. Selecting on the whole data set and then splitting would let the test segments choose the
features (selection leakage); as a Pipeline step the selection is refitted on the training data
of every fit, and `transform` only applies the stored choice.

`SequentialBackwardSelector` wraps `sklearn.feature_selection.SequentialFeatureSelector`
(direction="backward"): starting from all features it removes, one at a time, the feature whose
removal keeps the cross-validated score of `estimator` highest, until `n_features` remain. What
the wrapper adds: its folds follow the training set it is given (GroupKFold over the records,
never more folds than records: a measured-only fit at a small share trains on two or three
records; without groups, shuffled StratifiedKFold seeded by `random_state`, never more folds than
the smallest class has samples), a scale-aware default estimator and errors naming the bad value.

`select_then_classify` puts it in front of a classifier as a Pipeline. Fitted with sklearn's
metadata routing on, `fit(X, y, groups=record_ids)` hands the groups to the selector (it
requests them) and to the classifier only if that asks for them too.

`SelectionByInnerCV` is the measured-only baseline's own choice: the classifier on all features
or behind the selection, whichever an inner cross-validation over its training records scores
higher; never forced (too few records for an inner CV: all features).
"""

from __future__ import annotations

import numpy as np
import sklearn
from sklearn.base import BaseEstimator, ClassifierMixin, clone
from sklearn.feature_selection import SelectorMixin, SequentialFeatureSelector
from sklearn.model_selection import GroupKFold, StratifiedKFold
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline, make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.utils.metadata_routing import get_routing_for_object
from sklearn.utils.validation import check_is_fitted, validate_data


def default_estimator():
    """Standardised 5-nearest-neighbours: one of the study's classifiers, fast, scale-aware
    (the selection must not prefer features just because their unit makes them large)."""
    return make_pipeline(StandardScaler(), KNeighborsClassifier(n_neighbors=5))


class SequentialBackwardSelector(SelectorMixin, BaseEstimator):
    """Backward sequential feature selection to `n_features` features (default 3, as the study).

    Parameters
    - n_features: number of features kept.
    - estimator: scored on the candidate subsets (default `default_estimator()`); cloned.
    - cv: number of folds (int) or a CV splitter. With an int, folds are `StratifiedKFold`
      (shuffled with `random_state`), or `GroupKFold` when `fit` gets `groups` (pass the record
      ids: segments of one record are not independent, so folds must not cut through records).
      In a Pipeline with metadata routing on (`sklearn.config_context(enable_metadata_routing=
      True)`): `pipe.fit(X, y, groups=record_ids)`; the selector requests `groups` for `fit`.
    - scoring: sklearn scoring name (default "accuracy"); n_jobs: for the CV evaluations.

    Fitted attributes: `support_` (boolean mask), `selector_` (the fitted
    SequentialFeatureSelector), `n_features_in_`, `feature_names_in_` (if X was a DataFrame).
    `get_feature_names_out()` names the kept features.
    """

    # metadata routing: a Pipeline (or any meta-estimator) passes the record ids on to fit
    __metadata_request__fit = {"groups": True}

    def __init__(
        self,
        n_features: int = 3,
        estimator=None,
        cv=5,
        scoring="accuracy",
        n_jobs=None,
        random_state=0,
    ):
        self.n_features = n_features
        self.estimator = estimator
        self.cv = cv
        self.scoring = scoring
        self.n_jobs = n_jobs
        self.random_state = random_state

    def fit(self, X, y, groups=None):
        X, y = validate_data(self, X, y, ensure_min_features=2)
        n_in = X.shape[1]
        if not (isinstance(self.n_features, (int, np.integer)) and 1 <= self.n_features):
            raise ValueError(f"n_features must be a positive integer, got {self.n_features!r}")
        if self.n_features >= n_in:
            raise ValueError(
                f"n_features={self.n_features} must be smaller than the number of "
                f"input features ({n_in})"
            )
        estimator = default_estimator() if self.estimator is None else clone(self.estimator)
        selector = SequentialFeatureSelector(
            estimator,
            n_features_to_select=int(self.n_features),
            direction="backward",
            scoring=self.scoring,
            cv=self._splits(X, y, groups),
            n_jobs=self.n_jobs,
        )
        # X is checked above; the hundreds of inner fits and scores need not check it (nor the
        # estimator's fixed parameters) again: a fifth of a selection's time on small sets
        with sklearn.config_context(assume_finite=True, skip_parameter_validation=True):
            selector.fit(X, y)
        self.selector_ = selector
        self.support_ = selector.get_support()
        return self

    def _splits(self, X, y, groups):
        if not isinstance(self.cv, (int, np.integer)):
            if groups is None:
                return self.cv
            return list(self.cv.split(X, y, groups))
        if groups is not None:
            n_groups = len(np.unique(groups))
            if n_groups < 2:
                raise ValueError("groups: need at least 2 groups for cross-validation")
            return list(GroupKFold(n_splits=min(int(self.cv), n_groups)).split(X, y, groups))
        _, counts = np.unique(y, return_counts=True)
        n_splits = int(min(self.cv, counts.min()))
        if n_splits < 2:
            raise ValueError("every class needs at least 2 samples for cross-validation")
        return list(
            StratifiedKFold(n_splits=n_splits, shuffle=True, random_state=self.random_state).split(
                X, y
            )
        )

    def _get_support_mask(self):
        check_is_fitted(self, "support_")
        return self.support_

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.target_tags.required = True
        return tags


SELECT_STEP = "select"  # the selector's name in a select_then_classify Pipeline


def select_then_classify(selector: SequentialBackwardSelector, classifier) -> Pipeline:
    """Pipeline: `selector`, then `classifier` on the columns it keeps."""
    return Pipeline([(SELECT_STEP, selector), ("classify", classifier)])


def selected_features(model, feature_names) -> list[str] | None:
    """The names of the features a fitted select_then_classify Pipeline keeps, in input order;
    None for a model without a selection step."""
    if not isinstance(model, Pipeline) or SELECT_STEP not in model.named_steps:
        return None
    mask = model.named_steps[SELECT_STEP].get_support()
    return [str(name) for name, keep in zip(feature_names, mask, strict=True) if keep]


# -- a baseline's own choice: with or without the selection ------------------------------------
ALL_FEATURES = "all features"
BACKWARD = "backward selection"


def record_folds(y, groups, n_splits: int):
    """GroupKFold folds over the records (at most one fold per record), or None when they
    cannot score a classifier: fewer than two records, or a training fold with fewer than two
    classes."""
    y, groups = np.asarray(y), np.asarray(groups)
    n_groups = len(np.unique(groups))
    if n_groups < 2:
        return None
    folds = list(GroupKFold(n_splits=min(int(n_splits), n_groups)).split(y, y, groups))
    if any(len(np.unique(y[train])) < 2 for train, _ in folds):
        return None
    return folds


class SelectionByInnerCV(ClassifierMixin, BaseEstimator):
    """`classifier` on all features, or `selected` (the same classifier behind a backward
    selection, a `select_then_classify` Pipeline), whichever has the higher mean accuracy in
    an inner cross-validation over the training records (folds: `record_folds` with `cv`; a
    tie keeps all features). The selection is never forced: where the training records are too
    few for an inner CV, or for the selector's own folds inside every inner training fold, the
    classifier keeps all features.

    Fitted attributes: `model_` (the chosen estimator refitted on all the training data),
    `choice_` (ALL_FEATURES or BACKWARD), `reason_` (why), `inner_scores_` ({choice: mean inner
    CV accuracy}; empty without an inner CV). `fit(X, y, groups=record_ids)`.
    """

    __metadata_request__fit = {"groups": True}

    def __init__(self, classifier, selected: Pipeline, cv=3):
        self.classifier = classifier
        self.selected = selected
        self.cv = cv

    def fit(self, X, y, groups=None):
        X, y = np.asarray(X), np.asarray(y)
        groups = np.arange(len(y)) if groups is None else np.asarray(groups)
        self.inner_scores_ = {}
        folds = record_folds(y, groups, self.cv)
        selector_cv = self.selected.named_steps[SELECT_STEP].cv
        if folds is None:
            self.choice_, self.reason_ = ALL_FEATURES, "too few records for an inner CV"
        elif any(record_folds(y[train], groups[train], selector_cv) is None for train, _ in folds):
            self.choice_ = ALL_FEATURES
            self.reason_ = "too few records for the selector's folds inside the inner CV"
        else:
            for choice, estimator in ((ALL_FEATURES, self.classifier), (BACKWARD, self.selected)):
                scores = [
                    np.mean(
                        _fit(clone(estimator), X[train], y[train], groups[train]).predict(X[test])
                        == y[test]
                    )
                    for train, test in folds
                ]
                self.inner_scores_[choice] = float(np.mean(scores))
            better = self.inner_scores_[BACKWARD] > self.inner_scores_[ALL_FEATURES]
            self.choice_ = BACKWARD if better else ALL_FEATURES
            self.reason_ = f"inner CV over {len(folds)} record folds"
        chosen = self.selected if self.choice_ == BACKWARD else self.classifier
        self.model_ = _fit(clone(chosen), X, y, groups)
        self.classes_ = self.model_.classes_
        return self

    def predict(self, X):
        check_is_fitted(self, "model_")
        return self.model_.predict(X)


def _fit(estimator, X, y, groups):
    """Fit, handing the record ids to the steps that request them (the selector's folds)."""
    with sklearn.config_context(enable_metadata_routing=True):
        if get_routing_for_object(estimator).consumes("fit", ["groups"]):
            return estimator.fit(X, y, groups=groups)
        return estimator.fit(X, y)

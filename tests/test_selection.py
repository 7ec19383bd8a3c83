"""Sequential backward selection as a Pipeline step: it finds informative features and its choice
comes from the training data of each fit only."""

import numpy as np
import pandas as pd
import pytest
import sklearn
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from sklearn.model_selection import cross_validate
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from condmon.selection import SequentialBackwardSelector


def blobs(informative, n_per_class=40, n_features=8, n_classes=3, seed=0, scale=None):
    """Classes separated along the `informative` columns only; the others are noise."""
    rng = np.random.default_rng(seed)
    y = np.repeat(np.arange(n_classes), n_per_class)
    X = rng.normal(size=(len(y), n_features))
    centres = rng.normal(0, 3, size=(n_classes, len(informative)))
    X[:, informative] += centres[y]
    if scale is not None:
        X = X * scale
    return X, y


def pipeline(**kwargs):
    kwargs.setdefault("cv", 3)  # short test runs
    return Pipeline(
        [
            ("scale", StandardScaler()),
            ("sbs", SequentialBackwardSelector(**kwargs)),
            ("knn", KNeighborsClassifier(n_neighbors=5)),
        ]
    )


def test_selects_the_informative_features_inside_a_pipeline():
    # noise features get large units: a selector scoring unscaled distances would be misled
    scale = np.array([1, 1, 1, 1000, 1000, 1, 1000, 1.0])
    X, y = blobs([1, 4, 6], scale=scale)
    pipe = pipeline().fit(X, y)
    assert list(np.flatnonzero(pipe.named_steps["sbs"].get_support())) == [1, 4, 6]
    assert pipe.score(*blobs([1, 4, 6], seed=0, scale=scale)) > 0.9
    # standalone, with feature names
    names = [f"f{i}" for i in range(8)]
    selector = SequentialBackwardSelector(n_features=3).fit(pd.DataFrame(X, columns=names), y)
    assert list(selector.get_feature_names_out()) == ["f1", "f4", "f6"]
    assert selector.transform(pd.DataFrame(X, columns=names)).shape == (len(y), 3)


def test_choice_depends_on_the_training_data_only():
    # Two halves of the data (think: two sets of records) whose informative features differ.
    Xa, ya = blobs([0, 1, 2], seed=1)
    Xb, yb = blobs([5, 6, 7], seed=2)
    X, y = np.vstack([Xa, Xb]), np.concatenate([ya, yb])
    half = np.arange(len(X)) < len(Xa)
    folds = [
        (np.flatnonzero(half), np.flatnonzero(~half)),
        (np.flatnonzero(~half), np.flatnonzero(half)),
    ]
    result = cross_validate(pipeline(), X, y, cv=folds, return_estimator=True)
    chosen = [
        list(np.flatnonzero(est.named_steps["sbs"].get_support())) for est in result["estimator"]
    ]
    assert chosen == [[0, 1, 2], [5, 6, 7]]  # each fold picks what its training half says
    # selected inside the pipeline, the test half cannot help: chance-level accuracy there
    assert max(result["test_score"]) < 0.6

    # the fitted choice does not move whatever the test data are
    pipe = pipeline().fit(Xa, ya)
    before = pipe.named_steps["sbs"].get_support().copy()
    pipe.predict(Xb)
    pipe.predict(np.random.default_rng(3).normal(size=Xb.shape) * 1e6)
    assert (pipe.named_steps["sbs"].get_support() == before).all()


def test_selection_only_ever_fits_on_training_rows():
    seen = []

    class Spy(KNeighborsClassifier):
        def fit(self, X, y):
            seen.append(len(X))
            return super().fit(X, y)

    X, y = blobs([0, 3, 4], seed=4)
    train = np.arange(len(X)) % 4 != 0
    pipe = pipeline(estimator=Spy(n_neighbors=5), cv=3)
    pipe.fit(X[train], y[train])
    assert seen and max(seen) < train.sum()  # CV folds of the training rows only
    assert list(np.flatnonzero(pipe.named_steps["sbs"].get_support())) == [0, 3, 4]


def test_groups_keep_records_together():
    X, y = blobs([2, 3, 7], n_per_class=30, seed=5)
    groups = np.arange(len(X)) // 10  # 9 "records" of 10 segments, one class each
    # metadata routing: the Pipeline hands groups to the selector, which requests them
    with sklearn.config_context(enable_metadata_routing=True):
        pipe = pipeline(cv=3).fit(X, y, groups=groups)
    sbs = pipe.named_steps["sbs"]
    assert list(np.flatnonzero(sbs.get_support())) == [2, 3, 7]
    assert len(sbs.selector_.cv) == 3
    for train, test in sbs.selector_.cv:
        assert not set(groups[train]) & set(groups[test])
    # fewer records than folds (a measured-only fit on a few records): one fold per record
    few = np.isin(groups, [0, 3, 4, 7])  # four records, of classes 0, 1, 1, 2
    with sklearn.config_context(enable_metadata_routing=True):
        sbs = pipeline(cv=5).fit(X[few], y[few], groups=groups[few]).named_steps["sbs"]
    assert len(sbs.selector_.cv) == 4


def test_parameters_and_errors():
    X, y = blobs([0, 1], n_features=4, seed=6)
    selector = SequentialBackwardSelector(n_features=2, cv=4)
    assert clone(selector).get_params()["n_features"] == 2
    assert selector.fit(X, y).transform(X).shape == (len(y), 2)
    with pytest.raises(ValueError, match="smaller than the number of input features"):
        SequentialBackwardSelector(n_features=4).fit(X, y)
    with pytest.raises(ValueError, match="positive integer"):
        SequentialBackwardSelector(n_features=0).fit(X, y)
    with pytest.raises(NotFittedError):
        SequentialBackwardSelector().transform(X)  # not fitted


def test_select_then_classify_names_its_features_and_predicts_on_them():
    from sklearn.svm import SVC

    from condmon.selection import select_then_classify, selected_features

    X, y = blobs([1, 4, 6])
    groups = np.arange(len(X)) % 12  # 12 groups, each of every class
    names = [f"f{i}" for i in range(8)]
    model = select_then_classify(SequentialBackwardSelector(n_features=3, cv=3), SVC())
    with sklearn.config_context(enable_metadata_routing=True):
        model.fit(X, y, groups=groups)  # SVC requests nothing: the groups go to the selector only
    assert selected_features(model, names) == ["f1", "f4", "f6"]
    for train, test in model.named_steps["select"].selector_.cv:
        assert not set(groups[train]) & set(groups[test])
    shuffled = X.copy()
    shuffled[:, [0, 2, 3, 5, 7]] = 0.0  # dropped columns cannot matter
    assert (model.predict(shuffled) == model.predict(X)).all()
    assert (model.predict(X) == y).mean() > 0.9
    assert selected_features(SVC().fit(X, y), names) is None  # no selection step


# -- the measured-only baseline's own choice: never forced through the selection ------------------
def records_of(y, per_record=10):
    """Record ids: every `per_record` segments of a class one record (y sorted by class)."""
    return np.array([f"r{label}_{i // per_record}" for i, label in enumerate(y)])


def candidates(n_features):
    from condmon.selection import SelectionByInnerCV, select_then_classify

    knn = Pipeline([("scale", StandardScaler()), ("knn", KNeighborsClassifier(n_neighbors=5))])
    selected = select_then_classify(
        SequentialBackwardSelector(n_features=n_features, cv=3), clone(knn)
    )
    return SelectionByInnerCV(knn, selected, cv=3)


def test_the_baseline_keeps_all_features_when_they_score_better():
    from condmon.selection import ALL_FEATURES

    # every feature carries a little of the class: selecting one of six loses
    rng = np.random.default_rng(0)
    y = np.repeat(np.arange(2), 60)
    X = rng.normal(size=(120, 6)) + 0.8 * y[:, None]
    model = candidates(1).fit(X, y, groups=records_of(y))
    assert model.choice_ == ALL_FEATURES
    assert model.inner_scores_[ALL_FEATURES] > model.inner_scores_["backward selection"]
    assert not isinstance(model.model_, Pipeline) or "select" not in model.model_.named_steps


@pytest.mark.slow
def test_the_baseline_selects_when_its_own_records_say_so():
    from condmon.selection import BACKWARD

    rng = np.random.default_rng(3)
    y = np.repeat(np.arange(2), 60)
    X = rng.normal(size=(120, 12))
    X[:, :2] += 2.0 * y[:, None]  # two informative features among ten of noise
    model = candidates(2).fit(X, y, groups=records_of(y))
    assert model.choice_ == BACKWARD, model.inner_scores_
    assert list(np.flatnonzero(model.model_.named_steps["select"].get_support())) == [0, 1]


def test_too_few_records_for_an_inner_cv_means_no_selection():
    from condmon.selection import ALL_FEATURES

    X, y = blobs([0, 1, 2], n_per_class=20, n_features=8, n_classes=2)
    one_record_per_class = np.where(y == 0, "a", "b")
    model = candidates(3).fit(X, y, groups=one_record_per_class)
    assert model.choice_ == ALL_FEATURES and model.reason_ == "too few records for an inner CV"
    assert model.inner_scores_ == {} and model.model_.predict(X[:3]).shape == (3,)
    assert list(model.predict(X)) == list(model.model_.predict(X))

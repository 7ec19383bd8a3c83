"""The classifier and feature-family registries: a new classifier and a new feature family are
each one small piece of code plus one registry line; the config then accepts them (their own
sections and defaults, a bad value named), and the train and features stages use them."""

import numpy as np
import pandas as pd
import pytest
from sklearn.base import BaseEstimator, ClassifierMixin

from condmon import classifiers, features
from condmon.config import ConfigError
from condmon.protocols import make_splits
from condmon.signals import ID_COLUMNS, make_rows, to_arrays, write_signal_table
from condmon.train import run_protocol
from conftest import config_of


# -- a classifier: one small class, one registry line ------------------------------------------
class NearestMean(ClassifierMixin, BaseEstimator):
    """Each class's mean feature vector; a segment gets the class of the nearest mean
    (`shrink` pulls the means toward the overall mean)."""

    def __init__(self, shrink: float = 0.0):
        self.shrink = shrink

    def fit(self, X, y):
        X, y = np.asarray(X, float), np.asarray(y)
        self.classes_ = np.unique(y)
        centre = X.mean(axis=0)
        self.means_ = np.array(
            [
                (1 - self.shrink) * X[y == c].mean(axis=0) + self.shrink * centre
                for c in self.classes_
            ]
        )
        return self

    def predict(self, X):
        distances = ((np.asarray(X, float)[:, None, :] - self.means_[None]) ** 2).sum(axis=2)
        return self.classes_[distances.argmin(axis=1)]


@pytest.fixture
def nearest_mean():
    classifiers.register_classifier(
        "nearest_mean",
        lambda params, seed: NearestMean(**params),
        {"shrink": {"type": "number", "minimum": 0, "maximum": 1, "default": 0.0}},
    )
    yield "nearest_mean"
    del classifiers.CLASSIFIERS["nearest_mean"]


# -- a feature family: one small table function, one registry line ----------------------------
def peak_to_peak_table(signal_frame, channels, params, defect_orders=None):
    """`ptp_<channel>`: each segment's peak-to-peak amplitude (times `params["gain"]`)."""
    ids, arrays = to_arrays(signal_frame, list(channels))
    values = (np.ptp(arrays, axis=2) * params["gain"]).astype(np.float32)
    return pd.concat([ids, pd.DataFrame(values, columns=[f"ptp_{c}" for c in channels])], axis=1)


@pytest.fixture
def peak_to_peak():
    features.register_feature_family(
        "peak_to_peak",
        peak_to_peak_table,
        {
            "type": "object",
            "additionalProperties": False,
            "default": {},
            "properties": {"gain": {"type": "number", "exclusiveMinimum": 0, "default": 1.0}},
        },
    )
    yield "peak_to_peak"
    del features.FEATURE_FAMILIES["peak_to_peak"]


# -- the config accepts them -------------------------------------------------------------------
def test_the_config_accepts_a_registered_classifier_with_its_defaults(nearest_mean):
    config = config_of(changes={"classifiers": {"nearest_mean": {"enabled": True}}})
    assert config["classifiers"]["nearest_mean"] == {"enabled": True, "shrink": 0.0}
    assert {"svm", "knn", "cnn"} < set(config["classifiers"])  # beside the built-in ones
    with pytest.raises(ConfigError, match=r"classifiers\.nearest_mean\.shrink: 2 is greater than"):
        config_of(changes={"classifiers": {"nearest_mean": {"shrink": 2}}})
    with pytest.raises(
        ConfigError,
        match=r"unknown key classifiers\.nearest_mean\.shrnk; allowed keys here: \['enabled', 'shrink'\]",
    ):
        config_of(changes={"classifiers": {"nearest_mean": {"shrnk": 0.5}}})


def test_an_unregistered_classifier_is_an_unknown_key():
    with pytest.raises(ConfigError, match=r"unknown key classifiers\.nearest_mean;"):
        config_of(changes={"classifiers": {"nearest_mean": {"enabled": True}}})


def test_the_config_accepts_a_registered_feature_family_with_its_defaults(peak_to_peak):
    config = config_of(changes={"features": {"kind": "spectrum+peak_to_peak"}})
    assert config["features"]["peak_to_peak"] == {"gain": 1.0}
    with pytest.raises(ConfigError, match=r"features\.peak_to_peak\.gain: 0 is less than or equal"):
        config_of(changes={"features": {"kind": "peak_to_peak", "peak_to_peak": {"gain": 0}}})


def test_an_unregistered_family_is_refused_naming_the_registered_ones():
    with pytest.raises(
        ConfigError,
        match=r"'peak_to_peak' is not a feature family.*built in: spectrum, statistical",
    ):
        config_of(changes={"features": {"kind": "spectrum+peak_to_peak"}})


# -- the stages use them -----------------------------------------------------------------------
def test_a_registered_classifier_is_validated_built_and_trained(nearest_mean):
    assert classifiers.classifier_params(nearest_mean, {}) == {"shrink": 0.0}
    with pytest.raises(ValueError, match=r"classifiers\.nearest_mean\.shrink: -1 is less than"):
        classifiers.make_classifier(nearest_mean, {"shrink": -1})
    with pytest.raises(ValueError, match="already registered"):
        classifiers.register_classifier(nearest_mean, NearestMean, {})
    rng = np.random.default_rng(0)
    rows = [
        {
            "record_id": f"{source}_{label}_{r}",
            "segment": s,
            "source": source,
            "health_state": label,
            "speed_rpm": 600.0,
            "load": 1.0,
            "fs_hz": 1000.0,
            "f0": rng.normal(10.0 * k),
            "f1": rng.normal(-10.0 * k),
        }
        for source in ("simulated", "measured")
        for k, label in enumerate(("healthy", "fault"))
        for r in range(4)
        for s in range(3)
    ]
    table = pd.DataFrame(rows)
    simulated, measured = table[table.source == "simulated"], table[table.source == "measured"]
    splits = make_splits(
        measured[["record_id", "segment", "health_state", "speed_rpm"]],
        "record_split",
        measured_percent=[0, 50],
        repeats=1,
        seed=0,
    )
    predictions, metrics, models = run_protocol(
        nearest_mean, {"shrink": 0.1}, simulated, measured, splits, ["f0", "f1"], seed=0
    )
    assert set(metrics["classifier"]) == {nearest_mean}
    assert all(isinstance(model, NearestMean) and model.shrink == 0.1 for model in models.values())
    assert (metrics["accuracy"] == 1.0).all()  # classes 14 standard deviations apart


def test_a_registered_family_is_computed_beside_the_built_in_ones(peak_to_peak, tmp_path):
    fs, rows = 1000.0, []
    for record, amplitude in (("r1", 1.0), ("r2", 3.0)):
        t = np.arange(2000) / fs
        rows += make_rows(
            record,
            "measured",
            "healthy",
            600.0,
            1.0,
            fs,
            {"A1_x": amplitude * np.sin(2 * np.pi * 50 * t)},
            segment_length=1000,
        )
    path = tmp_path / "signals.parquet"
    write_signal_table(rows, path)
    spectrum = {
        "f_min_hz": 0.0,
        "f_max_hz": 100.0,
        "resolution_hz": 10.0,
        "scale": "linear",
        "band_statistic": "mean",
    }
    frame = features.compute_feature_table_from_files(
        [path],
        ["A1_x"],
        "spectrum+peak_to_peak",
        {"spectrum": spectrum, "peak_to_peak": {"gain": 0.5}},
    )
    columns = [c for c in frame.columns if c not in ID_COLUMNS]
    assert columns[:10] == [f"fft_A1_x_{f:07.1f}Hz" for f in range(5, 100, 10)]
    assert columns[10:] == ["ptp_A1_x"]
    assert np.allclose(frame["ptp_A1_x"], [1.0, 1.0, 3.0, 3.0], rtol=1e-3)  # 0.5 x peak to peak
    with pytest.raises(ValueError, match="already registered"):
        features.register_feature_family("peak_to_peak", peak_to_peak_table)

"""The CNN ensemble: estimator, reproducibility, serialisation, train stage, MLflow logging.

Small synthetic spectra (2 channels x 32 bands, a class-specific peak) and 2-member, 2-epoch
ensembles keep this file at a few seconds.
"""

import json
from pathlib import Path

import joblib
import mlflow
import numpy as np
import pandas as pd
import pytest
import torch

from condmon import tracking
from condmon.classifiers import make_classifier
from condmon.cnn import (
    CNNConfigError,
    CNNEnsembleClassifier,
    channels_from_feature_names,
    validation_split,
)
from condmon.features import write_feature_table
from condmon.hybrid import write_split_table
from condmon.model_store import build_store
from condmon.protocols import make_splits
from condmon.train import (
    HISTORY_FILE,
    PREDICTION_COLUMNS,
    JobCost,
    run_protocol,
    train_info,
    write_metrics,
    write_models,
    write_predictions,
)

CLASSES = ("healthy", "surface_fault", "missing_tooth")
SPEEDS = (450.0, 775.0)
CHANNELS = ("A1_x", "A2_y")
N_BANDS = 32
FEATURES = [f"fft_{c}_{2.0 * b:07.1f}Hz" for c in CHANNELS for b in range(N_BANDS)]
SMALL = {
    "members": 2,
    "epochs": 2,
    "batch_size": 16,
    "conv_channels": [4],
    "input_pool": 1,
    "dense_units": [8],
}

# MLflow's input-example handling raises this, not this code
pytestmark = pytest.mark.filterwarnings("ignore:Operation with range is deprecated")


def spectra(source, n_records, n_segments, seed):
    """Features table: log-like spectra with a peak at a class-specific band, plus noise."""
    rng = np.random.default_rng(seed)
    rows, values = [], []
    for k, label in enumerate(CLASSES):
        for speed in SPEEDS:
            for r in range(n_records):
                for segment in range(n_segments):
                    rows.append(
                        {
                            "record_id": f"{source}_{label}_{int(speed)}_{r:02d}",
                            "segment": segment,
                            "source": source,
                            "health_state": label,
                            "speed_rpm": speed,
                            "load": 10.0,
                            "fs_hz": 5120.0,
                        }
                    )
                    spectrum = rng.normal(0, 0.3, (len(CHANNELS), N_BANDS)) - 3.0
                    spectrum[:, 6 + 8 * k] += 2.0
                    values.append(spectrum.ravel())
    frame = pd.DataFrame(rows)
    frame[FEATURES] = np.asarray(values, dtype=np.float32)
    return frame


SIMULATED = spectra("simulated", n_records=6, n_segments=1, seed=1)
MEASURED = spectra("virtual_bench", n_records=3, n_segments=3, seed=2)
X = SIMULATED[FEATURES].to_numpy(np.float32)
Y = SIMULATED["health_state"].to_numpy()


def fitted(**params):
    return CNNEnsembleClassifier(**{**SMALL, **params}).fit(X, Y, feature_names=FEATURES)


# -- estimator ------------------------------------------------------------------------------
def test_registry_builds_the_ensemble_with_the_seed():
    model = make_classifier("cnn", {"members": 3}, seed=9)
    assert isinstance(model, CNNEnsembleClassifier)
    assert (model.members, model.random_state, model.epochs) == (3, 9, 25)
    with pytest.raises(ValueError, match=r"'layers'.*'cnn'"):
        make_classifier("cnn", {"layers": 2})


def test_fit_predict_shapes_probabilities_and_uncertainty():
    model = fitted(epochs=8)
    assert model.input_shape_ == (len(CHANNELS), N_BANDS)  # one input channel per sensor
    probabilities = model.predict_proba(X[:7])
    assert probabilities.shape == (7, 3)
    np.testing.assert_allclose(probabilities.sum(axis=1), 1, rtol=1e-5)
    members = model.member_proba(X[:7])
    assert members.shape == (2, 7, 3)
    np.testing.assert_allclose(members.mean(axis=0), probabilities)
    labels, spread = model.predict_with_uncertainty(X[:7])
    assert list(labels) == list(model.predict(X[:7]))
    chosen = probabilities.argmax(axis=1)
    np.testing.assert_allclose(spread, members[:, np.arange(7), chosen].std(axis=0), rtol=1e-6)
    assert ((spread >= 0) & (spread <= 0.5)).all()
    assert set(model.classes_) == set(CLASSES)
    # an easy problem: the ensemble gets most of the measured spectra right after 8 epochs
    measured = MEASURED[FEATURES].to_numpy(np.float32)
    assert (model.predict(measured) == MEASURED["health_state"].to_numpy()).mean() > 0.8


def test_same_seed_same_model_other_seed_other_model():
    first, second = fitted(random_state=4), fitted(random_state=4)
    np.testing.assert_array_equal(first.predict_proba(X), second.predict_proba(X))
    assert first.history_ == second.history_
    other = fitted(random_state=5)
    assert not np.array_equal(first.predict_proba(X), other.predict_proba(X))
    # the estimator leaves the process-wide settings as it found them
    assert not torch.are_deterministic_algorithms_enabled()


def test_standardisation_comes_from_the_training_data_only():
    model = fitted(standardize="channel")
    blocks = X.reshape(len(X), len(CHANNELS), N_BANDS)
    np.testing.assert_allclose(
        model.mean_.reshape(len(CHANNELS), N_BANDS)[:, 0], blocks.mean(axis=(0, 2)), rtol=1e-5
    )
    before = model.mean_.copy()
    model.predict(MEASURED[FEATURES].to_numpy(np.float32) + 100.0)  # never refits on test data
    np.testing.assert_array_equal(model.mean_, before)
    per_band = fitted(standardize="feature")
    np.testing.assert_allclose(per_band.mean_, X.mean(axis=0), rtol=1e-5)


def test_validation_split_keeps_records_whole_and_every_class_in_training():
    codes = np.repeat([0, 1, 2], 12)
    groups = np.repeat(np.arange(12), 3)  # 4 records of 3 segments per class
    val = validation_split(codes, groups, 0.25, np.random.default_rng(0))
    for group in np.unique(groups):
        assert len(set(val[groups == group])) == 1  # a record is on one side only
    for code in range(3):
        assert 0 < val[codes == code].sum() < (codes == code).sum()
    assert not validation_split(codes, groups, 0.0, np.random.default_rng(0)).any()


def test_early_stopping_history_and_member_info():
    model = fitted(epochs=30, patience=1, learning_rate=0.05)
    history = pd.DataFrame(model.history_)
    assert list(history.columns) == [
        "member",
        "epoch",
        "train_loss",
        "train_accuracy",
        "val_loss",
        "val_accuracy",
    ]
    for info in model.member_info_:
        rows = history[history.member == info["member"]]
        assert len(rows) == info["epochs_run"]
        assert info["best_epoch"] == rows.epoch[rows.val_loss.idxmin()]
        assert info["n_val"] > 0
    assert any(info["epochs_run"] < 30 for info in model.member_info_)  # stopped early
    # where it trained, as the MLflow run logs it (device "auto": the GPU if PyTorch sees one)
    assert (
        model.device_.startswith("cuda:") if torch.cuda.is_available() else model.device_ == "cpu"
    )


def test_epochs_are_logged_at_most_every_few_seconds(caplog, monkeypatch):
    from condmon import cnn

    with caplog.at_level("INFO", logger="condmon.cnn"):
        fitted(epochs=3, patience=5)
    lines = [r.getMessage() for r in caplog.records if ", epoch " in r.getMessage()]
    assert len(lines) == 2 and lines[0].startswith(
        "CNN member 1 of 2, epoch 1 of at most 3: train loss"
    )
    caplog.clear()
    monkeypatch.setattr(cnn, "EPOCH_LOG_SECONDS", 0.0)
    with caplog.at_level("INFO", logger="condmon.cnn"):
        fitted(epochs=3, patience=5)
    assert sum(", epoch " in r.getMessage() for r in caplog.records) == 6  # 2 members x 3 epochs


def test_joblib_round_trip_and_torch_export(tmp_path):
    model = fitted()
    joblib.dump(model, tmp_path / "model.joblib")
    loaded = joblib.load(tmp_path / "model.joblib")
    np.testing.assert_array_equal(loaded.predict_proba(X), model.predict_proba(X))
    module = loaded.to_torch_module()
    with torch.no_grad():
        exported = module(torch.from_numpy(X)).numpy()
    np.testing.assert_allclose(exported, model.predict_proba(X), rtol=1e-5, atol=1e-6)
    assert module.classes == list(model.classes_)


def test_side_features_join_after_the_convolutions(tmp_path):
    """Residual bands as their shape cannot show a fault that raises every band alike; an
    indicator beside them can. With `side_features` the ensemble reads it (standardised on the
    training data), without it the indicator is left out and the classes stay apart only by
    chance; the exported module and a pickled model give the same probabilities."""
    rng = np.random.default_rng(3)
    names = [f"res_{c}_pinion_b{b:02d}" for c in CHANNELS for b in range(12)] + [
        f"res_{c}_pinion_tooth_peak1" for c in CHANNELS
    ]
    labels = np.repeat(["healthy", "missing_tooth"], 40)
    bands = rng.normal(0.0, 1.0, (80, 24))  # the same shapes in both classes
    peaks = rng.normal(0.0, 0.2, (80, 2)) + 3.0 * (labels == "missing_tooth")[:, None] + 50.0
    x = np.hstack([bands, peaks]).astype(np.float32)
    params = {**SMALL, "epochs": 20, "input_pool": 1, "kernel_size": 3, "pool_size": 2}
    side = CNNEnsembleClassifier(**params, side_features=True).fit(x, labels, feature_names=names)
    np.testing.assert_array_equal(side.side_columns_, [24, 25])
    np.testing.assert_allclose(side.side_mean_, peaks.mean(axis=0), rtol=1e-5)
    assert side.input_shape_ == (2, 12)
    test = np.hstack(
        [rng.normal(0.0, 1.0, (40, 24)), peaks[::2] + rng.normal(0.0, 0.2, (40, 2))]
    ).astype(np.float32)
    assert (side.predict(test) == labels[::2]).mean() > 0.95
    alone = CNNEnsembleClassifier(**params).fit(x, labels, feature_names=names)
    assert alone.side_columns_ is None and (alone.predict(test) == labels[::2]).mean() < 0.8
    joblib.dump(side, tmp_path / "side.joblib")
    loaded = joblib.load(tmp_path / "side.joblib")
    np.testing.assert_array_equal(loaded.predict_proba(test), side.predict_proba(test))
    with torch.no_grad():
        exported = loaded.to_torch_module()(torch.from_numpy(test)).numpy()
    np.testing.assert_allclose(exported, side.predict_proba(test), rtol=1e-5, atol=1e-6)
    with pytest.raises(CNNConfigError, match="side_features"):
        CNNEnsembleClassifier(side_features="yes").fit(x, labels, feature_names=names)


def test_channels_from_feature_names():
    assert channels_from_feature_names(FEATURES) == 2
    assert channels_from_feature_names(["fft_A1_x_0010.0Hz", "fft_A1_x_0020.0Hz"]) == 1
    assert channels_from_feature_names(["f1", "f2"]) is None
    # interleaved channels are not blocks
    assert channels_from_feature_names(["fft_a_1.0Hz", "fft_b_1.0Hz", "fft_a_2.0Hz"]) is None
    model = CNNEnsembleClassifier(**SMALL).fit(X, Y)  # no names: one long sequence
    assert model.input_shape_ == (1, len(FEATURES))


@pytest.mark.parametrize(
    "params, message",
    [
        ({"members": 0}, "members=0"),
        ({"conv_channels": []}, "conv_channels is empty"),
        ({"dropout": 1.0}, "dropout=1.0"),
        ({"device": "tpu"}, "device='tpu'"),
        ({"standardize": "global"}, "standardize='global'"),
        ({"input_channels": 3}, "input_channels=3: 64 features do not split"),
        ({"pool_size": 8, "conv_channels": [4, 4]}, "pooled away"),
    ],
)
def test_bad_parameters_are_named(params, message):
    with pytest.raises(CNNConfigError, match=message):
        CNNEnsembleClassifier(**{**SMALL, **params}).fit(X, Y, feature_names=FEATURES)


# -- train stage ------------------------------------------------------------------------------
def test_run_protocol_with_a_subset_uncertainty_and_history(tmp_path):
    splits = make_splits(
        MEASURED[["record_id", "health_state", "speed_rpm"]],
        "condition_holdout",
        measured_percent=[0, 50, 100],
        repeats=2,
        seed=3,
    )
    predictions, metrics, models = run_protocol(
        "cnn",
        SMALL,
        SIMULATED,
        MEASURED,
        splits,
        FEATURES,
        seed=1,
        measured_percent=[0, 100],
        repeats=1,
    )
    assert set(models) == {(p, 0, h) for p in (0, 100) for h in ("speed_rpm=450", "speed_rpm=775")}
    assert set(metrics.measured_percent) == {0, 100} and set(metrics.repeat) == {0}
    assert list(predictions.columns) == PREDICTION_COLUMNS
    assert predictions.uncertainty.notna().all() and (predictions.uncertainty >= 0).all()
    entries = write_models(models, tmp_path / "models", FEATURES)
    assert entries[0]["members"][0]["epochs_run"] <= 2
    history = pd.read_parquet(tmp_path / "models" / HISTORY_FILE)
    assert len(history) == sum(len(m.history_) for m in models.values())
    assert set(history.holdout) == {"speed_rpm=450", "speed_rpm=775"}
    write_predictions(predictions, tmp_path / "predictions.parquet")
    assert pd.read_parquet(tmp_path / "predictions.parquet").uncertainty.notna().all()

    # SVM keeps the column, empty
    svm_predictions, _, _ = run_protocol("svm", {}, SIMULATED, MEASURED, splits, FEATURES, 1)
    assert svm_predictions.uncertainty.isna().all()


def test_subset_errors_name_the_config_key():
    splits = make_splits(
        MEASURED[["record_id", "health_state", "speed_rpm"]],
        "record_split",
        measured_percent=[0, 50],
        repeats=1,
        seed=3,
    )
    with pytest.raises(ValueError, match=r"classifiers.cnn.measured_percent: \[30\].*\[0, 50\]"):
        run_protocol(
            "cnn", SMALL, SIMULATED, MEASURED, splits, FEATURES, 1, measured_percent=[0, 30]
        )
    with pytest.raises(ValueError, match=r"classifiers.cnn.repeats: 2 .* 1 repeat"):
        run_protocol("cnn", SMALL, SIMULATED, MEASURED, splits, FEATURES, 1, repeats=2)


def test_tracking_logs_curves_and_the_ensemble_as_a_signal_model(tmp_path):
    """The track job's logging of a CNN fit: its members' mean curves and their table, and the
    packaged ensemble (the run's model store) as an MLflow pyfunc model whose estimator is the
    fitted one, torch among its requirements."""
    root = tmp_path / "results" / "cnn_demo"
    write_feature_table(MEASURED, FEATURES, root / "features/measured.parquet")
    write_feature_table(SIMULATED, FEATURES, root / "features/simulated.parquet")
    splits = make_splits(
        MEASURED[["record_id", "health_state", "speed_rpm"]],
        "record_split",
        measured_percent=[0],
        repeats=1,
        seed=3,
    )
    predictions, metrics, models = run_protocol(
        "cnn", SMALL, SIMULATED, MEASURED, splits, FEATURES, seed=1
    )
    out = root / "train/cnn/record_split"
    write_predictions(predictions, out / "predictions.parquet")
    write_metrics(metrics, out / "metrics.csv")
    entries = write_models(models, out / "models", FEATURES)
    (out / "info.json").write_text(
        json.dumps(
            train_info(
                "cnn", SMALL, 1, "record_split", CLASSES, FEATURES, metrics, entries, JobCost(1.0)
            )
        )
    )
    write_split_table(splits, root / "hybrid/record_split.parquet")
    signals = MEASURED.iloc[:1].assign(channel="A1_x", signal=[np.zeros(256, np.float32)])
    signals.drop(columns=FEATURES).to_parquet(root / "signals.parquet")
    tables = [root / "features/measured.parquet", root / "features/simulated.parquet"]
    store = root / "models/hash-c"
    build_store(
        store,
        [out],
        {"record_split": root / "hybrid/record_split.parquet"},
        root / "signals.parquet",
        tables[1],
        tables[0],
        {"kind": "spectrum", "channels": list(CHANNELS)},
        "healthy",
        None,
        "hash-c",
    )
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    info = tracking.log_pipeline_run(
        uri,
        tracking.TrackedRun("cnn_demo", "hash-c", "virtual_bench"),
        [out],
        {"measured_features": tables[:1], "simulated_features": tables[1:]},
        store,
        log_models="all",
        workdir=tmp_path,
    )
    assert info["n_nested_runs"] == info["n_models_logged"] == 1
    client = mlflow.MlflowClient(info["tracking_uri"])
    run = client.search_runs(
        [info["experiment_id"]], f"tags.mlflow.parentRunId = '{info['parent_run_id']}'"
    )[0]
    assert run.data.params["classifier.members"] == "2"
    assert run.data.params["classifier.conv_channels"] == "[4]"
    assert 0 <= run.data.metrics["uncertainty_mean"] <= 0.5
    model = models[(0, 0, "")]
    assert len(client.get_metric_history(run.info.run_id, "val_loss")) == max(
        i["epochs_run"] for i in model.member_info_
    )  # the members' mean, step = epoch
    members = pd.read_csv(client.download_artifacts(run.info.run_id, "training_history.csv"))
    assert list(members.loc[members.member == 1, "epoch"]) == [
        r["epoch"] for r in model.history_ if r["member"] == 1
    ]

    logged = mlflow.search_logged_models(
        experiment_ids=[info["experiment_id"]], output_format="list"
    )
    assert len(logged) == 1 and logged[0].source_run_id == run.info.run_id
    # the run's metrics, the curves among them, are the model's
    assert {m.key for m in logged[0].metrics} >= {"accuracy", "val_loss", "uncertainty_mean"}
    loaded = mlflow.pyfunc.load_model(logged[0].model_uri).unwrap_python_model().model
    np.testing.assert_allclose(
        loaded.estimator.predict_proba(X[:3]), model.predict_proba(X[:3]), rtol=1e-5, atol=1e-6
    )
    assert loaded.classes == list(model.classes_)
    assert run.data.params["device"] == "cpu"
    requirements = Path(mlflow.pyfunc.get_model_dependencies(logged[0].model_uri)).read_text()
    assert "torch==" in requirements

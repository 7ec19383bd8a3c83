"""Classifier registry, run_protocol on synthetic features, outputs, and the three scripts."""

import json
import logging
import runpy
from types import SimpleNamespace

import joblib
import numpy as np
import pandas as pd
import pytest
from sklearn.neighbors import KNeighborsClassifier
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from conftest import SCRIPTS
from condmon.classifiers import make_classifier
from condmon.features import read_feature_table
from condmon.hybrid import read_split_table
from condmon.protocols import make_splits
from condmon.signals import ID_COLUMNS, make_rows, write_signal_table
from condmon.selection import selected_features
from condmon.train import (
    METRIC_COLUMNS,
    PREDICTION_COLUMNS,
    model_filename,
    run_protocol,
    write_metrics,
    write_models,
)

CLASSES = ("healthy", "surface_fault", "missing_tooth")
SPEEDS = (450.0, 775.0)
N_FEATURES = 12
FEATURES = [f"f{i:02d}" for i in range(N_FEATURES)]


def synthetic_features(source, n_records, n_segments, seed, separable=True):
    """Features table: each class a well-separated cluster (or pure noise if not separable)."""
    rng = np.random.default_rng(seed)
    rows, values = [], []
    for label_index, label in enumerate(CLASSES):
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
                            "load": 1.0,
                            "fs_hz": 5120.0,
                        }
                    )
                    centre = np.zeros(N_FEATURES)
                    if separable:
                        centre[label_index] = 8.0
                    values.append(centre + rng.normal(size=N_FEATURES))
    frame = pd.DataFrame(rows)
    frame[FEATURES] = np.asarray(values, dtype=np.float32)
    return frame


SIMULATED = synthetic_features("simulated", n_records=4, n_segments=5, seed=1)
MEASURED = synthetic_features("measured", n_records=6, n_segments=4, seed=2)


def splits_for(measured, protocol="record_split", percents=(0, 50), repeats=2, seed=0, **kwargs):
    return make_splits(
        measured[["record_id", "segment", "health_state", "speed_rpm"]],
        protocol,
        measured_percent=list(percents),
        repeats=repeats,
        seed=seed,
        **kwargs,
    )


# -- classifiers -----------------------------------------------------------------------------
def test_svm_is_scaled_rbf_with_study_defaults():
    pipeline = make_classifier("svm", {}, seed=3)
    scaler, svm = (step for _, step in pipeline.steps)
    assert isinstance(scaler, StandardScaler) and isinstance(svm, SVC)
    assert (svm.kernel, svm.C, svm.gamma, svm.random_state) == ("rbf", 1.2, "scale", 3)
    assert make_classifier("svm", {"C": 10, "class_weight": "balanced"}).steps[1][1].C == 10


def test_knn_parameters():
    knn = make_classifier("knn", {"n_neighbors": 3, "weights": "distance"}).steps[1][1]
    assert isinstance(knn, KNeighborsClassifier)
    assert (knn.n_neighbors, knn.weights) == (3, "distance")


def test_unknown_classifier_and_parameter_are_named():
    with pytest.raises(ValueError, match=r"'forest'.*cnn.*knn.*svm"):
        make_classifier("forest", {})
    with pytest.raises(ValueError, match=r"'gama'.*'svm'"):
        make_classifier("svm", {"gama": 0.1})


# -- run_protocol ----------------------------------------------------------------------------
def test_separable_data_is_classified_perfectly_with_per_speed_rows():
    splits = splits_for(MEASURED)
    predictions, metrics, models = run_protocol(
        "svm", {}, SIMULATED, MEASURED, splits, FEATURES, seed=0
    )
    assert list(metrics.columns) == METRIC_COLUMNS
    assert list(predictions.columns) == PREDICTION_COLUMNS
    assert (metrics.accuracy == 1.0).all() and (metrics.macro_f1 == 1.0).all()
    assert set(models) == {(p, r, "") for p in (0, 50) for r in (0, 1)}
    for (percent, repeat), group in metrics.groupby(["measured_percent", "repeat"]):
        overall = group[group.speed_rpm.isna()]
        per_speed = group[group.speed_rpm.notna()]
        assert len(overall) == 1 and sorted(per_speed.speed_rpm) == list(SPEEDS)
        assert per_speed.n_test.sum() == overall.n_test.iloc[0]
        test_ids = set(
            splits.record_id[
                (splits.measured_percent == percent)
                & (splits.repeat == repeat)
                & (splits.role == "test")
            ]
        )
        n_test_segments = MEASURED.record_id.isin(test_ids).sum()
        assert overall.n_test.iloc[0] == n_test_segments
        assert overall.n_train_simulated.iloc[0] == len(SIMULATED)
        assert overall.n_train_measured.iloc[0] == len(MEASURED) - n_test_segments
        got = predictions[
            (predictions.measured_percent == percent) & (predictions.repeat == repeat)
        ]
        assert set(got.record_id) == test_ids and len(got) == n_test_segments
    assert (metrics.n_train_measured[metrics.measured_percent == 0] == 0).all()
    assert (metrics.n_train_measured[metrics.measured_percent == 50] > 0).all()


def test_shuffled_labels_give_chance_accuracy():
    rng = np.random.default_rng(5)
    sim = synthetic_features("simulated", n_records=4, n_segments=5, seed=1)
    meas = synthetic_features("measured", n_records=10, n_segments=4, seed=2)
    for frame in (sim, meas):  # shuffle labels between records: features carry no label
        records = frame.record_id.unique()
        record_labels = frame.groupby("record_id").health_state.first()[records]
        labels = dict(zip(records, rng.permutation(record_labels)))
        frame["health_state"] = frame.record_id.map(labels)
    _, metrics, _ = run_protocol(
        "svm", {}, sim, meas, splits_for(meas, percents=[0], repeats=1), FEATURES, seed=0
    )
    overall = metrics[metrics.speed_rpm.isna()].accuracy.iloc[0]
    assert abs(overall - 1 / 3) < 0.2


def test_condition_holdout_evaluates_only_the_held_out_speed():
    splits = splits_for(MEASURED, "condition_holdout", percents=[0, 100], repeats=1)
    predictions, metrics, models = run_protocol(
        "knn", {"n_neighbors": 3}, SIMULATED, MEASURED, splits, FEATURES, seed=0
    )
    assert set(models) == {(p, 0, h) for p in (0, 100) for h in ("speed_rpm=450", "speed_rpm=775")}
    for holdout, group in metrics.groupby("holdout"):
        held_out = float(holdout.split("=")[1])
        assert sorted(group.speed_rpm.dropna().unique()) == [held_out]
        assert set(predictions.speed_rpm[predictions.holdout == holdout]) == {held_out}
    at_100 = metrics[(metrics.measured_percent == 100) & metrics.speed_rpm.isna()]
    assert (at_100.n_train_measured == len(MEASURED) // 2).all()
    # at 0 % the other speed's records are "unused": neither trained on nor tested
    at_0 = metrics[(metrics.measured_percent == 0) & metrics.speed_rpm.isna()]
    assert (at_0.n_train_measured == 0).all() and (at_0.n_test == len(MEASURED) // 2).all()
    assert (metrics.accuracy == 1.0).all()


def test_split_without_test_records_is_skipped_with_a_warning(caplog):
    splits = splits_for(MEASURED, percents=[50], repeats=2)
    splits.loc[splits.repeat == 1, "role"] = "train"
    with caplog.at_level(logging.WARNING, logger="condmon.train"):
        _, metrics, models = run_protocol("knn", {}, SIMULATED, MEASURED, splits, FEATURES, 0)
    assert set(metrics.repeat) == {0} and set(models) == {(50, 0, "")}
    assert "repeat=1" in caplog.text and "no test records" in caplog.text


def test_unknown_record_and_missing_feature_are_named():
    splits = splits_for(MEASURED, percents=[50], repeats=1)
    bad = splits.copy()
    bad.loc[0, "record_id"] = "ghost_record"
    with pytest.raises(ValueError, match="ghost_record"):
        run_protocol("svm", {}, SIMULATED, MEASURED, bad, FEATURES, 0)
    with pytest.raises(ValueError, match=r"simulated features lack column\(s\) \['f99'\]"):
        run_protocol("svm", {}, SIMULATED, MEASURED, splits, FEATURES + ["f99"], 0)


def test_results_are_deterministic():
    splits = splits_for(MEASURED, percents=[50], repeats=1)
    first = run_protocol("svm", {}, SIMULATED, MEASURED, splits, FEATURES, seed=4)
    second = run_protocol("svm", {}, SIMULATED, MEASURED, splits, FEATURES, seed=4)
    pd.testing.assert_frame_equal(first[0], second[0])
    pd.testing.assert_frame_equal(
        first[1].drop(columns="fit_seconds"), second[1].drop(columns="fit_seconds")
    )


def test_model_files_and_metrics_csv(tmp_path):
    splits = splits_for(MEASURED, "condition_holdout", percents=[50], repeats=1)
    _, metrics, models = run_protocol("knn", {}, SIMULATED, MEASURED, splits, FEATURES, 0)
    entries = write_models(models, tmp_path / "models", FEATURES)
    assert sorted(p.name for p in (tmp_path / "models").iterdir()) == [
        "p050_r0_h0.joblib",
        "p050_r0_h1.joblib",
    ]
    assert entries[1] == {
        "file": "p050_r0_h1.joblib",
        "measured_percent": 50,
        "repeat": 0,
        "holdout": "speed_rpm=775",
        "holdout_index": 1,
    }
    model = joblib.load(tmp_path / "models" / "p050_r0_h1.joblib")
    assert model.predict(MEASURED[FEATURES].to_numpy()[:1])[0] == "healthy"
    assert model_filename(0, 3) == "p000_r3.joblib"
    write_metrics(metrics, tmp_path / "metrics.csv")
    lines = (tmp_path / "metrics.csv").read_text().splitlines()
    assert lines[0] == ",".join(METRIC_COLUMNS)
    assert lines[1].split(",")[5] == ""  # all-speeds row: empty speed_rpm


# -- the Snakemake scripts, with a stand-in snakemake object --------------------------------
class FakeSnakemake(SimpleNamespace):
    """Enough of Snakemake's script object: rule, input, output, params, log, threads."""


def run_script(name, **attributes):
    fake = FakeSnakemake(rule=name.removesuffix(".py"), threads=1, **attributes)
    runpy.run_path(str(SCRIPTS / name), init_globals={"snakemake": fake})


def write_signals(path, source, n_records, seed):
    """Records carrying a class-specific tone (100/200/300 Hz) plus noise on both channels."""
    rng = np.random.default_rng(seed)
    fs, n = 1024.0, 2048
    t = np.arange(n) / fs
    rows = []
    for k, label in enumerate(CLASSES):
        for speed in SPEEDS:
            for r in range(n_records):
                tone = np.sin(2 * np.pi * 100 * (k + 1) * t)
                channels = {
                    "A1_x": tone + 0.05 * rng.normal(size=n),
                    "A1_y": 0.5 * tone + 0.05 * rng.normal(size=n),
                }
                rows += make_rows(
                    f"{source}_{label}_{int(speed)}_{r}",
                    source,
                    label,
                    speed,
                    1.0,
                    fs,
                    channels,
                    segment_length=1024,
                )
    write_signal_table(rows, path)


def test_scripts_run_end_to_end(tmp_path, isolated_logging):
    spectrum = {"f_min_hz": 64, "f_max_hz": 320, "resolution_hz": 64, "scale": "log"}
    channels = ["A1_x", "A1_y"]
    (tmp_path / "logs").mkdir()  # Snakemake creates log directories before the job starts
    write_signals(tmp_path / "sim_a.parquet", "simulated", 2, seed=1)
    write_signals(tmp_path / "measured.parquet", "virtual_bench", 3, seed=2)
    # a second simulated batch, so the features script concatenates several tables
    write_signals(tmp_path / "sim_b.parquet", "simulated", 1, seed=3)
    frame = pd.read_parquet(tmp_path / "sim_b.parquet")
    frame["record_id"] = frame.record_id + "_b"
    write_signal_table(frame, tmp_path / "sim_b.parquet")

    for name, inputs in (
        ("simulated", [tmp_path / "sim_a.parquet", tmp_path / "sim_b.parquet"]),
        ("measured", str(tmp_path / "measured.parquet")),
    ):
        run_script(
            "features.py",
            input=SimpleNamespace(signals=inputs),
            output=SimpleNamespace(features=tmp_path / f"features/{name}.parquet"),
            params=SimpleNamespace(
                channels=channels, spectrum=spectrum, system={"name": "gear", "config": {}}
            ),
            log=[str(tmp_path / f"logs/features_{name}.log")],
        )
    simulated, names = read_feature_table(tmp_path / "features/simulated.parquet")
    assert len(simulated) == 3 * 2 * 3 * 2 and len(names) == 8
    assert list(simulated.columns[: len(ID_COLUMNS)]) == ID_COLUMNS

    measured, _ = read_feature_table(tmp_path / "features/measured.parquet")
    records = (
        measured[["record_id", "health_state", "speed_rpm"]].drop_duplicates().assign(status="kept")
    )
    records.to_csv(tmp_path / "records.csv", index=False)  # the measured stage's record list
    run_script(
        "hybrid.py",
        input=SimpleNamespace(
            features=tmp_path / "features/measured.parquet", records=tmp_path / "records.csv"
        ),
        output=SimpleNamespace(splits=tmp_path / "hybrid/record_split.parquet"),
        params=SimpleNamespace(
            protocol="record_split",
            measured_percent=[0, 50],
            repeats=2,
            seed=1,
            min_test_records=1,
            healthy_state="healthy",
            reserve={},
        ),
        log=[str(tmp_path / "logs/hybrid.log")],
    )
    splits = read_split_table(tmp_path / "hybrid/record_split.parquet")
    # every record in every (percentage, repeat); the healthy calibration set is never a test record
    assert splits.groupby(["measured_percent", "repeat"]).record_id.nunique().eq(18).all()
    assert (splits.role == "calibration").any() and len(
        splits.groupby(["measured_percent", "repeat"])
    ) == 2 * 2

    out = tmp_path / "train/svm/record_split"
    run_script(
        "train.py",
        input=SimpleNamespace(
            simulated=tmp_path / "features/simulated.parquet",
            measured=tmp_path / "features/measured.parquet",
            splits=tmp_path / "hybrid/record_split.parquet",
        ),
        output=SimpleNamespace(
            predictions=out / "predictions.parquet",
            metrics=out / "metrics.csv",
            models=out / "models",
            info=out / "info.json",
            measured_only=out / "measured_only.csv",
            measured_only_predictions=out / "measured_only_predictions.parquet",
        ),
        params=SimpleNamespace(
            classifier="svm",
            classifier_params={"C": 1.2},
            seed=1,
            feature_selection={"n_features": None},
            measured_only_baseline=True,
        ),
        log=[str(tmp_path / "logs/train.log")],
    )
    metrics = pd.read_csv(out / "metrics.csv")
    assert (metrics.accuracy == 1.0).all() and len(metrics) == 4 * 3
    # the baseline: nothing measured trains at 0 %, so only the 50 % splits have one
    baseline = pd.read_csv(out / "measured_only.csv")
    assert set(baseline.measured_percent) == {50} and (baseline.n_train_simulated == 0).all()
    # and its predictions, on the same test segments as the hybrid's at 50 %
    alone = pd.read_parquet(out / "measured_only_predictions.parquet")
    hybrid = pd.read_parquet(out / "predictions.parquet")
    key = ["repeat", "holdout", "record_id", "segment"]
    assert (
        alone.sort_values(key)[key]
        .reset_index(drop=True)
        .equals(hybrid[hybrid.measured_percent == 50].sort_values(key)[key].reset_index(drop=True))
    )
    assert sorted(p.name for p in (out / "models").iterdir()) == [
        "p000_r0.joblib",
        "p000_r1.joblib",
        "p050_r0.joblib",
        "p050_r1.joblib",
    ]
    info = json.loads((out / "info.json").read_text())
    assert info["labels"] == sorted(CLASSES) and info["n_features"] == 8
    assert info["classifier_params"] == {
        "C": 1.2,
        "gamma": "scale",
        "class_weight": None,
        "standardize": "feature",
    }
    assert "accuracy 1.000" in (tmp_path / "logs/train.log").read_text()
    assert not list(out.glob(".*tmp*"))  # no temporary files left behind


# -- segment_share, unseen_fault, selection inside the fit, measured-only baseline ---------------
def test_segment_share_trains_and_tests_single_segments():
    splits = splits_for(MEASURED, "segment_share", percents=(50,), repeats=1)
    predictions, metrics, _ = run_protocol("knn", {}, SIMULATED, MEASURED, splits, FEATURES, seed=0)
    n_segments = len(MEASURED)
    assert metrics.iloc[0].n_train_measured + metrics.iloc[0].n_test == n_segments
    tested = set(zip(predictions.record_id, predictions.segment))
    trained = splits[splits.role == "train"]
    assert not tested & set(zip(trained.record_id, trained.segment))
    # segments of one record on both sides: that is what makes the protocol leaky
    assert set(predictions.record_id) & set(trained.record_id)


def test_unseen_fault_measured_only_baseline_predicts_the_one_class_it_saw():
    splits = splits_for(
        MEASURED, "unseen_fault", percents=(0, 50), repeats=1, measured_classes=["healthy"]
    )
    _, metrics, _ = run_protocol("svm", {}, SIMULATED, MEASURED, splits, FEATURES, seed=0)
    _, baseline, models = run_protocol("svm", {}, None, MEASURED, splits, FEATURES, seed=0)
    assert set(baseline.measured_percent) == {50}  # nothing measured trains at 0 %
    overall = baseline[baseline.speed_rpm.isna()].iloc[0]
    n_healthy_test = (MEASURED.health_state == "healthy").sum() - overall.n_train_measured
    assert overall.accuracy == pytest.approx(n_healthy_test / overall.n_test)
    assert list(models[(50, 0, "")].predict(MEASURED[FEATURES].to_numpy())) == ["healthy"] * len(
        MEASURED
    )
    assert (metrics[metrics.speed_rpm.isna()].accuracy == 1.0).all()


def test_backward_selection_inside_each_fit_keeps_the_informative_features(tmp_path):
    splits = splits_for(MEASURED, percents=(0,), repeats=1)
    _, metrics, models = run_protocol(
        "svm",
        {},
        SIMULATED,
        MEASURED,
        splits,
        FEATURES,
        seed=0,
        feature_selection={"n_features": 3, "cv": 3},
    )
    model = models[(0, 0, "")]
    chosen = selected_features(model, FEATURES)
    # two of the three class-bearing columns already separate three classes
    assert len(chosen) == 3
    assert len(set(chosen) & set(FEATURES[:3])) >= 2
    assert (metrics.accuracy == 1.0).all()
    # the record ids reached the selector: its folds keep every record whole
    records = SIMULATED.record_id.to_numpy()  # at 0 % only the simulated records train
    for train, test in model.named_steps["select"].selector_.cv:
        assert not set(records[train]) & set(records[test])
    entries = write_models(models, tmp_path / "models", FEATURES)
    assert entries[0]["selected_features"] == chosen


@pytest.mark.slow
def test_the_measured_only_baseline_is_never_forced_through_the_selection(tmp_path):
    """With features.selection configured, the hybrid fit selects 3 features; the baseline
    chooses by its own inner CV, here all features (they score as well), and says so."""
    from condmon.selection import ALL_FEATURES, SelectionByInnerCV
    from condmon.train import BASELINE_COLUMNS

    splits = splits_for(MEASURED, percents=(50,), repeats=1)
    selection = {"n_features": 3, "cv": 3}
    _, _, hybrid = run_protocol(
        "knn", {}, SIMULATED, MEASURED, splits, FEATURES, seed=0, feature_selection=selection
    )
    assert len(selected_features(hybrid[(50, 0, "")], FEATURES)) == 3
    _, baseline, models = run_protocol(
        "knn", {}, None, MEASURED, splits, FEATURES, seed=0, feature_selection=selection
    )
    model = models[(50, 0, "")]
    assert isinstance(model, SelectionByInnerCV) and model.choice_ == ALL_FEATURES
    assert selected_features(model.model_, FEATURES) is None  # no selection step at all
    assert set(model.inner_scores_) == {ALL_FEATURES, "backward selection"}
    assert (baseline.selection == ALL_FEATURES).all()
    assert (baseline.selected_features == ";".join(FEATURES)).all()
    assert baseline.selection_reason.str.startswith("inner CV").all()
    write_metrics(baseline, tmp_path / "measured_only.csv", BASELINE_COLUMNS)
    written = pd.read_csv(tmp_path / "measured_only.csv")
    assert list(written.columns) == BASELINE_COLUMNS
    assert written.inner_cv_all_features.notna().all()


# -- fits shared by splits of one training set -----------------------------------------------
@pytest.mark.parametrize("name", ["svm", "knn"])
def test_the_seed_free_classifiers_fit_the_same_model_whatever_the_seed(name):
    from condmon.classifiers import CLASSIFIERS
    from condmon.train import build_baseline_model, build_model, fit_with_metadata

    assert CLASSIFIERS[name].seed_free
    features = FEATURES[:5]  # a small selection: the same code, fewer candidate subsets
    x = SIMULATED[features].to_numpy(np.float32)
    y = SIMULATED.health_state.to_numpy()
    groups = SIMULATED.record_id.to_numpy()
    x_test = MEASURED[features].to_numpy(np.float32)
    selection = {"n_features": 3, "cv": 3}
    for build in (build_model, build_baseline_model):
        fits = [build(name, {}, seed, selection) for seed in (1, 2)]
        for model in fits:
            fit_with_metadata(model, x, y, feature_names=features, groups=groups)
        fitted = [getattr(m, "model_", m) for m in fits]  # the baseline's chosen estimator
        decision = [
            m.decision_function(x_test) if name == "svm" else m.predict_proba(x_test)
            for m in fitted
        ]
        np.testing.assert_array_equal(decision[0], decision[1])


@pytest.mark.parametrize(
    "name, baseline", [("svm", False), ("knn", False), ("knn", True)]
)  # the baseline: the other classifier's path, with its own choice of selection
def test_a_training_set_several_splits_share_is_fitted_once(monkeypatch, name, baseline):
    import dataclasses

    import condmon.train as train
    from condmon.classifiers import CLASSIFIERS

    # at 0 % measured every repeat trains on the simulated records alone: one training set
    splits = splits_for(MEASURED, percents=(0, 50), repeats=3)
    simulated = None if baseline else SIMULATED
    fits = []
    fit = train.fit_with_metadata
    monkeypatch.setattr(
        train, "fit_with_metadata", lambda model, *a, **k: fits.append(model) or fit(model, *a, **k)
    )
    # the baseline's own choice of selection needs one; the selection's seed is held above
    selection = {"n_features": 3, "cv": 3} if baseline else None
    features = FEATURES[:5]
    shared = run_protocol(name, {}, simulated, MEASURED, splits, features, 0, None, None, selection)
    n_shared = len(fits)
    fits.clear()
    monkeypatch.setitem(CLASSIFIERS, name, dataclasses.replace(CLASSIFIERS[name], seed_free=False))
    apart = run_protocol(name, {}, simulated, MEASURED, splits, features, 0, None, None, selection)
    assert len(fits) == len(apart[2])  # one fit per split
    pd.testing.assert_frame_equal(shared[0], apart[0])
    pd.testing.assert_frame_equal(
        shared[1].drop(columns="fit_seconds"), apart[1].drop(columns="fit_seconds")
    )
    assert set(shared[2]) == set(apart[2])
    if not baseline:  # (the baseline trains nothing at 0 %: no split of its own there)
        assert n_shared == len(shared[2]) - 2  # the 0 % repeats 1 and 2 reuse repeat 0's fit
        assert shared[2][(0, 0, "")] is shared[2][(0, 1, "")] is shared[2][(0, 2, "")]

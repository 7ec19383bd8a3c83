"""`condmon predict` and the SignalModel (raw segments in, labels out) on a small real fit: two
health states told apart by a tone, two speeds; refusals of what the model was not trained for;
the MLflow pyfunc face; CWRU .mat files through the bearing system's reader."""

import json
import logging.handlers
import warnings

import joblib
import mlflow
import numpy as np
import pandas as pd
import pytest

from condmon.classifiers import make_classifier
from condmon.features import compute_feature_table
from condmon.predict import main
from condmon.hybrid import training_range
from condmon.signal_model import (
    REQUIRED_COLUMNS,
    SignalModel,
    UnsupportedRecords,
    health_summary,
    log_pyfunc,
    record_predictions,
)
from condmon.signals import make_rows, write_signal_table
from conftest import CWRU, config_of

FS, N = 2048.0, 512
CHANNELS = ["A1_x", "A1_y"]
SPECTRUM = {
    "f_min_hz": 0.0,
    "f_max_hz": 400.0,
    "resolution_hz": 8.0,
    "scale": "log",
    "band_statistic": "rms",
}


def records(seed, speeds=(450.0, 1100.0), per_state=3, fs=FS, n=N, channels=CHANNELS):
    """Signal-table rows: healthy = a tone at 10 x the shaft frequency, fault = that tone plus
    one at 15 x; noise on top; three segments a record."""
    rng = np.random.default_rng(seed)
    rows = []
    for state in ("healthy", "fault"):
        for speed in speeds:
            for k in range(per_state):
                t = np.arange(3 * n) / fs
                shaft = speed / 60
                signal = np.sin(2 * np.pi * 10 * shaft * t)
                if state == "fault":
                    signal = signal + 0.8 * np.sin(2 * np.pi * 15 * shaft * t)
                rows += make_rows(
                    f"{state}-{speed:g}-{seed}-{k}",
                    "measured",
                    state,
                    speed,
                    1.0,
                    fs,
                    {ch: signal + 0.2 * rng.normal(size=len(t)) for ch in channels},
                    segment_length=n,
                )
    return pd.DataFrame(rows)


@pytest.fixture(scope="module")
def model():
    train = compute_feature_table(records(1), CHANNELS, SPECTRUM)
    names = [c for c in train.columns if c.startswith("fft_")]
    estimator = make_classifier("knn", {"n_neighbors": 3}).fit(
        train[names].to_numpy(np.float32), train["health_state"].to_numpy()
    )
    return SignalModel(
        estimator,
        {
            "kind": "spectrum",
            "channels": CHANNELS,
            "spectrum": SPECTRUM,
            "statistical": None,
            "defect_orders": None,
            "feature_names": names,
        },
        {"fs_hz": FS, "n_samples": N, "channels": CHANNELS, "speeds_rpm": [450.0, 1100.0]},
        healthy_state="healthy",
        info={
            "classifier": "knn",
            "protocol": "record_split",
            "measured_percent": 100,
            "repeat": 0,
            "holdout": "",
        },
    )


def test_new_records_are_classified_with_probabilities_per_segment(model):
    segments = model.predict_segments(records(2))
    assert (segments["predicted_label"] == segments["true_label"]).mean() > 0.9
    probabilities = segments[["p_fault", "p_healthy"]].to_numpy()
    assert np.allclose(probabilities.sum(axis=1), 1.0)
    assert (
        segments["predicted_label"] == np.where(probabilities[:, 0] > 0.5, "fault", "healthy")
    ).all()


@pytest.mark.parametrize(
    "change, reason",
    [
        (dict(speeds=(900.0,)), "speed 900 rpm; the model was trained at [450.0, 1100.0] rpm"),
        (dict(fs=4096.0, n=1024), "sampling rate 4096 Hz; the model was trained at 2048 Hz"),
        (dict(n=256), "segments of [256] samples; the model was trained on 512"),
        (dict(channels=["A1_x"]), "no channel(s) ['A1_y']"),
    ],
)
def test_records_the_model_was_not_trained_for_are_refused_by_name(model, change, reason):
    table = pd.concat(
        [records(3, per_state=1), records(4, per_state=1, **change)], ignore_index=True
    )
    with pytest.raises(UnsupportedRecords) as refused:
        model.predict_segments(table)
    bad = sorted(table.loc[table["record_id"].str.endswith("-4-0"), "record_id"].unique())
    problems = refused.value.problems
    assert sorted(problems["record_id"].unique()) == bad  # only those, each by name
    assert (
        problems.groupby("record_id")["reason"]
        .agg(lambda lines: any(reason in r for r in lines))
        .all()
    )
    assert bad[0] in str(refused.value)


def test_segments_outside_the_training_range_are_marked_per_segment_and_record(
    model, tmp_path, capsys
):
    train = compute_feature_table(records(1), CHANNELS, SPECTRUM)
    names = model.features["feature_names"]
    used = names[:5]
    ranged = SignalModel(
        model.estimator,
        model.features,
        model.domain,
        "healthy",
        info=model.info,
        training_range={
            "features": used,
            "low": train[used].min().tolist(),
            "high": train[used].max().tolist(),
        },
    )
    loud = records(6, per_state=1)
    loud = loud.assign(
        signal=[
            np.asarray(s) * (20.0 if r.startswith("fault") else 1.0)
            for s, r in zip(loud["signal"], loud["record_id"])
        ]
    )
    segments = ranged.predict_segments(loud)
    faulty = segments["record_id"].str.startswith("fault")
    assert segments.loc[faulty, "outside_training"].all()  # 20 x louder: above every trained level
    per_record = record_predictions(segments, ranged.classes, "healthy").set_index("record_id")
    assert (
        per_record["outside_training"] == segments.groupby("record_id")["outside_training"].mean()
    ).all()
    summary = health_summary(per_record.reset_index(), ranged.classes, "healthy")
    assert list(summary["outside_training"]) == list(per_record["outside_training"])
    # a model packaged before the range was kept says nothing rather than "inside"
    assert "outside_training" not in model.predict_segments(loud)
    # the command names the records
    joblib.dump(ranged, tmp_path / "ranged.joblib")
    write_signal_table(loud, tmp_path / "loud.parquet")
    assert (
        main(
            [
                "predict",
                "--model",
                str(tmp_path / "ranged.joblib"),
                "--input",
                str(tmp_path / "loud.parquet"),
                "--output",
                str(tmp_path / "out"),
            ]
        )
        == 0
    )
    said = capsys.readouterr().out
    assert "outside the model's training range" in said and "fault-" in said
    assert (pd.read_csv(tmp_path / "out" / "health_summary.csv")["outside_training"] > 0).any()


def test_the_training_range_covers_the_fits_training_segments_only():
    simulated = pd.DataFrame({"record_id": ["s1", "s1", "s2"], "a": [0.0, 1.0, 50.0]})
    measured = pd.DataFrame(
        {"record_id": ["m1", "m1", "m2"], "segment": [0, 1, 0], "a": [-2.0, 3.0, 99.0]}
    )
    split = pd.DataFrame(
        {
            "record_id": ["s2", "m1", "m1", "m2"],
            "segment": [-1, 0, 1, -1],
            "role": ["simulated_validation", "train", "test", "test"],
        }
    )
    # s2 is held out for validation, m1's second segment and m2 are tested: none of them count
    assert training_range(simulated, measured, split, ["a"]) == {
        "features": ["a"],
        "low": [-2.0],
        "high": [1.0],
    }


def write_new_records(table: pd.DataFrame, path, columns=REQUIRED_COLUMNS) -> None:
    """A table of new records as a user writes it: only ``columns``, by pandas, no schema."""
    table[list(columns)].to_parquet(path, index=False)


def test_condmon_predict_writes_predictions_summary_and_plot(model, tmp_path, capsys):
    joblib.dump(model, tmp_path / "model.joblib")
    table = records(5)
    write_new_records(table, tmp_path / "new.parquet")  # only what a user has of new data: no truth
    assert set(pd.read_parquet(tmp_path / "new.parquet").columns) == {
        "record_id",
        "segment",
        "speed_rpm",
        "fs_hz",
        "channel",
        "signal",
    }
    out = tmp_path / "predictions"
    assert (
        main(
            [
                "predict",
                "--model",
                str(tmp_path / "model.joblib"),
                "--input",
                str(tmp_path / "new.parquet"),
                "--output",
                str(out),
            ]
        )
        == 0
    )
    segments = pd.read_csv(out / "segments.csv")
    assert len(segments) == table[["record_id", "segment"]].drop_duplicates().shape[0]
    per_record = pd.read_csv(out / "records.csv")
    summary = pd.read_csv(out / "health_summary.csv")
    assert len(per_record) == len(summary) == table["record_id"].nunique()
    faulty = summary["record_id"].str.startswith("fault")
    assert (summary.loc[faulty, "status"] == "fault").mean() > 0.8
    assert (summary.loc[~faulty, "status"] == "healthy").mean() > 0.8
    assert summary["correct"].isna().all()  # no truth given, none claimed
    assert not (out / "score.json").exists()
    assert (out / "predictions.png").stat().st_size > 0
    assert json.loads((out / "model.json").read_text())["classifier"] == "knn"
    said = capsys.readouterr().out
    assert "12 record(s)" in said and "scored" not in said


def test_a_table_with_health_states_is_scored(model, tmp_path, capsys):
    joblib.dump(model, tmp_path / "model.joblib")
    table = records(5)
    table.loc[table["record_id"] == "fault-450-5-0", "health_state"] = (
        "broken"  # a label the model lacks
    )
    write_new_records(table, tmp_path / "new.parquet", [*REQUIRED_COLUMNS, "health_state"])
    out = tmp_path / "predictions"
    assert (
        main(
            [
                "predict",
                "--model",
                str(tmp_path / "model.joblib"),
                "--input",
                str(tmp_path / "new.parquet"),
                "--output",
                str(out),
            ]
        )
        == 0
    )
    segments = pd.read_csv(out / "segments.csv")
    known = segments[segments["true_label"] != "broken"]
    right = known["predicted_label"] == known["true_label"]
    score = json.loads((out / "score.json").read_text())
    assert score["segments"] == len(known) == len(segments) - 3
    assert score["accuracy"] == pytest.approx(right.mean())
    assert score["balanced_accuracy"] == pytest.approx(
        right.groupby(known["true_label"]).mean().mean()
    )
    assert score["records"] == 11 and score["unscored_labels"] == ["broken"]
    summary = pd.read_csv(out / "health_summary.csv")
    assert score["records_right"] == int((summary["correct"] == True).sum())  # noqa: E712 (NaN: unscored)
    said = capsys.readouterr().out
    assert f"{score['records_right']} of 11 record(s) right" in said and "['broken']" in said


@pytest.mark.parametrize(
    "table, says",
    [
        (lambda: records(5).iloc[:0], "the signal table is empty (no rows)"),
        (lambda: records(5).drop(columns=["fs_hz"]), "missing signal-table columns ['fs_hz']"),
    ],
)
def test_a_bad_table_is_refused_naming_the_users_file(model, tmp_path, capsys, table, says):
    joblib.dump(model, tmp_path / "model.joblib")
    table().to_parquet(tmp_path / "new.parquet", index=False)
    assert (
        main(
            [
                "predict",
                "--model",
                str(tmp_path / "model.joblib"),
                "--input",
                str(tmp_path / "new.parquet"),
                "--output",
                str(tmp_path / "out"),
            ]
        )
        == 2
    )
    assert (
        capsys.readouterr().err.strip()
        == f"condmon predict: --input {tmp_path / 'new.parquet'}: {says}"
    )
    assert not (tmp_path / "out").exists()


def test_a_file_the_systems_reader_cannot_read_is_named_as_given(tmp_path, caplog):
    """The reader reads a folder; a single file is linked into a temporary one, which no message
    names."""
    from condmon.predict import PredictError, read_input
    from condmon.systems import get_system

    system = get_system(config_of(".test/config/cwru-smoke.yaml"))
    reader = SignalModel(
        None,
        {},
        {"channels": system.channels},
        system.healthy_state,
        system=system.job_spec("measured"),
    )
    for name, text in (("new.csv", "a,b\n1,2\n"), ("999.mat", "not MATLAB")):
        (tmp_path / name).write_text(text)
        with pytest.raises(PredictError) as error, caplog.at_level("WARNING"):
            read_input(tmp_path / name, reader)
        said = str(error.value) + caplog.text
        assert str(error.value).startswith(
            f"--input {tmp_path / name}: the bearing system cannot read it"
        )
        assert "/tmp" not in said.replace(str(tmp_path / name), "")  # only the user's file is named


def test_condmon_predict_refuses_an_untrained_speed_and_writes_nothing(model, tmp_path, capsys):
    joblib.dump(model, tmp_path / "model.joblib")
    table = pd.concat([records(6, per_state=1), records(7, speeds=(900.0,), per_state=1)])
    write_signal_table(table, tmp_path / "new.parquet")
    args = [
        "predict",
        "--model",
        str(tmp_path / "model.joblib"),
        "--input",
        str(tmp_path / "new.parquet"),
        "--output",
        str(tmp_path / "out"),
    ]
    assert main(args) == 2
    error = capsys.readouterr().err
    assert "healthy-900-7-0: speed 900 rpm" in error and "fault-900-7-0" in error
    assert not (tmp_path / "out").exists()
    # asked to, it predicts the others and lists the refused records apart
    assert main([*args, "--skip-unsupported"]) == 0
    refused = pd.read_csv(tmp_path / "out" / "refused_records.csv")
    assert sorted(refused["record_id"]) == ["fault-900-7-0", "healthy-900-7-0"]
    assert "900" not in set(
        pd.read_csv(tmp_path / "out" / "records.csv")["speed_rpm"].astype(int).astype(str)
    )


@pytest.mark.slow
def test_the_mlflow_pyfunc_model_takes_a_signal_table_and_gives_the_same_labels(
    model, tmp_path, monkeypatch
):
    joblib.dump(model, tmp_path / "model.joblib")
    (tmp_path / "results").mkdir()
    monkeypatch.chdir(tmp_path)  # a new store's artifacts go to ./mlruns: never the project's
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    mlflow.set_tracking_uri(f"sqlite:///{tmp_path / 'results' / 'mlflow.db'}")
    said = logging.handlers.BufferingHandler(1000)  # on MLflow's own logger: it does not propagate
    logging.getLogger("mlflow.pyfunc").addHandler(said)
    try:
        with warnings.catch_warnings(record=True) as warned, mlflow.start_run():
            warnings.simplefilter("always")
            info = log_pyfunc(tmp_path / "model.joblib", model, name="signal-model")
    finally:
        logging.getLogger("mlflow.pyfunc").removeHandler(said)
    # nothing MLflow asks for is missing (type hints), nor says what does not apply (input example,
    # cloudpickle): a smoke run's log logs 36 models
    assert [str(w.message) for w in warned if "mlflow" in w.filename] == []
    assert [r.getMessage() for r in said.buffer if r.levelno >= logging.WARNING] == []
    loaded = mlflow.pyfunc.load_model(info.model_uri)
    inputs = loaded.metadata.signature.inputs.input_names()
    assert {"record_id", "segment", "speed_rpm", "fs_hz", "channel", "signal"} <= set(inputs)
    table = records(8).drop(columns=["health_state", "source", "params", "load"])
    out = loaded.predict(table)
    assert list(out["predicted_label"]) == list(model.predict(table))
    assert list(out.columns) == ["record_id", "segment", "predicted_label", "p_fault", "p_healthy"]
    with pytest.raises(Exception, match="speed 900 rpm"):
        loaded.predict(records(9, speeds=(900.0,), per_state=1).drop(columns=["params"]))
    # condmon predict takes it by its run (the run's only model) or by its model URI, from the
    # store given or, in the project folder, from the project's own (results/mlflow.db)
    write_signal_table(records(8), tmp_path / "new.parquet")
    for source, store in (
        (f"runs:/{info.run_id}", ["--tracking-uri", "sqlite:///results/mlflow.db"]),
        (info.model_uri, []),
    ):
        out = tmp_path / source.replace(":", "").replace("/", "_")
        assert (
            main(
                [
                    "predict",
                    "--model",
                    source,
                    *store,
                    "--input",
                    "new.parquet",
                    "--output",
                    str(out),
                ]
            )
            == 0
        )
        assert list(pd.read_csv(out / "segments.csv")["predicted_label"]) == list(
            model.predict(table)
        )


def test_an_mlflow_model_without_a_store_says_where_it_looked_and_creates_none(
    tmp_path, monkeypatch, capsys
):
    """MLflow's own default would make ./mlflow.db and say only that the model is not there."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    records(5).to_parquet(tmp_path / "new.parquet")
    for store, named in (
        ([], "the project's store"),
        (["--tracking-uri", "sqlite:///elsewhere.db"], "--tracking-uri"),
    ):
        assert (
            main(
                [
                    "predict",
                    "--model",
                    "models:/condmon-smoke@best",
                    *store,
                    "--input",
                    "new.parquet",
                    "--output",
                    "out",
                ]
            )
            == 2
        )
        error = capsys.readouterr().err
        assert (
            f"no MLflow store at {tmp_path.resolve()}/" in error
            and named in error
            and "--tracking-uri" in error
        )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new.parquet"]  # nothing made


@pytest.mark.skipif(not CWRU.is_dir(), reason=f"no CWRU data at {CWRU}")
def test_a_single_cwru_file_is_read_by_the_bearing_systems_reader(tmp_path):
    """A model of the bearing system, fitted on two CWRU records, applied to a third file through
    the system's own reader (g to m/s^2, resampling, segments), as its training data was read."""
    from condmon.features import statistical_feature_table
    from condmon.predict import read_input
    from condmon.systems import get_system

    config = config_of(".test/config/cwru-smoke.yaml")
    system = get_system(config)
    train_dir = tmp_path / "train"
    train_dir.mkdir()
    for name in ("97.mat", "105.mat", "index.csv"):
        (train_dir / name).symlink_to(CWRU / name)
    spec = system.job_spec("measured")
    reader = SignalModel(None, {}, {"channels": system.channels}, system.healthy_state, system=spec)
    frame, _ = read_input(train_dir, reader)
    statistical = config["features"]["statistical"]
    features = statistical_feature_table(
        frame, system.channels, statistical, system.defect_orders()
    )
    names = [c for c in features.columns if c.startswith(tuple(system.channels))]
    estimator = make_classifier("knn", {"n_neighbors": 3}).fit(
        features[names].to_numpy(np.float32), features["health_state"].to_numpy()
    )
    model = SignalModel(
        estimator,
        {
            "kind": "statistical",
            "channels": system.channels,
            "spectrum": None,
            "statistical": statistical,
            "defect_orders": system.defect_orders(),
            "feature_names": names,
        },
        {
            "fs_hz": system.output_rate_hz,
            "n_samples": system.segment_length,
            "channels": system.channels,
            "speeds_rpm": sorted(set(frame["speed_rpm"])),
        },
        system.healthy_state,
        system=spec,
    )
    new, records_read = read_input(CWRU / "106.mat", model)  # inner race, 1 HP
    assert list(records_read["status"]) == ["kept"] and new["record_id"].nunique() == 1
    segments = model.predict_segments(new)
    assert len(segments) == new["segment"].nunique()
    assert set(segments["predicted_label"]) <= set(model.classes)

"""hybrid.simulated_validation_share: the held-out simulated records in the split table, training
without them, their metrics apart from the measured ones, the config check and the scripts."""

import dataclasses
import json
import math
import runpy
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from sklearn.base import BaseEstimator

from conftest import SCRIPTS, config_of
from condmon import train
from condmon.config import ConfigError
from condmon.hybrid import (
    SIMULATED_VALIDATION,
    SplitError,
    n_validation_records,
    read_split_table,
    simulated_validation_records,
    write_split_table,
)
from condmon.protocols import make_splits
from condmon.train import (
    METRIC_COLUMNS,
    SIMULATED_VALIDATION_COLUMNS,
    fit_and_evaluate,
    run_protocol,
)

CLASSES = ("healthy", "surface_fault", "missing_tooth")
SPEEDS = (450.0, 775.0)
FEATURES = [f"f{i:02d}" for i in range(6)]
ID_COLUMNS = ["record_id", "segment", "source", "health_state", "speed_rpm", "load", "fs_hz"]


def features(source, n_records, n_segments=2, seed=0):
    """Each class a well-separated cluster; records `<source>_<class>_<speed>_<k>`."""
    rng = np.random.default_rng(seed)
    rows = []
    for index, label in enumerate(CLASSES):
        for speed in SPEEDS:
            for k in range(n_records):
                for segment in range(n_segments):
                    centre = np.zeros(len(FEATURES))
                    centre[index] = 8.0
                    rows.append(
                        {
                            "record_id": f"{source}_{label}_{int(speed)}_{k:02d}",
                            "segment": segment,
                            "source": source,
                            "health_state": label,
                            "speed_rpm": speed,
                            "load": 1.0,
                            "fs_hz": 5120.0,
                            **dict(zip(FEATURES, centre + rng.normal(size=len(FEATURES)))),
                        }
                    )
    frame = pd.DataFrame(rows)
    return frame.astype({f: np.float32 for f in FEATURES})


SIMULATED = features("simulated", n_records=10, seed=1)
MEASURED = features("measured", n_records=4, seed=2)
ID = ["record_id", "segment", "health_state", "speed_rpm"]


def splits(protocol="record_split", share=0.3, seed=11, simulated=SIMULATED, **kwargs):
    return make_splits(
        MEASURED[ID],
        protocol,
        measured_percent=kwargs.pop("percents", [0, 50]),
        repeats=kwargs.pop("repeats", 2),
        seed=seed,
        simulated_records=None if simulated is None else simulated[ID],
        simulated_validation_share=share,
        **kwargs,
    )


def held_out(table):
    """{(percent, repeat, holdout): held-out simulated ids} of a split table."""
    chosen = table[table.role == SIMULATED_VALIDATION]
    return {
        key: set(group.record_id)
        for key, group in chosen.groupby(["measured_percent", "repeat", "holdout"])
    }


# -- the held-out records ----------------------------------------------------------------------
def test_share_zero_gives_the_measured_split_table_unchanged():
    plain = make_splits(
        MEASURED[ID], "condition_holdout", measured_percent=[0, 50], repeats=2, seed=11
    )
    pd.testing.assert_frame_equal(splits("condition_holdout", share=0.0), plain)
    pd.testing.assert_frame_equal(splits("condition_holdout", share=0.0, simulated=None), plain)
    assert simulated_validation_records(SIMULATED[ID], 0.0, seed=11) == []


@pytest.mark.parametrize("share", [0.3, 0.5])
def test_whole_records_per_stratum_round_share_times_n(share):
    ids = simulated_validation_records(SIMULATED[ID], share, seed=11)
    strata = SIMULATED.drop_duplicates("record_id").set_index("record_id")
    counts = strata.loc[ids].groupby(["health_state", "speed_rpm"]).size()
    expected = n_validation_records(10, share)
    assert expected == math.floor(share * 10 + 0.5)
    assert len(counts) == len(CLASSES) * len(SPEEDS) and (counts == expected).all()
    assert len(set(ids)) == len(ids) and ids == sorted(ids)


def test_same_seed_same_records_other_seed_other_records_larger_share_a_superset():
    one = simulated_validation_records(SIMULATED[ID], 0.3, seed=11)
    shuffled = SIMULATED[ID].sample(frac=1, random_state=3)  # row order must not matter
    assert simulated_validation_records(shuffled, 0.3, seed=11) == one
    assert simulated_validation_records(SIMULATED[ID], 0.3, seed=12) != one
    assert set(one) <= set(simulated_validation_records(SIMULATED[ID], 0.5, seed=11))


def test_the_same_records_in_every_split_and_protocol():
    expected = set(simulated_validation_records(SIMULATED[ID], 0.3, seed=11))
    for protocol, kwargs in (
        ("record_split", {}),
        ("condition_holdout", {}),
        ("segment_share", {}),
        ("unseen_fault", {"measured_classes": ["healthy"]}),
    ):
        table = splits(protocol, percents=[0, 50, 100], repeats=3, **kwargs)
        keys = table[["measured_percent", "repeat", "holdout"]].drop_duplicates()
        sets = held_out(table)
        assert len(sets) == len(keys), protocol  # every split lists them
        assert all(s == expected for s in sets.values()), protocol
        rows = table[table.role == SIMULATED_VALIDATION]
        assert (rows.segment == -1).all()  # whole records
        # the measured part of the table is the one without a simulated validation
        measured = table[table.role != SIMULATED_VALIDATION].reset_index(drop=True)
        plain = splits(protocol, share=0.0, percents=[0, 50, 100], repeats=3, **kwargs)
        pd.testing.assert_frame_equal(measured, plain)


def test_a_share_that_empties_a_stratum_names_the_key_and_the_stratum():
    lonely = pd.concat(
        [
            SIMULATED[ID],
            pd.DataFrame(
                [
                    {
                        "record_id": "simulated_crack_775_00",
                        "segment": 0,
                        "health_state": "crack",
                        "speed_rpm": 775.0,
                    }
                ]
            ),
        ]
    )
    # 0.5 of one record rounds to one: nothing of the crack stratum would train
    with pytest.raises(
        SplitError,
        match=r"hybrid\.simulated_validation_share = 0\.5 .*"
        r"health_state=crack, speed_rpm=775",
    ):
        simulated_validation_records(lonely, 0.5, seed=11)
    with pytest.raises(SplitError, match="health_state=crack, speed_rpm=775"):
        splits(share=0.5, simulated=lonely)
    assert "simulated_crack_775_00" not in simulated_validation_records(lonely, 0.4, seed=11)
    with pytest.raises(SplitError, match=r"hybrid\.simulated_validation_share.*\[0, 1\)"):
        simulated_validation_records(SIMULATED[ID], 1.0, seed=11)


def test_split_table_roundtrip_and_errors(tmp_path):
    table = splits("condition_holdout")
    write_split_table(table, tmp_path / "s.parquet")
    pd.testing.assert_frame_equal(read_split_table(tmp_path / "s.parquet"), table)
    cut = table.copy()
    cut.loc[cut.role == SIMULATED_VALIDATION, "segment"] = 0
    with pytest.raises(SplitError, match="whole record"):
        write_split_table(cut, tmp_path / "cut.parquet")
    with pytest.raises(SplitError, match="both measured and simulated"):
        splits(simulated=MEASURED)
    with pytest.raises(SplitError, match="needs the simulated records"):
        make_splits(
            MEASURED[ID],
            "record_split",
            measured_percent=[0],
            repeats=1,
            seed=0,
            simulated_validation_share=0.3,
        )


# -- training without them, evaluating on them -------------------------------------------------
class Recorder(BaseEstimator):
    """A classifier that remembers the record ids it was fitted on and predicts the class of the
    largest feature (the clusters' centres), so its accuracy is known."""

    fitted_on: list = []
    __metadata_request__fit = {"groups": True}  # as the CNN: the training loop passes them

    def fit(self, x, y, groups=None):
        Recorder.fitted_on.append(set(groups))
        return self

    def predict(self, x):
        return np.asarray(CLASSES)[np.argmax(np.asarray(x)[:, :3], axis=1)]


def test_held_out_records_never_train_and_are_evaluated_apart(monkeypatch):
    monkeypatch.setattr(train.classifiers, "make_classifier", lambda *a, **k: Recorder())
    # the Recorder stands in for a classifier that fits every split (no model shared between
    # the splits of one training set, as a seed-free one's would be)
    spec = train.classifiers.CLASSIFIERS["svm"]
    monkeypatch.setitem(
        train.classifiers.CLASSIFIERS, "svm", dataclasses.replace(spec, seed_free=False)
    )
    Recorder.fitted_on = []
    table = splits("condition_holdout", percents=[0, 100], repeats=1)
    validation_ids = set(simulated_validation_records(SIMULATED[ID], 0.3, seed=11))
    result = fit_and_evaluate("svm", {}, SIMULATED, MEASURED, table, FEATURES, seed=0)
    assert len(Recorder.fitted_on) == 4  # 2 percentages x 2 held-out speeds
    for fitted in Recorder.fitted_on:
        assert not fitted & validation_ids
        assert set(SIMULATED.record_id) - validation_ids <= fitted
    n_held = SIMULATED.record_id.isin(validation_ids).sum()
    assert (result.metrics.n_train_simulated == len(SIMULATED) - n_held).all()
    # measured predictions and metrics hold measured records only
    assert set(result.predictions.record_id) <= set(MEASURED.record_id)
    assert list(result.metrics.columns) == METRIC_COLUMNS
    # the simulated validation: every fit, all speeds and per speed, labelled
    validation = result.simulated_validation
    assert list(validation.columns) == SIMULATED_VALIDATION_COLUMNS
    assert set(validation.test_source) == {SIMULATED_VALIDATION}
    overall = validation[validation.speed_rpm.isna()]
    assert len(overall) == 4 and (overall.n_test == n_held).all()
    assert sorted(validation.speed_rpm.dropna().unique()) == list(SPEEDS)
    per_speed = validation[validation.speed_rpm.notna()]
    assert per_speed.groupby(["measured_percent", "holdout"]).n_test.sum().eq(n_held).all()
    assert (validation.accuracy == 1.0).all()  # the clusters are separable


def test_validation_accuracy_is_computed_on_the_held_out_records():
    """Held-out records labelled with the wrong class: their accuracy is 0 while the measured
    accuracy stays 1, so the two are never mixed."""
    ids = set(simulated_validation_records(SIMULATED[ID], 0.3, seed=11))
    wrong = SIMULATED.copy()
    held = wrong.record_id.isin(ids) & (wrong.health_state == "healthy")
    wrong.loc[held, "health_state"] = "surface_fault"
    table = splits(percents=[0], repeats=1)
    result = fit_and_evaluate("knn", {"n_neighbors": 3}, wrong, MEASURED, table, FEATURES, 0)
    at_all = result.simulated_validation[result.simulated_validation.speed_rpm.isna()].iloc[0]
    n_healthy_held = held.sum()
    assert at_all.accuracy == pytest.approx(1 - n_healthy_held / at_all.n_test)
    assert (result.metrics.accuracy == 1.0).all()


def test_share_zero_trains_on_every_simulated_record_and_has_no_validation():
    table = splits(share=0.0, percents=[50], repeats=1)
    result = fit_and_evaluate("svm", {}, SIMULATED, MEASURED, table, FEATURES, seed=0)
    assert result.simulated_validation.empty
    assert (result.metrics.n_train_simulated == len(SIMULATED)).all()
    predictions, metrics, _ = run_protocol("svm", {}, SIMULATED, MEASURED, table, FEATURES, 0)
    pd.testing.assert_frame_equal(predictions, result.predictions)
    pd.testing.assert_frame_equal(
        metrics.drop(columns="fit_seconds"), result.metrics.drop(columns="fit_seconds")
    )


def test_measured_only_baseline_ignores_the_simulated_validation_rows():
    table = splits(percents=[50], repeats=1)
    result = fit_and_evaluate("svm", {}, None, MEASURED, table, FEATURES, seed=0)
    assert (result.metrics.n_train_simulated == 0).all() and result.simulated_validation.empty


def test_held_out_record_missing_from_the_simulated_features_is_named():
    table = splits(percents=[0], repeats=1)
    fewer = SIMULATED[SIMULATED.record_id != sorted(held_out(table)[(0, 0, "")])[0]]
    with pytest.raises(ValueError, match="absent from the simulated features"):
        fit_and_evaluate("svm", {}, fewer, MEASURED, table, FEATURES, seed=0)


# -- config -----------------------------------------------------------------------------------
def test_config_default_and_range():
    assert config_of()["hybrid"]["simulated_validation_share"] == 0.0
    assert (
        config_of(changes={"hybrid": {"simulated_validation_share": 0.3}})["hybrid"][
            "simulated_validation_share"
        ]
        == 0.3
    )
    for bad in (1.0, -0.1, "0.3"):
        with pytest.raises(ConfigError, match=r"hybrid\.simulated_validation_share"):
            config_of(changes={"hybrid": {"simulated_validation_share": bad}})


# -- the hybrid and train scripts ----------------------------------------------------------------
def run_script(name, **attributes):
    fake = SimpleNamespace(rule=name.removesuffix(".py"), **attributes)
    runpy.run_path(str(SCRIPTS / name), init_globals={"snakemake": fake})


def write_features(frame, path):
    table = pa.Table.from_pandas(frame[ID_COLUMNS + FEATURES], preserve_index=False)
    meta = {
        b"condmon.feature_names": json.dumps(FEATURES).encode(),
        b"condmon.feature_kind": b"spectrum",
    }
    pq.write_table(table.replace_schema_metadata(meta), path)


def test_scripts_hold_out_write_and_keep_share_zero_as_before(tmp_path, isolated_logging):
    write_features(SIMULATED, tmp_path / "simulated.parquet")
    write_features(MEASURED, tmp_path / "measured.parquet")
    hybrid_params = dict(
        protocol="record_split",
        measured_percent=[0, 50],
        repeats=2,
        seed=11,
        min_test_records=1,
        healthy_state="healthy",
        reserve={},
    )
    log = [str(tmp_path / "log.txt")]
    records = (
        MEASURED[["record_id", "health_state", "speed_rpm"]].drop_duplicates().assign(status="kept")
    )
    records.to_csv(tmp_path / "records.csv", index=False)  # the measured stage's record list
    run_script(
        "hybrid.py",
        input=SimpleNamespace(
            features=tmp_path / "measured.parquet", records=tmp_path / "records.csv"
        ),
        output=SimpleNamespace(splits=tmp_path / "plain.parquet"),
        params=SimpleNamespace(**hybrid_params),
        log=log,
    )
    both = SimpleNamespace(
        features=tmp_path / "measured.parquet",
        records=tmp_path / "records.csv",
        simulated=tmp_path / "simulated.parquet",
    )
    for name, share in (("zero.parquet", 0.0), ("held.parquet", 0.3)):
        run_script(
            "hybrid.py",
            input=both,
            output=SimpleNamespace(splits=tmp_path / name),
            params=SimpleNamespace(**hybrid_params, simulated_validation_share=share),
            log=log,
        )
    plain = read_split_table(tmp_path / "plain.parquet")
    held = read_split_table(tmp_path / "held.parquet")
    pd.testing.assert_frame_equal(read_split_table(tmp_path / "zero.parquet"), plain)
    assert set(held.record_id[held.role == SIMULATED_VALIDATION]) == set(
        simulated_validation_records(SIMULATED[ID], 0.3, seed=11)
    )

    out = tmp_path / "train"
    run_script(
        "train.py",
        input=SimpleNamespace(
            simulated=tmp_path / "simulated.parquet",
            measured=tmp_path / "measured.parquet",
            splits=tmp_path / "held.parquet",
        ),
        output=SimpleNamespace(
            predictions=out / "predictions.parquet",
            metrics=out / "metrics.csv",
            models=out / "models",
            info=out / "info.json",
            measured_only=out / "measured_only.csv",
            measured_only_predictions=out / "measured_only_predictions.parquet",
            simulated_validation=out / "simulated_validation.csv",
        ),
        params=SimpleNamespace(
            classifier="knn",
            classifier_params={},
            seed=1,
            feature_selection={"n_features": None},
            measured_only_baseline=False,
        ),
        log=log,
    )
    assert pd.read_parquet(out / "measured_only_predictions.parquet").empty  # no baseline asked
    validation = pd.read_csv(out / "simulated_validation.csv")
    assert list(validation.columns) == SIMULATED_VALIDATION_COLUMNS
    assert set(validation.test_source) == {SIMULATED_VALIDATION}
    assert len(validation) == 4 * (1 + len(SPEEDS))  # 2 percents x 2 repeats, all + per speed
    assert "test_source" not in pd.read_csv(out / "metrics.csv").columns
    assert set(pd.read_parquet(out / "predictions.parquet").record_id) <= set(MEASURED.record_id)

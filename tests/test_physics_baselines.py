"""The system's training-free physics baselines: the bearing's envelope rule names an outer-race
fault in a simulated outer-race record, takes its healthy threshold from calibration segments
only, and is evaluated on the test sets of the splits (condmon.baselines)."""

import numpy as np
import pandas as pd
import pytest

from condmon.baselines import physics_predictions
from condmon.features import statistical_feature_table
from conftest import system_of
from condmon.models.bearing.rig import BearingRigParameters, RigSettings, simulate_rig
from condmon.protocols import make_splits
from condmon.signals import make_rows
from condmon.systems.bearing import BearingSystem

SPEED = 1797.0
FS = 12000.0
# config/cwru.yaml's features
STATISTICAL = {
    "names": [
        "env_ratio_bpfo",
        "env_ratio_bpfi",
        "env_ratio_bsf",
        "env_ratio_bsf_x2",
        "kurtosis",
        "std_frequency",
    ],
    "log_names": [
        "env_ratio_bpfo",
        "env_ratio_bpfi",
        "env_ratio_bsf",
        "env_ratio_bsf_x2",
        "kurtosis",
    ],
    "band_hz": [2000.0, 5000.0],
    "highpass_hz": 10.0,
}


def bearing_system(task="location", quantile=0.95):
    """The bearing system as the baselines job sees it (job_config("baselines"))."""
    return BearingSystem(
        {
            "bearing": {
                "health_states": None,
                "healthy_state": "normal",
                "envelope_rule": {"quantile": quantile},
            },
            "cwru": {"task": task},
        }
    )


def simulated_features(kind, record_id, seconds=2.0, seed=3, with_signals=False):
    """The statistical features of a simulated record of the rig model (its default noise and
    machine background; an outer-race defect at 6:00), segments of 4096 samples; `with_signals`:
    its signal table instead."""
    params = BearingRigParameters(speed_rpm=SPEED, defect_kind=kind)
    signal = simulate_rig(
        params, RigSettings(duration=seconds, settle_time=0.1), np.random.default_rng(seed)
    )["DE"]
    label = {"none": "normal"}.get(kind, kind)
    rows = make_rows(
        record_id, "simulated", label, SPEED, 0.0, FS, {"DE": signal}, segment_length=4096
    )
    if with_signals:
        return pd.DataFrame(rows)
    # the envelope lines where the bearing system puts them (its geometry, SKF 6205)
    return statistical_feature_table(
        pd.DataFrame(rows),
        ["DE"],
        STATISTICAL,
        system_of(".test/config/cwru-smoke.yaml").defect_orders(),
    )


@pytest.fixture(scope="module")
def records():
    return simulated_features("none", "healthy"), simulated_features("outer_race", "outer")


@pytest.mark.slow
def test_the_envelope_rule_says_outer_race_on_a_simulated_outer_race_record(records):
    healthy, outer = records
    names = [c for c in outer.columns if c.startswith("DE_")]
    rules = bearing_system().physics_baselines(names)
    rule = rules["envelope_rule"].fit(healthy)  # the healthy segments set the threshold
    assert list(rule.predict(outer)) == ["outer_race"] * len(outer)
    assert (rule.predict(healthy) != "normal").sum() <= 1  # the 0.95 quantile of 5 segments
    ratios = rule.line_ratios(outer)
    assert (ratios["bpfo"] > rule.threshold_).all()
    assert rule.threshold_ == pytest.approx(
        np.quantile(rule.line_ratios(healthy).max(axis=1), 0.95)
    )
    assert "calibration" in rule.describe()["threshold_from"]


def test_no_envelope_rule_without_one_label_per_location_or_without_the_lines():
    names = ["DE_log_env_ratio_bpfo", "DE_log_env_ratio_bpfi", "DE_log_env_ratio_bsf_x2"]
    assert set(bearing_system().physics_baselines(names)) == {"envelope_rule"}
    assert bearing_system("ten_class").physics_baselines(names) == {}  # three labels a location
    assert bearing_system().physics_baselines(names[:2] + ["DE_kurtosis"]) == {}


@pytest.mark.slow
def test_the_threshold_comes_from_calibration_segments_only(records):
    """On every split the rule is fitted on the calibration segments (role "calibration") and
    predicts exactly the test segments; test data never move the threshold."""
    healthy, outer = records
    measured = pd.concat([healthy.assign(load=0.0), outer.assign(load=0.0)], ignore_index=True)
    reserve = {"records": [], "calibration_segments": 2, "guard_segments": 1, "blocks": 1}
    # a second faulty record, so the split has something to test besides the healthy block
    measured = pd.concat([measured, outer.assign(record_id="outer2", load=0.0)], ignore_index=True)
    splits = make_splits(
        measured[["record_id", "segment", "health_state", "load"]],
        "unseen_fault",
        measured_percent=[0],
        repeats=1,
        seed=0,
        condition="load",
        measured_classes=["normal"],
        healthy_state="normal",
        reserve=reserve,
    )
    names = [c for c in measured.columns if c.startswith("DE_")]
    rules = bearing_system().physics_baselines(names)
    predictions, info = physics_predictions(rules, measured, splits)
    tested = splits[splits.role == "test"]
    whole = set(tested.record_id[tested.segment < 0])
    expected = {(r, s) for r, s in zip(measured.record_id, measured.segment) if r in whole}
    expected |= set(zip(tested.record_id[tested.segment >= 0], tested.segment[tested.segment >= 0]))
    assert set(zip(predictions.record_id, predictions.segment)) == expected
    assert not set(zip(predictions.record_id, predictions.segment)) & {
        ("healthy", 0),
        ("healthy", 1),
    }
    calibration = healthy[healthy.segment < 2]
    expected = np.quantile(rules["envelope_rule"].line_ratios(calibration).max(axis=1), 0.95)
    assert info["envelope_rule"]["threshold"] == pytest.approx(expected)
    assert info["envelope_rule"]["n_calibration_segments"] == 2
    assert (predictions.classifier == "envelope_rule").all()
    outer_rows = predictions[predictions.true_label == "outer_race"]
    assert (outer_rows.predicted_label == "outer_race").all()
    lines = {row["record_id"]: row for row in info["envelope_rule"]["fault_lines"]}
    assert set(lines) == {"outer", "outer2"} and all(row["shows_line"] for row in lines.values())
    assert {row["line"] for row in lines.values()} == {"bpfo"}


@pytest.mark.slow
def test_a_fault_record_whose_line_stays_at_the_healthy_level_does_not_show_it(records):
    """`fault_lines`: an outer-race record shows its BPFO line; a record labelled outer race whose
    envelope is a healthy one's (the line under the healthy threshold) does not."""
    healthy, outer = records
    names = [c for c in outer.columns if c.startswith("DE_")]
    rule = bearing_system().physics_baselines(names)["envelope_rule"].fit(healthy)
    # the healthy record's own segments labelled outer race: its median BPFO ratio is at most the
    # median of its largest ratio, so under the threshold (their 0.95 quantile)
    quiet = healthy.assign(record_id="quiet", health_state="outer_race")
    lines = {row["record_id"]: row for row in rule.fault_lines(pd.concat([healthy, outer, quiet]))}
    assert set(lines) == {"outer", "quiet"}  # healthy records have no defect line
    assert lines["outer"]["shows_line"] and not lines["quiet"]["shows_line"]
    assert (
        lines["quiet"]["median_ratio"]
        <= rule.thresholds_["features"]
        < lines["outer"]["median_ratio"]
    )
    assert lines["outer"]["shown_by"] == "features" and not lines["outer"]["no_line_why"]
    assert (
        not lines["quiet"]["shown_by"]
        and "no analysis lifts the median bpfo ratio" in lines["quiet"]["no_line_why"]
    )


@pytest.mark.slow
def test_the_rule_consults_every_analysis_of_the_measured_signals(records):
    """With the measured signals the rule reads `bearing.envelope_rule.line_analyses` beside the
    features' analysis: each analysis's ratios over its healthy median, the largest per line; a
    fault record names the analyses that show its line."""
    healthy, outer = records
    signals = pd.concat(
        [
            simulated_features("none", "healthy", with_signals=True),
            simulated_features("outer_race", "outer", with_signals=True),
        ],
        ignore_index=True,
    )
    analyses = ["fixed", "kurtogram", "prewhitened_fixed", "prewhitened_kurtogram"]
    system = BearingSystem(
        {
            "bearing": {
                "health_states": None,
                "healthy_state": "normal",
                "envelope_rule": {"quantile": 0.95, "line_analyses": analyses},
                "geometry": system_of(".test/config/cwru-smoke.yaml").bearing["geometry"],
            },
            "cwru": {"task": "location"},
            "features": {"statistical": STATISTICAL},
        }
    )
    names = [c for c in outer.columns if c.startswith("DE_")]
    rule = system.physics_baselines(names, signals)["envelope_rule"].fit(healthy)
    assert rule.analyses() == ["features", *analyses]
    assert set(rule.describe()["analysis_thresholds"]) == {"features", *analyses}
    assert list(rule.predict(outer)) == ["outer_race"] * len(outer)
    # the features' own analysis (the fixed band) and the line table's agree on the fixed band
    ratios = rule.analysis_ratios(outer)
    assert np.allclose(ratios["features"]["bpfo"], ratios["fixed"]["bpfo"])
    line = {row["record_id"]: row for row in rule.fault_lines(pd.concat([healthy, outer]))}["outer"]
    assert line["shows_line"] and "fixed" in line["shown_by"].split(", ")
    assert set(line["median_ratios"]) == {"features", *analyses}
    with pytest.raises(ValueError, match="no line ratios of segment"):
        rule.predict(outer.assign(record_id="elsewhere"))

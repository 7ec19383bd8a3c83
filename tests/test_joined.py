"""The joined method (condmon.joined): the classifier inside its fit's training range, the physics
rule outside it, scored in train's format."""

import numpy as np
import pandas as pd
import pytest

from condmon.joined import COVERAGE_COLUMNS, joined_metrics, joined_predictions, prediction_frame
from condmon.train import METRIC_COLUMNS, PREDICTION_COLUMNS

NAMES = ["kurtosis", "spread", "ratio"]


def _split(percent, trained=()):
    """unseen_fault-like: 'h' calibrates, 'a' and 'b' are tested, `trained` records train."""
    rows = [("h", "calibration"), ("a", "test"), ("b", "test")] + [(r, "train") for r in trained]
    return pd.DataFrame(
        {
            "protocol": "unseen_fault",
            "measured_percent": percent,
            "repeat": 0,
            "holdout": "",
            "record_id": [r for r, _ in rows],
            "segment": -1,
            "role": [role for _, role in rows],
        }
    )


def _case():
    # simulated: every feature within [0, 1]; a simulated validation record far out (never counts)
    simulated = pd.DataFrame(
        {
            "record_id": ["s0", "s1", "sv"],
            "segment": 0,
            "kurtosis": [0.0, 1.0, 50.0],
            "spread": [0.0, 1.0, 50.0],
            "ratio": [0.0, 1.0, 50.0],
        }
    )
    # measured: a0 inside; a1 out on spread (selected); b0 out on ratio alone (not selected at 0 %)
    measured = pd.DataFrame(
        {
            "record_id": ["h", "a", "a", "b", "t"],
            "segment": [0, 0, 1, 0, 0],
            "kurtosis": [0.5, 0.5, 0.5, 0.5, 0.5],
            "spread": [0.5, 0.5, 3.0, 0.5, 3.0],
            "ratio": [0.5, 0.5, 0.5, 9.0, 0.5],
        }
    )
    splits = pd.concat([_split(0), _split(50, trained=["t"])], ignore_index=True)
    splits = pd.concat(
        [
            splits,
            pd.DataFrame(
                {
                    "protocol": "unseen_fault",
                    "measured_percent": [0, 50],
                    "repeat": 0,
                    "holdout": "",
                    "record_id": "sv",
                    "segment": -1,
                    "role": "simulated_validation",
                }
            ),
        ],
        ignore_index=True,
    )
    tested = measured[measured["record_id"].isin(["a", "b"])]

    def calls(percent, label, name=None):
        frame = pd.DataFrame(
            {
                "protocol": "unseen_fault",
                "measured_percent": percent,
                "repeat": 0,
                "holdout": "",
                "record_id": tested["record_id"].to_numpy(),
                "segment": tested["segment"].to_numpy(),
                "speed_rpm": 1797.0,
                "true_label": ["ball", "ball", "outer_race"],
                "predicted_label": label,
                "uncertainty": np.nan,
            }
        )
        return frame if name is None else frame.assign(classifier=name)

    predictions = pd.concat([calls(0, "inner_race"), calls(50, "inner_race")], ignore_index=True)
    models = [
        {
            "measured_percent": 0,
            "repeat": 0,
            "holdout": "",
            "file": "m0.joblib",
            "selected_features": ["kurtosis", "spread"],
        },
        {"measured_percent": 50, "repeat": 0, "holdout": "", "file": "m50.joblib"},
    ]
    return simulated, measured, splits, predictions, models, calls


def test_the_rule_calls_the_segments_outside_the_fits_own_training_range():
    simulated, measured, splits, predictions, models, calls = _case()
    rule = pd.concat([calls(0, "ball", "envelope_rule"), calls(50, "ball", "envelope_rule")])
    joined, info, coverage = joined_predictions(
        "svm", predictions, rule, models, simulated, measured, splits, NAMES
    )
    at = {
        p: joined[joined["measured_percent"] == p].set_index(["record_id", "segment"])
        for p in (0, 50)
    }
    # 0 %: the fit used kurtosis and spread: a1 (spread 3) is outside, b0 (ratio 9) is not
    assert list(at[0]["outside_training"]) == [False, True, False]
    assert list(at[0]["predicted_label"]) == ["inner_race", "ball", "inner_race"]
    # 50 %: all features (no selection), the measured training record t widens spread to 3
    assert list(at[50]["outside_training"]) == [False, False, True]
    assert list(at[50]["predicted_label"]) == ["inner_race", "inner_race", "ball"]
    assert info["parts"] == ["svm", "envelope_rule"] and info["outside_training_share"] == 2 / 6
    assert list(prediction_frame(joined).columns) == PREDICTION_COLUMNS

    metrics = pd.DataFrame(
        {
            "classifier": "svm",
            "protocol": "unseen_fault",
            "measured_percent": [0, 50],
            "repeat": 0,
            "holdout": np.nan,
            "speed_rpm": np.nan,
            "accuracy": 0.0,
            "macro_f1": 0.0,
            "n_train_simulated": 2,
            "n_train_measured": [0, 1],
            "n_test": 3,
            "fit_seconds": 0.1,
        }
    )
    rows = joined_metrics("svm", joined, metrics)
    overall = rows[rows["speed_rpm"].isna()].set_index("measured_percent")
    assert set(overall["classifier"]) == {"joined_svm"} and set(METRIC_COLUMNS) <= set(rows.columns)
    assert overall.loc[0, "accuracy"] == pytest.approx(1 / 3)  # a1 now right (ball)
    assert overall.loc[50, "accuracy"] == 0.0  # b0 called ball, truly outer race
    assert list(overall["n_train_measured"]) == [0, 1]


def test_without_the_rules_predictions_the_classifier_keeps_its_calls():
    simulated, measured, splits, predictions, models, calls = _case()
    rule = calls(0, "ball", "envelope_rule")  # none at 50 %
    joined, info, _ = joined_predictions(
        "svm", predictions, rule, models, simulated, measured, splits, NAMES
    )
    assert (joined.loc[joined["measured_percent"] == 50, "predicted_label"] == "inner_race").all()
    assert info["splits_without_rule"] == [[50, 0, ""]]
    with pytest.raises(ValueError, match="no model listed"):
        joined_predictions("svm", predictions, rule, models[:1], simulated, measured, splits, NAMES)


def test_coverage_gives_each_records_share_outside_the_fits_own_range():
    """coverage.csv: per split and tested record, the share of its segments outside the training
    range on the fit's own features (the classifier's name: the range is its fit's), and which."""
    simulated, measured, splits, predictions, models, calls = _case()
    rule = pd.concat([calls(0, "ball", "envelope_rule"), calls(50, "ball", "envelope_rule")])
    _, _, coverage = joined_predictions(
        "svm", predictions, rule, models, simulated, measured, splits, NAMES
    )
    assert list(coverage.columns) == COVERAGE_COLUMNS and set(coverage["classifier"]) == {"svm"}
    rows = coverage.set_index(["measured_percent", "record_id"])
    # 0 %: kurtosis and spread only: a1 out on spread, b0's ratio 9 is no feature of the fit
    assert rows.loc[(0, "a"), ["n_segments", "outside_training"]].tolist() == [2, 0.5]
    assert rows.loc[(0, "a"), "features_outside_training"] == "spread"
    assert rows.loc[(0, "b"), "outside_training"] == 0.0
    assert rows.loc[(0, "a"), "features"] == "kurtosis, spread"
    # 50 %: all features, t widens spread: b0 out on ratio
    assert rows.loc[(50, "a"), "outside_training"] == 0.0
    assert rows.loc[(50, "b"), ["outside_training", "features_outside_training"]].tolist() == [
        1.0,
        "ratio",
    ]

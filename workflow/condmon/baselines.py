"""Training-free physics baselines a system supplies, evaluated on every split's test set.

A simulation-trained classifier must beat what physics alone says. A system offers such rules
(`System.physics_baselines(feature_names)`, e.g. a rule on the defect lines' envelope ratios); this module runs
each on the measured features of every split of a split table: `fit` on the split's calibration
segments only (role "calibration": healthy data that never train or test), `predict` on its test
segments. The predictions have train's columns plus `classifier` (the rule's name), so the
report scores them as it scores a classifier, on the very same test sets, and takes the gain of
the simulation against the strongest baseline. A split table without calibration segments (no
healthy record) gives a rule nothing to set its threshold on: no predictions, said in the log.
"""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd

from condmon.hybrid import CALIBRATION, measured_rows, segment_roles, validate_splits
from condmon.train import PREDICTION_COLUMNS, _split_keys

log = logging.getLogger(__name__)


def physics_predictions(
    baselines: dict, measured_features: pd.DataFrame, splits: pd.DataFrame
) -> tuple[pd.DataFrame, dict]:
    """(predictions, info) of every rule in `baselines` ({name: rule}) on every split.

    predictions: `classifier` (the rule's name) and train's PREDICTION_COLUMNS; info: per rule,
    its `describe()` after fitting on the first split's calibration segments (with a rule's
    `fault_lines`, whether each measured fault record shows its defect line), and the number of
    splits it was evaluated on."""
    validate_splits(splits)
    protocol = str(splits["protocol"].iloc[0])
    labels = measured_features["health_state"].astype(str).to_numpy()
    frames, info = [], {}
    for name, rule in baselines.items():
        evaluated = 0
        for percent, repeat, holdout in _split_keys(splits):
            split = splits[
                (splits["measured_percent"] == percent)
                & (splits["repeat"] == repeat)
                & (splits["holdout"] == holdout)
            ]
            role = segment_roles(measured_rows(split), measured_features)
            calibration, test = role == CALIBRATION, role == "test"
            if not calibration.any():
                log.warning(
                    "%s: split (%d %%, repeat %d, holdout %r) has no calibration "
                    "segment to set its threshold on: not evaluated",
                    name,
                    percent,
                    repeat,
                    holdout,
                )
                continue
            if not test.any():
                continue
            rule.fit(measured_features.loc[calibration])
            rows = measured_features.loc[test]
            frames.append(
                pd.DataFrame(
                    {
                        "classifier": name,
                        "protocol": protocol,
                        "measured_percent": percent,
                        "repeat": repeat,
                        "holdout": holdout,
                        "record_id": rows["record_id"].astype(str).to_numpy(),
                        "segment": rows["segment"].to_numpy(),
                        "speed_rpm": rows["speed_rpm"].to_numpy(float),
                        "true_label": labels[test],
                        "predicted_label": rule.predict(rows),
                        "uncertainty": np.nan,
                    }
                )
            )
            if not evaluated:
                info[name] = rule.describe()
                if hasattr(rule, "fault_lines"):  # every fault record: does its defect line show?
                    info[name]["fault_lines"] = rule.fault_lines(measured_features)
            evaluated += 1
        info.setdefault(name, rule.describe())["n_splits"] = evaluated
        log.info("%s: evaluated on %d splits of %s", name, evaluated, protocol)
    columns = ["classifier"] + PREDICTION_COLUMNS
    predictions = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=columns)
    predictions = predictions.astype(
        {
            "measured_percent": "int32",
            "repeat": "int32",
            "segment": "int32",
            "speed_rpm": float,
            "uncertainty": float,
        }
    )
    return predictions[columns], info

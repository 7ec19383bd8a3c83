"""The joined method: a simulation-trained classifier where it has training examples, the
system's training-free physics rule where it has none.

A classifier trained on simulation extrapolates, with full confidence, on a measured segment
whose features lie outside every training example (`hybrid.training_range`: the range of
each feature the fit uses, its selection's or all, over its training segments; `condmon predict`
flags such segments `outside_training`). The physics rule needs no training example: its
threshold comes from the healthy calibration segments alone (`condmon.baselines`). So the joined
method takes, per test segment, the classifier's call inside the fit's training range and the
rule's outside it. Which classifier is joined is the config's (`joined.classifiers`), chosen on
design records only; the range is the fit's own features', never all the candidates': a
feature the fit does not read says nothing of whether it extrapolates, and a healthy record
outside the range on such a feature would be handed to the rule for nothing.

Its predictions and metrics have train's format, under `joined/<name>/<protocol>/`, so the
report scores it as any classifier beside its parts (the classifier and the rule), on the very
same test sets. A split without the rule's predictions (no calibration segment to set its
threshold) keeps the classifier's call, said in the log and counted in `info.json`.
"""

from __future__ import annotations

import logging

import numpy as np
import pandas as pd

from condmon.hybrid import training_range, validate_splits
from condmon.train import PREDICTION_COLUMNS, metric_rows

log = logging.getLogger(__name__)

PREFIX = "joined_"  # joined_<classifier>: its name in every table and plot
SEGMENT_KEYS = ["measured_percent", "repeat", "holdout", "record_id", "segment"]
# coverage.csv: per split and tested record, how much of it lies outside the fit's training range
COVERAGE_COLUMNS = [
    "classifier",
    "protocol",
    "measured_percent",
    "repeat",
    "holdout",
    "record_id",
    "n_segments",
    "outside_training",
    "features_outside_training",
    "features",
]


def joined_name(classifier: str) -> str:
    return f"{PREFIX}{classifier}"


def outside_features(rows: pd.DataFrame, span: dict) -> pd.DataFrame:
    """Per row and feature of `span` (training_range's): whether it lies outside its range."""
    values = rows[span["features"]]
    return values.lt(np.asarray(span["low"], float)) | values.gt(np.asarray(span["high"], float))


def coverage_rows(split_key: dict, tested: pd.DataFrame, outside: pd.DataFrame) -> pd.DataFrame:
    """COVERAGE_COLUMNS of one split: per tested record, the share of its segments with a feature
    (of the fit's own) outside the fit's training range, and those features (most often out
    first)."""
    record = tested["record_id"].astype(str).to_numpy()
    per_feature = outside.set_axis(record).groupby(level=0).mean()
    share = outside.any(axis=1).set_axis(record).groupby(level=0).mean()
    leaving = [
        ", ".join(row[row > 0].sort_values(ascending=False, kind="stable").index)
        for _, row in per_feature.iterrows()
    ]
    return pd.DataFrame(
        {
            **split_key,
            "record_id": share.index,
            "n_segments": pd.Series(record).value_counts().reindex(share.index).to_numpy(),
            "outside_training": share.to_numpy(float),
            "features_outside_training": leaving,
            "features": ", ".join(outside.columns),
        }
    )


def joined_predictions(
    classifier: str,
    predictions: pd.DataFrame,
    rule: pd.DataFrame,
    models: list[dict],
    simulated: pd.DataFrame,
    measured: pd.DataFrame,
    splits: pd.DataFrame,
    names,
) -> tuple[pd.DataFrame, dict, pd.DataFrame]:
    """(predictions, info, coverage) of the joined method on every split the classifier was
    tested on.

    `predictions`: the classifier's (train's PREDICTION_COLUMNS); `rule`: the physics rule's on the
    same splits (`classifier` its name; empty: none); `models`: the train job's info.json
    `models` (each fit's split and `selected_features`); `names`: the feature candidates (a fit
    without a selection used them all). The predictions carry `outside_training` per segment;
    coverage (COVERAGE_COLUMNS, `classifier` the classifier's own name: the range is its fit's)
    the share of each tested record's segments outside it (issue 49's "simulation covers the
    machine", asked of the features the classifier uses)."""
    validate_splits(splits)
    rules = sorted(set(rule["classifier"])) if len(rule) else []
    if len(rules) > 1:
        raise ValueError(f"joined {classifier}: one physics rule to join, got {rules}")
    by_fit = {(int(m["measured_percent"]), int(m["repeat"]), m["holdout"] or ""): m for m in models}
    frames, coverage, without_rule = [], [], []
    keys = ["measured_percent", "repeat", "holdout"]
    for (percent, repeat, holdout), tested in predictions.groupby(keys, sort=True):
        model = by_fit.get((int(percent), int(repeat), holdout))
        if model is None:
            raise ValueError(
                f"joined {classifier}: no model listed for split ({percent} %, repeat "
                f"{repeat}, holdout {holdout!r}) in its info.json"
            )
        split = splits[
            (splits["measured_percent"] == percent)
            & (splits["repeat"] == repeat)
            & (splits["holdout"] == holdout)
        ]
        span = training_range(simulated, measured, split, model.get("selected_features") or names)
        features = tested[["record_id", "segment"]].merge(
            measured.astype({"record_id": str}), on=["record_id", "segment"], how="left"
        )
        out_by_feature = outside_features(features, span)
        outside = out_by_feature.any(axis=1).to_numpy()
        coverage.append(
            coverage_rows(
                {
                    "classifier": classifier,
                    "protocol": str(tested["protocol"].iloc[0]),
                    "measured_percent": int(percent),
                    "repeat": int(repeat),
                    "holdout": holdout,
                },
                tested,
                out_by_feature,
            )
        )
        calls = tested.merge(
            rule[SEGMENT_KEYS + ["predicted_label"]].rename(columns={"predicted_label": "_rule"}),
            on=SEGMENT_KEYS,
            how="left",
        )
        if calls["_rule"].isna().all():
            without_rule.append((int(percent), int(repeat), holdout))
        use_rule = outside & calls["_rule"].notna().to_numpy()
        frames.append(
            tested.assign(
                predicted_label=np.where(
                    use_rule,
                    calls["_rule"].to_numpy(object),
                    tested["predicted_label"].to_numpy(object),
                ).astype(str),
                outside_training=outside,
            )
        )
    if without_rule:
        log.warning(
            "joined %s: %d split(s) without the rule's predictions keep the classifier's calls: %s",
            classifier,
            len(without_rule),
            without_rule[:5],
        )
    joined = pd.concat(frames, ignore_index=True)
    info = {
        "classifier": joined_name(classifier),
        "parts": [classifier, *rules],
        "rule": rules[0] if rules else None,
        "method": (
            f"{classifier} where a segment's features (the fit's own) lie inside its "
            f"training range, the physics rule {rules[0] if rules else '(none)'} "
            "outside it"
        ),
        "outside_training_share": float(joined["outside_training"].mean()),
        "splits_without_rule": [list(k) for k in without_rule],
    }
    return joined, info, pd.concat(coverage, ignore_index=True)[COVERAGE_COLUMNS]


def joined_metrics(
    classifier: str, joined: pd.DataFrame, classifier_metrics: pd.DataFrame
) -> pd.DataFrame:
    """metrics.csv's rows of the joined predictions: train's figures per split (all speeds and
    each speed), the training counts and fit time the classifier's own."""
    keys = ["protocol", "measured_percent", "repeat", "holdout"]
    rows = []
    for key, tested in joined.groupby(keys, sort=True):
        rows += metric_rows(
            {"classifier": joined_name(classifier), **dict(zip(keys, key))},
            tested["true_label"],
            tested["predicted_label"],
            tested["speed_rpm"],
        )
    metrics = pd.DataFrame(rows)
    own = classifier_metrics[classifier_metrics["speed_rpm"].isna()]
    own = own.assign(holdout=[h if isinstance(h, str) else "" for h in own["holdout"]])[
        keys + ["n_train_simulated", "n_train_measured", "fit_seconds"]
    ]
    return metrics.merge(own, on=keys, how="left")


def prediction_frame(joined: pd.DataFrame) -> pd.DataFrame:
    """The joined predictions in train's columns (outside_training left to the info)."""
    return joined[PREDICTION_COLUMNS]

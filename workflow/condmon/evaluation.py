"""Evaluation figures a reviewer can trust, from the test predictions of the train stage.

Per evaluation (classifier, protocol, measured percentage, repeat, holdout), for all test data,
per operating condition (`hybrid.condition`, e.g. load: never a file's stored rpm) and, with
`report.design_records`, for the records design choices were tuned on and for the others apart
(and the records of specimens the model does not describe, `System.unmodelled_specimens`, in
rows of their own, `unmodelled`, never among the evaluation records):
- per-segment accuracy, per-record accuracy (majority vote of a record's test segments) and
  balanced accuracy (mean recall over the tested classes: a class of few segments weighs as much);
- the false-alarm rate: the share of healthy test segments called faulty;
- a 95 % Wilson interval on every accuracy and rate (segments of one record are not independent:
  the per-segment interval is optimistic) and `small_test_set` under 30 test segments;
- baselines that can win: chance (1 / classes), the majority class of the test set, the best
  measured-only classifier the split allows (any classifier's `measured_only.csv`: the same
  candidate features, its selection chosen by its own inner CV), and the system's training-free
  physics baselines on the same test set (`System.physics_baselines`, `condmon.baselines`); the
  gain is taken against the strongest of them, and is negative where a baseline wins. On the
  design and evaluation rows the same on those records alone (the measured-only baseline from
  its predictions).
Aggregated over repeats and holdouts (`summarise`): means, Wilson intervals on one repeat's
distinct test segments (a segment tested again by another repeat or holdout is no new data, so
identical repeats do not narrow them), and how many repeats differ (identical repeats are one
repeat, and said so).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy.special import ndtri

from condmon.labels import LEAKY_PROTOCOLS, format_speed

KEYS = ["classifier", "protocol", "measured_percent", "repeat", "holdout"]
SMALL_TEST_SET = 30  # segments: fewer, and an accuracy says little
ALL = "all"
UNMODELLED = "unmodelled"  # the records side of specimens the model does not describe
EVALUATION_COLUMNS = KEYS + [
    "condition",
    "records",
    "n_test",
    "accuracy",
    "accuracy_ci_low",
    "accuracy_ci_high",
    "n_records",
    "record_accuracy",
    "record_accuracy_ci_low",
    "record_accuracy_ci_high",
    "balanced_accuracy",
    "n_healthy",
    "false_alarm_rate",
    "false_alarm_ci_low",
    "false_alarm_ci_high",
    "small_test_set",
    "leaky",
    "chance",
    "majority_class",
    "measured_only_best",
    "physics_baseline",
    "physics_baseline_accuracy",
    "strongest_baseline",
    "strongest_baseline_accuracy",
    "gain_vs_strongest",
]


def wilson_interval(successes: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """The Wilson score interval of a proportion `successes / n` (NaN for n = 0), rounded to 4
    decimals: Newcombe's (1998) closed form as `scipy.stats.binomtest(...).proportion_ci(method=
    "wilson")` computes it, without the binomial test's p-value that made the report's thousands
    of test sets slow."""
    if n <= 0:
        return float("nan"), float("nan")
    k, n = int(successes), int(n)
    p, z = k / n, float(ndtri(0.5 + 0.5 * confidence))
    denom = 2 * (n + z**2)
    center = (2 * n * p + z**2) / denom
    delta = z / denom * math.sqrt(4 * n * p * (1 - p) + z**2)
    low = 0.0 if k == 0 else center - delta
    high = 1.0 if k == n else center + delta
    return round(float(low), 4), round(float(high), 4)


CODES = ("_record", "_true", "_predicted")


def coded(predictions: pd.DataFrame) -> pd.DataFrame:
    """`predictions` with integer codes, so that its test sets are scored on arrays: `_record`
    (each record id) and `_true`, `_predicted` (the labels of both columns, one code each in
    sorted order: the smaller code is the alphabetically first label)."""
    true = predictions["true_label"].to_numpy(dtype=str)
    predicted = predictions["predicted_label"].to_numpy(dtype=str)
    labels = np.unique(np.concatenate([true, predicted]))
    return predictions.assign(
        _record=pd.factorize(predictions["record_id"])[0],
        _true=np.searchsorted(labels, true),
        _predicted=np.searchsorted(labels, predicted),
    )


def record_hits(records: np.ndarray, true: np.ndarray, predicted: np.ndarray) -> tuple[int, int]:
    """(records, records whose majority vote is right) of a test set's segments, as integer codes
    (`coded`). A record's vote is its most predicted label; of equal counts the alphabetically
    first (the smallest code), so the vote is deterministic."""
    ids, first, row_record = np.unique(records, return_index=True, return_inverse=True)
    n_labels = int(max(true.max(), predicted.max())) + 1
    counts = np.bincount(row_record * n_labels + predicted, minlength=len(ids) * n_labels)
    votes = counts.reshape(len(ids), n_labels).argmax(axis=1)  # the first of equal counts
    return len(ids), int((votes == true[first]).sum())


def balanced_accuracy(test: pd.DataFrame) -> float:
    """Mean recall over the tested classes (predicted-only classes add no term), in the sorted
    order of the classes, as sklearn's balanced_accuracy_score sums them."""
    true = test["true_label"].to_numpy(dtype=str)
    hit = true == test["predicted_label"].to_numpy(dtype=str)
    return _balanced_accuracy(np.unique(true, return_inverse=True)[1], hit)


def _balanced_accuracy(true: np.ndarray, hit: np.ndarray) -> float:
    support = np.bincount(true)
    tested = support > 0
    return float(np.mean(np.bincount(true, weights=hit)[tested] / support[tested]))


def test_set_figures(test: pd.DataFrame, healthy_state: str | None) -> dict:
    """The figures of one test set (rows of the predictions table; `coded` once beforehand where
    many test sets of one table are scored)."""
    test = test if "_true" in test else coded(test)
    records, true, predicted = (test[column].to_numpy() for column in CODES)
    hit = true == predicted
    hits = int(hit.sum())
    n_records, right_records = record_hits(records, true, predicted)
    is_healthy = test["true_label"].to_numpy() == healthy_state
    n_healthy = int(is_healthy.sum())
    alarms = int((test["predicted_label"].to_numpy()[is_healthy] != healthy_state).sum())
    low, high = wilson_interval(hits, len(test))
    record_low, record_high = wilson_interval(right_records, n_records)
    alarm_low, alarm_high = wilson_interval(alarms, n_healthy)
    return {
        "n_test": len(test),
        "accuracy": hits / len(test),
        "accuracy_ci_low": low,
        "accuracy_ci_high": high,
        "n_records": n_records,
        "record_accuracy": right_records / n_records,
        "record_accuracy_ci_low": record_low,
        "record_accuracy_ci_high": record_high,
        "balanced_accuracy": _balanced_accuracy(true, hit),
        "n_healthy": n_healthy,
        "false_alarm_rate": alarms / n_healthy if n_healthy else np.nan,
        "false_alarm_ci_low": alarm_low,
        "false_alarm_ci_high": alarm_high,
        "small_test_set": len(test) < SMALL_TEST_SET,
    }


def with_conditions(predictions: pd.DataFrame, conditions: dict, condition: str) -> pd.DataFrame:
    """`predictions` with `_condition`, each record's "<condition>=<value>" (an error names the
    records that have none)."""
    predictions = predictions.assign(
        _condition=predictions["record_id"].map(
            lambda r: f"{condition}={format_speed(conditions[r])}" if r in conditions else ""
        )
    )
    missing = sorted(set(predictions.loc[predictions["_condition"] == "", "record_id"]))
    if missing:
        raise ValueError(f"record(s) {missing[:5]} have no {condition} in the measured features")
    return predictions


def record_side(record_ids: pd.Series, design: set, apart: set = frozenset()) -> np.ndarray:
    """Per record: "design", UNMODELLED (a record of a specimen the model does not describe, `apart`) or
    "evaluation" (every other record)."""
    ids = record_ids.astype(str)
    return np.where(ids.isin(apart), UNMODELLED, np.where(ids.isin(design), "design", "evaluation"))


def subsets(test: pd.DataFrame, design: set, apart: set = frozenset()):
    """(condition, records, rows) of a test set: all of it, per condition and, with design
    records or unmodelled records (`apart`), the design records, the unmodelled ones and the
    others ("evaluation") apart."""
    yield ALL, ALL, test
    for value, part in test.groupby("_condition", sort=True):
        yield value, ALL, part
    if design or apart:
        side = record_side(test["record_id"], design, apart)
        for name in ("design", "evaluation", UNMODELLED):
            if (side == name).any():
                yield ALL, name, test[side == name]


def evaluation_table(
    predictions: pd.DataFrame,
    healthy_state: str | None,
    labels,
    conditions: dict,
    condition: str,
    design_records=(),
    measured_only: pd.DataFrame | None = None,
    physics: pd.DataFrame | None = None,
    measured_only_predictions: pd.DataFrame | None = None,
    apart_records=(),
) -> pd.DataFrame:
    """One row per evaluation and subset (columns EVALUATION_COLUMNS).

    `conditions`: {record_id: value of `condition`}; `labels`: the task's classes (chance);
    `design_records`: records design choices were tuned on (subsets `design` and `evaluation`
    besides `all`); `measured_only`: the measured-only metrics rows of every classifier (all
    speeds rows used); `physics`: the physics baselines' predictions (`classifier` = the rule's
    name) on the same splits; `measured_only_predictions`: the measured-only baselines'
    predictions (`classifier` = the classifier), which score them on the design and evaluation
    records apart. Baselines and the gain are given on the rows of condition `all` (records
    `all`, `design`, `evaluation`; without measured-only predictions that baseline on `all`
    only, from its metrics, as on `all` always). `apart_records`: records of specimens the
    model does not describe (subset `unmodelled`, never `evaluation`).
    """
    design, apart = set(map(str, design_records)), set(map(str, apart_records))
    predictions = coded(with_conditions(predictions, conditions, condition))
    best_alone = _best_measured_only(measured_only)
    by_rule = _physics_accuracy(physics, design, apart)
    # the best measured-only classifier per split and side: the same bookkeeping as the rules'
    alone_by_records = {
        key: {records: max(by_classifier.values()) for records, by_classifier in sides.items()}
        for key, sides in _physics_accuracy(measured_only_predictions, design, apart).items()
    }
    rows = []
    for key, test in predictions.groupby(KEYS, sort=True):
        for condition_label, records, part in subsets(test, design, apart):
            row = dict(
                zip(KEYS, key),
                condition=condition_label,
                records=records,
                **test_set_figures(part, healthy_state),
                leaky=key[1] in LEAKY_PROTOCOLS,
            )
            if condition_label == ALL:
                # the measured-only baseline on all records from its metrics (as always), on the
                # design and evaluation records from its predictions where given
                alone = (
                    best_alone.get(key[1:])
                    if records == ALL
                    else alone_by_records.get(key[1:], {}).get(records)
                )
                row.update(
                    _baselines(
                        part,
                        row["accuracy"],
                        len(labels),
                        alone,
                        by_rule.get(key[1:], {}).get(records, {}),
                    )
                )
            rows.append(row)
    return pd.DataFrame(rows, columns=EVALUATION_COLUMNS)


def _best_measured_only(measured_only: pd.DataFrame | None) -> dict:
    """{(protocol, percent, repeat, holdout): the best measured-only accuracy of any classifier}."""
    if measured_only is None or measured_only.empty:
        return {}
    overall = measured_only[measured_only["speed_rpm"].isna()]
    best = overall.groupby(KEYS[1:])["accuracy"].max()
    return {(p, int(m), int(r), h): float(a) for (p, m, r, h), a in best.items()}


def _physics_accuracy(
    physics: pd.DataFrame | None, design: set = frozenset(), apart: set = frozenset()
) -> dict:
    """{(protocol, percent, repeat, holdout): {records: {rule: accuracy}}}: on that split's whole
    test set (records `all`) and, with design or unmodelled records, on its design, evaluation
    and unmodelled records.
    Any predictions with a `classifier` column (the rule, or a measured-only classifier)."""
    if physics is None or physics.empty:
        return {}
    hits = physics.assign(
        _hit=physics["true_label"] == physics["predicted_label"],
        _records=record_side(physics["record_id"], design, apart),
    )
    found = {}
    for by_records in [False, True] if design or apart else [False]:
        group = ["classifier"] + KEYS[1:] + (["_records"] if by_records else [])
        for key, value in hits.groupby(group)["_hit"].mean().items():
            rule, protocol, percent, repeat, holdout = key[:5]
            records = key[5] if by_records else ALL
            found.setdefault((protocol, int(percent), int(repeat), holdout), {}).setdefault(
                records, {}
            )[rule] = float(value)
    return found


def _baselines(
    test: pd.DataFrame, accuracy: float, n_labels: int, measured_only, physics: dict | None = None
) -> dict:
    """Chance, majority class of the test set, best measured-only, the best physics baseline
    ({rule: accuracy}); the strongest of all and the gain against it."""
    candidates = {
        "chance": 1.0 / n_labels,
        "majority_class": float(test["true_label"].value_counts(normalize=True).max()),
    }
    if measured_only is not None:
        candidates["measured_only_best"] = measured_only
    best_rule = max(physics, key=physics.get) if physics else None
    if best_rule is not None:
        candidates[best_rule] = physics[best_rule]
    strongest = max(candidates, key=candidates.get)
    return {
        "chance": candidates["chance"],
        "majority_class": candidates["majority_class"],
        "measured_only_best": measured_only if measured_only is not None else np.nan,
        "physics_baseline": best_rule or "",
        "physics_baseline_accuracy": physics[best_rule] if best_rule else np.nan,
        "strongest_baseline": strongest,
        "strongest_baseline_accuracy": candidates[strongest],
        "gain_vs_strongest": accuracy - candidates[strongest],
    }


def distinct_repeats(predictions: pd.DataFrame) -> pd.Series:
    """Per (classifier, protocol, measured_percent): how many repeats predicted differently
    (1: the repeats are one repeat, whatever `hybrid.repeats` says)."""

    def fingerprint(rows):
        ordered = rows.sort_values(["holdout", "record_id", "segment"])
        return hash(
            tuple(ordered["record_id"])
            + tuple(ordered["segment"])
            + tuple(ordered["predicted_label"])
        )

    prints = predictions.groupby(["classifier", "protocol", "measured_percent", "repeat"]).apply(
        fingerprint, include_groups=False
    )
    return prints.groupby(level=[0, 1, 2]).nunique().rename("distinct_repeats")


SUMMARY_MEANS = [
    "accuracy",
    "record_accuracy",
    "balanced_accuracy",
    "false_alarm_rate",
    "majority_class",
    "measured_only_best",
    "physics_baseline_accuracy",
    "strongest_baseline_accuracy",
    "gain_vs_strongest",
]


def distinct_tested(
    predictions: pd.DataFrame,
    healthy_state: str | None,
    conditions: dict,
    condition: str,
    design_records=(),
    apart_records=(),
) -> pd.DataFrame:
    """Per (classifier, protocol, measured_percent, repeat, condition, records): how many distinct
    segments, records and healthy segments the repeat tested over all its holdouts (a healthy
    record tested in every holdout counts once)."""
    design, apart = set(map(str, design_records)), set(map(str, apart_records))
    predictions = with_conditions(predictions, conditions, condition).assign(
        # each segment and each record numbered once, so that a test set's distinct ones are
        # counted on integers
        _segment=lambda p: p.groupby(["record_id", "segment"], sort=False).ngroup(),
        _record=lambda p: pd.factorize(p["record_id"])[0],
    )
    rows = []
    for key, test in predictions.groupby(KEYS[:4], sort=True):
        for condition_label, records, part in subsets(test, design, apart):
            segments = part["_segment"].to_numpy()
            healthy = segments[part["true_label"].to_numpy() == healthy_state]
            rows.append(
                dict(
                    zip(KEYS[:4], key),
                    condition=condition_label,
                    records=records,
                    distinct_segments=len(np.unique(segments)),
                    distinct_records=len(np.unique(part["_record"].to_numpy())),
                    distinct_healthy=len(np.unique(healthy)),
                )
            )
    return pd.DataFrame(rows)


def _pooled_interval(
    per_repeat: pd.DataFrame, successes: str, tested: str, distinct: str
) -> tuple[float, float]:
    """Wilson interval of one repeat's worth of data: per repeat the rate pooled over its
    holdouts times the distinct units it tested, averaged over repeats. Repeats (identical or
    not) and holdouts that test the same segments again add no independent data, so they do not
    narrow the interval."""
    rate = per_repeat[successes] / per_repeat[tested].where(per_repeat[tested] > 0)
    n = per_repeat[distinct].mean()
    if not n or rate.isna().all():
        return float("nan"), float("nan")
    return wilson_interval(round((rate * per_repeat[distinct]).mean()), round(n))


def summarise(
    table: pd.DataFrame,
    predictions: pd.DataFrame,
    healthy_state: str | None,
    conditions: dict,
    condition: str,
    design_records=(),
    apart_records=(),
) -> pd.DataFrame:
    """Per (classifier, protocol, measured_percent, condition, records): means over repeats and
    holdouts, Wilson intervals on one repeat's distinct test segments (records, healthy
    segments; see _pooled_interval), the number of repeats and of distinct ones, the strongest
    baseline named."""
    group = ["classifier", "protocol", "measured_percent", "condition", "records"]
    table = table.assign(
        _hits=(table["accuracy"] * table["n_test"]).round(),
        _record_hits=(table["record_accuracy"] * table["n_records"]).round(),
        _alarms=(table["false_alarm_rate"].fillna(0) * table["n_healthy"]).round(),
    )
    per_repeat = (
        table.groupby(group + ["repeat"], sort=True)[
            ["_hits", "n_test", "_record_hits", "n_records", "_alarms", "n_healthy"]
        ]
        .sum()
        .reset_index()
        .merge(
            distinct_tested(
                predictions, healthy_state, conditions, condition, design_records, apart_records
            ),
            on=group + ["repeat"],
            how="left",
        )
    )
    per_repeat = {key: part for key, part in per_repeat.groupby(group, sort=True)}
    rows = []
    for key, part in table.groupby(group, sort=True):
        repeats = per_repeat[key]
        row = dict(
            zip(group, key),
            n_repeats=int(part["repeat"].nunique()),
            n_evaluations=len(part),
            n_test_per_evaluation=part["n_test"].mean(),
            n_test_distinct=repeats["distinct_segments"].mean(),
            **{f"{c}_mean": part[c].mean() for c in SUMMARY_MEANS},
            accuracy_std=part.groupby("repeat")["accuracy"].mean().std(),
            physics_baseline=",".join(sorted(set(part["physics_baseline"].dropna()) - {""})),
            strongest_baseline=",".join(sorted(set(part["strongest_baseline"].dropna()))),
        )
        row["accuracy_ci_low"], row["accuracy_ci_high"] = _pooled_interval(
            repeats, "_hits", "n_test", "distinct_segments"
        )
        row["record_accuracy_ci_low"], row["record_accuracy_ci_high"] = _pooled_interval(
            repeats, "_record_hits", "n_records", "distinct_records"
        )
        row["false_alarm_ci_low"], row["false_alarm_ci_high"] = _pooled_interval(
            repeats, "_alarms", "n_healthy", "distinct_healthy"
        )
        row["small_test_set"] = row["n_test_per_evaluation"] < SMALL_TEST_SET
        row["leaky"] = bool(part["leaky"].any())
        rows.append(row)
    summary = pd.DataFrame(rows)
    distinct = distinct_repeats(predictions).reset_index()
    summary = summary.merge(distinct, on=["classifier", "protocol", "measured_percent"], how="left")
    # identical repeats are one repeat: no spread to report
    summary.loc[summary["distinct_repeats"] < 2, "accuracy_std"] = np.nan
    return summary

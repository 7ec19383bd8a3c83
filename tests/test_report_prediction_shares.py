"""The report's prediction shares per speed (the CFRP study's Fig. 9) and the simulated
validation accuracy in summary.json."""

import json

import numpy as np
import pandas as pd
import pytest

import fake_train_outputs as fake
from condmon import plots, train_tables
from condmon.report.loading import load_simulated_validation
from condmon.report.prediction_shares import prediction_shares, share_rows
from condmon.labels import label_order
from condmon.hybrid import SIMULATED_VALIDATION


def hand_built_predictions():
    """knn, record_split, 0 %: at 450 rpm 4 healthy segments (3 right, 1 as fault) over two
    repeats, 2 fault segments (both as healthy); at 775 rpm 2 healthy (right), no fault."""
    rows = [
        ("healthy", "healthy", 450.0, 0),
        ("healthy", "healthy", 450.0, 0),
        ("healthy", "healthy", 450.0, 1),
        ("healthy", "fault", 450.0, 1),
        ("fault", "healthy", 450.0, 0),
        ("fault", "healthy", 450.0, 1),
        ("healthy", "healthy", 775.0, 0),
        ("healthy", "healthy", 775.0, 1),
    ]
    frame = pd.DataFrame(rows, columns=["true_label", "predicted_label", "speed_rpm", "repeat"])
    return frame.assign(
        classifier="knn",
        protocol="record_split",
        measured_percent=0,
        holdout="",
        record_id=[f"r{i}" for i in range(len(rows))],
        segment=0,
    )


def test_hand_built_predictions_give_known_shares():
    labels = label_order(["fault", "healthy"], healthy_state="healthy")
    shares = prediction_shares(hand_built_predictions(), labels)
    assert list(shares.columns) == [
        "classifier",
        "protocol",
        "measured_percent",
        "speed_rpm",
        "true_label",
        "predicted_label",
        "share",
        "n",
    ]
    got = {
        (r.speed_rpm, r.true_label, r.predicted_label): (r.share, r.n) for r in shares.itertuples()
    }
    assert got == {
        (450.0, "healthy", "healthy"): (0.75, 4),
        (450.0, "healthy", "fault"): (0.25, 4),
        (450.0, "fault", "healthy"): (1.0, 2),
        (450.0, "fault", "fault"): (0.0, 2),
        (775.0, "healthy", "healthy"): (1.0, 2),
        (775.0, "healthy", "fault"): (0.0, 2),
    }
    # the fault was never tested at 775 rpm: no rows, not a share of 0
    assert shares[(shares.speed_rpm == 775.0) & (shares.true_label == "fault")].empty
    # rows in label order, the healthy state first
    assert list(shares.true_label[shares.speed_rpm == 450.0]) == ["healthy"] * 2 + ["fault"] * 2


def test_share_rows_of_one_matrix():
    counts = np.array([[3, 1, 0], [0, 0, 0], [2, 0, 2]])
    rows = share_rows(("k",), counts, ["a", "b", "c"])
    assert rows == [
        ("k", "a", "a", 0.75, 4),
        ("k", "a", "b", 0.25, 4),
        ("k", "a", "c", 0.0, 4),
        ("k", "c", "a", 0.5, 4),
        ("k", "c", "b", 0.0, 4),
        ("k", "c", "c", 0.5, 4),
    ]


@pytest.fixture(scope="module")
def fake_outputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("results") / "demo"
    paths = fake.build(root)
    # simulated validation files as the train stage writes them (hybrid share > 0)
    validation_paths = []
    for path in paths["metrics"]:
        frame = pd.read_csv(path)
        frame = frame.assign(accuracy=np.round(0.9 + 0.01 * frame["repeat"], 4), n_test=20)
        frame.insert(2, "test_source", SIMULATED_VALIDATION)
        target = path.parent / "simulated_validation.csv"
        frame.to_csv(target, index=False)
        validation_paths.append(target)
    return root, paths, validation_paths


def build_report(paths, out, simulated_validation=()):
    """The report with prediction_shares.csv, no healthy state (labels sorted alone)."""
    return fake.write_report(
        paths,
        out,
        run={"healthy_state": None},
        train={"simulated_validation": simulated_validation},
        outputs={"prediction_shares": out / "prediction_shares.csv"},
    )


@pytest.fixture(scope="module")
def reports(fake_outputs):
    """The report without (share 0) and with simulated validation files: (folder, summary) each."""
    root, paths, validation_paths = fake_outputs
    without = build_report(paths, root / "without")
    with_validation = build_report(paths, root / "with", simulated_validation=validation_paths)
    return (root / "without", without), (root / "with", with_validation)


@pytest.mark.slow
def test_prediction_shares_csv_matches_the_predictions(fake_outputs, reports):
    _, paths, _ = fake_outputs
    (out, summary), _ = reports
    shares = pd.read_csv(out / "prediction_shares.csv")
    keys = ["classifier", "protocol", "measured_percent", "speed_rpm", "true_label"]
    # every true class's shares at every speed sum to 1, over every predicted class
    assert np.allclose(shares.groupby(keys)["share"].sum(), 1.0)
    assert (shares.groupby(keys).size() == len(fake.LABELS)).all()
    # against the predictions themselves, pooled over repeats
    predictions = train_tables.load_predictions(paths["predictions"])
    chosen = predictions[
        (predictions.classifier == "logreg")
        & (predictions.protocol == "condition_holdout")
        & (predictions.measured_percent == 50)
        & (predictions.speed_rpm == 900.0)
        & (predictions.true_label == "surface_fault")
    ]
    row = shares[
        (shares.classifier == "logreg")
        & (shares.protocol == "condition_holdout")
        & (shares.measured_percent == 50)
        & (shares.speed_rpm == 900.0)
        & (shares.true_label == "surface_fault")
    ].set_index("predicted_label")
    assert (row.n == len(chosen)).all()
    for label in fake.LABELS:
        assert row.loc[label, "share"] == pytest.approx((chosen.predicted_label == label).mean())
    # one plot per classifier and protocol, beside the confusion matrices
    for clf in fake.CLASSIFIERS:
        for protocol in fake.PROTOCOL_HOLDOUTS:
            name = f"prediction_shares_{clf}_{protocol}.png"
            assert name in summary["plots"]
            assert (out / "plots" / name).read_bytes()[:4] == b"\x89PNG"
    assert "simulated_validation" not in summary  # share 0: no such key


@pytest.mark.slow
def test_simulated_validation_in_summary_apart_from_the_measured_results(reports):
    (plain, without), (out, summary) = reports
    # the measured numbers are the same with and without a simulated validation
    assert summary["results"] == without["results"]
    assert (out / "accuracy.csv").read_text() == (plain / "accuracy.csv").read_text()
    assert {k: v for k, v in summary.items() if k != "simulated_validation"} == without
    section = summary["simulated_validation"]
    assert section["test_source"] == SIMULATED_VALIDATION and "SIMULATED" in section["label"]
    row = next(
        r
        for r in section["results"]
        if r["classifier"] == "knn"
        and r["protocol"] == "record_split"
        and r["measured_percent"] == 50
    )
    assert row["accuracy_mean"] == pytest.approx(0.905)  # repeats 0.90 and 0.91
    assert row["accuracy_mean_per_speed"] == pytest.approx({"600": 0.905, "900": 0.905})
    assert row["n_validation_segments"] == 20 and row["n_repeats"] == 2
    assert {r["classifier"] for r in section["results"]} == set(fake.CLASSIFIERS)
    assert json.loads((out / "summary.json").read_text()) == summary


@pytest.mark.slow
def test_simulated_validation_file_with_another_source_is_refused(fake_outputs, tmp_path):
    _, _, validation_paths = fake_outputs
    bad = tmp_path / "simulated_validation.csv"
    pd.read_csv(validation_paths[0]).assign(test_source="measured").to_csv(bad, index=False)
    with pytest.raises(train_tables.ReportInputError, match="test_source"):
        load_simulated_validation([bad])
    empty = tmp_path / "empty.csv"
    pd.read_csv(validation_paths[0]).iloc[:0].to_csv(empty, index=False)
    assert load_simulated_validation([empty]) is None


def test_plot_with_an_untested_class_and_many_labels():
    labels = [f"class_{i}" for i in range(6)]
    predictions = pd.DataFrame(
        {
            "classifier": "svm",
            "protocol": "segment_share",
            "measured_percent": [0] * 6 + [50] * 3,
            "speed_rpm": 1797.0,
            "true_label": labels + labels[:3],
            "predicted_label": labels[1:] + labels[:1] + labels[:3],
        }
    )
    shares = prediction_shares(predictions, labels)
    fig = plots.prediction_shares(shares, labels, "svm", "segment_share", [0, 50], "note")
    titles = [ax.get_title() for ax in fig.axes if ax.get_visible()]
    assert any("class_5" in t and "50 %" in t for t in titles)  # shown, marked "not tested"
    assert "LEAKY" in fig._suptitle.get_text()
    plots.plt.close(fig)

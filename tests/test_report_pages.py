"""The report's front-page headline, its tables as HTML, figures per operating condition, and
plot text that fits its figure, on small fake train outputs."""

import json
import re

import numpy as np
import pandas as pd
import pytest

import fake_train_outputs as fake
from condmon import labels, plots
from condmon.features import read_feature_table, write_feature_table
from condmon.report.headline import CEILING_MODEL
from condmon.report.pages import write_pages
from condmon.train_tables import ReportInputError


ONE_CLASSIFIER = {"knn": {"n_neighbors": 3}}


@pytest.fixture(scope="module")
def one_classifier_outputs(tmp_path_factory):
    """One classifier: every claim here holds per classifier, and the report's plots (most of a
    test's time) are drawn per classifier."""
    root = tmp_path_factory.mktemp("results") / "demo"
    return root, fake.build(root, classifiers=ONE_CLASSIFIER)


def write(paths, out, sections, outputs=(), **parts):
    """The report's `sections` with the headline table among the outputs (fake.write_sections:
    `outputs`, `parts`): a claim's own sections, not the whole report's ~20 plots."""
    return fake.write_sections(
        paths, out, sections, outputs={"headline": out / "headline.csv", **dict(outputs)}, **parts
    )


def expected_means(accuracy_csv) -> dict:
    """{(classifier, protocol, percent): mean accuracy over repeats} from accuracy.csv, computed
    here: the all-speeds rows, a repeat's held-out conditions averaged first."""
    table = pd.read_csv(accuracy_csv)
    whole = table[table["speed_rpm"].isna()]
    per_repeat = whole.groupby(["classifier", "protocol", "measured_percent", "repeat"])[
        "accuracy"
    ].mean()
    return per_repeat.groupby(level=[0, 1, 2]).mean().to_dict()


def test_the_headline_gives_the_accuracy_at_both_ends_beside_the_baselines(
    one_classifier_outputs, tmp_path
):
    _, paths = one_classifier_outputs
    # a measured-only baseline 0.25 below the knn's accuracy; a physics rule that is always right
    baselines, physics = [], []
    for path in paths["metrics"]:
        frame = pd.read_csv(path)
        target = tmp_path / "mo" / path.parent.parent.name / path.parent.name / "measured_only.csv"
        target.parent.mkdir(parents=True)
        if frame["classifier"].iloc[0] == "knn":
            frame = frame.assign(accuracy=frame["accuracy"] - 0.25)
        else:
            frame = frame.iloc[:0]
        frame.to_csv(target, index=False)
        baselines.append(target)
    for path in paths["predictions"]:
        if "/knn/" in str(path):
            frame = pd.read_parquet(path).assign(classifier="oracle_rule")
            frame = frame.assign(predicted_label=frame["true_label"])
            target = tmp_path / "baselines" / path.parent.name / "predictions.parquet"
            target.parent.mkdir(parents=True)
            frame.to_parquet(target)
            physics.append(target)
    out = tmp_path / "report"
    write(
        paths,
        out,
        ["accuracy", "evaluation", "ceiling", "headline"],
        train={"measured_only": baselines, "physics": physics},
        evaluation={"measured_features": paths["features_measured"], "condition": "speed_rpm"},
    )
    headline = pd.read_csv(out / "headline.csv", dtype=str)
    low, high = fake.PERCENTS[0], fake.PERCENTS[-1]
    columns = ["simulation only (0 % measured)", f"{high} % measured"]
    assert list(headline.columns) == ["records", "protocol", "model", *columns]
    assert set(headline.records) == {"all"}  # no design records declared
    means = expected_means(out / "accuracy.csv")
    for (classifier, protocol, percent), mean in means.items():
        if percent not in (low, high):
            continue
        row = headline[
            (headline.protocol == protocol)
            & (headline.model == f"{classifier} (simulated + measured)")
        ]
        assert len(row) == 1, (classifier, protocol)
        cell = row.iloc[0][columns[0] if percent == low else columns[1]]
        assert float(cell.split()[0]) == pytest.approx(mean, abs=5e-4), (
            classifier,
            protocol,
            percent,
        )
    # last, the ceiling: the measured records alone, each left out (summary.json's figure)
    ceiling = headline.iloc[-1]
    assert ceiling.model == CEILING_MODEL and ceiling[columns[0]] == "-"
    separability = json.loads((out / "summary.json").read_text())["measured_separability"]["all"]
    assert float(ceiling[columns[1]].split()[0]) == pytest.approx(
        separability["balanced_accuracy"], abs=5e-4
    )
    assert f"chance {separability['chance']['mean']:.3f}" in ceiling[columns[1]]
    for protocol in headline.protocol.unique()[:-1]:
        rows = headline[headline.protocol == protocol].set_index("model")
        alone = rows.loc["baseline: measured data only (best classifier)", columns[1]]
        assert float(alone.split()[0]) == pytest.approx(
            means[("knn", protocol, high)] - 0.25, abs=5e-4
        )
        assert alone.endswith("knn")  # which measured-only classifier was best
        assert rows.loc["baseline: physics rule oracle_rule (no training)", columns[1]] == "1.000"
        assert rows.loc["chance", columns[0]] == f"{1 / len(fake.LABELS):.3f}"

    # the pages: every table as an HTML table, the headline's numbers in its own
    config = tmp_path / "config.yaml"
    config.write_text("run_name: demo\n")
    pages = tmp_path / "pages"
    names = write_pages(
        {"accuracy": out / "accuracy.csv", "evaluation_summary": out / "evaluation_summary.csv"},
        out / "headline.csv",
        {"rig": paths["calibration_params"]},
        out / "plots",
        config,
        pages,
        protocols=labels.PROTOCOL_LABELS,
        bench_differences=[
            {
                "difference": "block housings",
                "handled": "neither",
                "how": "point masses",
                "within_range": None,
            }
        ],
    )
    assert names == [
        "headline",
        "accuracy",
        "evaluation_summary",
        "protocols",
        "bench_differences",
        "calibration_rig",
    ]
    for name in names:
        page = (pages / "tables" / f"{name}.html").read_text()
        assert page.startswith("<!DOCTYPE html>") and "<table" in page, name
    headline_page = (pages / "tables" / "headline.html").read_text()
    for cell in headline[columns[1]]:
        assert f"<td>{cell}</td>" in headline_page
    rows = re.findall(r"<tr[ >]", (pages / "tables" / "accuracy.html").read_text())
    assert len(rows) == len(pd.read_csv(out / "accuracy.csv")) + 1  # every row and the header
    assert "parameter: " in (pages / "tables" / "calibration_rig.html").read_text()
    assert "LEAKY" in (pages / "tables" / "protocols.html").read_text()  # segment_share's test set
    assert "<td>block housings</td>" in (pages / "tables" / "bench_differences.html").read_text()
    assert sorted(p.name for p in (pages / "plots").iterdir()) == sorted(
        p.name for p in (out / "plots").iterdir()
    )
    assert (pages / "headline.csv").read_text() == (out / "headline.csv").read_text()
    assert (pages / "config.yaml").read_text() == "run_name: demo\n"


def test_a_cwru_like_condition_groups_the_figures_by_load_not_by_each_files_rpm(
    one_classifier_outputs, tmp_path
):
    """As on CWRU: every file stores its own measured speed (a dozen rpm values), the operating
    condition is the motor load (two values). The per-condition figures and prediction_shares.csv
    group by the load."""
    root, paths = one_classifier_outputs
    features, names = read_feature_table(paths["features_measured"])
    records = sorted(features["record_id"].unique())
    load_of = {record: float(i % 2) for i, record in enumerate(records)}
    rpm_of = {
        record: 1720.0 + 3 * i for i, record in enumerate(records)
    }  # one stored speed per file
    features["load"] = features["record_id"].map(load_of)
    features_path = tmp_path / "measured.parquet"
    write_feature_table(features, names, features_path)
    predictions = []
    for path in paths["predictions"]:
        frame = pd.read_parquet(path)
        frame["speed_rpm"] = frame["record_id"].map(rpm_of)
        target = (
            tmp_path / "train" / path.parent.parent.name / path.parent.name / "predictions.parquet"
        )
        target.parent.mkdir(parents=True)
        frame.to_parquet(target)
        predictions.append(target)
    out = tmp_path / "report"
    summary = write(
        dict(paths, predictions=predictions),
        out,
        ["accuracy", "prediction_shares", "conditions", "fault_signatures"],
        evaluation={"measured_features": features_path, "condition": "load"},
        outputs={"prediction_shares": out / "prediction_shares.csv"},
    )
    confusion = sorted(name for name in summary["plots"] if name.startswith("confusion_"))
    pairs = {f"{c}_{p}" for c in ONE_CLASSIFIER for p in ("record_split", "condition_holdout")}
    assert confusion == sorted(
        f"confusion_{pair}_{part}.png" for pair in pairs for part in ("all", "load0", "load1")
    )
    assert "accuracy_per_speed.png" not in summary["plots"]  # accuracy_per_condition covers it
    assert "accuracy_per_condition.png" in summary["plots"]
    # no simulated features given: no fault signatures
    assert "fault_signatures" not in summary and "fault_signatures.png" not in summary["plots"]
    shares = pd.read_csv(out / "prediction_shares.csv")
    assert "speed_rpm" not in shares.columns and set(shares["load"]) == {0.0, 1.0}
    # n: a true class's test segments at that load, pooled over repeats and holdouts
    tested = pd.concat(
        pd.read_parquet(p).assign(classifier=p.parent.parent.name) for p in predictions
    )
    tested["load"] = tested["record_id"].map(load_of)
    counts = tested.groupby(
        ["classifier", "protocol", "measured_percent", "load", "true_label"]
    ).size()
    firsts = shares.groupby(["classifier", "protocol", "measured_percent", "load", "true_label"])[
        "n"
    ].first()
    assert firsts.to_dict() == counts.to_dict()


def test_a_tested_record_without_a_condition_is_named(one_classifier_outputs, tmp_path):
    _, paths = one_classifier_outputs
    features = pd.read_parquet(paths["features_measured"])
    dropped = sorted(features["record_id"].unique())[0]
    features = features[features["record_id"] != dropped]
    features_path = tmp_path / "measured.parquet"
    features.to_parquet(features_path)
    with pytest.raises(ReportInputError, match=f"no 'load'.*{dropped}"):
        write(
            paths,
            tmp_path / "report",
            ["prediction_shares"],
            evaluation={"measured_features": features_path, "condition": "load"},
        )


def texts_outside(fig) -> list[str]:
    """The texts (titles, footnote, legend entries, tick labels) that reach beyond the figure."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    width, height = fig.bbox.width, fig.bbox.height
    texts = list(fig.texts) + [
        legend_text for legend in fig.legends for legend_text in legend.get_texts()
    ]
    if fig._suptitle is not None:
        texts.append(fig._suptitle)
    for ax in fig.axes:
        texts += [ax.title, ax.xaxis.label, ax.yaxis.label]
        for axis, (low, high) in (
            (ax.xaxis, sorted(ax.get_xlim())),
            (ax.yaxis, sorted(ax.get_ylim())),
        ):
            # the tick labels drawn: those inside the view limits
            texts += [
                tick.label1 for tick in axis.get_major_ticks() if low <= tick.get_loc() <= high
            ]
    outside = []
    for text in texts:
        if not text.get_visible() or not text.get_text():
            continue
        box = text.get_window_extent(renderer)
        if box.x0 < -1 or box.y0 < -1 or box.x1 > width + 1 or box.y1 > height + 1:
            outside.append(text.get_text())
    return outside


LONG_NOTE = (
    "Data: virtual bench (synthetic) | run a-rather-long-run-name | bench differs from the "
    "model in form: 8 effects (summary.json) | a footnote long enough to need a second line"
)


def test_a_confusion_matrix_keeps_its_whole_footnote_inside_the_figure():
    counts = np.array([[5, 1, 0], [2, 3, 1], [0, 0, 6]])
    fig = plots.confusion_matrices(
        {0: (counts, 2), 100: (counts, 2)}, fake.LABELS, "svm", "record_split", None, LONG_NOTE
    )
    assert texts_outside(fig) == []
    small = plots.confusion_matrix_small(
        counts,
        fake.LABELS,
        "svm, record_split, 0 % measured, repeat 0, held out: speed_rpm=600",
        LONG_NOTE,
    )
    assert texts_outside(small) == []
    assert "counts summed over repeats" in " ".join(t.get_text() for t in fig.texts).replace(
        "\n", " "
    )


def test_recall_and_gain_titles_are_short_and_every_text_fits():
    rows = []
    for classifier in ("knn", "svm"):
        for protocol in ("condition_holdout", "record_split", "segment_share"):
            for percent in (0, 50, 100):
                for label in fake.LABELS:
                    rows.append(
                        {
                            "classifier": classifier,
                            "protocol": protocol,
                            "measured_percent": percent,
                            "true_label": label,
                            "recall": 0.5,
                        }
                    )
    recall = plots.recall_per_class(pd.DataFrame(rows), LONG_NOTE)
    titles = [ax.get_title() for ax in recall.axes if ax.get_title()]
    assert len(titles) == 6 and all(title.count("\n") <= 1 for title in titles)
    assert texts_outside(recall) == []
    gain = pd.DataFrame(
        [
            {
                "classifier": c,
                "protocol": p,
                "measured_percent": m,
                "hybrid": 0.6,
                "strongest": 0.5,
                "gain": 0.1,
                "measured_only_best": 0.5,
                "physics_baseline_accuracy": 0.4,
                "majority_class": 0.33,
            }
            for c in ("knn", "svm")
            for p in ("record_split", "condition_holdout")
            for m in (0, 50, 100)
        ]
    )
    figure = plots.simulation_gain(gain, 1 / 3, LONG_NOTE)
    assert all(ax.get_title().count("\n") <= 1 for ax in figure.axes)
    assert texts_outside(figure) == []  # the legend's entries too

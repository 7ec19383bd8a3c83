"""The report stage on small fake train outputs: accuracy table, summary, plots."""
import json

import numpy as np
import pandas as pd
import pytest

import fake_train_outputs as fake
from condmon import report


@pytest.fixture(scope="module")
def train_outputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("results") / "demo"
    return root, fake.build(root)


@pytest.fixture(scope="module")
def built_report(train_outputs):
    root, paths = train_outputs
    out = root / "report"
    summary = report.write_report(
        paths["metrics"], paths["predictions"], paths["calibration_params"],
        paths["calibration_spectra"], paths["calibration_history"],
        accuracy_path=out / "accuracy.csv", summary_path=out / "summary.json",
        plots_dir=out / "plots", run_name="demo", data_source="virtual_bench",
        confusion_percent=[0])
    return out, paths, summary


def test_accuracy_csv_is_the_sorted_concatenation_of_metrics(built_report):
    out, paths, _ = built_report
    table = pd.read_csv(out / "accuracy.csv")
    assert list(table.columns) == ["classifier", "protocol", "measured_percent", "repeat",
                                   "speed_rpm", "accuracy", "macro_f1", "holdout",
                                   "n_train_simulated", "n_train_measured", "n_test"]
    metrics = pd.concat(pd.read_csv(p) for p in paths["metrics"])
    assert len(table) == len(metrics)
    # speed_rpm empty on the all-speeds rows; one per evaluation
    n_evaluations = len(fake.CLASSIFIERS) * len(fake.PERCENTS) * len(fake.REPEATS) * 3
    assert table["speed_rpm"].isna().sum() == n_evaluations
    assert np.isclose(table["accuracy"].sum(), metrics["accuracy"].sum())
    raw = (out / "accuracy.csv").read_text().splitlines()
    assert raw[1].startswith("knn,condition_holdout,0,0,,")  # sorted, all-speeds row first


def test_summary_aggregates_over_repeats_and_labels_the_source(built_report):
    out, paths, summary = built_report
    assert json.loads((out / "summary.json").read_text()) == summary
    source = summary["data_source"]
    assert source["kind"] == "virtual_bench" and source["synthetic"] is True
    assert source["label"] == "virtual bench (synthetic)" and "not real" in source["note"]
    assert summary["calibration"]["contact_law"] == "hertz"
    assert summary["calibration"]["evaluations"] == 40
    accuracy = pd.read_csv(out / "accuracy.csv", keep_default_na=True)
    accuracy["holdout"] = accuracy["holdout"].fillna("")
    row = next(r for r in summary["results"] if r["classifier"] == "logreg"
               and r["protocol"] == "record_split" and r["measured_percent"] == 50)
    expected = accuracy[(accuracy.classifier == "logreg") & (accuracy.protocol == "record_split")
                        & (accuracy.measured_percent == 50) & accuracy.speed_rpm.isna()]
    assert row["n_repeats"] == 2
    assert row["accuracy_mean"] == pytest.approx(expected["accuracy"].mean())
    assert row["accuracy_std"] == pytest.approx(expected["accuracy"].std())
    assert set(row["accuracy_mean_per_speed"]) == {"600", "900"}
    # condition_holdout: holdouts are averaged within a repeat before the spread over repeats
    row = next(r for r in summary["results"] if r["classifier"] == "knn"
               and r["protocol"] == "condition_holdout" and r["measured_percent"] == 0)
    holdout_rows = accuracy[(accuracy.classifier == "knn")
                            & (accuracy.protocol == "condition_holdout")
                            & (accuracy.measured_percent == 0) & accuracy.speed_rpm.isna()]
    per_repeat = holdout_rows.groupby("repeat")["accuracy"].mean()
    assert row["accuracy_mean"] == pytest.approx(per_repeat.mean())
    assert row["accuracy_min"] == pytest.approx(per_repeat.min())
    assert summary["n_measured_records"] == len(fake.LABELS) * len(fake.SPEEDS) * 3


def test_plots_exist_are_listed_and_are_real_images(built_report):
    out, _, summary = built_report
    plots = sorted(p.name for p in (out / "plots").iterdir())
    assert plots == sorted(summary["plots"])
    expected = {"accuracy_vs_measured_percent.png", "accuracy_per_speed.png",
                "spectra_measured_vs_calibrated.png", "calibration_convergence.png",
                "confusion_knn_record_split_all.png", "confusion_logreg_condition_holdout_600rpm.png"}
    assert expected <= set(plots)
    # classifiers x protocols x (all + 2 speeds) confusion figures, 4 others
    assert len(plots) == 2 * 2 * 3 + 4
    for name in plots:
        data = (out / "plots" / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n", name
        assert len(data) > 15_000, f"{name} looks empty ({len(data)} bytes)"
    assert not list(out.glob(".*tmp*")), "temporary files left behind"


def test_unknown_confusion_percent_names_the_available_ones(train_outputs, tmp_path):
    _, paths = train_outputs
    with pytest.raises(report.ReportInputError, match=r"confusion_percent \[30\].*\[0, 50\]"):
        report.write_report(paths["metrics"], paths["predictions"], paths["calibration_params"],
                            paths["calibration_spectra"], paths["calibration_history"],
                            tmp_path / "a.csv", tmp_path / "s.json", tmp_path / "plots",
                            "demo", "virtual_bench", confusion_percent=[30])
    assert not (tmp_path / "a.csv").exists() and not (tmp_path / "plots").exists()


def test_metrics_file_missing_a_column_is_named(tmp_path):
    bad = tmp_path / "train/knn/record_split/metrics.csv"
    bad.parent.mkdir(parents=True)
    pd.DataFrame({"classifier": ["knn"], "accuracy": [0.5]}).to_csv(bad, index=False)
    with pytest.raises(report.ReportInputError, match=f"{bad}.*lacks columns"):
        report.load_metrics([bad])


def test_source_labels_never_call_synthetic_data_real():
    assert report.data_source_label("virtual_bench") == "virtual bench (synthetic)"
    assert report.is_synthetic("virtual_bench") and not report.is_synthetic("measured")

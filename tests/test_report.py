"""The report stage on small fake train outputs: accuracy table, summary, plots."""

import json
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import fake_train_outputs as fake
from condmon import labels, train_tables
from condmon.report.accuracy import labelled_accuracy
from condmon.report.evaluation_tables import design_summary
from condmon.report.headline import CEILING_MODEL, NO_EVALUATION_SPECIMEN, headline_table
from condmon.report.loading import design_record_ids, load_fault_lines
from condmon.report.prediction_shares import confusion_counts, record_sides
from condmon.report.recall_per_record import fault_lines_summary, recall_per_record


@pytest.fixture(scope="module")
def train_outputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("results") / "demo"
    return root, fake.build(root)


def evaluated_report(paths, out, evaluation=(), sections=None, **parts):
    """The report on the fake train outputs with the evaluation tables (per-speed), into `out`;
    `evaluation`, `parts`: fields of ReportInputs' groups (fake.report_inputs). With `sections`
    (registry names) only those sections run (fake.write_sections: their tables and plots)."""
    evaluation = {
        "measured_features": paths["features_measured"],
        "condition": "speed_rpm",
        **dict(evaluation),
    }
    if sections is not None:
        return fake.write_sections(paths, out, sections, evaluation=evaluation, **parts)
    return fake.write_report(paths, out, evaluation=evaluation, **parts)


@pytest.fixture(scope="module")
def built_report(train_outputs):
    root, paths = train_outputs
    out = root / "report"
    summary = evaluated_report(paths, out, evaluation={"design_records": DESIGN})
    return out, paths, summary


DESIGN = ["virtual_bench_healthy_600_0", "virtual_bench_missing_tooth_600_0"]


@pytest.mark.slow
def test_accuracy_csv_is_the_sorted_concatenation_of_metrics(built_report):
    out, paths, _ = built_report
    table = pd.read_csv(out / "accuracy.csv")
    assert list(table.columns) == [
        "classifier",
        "protocol",
        "measured_percent",
        "repeat",
        "speed_rpm",
        "accuracy",
        "macro_f1",
        "holdout",
        "n_train_simulated",
        "n_train_measured",
        "n_test",
        "leaky",
        "accuracy_ci_low",
        "accuracy_ci_high",
        "small_test_set",
    ]
    assert (table["accuracy_ci_low"] <= table["accuracy"]).all() and (
        table["accuracy"] <= table["accuracy_ci_high"]
    ).all()
    metrics = pd.concat(pd.read_csv(p) for p in paths["metrics"])
    assert len(table) == len(metrics)
    # speed_rpm empty on the all-speeds rows; one per evaluation
    n_evaluations = len(fake.CLASSIFIERS) * len(fake.PERCENTS) * len(fake.REPEATS) * 3
    assert table["speed_rpm"].isna().sum() == n_evaluations
    assert np.isclose(table["accuracy"].sum(), metrics["accuracy"].sum())
    raw = (out / "accuracy.csv").read_text().splitlines()
    assert raw[1].startswith("knn,condition_holdout,0,0,,")  # sorted, all-speeds row first


def test_confusion_sides_split_the_tested_records_by_specimen():
    predictions = pd.DataFrame({"record_id": ["d0", "e0", "d1", "e1", "e0"]})

    def sides_of(design_records):
        return record_sides(predictions["record_id"].isin(design_records))

    sides = {name: mask for name, mask, _ in sides_of(["d0", "d1", "unseen"])}
    assert list(predictions[sides["evaluation"]].record_id) == ["e0", "e1", "e0"]
    assert list(predictions[sides["design"]].record_id) == ["d0", "d1"]
    # one side tested alone (the shared CWRU records are all of design specimens): no split
    assert sides_of(["d0", "d1", "e0", "e1"]) == []
    assert sides_of([]) == []


@pytest.mark.slow
def test_summary_aggregates_over_repeats_and_labels_the_source(built_report):
    out, paths, summary = built_report
    assert json.loads((out / "summary.json").read_text()) == summary
    source = summary["data_source"]
    assert source["kind"] == "virtual_bench" and source["synthetic"] is True
    assert source["label"] == "virtual bench (synthetic)" and "not real" in source["note"]
    assert summary["calibration"]["model_variant"] == "hertz"
    assert summary["calibration"]["evaluations"] == 40
    accuracy = pd.read_csv(out / "accuracy.csv", keep_default_na=True)
    accuracy["holdout"] = accuracy["holdout"].fillna("")
    row = next(
        r
        for r in summary["results"]
        if r["classifier"] == "logreg"
        and r["protocol"] == "record_split"
        and r["measured_percent"] == 50
    )
    expected = accuracy[
        (accuracy.classifier == "logreg")
        & (accuracy.protocol == "record_split")
        & (accuracy.measured_percent == 50)
        & accuracy.speed_rpm.isna()
    ]
    assert row["n_repeats"] == 2
    assert row["accuracy_mean"] == pytest.approx(expected["accuracy"].mean())
    assert row["accuracy_std"] == pytest.approx(expected["accuracy"].std())
    assert set(row["accuracy_mean_per_speed"]) == {"600", "900"}
    # condition_holdout: holdouts are averaged within a repeat before the spread over repeats
    row = next(
        r
        for r in summary["results"]
        if r["classifier"] == "knn"
        and r["protocol"] == "condition_holdout"
        and r["measured_percent"] == 0
    )
    holdout_rows = accuracy[
        (accuracy.classifier == "knn")
        & (accuracy.protocol == "condition_holdout")
        & (accuracy.measured_percent == 0)
        & accuracy.speed_rpm.isna()
    ]
    per_repeat = holdout_rows.groupby("repeat")["accuracy"].mean()
    assert row["accuracy_mean"] == pytest.approx(per_repeat.mean())
    assert row["accuracy_min"] == pytest.approx(per_repeat.min())
    assert summary["n_measured_records"] == len(fake.LABELS) * len(fake.SPEEDS) * 3
    # the measured records' own separability, per speed and over all (condmon.separability)
    separability = summary["measured_separability"]
    assert (
        set(separability["per_condition"]) == {"600", "900"}
        and separability["condition"] == "speed_rpm"
    )
    assert separability["all"]["records"] == summary["n_measured_records"]
    assert 0.0 <= separability["all"]["balanced_accuracy"] <= 1.0


@pytest.mark.slow
def test_plots_exist_are_listed_and_are_real_images(built_report):
    out, _, summary = built_report
    plots = sorted(p.name for p in (out / "plots").iterdir())
    assert plots == sorted(summary["plots"])
    expected = {
        "accuracy_vs_measured_percent.png",
        "accuracy_per_speed.png",
        "spectra_measured_vs_calibrated.png",
        "calibration_convergence.png",
        "confusion_knn_record_split_all.png",
        "confusion_logreg_condition_holdout_600rpm.png",
        "prediction_shares_knn_record_split.png",
        "prediction_shares_logreg_condition_holdout.png",
        "accuracy_per_condition.png",
        "accuracy_design_vs_evaluation.png",
        "simulation_gain.png",
        "confusion_knn_record_split_evaluation.png",
        "confusion_logreg_condition_holdout_design.png",
    }
    assert expected <= set(plots)
    # classifiers x protocols x (all + 2 speeds + evaluation and design records' confusion figures
    # + prediction shares), 8 others (the gain against the strongest baseline is drawn with or
    # without a measured-only one)
    assert len(plots) == 2 * 2 * 6 + 8
    for name in plots:
        data = (out / "plots" / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n", name
        assert len(data) > 15_000, f"{name} looks empty ({len(data)} bytes)"
    assert not list(out.glob(".*tmp*")), "temporary files left behind"


@pytest.mark.slow
def test_unknown_confusion_percent_names_the_available_ones(train_outputs, tmp_path):
    _, paths = train_outputs
    with pytest.raises(train_tables.ReportInputError, match=r"confusion_percent \[30\].*\[0, 50\]"):
        fake.write_report(paths, tmp_path, evaluation={"confusion_percent": [30]})
    assert not (tmp_path / "accuracy.csv").exists() and not (tmp_path / "plots").exists()


@pytest.mark.slow
def test_one_calibration_per_calibration_variant(train_outputs, tmp_path):
    """Calibrations of two calibration variants (e.g. the gear's mesh stiffness models): the first
    one (the simulation's) is the summary's calibration, each is listed with its costs, and the
    spectra plot shows both."""
    _, paths = train_outputs
    files = {}
    for model, cost in (("potential_energy", 0.21), ("simple", 0.25)):
        folder = tmp_path / "calibration" / model
        folder.mkdir(parents=True)
        params = json.loads(paths["calibration_params"].read_text())
        params.update(cost=cost, nominal_cost=0.3, seconds=12.5)
        (folder / "params.json").write_text(json.dumps(params))
        spectra = pd.read_parquet(paths["calibration_spectra"])
        spectra["calibrated"] *= 1.0 if model == "simple" else 0.9
        spectra.to_parquet(folder / "spectra.parquet")
        files[model] = folder
    out = tmp_path / "report"
    summary = fake.write_report(
        paths,
        out,
        calibration={
            "params": {m: f / "params.json" for m, f in files.items()},
            "spectra": {m: f / "spectra.parquet" for m, f in files.items()},
            "history": {m: paths["calibration_history"] for m in files},
        },
    )
    assert summary["calibration"]["calibration_variant"] == "potential_energy"
    assert summary["calibration"]["cost"] == 0.21
    by_model = summary["calibration_by_variant"]
    assert list(by_model) == ["potential_energy", "simple"]
    assert by_model["simple"]["cost"] == 0.25 and by_model["simple"]["nominal_cost"] == 0.3
    assert by_model["simple"]["seconds"] == 12.5 and by_model["simple"]["evaluations"] == 40
    assert {
        "spectra_measured_vs_calibrated.png",
        "spectra_measured_vs_calibrated_simple.png",
        "spectra_measured_vs_calibrated_potential_energy.png",
        "calibration_convergence_simple.png",
        "calibration_convergence_potential_energy.png",
    } <= set(summary["plots"])
    assert "calibration_convergence.png" not in summary["plots"]
    with pytest.raises(train_tables.ReportInputError, match="same calibration variants"):
        fake.write_report(
            paths,
            tmp_path,
            calibration={
                "params": {m: f / "params.json" for m, f in files.items()},
                "spectra": {"simple": files["simple"] / "spectra.parquet"},
                "history": {m: paths["calibration_history"] for m in files},
            },
        )


def test_metrics_file_missing_a_column_is_named(tmp_path):
    bad = tmp_path / "train/knn/record_split/metrics.csv"
    bad.parent.mkdir(parents=True)
    pd.DataFrame({"classifier": ["knn"], "accuracy": [0.5]}).to_csv(bad, index=False)
    with pytest.raises(train_tables.ReportInputError, match=f"{bad}.*lacks columns"):
        train_tables.load_metrics([bad])


def test_source_labels_never_call_synthetic_data_real():
    assert labels.data_source_label("virtual_bench") == "virtual bench (synthetic)"
    assert labels.is_synthetic("virtual_bench") and not labels.is_synthetic("measured")


@pytest.mark.slow
def test_simulation_gain_recall_and_protocol_labels(train_outputs, tmp_path):
    _, paths = train_outputs
    # a measured-only baseline 0.25 below the hybrid accuracy, for the knn files only
    baselines = []
    for path in paths["metrics"]:
        frame = pd.read_csv(path)
        target = tmp_path / path.parent.parent.name / path.parent.name / "measured_only.csv"
        target.parent.mkdir(parents=True, exist_ok=True)
        if frame["classifier"].iloc[0] == "knn":
            frame = frame.assign(accuracy=frame["accuracy"] - 0.25, n_train_simulated=0)
        else:
            frame = frame.iloc[:0]  # baseline off: an empty file
        frame.to_csv(target, index=False)
        baselines.append(target)
    records = tmp_path / "records.csv"
    pd.DataFrame(
        {
            "record_id": ["a", ""],
            "file": ["1.mat", "2.mat"],
            "status": ["kept", "left out"],
            "reason": ["", "class not in task 'severity'"],
        }
    ).to_csv(records, index=False)
    summary = fake.write_report(
        paths,
        tmp_path,
        train={"measured_only": baselines},
        upstream={"measured_records": records},
        outputs={"recall_per_record": tmp_path / "recall_per_record.csv"},
    )
    per_record = pd.read_csv(tmp_path / "recall_per_record.csv")
    assert {"record_id", "true_label", "recall", "n_test", "most_predicted"} <= set(
        per_record.columns
    )
    assert per_record.recall.between(0, 1).all()
    knn = [r for r in summary["results"] if r["classifier"] == "knn"]
    assert all(r["simulation_gain"] == pytest.approx(0.25) for r in knn)
    assert all(
        r["measured_only_accuracy_mean"] == pytest.approx(r["accuracy_mean"] - 0.25) for r in knn
    )
    assert all(r["simulation_gain"] is None for r in summary["results"] if r["classifier"] != "knn")
    assert "simulation_gain.png" in summary["plots"] and "recall_per_class.png" in summary["plots"]
    assert summary["measured_records"] == {
        "kept": 1,
        "left_out": [{"file": "2.mat", "record_id": "", "reason": "class not in task 'severity'"}],
    }
    # recall per class: from the predictions, pooled over repeats
    predictions = pd.concat(
        pd.read_parquet(p)
        for p in paths["predictions"]
        if "record_split" in str(p) and "/knn/" in str(p)
    )
    chosen = predictions[(predictions.measured_percent == 0)]
    label = sorted(chosen.true_label.unique())[0]
    expected = (chosen[chosen.true_label == label].predicted_label == label).mean()
    row = next(r for r in knn if r["protocol"] == "record_split" and r["measured_percent"] == 0)
    assert row["recall_per_class"][label] == pytest.approx(expected)
    assert "LEAKY" in labels.PROTOCOL_LABELS["segment_share"]
    assert set(summary["protocols"]) == {"record_split", "condition_holdout"}


def test_job_timings_summarise_snakemake_benchmark_files(tmp_path):
    from condmon.job_timings import summarise
    from condmon.plots import job_timings as timings_plot

    header = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
    paths = []
    for name, seconds, rss in (
        ("simulate/healthy_450rpm_batch000", 6.5, 310.2),
        ("simulate/healthy_775rpm_batch000", 8.5, 290.0),
        ("track", 20.0, 800.5),
        ("simulate/healthy_450rpm_batch001", 99.0, 999.0),
    ):
        path = tmp_path / f"{name}.tsv"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(header + f"{seconds}\t0:00:06\t{rss}\t1\t1\t1\t0\t0\t90\t{seconds - 0.5}\n")
        paths.append(path)
    timings = summarise({"simulate": paths[:2], "track": paths[2:3]}).set_index(
        "rule"
    )  # not the last one
    assert list(timings.index) == ["simulate", "track"]
    assert (
        timings.loc["simulate", "jobs"] == 2
        and timings.loc["simulate", "wall_seconds_total"] == 15.0
    )
    assert (
        timings.loc["simulate", "wall_seconds_median"] == 7.5
        and timings.loc["simulate", "peak_rss_mb_max"] == 310.2
    )
    assert timings.loc["track", "cpu_seconds_total"] == 19.5
    assert summarise({"simulate": []}).empty
    # the run: from the first job's start (its file's time less its wall seconds) to the last end
    import os

    for path, end in zip(paths[:3], (1000.0, 1004.0, 1030.0)):
        os.utime(path, (end, end))
    run = (
        summarise({"simulate": paths[:2], "track": paths[2:3]}, cores=2)
        .set_index("rule")
        .loc["run"]
    )
    assert (
        run["wall_seconds_total"] == 1030.0 - (1000.0 - 6.5)
        and run["cpu_seconds_total"] == 6.0 + 8.0 + 19.5
    )
    assert run["cores"] == 2 and run["cpu_seconds_per_core"] == 16.75
    assert run["parallel_efficiency"] == round(16.75 / 36.5, 2)
    figure = timings_plot(timings.reset_index(), "note")
    assert [ax.get_xlabel() for ax in figure.axes] == [
        "wall seconds (all jobs)",
        "peak memory per job (MB)",
    ]
    assert [t.get_text() for t in figure.axes[0].get_yticklabels()] == ["simulate", "track"]


def test_the_job_timeline_says_when_each_job_ran_and_how_many_cores_it_kept_busy(tmp_path):
    """Two jobs side by side, then one alone: the timeline starts at the first job, counts the
    jobs running and the cores their CPU work filled (a job's CPU seconds over its wall time)."""
    import os

    from condmon.job_timings import busy_cores, read_benchmarks, timeline
    from condmon.plots import job_timeline

    header = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
    files = {}
    for rule, name, wall, cpu, end in (
        ("simulate", "a", 10.0, 10.0, 110.0),
        ("simulate", "b", 10.0, 5.0, 110.0),
        ("features", "c", 4.0, 4.0, 114.0),
    ):
        path = tmp_path / f"{name}.tsv"
        path.write_text(header + f"{wall}\t0:00:10\t100\t1\t1\t1\t0\t0\t90\t{cpu}\n")
        os.utime(path, (end, end))
        files.setdefault(rule, []).append(path)
    jobs = timeline(read_benchmarks(files))
    assert list(jobs["job"]) == ["a", "b", "c"]
    assert list(jobs["start"]) == [0.0, 0.0, 10.0] and list(jobs["end"]) == [10.0, 10.0, 14.0]
    busy = busy_cores(jobs).set_index("time")
    assert busy.loc[5.0, "jobs"] == 2 and busy.loc[5.0, "cores"] == 1.5
    assert busy.loc[12.0, "jobs"] == 1 and busy.loc[12.0, "cores"] == 1.0
    assert busy.loc[14.0, "jobs"] == 0
    figure = job_timeline(jobs, busy.reset_index(), 2, "note")
    assert [ax.get_xlabel() for ax in figure.axes][-1] == "seconds from the first job's start"
    assert timeline(read_benchmarks({})).empty


def test_accuracy_rows_carry_leaky_wilson_interval_and_small_test_flag():
    import pandas as pd

    accuracy = pd.DataFrame(
        {
            "protocol": ["record_split", "segment_share", "record_split"],
            "accuracy": [0.9, 1.0, 0.5],
            "n_test": [100, 4, 0],
        }
    )
    out = labelled_accuracy(accuracy)
    assert list(out["leaky"]) == [False, True, False]
    assert list(out["small_test_set"]) == [False, True, True]
    # Wilson 95 % for 90/100: 0.8256-0.9448; for 4/4: 0.5101-1
    assert (out.loc[0, "accuracy_ci_low"], out.loc[0, "accuracy_ci_high"]) == (0.8256, 0.9448)
    assert out.loc[1, "accuracy_ci_low"] == 0.5101 and out.loc[1, "accuracy_ci_high"] == 1.0
    assert np.isnan(out.loc[2, "accuracy_ci_low"])


def test_confusion_counts_in_label_order_and_empty_when_nothing_was_predicted():
    counts = confusion_counts(["a", "b", "b"], ["a", "a", "b"], ["b", "a", "c"])
    assert counts.tolist() == [[1, 1, 0], [0, 1, 0], [0, 0, 0]]
    assert confusion_counts([], [], ["a", "b"]).tolist() == [[0, 0], [0, 0]]


# -- honest evaluation: per-record, balanced, false alarms, baselines, conditions, design ------
def test_test_set_figures_by_hand():
    from condmon.evaluation import test_set_figures

    test = pd.DataFrame(
        {
            "record_id": ["h1", "h1", "h1", "f1", "f1", "f2"],
            "true_label": ["ok", "ok", "ok", "ball", "ball", "inner"],
            "predicted_label": ["ok", "ball", "ball", "ball", "inner", "inner"],
        }
    )
    figures = test_set_figures(test, "ok")
    assert figures["accuracy"] == pytest.approx(3 / 6)
    # votes: h1 -> ball (2 of 3, wrong), f1 -> ball/inner tie -> "ball" (right), f2 -> inner
    assert figures["n_records"] == 3 and figures["record_accuracy"] == pytest.approx(2 / 3)
    assert figures["balanced_accuracy"] == pytest.approx((1 / 3 + 1 / 2 + 1) / 3)
    assert figures["n_healthy"] == 3 and figures["false_alarm_rate"] == pytest.approx(2 / 3)
    assert figures["small_test_set"]
    assert figures["accuracy_ci_low"] < 0.5 < figures["accuracy_ci_high"]


def test_the_closed_form_figures_are_scipys_and_sklearns_to_the_last_digit():
    """wilson_interval and balanced_accuracy are computed by hand for speed (the report scores
    thousands of test sets): the same numbers as the libraries' own."""
    from scipy.stats import binomtest
    from sklearn.metrics import balanced_accuracy_score

    from condmon.evaluation import balanced_accuracy, wilson_interval

    for n in (1, 2, 7, 30, 101, 977):
        for k in sorted({0, 1, n // 3, n // 2, n - 1, n}):
            ci = binomtest(k, n).proportion_ci(method="wilson")
            assert wilson_interval(k, n) == (round(ci.low, 4), round(ci.high, 4)), (k, n)
    rng = np.random.default_rng(3)
    for _ in range(20):
        classes = np.array(["ok", "ball", "inner", "outer"])
        test = pd.DataFrame(
            {
                "true_label": classes[rng.integers(0, 3, 50)],
                "predicted_label": classes[rng.integers(0, 4, 50)],  # one only predicted
            }
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            expected = balanced_accuracy_score(test["true_label"], test["predicted_label"])
        assert balanced_accuracy(test) == expected


def test_identical_repeats_count_as_one():
    from condmon.evaluation import distinct_repeats

    rows = pd.DataFrame(
        {
            "classifier": "svm",
            "protocol": "p",
            "measured_percent": 0,
            "holdout": "",
            "record_id": "r",
            "segment": [0, 1, 0, 1],
            "repeat": [0, 0, 1, 1],
            "predicted_label": ["a", "b", "a", "b"],
        }
    )
    assert distinct_repeats(rows).tolist() == [1]
    rows.loc[3, "predicted_label"] = "a"
    assert distinct_repeats(rows).tolist() == [2]


@pytest.mark.slow
def test_evaluation_tables_per_condition_design_records_and_baselines(built_report):
    out, paths, summary = built_report
    table = pd.read_csv(out / "evaluation.csv", dtype={"holdout": str})
    table["holdout"] = table["holdout"].fillna("")
    assert set(table["condition"]) == {"all", "speed_rpm=600", "speed_rpm=900"}
    assert set(table["records"]) == {"all", "design", "evaluation"}
    predictions = train_tables.load_predictions(paths["predictions"])
    whole = table[(table.condition == "all") & (table.records == "all")]
    for row in whole.itertuples():
        test = predictions[
            (predictions.classifier == row.classifier)
            & (predictions.protocol == row.protocol)
            & (predictions.measured_percent == row.measured_percent)
            & (predictions.repeat == row.repeat)
            & (predictions.holdout == row.holdout)
        ]
        healthy = test[test.true_label == "healthy"]
        assert row.n_test == len(test) and row.n_healthy == len(healthy)
        assert row.false_alarm_rate == pytest.approx((healthy.predicted_label != "healthy").mean())
        assert row.majority_class == pytest.approx(
            test.true_label.value_counts(normalize=True).max()
        )
    assert np.allclose(whole.chance, 1 / 3)
    assert (
        whole.strongest_baseline_accuracy >= whole[["chance", "majority_class"]].max(axis=1)
    ).all()
    assert np.allclose(whole.gain_vs_strongest, whole.accuracy - whole.strongest_baseline_accuracy)
    assert (table[table.records == "design"].n_records <= len(DESIGN)).all()
    result = summary["results"][0]
    for key in (
        "record_accuracy_mean",
        "balanced_accuracy_mean",
        "false_alarm_rate_mean",
        "gain_vs_strongest_mean",
        "strongest_baseline",
        "accuracy_ci_low",
        "distinct_repeats",
        "accuracy_mean_per_condition",
        "accuracy_mean_by_records",
    ):
        assert key in result, key
    assert set(result["accuracy_mean_per_condition"]) == {"speed_rpm=600", "speed_rpm=900"}
    assert set(result["accuracy_mean_by_records"]) == {"design", "evaluation"}
    assert "design" in summary["design_records"]["note"]
    # condition_holdout at 0 %: the same test set and deterministic fits in both repeats
    alike = next(
        r
        for r in summary["results"]
        if r["classifier"] == "knn"
        and r["protocol"] == "condition_holdout"
        and r["measured_percent"] == 0
    )
    assert alike["distinct_repeats"] == 1 and alike["n_repeats"] == 2
    assert alike["accuracy_std"] is None and "one repeat" in alike["repeats_note"]
    assert "simulated training data are the same in every repeat" in summary["repeats"]
    overall = pd.read_csv(out / "evaluation_summary.csv")
    assert {"accuracy_ci_low", "false_alarm_ci_high", "distinct_repeats", "leaky"} <= set(overall)


def test_summary_intervals_count_a_tested_segment_once():
    """Identical repeats, and a healthy record tested by every holdout, add no data: the pooled
    interval is that of one repeat's distinct test segments (pooling all rows made it narrower)."""
    from condmon.evaluation import evaluation_table, summarise, wilson_interval

    def predictions(repeats):
        rows = []
        for repeat in range(repeats):
            for holdout, fault in (("g=a", "fa"), ("g=b", "fb")):
                # healthy h tests in both holdouts: 10 segments, 2 called faulty
                rows += [
                    (repeat, holdout, "h", s, "ok", "ok" if s >= 2 else "ball") for s in range(10)
                ]
                rows += [
                    (repeat, holdout, fault, s, "ball", "ball" if s >= 5 else "ok")
                    for s in range(20)
                ]
        frame = pd.DataFrame(
            rows,
            columns=["repeat", "holdout", "record_id", "segment", "true_label", "predicted_label"],
        )
        return frame.assign(classifier="svm", protocol="specimen_holdout", measured_percent=0)

    conditions = {"h": 0.0, "fa": 0.0, "fb": 1.0}
    summaries = []
    for repeats in (1, 3):
        frame = predictions(repeats)
        table = evaluation_table(frame, "ok", ["ok", "ball"], conditions, "load")
        summaries.append(
            summarise(table, frame, "ok", conditions, "load")
            .set_index(["condition", "records"])
            .loc[("all", "all")]
        )
    one, three = summaries
    # 50 distinct segments (10 healthy + 2 x 20 fault): 2 x 8 + 2 x 15 = 46 hits of 60 rows
    assert three["n_test_distinct"] == 50 and three["distinct_repeats"] == 1
    assert (three["accuracy_ci_low"], three["accuracy_ci_high"]) == wilson_interval(
        round(46 / 60 * 50), 50
    )
    assert (three["false_alarm_ci_low"], three["false_alarm_ci_high"]) == wilson_interval(2, 10)
    for name in (
        "accuracy_ci_low",
        "accuracy_ci_high",
        "false_alarm_ci_low",
        "record_accuracy_ci_high",
    ):
        assert three[name] == one[name], name


@pytest.mark.slow
def test_a_physics_baseline_that_wins_gives_a_negative_gain(train_outputs, tmp_path):
    """A training-free rule on the same test sets is a candidate of the strongest baseline; where
    it beats the classifier the gain is negative and said so, in the tables, summary.json and
    the plot."""
    _, paths = train_outputs
    physics = []
    for path in paths["predictions"]:
        if "/knn/" not in str(path):
            continue
        frame = pd.read_parquet(path)
        # a rule that is always right: no classifier can beat it
        frame = frame.assign(classifier="oracle_rule", predicted_label=frame["true_label"])
        target = tmp_path / "baselines" / path.parent.name / "predictions.parquet"
        target.parent.mkdir(parents=True)
        frame.to_parquet(target)
        physics.append(target)
    out = tmp_path / "report"
    summary = evaluated_report(
        paths,
        out,
        train={"physics": physics},
        outputs={"physics_baselines": out / "physics_baselines.csv"},
    )
    table = pd.read_csv(out / "evaluation.csv")
    whole = table[(table.condition == "all") & (table.records == "all")]
    assert (whole.physics_baseline == "oracle_rule").all()
    assert np.allclose(whole.physics_baseline_accuracy, 1.0)
    assert (whole.strongest_baseline == "oracle_rule").all()
    assert np.allclose(whole.gain_vs_strongest, whole.accuracy - 1.0)
    assert (whole.gain_vs_strongest < 0).any()
    for result in summary["results"]:
        assert result["strongest_baseline"] == "oracle_rule"
        assert result["gain_vs_strongest_mean"] <= 0
        assert result["physics_baseline_accuracy_mean"] == pytest.approx(1.0)
    own = pd.read_csv(out / "physics_baselines.csv")
    assert set(own.classifier) == {"oracle_rule"} and np.allclose(own.accuracy_mean, 1.0)
    entry = summary["physics_baselines"][0]
    assert entry["baseline"] == "oracle_rule" and set(entry["recall_per_class"].values()) == {1.0}
    assert "simulation_gain.png" in summary["plots"]


def test_a_design_specimen_record_never_counts_in_the_evaluation_figures(tmp_path):
    """Records of a design specimen (matched through records.csv's `specimen`) are reported as
    design records only: the evaluation rows, their baselines and the headline are the other
    records' alone, whatever the design records' predictions; with no other record the
    headline says there is no evaluation specimen instead of showing design figures."""
    from condmon.evaluation import evaluation_table, summarise

    records = pd.DataFrame(
        {
            "record_id": ["n0", "ir7", "ir14", "or7", "gone"],
            "specimen": [
                "normal",
                "inner_race 0.007 in",
                "inner_race 0.014 in",
                "outer_race 0.007 in at 3:00",
                "inner_race 0.014 in",
            ],
            "status": ["kept", "kept", "kept", "kept", "left out"],
        }
    )
    records.to_csv(tmp_path / "records.csv", index=False)
    design, specimens = design_record_ids(
        ["n0"], ["inner_race 0.007 in", "ball 0.021 in"], tmp_path / "records.csv"
    )
    assert design == ["ir7", "n0"] and specimens["ir14"] == "inner_race 0.014 in"
    assert "gone" not in specimens  # a left-out file is no tested record
    truth = {"n0": "normal", "ir7": "inner_race", "ir14": "inner_race", "or7": "outer_race"}

    def frame(design_guess, evaluation_guess, classifier="svm"):
        rows = [
            (r, s, truth[r], design_guess(r) if r in design else evaluation_guess(r))
            for r in truth
            for s in range(4)
        ]
        out = pd.DataFrame(rows, columns=["record_id", "segment", "true_label", "predicted_label"])
        return out.assign(
            classifier=classifier, protocol="unseen_fault", measured_percent=0, repeat=0, holdout=""
        )

    labels = ["normal", "inner_race", "outer_race"]
    conditions = dict.fromkeys(truth, 0.0)
    wrong, right = (lambda r: "normal" if truth[r] != "normal" else "outer_race"), truth.get
    physics = frame(wrong, right, classifier="envelope_rule")  # right on evaluation only
    # measured-only classifiers: one right on the design records only, one on ir14 only
    alone = pd.concat(
        [
            frame(right, wrong, classifier="knn"),
            frame(wrong, lambda r: truth[r] if r == "ir14" else "normal", classifier="svm"),
        ]
    )
    tables = {}
    for name, design_guess in (("design right", right), ("design wrong", wrong)):
        predictions = frame(design_guess, wrong)  # the classifier: wrong on evaluation
        table = evaluation_table(
            predictions,
            "normal",
            labels,
            conditions,
            "load",
            design,
            physics=physics,
            measured_only_predictions=alone,
        )
        tables[name] = table[table.condition == "all"].set_index("records")
    for table in tables.values():
        row = table.loc["evaluation"]
        assert row.n_test == 8 and row.n_records == 2
        assert row.accuracy == 0 and row.n_healthy == 0  # the healthy bearing is a design record
        assert row.majority_class == 0.5 and row.physics_baseline_accuracy == 1.0
        assert row.strongest_baseline == "envelope_rule" and row.gain_vs_strongest == -1.0
        assert row.measured_only_best == 0.5  # the best on these records: svm, right on ir14
    evaluation_columns = [c for c in tables["design right"].columns if c != "records"]
    pd.testing.assert_series_equal(
        tables["design right"].loc["evaluation", evaluation_columns],
        tables["design wrong"].loc["evaluation", evaluation_columns],
    )
    assert tables["design right"].loc["design", "accuracy"] == 1.0
    assert tables["design right"].loc["design", "measured_only_best"] == 1.0  # knn there
    assert np.isnan(tables["design right"].loc["all", "measured_only_best"])  # from metrics only
    assert tables["design right"].loc["all", "accuracy"] == 0.5

    # the headline: evaluation specimens first, design specimens labelled apart
    predictions = frame(right, wrong)
    table = evaluation_table(
        predictions, "normal", labels, conditions, "load", design, physics=physics
    )
    physics_table = evaluation_table(physics, "normal", labels, conditions, "load", design)
    accuracy = pd.DataFrame(
        {
            "classifier": ["svm"],
            "protocol": ["unseen_fault"],
            "measured_percent": [0],
            "repeat": [0],
            "speed_rpm": [np.nan],
            "accuracy": [0.5],
            "macro_f1": [0.5],
            "n_test": [16],
        }
    )
    alone_table = evaluation_table(alone, "normal", labels, conditions, "load", design)
    headline = headline_table(accuracy, None, None, 1 / 3, table, physics_table, alone_table)
    column = "simulation only (0 % measured)"
    cells = headline.set_index(["records", "model"])[column]
    best_alone = "baseline: measured data only (best classifier)"
    assert cells[("evaluation specimens", best_alone)] == "0.500 svm"
    assert cells[("design specimens", best_alone)] == "1.000 knn"
    assert list(headline.records.unique()) == ["evaluation specimens", "design specimens"]
    assert cells[("evaluation specimens", "svm (simulated + measured)")] == "0.000"
    assert (
        cells[("evaluation specimens", "baseline: physics rule envelope_rule (no training)")]
        == "1.000"
    )
    assert cells[("design specimens", "svm (simulated + measured)")] == "1.000"
    summary = design_summary(predictions, design, ["inner_race 0.007 in"], specimens)
    assert summary["headline_records"] == "evaluation"
    assert summary["tested_evaluation_records"] == ["ir14", "or7"]
    assert summary["evaluation_specimens"] == ["inner_race 0.014 in", "outer_race 0.007 in at 3:00"]

    # every tested record a design record: no evaluation figure, and the headline says so
    everything = sorted(truth)
    table = evaluation_table(predictions, "normal", labels, conditions, "load", everything)
    assert "evaluation" not in set(table.records)
    headline = headline_table(accuracy, None, None, 1 / 3, table)
    assert headline.iloc[0]["records"] == "evaluation specimens"
    assert headline.iloc[0]["model"] == NO_EVALUATION_SPECIMEN
    assert "no evaluation specimen in this data" in headline.iloc[0]["model"]
    assert set(headline.iloc[1:]["records"]) == {"design specimens"}
    summary = design_summary(predictions, everything, [], specimens)
    assert summary["headline_records"] == "none"
    assert "no evaluation specimen in this data" in summary["note"]
    summarise(
        table, predictions, "normal", conditions, "load", everything
    )  # no evaluation rows: fine
    with pytest.raises(train_tables.ReportInputError, match="name no specimen"):
        records.drop(columns="specimen").to_csv(tmp_path / "bare.csv", index=False)
        design_record_ids([], ["normal"], tmp_path / "bare.csv")


@pytest.mark.slow
def test_a_record_of_another_bearing_never_reaches_the_headline(train_outputs, tmp_path):
    """A record whose specimen the system marks as not described by its model (another bearing:
    System.unmodelled_specimens, with its reason) is reported in rows of its own ('unmodelled'),
    with its reason in
    summary.json and recall_per_record.csv; the headline and the evaluation rows are exactly those
    of the same report without its predictions (the ceiling aside: that report still has the
    record's features)."""
    from condmon.atomic import write_frame

    _, paths = train_outputs
    tested = pd.concat(pd.read_parquet(p) for p in paths["predictions"])["record_id"].unique()
    apart = sorted(r for r in tested if r not in DESIGN)[0]
    measured = pd.read_parquet(paths["features_measured"], columns=["record_id"])
    records = pd.DataFrame({"record_id": measured["record_id"].unique()})
    records.assign(specimen=records["record_id"], status="kept").to_csv(
        tmp_path / "records.csv", index=False
    )
    reason = "another bearing: its lines sum to 9.00 orders"

    def written(name, predictions, unmodelled, sections=None):
        out = tmp_path / name
        evaluated_report(
            paths,
            out,
            sections=sections,
            evaluation={"design_records": DESIGN, "unmodelled": unmodelled},
            upstream={"measured_records": tmp_path / "records.csv"},
            train={"predictions": predictions},
            outputs={
                "headline": out / "headline.csv",
                "recall_per_record": out / "recall_per_record.csv",
            },
        )
        return out

    marked = written("marked", paths["predictions"], {apart: reason})
    dropped = []
    for path in map(Path, paths["predictions"]):  # train/<classifier>/<protocol>/ kept
        frame = pd.read_parquet(path)
        dropped.append(
            tmp_path / "dropped" / path.parent.parent.name / path.parent.name / path.name
        )
        write_frame(frame[frame["record_id"] != apart], dropped[-1])
    # the report to compare with: only the sections of the two tables compared and the results
    # the evaluation rows follow (accuracy's); the whole report, its ~20 plots included, is the
    # marked one's. Both tables are compared whole, so a section left out that changed them
    # would fail here.
    without = written("without", dropped, {}, sections=["accuracy", "evaluation", "headline"])
    # the ceiling row aside: the report without its predictions still has its features
    headline = pd.read_csv(marked / "headline.csv")
    headline = headline[headline["model"] != CEILING_MODEL]
    other = pd.read_csv(without / "headline.csv")
    pd.testing.assert_frame_equal(headline, other[other["model"] != CEILING_MODEL])
    assert "evaluation specimens" in set(headline["records"])
    table = pd.read_csv(marked / "evaluation.csv")
    sides = {
        side: table[table["records"] == side].reset_index(drop=True)
        for side in ("evaluation", "design")
    }
    other = pd.read_csv(without / "evaluation.csv")
    for side, rows in sides.items():
        pd.testing.assert_frame_equal(rows, other[other["records"] == side].reset_index(drop=True))
    own = table[table["records"] == "unmodelled"]
    assert len(own) and (own["n_records"] == 1).all()
    summary = json.loads((marked / "summary.json").read_text())
    entry = summary["design_records"]
    assert entry["unmodelled"]["records"][apart]["reason"] == reason
    assert apart not in entry["tested_evaluation_records"]
    per_record = pd.read_csv(marked / "recall_per_record.csv", keep_default_na=False)
    assert set(per_record.loc[per_record["unmodelled"] != "", "record_id"]) == {apart}


def test_recall_beside_whether_each_fault_record_shows_its_line(tmp_path):
    """The envelope rule's fault_lines (physics baselines' info.json) mark each fault record;
    recall_per_record.csv carries it and summary.json's fault_lines splits each class's recall
    into the records that show their line and those that do not."""
    info = tmp_path / "info.json"
    info.write_text(
        json.dumps(
            {
                "protocol": "unseen_fault",
                "baselines": {
                    "envelope_rule": {
                        "threshold": 3.0,
                        "threshold_from": "calibration",
                        "fault_lines": [
                            {
                                "record_id": "or1",
                                "label": "outer_race",
                                "line": "bpfo",
                                "median_ratio": 9.0,
                                "threshold": 3.0,
                                "shows_line": True,
                                "shown_by": "fixed, kurtogram",
                                "no_line_why": "",
                            },
                            {
                                "record_id": "or2",
                                "label": "outer_race",
                                "line": "bpfo",
                                "median_ratio": 1.2,
                                "threshold": 3.0,
                                "shows_line": False,
                                "shown_by": "",
                                "no_line_why": "no analysis lifts the median bpfo ratio above its healthy threshold",
                            },
                        ],
                    }
                },
            }
        )
    )
    lines, rule = load_fault_lines([info])
    predictions = pd.DataFrame(
        {
            "classifier": "svm",
            "protocol": "unseen_fault",
            "measured_percent": 0,
            "record_id": ["or1", "or1", "or2", "or2", "h"],
            "true_label": ["outer_race"] * 4 + ["normal"],
            "predicted_label": ["outer_race", "outer_race", "normal", "outer_race", "normal"],
        }
    )
    per_record = recall_per_record(predictions, lines).set_index("record_id")
    assert (
        per_record.loc["or1", "shows_line"] is True and per_record.loc["or2", "shows_line"] is False
    )
    assert pd.isna(per_record.loc["h", "shows_line"])
    # which analyses show a record's line, or why none does
    assert (
        per_record.loc["or1", "line_shown_by"] == "fixed, kurtogram"
        and not per_record.loc["or1", "no_line_why"]
    )
    assert per_record.loc["or2", "no_line_why"].startswith("no analysis lifts")
    # the rule's own reading of each record stands beside the classifiers'
    rule_reads = predictions.assign(classifier="envelope_rule", predicted_label="inner_race")
    both = recall_per_record(predictions, lines, rule_reads)
    read = both[both["classifier"] == "envelope_rule"].set_index("record_id")
    assert list(read["most_predicted"]) == ["inner_race"] * 3 and read.loc["or1", "recall"] == 0.0
    assert (
        both[both["classifier"] == "svm"]
        .reset_index(drop=True)
        .equals(recall_per_record(predictions, lines))
    )
    summary = fault_lines_summary(predictions, lines, rule)
    (row,) = summary["recall"]
    assert (row["recall_shows_line"], row["records_shows_line"]) == (1.0, 1)
    assert (row["recall_no_line"], row["records_no_line"]) == (0.5, 1)
    assert summary["rule"] == "envelope_rule" and len(summary["records"]) == 2
    assert load_fault_lines([]) == (None, {})


def test_the_measured_ceiling_leaves_out_the_calibration_set(train_outputs, tmp_path):
    # the calibration saw its records, and a healthy reference's features are near zero against
    # themselves: the measured-only classifier must not count them among the healthy records
    from condmon.report.context import Report

    _, paths = train_outputs
    evaluation = {"measured_features": paths["features_measured"], "condition": "speed_rpm"}
    plain = Report(fake.report_inputs(paths, tmp_path / "a", evaluation=evaluation), tmp_path / "a")
    spec = {
        "healthy_state": "healthy",
        "condition": "speed_rpm",
        "reserve": {},
        "states": ["healthy"],
    }
    calibrated = Report(
        fake.report_inputs(
            paths, tmp_path / "b", evaluation={**evaluation, "calibration_set": spec}
        ),
        tmp_path / "b",
    )
    frame, _ = calibrated.measured
    left_out = set(frame.loc[calibrated.calibration_rows, "record_id"].astype(str))
    assert left_out and all("healthy" in record for record in left_out)
    assert plain.calibration_rows.empty
    before, after = plain.separability["all"]["records"], calibrated.separability["all"]["records"]
    assert after == before - len(left_out)

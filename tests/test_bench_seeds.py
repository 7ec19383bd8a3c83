"""benchmarks/bench_seeds.py: the seed table has every column issue 48 asks for, its means
leave a class out where the bench's own records cannot show it, and a seed's run name."""

import importlib.util
import json

import pandas as pd
import pytest

from conftest import ROOT

spec = importlib.util.spec_from_file_location("bench_seeds", ROOT / "benchmarks" / "bench_seeds.py")
bench_seeds = importlib.util.module_from_spec(spec)
spec.loader.exec_module(bench_seeds)
CLASSES = ("healthy", "surface_fault", "missing_tooth")


def fake_report(
    folder, recall: dict, ceiling: dict, correlation: dict, classifiers=("svm",), alone=None
):
    """The three report files the benchmark reads, as the report writes them, for one speed (450)."""
    folder.mkdir(parents=True)
    rows = [
        {
            "classifier": classifier,
            "protocol": "record_split",
            "measured_percent": p,
            "condition": condition,
            "records": "all",
            "balanced_accuracy_mean": 0.9 if p == 0 else 1.0,
            "false_alarm_rate_mean": 0.05 if p == 0 else 0.0,
        }
        for p in (0, 100)
        for condition in ("all", "speed_rpm=450")
        for classifier in classifiers
    ]
    pd.DataFrame(rows).to_csv(folder / "evaluation_summary.csv", index=False)
    shares = [
        {
            "classifier": classifier,
            "protocol": "record_split",
            "measured_percent": p,
            "speed_rpm": 450.0,
            "true_label": true,
            "predicted_label": predicted,
            "share": (recall[true] if predicted == true else 1 - recall[true])
            if p == 0
            else float(predicted == true),
            "n": 8,
        }
        for p in (0, 100)
        for true in CLASSES
        for predicted in (true, next(c for c in CLASSES if c != true))
        for classifier in classifiers
    ]
    pd.DataFrame(shares).to_csv(folder / "prediction_shares.csv", index=False)
    chance = {"mean": 1 / 3, "upper": 0.5, "permutations": 50}
    summary = {
        "measured_separability": {
            "per_condition": {
                "450": {
                    "recall_per_class": ceiling,
                    "chance": chance,
                    "not_shown": sorted(c for c, r in ceiling.items() if r < 0.8),
                }
            }
        },
        "fault_signatures": {
            "per_condition": {
                "450": {
                    "classes": {c: {"direction_correlation": r} for c, r in correlation.items()}
                }
            }
        },
    }
    if alone is not None:  # reports from before the simulation's own ceiling have none
        summary["simulated_separability"] = {"per_condition": {"450": {"balanced_accuracy": alone}}}
    (folder / "summary.json").write_text(json.dumps(summary))


def test_the_seed_table_has_every_column_and_exempts_what_the_bench_cannot_show(tmp_path):
    fake_report(
        tmp_path / "a",
        {"healthy": 1.0, "surface_fault": 0.9, "missing_tooth": 1.0},
        {"healthy": 1.0, "surface_fault": 1.0, "missing_tooth": 1.0},
        {"surface_fault": 0.8, "missing_tooth": 0.9},
        alone=0.7,
    )
    fake_report(
        tmp_path / "b",
        {"healthy": 1.0, "surface_fault": 0.1, "missing_tooth": 1.0},
        {"healthy": 1.0, "surface_fault": 0.5, "missing_tooth": 1.0},
        {"surface_fault": 0.2, "missing_tooth": 0.9},
    )
    rows = bench_seeds.seed_rows(tmp_path / "a", 7, "svm") + bench_seeds.seed_rows(
        tmp_path / "b", 8, "svm"
    )
    assert len(rows) == 4  # two seeds x (0 %, 100 %) at the one speed
    for row in rows:
        assert set(bench_seeds.COLUMNS) == set(row)
    zero = next(r for r in rows if r["seed"] == 8 and r["measured_percent"] == 0)
    assert zero["recall"]["surface_fault"] == pytest.approx(0.1)
    assert zero["exempt"] == ["surface_fault"]  # its own records find it only half the time
    assert zero["signature_correlation"]["surface_fault"] == pytest.approx(0.2)
    mean = next(m for m in bench_seeds.means(rows) if m["measured_percent"] == 0)
    assert mean["seeds"] == 2 and mean["balanced_accuracy"] == pytest.approx(0.9)
    # the exempt seed's recall is left out of the class's mean, and the table says which seed
    assert mean["recall"]["surface_fault"] == pytest.approx(0.9)
    assert mean["exempt"] == {"seed8": ["surface_fault"]}
    assert mean["signature_correlation"]["surface_fault"] == pytest.approx(0.5)
    # the simulation's own ceiling: seed 7's report has one, seed 8's predates it
    assert zero["simulation_alone"] is None
    assert next(r for r in rows if r["seed"] == 7)["simulation_alone"] == pytest.approx(0.7)
    assert mean["simulation_alone"] == pytest.approx(0.7)


def test_a_seed_runs_under_its_own_name_unless_it_is_the_configs_finished_run(
    tmp_path, monkeypatch
):
    config = tmp_path / "c.yaml"
    config.write_text("run_name: gears\nvirtual_bench: {seed: 7}\n")
    monkeypatch.setattr(bench_seeds, "ROOT", tmp_path)
    assert bench_seeds.run_name_of([config], 8) == ("gears-seed8", True)
    assert bench_seeds.run_name_of([config], 7) == ("gears-seed7", True)  # not finished yet
    (tmp_path / "results" / "gears" / "report").mkdir(parents=True)
    (tmp_path / "results" / "gears" / "report" / "summary.json").write_text("{}")
    assert bench_seeds.run_name_of([config], 7) == ("gears", False)


def test_the_benchmark_writes_its_record(tmp_path, monkeypatch):
    """A collected seed table lands in benchmarks/records/ as bench_seeds-<name>.json, with the
    command and config files that made it (here a finished run of the config's own seed)."""
    from condmon import records

    config = tmp_path / "c.yaml"
    config.write_text("run_name: gears\nvirtual_bench: {seed: 7}\n")
    fake_report(
        tmp_path / "results" / "gears" / "report",
        {"healthy": 1.0, "surface_fault": 0.9, "missing_tooth": 1.0},
        {"healthy": 1.0, "surface_fault": 1.0, "missing_tooth": 1.0},
        {"surface_fault": 0.8},
    )
    monkeypatch.setattr(bench_seeds, "ROOT", tmp_path)
    monkeypatch.setattr(records, "RECORDS_DIR", tmp_path / "records")
    argv = [
        "--configfile",
        str(config),
        "--seeds",
        "7",
        "--layer",
        "none",
        "--collect-only",
        "--name",
        "t",
    ]
    assert bench_seeds.main(argv) == 0
    record = json.loads((tmp_path / "records" / "bench_seeds-t.json").read_text())
    assert record["command"].startswith("python3 benchmarks/bench_seeds.py --configfile")
    assert record["configfiles"] == [str(config)] and record["config_hash"]
    assert record["figures"]["per_seed"][0]["seed"] == 7
    assert record["figures"]["mean"][0]["balanced_accuracy"] == pytest.approx(0.9)


def test_the_variants_run_beside_the_seeds_each_under_its_own_name(tmp_path, monkeypatch):
    """--benches: a bench variant is collected from its own run (its run_name, its seed), beside the
    seeds, for every classifier asked; the means pool every bench per classifier."""
    from condmon import records

    config, variant = tmp_path / "c.yaml", tmp_path / "benches" / "other.yaml"
    variant.parent.mkdir()
    config.write_text("run_name: gears\nvirtual_bench: {seed: 7}\n")
    variant.write_text("run_name: bench-other\nvirtual_bench: {seed: 21}\n")
    perfect = {"healthy": 1.0, "surface_fault": 1.0, "missing_tooth": 1.0}
    both = ("svm", "knn")
    fake_report(
        tmp_path / "results" / "gears" / "report", perfect, perfect, {"surface_fault": 0.8}, both
    )
    fake_report(
        tmp_path / "results" / "bench-other" / "report",
        {"healthy": 1.0, "surface_fault": 0.5, "missing_tooth": 1.0},
        perfect,
        {"surface_fault": 0.6},
        both,
    )
    monkeypatch.setattr(bench_seeds, "ROOT", tmp_path)
    monkeypatch.setattr(records, "RECORDS_DIR", tmp_path / "records")
    argv = [
        "--configfile",
        str(config),
        "--seeds",
        "7",
        "--benches",
        str(variant),
        "--layer",
        "none",
        "--classifier",
        "svm",
        "knn",
        "--collect-only",
        "--name",
        "t",
    ]
    assert bench_seeds.main(argv) == 0
    figures = json.loads((tmp_path / "records" / "bench_seeds-t.json").read_text())["figures"]
    assert {(r["bench"], r["seed"], r["classifier"]) for r in figures["per_seed"]} == {
        ("seed7", 7, "svm"),
        ("seed7", 7, "knn"),
        ("other", 21, "svm"),
        ("other", 21, "knn"),
    }
    mean = next(
        m for m in figures["mean"] if m["classifier"] == "knn" and m["measured_percent"] == 0
    )
    assert mean["seeds"] == 2 and mean["recall"]["surface_fault"] == pytest.approx(0.75)


def fake_bearing_run(folder, ball_recall: float):
    """The three files a bearing seed's rows come from (recall_per_record.csv, records.csv,
    summary.json's design_records), as the pipeline writes them: two ball records (one shows its
    line), a normal record, at 0 % and 100 % of unseen_fault."""
    (folder / "report").mkdir(parents=True)
    (folder / "measured").mkdir()
    rows = [
        {
            "classifier": classifier,
            "protocol": "unseen_fault",
            "measured_percent": percent,
            "record_id": record,
            "true_label": label,
            "recall": recall,
            "n_test": 10,
            "shows_line": shows,
        }
        for classifier in ("joined_svm", "envelope_rule")
        for percent in (0, 100)
        for record, label, recall, shows in (
            ("b1", "ball", ball_recall, True),
            ("b2", "ball", 0.0, False),
            ("n1", "normal", 1.0, None),
        )
    ]
    pd.DataFrame(rows).to_csv(folder / "report" / "recall_per_record.csv", index=False)
    pd.DataFrame(
        {
            "record_id": ["b1", "b2", "n1"],
            "specimen": ["ball 0.007 in", "ball 0.014 in", "normal"],
            "load_hp": [0, 1, 0],
        }
    ).to_csv(folder / "measured" / "records.csv", index=False)
    (folder / "report" / "summary.json").write_text(
        json.dumps({"design_records": {"records": ["b1", "b2", "n1"]}})
    )


def test_the_bearing_seed_rows_carry_groups_classes_lines_and_specimens_and_their_spread(tmp_path):
    fake_bearing_run(tmp_path / "s1", 1.0)
    fake_bearing_run(tmp_path / "s2", 0.5)
    rows = bench_seeds.bearing_rows(tmp_path / "s1", 1) + bench_seeds.bearing_rows(
        tmp_path / "s2", 2
    )
    assert {(r["protocol"], r["measured_percent"], r["classifier"]) for r in rows} == {
        ("unseen_fault", p, c) for p in (0, 100) for c in ("joined_svm", "envelope_rule")
    }
    row = next(
        r
        for r in rows
        if r["seed"] == 2 and r["classifier"] == "joined_svm" and r["measured_percent"] == 0
    )
    assert row["group"] == "design, loads 0-1"
    assert row["recall"] == {"ball": 0.25, "normal": 1.0} and row[
        "balanced_accuracy"
    ] == pytest.approx(0.625)
    assert row["recall_shows_line"] == {"ball": 0.5} and row["recall_no_line"] == {"ball": 0.0}
    assert row["per_specimen"]["ball 0.007 in"] == 0.5
    mean = next(
        m
        for m in bench_seeds.bearing_means(rows)
        if m["classifier"] == "joined_svm" and m["measured_percent"] == 0
    )
    assert mean["seeds"] == [1, 2]
    assert mean["balanced_accuracy"]["mean"] == pytest.approx(0.6875)
    assert (mean["balanced_accuracy"]["lowest"], mean["balanced_accuracy"]["highest"]) == (
        0.625,
        0.75,
    )
    assert mean["recall_shows_line"]["ball"]["mean"] == pytest.approx(0.75)
    assert bench_seeds.bearing_run_name(["config/cwru.yaml"], 7) == ("cwru-seed7", True)

"""condmon.records: a benchmark's record names its command, commit, config, machine and date
beside its figures, is written under a stable name and read back in date order."""

import json
import re
import subprocess

import pytest

from condmon import records
from conftest import ROOT


def test_a_record_names_what_made_its_figures(tmp_path):
    config = tmp_path / "a.yaml"
    config.write_text("x: 1\n")
    record = records.make_record(
        "bench",
        "seeds 7-11",
        {"accuracy": 0.9},
        script=str(ROOT / "benchmarks" / "b.py"),
        argv=["--seeds", "7", "8"],
        configfiles=[config],
        date="2026-12-06",
    )
    assert record["command"] == "python3 benchmarks/b.py --seeds 7 8"
    assert record["figures"] == {"accuracy": 0.9} and record["date"] == "2026-12-06"
    assert set(record["machine"]) == {"cpu_count", "cpu", "python"}
    assert record["commit"] == records.COMMIT_AT_START and len(record["commit"].split("+")[0]) == 40
    # the hash follows the config's text, and the order the files layer in
    first = record["config_hash"]
    config.write_text("x: 2\n")
    assert records.config_hash([config]) != first
    other = tmp_path / "b.yaml"
    other.write_text("y: 1\n")
    assert records.config_hash([config, other]) != records.config_hash([other, config])
    assert records.config_hash([]) is None


def test_records_are_written_under_a_stable_name_and_read_oldest_first(tmp_path):
    newer = {
        "benchmark": "throughput",
        "name": "default",
        "date": "2026-12-06",
        "figures": {"b": 2},
    }
    older = {
        "benchmark": "bench_seeds",
        "name": "cfrp/x y",
        "date": "2026-12-01",
        "figures": {"a": 1},
    }
    assert records.write_record(newer, tmp_path).name == "throughput-default.json"
    assert records.write_record(older, tmp_path).name == "bench_seeds-cfrp_x_y.json"
    assert [r["figures"] for r in records.read_records(tmp_path)] == [{"a": 1}, {"b": 2}]
    # on one day, by the time each was made, whatever the file names; one without a time first
    records.write_record(dict(older, name="z", date="2026-12-06", time="10:00:00"), tmp_path)
    records.write_record(dict(older, name="a", date="2026-12-06", time="11:00:00"), tmp_path)
    assert [r["name"] for r in records.read_records(tmp_path)] == ["cfrp/x y", "default", "z", "a"]
    made = records.make_record("bench", "n", {}, script=str(ROOT / "benchmarks" / "b.py"), argv=[])
    assert re.fullmatch(r"\d\d:\d\d:\d\d", made["time"])
    # a rerun replaces the file, keys in a stable order
    records.write_record(dict(newer, figures={"b": 3}), tmp_path)
    text = (tmp_path / "throughput-default.json").read_text()
    assert json.loads(text)["figures"] == {"b": 3} and text.index('"benchmark"') < text.index(
        '"figures"'
    )


def test_the_cpu_model_and_the_commit(tmp_path):
    assert records.cpu_model("processor\t: 0\nmodel name\t: AMD EPYC 7B13\n") == "AMD EPYC 7B13"
    assert records.git_commit(tmp_path) == "unknown"  # not a checkout
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], cwd=tmp_path, check=True)
    (tmp_path / "f").write_text("1")
    subprocess.run([*git, "add", "f"], cwd=tmp_path, check=True)
    subprocess.run([*git, "commit", "-qm", "one"], cwd=tmp_path, check=True)
    clean = records.git_commit(tmp_path)
    assert len(clean) == 40 and "+" not in clean
    (tmp_path / "f").write_text("2")
    assert records.git_commit(tmp_path) == clean + "+dirty"


NO_RECORD = ("throughput_guard.py", "render_results.py", "fake_train_outputs.py")


@pytest.mark.parametrize(
    "script", sorted(p.name for p in (ROOT / "benchmarks").glob("*.py") if p.name not in NO_RECORD)
)
def test_every_benchmark_writes_a_record(script):
    """Each benchmark that reports figures ends with condmon.records.save_record (the guard keeps
    its own baseline file; the renderer reads the records; fake_train_outputs.py is no benchmark
    but the synthetic train outputs the tracking benchmark and the tests build)."""
    assert "save_record(" in (ROOT / "benchmarks" / script).read_text()


def benchmark_module(name: str):
    """benchmarks/<name>.py as a module (the benchmarks are scripts, not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_study_table_reads_a_runs_report_beside_the_studys_figures(tmp_path, monkeypatch):
    """benchmarks/study_table.py: per speed the SVM's accuracy and balanced accuracy at 0 %
    measured (record_split), each class's recall and the study's figure beside it."""
    import pandas as pd

    study_table = benchmark_module("study_table")
    report = tmp_path / "results" / "run" / "report"
    report.mkdir(parents=True)
    keys = {"classifier": "svm", "protocol": "record_split", "measured_percent": 0}
    pd.DataFrame(
        [
            dict(keys, speed_rpm=450.0, true_label=t, predicted_label=p, share=s, n=10)
            for t, p, s in [
                ("healthy", "healthy", 0.5),
                ("healthy", "fault", 0.5),
                ("fault", "fault", 1.0),
            ]
        ]
    ).to_csv(report / "prediction_shares.csv", index=False)
    pd.DataFrame([dict(keys, repeat=0, speed_rpm=450.0, accuracy=0.75)]).to_csv(
        report / "accuracy.csv", index=False
    )
    (report / "summary.json").write_text(
        json.dumps({"job_timings": {"simulate": {"cpu_seconds_total": 5.0}}})
    )
    monkeypatch.setattr(study_table, "ROOT", tmp_path)
    figures = study_table.study_table("run", [0.99])
    assert figures["per_speed"] == {
        "450 rpm": {
            "accuracy": 0.75,
            "balanced_accuracy": 0.75,
            "recall fault": 1.0,
            "recall healthy": 0.5,
            "study": 0.99,
        }
    }
    assert figures["cpu_seconds"] == 5.0 and figures["simulated_validation_accuracy"] is None


def test_a_condition_table_reads_a_runs_figures_per_condition(tmp_path, monkeypatch):
    """benchmarks/condition_table.py: per condition, classifier and measured share the mean over
    repeats of record_split's balanced accuracy and false alarms, and the ceiling per condition."""
    import pandas as pd

    condition_table = benchmark_module("condition_table")
    report = tmp_path / "results" / "run" / "report"
    report.mkdir(parents=True)
    keys = {"classifier": "svm", "protocol": "record_split", "records": "all"}
    pd.DataFrame(
        [
            dict(
                keys,
                measured_percent=0,
                repeat=r,
                condition="load=5",
                balanced_accuracy=b,
                false_alarm_rate=f,
            )
            for r, b, f in [(0, 0.9, 0.25), (1, 0.8, 0.0)]
        ]
        + [
            dict(
                keys,
                measured_percent=50,
                repeat=0,
                condition="load=5",
                balanced_accuracy=0.1,
                false_alarm_rate=0.0,
            ),
            dict(
                keys,
                measured_percent=0,
                repeat=0,
                condition="load=5",
                balanced_accuracy=0.1,
                false_alarm_rate=0.0,
                protocol="condition_holdout",
            ),
        ]
    ).to_csv(report / "evaluation.csv", index=False)
    separability = {
        "condition": "load",
        "per_condition": {
            "5": {"balanced_accuracy": 0.97, "chance": {"upper": 0.6}, "reads_above_chance": True},
            "10": {"balanced_accuracy": None, "refused": "fewer than 3 records"},
        },
    }
    (report / "summary.json").write_text(json.dumps({"measured_separability": separability}))
    monkeypatch.setattr(condition_table, "ROOT", tmp_path)
    figures = condition_table.condition_table("run")
    assert figures["per_condition"] == {
        "load=5, svm, 0 %": {"balanced_accuracy": 0.85, "false_alarm_rate": 0.125}
    }
    assert figures["ceiling"] == {
        "load=5": {"balanced_accuracy": 0.97, "chance_upper": 0.6, "reads_above_chance": True}
    }


def test_the_run_times_benchmark_reads_a_runs_job_timings(tmp_path):
    """benchmarks/run_times.py records a run's jobs from its report/job_timings.csv: the window
    of its jobs against their CPU seconds over the cores, and each rule's row."""
    import pandas as pd

    run_times = benchmark_module("run_times")
    (tmp_path / "report").mkdir()
    pd.DataFrame(
        [
            {"rule": "simulate", "jobs": 4, "wall_seconds_total": 80.0, "cpu_seconds_total": 76.0},
            {"rule": "train", "jobs": 1, "wall_seconds_total": 20.0, "cpu_seconds_total": 18.0},
            {
                "rule": "run",
                "jobs": 5,
                "wall_seconds_total": 70.0,
                "cpu_seconds_total": 94.0,
                "cores": 2.0,
                "cpu_seconds_per_core": 47.0,
                "parallel_efficiency": 0.67,
            },
        ]
    ).to_csv(tmp_path / "report" / "job_timings.csv", index=False)
    figures = run_times.job_figures(tmp_path)
    assert figures["jobs_window_seconds"] == 70.0 and figures["jobs_cpu_seconds"] == 94.0
    assert figures["cores"] == 2 and figures["window_over_cpu_per_core"] == round(70 / 47, 3)
    assert [rule["rule"] for rule in figures["rules"]] == ["simulate", "train"]
    assert "parallel_efficiency" not in figures["rules"][0]
    # the run a timed command makes is the one its config names
    assert run_times.run_name([]) == "default"
    assert (
        run_times.run_name(["--configfile", ".test/config/smoke.yaml", "--cores", "2"]) == "smoke"
    )
    assert run_times.run_name(["--config", "hybrid={}", "run_name=mine", "--cores", "2"]) == "mine"

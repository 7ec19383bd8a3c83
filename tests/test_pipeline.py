"""The smoke pipeline end to end: outputs, MLflow, what an edit reruns, spectra, config errors.

One smoke run (about two minutes on 2 cores) in a copy of the project, the session fixture `smoke`
of conftest.py, serves every test here; a test that reruns or edits works on a copy.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.signal import find_peaks

from condmon.hybrid import read_split_table
from condmon.signals import read_signal_table, to_arrays
from conftest import ROOT, SNAKEMAKE, config_file, copy_project, snakemake

pytestmark = pytest.mark.pipeline


def planned_jobs(workdir, config: dict) -> dict:
    """Job counts of a dry run with `config` (a modified smoke config)."""
    path = workdir / "edited.yaml"
    path.write_text(yaml.safe_dump(config))
    out = snakemake(workdir, "-n", "--configfile", str(path)).stdout
    return job_counts(out)


def job_counts(out: str) -> dict:
    """{rule: jobs} of a dry run's "Job stats" table ({} when nothing is to be done)."""
    if "Nothing to be done" in out:
        return {}
    table = out.split("Job stats:")[1].split("total")[0]
    rows = [line.split() for line in table.strip().splitlines()[2:]]
    return {name: int(count) for name, count in rows}


def smoke_config():
    return config_file(".test/config/smoke.yaml")


def test_every_design_output_is_written(smoke):
    _, results = smoke
    for name in (
        "measured/signals.parquet",
        "measured/healthy.parquet",
        *(
            f"calibration/{model}/{file}"
            for model in ("potential_energy", "simple")
            for file in (
                "params.json",
                "history.parquet",
                "convergence.png",
                "spectra.parquet",
                "background.parquet",
                "background.png",
            )
        ),
        "features/measured.parquet",
        "features/simulated.parquet",
        "report/accuracy.csv",
        "report/summary.json",
        "report/mlflow_run.json",
        "report/plots/accuracy_vs_measured_percent.png",
        "report/plots/spectra_measured_vs_calibrated.png",
    ):
        assert (results / name).stat().st_size > 0, name
    assert (
        len(list((results / "simulated").rglob("*.parquet"))) == 6
    )  # 3 states x 2 speeds x 1 batch
    assert list((results / "report" / "plots").glob("confusion_*.png"))
    simulated_with = smoke_config()["model"]["mesh_stiffness_model"]
    for model in ("potential_energy", "simple"):
        calibration = json.loads((results / "calibration" / model / "params.json").read_text())
        assert {"model_variant", "parameters", "cost", "nominal_cost", "evaluations"} <= set(
            calibration
        )
        assert (
            calibration["mesh_stiffness_model"] == model
            and calibration["contact_law"] == calibration["model_variant"]
        )
    summary = json.loads((results / "report" / "summary.json").read_text())
    assert summary["calibration"]["calibration_variant"] == simulated_with
    assert set(summary["calibration_by_variant"]) == {"potential_energy", "simple"}
    accuracy = pd.read_csv(results / "report" / "accuracy.csv")
    assert list(accuracy.columns[:7]) == [
        "classifier",
        "protocol",
        "measured_percent",
        "repeat",
        "speed_rpm",
        "accuracy",
        "macro_f1",
    ]
    assert set(accuracy["classifier"]) == {"svm", "knn"}
    assert set(accuracy["protocol"]) == {"record_split", "condition_holdout"}
    assert accuracy["accuracy"].between(0, 1).all()
    measured = read_signal_table(results / "measured" / "signals.parquet")
    assert set(measured["source"]) == {"virtual_bench"}  # synthetic data is never labelled measured
    timings = pd.read_csv(results / "report" / "job_timings.csv").set_index("rule")
    assert set(timings.index) == {
        "measured_part",
        "measured",
        "measured_healthy",  # the bench's healthy records the calibrations read
        "calibrate",
        "simulate",
        "features_measured",
        "features_simulated",
        "hybrid",
        "train",
        "physics_baseline",
        "run",
    }  # every job before the report, the run
    assert timings.loc["simulate", "jobs"] == 6 and (timings["peak_rss_mb_max"] > 0).all()
    run = timings.loc["run"]  # elapsed time at least the CPU work over the cores
    assert run["cores"] >= 1 and 0 < run["parallel_efficiency"] <= 1.05
    for plot in ("job_timings.png", "job_timeline.png"):
        assert plot in summary["plots"] and (results / "report" / "plots" / plot).is_file()
    assert set(summary["job_timings"]) == set(timings.index)
    # the bench's first healthy record per speed calibrates whole (no healthy reference here)
    assert summary["calibration_set"] == {
        "whole": ["vb-healthy-1100rpm-r00", "vb-healthy-450rpm-r00"],
        "split_in_time": {},
    }
    # the Hz spectra track no shaft: the shaft tracking table is written, empty
    tracking = pd.read_csv(results / "report" / "shaft_tracking.csv")
    assert tracking.empty and "nominal_segments" in tracking and "shaft_tracking" not in summary


def test_mlflow_has_one_parent_and_nested_runs(smoke):
    from mlflow.tracking import MlflowClient

    workdir, results = smoke
    info = json.loads((results / "report" / "mlflow_run.json").read_text())
    client = MlflowClient(tracking_uri=f"sqlite:///{workdir}/results/mlflow.db")
    runs = client.search_runs([info["experiment_id"]])
    children = [r for r in runs if r.data.tags.get("mlflow.parentRunId") == info["parent_run_id"]]
    assert len(children) == info["n_nested_runs"] > 0
    assert all("accuracy" in r.data.metrics for r in children)
    assert all(
        Path(r.data.tags["model_file"]).is_file() for r in children
    )  # as train's info.json lists them
    assert info["n_models_logged"] == len(children)  # smoke.yaml: log_models all
    parent = client.get_run(info["parent_run_id"])
    assert {d.dataset.name for d in parent.inputs.dataset_inputs} == {
        "measured_signals",
        "simulated_signals",
        "measured_features",
        "simulated_features",
    }
    assert any(name.startswith("accuracy.svm.record_split.p") for name in parent.data.metrics)


def copy_of_run(workdir: Path, target: Path) -> Path:
    """The smoke run's project folder, results and Snakemake's records included, with its MLflow
    store pointing at its own artifacts (the store keeps absolute paths)."""
    import sqlite3

    shutil.copytree(workdir, target, symlinks=True)
    with sqlite3.connect(target / "results" / "mlflow.db") as db:
        for table, column in (
            ("experiments", "artifact_location"),
            ("runs", "artifact_uri"),
            ("logged_models", "artifact_location"),
            ("model_versions", "storage_location"),
        ):
            db.execute(
                f"UPDATE {table} SET {column} = replace({column}, ?, ?)",
                (workdir.as_uri(), target.as_uri()),
            )
    return target


def test_two_runs_differing_in_svm_C_compared_through_mlflow(smoke, tmp_path):
    """The README's comparison: edit classifiers.svm.C, rerun (the SVM's train jobs, track and
    report only), then both invocations are parent runs of the experiment, found by
    mlflow.search_runs with their differing parameter and their summary metrics."""
    import mlflow
    from condmon.compare import latest_parents

    workdir = copy_of_run(smoke[0], tmp_path / "project")
    config = smoke_config()
    config["classifiers"]["svm"]["C"] = 2.5
    jobs = planned_jobs(workdir, config)
    # and the report's pages with the edited config
    assert set(jobs) == {
        "train",
        "track",
        "track_plots",
        "report",
        "run_config",
        "report_pages",
        "all",
    }
    assert jobs["train"] == len(config["hybrid"]["protocols"])  # the SVM's jobs only
    snakemake(workdir, "--cores", "2", "--configfile", "edited.yaml")

    mlflow.set_tracking_uri(f"sqlite:///{workdir}/results/mlflow.db")
    runs = mlflow.search_runs(
        experiment_names=["smoke"], filter_string="tags.snakemake_run_name = 'smoke'"
    )
    assert len(runs) == 2 and set(runs["status"]) == {"FINISHED"}
    assert len(latest_parents(mlflow.search_runs(experiment_names=["smoke"]))) == 2  # two configs
    runs = runs.set_index("params.classifiers.svm.C")
    assert set(runs.index) == {str(smoke_config()["classifiers"]["svm"]["C"]), "2.5"}
    assert runs["tags.config_hash"].nunique() == 2
    summary = [c for c in runs.columns if c.startswith("metrics.accuracy.")]
    assert {c.split(".")[2] for c in summary} == {"svm", "knn"} and runs[
        summary
    ].notna().all().all()
    knn = [c for c in summary if ".knn." in c]
    assert (runs[knn].nunique() == 1).all()  # the k-NN did not rerun: the same numbers

    # each config's models in a folder of their own: both load, the SVMs differ, the k-NNs are one
    # model, logged once (the second run links them)
    import joblib
    from condmon.model_store import read_index

    stores = {
        h: read_index(workdir / "results" / "smoke" / "models" / h)
        for h in runs["tags.config_hash"]
    }
    assert len(stores) == 2
    first, second = ({e["file"]: e for e in store["models"]} for store in stores.values())
    assert first.keys() == second.keys()
    for name in first:
        same = first[name]["digest"] == second[name]["digest"]
        assert same == name.startswith("knn/"), name
    svm = "svm/record_split/p100_r0.joblib"
    models = [joblib.load(workdir / "results" / "smoke" / "models" / h / svm) for h in stores]
    assert models[0].estimator.named_steps["svm"].C != models[1].estimator.named_steps["svm"].C
    for run_id in runs["run_id"]:  # every nested run names a file of its own config's folder
        children = mlflow.search_runs(
            experiment_names=["smoke"], filter_string=f"tags.mlflow.parentRunId = '{run_id}'"
        )
        config_hash = runs.set_index("run_id").loc[run_id, "tags.config_hash"]
        assert children["tags.model_file"].str.contains(f"/models/{config_hash}/").all()
    info = json.loads((workdir / "results" / "smoke" / "report" / "mlflow_run.json").read_text())
    n_knn = sum(name.startswith("knn/") for name in first)
    assert info["n_models_linked_not_logged"] >= n_knn
    # condmon-compare names the key that differs
    result = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from condmon.compare import main; "
            f"sys.exit(main(['--tracking-uri', 'sqlite:///{workdir}/results/mlflow.db', "
            "'--experiment', 'smoke', '--percent', '100']))",
        ],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert "config keys that differ between these 2 runs: classifiers.svm.C\n" in result.stdout
    # the report's plots are artifacts of the parent run
    client = mlflow.MlflowClient()
    plots = {f.path for f in client.list_artifacts(info["parent_run_id"], "plots")}
    assert plots and all(p.endswith(".png") for p in plots)


def new_records(results, speed=None):
    """A signal table of records the run never measured: its simulated 450 rpm samples."""
    frame = pd.concat(
        [
            read_signal_table(p)
            for p in sorted((results / "simulated").glob("*/450rpm/batch000.parquet"))
        ],
        ignore_index=True,
    )
    return frame if speed is None else frame.assign(speed_rpm=speed)


def test_condmon_predict_and_the_registered_model_give_the_same_labels(smoke, tmp_path):
    import mlflow
    from condmon.signals import write_signal_table

    workdir, results = smoke
    write_signal_table(new_records(results), tmp_path / "new.parquet")
    predict = [
        sys.executable,
        "-m",
        "condmon.predict",
        "predict",
        "--model",
        str(results),
        "--input",
        str(tmp_path / "new.parquet"),
    ]
    subprocess.run([*predict, "--output", str(tmp_path / "out")], check=True, cwd=workdir)
    segments = pd.read_csv(tmp_path / "out" / "segments.csv")
    assert {"health_summary.csv", "records.csv", "predictions.png"} <= {
        p.name for p in (tmp_path / "out").iterdir()
    }
    # the packaged model keeps its training range: each segment says whether it lies outside
    assert segments["outside_training"].isin([True, False]).all()
    mlflow.set_tracking_uri(f"sqlite:///{workdir}/results/mlflow.db")
    registered = mlflow.pyfunc.load_model("models:/condmon-smoke@best")
    labels = registered.predict(read_signal_table(tmp_path / "new.parquet"))
    assert list(labels["predicted_label"]) == list(segments["predicted_label"])
    assert list(labels["record_id"]) == list(segments["record_id"])
    info = json.loads((results / "report" / "mlflow_run.json").read_text())
    used = json.loads((tmp_path / "out" / "model.json").read_text())
    assert (
        used["classifier"] == info["best_model"]["classifier"]
        and used["config_hash"] == info["config_hash"]
    )
    # a record at a speed the model was never trained at is refused by name; nothing written
    write_signal_table(new_records(results, speed=900.0), tmp_path / "at900.parquet")
    refused = subprocess.run(
        [
            sys.executable,
            "-m",
            "condmon.predict",
            "predict",
            "--model",
            str(results),
            "--input",
            str(tmp_path / "at900.parquet"),
            "--output",
            str(tmp_path / "no"),
        ],
        cwd=workdir,
        capture_output=True,
        text=True,
    )
    assert refused.returncode == 2 and "speed 900 rpm" in refused.stderr
    assert not (tmp_path / "no").exists()


def test_the_predict_rule_runs_only_the_prediction(smoke, tmp_path):
    from condmon.signals import write_signal_table

    workdir, results = smoke
    write_signal_table(new_records(results), tmp_path / "new.parquet")
    args = [
        "predict",
        "--configfile",
        ".test/config/smoke.yaml",
        "--config",
        f"predict_input={tmp_path / 'new.parquet'}",
    ]
    assert job_counts(snakemake(workdir, "-n", *args).stdout) == {
        "predict": 1
    }  # nothing else reruns
    snakemake(workdir, "--cores", "1", *args)
    out = results / "predict" / "new"
    assert (
        pd.read_csv(out / "health_summary.csv")["record_id"].nunique()
        == new_records(results)["record_id"].nunique()
    )
    assert (results / "logs" / "predict" / "new.log").is_file()


@pytest.mark.parametrize("override", ["classifiers={svm: {C: 3.0}}", "set=classifiers.svm.C=3.0"])
def test_a_nested_or_dotted_config_override_is_typed_and_reruns_only_the_svm(smoke, override):
    """Snakemake hands `--config classifiers='{svm: {C: 3.0}}'` (or `set=classifiers.svm.C=3.0`)
    over as text; read as the schema's number it plans the SVM's train jobs and what follows
    them, nothing else."""
    workdir, _ = smoke
    out = snakemake(
        workdir, "-n", "--configfile", ".test/config/smoke.yaml", "--config", override
    ).stdout
    jobs = job_counts(out)
    assert jobs == {
        "train": len(smoke_config()["hybrid"]["protocols"]),
        "report": 1,
        "track": 1,
        "track_plots": 1,
        "run_config": 1,
        "report_pages": 1,
        "all": 1,
    }
    assert out.count("classifier=svm") == jobs["train"] and "classifier=knn" not in out
    # run_config's reason names the changed key, not the whole config before and now
    reasons = [line for line in out.splitlines() if "Params have changed" in line]
    assert (
        any("'classifiers.svm.C=3.0'" in line for line in reasons) and max(map(len, reasons)) < 500
    )


def test_choosing_which_models_mlflow_logs_reruns_only_the_tracking(smoke):
    """... and the report's pages, which show the full config."""
    workdir, _ = smoke
    config = smoke_config()
    config["tracking"]["log_models"] = "first_repeat"
    assert set(planned_jobs(workdir, config)) == {
        "track",
        "track_plots",
        "run_config",
        "report_pages",
        "all",
    }


def test_editing_a_simulation_setting_reruns_simulation_and_downstream_not_calibration(smoke):
    """The gear's own simulation knob (model.variability.perturbation_sigma; test_systems.py
    checks its job specs, test_cwru_pipeline.py that a bearing run refuses it): the simulations
    and exactly what follows them, and the report's pages (they show the full config)."""
    workdir, _ = smoke
    config = smoke_config()
    config["model"]["variability"]["perturbation_sigma"] = 0.05
    jobs = planned_jobs(workdir, config)
    assert {"simulate", "features_simulated", "train", "track", "report"} <= set(jobs)
    assert not {"calibrate", "measured", "measured_part", "features_measured", "hybrid"} & set(jobs)
    after = {"train", "track", "track_plots", "report", "run_config", "report_pages", "all"}
    assert set(jobs) == {"simulate", "features_simulated", *after}


def test_editing_the_background_reruns_calibration_and_simulation_not_the_bench(smoke):
    """calibration.background (on in the smoke config): its runs change the calibrate jobs'
    background.parquet, which the simulate jobs read; switched off, simulate no longer needs it."""
    workdir, _ = smoke
    for edit in ({"background_runs": 3}, {"background": False}):
        config = smoke_config()
        config["calibration"].update(edit)
        jobs = planned_jobs(workdir, config)
        assert {"calibrate", "simulate", "features_simulated", "train", "report"} <= set(jobs), edit
        assert not {"measured", "measured_part", "features_measured"} & set(jobs), edit


def test_the_calibrations_wait_for_the_benchs_healthy_records_alone():
    """They read the bench's healthy parts (merged by `measured_healthy`), so they run while the
    bench still makes its fault records, which the healthy parts go before."""
    out = snakemake(
        ROOT, "-n", "--forceall", "--until", "calibrate", "--configfile", ".test/config/smoke.yaml"
    ).stdout
    config = smoke_config()
    speeds = len(config["rig"]["speeds_rpm"])
    assert job_counts(out) == {"measured_part": speeds, "measured_healthy": 1, "calibrate": 2}
    assert out.count("priority: 1") == speeds  # the healthy parts, first


def test_switching_the_mesh_stiffness_model_reruns_simulation_not_the_bench_or_calibration(smoke):
    """Both models are calibrated in every run; the switch only picks the simulation's."""
    workdir, _ = smoke
    config = smoke_config()
    model = config["model"]["mesh_stiffness_model"]
    config["model"]["mesh_stiffness_model"] = (
        "simple" if model == "potential_energy" else "potential_energy"
    )
    jobs = planned_jobs(workdir, config)
    assert {"simulate", "features_simulated", "train", "track", "report"} <= set(jobs)
    assert not {"calibrate", "measured", "measured_part", "features_measured", "hybrid"} & set(jobs)


def mean_spectrum(results, health, speed, channel="A1_y"):
    frames = [
        read_signal_table(p)
        for p in (results / "simulated" / health / f"{speed}rpm").glob("*.parquet")
    ]
    frame = pd.concat(frames, ignore_index=True)
    _, arrays = to_arrays(frame, [channel])
    x = arrays[:, 0].astype(float)
    x = x - x.mean(axis=1, keepdims=True)
    fs = frame["fs_hz"].iloc[0]
    return np.fft.rfftfreq(x.shape[1], 1 / fs), np.abs(
        np.fft.rfft(x * np.hanning(x.shape[1]), axis=1)
    ).mean(0)


def test_healthy_spectrum_peaks_at_the_gear_mesh_frequency_and_harmonics(smoke):
    _, results = smoke
    freqs, amplitude = mean_spectrum(results, "healthy", 1100)
    gmf = 1100 / 60 * 29
    bin_width = freqs[1]
    # Local maxima at least half a mesh frequency apart; the three largest sit on harmonics.
    peaks, _ = find_peaks(amplitude, distance=int(gmf / 2 / bin_width))
    top = freqs[peaks[np.argsort(amplitude[peaks])[-3:]]]
    assert np.all(np.abs(top / gmf - np.round(top / gmf)) * gmf <= 1.5 * bin_width), top / gmf
    assert freqs[np.argmax(amplitude)] == pytest.approx(
        round(freqs[np.argmax(amplitude)] / gmf) * gmf, abs=1.5 * bin_width
    )


def test_missing_tooth_adds_sidebands_at_the_input_shaft_frequency(smoke):
    _, results = smoke
    freqs, healthy = mean_spectrum(results, "healthy", 1100)
    _, missing = mean_spectrum(results, "missing_tooth", 1100)
    shaft, gmf = 1100 / 60, 1100 / 60 * 29

    def at(spectrum, f):
        return spectrum[np.argmin(np.abs(freqs - f))]

    sidebands = [gmf + k * shaft for k in (-3, -2, -1, 1, 2, 3)]
    # The sidebands' energy rises above the healthy spectrum's (potential-energy mesh: far less
    # than with the simple one, as the helical pair's neighbouring teeth carry the load over the
    # gap; over 10x with the simple mesh). Each simulated sample is a new gear pair of ISO grade
    # 4-6 whose own errors put lines at every shaft order, starts at a random shaft angle (where
    # the tooth passes in the 0.25 s Hann window varies) and loses half to all of the tooth; the
    # background of the bench's healthy records (its sensor noise) is added. Four samples: the
    # median of the six single ratios scatters too much to test. The noise-free 2x
    # criterion is the model's own test (test_gear_model.py); here, no more than a rise.
    rise = 10 if smoke_config()["model"]["mesh_stiffness_model"] == "simple" else 1.3
    energy = [sum(at(spectrum, f) ** 2 for f in sidebands) for spectrum in (healthy, missing)]
    assert energy[1] / energy[0] > rise
    # ... and stand out of the missing-tooth spectrum between them (lines every shaft frequency).
    between = [gmf + (k + 0.5) * shaft for k in (-3, -2, 1, 2)]
    assert np.median([at(missing, f) for f in sidebands]) > 2 * np.median(
        [at(missing, f) for f in between]
    )


@pytest.mark.parametrize(
    "edit, key",
    [
        (lambda c: c.update(unknown_setting=1), "unknown_setting"),
        (
            lambda c: c["simulation"].update(samples_per_state="many"),
            "simulation.samples_per_state",
        ),
        (
            lambda c: c["calibration"].update(contact_laws=["flores", "hertz"]),
            "calibration.contact_laws",
        ),
        (lambda c: c["hybrid"].update(measured_percent=[0, 150]), "hybrid.measured_percent"),
    ],
)
def test_config_errors_stop_before_any_job_and_name_the_key(tmp_path, edit, key):
    workdir = copy_project(tmp_path)
    config = smoke_config()
    edit(config)
    (workdir / "bad.yaml").write_text(yaml.safe_dump(config))
    result = snakemake(workdir, "--cores", "1", "--configfile", "bad.yaml", check=False)
    assert result.returncode != 0
    assert key in result.stderr + result.stdout
    assert not (workdir / "results").exists()


def sha256(path):
    import hashlib

    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_simulated_files_do_not_depend_on_the_core_count(smoke, tmp_path):
    """The smoke run used 2 cores; the same config on 1 core gives byte-identical simulations.
    The last and the first batch, run alone in the reverse order: a batch's random stream must
    depend on its own key only, not on which jobs ran before it or beside it."""
    source, results = smoke
    workdir = copy_of_run(
        source, tmp_path / "project"
    )  # the bench and calibrations as the smoke run left them
    batches = sorted(
        p.relative_to(results.parent.parent) for p in (results / "simulated").rglob("*.parquet")
    )
    assert len(batches) >= 3, batches
    targets = [batches[-1], batches[0]]
    for target in targets:
        (workdir / target).unlink()
    snakemake(
        workdir, "--cores", "1", *map(str, targets), "--configfile", ".test/config/smoke.yaml"
    )
    for target in targets:
        assert sha256(workdir / target) == sha256(results.parent.parent / target), target


def test_a_users_measured_table_replaces_the_virtual_bench(smoke, tmp_path):
    """A user's table as a rig gives it: its own single-axis sensor names, one record per state
    and speed, no `params` column; each speed's lone healthy record is split in time (calibration
    block, test blocks) and the table runs through the hybrid splits."""
    _, results = smoke
    workdir = copy_project(tmp_path)
    bench = read_signal_table(results / "measured" / "signals.parquet")
    bench = bench[bench["channel"].isin(["A1_y", "A2_y"])].drop(columns="params")
    bench["channel"] = bench["channel"].map({"A1_y": "v1", "A2_y": "v2"})
    bench["source"] = "measured"
    # the bench's records of a state and speed, one after another, as one record of the rig
    bench = bench.sort_values(["health_state", "speed_rpm", "record_id", "segment"])
    bench["record_id"] = (
        "rig-" + bench["health_state"] + "-" + bench["speed_rpm"].map("{:g}".format)
    )
    bench["segment"] = bench.groupby(["record_id", "channel"]).cumcount().astype("int32")
    bench.to_parquet(tmp_path / "rig.parquet")
    (tmp_path / "rig.yaml").write_text(
        yaml.safe_dump(
            {
                "base": ".test/config/smoke.yaml",
                "run_name": "rig",
                "measured_table": str(tmp_path / "rig.parquet"),
                "model": {
                    "sensors": {
                        "v1": {"housing": 0, "directions": ["y"]},
                        "v2": {"housing": 2, "directions": ["y"]},
                    }
                },
                "features": {"channels": ["v1", "v2"]},
                "calibration": {"reserve": {"each_condition": True, "calibration_segments": 2}},
            }
        )
    )
    snakemake(
        workdir, "--cores", "1", "--until", "hybrid", "--configfile", str(tmp_path / "rig.yaml")
    )
    measured = read_signal_table(workdir / "results/rig/measured/signals.parquet")
    assert (
        set(measured["source"]) == {"measured"}
        and measured["record_id"].str.startswith("rig-").all()
        and set(measured["channel"]) == {"v1", "v2"}
    )
    assert not (workdir / "results" / "rig" / "measured" / "virtual_bench").exists()
    splits = read_split_table(workdir / "results/rig/hybrid/record_split.parquet")
    healthy = splits[splits["record_id"].str.startswith("rig-healthy")]
    roles = healthy.groupby("record_id")["role"].agg(set)
    assert len(roles) == 2 and all({"calibration", "unused", "test"} <= r for r in roles)


def run_until(workdir, marker: Path, sig, timeout=600):
    """Start the smoke run up to the training (`--until train`, as the resume runs: the stages
    after it read only its files, and the smoke run tests them) and send `sig` to it and all its
    jobs (its process group, as a cluster scheduler's cancel or time limit does) once `marker`
    exists. Without --until, the physics baselines (which no train job reads) ran before the
    training began, on the cores the training waited for."""
    import os
    import time

    process = subprocess.Popen(
        SNAKEMAKE + ["--cores", "2", "--until", "train", "--configfile", ".test/config/smoke.yaml"],
        cwd=workdir,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + timeout
    while not marker.exists():
        assert process.poll() is None, "the run ended before reaching the point to kill it"
        assert time.monotonic() < deadline, f"{marker} never appeared"
        time.sleep(0.2)
    os.killpg(process.pid, sig)
    process.wait(timeout=120)  # after SIGTERM Snakemake cleans up its failed jobs, then exits
    assert process.returncode != 0
    snakemake(workdir, "--unlock", "--cores", "1", "--configfile", ".test/config/smoke.yaml")


OUTPUT_SUFFIXES = (".parquet", ".joblib", ".json", ".csv", ".png", ".mat")


def assert_no_partial_outputs(results: Path):
    """Whatever a killed run left reads as complete: every Parquet file has its footer, every
    JSON and CSV parses; a temporary file of an interrupted atomic write (`.<name>.tmp<pid>`)
    is never named like an output, so no glob of a later stage picks it up."""
    import pyarrow.parquet as pq

    for path in results.rglob("*"):
        if path.is_dir():
            continue
        if ".tmp" in path.name:
            assert path.name.startswith(".") and not path.name.endswith(OUTPUT_SUFFIXES), path
        elif path.suffix == ".parquet":
            pq.read_metadata(path)
        elif path.suffix == ".json":
            json.loads(path.read_text())
        elif path.suffix == ".csv":
            pd.read_csv(path)


def test_a_run_killed_mid_simulation_and_mid_training_resumes_to_the_same_results(smoke, tmp_path):
    """SIGKILL mid-simulation (the OOM killer, a lost node: no clean-up at all), then SIGTERM
    mid-training (a scheduler's cancel or time limit: Snakemake cleans up), then a resume up to
    the training (the stages after it read only its files, and the smoke run tests them)."""
    import signal

    source, results = smoke
    workdir = copy_of_run(
        source, tmp_path / "project"
    )  # its MLflow store writing to its own artifacts
    killed = workdir / "results" / "smoke"
    # The bench and the calibrations stay as the smoke run left them (the kill comes after them);
    # everything from the simulations on is gone, so the killed and resumed runs produce it all.
    downstream = [
        "simulated",
        "features/simulated.parquet",
        "hybrid",
        "train",
        "models",
        "baselines",
        "report",
    ]
    downstream += [
        f"logs/{name}"
        for name in (
            "simulate",
            "features_simulated.log",
            "hybrid",
            "train",
            "physics_baseline",
            "report.log",
            "report_pages.log",
            "run_config.log",
            "track.log",
            "track_plots.log",
        )
    ]
    for name in downstream:
        path = killed / name
        assert path.exists(), f"the smoke run has no {name}: update this list"
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    run_until(workdir, killed / "logs" / "simulate", signal.SIGKILL)
    assert_no_partial_outputs(killed)
    run_until(workdir, killed / "logs" / "train", signal.SIGTERM)
    assert_no_partial_outputs(killed)
    snakemake(
        workdir,
        "--cores",
        "2",
        "--rerun-incomplete",
        "--until",
        "train",
        "--configfile",
        ".test/config/smoke.yaml",
    )
    assert_no_partial_outputs(killed)
    for path in sorted((results / "simulated").rglob("*.parquet")):
        assert sha256(killed / path.relative_to(results)) == sha256(path)
    metrics = sorted((results / "train").glob("*/*/metrics.csv"))
    assert len(metrics) == 4  # SVM and k-NN, two protocols
    for path in metrics:  # the same numbers (a fit's seconds are the machine's)
        resumed, first = (
            pd.read_csv(p).drop(columns="fit_seconds")
            for p in (killed / path.relative_to(results), path)
        )
        pd.testing.assert_frame_equal(resumed, first)


def screenshot(chromium, page: Path, png: Path) -> np.ndarray:
    """Headless Chromium's screenshot of a local page (its scripts run) as an RGB array."""
    from PIL import Image

    subprocess.run(
        [
            chromium,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
            "--window-size=1400,1000",
            "--virtual-time-budget=5000",
            f"--screenshot={png}",
            page.as_uri(),
        ],
        check=True,
        capture_output=True,
        timeout=180,
    )
    return np.asarray(Image.open(png).convert("RGB"), dtype=float)


@pytest.fixture(scope="module")
def smoke_report(smoke, tmp_path_factory) -> Path:
    """`snakemake --report report.html` on the smoke run (the README's report command), made
    once for the tests that read the page; read only."""
    workdir, _ = smoke
    report = tmp_path_factory.mktemp("report") / "report.html"
    snakemake(workdir, "--configfile", ".test/config/smoke.yaml", "--report", str(report))
    return report


def test_snakemake_report_embeds_the_plots_and_chromium_renders_them(smoke, smoke_report, tmp_path):
    """`snakemake --report report.html` on the smoke run: every report plot is embedded, byte for
    byte, in its section; the page renders; and the accuracy plot shows when opened as the
    report's own buttons open it (its classifiers' line colours fill the screenshot)."""
    import base64
    import re

    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("headless Chromium is not installed (Debian package `chromium`)")
    workdir, results = smoke
    report = smoke_report
    html = report.read_text()
    entries = json.loads(re.search(r"var results = (\{.*?\});\n", html, re.S).group(1))
    categories = json.loads(re.search(r"var categories = (\{.*?\});\n", html, re.S).group(1))
    section = {
        path: name
        for name, subcategories in categories.items()
        for paths in subcategories.values()
        for path in paths
    }
    plots = sorted((results / "report" / "pages" / "plots").glob("*.png"))
    assert [p.name for p in plots] == sorted(
        p.name for p in (results / "report" / "plots").glob("*.png")
    )
    for plot in plots:
        key = str(plot.relative_to(workdir))
        assert entries[key]["data_uri"].startswith("data:image/png")
        assert (
            base64.b64decode(entries[key]["data_uri"].split("base64,", 1)[1]) == plot.read_bytes()
        )
        assert entries[key]["caption"], key
    assert {section[str(p.relative_to(workdir))] for p in plots} == {
        "Accuracy",
        "Confusion matrices",
        "Calibration",
        "Job timings",
    }
    assert {Path(key).name for key in entries} >= {
        "accuracy.html",
        "job_timings.html",
        "headline.html",
        "calibration_simple.html",
        "config.yaml",
    }

    def plot_colour_share(image):  # matplotlib's C0 and C1: the first two classifiers' lines
        return sum(
            (np.abs(image - colour).max(axis=2) < 30).mean()
            for colour in ([31, 119, 180], [255, 127, 14])
        )

    front = screenshot(chromium, report, tmp_path / "front.png")
    assert front.std() > 10  # not a blank page
    key = str(
        results.relative_to(workdir)
        / "report"
        / "pages"
        / "plots"
        / "accuracy_vs_measured_percent.png"
    )
    page, end = html.rsplit("</body>", 1)
    opened = tmp_path / "report_opened.html"
    opened.write_text(
        page
        + "<script>window.addEventListener('load', () => setTimeout(() => app.setView({content: 'img', "
        f"contentPath: results[{json.dumps(key)}].data_uri, resultPath: {json.dumps(key)}}}), 500));"
        "</script></body>" + end
    )
    shot = screenshot(chromium, opened, tmp_path / "accuracy.png")
    assert plot_colour_share(shot) > 5e-4 and plot_colour_share(shot) > 10 * plot_colour_share(
        front
    )


def test_the_report_front_page_opens_on_the_headline_table_and_shows_tables_as_tables(
    smoke, smoke_report
):
    """`snakemake --report`: the front page holds the headline table with accuracy.csv's numbers
    (mean over repeats at 0 and 100 % measured); every report table is an HTML page; a result's
    details pane lists the few params that identify the run."""
    import re

    workdir, results = smoke
    report = smoke_report
    html = report.read_text()
    front = json.loads(re.search(r"var workflow_desc = (.*?);\n", html, re.S).group(1))
    assert (
        "A tiny run (the CI smoke run)" in front.split("<table", 1)[0]
    )  # report.note, above the table
    table = front.split("<table", 1)[1].split("</table>", 1)[0]
    rows = [
        re.findall(r"<td>(.*?)</td>", row, re.S)
        for row in re.findall(r"<tr>(.*?)</tr>", table, re.S)
    ]
    assert {row[0] for row in rows if row} == {"all"}  # records: no design record declared
    cells = {(row[1], row[2]): row[3:] for row in rows if row}
    accuracy = pd.read_csv(results / "report" / "accuracy.csv")
    whole = accuracy[accuracy["speed_rpm"].isna()]
    means = (
        whole.groupby(["classifier", "protocol", "measured_percent", "repeat"])["accuracy"]
        .mean()
        .groupby(level=[0, 1, 2])
        .mean()
    )
    assert len(means) > 0
    for (classifier, protocol, percent), mean in means.items():
        if percent in (0, 100):
            shown = cells[(protocol, f"{classifier} (simulated + measured)")][
                0 if percent == 0 else 1
            ]
            assert float(shown.split()[0]) == pytest.approx(mean, abs=5e-4), (
                classifier,
                protocol,
                percent,
            )
    assert {model for _, model in cells} >= {"chance"}
    entries = json.loads(re.search(r"var results = (\{.*?\});\n", html, re.S).group(1))
    pages = {Path(key).name: entry for key, entry in entries.items()}
    for name in (
        "accuracy",
        "evaluation_summary",
        "prediction_shares",
        "recall_per_record",
        "job_timings",
        "headline",
        "calibration_potential_energy",
    ):
        assert pages[f"{name}.html"]["mime_type"] == "text/html", name
    assert not any(name.endswith(".csv") and name != "headline.csv" for name in pages)
    params = {entry["job_properties"]["params"] for entry in entries.values()}
    assert len(params) == 1
    shown = dict(item.split("=", 1) for item in re.split(r", (?=[a-z_]+=)", params.pop()))
    assert set(shown) == {
        "run_name",
        "system",
        "config_hash",
        "protocols",
        "classifiers",
        "full_config",
    }
    assert shown["run_name"] == "smoke" and shown["full_config"].endswith(
        "report/pages/config.yaml"
    )
    full = yaml.safe_load((results / "report" / "pages" / "config.yaml").read_text())
    assert (
        full["run_name"] == "smoke"
        and full["classifiers"]["svm"]["C"] == smoke_config()["classifiers"]["svm"]["C"]
    )
    assert set(full) >= set(smoke_config()) - {"predict_input"}


def test_a_report_without_its_configfile_names_the_runs_there_are(smoke, tmp_path):
    """Without --configfile Snakemake reports the default run, which this project never made."""
    workdir, _ = smoke
    result = snakemake(workdir, "--report", str(tmp_path / "report.html"), check=False)
    said = result.stdout + result.stderr
    assert result.returncode != 0 and "no finished run 'default' to report" in said
    assert "finished runs: smoke (the run_name of .test/config/smoke.yaml)" in said
    assert not (tmp_path / "report.html").exists()


def node_profile(workdir: Path, node: dict) -> str:
    """profiles/slurm as shipped, with every job's threads and memory capped at what the test
    cluster's one node has (a job asking for more would wait forever); returns its folder."""
    profile = yaml.safe_load((workdir / "profiles" / "slurm" / "config.yaml").read_text())
    for rule, threads in profile.get("set-threads", {}).items():
        profile["set-threads"][rule] = min(threads, node["cpus"])
    for resources in [profile["default-resources"], *profile.get("set-resources", {}).values()]:
        if "mem_mb" in resources:
            resources["mem_mb"] = min(resources["mem_mb"], node["mem_mb"])
    folder = workdir / "profiles" / "slurm-node"
    folder.mkdir()
    (folder / "config.yaml").write_text(yaml.safe_dump(profile))
    return str(folder.relative_to(workdir))


def slurm_test_skip_reason():
    import os
    from slurm_cluster import can_install_packages, machine_has_its_own_slurm

    if os.environ.get("CONDMON_SLURM_TEST") != "1":
        return "opt-in: CONDMON_SLURM_TEST=1 (installs and starts a SLURM cluster, reruns the smoke pipeline on it)"
    if not can_install_packages():
        return "needs SLURM's daemons installed, or root with apt-get to install them"
    if machine_has_its_own_slurm():
        return "this machine has a SLURM configuration of its own (/etc/slurm/slurm.conf)"
    return None


@pytest.mark.skipif(slurm_test_skip_reason() is not None, reason=str(slurm_test_skip_reason()))
def test_the_smoke_run_through_the_slurm_profile_goes_through_slurm_and_equals_the_local_run(
    smoke, tmp_path
):
    import tempfile
    import time
    from slurm_cluster import SlurmCluster

    _, results = smoke
    workdir = copy_project(tmp_path / "project")
    planned = planned_jobs(workdir, smoke_config())
    # a folder of its own under /tmp: munged wants every folder above its socket open to all
    cluster_root = Path(tempfile.mkdtemp(prefix="condmon-slurm-"))
    try:
        with SlurmCluster(cluster_root) as cluster:
            start = time.monotonic()
            result = subprocess.run(
                SNAKEMAKE
                + [
                    "--profile",
                    node_profile(workdir, cluster.node()),
                    "--configfile",
                    ".test/config/smoke.yaml",
                    "--slurm-status-command",
                    "squeue",
                    "--slurm-init-seconds-before-status-checks",
                    "5",
                    "--slurm-keep-successful-logs",
                ],
                cwd=workdir,
                env=cluster.env,
                capture_output=True,
                text=True,
            )
            seconds = time.monotonic() - start
            assert result.returncode == 0, f"SLURM run failed:\n{result.stderr[-6000:]}"
            jobs = cluster.sacct()
            sacct_text = cluster.sacct_text()
    finally:
        shutil.rmtree(cluster_root, ignore_errors=True)
    # the executor's log of each SLURM job: slurm_logs/rule_<rule>[/<wildcards>]/<SLURM job id>.log
    logs = workdir / ".snakemake" / "slurm_logs"
    slurm_jobs = {
        int(log.stem): str(log.parent.relative_to(logs)).removeprefix("rule_")
        for log in logs.rglob("*.log")
    }
    print(
        f"\nsmoke run through SLURM: {seconds:.0f} s\n{sacct_text}\nSLURM job: rule/wildcards\n"
        + "\n".join(f"{job}: {slurm_jobs[job]}" for job in sorted(slurm_jobs))
    )
    # every job of the run, and nothing else, went through SLURM and completed there
    assert (jobs["State"] == "COMPLETED").all(), jobs
    assert sorted(jobs["JobID"].astype(int)) == sorted(slurm_jobs)
    submitted = (
        pd.Series([job.split("/")[0] for job in slurm_jobs.values()]).value_counts().to_dict()
    )
    assert submitted == {rule: n for rule, n in planned.items() if rule != "all"}
    # the same results as the local run
    run = workdir / "results" / "smoke"
    for path in sorted((results / "simulated").rglob("*.parquet")):
        assert sha256(run / path.relative_to(results)) == sha256(path), path
    for table in ("measured", "simulated"):
        pd.testing.assert_frame_equal(
            pd.read_parquet(run / "features" / f"{table}.parquet"),
            pd.read_parquet(results / "features" / f"{table}.parquet"),
        )
    for params in sorted((results / "calibration").glob("*/params.json")):
        local, on_slurm = (
            json.loads(p.read_text()) for p in (params, run / params.relative_to(results))
        )
        for timing in ("seconds", "seconds_per_evaluation"):
            on_slurm.pop(timing), local.pop(timing)
        assert on_slurm == local, params
    columns = [
        "classifier",
        "protocol",
        "measured_percent",
        "repeat",
        "speed_rpm",
        "holdout",
        "accuracy",
        "macro_f1",
    ]
    pd.testing.assert_frame_equal(
        pd.read_csv(run / "report" / "accuracy.csv")[columns],
        pd.read_csv(results / "report" / "accuracy.csv")[columns],
    )

"""The bearing-rig pipeline end to end on a small slice of the shared CWRU files
(.test/config/cwru-smoke.yaml): ingestion, rig calibration, randomised simulation, statistical
features with backward selection, the four protocols, the measured-only baseline, the report.

A second run points `measured_dir` at another set of files (other fault sizes, no healthy record)
by config alone (`--config`, and a layer that makes it smaller): it must run without edits,
simulate every class and test the ones present.
"""

import json
import os
import re
import time

import pandas as pd
import pytest
import yaml

from conftest import CWRU, CWRU_SLICE as SLICE, cwru_folder, deep_update, snakemake

pytestmark = pytest.mark.pipeline
# another set: 0.021 in faults at 0 and 1 HP, and no healthy record
OTHER_SET = ["209.mat", "210.mat", "222.mat", "223.mat", "234.mat", "235.mat"]


def test_cwru_run_writes_every_protocol_labelled_with_gain_and_recall(cwru_run):
    _, results = cwru_run
    summary = json.loads((results / "report" / "summary.json").read_text())
    assert summary["data_source"]["kind"] == "measured"
    assert summary["labels"] == ["normal", "ball", "inner_race", "outer_race"]
    assert set(summary["protocols"]) == {
        "unseen_fault",
        "condition_holdout",
        "record_split",
        "segment_share",
    }
    assert "LEAKY" in summary["protocols"]["segment_share"]
    accuracy = pd.read_csv(results / "report" / "accuracy.csv")
    assert (accuracy["leaky"] == (accuracy["protocol"] == "segment_share")).all()
    assert accuracy.loc[accuracy["n_test"] < 30, "small_test_set"].all()
    rows = {(r["classifier"], r["protocol"], r["measured_percent"]): r for r in summary["results"]}
    # every result carries its protocol's label and a recall per tested class
    assert all(r["protocol_label"] == summary["protocols"][r["protocol"]] for r in rows.values())
    unseen = rows[("svm", "unseen_fault", 0)]
    assert set(unseen["recall_per_class"]) == {"normal", "inner_race", "ball", "outer_race"}
    # with measured training data there is a measured-only baseline and hence a gain
    for protocol in ("condition_holdout", "segment_share"):
        row = rows[("knn", protocol, 50)]
        assert row["simulation_gain"] == pytest.approx(
            row["accuracy_mean"] - row["measured_only_accuracy_mean"]
        )
    assert rows[("svm", "unseen_fault", 0)]["simulation_gain"] is None  # nothing measured trains
    assert summary["simulation"]["samples"] == 4 * 2 * 3 and summary["simulation"]["failed"] == 0
    assert summary["measured_records"]["kept"] == len(SLICE)
    for name in (
        "simulation_gain.png",
        "recall_per_class.png",
        "accuracy_vs_measured_percent.png",
        "spectra_measured_vs_calibrated.png",
    ):
        assert name in summary["plots"]
    # the shared files hold design specimens only (cwru.design_specimens): every figure is a
    # design figure, and the headline says there is no evaluation specimen instead of showing one
    design = summary["design_records"]
    assert design["headline_records"] == "none" and not design["tested_evaluation_records"]
    assert sorted(design["tested_design_records"]) == sorted(
        f"cwru-{n.split('.')[0]}" for n in SLICE
    )
    assert "no evaluation specimen in this data" in design["note"]
    assert unseen["by_records"]["evaluation"] == {"note": "no evaluation record tested"}
    assert unseen["by_records"]["design"]["accuracy_mean"] == pytest.approx(unseen["accuracy_mean"])
    headline = pd.read_csv(results / "report" / "headline.csv")
    assert headline.iloc[0]["records"] == "evaluation specimens"
    assert headline.iloc[0]["model"].startswith("no evaluation specimen in this data")
    assert set(headline.iloc[1:]["records"]) == {"design specimens"}
    # the joined method (joined.classifiers: [svm]) beside its parts, on the same test sets
    assert ("joined_svm", "unseen_fault", 0) in rows
    keys = ["measured_percent", "repeat", "holdout", "record_id", "segment"]
    tested = [
        pd.read_parquet(results / part / "unseen_fault" / "predictions.parquet")[keys]
        for part in ("train/svm", "joined/joined_svm")
    ]
    pd.testing.assert_frame_equal(*(t.sort_values(keys).reset_index(drop=True) for t in tested))
    assert "joined_svm (simulated + measured)" in set(headline["model"])
    info = json.loads(
        (results / "joined" / "joined_svm" / "unseen_fault" / "info.json").read_text()
    )
    assert info["parts"] == ["svm", "envelope_rule"] and 0 <= info["outside_training_share"] <= 1
    assert "confusion_joined_svm_unseen_fault_all.png" in summary["plots"]
    # simulation covers the machine (issue 49 item 2): each design record judged on the features
    # the SVM's fits use, at 0 % (the simulated range), from the joined job's coverage.csv
    coverage = pd.read_csv(
        results / "joined" / "joined_svm" / "unseen_fault" / "coverage.csv",
        dtype={"record_id": str, "holdout": str},
    )
    fits = json.loads((results / "train" / "svm" / "unseen_fault" / "info.json").read_text())[
        "models"
    ]
    (entry,) = [
        e
        for e in summary["simulation_coverage"]["results"]
        if (e["classifier"], e["protocol"]) == ("svm", "unseen_fault")
    ]
    assert entry["measured_percent"] == 0 and entry["design_records"] == len(SLICE)
    assert entry["features"] == sorted(
        {f for m in fits if m["measured_percent"] == 0 for f in m["selected_features"]}
    )
    at_zero = coverage[coverage["measured_percent"] == 0]
    out = at_zero.groupby("record_id").apply(
        lambda r: (r["outside_training"] * r["n_segments"]).sum() / r["n_segments"].sum()
    )
    assert set(entry["design_records_outside"]) == set(out[out > 0.05].index)
    assert entry["covers_design_records"] == bool((out <= 0.05).all())
    per_record = pd.read_csv(results / "report" / "recall_per_record.csv", dtype={"record_id": str})
    mine = per_record[
        (per_record["protocol"] == "unseen_fault")
        & (per_record["measured_percent"] == 0)
        & per_record["classifier"].isin(["svm", "joined_svm"])
    ].set_index("record_id")
    for classifier in ("svm", "joined_svm"):
        got = mine[mine["classifier"] == classifier]["outside_training"]
        assert got.to_dict() == pytest.approx(out.reindex(got.index).to_dict())
    assert per_record.loc[per_record["classifier"] == "knn", "outside_training"].isna().all()
    # every fault record says whether an envelope analysis shows its line, which, or why none does
    # (issue 71), and the report says where measured data of other records lower a figure
    faults = per_record[per_record["true_label"] != "normal"]
    shown = faults["shows_line"].astype(str) == "True"
    assert faults.loc[shown, "line_shown_by"].notna().all()
    assert faults.loc[~shown, "no_line_why"].str.startswith("no analysis lifts").all()
    share = pd.read_csv(results / "report" / "measured_share.csv")
    assert {"svm", "joined_svm", "envelope_rule"} <= set(share["classifier"])
    assert (share.loc[share["lowered"], "why"].str.len() > 0).all()
    summary = json.loads((results / "report" / "summary.json").read_text())
    assert "measured_share" in summary and summary["fault_lines"]["analyses"][0] == "features"


def test_cwru_hybrid_splits_follow_their_protocols(cwru_run):
    _, results = cwru_run
    records = pd.read_csv(results / "measured" / "records.csv")
    label = dict(zip(records.record_id, records.health_state))
    unseen = pd.read_parquet(results / "hybrid" / "unseen_fault.parquet")
    trained = unseen[unseen.role == "train"].record_id.map(label)
    assert set(trained) == {"normal"}  # faults are never measured in training
    holdout = pd.read_parquet(results / "hybrid" / "condition_holdout.parquet")
    assert sorted(holdout.holdout.unique()) == ["load=0", "load=1"]
    share = pd.read_parquet(results / "hybrid" / "segment_share.parquet")
    assert (share.segment >= 0).all()


def test_cwru_training_selects_three_features_on_training_data(cwru_run):
    _, results = cwru_run
    info = json.loads((results / "train" / "svm" / "unseen_fault" / "info.json").read_text())
    assert info["n_features"] == 6
    chosen = [m["selected_features"] for m in info["models"]]
    assert chosen and all(len(c) == 3 for c in chosen)
    calibration = json.loads((results / "calibration" / "rig" / "params.json").read_text())
    assert calibration["calibrated"] is True and calibration["speeds_rpm"] == [1796.0]
    assert calibration["cost"] <= calibration["nominal_cost"]


def test_another_folder_without_a_healthy_record_runs_by_config_alone(cwru_run, tmp_path):
    """Another download without a healthy record: no calibration, every class simulated, the
    faults present tested. The plumbing is the point, so a smaller run than the smoke's (two
    samples a state, one protocol, two shares, one classifier), layered as a user would."""
    workdir, _ = cwru_run
    folder = cwru_folder(tmp_path / "other", OTHER_SET)
    smaller = tmp_path / "smaller.yaml"
    smaller.write_text(
        yaml.safe_dump(
            {
                "simulation": {"samples_per_state": 2, "samples_per_job": 2},
                "hybrid": {"protocols": ["unseen_fault"], "measured_percent": [0, 100]},
                "classifiers": {"knn": {"enabled": False}},
            }
        )
    )
    snakemake(
        workdir,
        "--cores",
        "2",
        "--configfile",
        ".test/config/cwru-smoke.yaml",
        str(smaller),
        "--config",
        f"measured_dir={folder}",
        "run_name=cwru-other",
    )
    results = workdir / "results" / "cwru-other"
    summary = json.loads((results / "report" / "summary.json").read_text())
    calibration = json.loads((results / "calibration" / "rig" / "params.json").read_text())
    assert calibration["calibrated"] is False and "normal" in calibration["reason"]
    # every configured class is simulated; the tests cover the classes present
    simulated = {p.name for p in (results / "simulated").iterdir()}
    assert simulated == {"normal", "inner_race", "ball", "outer_race"}
    tested = {label for r in summary["results"] for label in r["recall_per_class"]}
    assert tested == {"ball", "inner_race", "outer_race"}


def test_data_files_whose_times_change_but_not_their_contents_rerun_nothing(cwru_run):
    """A refreshed share, a copied download or new links give the same data files new times.
    Snakemake compares the contents it recorded (profiles/default's max-checksum-file-size covers
    the 2-4 MB CWRU files; its own 1 MB default does not), so the finished run stays finished."""
    workdir, _ = cwru_run
    folder = workdir.parent / "slice"  # the fixture's folder of links to the shared files
    run = [
        "-n",
        "--configfile",
        ".test/config/cwru-smoke.yaml",
        "--config",
        f"measured_dir={folder}",
    ]
    assert "Nothing to be done" in snakemake(workdir, *run).stdout
    links = sorted(folder.glob("*.mat"))
    assert max((CWRU / link.name).stat().st_size for link in links) > 1_000_000
    times = {link: link.lstat() for link in links}
    try:
        now = time.time()
        for link in links:
            os.utime(link, (now, now), follow_symlinks=False)
        assert "Nothing to be done" in snakemake(workdir, *run).stdout
    finally:  # the fixture's files are read only: their times go back
        for link, stat in times.items():
            os.utime(link, ns=(stat.st_atime_ns, stat.st_mtime_ns), follow_symlinks=False)


def planned_rules(workdir, edited: dict, folder) -> set | str:
    """The rules a params-triggered dry run of the finished run plans after the config edit
    `edited` (merged into .test/config/cwru-smoke.yaml), or the config error's message."""
    config = yaml.safe_load((workdir / ".test" / "config" / "cwru-smoke.yaml").read_text())
    path = workdir / "edited.yaml"
    path.write_text(yaml.safe_dump(deep_update(config, edited)))
    try:
        result = snakemake(
            workdir,
            "-n",
            "--rerun-triggers",
            "params",
            "--configfile",
            path.name,
            "--config",
            f"measured_dir={folder}",
            check=False,
        )
    finally:
        path.unlink()
    if result.returncode != 0:
        return result.stdout + result.stderr
    if "Nothing to be done" in result.stdout:
        return set()
    return set(re.findall(r"^rule (\w+):", result.stdout, flags=re.M))


def test_a_bearing_runs_simulation_knob_reruns_its_simulations_and_a_gear_knob_is_refused(
    cwru_run,
):
    """Snakemake's plans on the finished run (test_systems.py checks the job specs): the shared
    simulation section reruns the simulations and what follows, the joined method included (it
    reads the SVM's predictions), never the ingestion or the calibration; the gear's own knob
    (model.variability.perturbation_sigma) is no key of a bearing run."""
    workdir, _ = cwru_run
    folder = workdir.parent / "slice"  # the fixture's folder of links to the shared files
    after = {"train", "track", "track_plots", "report", "run_config", "report_pages", "all"}
    assert planned_rules(workdir, {"simulation": {"max_failed_share": 0.2}}, folder) == {
        "simulate",
        "features_simulated",
        "joined",
        *after,
    }
    knob = {"model": {"variability": {"perturbation_sigma": 0.05}}}
    assert "unknown key model" in planned_rules(workdir, knob, folder)

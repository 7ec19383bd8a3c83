"""Loads as operating conditions of the gear rig (`rig.loads`): the virtual bench, the simulation
and the calibration run every (speed, load), and the config check catches a table or a condition
that does not fit them."""

import json

import numpy as np
import pandas as pd
import pytest

from condmon.calibrate import measured_spectra
from condmon.config import ConfigError
from condmon.operating import OperatingPoint
from condmon.signals import make_rows, write_signal_table
from condmon.simulate import machine_of, simulate_batch
from conftest import config_of, system_of

LOADS = {
    "rig": {"speeds_rpm": [775], "loads": [5.0, 20.0], "segment_seconds": 0.1},
    "hybrid": {"condition": "load"},
    "numerics": {"settle_time": 0.05},
    "model": {"mesh_compliance": None},
    "features": {"spectrum": {"resolution_hz": 10.0}},
}
CALIBRATED = {
    "contact_law": "flores",
    "sensor_noise": 0.0,
    "parameters": {"mesh_stiffness": 4e8, "contact_exponent": 1.4, "bushing_stiffness": 2e8},
}


@pytest.fixture(scope="module")
def gear():
    return system_of(".test/config/smoke.yaml", LOADS)


def test_operating_points_are_every_speed_and_load_named_for_files():
    assert OperatingPoint(450.0).label == "450rpm"
    assert OperatingPoint(450.0, 20.0).label == "450rpm_20Nm"
    assert OperatingPoint(450.0, 50.0, "percent").label == "450rpm_50pct"
    assert OperatingPoint(450.0, 50.0, "percent").describe() == "450 rpm, 50%"
    table = pd.DataFrame({"speed_rpm": [450.0, 450.0, 775.0], "load": [20.0, 5.0, 20.0]})
    assert OperatingPoint(450.0, 20.0).holds(table).tolist() == [True, False, False]
    assert OperatingPoint(450.0).holds(table).tolist() == [True, True, False]

    two = system_of(
        ".test/config/smoke.yaml",
        {"rig": {"speeds_rpm": [1100], "loads": [20.0, 5.0]}, "hybrid": {"condition": "load"}},
    )
    # by speed and load, as the calibration and the background take them, whatever the config's order
    assert [p.label for p in two.operating_points] == ["1100rpm_5Nm", "1100rpm_20Nm"]
    assert two.operating_point("1100rpm_5Nm") == OperatingPoint(1100.0, 5.0)
    with pytest.raises(ValueError, match="operating point '1100rpm'"):
        two.operating_point("1100rpm")
    # no rig.loads: one point per speed, named as the speed's jobs always were
    one = system_of(".test/config/smoke.yaml")
    assert [p.label for p in one.operating_points] == ["450rpm", "1100rpm"]
    assert one.measured_parts()[:2] == ["healthy_450rpm", "healthy_1100rpm"]


def test_a_load_in_percent_is_a_share_of_the_rated_torque():
    system = system_of(
        ".test/config/smoke.yaml",
        {"rig": {"loads": [50.0], "load_unit": "percent"}, "model": {"load_torque": 12.0}},
    )
    assert system.load_torque(50.0) == pytest.approx(6.0)
    assert system.table_load(6.0) == pytest.approx(50.0)
    assert system.at_load({"mesh_stiffness": 1.0}, 50.0) == {
        "mesh_stiffness": 1.0,
        "load_torque": pytest.approx(6.0),
    }
    assert system.at_load({"mesh_stiffness": 1.0}, None) == {"mesh_stiffness": 1.0}


def _batch(system, load, health="healthy", seed=1):
    return simulate_batch(
        system,
        CALIBRATED,
        health,
        775.0,
        0,
        samples=1,
        simulation={"segments_per_sample": 1, "seed": seed, "max_failed_share": 0.0},
        load=load,
    )


def test_the_simulation_runs_each_load_and_records_it(gear):
    light, report = _batch(gear, 5.0)
    heavy, _ = _batch(gear, 20.0)
    assert {r["load"] for r in light} == {5.0} and {r["load"] for r in heavy} == {20.0}
    assert report["load"] == 5.0 and report["speed_rpm"] == 775.0
    light_params, heavy_params = (json.loads(rows[0]["params"]) for rows in (light, heavy))
    assert light_params["load_torque"] == 5.0 and heavy_params["load_torque"] == 20.0
    # each load its own machine (twins pair within a point) and its own random stream
    assert machine_of(light[0]["record_id"]) == "775rpm_5Nm-b000-s000"
    assert light_params["seed"] != heavy_params["seed"]


def test_the_load_reaches_the_model(gear):
    """One machine (one seed) at the model's own load runs as without a load; at another, not."""
    values = {**CALIBRATED["parameters"], "contact_law": "flores"}

    def run(load):
        signals = gear.simulate_sample(gear.at_load(values, load), "healthy", 775.0, 0.1, 3)
        return np.concatenate(list(signals.values()))

    own = float(gear.config["model"]["load_torque"])
    assert np.array_equal(run(own), run(None))
    assert not np.allclose(run(4.0 * own), run(None), rtol=1e-3, atol=0.0)


def test_the_virtual_bench_records_every_load_in_the_tables_unit(gear):
    parts = gear.measured_parts()
    assert "healthy_775rpm_5Nm" in parts and "missing_tooth_775rpm_20Nm" in parts
    rows = gear.measured_part_rows("healthy_775rpm_20Nm")
    assert {r["load"] for r in rows} == {20.0}
    assert {r["record_id"] for r in rows} >= {"vb-healthy-775rpm_20Nm-r00"}
    assert all(r["speed_rpm"] == 775.0 for r in rows)


def test_the_calibration_target_is_each_points_own_records():
    rows = []
    t = np.arange(2048) / 5120.0
    for load, amplitude in ((5.0, 1.0), (20.0, 3.0)):
        signals = {c: amplitude * np.sin(2 * np.pi * 300.0 * t) for c in ("a", "b")}
        rows += make_rows(f"h-{load:g}", "measured", "healthy", 775.0, load, 5120.0, signals, 512)
    frame = pd.DataFrame(rows)
    spectrum = {"f_min_hz": 0.0, "f_max_hz": 1000.0, "resolution_hz": 10.0, "scale": "linear"}
    points = [OperatingPoint(775.0, 5.0), OperatingPoint(775.0, 20.0)]
    per_point = measured_spectra(frame, points, ["a", "b"], spectrum, 10.0, 5120.0)
    assert per_point[1].max() == pytest.approx(3.0 * per_point[0].max(), rel=1e-6)
    with pytest.raises(ValueError, match="no measured 'healthy' records at 775 rpm, 50 N m"):
        measured_spectra(frame, [OperatingPoint(775.0, 50.0)], ["a"], spectrum, 10.0, 5120.0)


def _table(path, loads):
    rows, rng = [], np.random.default_rng(0)
    for load in loads:
        for health in ("healthy", "missing_tooth"):
            signals = {c: rng.normal(0.0, 0.1, 2560) for c in ("B1_x", "B1_y", "B2_x", "B2_y")}
            rows += make_rows(
                f"{health}-{load:g}", "measured", health, 775.0, load, 5120.0, signals, 1280
            )
    write_signal_table(pd.DataFrame(rows), path)
    return path


def test_the_config_check_names_an_unlisted_load_and_a_condition_that_is_not_the_load(tmp_path):
    with pytest.raises(
        ConfigError, match=r"records at \[50.0\] N m .* but rig.loads is \[5.0, 20.0\]"
    ):
        config_of(
            ".test/config/smoke.yaml",
            {**LOADS, "measured_table": str(_table(tmp_path / "t.parquet", [5.0, 50.0]))},
        )
    with pytest.raises(ConfigError, match="set hybrid.condition: load"):
        config_of(".test/config/smoke.yaml", {**LOADS, "hybrid": {"condition": "speed_rpm"}})
    with pytest.raises(ConfigError, match="a grid of several speeds and several loads"):
        grid = {**LOADS, "rig": {**LOADS["rig"], "speeds_rpm": [450, 775]}}
        config_of(".test/config/smoke.yaml", grid)
    config_of(".test/config/smoke.yaml", LOADS)


def test_the_calibration_and_its_background_run_each_load(gear):
    """A bench of two loads calibrates on each load's healthy records with the model at that
    load (one generation of four), and the background is one per speed."""
    from condmon.background import estimate_background

    frame = pd.DataFrame(
        gear.measured_part_rows("healthy_775rpm_5Nm")
        + gear.measured_part_rows("healthy_775rpm_20Nm")
    )
    config = gear.config
    calibration = dict(
        config["calibration"], population=4, generations=1, sim_seconds=0.2, contact_laws=["flores"]
    )
    channels = list(config["features"]["channels"])[:2]
    result, _, spectra = gear.calibrate(
        frame, "potential_energy", calibration, config["features"]["spectrum"], channels
    )
    assert result["operating_points"] == ["775rpm_5Nm", "775rpm_20Nm"]
    assert result["speeds_rpm"] == [775.0]
    model = spectra.groupby("load")["model_only"].sum()
    assert sorted(model.index) == [5.0, 20.0] and model[5.0] != model[20.0]
    background = estimate_background(
        gear, frame, result, channels, runs=1, sim_seconds=0.2, seed=1, method="deficit"
    )
    assert sorted(background["speed_rpm"].unique()) == [775.0]
    assert len(background) == len(channels) * background["freq_hz"].nunique()


def _rig_table(gear, path, fs_hz):
    """The bench's records as a user's rig gives them: two single-axis sensors (v1, v2), one
    record per state and load (the bench's records of each, one after another), no params,
    declared at `fs_hz`."""
    bench = pd.DataFrame(
        [row for part in gear.measured_parts() for row in gear.measured_part_rows(part)]
    )
    bench = bench[bench["channel"].isin(["A1_y", "A2_y"])].drop(columns="params")
    bench["channel"] = bench["channel"].map({"A1_y": "v1", "A2_y": "v2"})
    bench["source"], bench["fs_hz"] = "measured", float(fs_hz)
    bench = bench.sort_values(["health_state", "load", "record_id", "segment"])
    bench["record_id"] = "rig-" + bench["health_state"] + "-" + bench["load"].map("{:g}Nm".format)
    bench["segment"] = bench.groupby(["record_id", "channel"]).cumcount().astype("int32")
    bench.to_parquet(path)  # as a rig writes it: without the optional params column
    return path


# the bench of the rig test: segments of 0.25 s, whose spectrum resolves the mesh line from one
# a tenth off (the rate check refuses on clear evidence only)
RIG = {**LOADS, "rig": {**LOADS["rig"], "segment_seconds": 0.25}, "features": {}}


def _rig_config(table, fs_hz):
    return {
        **LOADS,
        "rig": {**LOADS["rig"], "output_rate_hz": float(fs_hz), "segment_seconds": 1280 / fs_hz},
        "run_name": "rig",
        "measured_table": str(table),
        "model": {
            **LOADS["model"],
            "sensors": {
                "v1": {"housing": 0, "directions": ["y"]},
                "v2": {"housing": 2, "directions": ["y"]},
            },
        },
        "features": {"spectrum": {"resolution_hz": 5.0}, "channels": ["v1", "v2"]},
        "calibration": {"reserve": {"each_condition": True, "calibration_segments": 2}},
    }


@pytest.mark.pipeline
def test_a_single_axis_table_of_one_record_per_state_and_load(tmp_path):
    """Issue 73's user: single-axis sensors, one record per state and load at one speed. At a
    rate the spectrum contradicts the config check names the rate the mesh lines imply; at the
    right one the table runs through the hybrid splits with no cutting by hand: each load's lone
    healthy record split in time, condition_holdout holding out each load."""
    import yaml

    from condmon.hybrid import read_split_table
    from conftest import copy_project, snakemake

    gear = system_of(".test/config/smoke.yaml", RIG)
    wrong = 1.1 * gear.output_rate_hz
    table = _rig_table(gear, tmp_path / "wrong.parquet", wrong)
    with pytest.raises(ConfigError, match=r"the lines imply a rate of 51(19|2\d) Hz"):
        config_of(".test/config/smoke.yaml", _rig_config(table, wrong))

    table = _rig_table(gear, tmp_path / "rig.parquet", gear.output_rate_hz)
    workdir = copy_project(tmp_path / "project")
    config = dict(_rig_config(table, gear.output_rate_hz), base=".test/config/smoke.yaml")
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(config))
    snakemake(
        workdir, "--cores", "1", "--until", "hybrid", "--configfile", str(tmp_path / "rig.yaml")
    )
    splits = read_split_table(workdir / "results/rig/hybrid/record_split.parquet")
    healthy = splits[splits["record_id"].str.startswith("rig-healthy")]
    roles = healthy.groupby("record_id")["role"].agg(set)
    assert sorted(roles.index) == ["rig-healthy-20Nm", "rig-healthy-5Nm"]
    assert all({"calibration", "unused", "test"} <= r for r in roles)
    held_out = read_split_table(workdir / "results/rig/hybrid/condition_holdout.parquet")
    assert sorted(held_out["holdout"].unique()) == ["load=20", "load=5"]

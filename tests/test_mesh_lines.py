"""The config checks of a gear table against its rate: where its mesh lines lie, and the TSA grid (issue 73, item 4)."""

import numpy as np
import pytest

from condmon.signals import make_rows, write_signal_table
from conftest import ROOT
from condmon.systems.gear.mesh_lines import (
    implied_rate,
    line_to_floor,
    mesh_line_problems,
    power_spectrum,
)

FS, TEETH, RPM = 5120.0, 29, 450.0


def gear_record(rng, seconds=4.0, fs=FS, rpm=RPM, teeth=TEETH):
    """A healthy gear's vibration: three mesh harmonics, amplitude-modulated once a revolution,
    in coloured noise (a housing resonance near 1.5 kHz) at `fs` samples per second."""
    t = np.arange(int(seconds * fs)) / fs
    shaft, mesh = rpm / 60, teeth * rpm / 60
    lines = sum(
        a * np.sin(2 * np.pi * k * mesh * t + rng.uniform(0, 6))
        for k, a in ((1, 1.0), (2, 0.5), (3, 0.3))
    )
    signal = lines * (1 + 0.2 * np.sin(2 * np.pi * shaft * t))
    noise = np.convolve(rng.normal(0, 1.0, t.size), np.hanning(7), "same")
    return signal + noise


def table(tmp_path, declared_fs, records=2):
    """A signal table of healthy records sampled at FS but declared at `declared_fs`."""
    rng = np.random.default_rng(3)
    rows = []
    for r in range(records):
        rows += make_rows(
            f"h{r}",
            "measured",
            "healthy",
            RPM,
            0.0,
            declared_fs,
            {"a1": gear_record(rng), "a2": gear_record(rng)},
            segment_length=int(FS),
        )
    path = tmp_path / "rig.parquet"
    write_signal_table(rows, path)
    return path


def test_a_line_stands_above_its_floor_and_noise_does_not():
    rng = np.random.default_rng(1)
    freqs, power = power_spectrum(gear_record(rng)[None, :], FS, resolution_hz=RPM / 60 / 8)
    mesh = TEETH * RPM / 60
    assert line_to_floor(freqs, power, mesh) > 100
    assert line_to_floor(freqs, power, 1.17 * mesh) < 4  # between the lines: the floor
    assert line_to_floor(freqs, power, FS) == 0.0  # beyond the spectrum


def test_the_right_rate_passes(tmp_path):
    assert mesh_line_problems(table(tmp_path, FS), "healthy", TEETH) == []


def test_a_rate_off_by_ten_percent_is_refused_with_the_implied_rate(tmp_path):
    problems = mesh_line_problems(table(tmp_path, 1.1 * FS), "healthy", TEETH)
    assert len(problems) == 1 and "fs_hz 5632 Hz" in problems[0]
    implied = float(problems[0].split("imply a rate of ")[1].split(" Hz")[0])
    assert implied == pytest.approx(FS, rel=0.005)


def test_no_clear_evidence_refuses_nothing():
    """Pure noise has no line anywhere: the rate is not refused on a guess."""
    rng = np.random.default_rng(2)
    freqs, power = power_spectrum(rng.normal(size=(4, 20480)), FS, resolution_hz=1.0)
    assert implied_rate(freqs, power, FS, TEETH * RPM / 60)["rate_hz"] is None


def test_silent_healthy_records_are_named_not_divided_by(tmp_path):
    """A table whose healthy records are all zeros (a dead sensor, an empty export) has no
    spectrum to check: named as such, where the weighted line centre once divided by zero."""
    rows = make_rows("h0", "measured", "healthy", RPM, 0.0, FS, {"a1": np.zeros(8192)}, 4096)
    path = tmp_path / "silent.parquet"
    write_signal_table(rows, path)
    (problem,) = mesh_line_problems(path, "healthy", TEETH)
    assert "healthy records at 450 rpm hold only zeros (the 2 segments read)" in problem


def test_the_gear_config_check_names_the_rate(tmp_path):
    """The default rig (a 29-tooth pinion, 450 rpm among its speeds) over a table at a wrong rate:
    refused when the config is read, before any job."""
    from condmon.config import ConfigError, load_schema, validate_config

    schema = load_schema(ROOT / "config" / "schema.yaml")
    with pytest.raises(ConfigError, match=r"fs_hz 5632 Hz.*imply a rate of 51[0-9][0-9] Hz"):
        validate_config({"measured_table": str(table(tmp_path, 1.1 * FS))}, schema)


def test_an_angular_grid_that_folds_is_refused_when_the_config_is_read():
    """The residual's TSA grid against the rate, for the widest window `auto` can give: found by
    the config check (before any job), not by the features job after the simulation."""
    from condmon.config import ConfigError, load_schema, validate_config

    schema = load_schema(ROOT / "config" / "schema.yaml")
    config = {
        "features": {
            "kind": "residual",
            "residual": {"samples_per_revolution": 400},
            "healthy_reference": {"enabled": True},
        }
    }
    with pytest.raises(
        ConfigError, match=r"samples_per_revolution: 400 per revolution of the pinion at 450 rpm"
    ):
        validate_config(config, schema)
    config["features"]["residual"]["samples_per_revolution"] = 1024
    validate_config(config, schema)


def test_the_check_reads_the_first_healthy_rows_of_each_speed_from_their_row_groups(tmp_path):
    """Only the row groups holding the chosen rows are read; what comes back is those rows."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    from condmon.systems.gear.mesh_lines import healthy_records

    path = table(tmp_path, FS)
    frame = pd.read_parquet(path)
    frame.loc[frame.index[:3], "health_state"] = "pitting"  # the first rows are not healthy
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), path, row_group_size=3)
    assert pq.ParquetFile(path).num_row_groups > 3
    records = healthy_records(path, "healthy", max_rows=4)
    expected = np.vstack(frame[frame["health_state"] == "healthy"]["signal"].head(4).tolist())
    assert list(records) == [(RPM, FS)]
    np.testing.assert_array_equal(records[RPM, FS], expected)

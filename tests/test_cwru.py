"""CWRU ingestion: catalogue, labels, errors on synthetic files, and the real shared files."""

import logging
import re

import numpy as np
import pandas as pd
import pytest
import scipy.io
import yaml

from conftest import CWRU, ROOT
from condmon.systems.bearing.cwru import (
    CWRU_TABLE,
    G,
    NOMINAL_RPM,
    CwruError,
    cwru_rows,
    health_label,
    read_cwru_file,
    read_manifest,
    task_labels,
    write_cwru_signal_table,
)
from condmon.signals import read_signal_table

CWRU_DIR = CWRU
needs_data = pytest.mark.skipif(
    not CWRU_DIR.is_dir(), reason=f"CWRU data folder {CWRU_DIR} not present"
)


def write_mat(path, number, n=10_000, rpm=1796, channels=("DE", "FE"), extra=None, seed=0):
    """A small file in the CWRU layout (values in g)."""
    rng = np.random.default_rng(seed)
    variables = {f"X{number:03d}_{ch}_time": rng.normal(0, 0.1, (n, 1)) for ch in channels}
    if rpm is not None:
        variables[f"X{number:03d}RPM"] = np.array([[rpm]], dtype=np.uint16)
    variables.update(extra or {})
    scipy.io.savemat(path, variables)
    return variables


# -- catalogue and labels --------------------------------------------------------------------
@needs_data
def test_builtin_table_covers_the_shared_index():
    index = read_manifest(CWRU_DIR / "index.csv")
    table = CWRU_TABLE.set_index("cwru_number")
    for row in index.itertuples():
        ours = table.loc[row.cwru_number]
        assert (ours.fault, ours.or_position, ours.load_hp, ours.fs_hz, ours.rpm, ours.sha256) == (
            row.fault,
            row.or_position,
            row.load_hp,
            row.fs_hz,
            row.rpm,
            row.sha256,
        )
        assert ours.diameter_in == pytest.approx(row.diameter_in)


def test_catalogue_is_consistent():
    assert CWRU_TABLE["cwru_number"].is_unique
    assert set(CWRU_TABLE["fs_hz"]) == {12000.0, 48000.0}
    assert (CWRU_TABLE.loc[CWRU_TABLE["fault"] == "normal", "fs_hz"] == 48000).all()
    assert CWRU_TABLE.groupby(["fault", "or_position", "diameter_in"]).size().eq(4).all()


@pytest.mark.parametrize(
    "task,fault,diameter,label",
    [
        ("location", "normal", 0.0, "normal"),
        ("location", "outer_race", 0.014, "outer_race"),
        ("location", "ball", 0.028, "ball"),
        ("severity", "outer_race", 0.007, "outer_race_0.007in"),
        ("severity", "normal", 0.0, "normal"),
        ("severity", "inner_race", 0.007, None),
        ("ten_class", "ball", 0.021, "ball_0.021in"),
        ("ten_class", "inner_race", 0.028, None),
        ("ten_class", "normal", 0.0, "normal"),
    ],
)
def test_health_label(task, fault, diameter, label):
    assert health_label(task, fault, diameter) == label


def test_task_labels_and_unknown_task():
    assert task_labels("severity") == [
        "outer_race_0.007in",
        "outer_race_0.014in",
        "outer_race_0.021in",
        "normal",
    ]
    assert len(task_labels("ten_class")) == 10
    for row in CWRU_TABLE.itertuples():
        for task in ("location", "severity", "ten_class"):
            label = health_label(task, row.fault, row.diameter_in)
            assert label is None or label in task_labels(task)
    with pytest.raises(ValueError, match="unknown task"):
        health_label("size", "ball", 0.007)


# -- synthetic files -------------------------------------------------------------------------
def test_reads_channels_in_si_units_and_the_stored_speed(tmp_path):
    variables = write_mat(tmp_path / "130.mat", 130, rpm=1801)
    record = read_cwru_file(tmp_path / "130.mat", channels=("DE", "FE"))
    assert record.number == 130 and record.fs_hz == 12000.0
    assert record.speed_rpm == 1801.0 and record.speed_from_file
    assert record.signals["DE"] == pytest.approx(variables["X130_DE_time"].ravel() * G)
    assert record.signals["FE"] == pytest.approx(variables["X130_FE_time"].ravel() * G)


def test_selects_variables_by_the_file_number(tmp_path):
    # 99.mat of the original set also holds a stray copy of record 98's variables
    own = write_mat(
        tmp_path / "99.mat",
        99,
        seed=1,
        extra={
            "X098_DE_time": np.full((10_000, 1), 7.0),
            "X098RPM": np.array([[1234]], dtype=np.uint16),
        },
    )
    record = read_cwru_file(tmp_path / "99.mat")
    assert record.signals["DE"] == pytest.approx(own["X099_DE_time"].ravel() * G)
    assert record.speed_rpm == 1796.0 and record.fs_hz == 48000.0


def test_a_file_holding_only_another_record_is_an_error(tmp_path):
    write_mat(tmp_path / "130.mat", 131)
    with pytest.raises(CwruError, match=r"130\.mat.*no X130_DE_time.*\[131\]"):
        read_cwru_file(tmp_path / "130.mat")


@pytest.mark.parametrize("number,stored_as,load_hp", [(3001, 56, 0), (3007, 50, 2)])
def test_the_0028_in_files_are_read_under_the_number_they_store(
    tmp_path, number, stored_as, load_hp, caplog
):
    # the data centre's 3001.mat (inner race 0.028 in, 0 HP) holds X056_DE_time and no RPM
    own = write_mat(tmp_path / f"{number}.mat", stored_as, rpm=None, channels=("DE",))
    with caplog.at_level(logging.WARNING, logger="condmon.systems.bearing.cwru"):
        record = read_cwru_file(tmp_path / f"{number}.mat")
    assert record.number == number and record.fs_hz == 12000.0
    assert record.signals["DE"] == pytest.approx(own[f"X{stored_as:03d}_DE_time"].ravel() * G)
    assert record.speed_rpm == NOMINAL_RPM[load_hp] and not record.speed_from_file
    write_mat(tmp_path / "3002.mat", 56)  # 3002 stores X057: record 56 is another file's
    with pytest.raises(CwruError, match=r"3002\.mat.*\[56\]"):
        read_cwru_file(tmp_path / "3002.mat")


def test_missing_speed_falls_back_to_the_table_with_a_warning(tmp_path, caplog):
    write_mat(tmp_path / "131.mat", 131, rpm=None)
    with caplog.at_level(logging.WARNING, logger="condmon.systems.bearing.cwru"):
        record = read_cwru_file(tmp_path / "131.mat")
    assert record.speed_rpm == 1773.0 and not record.speed_from_file
    assert "X131RPM" in caplog.text and "131.mat" in caplog.text


@pytest.mark.parametrize(
    "content,match",
    [
        (b"cwru_number,file\n130,130.mat\n", "not a CWRU record: not a MATLAB"),
        (b"MATLAB 5.0 MAT-file, truncated", "not a readable MATLAB file"),
    ],
)
def test_not_a_matlab_file(tmp_path, content, match):
    (tmp_path / "130.mat").write_bytes(content)
    with pytest.raises(CwruError, match=match) as err:
        read_cwru_file(tmp_path / "130.mat")
    assert "130.mat" in str(err.value)


def test_errors_name_the_file(tmp_path):
    scipy.io.savemat(tmp_path / "130.mat", {"vibration": np.zeros((100, 1))})
    with pytest.raises(CwruError, match=r"130\.mat: not a CWRU record: no X<n>_DE_time"):
        read_cwru_file(tmp_path / "130.mat")

    write_mat(tmp_path / "131.mat", 131, channels=("DE",))
    with pytest.raises(CwruError, match=r"131\.mat: channel FE missing \(no variable X131_FE_time"):
        read_cwru_file(tmp_path / "131.mat", channels=("DE", "FE"))

    bad = np.random.default_rng(0).normal(size=(10_000, 1))
    bad[500] = np.nan
    write_mat(tmp_path / "197.mat", 197, extra={"X197_DE_time": bad})
    with pytest.raises(CwruError, match=r"197\.mat: X197_DE_time has 1 non-finite.*index 500"):
        read_cwru_file(tmp_path / "197.mat")

    write_mat(tmp_path / "4321.mat", 4321)
    with pytest.raises(CwruError, match=r"4321\.mat: file number 4321 is not in the CWRU table"):
        read_cwru_file(tmp_path / "4321.mat")


def test_short_record_is_an_error(tmp_path):
    write_mat(tmp_path / "130.mat", 130, n=3000)
    with pytest.raises(CwruError, match=r"130\.mat: 3000 samples .* shorter than one segment"):
        cwru_rows(tmp_path, manifest=None)


def test_folder_to_rows_resamples_segments_and_reports_left_out_files(tmp_path, caplog):
    write_mat(tmp_path / "97.mat", 97, n=48_000, seed=2)  # 48 kHz baseline: 1 s
    write_mat(tmp_path / "130.mat", 130, n=12_500, seed=3)
    write_mat(tmp_path / "105.mat", 105, n=12_500, seed=4)
    (tmp_path / "118.mat").write_bytes(b"left out unread: ball is not a severity class")
    (tmp_path / "notes.txt").write_text("not a record")
    with caplog.at_level(logging.WARNING, logger="condmon.systems.bearing.cwru"):
        ingest = cwru_rows(tmp_path, task="severity", segment_length=2048, manifest=None)
    # these synthetic files are not the originals: a sha256 warning, not an error
    assert "sha256" in caplog.text
    assert list(ingest.records["record_id"]) == ["cwru-97", "cwru-130"]
    assert list(ingest.records["health_state"]) == ["normal", "outer_race_0.007in"]
    assert list(ingest.records["n_samples"]) == [12_000, 12_500]
    assert list(ingest.records["n_segments"]) == [5, 6]
    assert not ingest.records["sha256_ok"].any()
    assert list(ingest.excluded["file"]) == ["105.mat", "118.mat"]
    assert ingest.excluded.loc[0, "fault"] == "inner_race"
    frame = pd.DataFrame(ingest.rows)
    assert set(frame["source"]) == {"measured"} and set(frame["channel"]) == {"DE"}
    assert set(frame["fs_hz"]) == {12000.0}
    assert {len(s) for s in frame["signal"]} == {2048}
    assert frame.groupby("record_id")["load"].first().to_dict() == {"cwru-97": 0.0, "cwru-130": 0.0}


def test_manifest_extends_and_overrides(tmp_path):
    write_mat(tmp_path / "OR007_1_5000.mat", 5000, n=9000)
    write_mat(tmp_path / "130.mat", 130, n=9000)
    manifest = tmp_path / "mine.csv"
    pd.DataFrame(
        [
            dict(
                cwru_number=5000,
                file="OR007_1_5000.mat",
                fault="ball",
                or_position="",
                diameter_in=0.014,
                load_hp=2,
                rpm=1750,
                fs_hz=12000,
                de_samples="",
                sha256="",
            ),
            dict(
                cwru_number=130,
                file="130.mat",
                fault="inner_race",
                or_position="",
                diameter_in=0.021,
                load_hp=3,
                rpm=1730,
                fs_hz=12000,
                de_samples="",
                sha256="",
            ),
        ]
    ).to_csv(manifest, index=False)
    ingest = cwru_rows(
        tmp_path, task="ten_class", manifest=manifest, segment_length=4096, channels=("DE", "FE")
    )
    records = ingest.records.set_index("record_id")
    assert records.loc["cwru-5000", "health_state"] == "ball_0.014in"
    assert records.loc["cwru-5000", "load_hp"] == 2.0
    assert records.loc["cwru-130", "health_state"] == "inner_race_0.021in"
    assert records["sha256_ok"].isna().all()  # no sha256 listed: not checked
    frame = pd.DataFrame(ingest.rows)
    assert set(frame["channel"]) == {"DE", "FE"} and len(frame) == 2 * 2 * 2
    with pytest.raises(CwruError, match="unknown fault"):
        pd.DataFrame(
            [dict(cwru_number=1, fault="cage", diameter_in=0, load_hp=0, fs_hz=12000)]
        ).to_csv(manifest, index=False)
        read_manifest(manifest)


# -- the real shared files -------------------------------------------------------------------
@pytest.fixture(scope="module")
def real_location():
    if not CWRU_DIR.is_dir():
        pytest.skip(f"CWRU data folder {CWRU_DIR} not present")
    return cwru_rows(CWRU_DIR, task="location")


def test_real_files_ingest(real_location):
    records = real_location.records.set_index("record_id")
    assert len(records) == 19 and real_location.excluded.empty
    assert records["sha256_ok"].all() and records["speed_from_file"].all()
    assert records.loc["cwru-97", "n_samples"] == -(-243938 // 4)  # 48 kHz resampled by 1/4
    assert records.loc["cwru-97", "speed_rpm"] == 1796.0
    assert records.loc["cwru-131", "speed_rpm"] == 1773.0
    assert records.loc["cwru-131", "load_hp"] == 1.0
    assert (records.loc[records["fs_original_hz"] == 12000, "n_segments"] == 29).all()
    assert records.loc["cwru-97", "n_segments"] == 14
    assert records["health_state"].value_counts().to_dict() == {
        "inner_race": 6,
        "ball": 6,
        "outer_race": 6,
        "normal": 1,
    }


def test_real_records_match_the_readme_levels(real_location):
    """Whole-record RMS and kurtosis of the drive-end signal against the data README."""
    frame = pd.DataFrame(real_location.rows)
    stats = {}
    for rid, rows in frame.groupby("record_id"):
        x = np.concatenate(rows.sort_values("segment")["signal"].to_list()).astype(float) / G
        x = x - x.mean()
        stats[rid] = (np.sqrt(np.mean(x**2)), np.mean(x**4) / np.mean(x**2) ** 2)
    assert stats["cwru-97"][0] == pytest.approx(0.072, rel=0.03)  # survives the resampling
    assert stats["cwru-131"][0] == pytest.approx(0.58, rel=0.05)
    assert stats["cwru-198"][0] == pytest.approx(0.095, rel=0.05)
    assert stats["cwru-235"][0] == pytest.approx(0.56, rel=0.05)
    for rid, (low, high) in {
        "cwru-130": (7.3, 8.2),
        "cwru-131": (7.3, 8.2),
        "cwru-197": (2.8, 3.9),
        "cwru-198": (2.8, 3.9),
        "cwru-234": (19.5, 24.0),
        "cwru-235": (19.5, 24.0),
    }.items():
        assert low < stats[rid][1] < high, (rid, stats[rid])


@needs_data
def test_real_severity_table_round_trip(tmp_path):
    ingest = write_cwru_signal_table(
        CWRU_DIR,
        tmp_path / "signals.parquet",
        task="severity",
        files=["97.mat", "130.mat", "105.mat"],
        config={"task": "severity"},
    )
    assert list(ingest.excluded["cwru_number"]) == [105]
    table = read_signal_table(tmp_path / "signals.parquet", allowed_sources=("measured",))
    assert sorted(table["record_id"].unique()) == ["cwru-130", "cwru-97"]
    assert set(table["health_state"]) == {"normal", "outer_race_0.007in"}
    assert table["signal"].map(len).eq(4096).all()


# -- bad records among the real files: stop names the file and reason, skip lists it --------
def bad_copy(folder, case):
    """`folder` with a good 131.mat (a link to the shared file) and a bad 130.mat made from the
    shared original; returns the channels to request."""
    folder.mkdir()
    (folder / "131.mat").symlink_to(CWRU_DIR / "131.mat")
    bad = folder / "130.mat"
    variables = {
        k: v for k, v in scipy.io.loadmat(CWRU_DIR / "130.mat").items() if not k.startswith("__")
    }
    de = variables["X130_DE_time"]
    if case == "missing file":
        return ("DE",)
    if case == "unreadable":
        bad.mkdir()  # root reads any file: a folder by that name cannot be read as one
        return ("DE",)
    if case == "truncated":
        bad.write_bytes((CWRU_DIR / "130.mat").read_bytes()[:1_000_000])
        return ("DE",)
    if case == "missing channel":
        del variables["X130_FE_time"]
    elif case in ("nan", "inf"):
        de[12_345] = np.nan if case == "nan" else -np.inf
    elif case == "dead sensor":
        variables["X130_DE_time"] = np.zeros_like(de)
    elif case == "length differs from the table":
        variables["X130_DE_time"] = de[:100_000]
    elif case == "stored rate differs from the table":
        variables["X130_fs"] = np.array([[48000.0]])
    elif case == "shorter than one segment":  # consistent with its manifest row, but too short
        variables = {k: v[:3000] if v.shape[0] > 1 else v for k, v in variables.items()}
    scipy.io.savemat(bad, variables)
    return ("DE", "FE")


BAD_CASES = {
    "missing file": r"no such file",
    "unreadable": r"cannot read \(.*Is a directory",
    "truncated": r"not a readable MATLAB file, truncated or corrupt",
    "missing channel": r"channel FE missing \(no variable X130_FE_time\)",
    "nan": r"X130_DE_time has 1 non-finite samples \(NaN or inf\), first at index 12345",
    "inf": r"X130_DE_time has 1 non-finite samples \(NaN or inf\), first at index 12345",
    "dead sensor": r"X130_DE_time is constant \(0 g in all 121991 samples\): dead sensor",
    "length differs from the table": r"X130_DE_time has 100000 samples but the table lists de_samples = 121991",
    "stored rate differs from the table": r"sampling rate 48000 Hz stored in X130_fs differs from the table's fs_hz 12000 Hz",
    "shorter than one segment": r"3000 samples at 12000 Hz, shorter than one segment \(4096\)",
}


def manifest_for(folder, case):
    """The shared index.csv, except that a record cut short on purpose lists its new length."""
    if case != "shorter than one segment":
        return CWRU_DIR / "index.csv"
    index = pd.read_csv(CWRU_DIR / "index.csv")
    index.loc[index["cwru_number"] == 130, "de_samples"] = 3000
    index.to_csv(folder / "manifest.csv", index=False)
    return folder / "manifest.csv"


@needs_data
@pytest.mark.parametrize("case", BAD_CASES)
def test_a_bad_file_stops_ingestion_naming_file_and_reason(tmp_path, case):
    folder = tmp_path / "cwru"
    channels = bad_copy(folder, case)
    with pytest.raises(CwruError) as error:
        cwru_rows(
            folder,
            channels=channels,
            manifest=manifest_for(tmp_path, case),
            files=["130.mat", "131.mat"],
        )
    assert str(error.value).startswith(f"{folder / '130.mat'}: ")
    assert re.search(BAD_CASES[case], str(error.value)), str(error.value)


@needs_data
@pytest.mark.parametrize("case", BAD_CASES)
def test_a_bad_file_is_skipped_and_listed_with_its_reason(tmp_path, case, caplog):
    folder = tmp_path / "cwru"
    channels = bad_copy(folder, case)
    with caplog.at_level(logging.WARNING, logger="condmon.systems.bearing.cwru"):
        ingest = write_cwru_signal_table(
            folder,
            tmp_path / "signals.parquet",
            channels=channels,
            manifest=manifest_for(tmp_path, case),
            files=["130.mat", "131.mat"],
            on_bad_record="skip",
        )
    assert list(ingest.records["record_id"]) == ["cwru-131"]
    assert set(read_signal_table(tmp_path / "signals.parquet")["record_id"]) == {"cwru-131"}
    excluded = ingest.excluded
    assert list(excluded["file"]) == ["130.mat"] and excluded["bad_record"].all()
    assert excluded.loc[0, "cwru_number"] == 130 and excluded.loc[0, "fault"] == "outer_race"
    assert re.search(BAD_CASES[case], excluded.loc[0, "reason"]), excluded.loc[0, "reason"]
    assert "130.mat" in caplog.text and "skipped" in caplog.text


@needs_data
def test_a_file_listed_in_the_manifest_but_absent_is_a_missing_file(tmp_path):
    folder = tmp_path / "cwru"
    folder.mkdir()
    (folder / "131.mat").symlink_to(CWRU_DIR / "131.mat")
    index = pd.read_csv(CWRU_DIR / "index.csv")
    index[index["cwru_number"].isin([130, 131, 105])].to_csv(folder / "index.csv", index=False)
    manifest = folder / "index.csv"
    with pytest.raises(CwruError, match=r"130\.mat: no such file"):
        cwru_rows(folder, task="severity", manifest=manifest)  # 105 is not a severity class
    ingest = cwru_rows(folder, task="severity", manifest=manifest, on_bad_record="skip")
    assert list(ingest.records["record_id"]) == ["cwru-131"]
    excluded = ingest.excluded.set_index("file")
    assert (
        excluded.loc["130.mat", "reason"] == "no such file"
        and excluded.loc["130.mat", "bad_record"]
    )
    assert not excluded.loc["105.mat", "bad_record"]
    # the folder's own index.csv (manifest "auto") describes a download, it does not list a duty
    assert list(cwru_rows(folder, task="severity").records["record_id"]) == ["cwru-131"]


def test_skip_with_no_usable_file_left_is_an_error(tmp_path):
    write_mat(tmp_path / "130.mat", 130, n=3000)
    (tmp_path / "131.mat").write_bytes(b"MATLAB 5.0 MAT-file, truncated")
    with pytest.raises(
        CwruError,
        match=r"no usable record left; 2 bad file\(s\) skipped: "
        r"130\.mat: 3000 samples.*; 131\.mat: not a readable MATLAB",
    ):
        cwru_rows(tmp_path, manifest=None, on_bad_record="skip")
    with pytest.raises(ValueError, match="on_bad_record"):
        cwru_rows(tmp_path, manifest=None, on_bad_record="ignore")


def test_a_file_without_a_number_is_listed_when_skipped(tmp_path):
    write_mat(tmp_path / "130.mat", 130, n=9000)
    scipy.io.savemat(tmp_path / "notes.mat", {"vibration": np.zeros((100, 1))})
    ingest = cwru_rows(tmp_path, manifest=None, on_bad_record="skip")
    assert list(ingest.records["record_id"]) == ["cwru-130"]
    row = ingest.excluded.iloc[0]
    assert row["file"] == "notes.mat" and pd.isna(row["cwru_number"]) and row["bad_record"]
    assert row["reason"].startswith("not a CWRU record: no X<n>_DE_time")


def test_design_specimens_are_named_as_records_csv_names_them_and_checked():
    """cwru.design_specimens entries become records.csv's specimen names (the report matches
    them); an outer race without its position, a position or size where none belongs, is a config
    problem naming the entry; the design specimens reach the report alone, no job's config."""
    from conftest import system_of
    from condmon.systems.bearing.cwru import specimen_of

    system = system_of(
        ".test/config/cwru-smoke.yaml",
        {
            "cwru": {
                "design_specimens": [
                    {"fault": "normal"},
                    {"fault": "outer_race", "diameter_in": 0.021, "position": "3:00"},
                    {"fault": "ball", "diameter_in": 0.014},
                ]
            }
        },
    )
    assert system.design_specimens() == ["normal", "outer_race 0.021 in at 3:00", "ball 0.014 in"]
    row = CWRU_TABLE[CWRU_TABLE.cwru_number == 246].iloc[0]  # outer race 0.021 in at 3:00, 0 HP
    assert specimen_of(row)["specimen"] == system.design_specimens()[1]
    assert not system.problems()
    for stage in ("measured", "calibrate", "simulate", "features", "baselines"):
        assert "design_specimens" not in system.job_config(stage).get("cwru", {}), stage
    from condmon.config import ConfigError

    with pytest.raises(ConfigError) as error:
        system_of(
            ".test/config/cwru-smoke.yaml",
            {
                "cwru": {
                    "design_specimens": [
                        {"fault": "outer_race", "diameter_in": 0.007},
                        {"fault": "normal", "diameter_in": 0.007},
                        {"fault": "ball", "diameter_in": 0.007, "position": "6:00"},
                    ]
                }
            },
        )
    assert re.findall(r"cwru\.design_specimens\[\d\]", str(error.value)) == [
        "cwru.design_specimens[0]",
        "cwru.design_specimens[1]",
        "cwru.design_specimens[2]",
    ]


def test_the_0028_in_inner_race_is_another_bearing_with_its_reason():
    """cwru.other_bearing (default: the 0.028-in inner race, files 3001-3004) names the specimen as
    records.csv does, with its reason, for the report alone; a specimen both design and another
    bearing is a config problem naming it."""
    from conftest import system_of
    from condmon.config import ConfigError
    from condmon.systems.bearing.cwru import specimen_of

    system = system_of("config/cwru.yaml")
    other = system.unmodelled_specimens()
    row = CWRU_TABLE[CWRU_TABLE.cwru_number == 3001].iloc[0]
    assert list(other) == [specimen_of(row)["specimen"]] == ["inner_race 0.028 in"]
    assert "NTN" in other["inner_race 0.028 in"] and "5.32" in other["inner_race 0.028 in"]
    assert not set(other) & set(system.design_specimens())
    for stage in ("measured", "calibrate", "simulate", "features", "baselines"):
        assert "other_bearing" not in system.job_config(stage).get("cwru", {}), stage
    with pytest.raises(ConfigError, match=r"ball 0.007 in.*both a design specimen and another"):
        system_of(
            ".test/config/cwru-smoke.yaml",
            {
                "cwru": {
                    "other_bearing": [{"fault": "ball", "diameter_in": 0.007, "reason": "test"}]
                }
            },
        )


@pytest.mark.parametrize(
    "task", sorted(p.name for p in (ROOT / "config" / "cwru-tasks").glob("*.yaml"))
)
def test_cwru_task_variants_layer_over_the_cwru_config(task):
    """Each CWRU task variant states only what differs from config/cwru.yaml, its base: alone
    (`--configfile config/cwru-tasks/<task>`) it validates, names its own run and task, and
    changes nothing of the rig, calibration, simulation or features."""
    from conftest import system_of

    changes = yaml.safe_load((ROOT / "config" / "cwru-tasks" / task).read_text())
    base = system_of("config/cwru.yaml")
    system = system_of(f"config/cwru-tasks/{task}")
    assert not system.problems()
    assert changes.pop("base") == "config/cwru.yaml"
    assert system.config["run_name"] != base.config["run_name"]
    assert system.config["cwru"]["task"] != base.config["cwru"]["task"]
    assert set(changes) <= {"run_name", "cwru", "hybrid"}
    for section in ("bearing", "rig", "calibration", "simulation", "features"):
        assert system.config[section] == base.config[section], section


@pytest.mark.parametrize(
    "variant", sorted(p.name for p in (ROOT / "config" / "cwru-envelopes").glob("*.yaml"))
)
def test_cwru_envelope_variants_change_the_envelope_analysis_only(variant):
    """Each envelope-analysis variant layers on config/cwru.yaml (its `base`), validates, names its
    own run, and changes nothing but features.statistical.envelope (issue 71)."""
    from conftest import system_of

    changes = yaml.safe_load((ROOT / "config" / "cwru-envelopes" / variant).read_text())
    assert changes.pop("base") == "config/cwru.yaml"
    base = system_of("config/cwru.yaml")
    system = system_of("config/cwru.yaml", changes)
    assert not system.problems()
    assert system.config["run_name"] != base.config["run_name"]
    assert set(changes) == {"run_name", "features"} and set(changes["features"]) == {"statistical"}
    assert set(changes["features"]["statistical"]) == {"envelope"}
    for section in ("bearing", "rig", "calibration", "simulation", "hybrid", "classifiers"):
        assert system.config[section] == base.config[section], section
    assert (
        system.config["features"]["statistical"]["envelope"]
        != base.config["features"]["statistical"]["envelope"]
    )


def test_the_envelope_rules_settings_reach_the_baselines_job_alone():
    """bearing.envelope_rule (quantile, line_analyses) and the envelope analysis it reads are the
    baselines job's: an edit of them reruns no calibration or simulation."""
    from conftest import system_of

    system = system_of("config/cwru.yaml")
    for stage in ("measured", "calibrate", "simulate", "features"):
        assert "envelope_rule" not in system.job_config(stage).get("bearing", {}), stage
    baselines = system.job_config("baselines")
    assert baselines["bearing"]["envelope_rule"]["line_analyses"] == [
        "fixed",
        "kurtogram",
        "prewhitened_fixed",
        "prewhitened_kurtogram",
    ]
    assert set(baselines["features"]["statistical"]) >= {"band_hz", "envelope", "line_tolerance"}

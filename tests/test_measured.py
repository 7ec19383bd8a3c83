"""A user's measured signal table: every bad input stops ingestion, naming the file and reason."""

import numpy as np
import pandas as pd
import pytest

from condmon.config import ConfigError
from condmon.measured import read_user_table, read_user_table_checked
from condmon.signals import SignalTableError, make_rows, write_signal_table

CHANNELS = ["A1_x", "A1_y"]
FS, SEGMENT = 5120.0, 0.25


def rows(record="rig-1", health="healthy", n=1280, signal=None):
    rng = np.random.default_rng(0)
    channels = {c: rng.normal(size=2 * n) if signal is None else signal for c in CHANNELS}
    return make_rows(record, "measured", health, 775.0, 10.0, FS, channels, segment_length=n)


def read(path, **overrides):
    args = dict(
        health_states=["healthy", "missing_tooth"],
        channels=CHANNELS,
        fs_hz=FS,
        segment_seconds=SEGMENT,
    )
    args.update(overrides)
    return read_user_table(path, **args)


def test_a_good_table_is_read(tmp_path):
    path = tmp_path / "rig.parquet"
    write_signal_table(rows() + rows("rig-2", "missing_tooth"), path)
    frame = read(path)
    assert set(frame["record_id"]) == {"rig-1", "rig-2"} and len(frame) == 8


def test_a_table_without_params_is_read_and_one_without_a_column_refused_at_the_config_check(
    tmp_path,
):
    """`params` (a simulated sample's parameters) is no column a rig's table needs; a missing
    signal-table column is named when the config is read, before any job."""
    from conftest import system_of

    frame = pd.DataFrame(rows() + rows("rig-2", "missing_tooth"))
    frame.drop(columns="params").to_parquet(tmp_path / "rig.parquet")
    assert set(read(tmp_path / "rig.parquet")["record_id"]) == {"rig-1", "rig-2"}
    rig = {"rig": {"speeds_rpm": [775]}, "hybrid": {"protocols": ["record_split"]}}
    system = system_of(changes=dict(rig, measured_table=str(tmp_path / "rig.parquet")))
    assert not [p for p in system.problems() if "lacks" in p]
    frame.drop(columns=["params", "fs_hz"]).to_parquet(tmp_path / "bad.parquet")
    with pytest.raises(ConfigError, match=r"lacks the signal-table columns \['fs_hz'\]"):
        system_of(changes=dict(rig, measured_table=str(tmp_path / "bad.parquet")))


def test_condition_holdout_over_loads_counts_the_tables_loads(tmp_path):
    """Loads as the operating condition: condition_holdout needs two loads in the table, however
    many speeds the rig lists."""
    from conftest import system_of

    frame = pd.DataFrame(rows() + rows("rig-2", "missing_tooth"))
    frame.to_parquet(tmp_path / "one-load.parquet")
    frame.assign(load=np.where(frame["record_id"] == "rig-1", 10.0, 20.0)).to_parquet(
        tmp_path / "two-loads.parquet"
    )
    rig = {"rig": {"speeds_rpm": [775]}, "hybrid": {"condition": "load"}}
    with pytest.raises(ConfigError, match=r"condition_holdout .* \(load\) .* the run has \[10.0\]"):
        system_of(changes=dict(rig, measured_table=str(tmp_path / "one-load.parquet")))
    system = system_of(changes=dict(rig, measured_table=str(tmp_path / "two-loads.parquet")))
    assert not [p for p in system.problems() if "condition_holdout" in p]


@pytest.mark.parametrize(
    "case, message",
    [
        ("missing file", "no such signal table"),
        ("not parquet", "not a readable Parquet file"),
        ("truncated", "not a readable Parquet file"),
        ("unknown label", "health states ['cracked']"),
        ("missing channel", "channels ['A1_y']"),
        ("other rate", "sampling rate [12000.0] Hz"),
        ("short segments", "segments have [640] samples"),
        ("dead sensor", "record 'rig-1': channel 'A1_x' is constant"),
        ("nan", "non-finite samples"),
        ("simulated source", "source ['simulated']"),
    ],
)
def test_bad_tables_name_the_file_and_the_reason(tmp_path, case, message):
    path = tmp_path / "rig.parquet"
    good = rows()
    if case == "not parquet":
        path.write_text("time,acc\n0,1\n")
    elif case == "truncated":
        write_signal_table(good, path)
        path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    elif case == "unknown label":
        write_signal_table(rows(health="cracked"), path)
    elif case == "missing channel":
        write_signal_table([r for r in good if r["channel"] == "A1_x"], path)
    elif case == "other rate":
        write_signal_table([dict(r, fs_hz=12000.0) for r in good], path)
    elif case == "short segments":
        write_signal_table(rows(n=640), path)
    elif case == "dead sensor":
        write_signal_table(
            [
                dict(r, signal=np.zeros(1280, np.float32)) if r["channel"] == "A1_x" else r
                for r in good
            ],
            path,
        )
    elif case == "nan":
        frame = pd.DataFrame(good)
        frame.at[0, "signal"] = np.full(1280, np.nan, np.float32)
        # Written with pyarrow directly: write_signal_table itself refuses non-finite samples.
        import pyarrow as pa
        import pyarrow.parquet as pq
        from condmon.signals import SCHEMA

        pq.write_table(pa.Table.from_pandas(frame, schema=SCHEMA, preserve_index=False), path)
    elif case == "simulated source":
        write_signal_table([dict(r, source="simulated") for r in good], path)
    with pytest.raises(SignalTableError) as error:
        read(path)
    assert message in str(error.value)
    assert str(path) in str(error.value)


# -- one bad record among good ones: stop names it, skip leaves it out and lists it ----------
def write_raw(rows_, path):
    """Written with pyarrow directly: write_signal_table itself refuses non-finite samples."""
    import pyarrow as pa
    import pyarrow.parquet as pq
    from condmon.signals import SCHEMA

    pq.write_table(
        pa.Table.from_pandas(pd.DataFrame(rows_), schema=SCHEMA, preserve_index=False), path
    )


def bad_record(case):
    """Rows of record 'rig-1' with one problem."""
    good = rows()
    if case == "missing channel":
        return [r for r in good if r["channel"] == "A1_x"]
    if case == "other rate":
        return [dict(r, fs_hz=12000.0) for r in good]
    if case == "shorter than one segment":
        return rows(n=640)
    if case == "dead sensor":
        return [
            dict(r, signal=np.full(1280, 0.3, np.float32)) if r["channel"] == "A1_y" else r
            for r in good
        ]
    if case in ("nan", "inf"):
        bad = np.ones(1280, np.float32)
        bad[7] = np.nan if case == "nan" else np.inf
        return [
            dict(r, signal=bad) if (r["channel"], r["segment"]) == ("A1_x", 1) else r for r in good
        ]
    if case == "channel lacks a segment":
        return [r for r in good if (r["channel"], r["segment"]) != ("A1_y", 1)]
    raise ValueError(case)


RECORD_CASES = {
    "missing channel": "channels ['A1_y'] used by the features are missing",
    "other rate": "sampling rate [12000.0] Hz differs",
    "shorter than one segment": "segments have [640] samples (shorter than one segment)",
    "dead sensor": "channel 'A1_y' is constant (dead sensor)",
    "nan": "channel 'A1_x' segment 1: 1 non-finite samples (NaN or inf), first at index 7",
    "inf": "channel 'A1_x' segment 1: 1 non-finite samples (NaN or inf), first at index 7",
    "channel lacks a segment": "channel 'A1_y' lacks segment(s) [1]",
}


@pytest.mark.parametrize("case", RECORD_CASES)
def test_a_bad_record_stops_ingestion_naming_file_record_and_reason(tmp_path, case):
    path = tmp_path / "rig.parquet"
    write_raw(bad_record(case) + rows("rig-2", "missing_tooth"), path)
    with pytest.raises(SignalTableError) as error:
        read(path)
    assert str(error.value).startswith(f"{path}: record 'rig-1': ")
    assert RECORD_CASES[case] in str(error.value)
    with pytest.raises(SignalTableError, match="rig-1"):
        read_user_table_checked(
            path, ["healthy", "missing_tooth"], CHANNELS, FS, SEGMENT, on_bad_record="stop"
        )


@pytest.mark.parametrize("case", RECORD_CASES)
def test_a_bad_record_is_skipped_and_listed_with_its_reason(tmp_path, case, caplog):
    path = tmp_path / "rig.parquet"
    write_raw(bad_record(case) + rows("rig-2", "missing_tooth"), path)
    frame, skipped = read_user_table_checked(
        path, ["healthy", "missing_tooth"], CHANNELS, FS, SEGMENT, on_bad_record="skip"
    )
    assert set(frame["record_id"]) == {"rig-2"} and len(frame) == 4
    assert list(skipped.columns) == ["record_id", "health_state", "speed_rpm", "load", "reason"]
    assert list(skipped["record_id"]) == ["rig-1"] and skipped.loc[0, "health_state"] == "healthy"
    assert RECORD_CASES[case] in skipped.loc[0, "reason"]
    assert "rig-1" in caplog.text and str(path) in caplog.text
    # the plain reader gives the same kept rows
    pd.testing.assert_frame_equal(read(path, on_bad_record="skip"), frame)


def test_skip_with_no_record_left_is_an_error(tmp_path):
    path = tmp_path / "rig.parquet"
    write_raw(bad_record("dead sensor") + rows("rig-2", signal=np.zeros(2560)), path)
    with pytest.raises(
        SignalTableError, match=r"every record is bad.*'rig-1'.*constant.*'rig-2'.*constant"
    ):
        read(path, on_bad_record="skip")


@pytest.mark.parametrize(
    "case, message",
    [
        ("missing file", "no such signal table"),
        ("truncated", "not a readable Parquet file"),
        ("unknown label", "health states ['cracked']"),
        ("simulated source", "source ['simulated']"),
    ],
)
def test_file_level_problems_stop_even_with_skip(tmp_path, case, message):
    path = tmp_path / "rig.parquet"
    if case == "truncated":
        write_signal_table(rows(), path)
        path.write_bytes(path.read_bytes()[:-100])
    elif case == "unknown label":
        write_signal_table(rows() + rows("rig-2", "cracked"), path)
    elif case == "simulated source":
        write_signal_table(rows() + [dict(r, source="simulated") for r in rows("rig-2")], path)
    with pytest.raises(SignalTableError) as error:
        read(path, on_bad_record="skip")
    assert message in str(error.value) and str(path) in str(error.value)


def test_a_good_table_skips_nothing_and_bad_settings_are_refused(tmp_path):
    path = tmp_path / "rig.parquet"
    write_signal_table(rows() + rows("rig-2", "missing_tooth"), path)
    frame, skipped = read_user_table_checked(
        path, ["healthy", "missing_tooth"], CHANNELS, FS, SEGMENT, on_bad_record="skip"
    )
    assert len(frame) == 8 and skipped.empty
    with pytest.raises(ValueError, match="on_bad_record"):
        read(path, on_bad_record="ignore")

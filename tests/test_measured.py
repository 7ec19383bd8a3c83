"""A user's measured signal table: every bad input stops ingestion, naming the file and reason."""
import numpy as np
import pandas as pd
import pytest

from condmon.measured import read_user_table
from condmon.signals import SignalTableError, make_rows, write_signal_table

CHANNELS = ["A1_x", "A1_y"]
FS, SEGMENT = 5120.0, 0.25


def rows(record="rig-1", health="healthy", n=1280, signal=None):
    rng = np.random.default_rng(0)
    channels = {c: rng.normal(size=2 * n) if signal is None else signal for c in CHANNELS}
    return make_rows(record, "measured", health, 775.0, 10.0, FS, channels, segment_length=n)


def read(path, **overrides):
    args = dict(health_states=["healthy", "missing_tooth"], channels=CHANNELS, fs_hz=FS, segment_seconds=SEGMENT)
    args.update(overrides)
    return read_user_table(path, **args)


def test_a_good_table_is_read(tmp_path):
    path = tmp_path / "rig.parquet"
    write_signal_table(rows() + rows("rig-2", "missing_tooth"), path)
    frame = read(path)
    assert set(frame["record_id"]) == {"rig-1", "rig-2"} and len(frame) == 8


@pytest.mark.parametrize("case, message", [
    ("missing file", "no such signal table"),
    ("not parquet", "not a readable Parquet file"),
    ("truncated", "not a readable Parquet file"),
    ("unknown label", "health states ['cracked']"),
    ("missing channel", "channels ['A1_y']"),
    ("other rate", "sampling rate [12000.0] Hz"),
    ("short segments", "segments have [640] samples"),
    ("dead sensor", "record 'rig-1' channel 'A1_x' is constant"),
    ("nan", "non-finite samples"),
    ("simulated source", "source ['simulated']"),
])
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
        write_signal_table([dict(r, signal=np.zeros(1280, np.float32)) if r["channel"] == "A1_x" else r
                            for r in good], path)
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

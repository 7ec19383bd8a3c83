"""Atomic writes: no half-written file under an output's name, and no temporary file left after
SIGTERM; stale temporary files of a SIGKILLed attempt are removed by the next write."""

import signal
import subprocess
import sys

from condmon.atomic import write_text


def test_stale_temporary_files_of_a_killed_attempt_are_removed(tmp_path):
    target = tmp_path / "table.parquet"
    stale = tmp_path / ".table.parquet.tmp12345"
    stale.write_text("half a table")
    other = tmp_path / ".other.parquet.tmp12345"
    other.write_text("another output's attempt")
    write_text("done", target)
    assert target.read_text() == "done"
    assert not stale.exists() and other.exists()


def test_sigterm_mid_write_leaves_neither_output_nor_temporary_file(tmp_path):
    script = f"""
import sys, time
from types import SimpleNamespace
from condmon.atomic import temporary_path
from condmon.runlog import setup_logging
setup_logging(SimpleNamespace(log=[], rule="demo"))
with temporary_path({str(tmp_path / "out.txt")!r}) as tmp:
    tmp.write_text("partial")
    print("writing", flush=True)
    time.sleep(30)
"""
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "writing"
    process.send_signal(signal.SIGTERM)
    assert process.wait(timeout=10) == 128 + signal.SIGTERM
    assert list(tmp_path.iterdir()) == []

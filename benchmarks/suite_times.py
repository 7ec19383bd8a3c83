"""Time the whole test suite as CI runs it: the README's test command without its install step
(COMMAND, `python3 -m pytest -q --durations=25`; tests/test_readme.py keeps the two alike) in
this checkout, and record its wall and CPU seconds (pytest and every process it waited for), the
outcomes and the time per test file (tests/conftest.py writes them where CONDMON_TEST_TIMES
points). The record names the cores and the load average at the start and the end: a suite
timed on a shared machine says so.

    python3 benchmarks/suite_times.py [--name default] [-- more pytest arguments]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "workflow")]  # condmon
from condmon.records import save_record  # noqa: E402

COMMAND = ["python3", "-m", "pytest", "-q", "--durations=25"]


def cpu_seconds() -> float:
    """User and system seconds of the processes this one has waited for, theirs included."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def time_suite(extra: list[str]) -> dict:
    """Run the suite (COMMAND and `extra`) in the project folder; its figures."""
    with tempfile.TemporaryDirectory() as folder:
        times = Path(folder) / "times.json"
        load, cpu, start = os.getloadavg(), cpu_seconds(), time.monotonic()
        result = subprocess.run(
            [sys.executable, *COMMAND[1:], *extra],
            cwd=ROOT,
            env={**os.environ, "CONDMON_TEST_TIMES": str(times)},
        )
        wall, cpu = time.monotonic() - start, cpu_seconds() - cpu
        found = json.loads(times.read_text()) if times.exists() else {"outcomes": {}, "files": {}}
    return {
        "command": " ".join(COMMAND + extra),
        "returncode": result.returncode,
        "wall_seconds": round(wall, 1),
        "cpu_seconds": round(cpu, 1),
        "tests": sum(found["outcomes"].values()),
        "outcomes": found["outcomes"],
        "machine": {
            "cores": os.cpu_count(),
            "load_average_at_start": [round(x, 2) for x in load],
            "load_average_at_end": [round(x, 2) for x in os.getloadavg()],
        },
        "files": found["files"],
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--name", default="default", help="the record's name")
    parser.add_argument("extra", nargs="*", help="more pytest arguments (after --)")
    args = parser.parse_args(argv)
    figures = time_suite(args.extra)
    print(
        f"{figures['tests']} tests in {figures['wall_seconds']:.0f} s "
        f"({figures['cpu_seconds']:.0f} CPU-seconds), exit code {figures['returncode']}"
    )
    save_record("suite_times", args.name, figures, script=__file__, argv=argv)
    return figures["returncode"]


if __name__ == "__main__":
    sys.exit(main())

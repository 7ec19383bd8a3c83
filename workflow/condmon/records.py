"""Benchmark records: the small JSON file every benchmark in `benchmarks/` writes beside its own
output, committed under `benchmarks/records/`, so that each figure the docs give can be traced to
the command, commit, config and machine that produced it (benchmarks/render_results.py renders
docs/results.md and the README's table from them).

A record is one JSON object:
    benchmark    the script's name (`bench_seeds`, `throughput`, ...)
    name         which run of it (a script's `--name`, a results folder, ...): with the benchmark,
                 the file name `<benchmark>-<name>.json`; a rerun replaces it (git keeps the old)
    command      the command line as run from the project folder
    commit       the git commit of the checkout when the benchmark started (this module's
                 import), `+dirty` where tracked files had changes then
    configfiles  the config files the figures depend on, and config_hash: a hash of their text
    machine      cpu_count, cpu (the model name), python
    date         the day it was written (UTC, ISO)
    figures      the benchmark's own figures (JSON)
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import platform
import re
import shlex
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the project folder (workflow/condmon/records.py)
RECORDS_DIR = ROOT / "benchmarks" / "records"


def git_commit(root: Path = ROOT) -> str:
    """The checkout's commit, `+dirty` where tracked files differ from it; `unknown` outside git."""

    def git(*args):
        return subprocess.run(["git", *args], cwd=root, capture_output=True, text=True)

    head = git("rev-parse", "HEAD")
    if head.returncode:
        return "unknown"
    dirty = git("status", "--porcelain", "--untracked-files=no").stdout.strip()
    return head.stdout.strip() + ("+dirty" if dirty else "")


# taken at import, as the benchmark starts: files edited while a long benchmark runs are not
# what it measured
COMMIT_AT_START = git_commit()


def config_hash(paths, root: Path = ROOT) -> str | None:
    """Hash (16 hex digits) of the config files' text in the given order (the order they layer
    in); None for a benchmark that reads no config."""
    if not paths:
        return None
    digest = hashlib.sha256()
    for path in paths:
        digest.update(str(path).encode() + b"\0" + (root / path).read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def cpu_model(cpuinfo: str) -> str:
    """The processor's model name from /proc/cpuinfo's text (platform's guess without it)."""
    found = re.search(r"^model name\s*:\s*(.*)$", cpuinfo, re.MULTILINE)
    return found.group(1).strip() if found else (platform.processor() or "unknown")


def machine() -> dict:
    """What the figures were measured on: core count, processor model, Python version."""
    info = Path("/proc/cpuinfo")
    return {
        "cpu_count": os.cpu_count(),
        "cpu": cpu_model(info.read_text() if info.exists() else ""),
        "python": platform.python_version(),
    }


def command_line(script: str, argv=None) -> str:
    """The command as a user types it in the project folder: `python3 <script relative> <args>`."""
    path = Path(script).resolve()
    shown = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
    return shlex.join(["python3", str(shown), *(sys.argv[1:] if argv is None else argv)])


def make_record(
    benchmark: str,
    name: str,
    figures,
    *,
    script: str,
    argv=None,
    configfiles=(),
    root: Path = ROOT,
    date: str | None = None,
) -> dict:
    """A record of `figures` (module docstring); `argv`: the script's arguments (default sys.argv's)."""
    configfiles = [str(p) for p in configfiles]
    now = datetime.datetime.now(datetime.timezone.utc)
    return {
        "benchmark": benchmark,
        "name": name,
        "command": command_line(script, argv),
        "commit": COMMIT_AT_START if root == ROOT else git_commit(root),
        "configfiles": configfiles,
        "config_hash": config_hash(configfiles, root),
        "machine": machine(),
        "date": date or now.date().isoformat(),
        # UTC, so records of one day read in the order they were made (older ones have none)
        "time": None if date else now.strftime("%H:%M:%S"),
        "figures": figures,
    }


def record_path(record: dict, directory: Path = RECORDS_DIR) -> Path:
    """`<directory>/<benchmark>-<name>.json`, the name made safe for a file name."""
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", str(record["name"])).strip("_") or "default"
    return Path(directory) / f"{record['benchmark']}-{name}.json"


def write_record(record: dict, directory: Path | None = None) -> Path:
    """Write `record` to `directory` (default RECORDS_DIR) in a stable key order, so a rerun's
    diff shows what changed; its path."""
    path = record_path(record, directory or RECORDS_DIR)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=1, sort_keys=True, default=float) + "\n")
    print(f"wrote the record {path}")
    return path


def save_record(
    benchmark: str, name: str, figures, *, script: str, argv=None, configfiles=()
) -> Path:
    """Make and write a record (`make_record`, `write_record`): the call a benchmark ends with."""
    return write_record(
        make_record(benchmark, name, figures, script=script, argv=argv, configfiles=configfiles)
    )


def run_configfiles(run: Path) -> list[str]:
    """The config a finished run ran with (its report/config.yaml, defaults filled in), for the
    record of a benchmark that reads the run's results; [] where the run has no report yet."""
    path = Path(run) / "report" / "config.yaml"
    return [str(path)] if path.exists() else []


def read_records(directory: Path | None = None) -> list[dict]:
    """Every record in `directory` (default RECORDS_DIR), oldest first: by date and time (a
    record without a time, made before records had one, first of its day), then file name."""
    paths = sorted(Path(directory or RECORDS_DIR).glob("*.json"))
    records = [json.loads(p.read_text()) for p in paths]
    return sorted(records, key=lambda r: (r["date"], r.get("time") or ""))

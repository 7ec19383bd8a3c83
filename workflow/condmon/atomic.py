"""Atomic file writes: a temporary file in the same folder, then a rename, so a job killed
mid-write never leaves a file that a later stage could take as complete."""

from __future__ import annotations

import json
import os
import shutil
from contextlib import contextmanager
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq


@contextmanager
def temporary_path(path):
    """Yield a temporary path beside `path`; renamed to `path` when the block succeeds.

    Temporary files of earlier attempts at `path` (a job killed by SIGKILL cannot clean up)
    are removed first; they are hidden and never named like an output."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    for stale in path.parent.glob(f".{path.name}.tmp*"):
        if stale.is_file():
            stale.unlink(missing_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text(text: str, path) -> None:
    with temporary_path(path) as tmp:
        tmp.write_text(text)


def write_json(data, path) -> None:
    write_text(json.dumps(data, indent=2, sort_keys=True, default=str) + "\n", path)


def write_table(table: pa.Table, path) -> None:
    """A pyarrow table as zstd-compressed Parquet."""
    with temporary_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def write_frame(frame: pd.DataFrame, path) -> None:
    write_table(pa.Table.from_pandas(frame, preserve_index=False), path)


@contextmanager
def staging_directory(target):
    """Yield an empty folder beside `target`; it replaces `target` whole when the block
    succeeds (so no stale file of an earlier run lingers) and is removed otherwise."""
    target = Path(target)
    staging = target.with_name(f".{target.name}.tmp{os.getpid()}")
    shutil.rmtree(staging, ignore_errors=True)
    staging.mkdir(parents=True)
    try:
        yield staging
        if target.exists():
            shutil.rmtree(target)
        os.replace(staging, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)

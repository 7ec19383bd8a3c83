"""Reproducible random streams from the config seed and a job's wildcards, never the clock."""

from __future__ import annotations

import zlib

import numpy as np


def stable_int(*parts) -> int:
    """A process-independent integer of strings/numbers (Python's hash() is salted per process)."""
    return zlib.crc32("|".join(str(p) for p in parts).encode())


def derive_seed(seed: int, *keys: int) -> int:
    """A 32-bit seed from the config seed and stable integer keys (e.g. percent, repeat)."""
    return int(np.random.SeedSequence([int(seed), *map(int, keys)]).generate_state(1)[0])


def job_rng(seed: int, *parts) -> np.random.Generator:
    """An independent, reproducible stream for one job: (seed, stable_int(parts))."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), stable_int(*parts)]))

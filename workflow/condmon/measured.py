"""Measured stage: the virtual bench, or a user's own signal table, into one signal table."""
from __future__ import annotations

import logging
import time

import numpy as np
import pandas as pd

from condmon.gear_model import build_parameters, simulation_settings
from condmon.seeds import job_rng
from condmon.signals import SignalTableError, make_rows, read_signal_table
from models.virtual_bench import bench_record

log = logging.getLogger(__name__)


def virtual_bench_rows(model: dict, bench: dict, health_states, speeds_rpm, numerics: dict,
                       segment_seconds: float) -> list[dict]:
    """Records of the virtual bench: `records_per_state` acquisitions per health state and speed,
    each `record_seconds` long, cut into segments. Source is always `virtual_bench`."""
    true = dict(bench["true_parameters"])
    effects = {k: bench[k] for k in ("speed_fluctuation", "speed_fluctuation_hz")}
    effects["runout_pinion"] = effects["runout_gear"] = bench["runout"]
    settings = simulation_settings(numerics, duration=bench["record_seconds"])
    segment_length = int(round(segment_seconds * settings.output_rate))
    rows = []
    for health_state in health_states:
        for speed in speeds_rpm:
            rng = job_rng(bench["seed"], "virtual_bench", health_state, float(speed))
            params = build_parameters(model, speed_rpm=float(speed), health_state=health_state, **true, **effects)
            for k in range(bench["records_per_state"]):
                start = time.perf_counter()
                signals = bench_record(params, settings, bench["sensor_noise"], rng)
                log.info("virtual bench %s %s rpm record %d: %.1f s", health_state, speed, k,
                         time.perf_counter() - start)
                rows += make_rows(f"vb-{health_state}-{speed:g}rpm-r{k:02d}", "virtual_bench", health_state,
                                  speed, params.load_torque, settings.output_rate, signals,
                                  segment_length=segment_length)
    return rows


def read_user_table(path, health_states, channels, fs_hz: float, segment_seconds: float) -> pd.DataFrame:
    """A user's measured signal table, checked against the run's labels, channels, sampling rate
    and segment length (simulated segments have that length; features must compare alike)."""
    frame = read_signal_table(path, allowed_sources=("measured",))
    unknown = sorted(set(frame["health_state"]) - set(health_states))
    if unknown:
        raise SignalTableError(f"{path}: health states {unknown} are not in the config's "
                               f"health_states {list(health_states)}")
    missing = sorted(set(channels) - set(frame["channel"]))
    if missing:
        raise SignalTableError(f"{path}: channels {missing} used by the features are missing")
    rates = sorted(set(frame["fs_hz"]))
    if rates != [float(fs_hz)]:
        raise SignalTableError(f"{path}: sampling rate {rates} Hz differs from the config's "
                               f"output_rate_hz {fs_hz} Hz")
    samples = int(round(segment_seconds * fs_hz))
    lengths = sorted({len(s) for s in frame["signal"]})
    if lengths != [samples]:
        raise SignalTableError(f"{path}: segments have {lengths} samples; rig.segment_seconds = "
                               f"{segment_seconds} s at {fs_hz} Hz needs {samples}: cut the records to that length")
    for record_id, rows in frame.groupby("record_id"):
        for channel, signals in rows.groupby("channel"):
            if max(float(np.ptp(s)) for s in signals["signal"]) == 0.0:
                raise SignalTableError(f"{path}: record {record_id!r} channel {channel!r} is constant "
                                       "(dead sensor)")
    return frame

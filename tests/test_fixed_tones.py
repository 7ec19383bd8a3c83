"""Fixed tones (systems/gear/fixed_tones.py): a line at one frequency at every speed is found, a
shaft's own lines are not; a tone is removed where a synchronous average would keep it, and then a
healthy record's residual against a reference with the tone at another phase is noise again."""

import numpy as np
import pandas as pd

from condmon.features import FamilyInputs
from condmon.systems.gear import fixed_tones as ft
from condmon.systems.gear import residual_features as rf

FS = 5120.0
PINION, GEAR = 29, 44
SHAFTS = [("pinion", 1.0, PINION), ("gear", PINION / GEAR, GEAR)]


def record(
    speed_rpm: float,
    seconds: float,
    rng,
    tone_hz=120.0,
    tone=0.02,
    phase=None,
    noise=1e-3,
    channels=2,
):
    """Channels of a gear pair's mesh line and shaft order 3 (moving with the speed), a fixed tone
    (its phase `phase`, else random) and white noise: (channels, n)."""
    t = np.arange(int(seconds * FS)) / FS
    shaft_hz = speed_rpm / 60.0
    phase = rng.uniform(0, 2 * np.pi) if phase is None else phase
    x = (
        0.05 * np.cos(2 * np.pi * PINION * shaft_hz * t)
        + 0.01 * np.cos(2 * np.pi * 3 * shaft_hz * t + 1.0)
        + tone * np.cos(2 * np.pi * tone_hz * t + phase)
    )
    return np.stack([x * (1 + 0.3 * c) + rng.normal(0, noise, t.shape) for c in range(channels)])


def test_a_line_at_one_frequency_at_every_speed_is_a_fixed_tone_and_the_shafts_lines_are_not():
    rng = np.random.default_rng(0)
    by_speed = {
        speed: np.stack([record(speed, 3.0, rng) for _ in range(2)])
        for speed in (450.0, 775.0, 1100.0)
    }
    tones = ft.fixed_tones(by_speed, FS)
    assert len(tones) == 1 and abs(tones[0] - 120.0) < 0.02
    lines, _ = ft.spectrum_lines(by_speed[450.0], FS)
    assert np.min(np.abs(lines - PINION * 7.5)) < 0.05  # the mesh line is a line, only at its speed
    # one speed: a fixed tone cannot be told from a shaft order
    assert ft.fixed_tones({450.0: by_speed[450.0]}, FS) == []
    # a line at one speed only, or far weaker at another, is no fixed tone
    weaker = {**by_speed, 775.0: np.stack([record(775.0, 3.0, rng, tone=0.002) for _ in range(2)])}
    assert ft.fixed_tones(weaker, FS) == []
    elsewhere = {
        **by_speed,
        775.0: np.stack([record(775.0, 3.0, rng, tone_hz=100.0) for _ in range(2)]),
    }
    assert ft.fixed_tones(elsewhere, FS) == []


def test_a_tone_is_removed_where_the_average_keeps_it_and_left_where_it_falls_between_orders():
    # 120 Hz is order 16 of a 450 rpm pinion; at 775 rpm it falls between the orders of both shafts
    assert ft.kept_by_the_average(120.0, 450.0, 3.0, SHAFTS)
    assert not ft.kept_by_the_average(120.0, 775.0, 3.0, SHAFTS)
    rng = np.random.default_rng(1)
    x = record(450.0, 3.0, rng, noise=0.0)
    cleaned, removed = ft.remove_fixed_tones(x, FS, 450.0, SHAFTS, [120.0])
    assert removed == [120.0]
    without = record(450.0, 3.0, np.random.default_rng(1), tone=0.0, noise=0.0)
    # what is left is the record without its tone, less its own content at that one order
    assert np.sqrt(np.mean((cleaned - without) ** 2)) < 0.02 * 0.02
    same, removed = ft.remove_fixed_tones(x, FS, 775.0, SHAFTS, [120.0])
    assert removed == [] and same is x


def signal_rows(record_id, health, speed, segment, x, source="virtual_bench"):
    return [
        {
            "record_id": record_id,
            "segment": segment,
            "source": source,
            "health_state": health,
            "speed_rpm": speed,
            "load": 10.0,
            "fs_hz": FS,
            "channel": channel,
            "signal": x[c].astype(np.float32),
            "params": "",
        }
        for c, channel in enumerate(("A1_x", "A1_y"))
    ]


PARAMS = {
    "shafts": [list(s) for s in SHAFTS],
    "samples_per_revolution": 1024,
    "bands_per_mesh": 4,
    "mesh_harmonics": 3,
    "shaft_orders": 2,
    "phase_harmonic": 1,
    "phase_band_orders": 0.3,
    "phase_min_snr": 5.0,
}
CHANNELS = ["A1_x", "A1_y"]
# the residual's RMS over the reference's (log10): 120 Hz at 450 rpm is order 16 of the pinion
BAND = "res_A1_x_pinion_rms_ratio"
SECONDS = 1.5  # a segment: 11 pinion revolutions at 450 rpm


def bench(speeds, rng):
    """Per speed a calibration record (two segments, the tone at one phase) and a healthy test
    record (the tone at another phase)."""
    rows = []
    for speed in speeds:
        for segment in range(2):
            rows += signal_rows(
                f"vb-healthy-{speed:g}rpm-r00",
                "healthy",
                speed,
                segment,
                record(speed, SECONDS, rng, phase=0.3),
            )
        rows += signal_rows(
            f"vb-healthy-{speed:g}rpm-r01",
            "healthy",
            speed,
            0,
            record(speed, SECONDS, rng, phase=2.9),
        )
    return pd.DataFrame(rows)


def test_a_healthy_record_whose_tone_has_another_phase_stays_healthy_and_the_tones_are_packaged():
    """At 450 rpm a 120 Hz tone with a phase of its own in each record: with one speed it cannot
    be told from a shaft order and the healthy test record's residual carries it; with a second
    speed it is found and removed. The references table lists it, and a packaged model and a
    simulated run (given the measured references) remove it too."""
    spec = {
        "source": "measured",
        "healthy_state": "healthy",
        "condition": "speed_rpm",
        "reserve": {},
    }
    written = rf.residual_feature_table(
        bench([450.0, 775.0], np.random.default_rng(2)),
        CHANNELS,
        PARAMS,
        FamilyInputs(healthy_reference=spec),
    )
    references = written.attrs["references"]
    assert np.allclose(rf.tones_from_table(references), [120.0], atol=0.05)
    one_speed = rf.residual_feature_table(
        bench([450.0], np.random.default_rng(2)),
        CHANNELS,
        PARAMS,
        FamilyInputs(healthy_reference=spec),
    )
    assert rf.tones_from_table(one_speed.attrs["references"]) == []
    test = "vb-healthy-450rpm-r01"
    assert (
        one_speed.set_index("record_id").at[test, BAND]
        > written.set_index("record_id").at[test, BAND] + 1.0
    )  # 2 sin(1.3) x 0.02 m/s^2 against noise
    # a packaged model's copy removes the same tone
    frame = bench([450.0, 775.0], np.random.default_rng(2))
    packaged = rf.residual_feature_table(
        frame, CHANNELS, PARAMS, FamilyInputs(packaged_references=references.to_dict("list"))
    )
    names = written.attrs["referenced_columns"]
    np.testing.assert_allclose(packaged[names].to_numpy(), written[names].to_numpy(), atol=1e-5)
    # a simulated healthy sample (segment 0) against its twin (segments 1, 2), its tone at another phase
    rng = np.random.default_rng(3)
    machine = "sim-healthy-450rpm-b000-s000"
    rows = signal_rows(
        machine, "healthy", 450.0, 0, record(450.0, SECONDS, rng, phase=2.9), "simulated"
    )
    for segment in (1, 2):
        rows += signal_rows(
            machine, "healthy", 450.0, segment, record(450.0, SECONDS, rng, phase=0.3), "simulated"
        )
    twins = {"source": "simulated", "healthy_state": "healthy", "segments_per_sample": 1}
    simulated = pd.DataFrame(rows)
    removed = rf.residual_feature_table(
        simulated,
        CHANNELS,
        PARAMS,
        FamilyInputs(healthy_reference=twins, measured_references=references),
    )
    left = rf.residual_feature_table(
        simulated, CHANNELS, PARAMS, FamilyInputs(healthy_reference=twins)
    )
    assert left.at[0, BAND] > removed.at[0, BAND] + 1.0

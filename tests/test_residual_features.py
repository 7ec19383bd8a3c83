"""Residual signatures (systems/gear/residual_features.py): alignment, the shafts kept apart, a
localised fault on its own teeth, a healthy twin pair within noise, the family in the features
job and in a packaged model."""

import numpy as np
import pandas as pd
import pytest

from condmon.features import FamilyInputs, FeatureTableError
from condmon.report.shaft_tracking import record_tracking
from condmon.systems.gear import residual_features as rf

P = 1024
PINION, GEAR = 29, 44
SHAFTS = [("pinion", 1.0, PINION), ("gear", PINION / GEAR, GEAR)]
# the family's settings as the gear system gives them (`residual_settings`), for these shafts
SETTINGS = {
    "shafts": [list(s) for s in SHAFTS],
    "samples_per_revolution": P,
    "bands_per_mesh": 4,
    "mesh_harmonics": 3,
    "shaft_orders": 2,
    "phase_harmonic": 1,
    "phase_band_orders": 0.3,
    "phase_min_snr": 5.0,
}


def pitch_pattern(
    teeth: int, rng, mesh_amplitude: float = 1.0, pitch_rms: float = 0.2
) -> np.ndarray:
    """One revolution of a gear's synchronous pattern: mesh harmonics plus a random pitch pattern
    (a different small offset of every tooth's mesh pulse) and an eccentricity."""
    angle = np.arange(P) / P
    phase = np.repeat(rng.normal(0.0, pitch_rms, teeth), P // teeth + 1)[:P]
    mesh = sum(
        mesh_amplitude / h * np.cos(2 * np.pi * h * teeth * angle + h * phase) for h in (1, 2, 3)
    )
    return mesh + 0.3 * np.cos(2 * np.pi * angle + rng.uniform(0, 2 * np.pi))


def tooth_bump(teeth: int, tooth: int, depth: float) -> np.ndarray:
    """A local event on one tooth: a short Gaussian dip centred on that tooth's pitch."""
    angle = np.arange(P) / P
    centre = (tooth + 0.5) / teeth
    distance = (angle - centre + 0.5) % 1.0 - 0.5
    return -depth * np.exp(-0.5 * (distance * teeth / 0.15) ** 2)


def in_time(
    patterns, fs_hz: float, speed_rpm: float, seconds: float, start=(0.0, 0.0), noise=0.0, rng=None
):
    """A one-channel record of the shafts' patterns at a constant speed, each shaft starting at
    its own angle, plus white noise: (1, n), input-shaft angle."""
    t = np.arange(int(seconds * fs_hz)) / fs_hz
    angle = speed_rpm / 60.0 * t
    x = sum(
        rf.pattern_at(p[None, :], angle * ratio + s0)[0]
        for p, (_, ratio, _), s0 in zip(patterns, SHAFTS, start)
    )
    if noise:
        x = x + rng.normal(0.0, noise, x.shape)
    return x[None, :], angle


def test_a_pattern_read_at_any_angles_is_its_dft_interpolant():
    """pattern_at reads the pattern's DFT interpolant at any angles, also below 0 and past a turn
    (within 0.5 % of its scale for a pitch pattern's broad spectrum), and the angles' interpolation points found once give the same numbers
    as the angles (what shaft_patterns reuses over its iterations), as np.interp would."""
    rng = np.random.default_rng(4)
    pattern = np.stack([pitch_pattern(PINION, rng), pitch_pattern(PINION, rng)])
    angle = np.concatenate([[-1e-17, -0.3, 0.0, 1.0], rng.uniform(-2.0, 5.0, 500)])
    spectrum = np.fft.rfft(pattern, axis=-1)
    orders = np.arange(spectrum.shape[-1])
    weights = np.where((orders == 0) | (orders == P // 2), 1.0, 2.0) / P
    exact = np.real(
        (spectrum * weights) @ np.exp(2j * np.pi * orders[:, None] * np.mod(angle, 1.0)[None, :])
    )
    read = rf.pattern_at(pattern, angle)
    assert np.abs(read - exact).max() < 5e-3 * np.abs(pattern).max()
    points = rf.interpolation_points(angle, P)
    assert np.array_equal(rf.pattern_at(pattern, points=points), read)
    fine = rf.PATTERN_UPSAMPLING
    upsampled = np.fft.irfft(spectrum, n=P * fine, axis=-1) * fine
    wrapped = np.concatenate([upsampled, upsampled[..., :1]], axis=-1)
    grid = np.arange(P * fine + 1) / fine
    position = np.mod(angle, 1.0) * P
    assert np.array_equal(read, np.stack([np.interp(position, grid, c) for c in wrapped]))


def test_a_record_against_itself_shifted_by_whole_teeth_leaves_no_residual():
    rng = np.random.default_rng(1)
    pattern = np.stack([pitch_pattern(PINION, rng), pitch_pattern(PINION, rng)])  # two channels
    for teeth_shift in (1, 7, 20):
        moved = np.roll(pattern, teeth_shift * P // PINION + 3, axis=-1)
        features = rf.residual_features(moved, pattern, PINION, PINION / 4, 12)
        assert np.all(features["rms_ratio"] < 1e-3), teeth_shift
    # a fractional shift too (the DFT's shift theorem)
    features = rf.residual_features(rf.shifted(pattern, 12.37), pattern, PINION, PINION / 4, 12)
    assert np.all(features["rms_ratio"] < 1e-3)
    # without alignment, half a tooth off, the same record would leave a residual as large as itself
    assert np.sqrt(np.mean((np.roll(pattern, 17, axis=-1) - pattern) ** 2)) > 0.5 * pattern.std()


def noise_above(order: int, rms: float, rng) -> np.ndarray:
    """One revolution of random content at the orders above `order` only."""
    spectrum = np.zeros(P // 2 + 1, complex)
    spectrum[order + 1 :] = rng.normal(size=P // 2 - order) + 1j * rng.normal(size=P // 2 - order)
    x = np.fft.irfft(spectrum, n=P)
    return rms * x / x.std()


def test_the_alignment_reads_the_orders_the_bands_hold():
    """A short record at a low speed: above the bands' orders more noise than pattern. On every
    order the correlation picks a wrong whole-tooth shift; on the bands' orders the right one."""
    top = rf.top_band_order(PINION / 4, 12)
    assert top == 87  # bands of 7.25 orders from order 0.5: 12 of them end at 87.5
    true_shift = 7 * P // PINION + 3
    wrong_on_every_order = 0
    for seed in range(5):
        rng = np.random.default_rng(seed)
        pattern = pitch_pattern(PINION, rng)[None, :]
        record = np.roll(pattern, true_shift, axis=-1) + noise_above(top, 2 * pattern.std(), rng)
        reference = pattern + noise_above(top, 2 * pattern.std(), rng)
        found = rf.alignment_shift(record, reference, PINION, top) % P
        assert abs(found - true_shift) < 1, seed
        wrong_on_every_order += (
            abs(rf.alignment_shift(record, reference, PINION) % P - true_shift) > P / PINION / 2
        )
    assert wrong_on_every_order >= 4


def test_bands_without_mesh_lines_follow_the_path_not_the_mesh_lines_size():
    """reference_level without_mesh_lines: the same residual over a reference whose mesh lines are
    four times stronger (a stiffer or more loaded mesh, the same path) keeps its bands; over
    the whole level (the default) the bands holding a mesh line fall. A path twice as strong
    scales residual and reference alike: the bands stay in both."""
    rng = np.random.default_rng(5)
    reference = pitch_pattern(PINION, rng)[None, :]
    angle = np.arange(P) / P
    mesh = sum(np.cos(2 * np.pi * h * PINION * angle) / h for h in (1, 2, 3))[None, :]
    pitted = reference + tooth_bump(PINION, 4, 0.05)

    def bands(pattern, ref, level):
        found = rf.residual_features(pattern, ref, PINION, PINION / 4, 12, reference_level=level)
        return np.array([found[name][0] for name in rf.band_names(12)])

    for level in rf.REFERENCE_LEVELS:
        doubled = bands(2 * pitted, 2 * reference, level)
        assert np.allclose(doubled, bands(pitted, reference, level), rtol=1e-6), level
    stronger_mesh = reference + 3 * mesh
    kept = bands(pitted + 3 * mesh, stronger_mesh, "without_mesh_lines")
    # (within the alignment's refinement, which the stronger lines move slightly)
    assert np.allclose(kept, bands(pitted, reference, "without_mesh_lines"), rtol=0.03)
    whole = bands(pitted + 3 * mesh, stronger_mesh, "whole") / bands(pitted, reference, "whole")
    assert np.all(whole[[3, 7, 11]] < 0.5)  # the bands holding mesh orders 29, 58, 87


def test_an_unknown_reference_level_names_the_key():
    with pytest.raises(FeatureTableError, match="reference_level"):
        rf.residual_feature_table(
            pd.DataFrame(),
            ["A1_x"],
            dict(
                shafts=SHAFTS,
                samples_per_revolution=P,
                bands_per_mesh=4,
                mesh_harmonics=3,
                shaft_orders=2,
                phase_harmonic=1,
                phase_band_orders=0.3,
                phase_min_snr=5.0,
                reference_level="median",
            ),
            FamilyInputs(healthy_reference={"source": "measured"}),
        )


def test_a_pit_on_one_tooth_shows_in_that_teeths_residual_energy():
    rng = np.random.default_rng(2)
    healthy = pitch_pattern(PINION, rng)[None, :]
    tooth = 11
    pitted = healthy + tooth_bump(PINION, tooth, 0.1)
    found = rf.residual_features(np.roll(pitted, 200, axis=-1), healthy, PINION, PINION / 4, 12)
    same = rf.residual_features(
        np.roll(healthy, 200, axis=-1) + rng.normal(0, 1e-3, P), healthy, PINION, PINION / 4, 12
    )
    assert found["tooth_peak1"][0] > 10 * same["tooth_peak1"][0]
    # the largest one-tooth energy of the residual sits on that tooth
    residual = rf.aligned(np.roll(pitted, 200, axis=-1), healthy, PINION) - healthy
    local = rf.residual_signal(residual, PINION, 2, 3)[0]
    window = P // PINION
    energy = [np.sum(local[k * window : (k + 1) * window] ** 2) for k in range(PINION)]
    assert int(np.argmax(energy)) == tooth


def test_the_shafts_kept_apart_in_a_record_shorter_than_the_hunting_cycle():
    """11 of the 44 pinion revolutions of the hunting cycle (1.5 s at 450 rpm): the plain TSA keeps
    much of the gear's pattern, the joint estimate little of it."""
    rng = np.random.default_rng(3)
    pinion, gear = (
        pitch_pattern(PINION, rng),
        rf.without_orders(pitch_pattern(GEAR, rng, 2.0, 0.4)[None, :], GEAR)[0],
    )
    fs, speed = 5120.0, 450.0
    x, angle = in_time([pinion, gear], fs, speed, 1.5, start=(0.0, 0.37))
    plain = rf.synchronous_average(x, angle, P)[0]
    joint = rf.shaft_patterns(x, angle, SHAFTS, P)[0][0]
    truth = pinion - pinion.mean()
    plain_error = np.sqrt(np.mean((plain - plain.mean() - truth) ** 2))
    joint_error = np.sqrt(np.mean((joint - truth) ** 2))
    assert joint_error < 0.2 * plain_error


def test_a_healthy_twin_pair_lies_within_noise_and_a_pitted_twin_does_not():
    """Two records of one machine (other start angles, other noise): the residual of one against
    the other is the noise's; the same machine with a pit on three teeth stands out."""
    rng = np.random.default_rng(4)
    pinion, gear = (
        pitch_pattern(PINION, rng),
        rf.without_orders(pitch_pattern(GEAR, rng)[None, :], GEAR)[0],
    )
    fs, speed, noise = 5120.0, 775.0, 0.1
    pitted = pinion + sum(tooth_bump(PINION, k, 0.5) for k in (5, 6, 7))

    def patterns(pinion_pattern, start):
        x, angle = in_time(
            [pinion_pattern, gear], fs, speed, 1.5, start=start, noise=noise, rng=rng
        )
        return rf.shaft_patterns(x, angle, SHAFTS, P)

    reference = patterns(pinion, (0.1, 0.2))
    twins = [
        rf.residual_features(
            patterns(pinion, (rng.uniform(), rng.uniform()))[0],
            reference[0],
            PINION,
            PINION / 4,
            12,
        )
        for _ in range(4)
    ]
    damaged = rf.residual_features(
        patterns(pitted, (0.6, 0.9))[0], reference[0], PINION, PINION / 4, 12
    )
    # the noise left in two averages of 19 revolutions each, over the pattern's RMS
    expected = noise * np.sqrt(2 / 19 * fs / (speed / 60 * P)) / reference[0].std()
    for twin in twins:
        assert twin["rms_ratio"][0] < 2.5 * expected
    assert damaged["rms_ratio"][0] > 2 * max(t["rms_ratio"][0] for t in twins)
    assert damaged["tooth_peak3"][0] > 2 * max(t["tooth_peak3"][0] for t in twins)


def test_the_cnns_input_carries_no_machines_healthy_pattern():
    """The CNN ensemble reads the residual bands (`condmon.bands`' RESIDUAL_NAME) and, with
    `side_features`, the size-free indicators beside them: two machines of other gears (other
    pitch patterns), each healthy against its own reference, give it inputs no further apart
    than two records of one machine (noise alone); a pitted one stands out."""
    from condmon.bands import band_pattern

    rng = np.random.default_rng(6)
    fs, speed, noise = 5120.0, 775.0, 0.1
    gear = rf.without_orders(pitch_pattern(GEAR, rng)[None, :], GEAR)[0]

    def bands(pinion_pattern, reference_pattern):
        """The CNN's input (log10 residual bands) of a record against its machine's reference."""
        taken = [
            rf.shaft_patterns(
                *in_time([pattern, gear], fs, speed, 1.5, start=start, noise=noise, rng=rng),
                SHAFTS,
                P,
            )[0]
            for pattern, start in (
                (pinion_pattern, tuple(rng.uniform(size=2))),
                (reference_pattern, tuple(rng.uniform(size=2))),
            )
        ]
        features = rf.residual_features(taken[0], taken[1], PINION, PINION / 4, 12)
        names = {f"res_A1_x_pinion_{key}": key for key in features}
        read = [key for name, key in names.items() if band_pattern(list(names)).fullmatch(name)]
        assert len(read) == 12
        side = rf.kept_features(magnitudes=False)  # the size-free indicators
        return np.log10([features[key][0] for key in read + side])

    first, other = (pitch_pattern(PINION, rng) for _ in range(2))
    pitted = first + sum(tooth_bump(PINION, k, 0.5) for k in (5, 6, 7))
    for read in (slice(0, 12), slice(12, None)):  # the bands, then the side features

        def apart(a, b):
            return np.mean([np.abs(bands(*a)[read] - bands(*b)[read]).mean() for _ in range(4)])

        within = apart((first, first), (first, first))
        between = apart((first, first), (other, other))
        damaged = apart((pitted, first), (first, first))
        assert between < 1.5 * within and damaged > 3 * within


def band_limited_pattern(pattern: np.ndarray, top_order: int) -> np.ndarray:
    """A pattern without its orders above `top_order`: what an anti-aliased sensor records."""
    spectrum = np.fft.rfft(pattern)
    spectrum[top_order + 1 :] = 0.0
    return np.fft.irfft(spectrum, n=pattern.size)


def pair_record(pinion, gear, tooth_gain, fs_hz, speed_rpm, seconds, start, noise, rng):
    """A one-channel record of one gear pair from `start` pinion revolutions into its hunting
    cycle: the pinion's pattern, its mesh pulses scaled by the gear tooth they meet (`tooth_gain`:
    load sharing is each tooth pair's own, so the record is no sum of two shaft patterns), the
    gear's pattern, white noise. (1, n), the input-shaft angle from 0."""
    t = np.arange(int(seconds * fs_hz)) / fs_hz
    angle = speed_rpm / 60.0 * t + start
    gear_angle = angle * PINION / GEAR + 0.37
    x = (
        rf.pattern_at(pinion[None], angle)[0]
        * (1.0 + 0.1 * rf.pattern_at(tooth_gain[None], gear_angle)[0])
        + rf.pattern_at(gear[None], gear_angle)[0]
        + rng.normal(0.0, noise, t.size)
    )
    return x[None], angle - start


def test_against_the_hunting_cycle_a_healthy_segment_leaves_neither_gears_pattern():
    """A healthy record covering the hunting cycle (44 pinion revolutions, 2.4 s at 1100 rpm) and
    segments of half a cycle from elsewhere in it: a segment less the cycle's average where it
    lies in the cycle is the noise, whichever part it covers; against the shafts' separately
    estimated patterns the pairs' own mesh leaves twice that. A pit on one tooth stands out."""
    rng = np.random.default_rng(8)
    pinion = band_limited_pattern(pitch_pattern(PINION, rng), 120)
    gear = band_limited_pattern(
        rf.without_orders(pitch_pattern(GEAR, rng, 2.0, 0.4)[None, :], GEAR)[0], 180
    )
    tooth_gain = band_limited_pattern(np.repeat(rng.normal(0.0, 1.0, GEAR), P // GEAR + 1)[:P], 60)
    fs, speed, noise = 5120.0, 1100.0, 0.01
    assert rf.hunting_revolutions(SHAFTS) == GEAR

    def record(pinion_pattern, seconds, start):
        return pair_record(pinion_pattern, gear, tooth_gain, fs, speed, seconds, start, noise, rng)

    x, angle = record(pinion, 2.45, 0.0)
    cycle = rf.hunting_cycle(x, angle, GEAR, P)
    assert cycle.shape == (1, GEAR * P)
    assert (
        rf.hunting_cycle(x[:, : int(2.3 * fs)], angle[: int(2.3 * fs)], GEAR, P) is None
    )  # less than a cycle
    top = rf.top_band_order(PINION / 4, 12)
    from_cycle = rf.cycle_shaft_patterns(cycle, SHAFTS, GEAR, P)
    truth = (pinion - pinion.mean())[
        None, :
    ]  # the cycle starts half a revolution in: aligned to it
    assert np.std(rf.aligned(from_cycle[0], truth, PINION) - truth) < 0.01 * pinion.std()
    separated = rf.shaft_patterns(x, angle, SHAFTS, P)
    for start in (11.3, 25.0, 37.6):  # pinion revolutions into the cycle
        segment, segment_angle = record(pinion, 1.2, start)
        residual = rf.cycle_residual(segment, segment_angle, cycle, P, PINION, top)
        assert residual.std() < 1.2 * np.sqrt(2) * noise, (
            start
        )  # the segment's noise and the cycle's
        against_cycle = rf.shaft_patterns(residual, segment_angle, SHAFTS, P)[0]
        against_shafts = (
            rf.aligned(
                rf.shaft_patterns(segment, segment_angle, SHAFTS, P)[0], separated[0], PINION, top
            )
            - separated[0]
        )
        assert against_cycle.std() < 0.5 * against_shafts.std(), start
    found = {}
    for name, pattern, start in (
        ("pitted", pinion + tooth_bump(PINION, 5, 0.1), 30.2),
        ("healthy", pinion, 17.9),
    ):
        segment, segment_angle = record(pattern, 1.2, start)
        residual = rf.cycle_residual(segment, segment_angle, cycle, P, PINION, top)
        found[name] = rf.residual_signatures(
            rf.shaft_patterns(residual, segment_angle, SHAFTS, P)[0],
            from_cycle[0],
            PINION,
            PINION / 4,
            12,
        )
    assert found["pitted"]["tooth_peak1"][0] > 3 * found["healthy"]["tooth_peak1"][0]
    assert found["pitted"]["rms_ratio"][0] > 3 * found["healthy"]["rms_ratio"][0]


def test_the_family_takes_references_covering_the_hunting_cycle_against_it():
    """A calibration record covering the cycle (two segments that follow one another) makes its
    condition's reference the cycle's average: packaged with the model, it gives a new record the
    same features; a healthy test record lies near zero, a pitted one does not."""
    rng = np.random.default_rng(9)
    pinion, gear = (
        pitch_pattern(PINION, rng),
        rf.without_orders(pitch_pattern(GEAR, rng)[None, :], GEAR)[0],
    )
    fs, speed, ratio = 5120.0, 1100.0, PINION / GEAR
    rows = []
    x, _ = in_time([pinion, gear], fs, speed, 2.6, start=(0.0, 0.2), noise=0.01, rng=rng)
    half = x.shape[-1] // 2
    for segment in range(2):
        rows += signal_rows(
            "vb-healthy-1100rpm-r00",
            "healthy",
            speed,
            segment,
            x[0, segment * half : (segment + 1) * half],
            fs,
        )
    for record_id, health, pattern, start in (
        ("vb-healthy-1100rpm-r01", "healthy", pinion, 20.3),
        (
            "vb-surface_fault-1100rpm-r00",
            "surface_fault",
            pinion + tooth_bump(PINION, 3, 0.3),
            31.7,
        ),
    ):
        x, _ = in_time(
            [pattern, gear], fs, speed, 1.3, start=(start, 0.2 + start * ratio), noise=0.01, rng=rng
        )
        rows += signal_rows(record_id, health, speed, 0, x[0, :half], fs)
    frame = pd.DataFrame(rows).assign(source="virtual_bench")
    params = dict(SETTINGS)
    spec = {
        "source": "measured",
        "healthy_state": "healthy",
        "condition": "speed_rpm",
        "reserve": {},
    }
    written = rf.residual_feature_table(
        frame, ["A1_x"], params, FamilyInputs(healthy_reference=spec)
    )
    references = written.attrs["references"]
    assert (references["shaft"] == rf.CYCLE_ROW).sum() == 1
    assert len(references.loc[references["shaft"] == rf.CYCLE_ROW, "pattern"].iloc[0]) == GEAR * P
    rms = written.set_index("record_id")["res_A1_x_pinion_tooth_peak1"]
    assert rms["vb-surface_fault-1100rpm-r00"] > rms["vb-healthy-1100rpm-r01"] + 0.3
    packaged = rf.residual_feature_table(
        frame, ["A1_x"], params, FamilyInputs(packaged_references=references.to_dict("list"))
    )
    names = rf.feature_names(["A1_x"], SHAFTS, 12)
    np.testing.assert_allclose(packaged[names].to_numpy(), written[names].to_numpy(), atol=1e-5)


def test_a_record_without_a_mesh_line_falls_back_on_the_nominal_speed_and_says_so(caplog):
    """A segment whose mesh line can be followed is tracked on it; one of noise alone (a rate or
    tooth count that puts the line elsewhere looks the same) falls back on the nominal speed,
    counted per record in the table the report reads and in the log."""
    rng = np.random.default_rng(9)
    pinion, gear = (
        pitch_pattern(PINION, rng),
        rf.without_orders(pitch_pattern(GEAR, rng)[None, :], GEAR)[0],
    )
    fs, speed = 5120.0, 1100.0
    x, _ = in_time([pinion, gear], fs, speed, 2.6, start=(0.0, 0.2), noise=0.01, rng=rng)
    half = x.shape[-1] // 2
    rows = []
    for segment in range(2):
        chunk = x[0, segment * half : (segment + 1) * half]
        rows += signal_rows("vb-healthy-1100rpm-r00", "healthy", speed, segment, chunk, fs)
        rows += signal_rows(
            "noise-r01", "healthy", speed, segment, rng.normal(0.0, chunk.std(), half), fs
        )
    params = dict(SETTINGS)
    spec = {"source": "measured", "healthy_state": "healthy", "condition": "speed_rpm"}
    with caplog.at_level("WARNING"):
        written = rf.residual_feature_table(
            pd.DataFrame(rows).assign(source="measured"),
            ["A1_x"],
            params,
            FamilyInputs(healthy_reference=dict(spec, reserve={})),
        )
    tracking = written.attrs["shaft_tracking"].set_index(["record_id", "segment"])
    assert (tracking.loc["vb-healthy-1100rpm-r00", "method"] == "mesh_phase").all()
    assert (tracking.loc["vb-healthy-1100rpm-r00", "line_to_floor"] > 5.0).all()
    assert (tracking.loc["noise-r01", "method"] == "nominal").all()
    assert (
        "fell back to the nominal speed on 2 of 4 segments, in 1 records: noise-r01 (2 of 2)"
        in caplog.text
    )
    counted = record_tracking(written.attrs["shaft_tracking"]).set_index("record_id")
    assert counted["nominal_segments"].to_dict() == {"noise-r01": 2, "vb-healthy-1100rpm-r00": 0}
    assert counted.loc["vb-healthy-1100rpm-r00", "line_to_floor_median"] > 5.0


def signal_rows(record_id, health, speed, segment, x, fs):
    return [
        {
            "record_id": record_id,
            "segment": segment,
            "source": "simulated",
            "health_state": health,
            "speed_rpm": speed,
            "load": 10.0,
            "fs_hz": fs,
            "channel": "A1_x",
            "signal": x.astype(np.float32),
            "params": "",
        }
    ]


def test_the_family_takes_simulated_twins_and_packaged_references():
    """Simulated records against their healthy twin's last segment; the measured references written
    and packaged give a new record the same features."""
    rng = np.random.default_rng(5)
    fs, speed = 5120.0, 1100.0
    pinion, gear = (
        pitch_pattern(PINION, rng),
        rf.without_orders(pitch_pattern(GEAR, rng)[None, :], GEAR)[0],
    )
    rows = []
    for segment in range(2):  # the healthy twin: segment 1 is its reference
        x, _ = in_time(
            [pinion, gear], fs, speed, 0.6, start=(0.3 * segment, 0.1), noise=0.01, rng=rng
        )
        rows += signal_rows("sim-healthy-1100rpm-b000-s000", "healthy", speed, segment, x[0], fs)
    x, _ = in_time(
        [pinion + tooth_bump(PINION, 3, 0.3), gear],
        fs,
        speed,
        0.6,
        start=(0.5, 0.4),
        noise=0.01,
        rng=rng,
    )
    rows += signal_rows("sim-surface_fault-1100rpm-b000-s000", "surface_fault", speed, 0, x[0], fs)
    frame = pd.DataFrame(rows)
    params = dict(SETTINGS)
    against = {"source": "simulated", "healthy_state": "healthy", "segments_per_sample": 1}
    table = rf.residual_feature_table(
        frame, ["A1_x"], params, FamilyInputs(healthy_reference=against)
    )
    peak = table.set_index(["record_id", "segment"])["res_A1_x_pinion_tooth_peak1"]
    assert (
        peak[("sim-surface_fault-1100rpm-b000-s000", 0)]
        > peak[("sim-healthy-1100rpm-b000-s000", 0)] + 0.5
    )
    assert table.attrs["referenced_columns"] == rf.feature_names(["A1_x"], SHAFTS, 12)
    # the segments spread over worker processes: the same table
    spread = rf.residual_feature_table(
        frame, ["A1_x"], params, FamilyInputs(healthy_reference=against, processes=2)
    )
    pd.testing.assert_frame_equal(spread, table)
    with pytest.raises(FeatureTableError, match="healthy_reference"):
        rf.residual_feature_table(frame, ["A1_x"], params)
    # measured: the calibration set (the first healthy record) is the reference, written out ...
    measured = frame.assign(
        record_id=frame["record_id"].str.replace("sim-", "vb-"), source="virtual_bench"
    )
    measured.loc[measured["segment"] == 1, "record_id"] = "vb-healthy-1100rpm-r00"
    measured.loc[measured["segment"] == 1, "segment"] = 0
    spec = {
        "source": "measured",
        "healthy_state": "healthy",
        "condition": "speed_rpm",
        "reserve": {},
    }
    written = rf.residual_feature_table(
        measured, ["A1_x"], params, FamilyInputs(healthy_reference=spec)
    )
    # ... and a packaged model's copy gives a new record the same features
    packaged = rf.residual_feature_table(
        measured,
        ["A1_x"],
        params,
        FamilyInputs(packaged_references=written.attrs["references"].to_dict("list")),
    )
    names = rf.feature_names(["A1_x"], SHAFTS, 12)
    np.testing.assert_allclose(packaged[names].to_numpy(), written[names].to_numpy(), atol=1e-5)
    # without magnitudes: no feature that grows with the fault's size, the bands as their shape
    # (zero mean per channel and shaft), every feature the fault's size leaves unchanged as it was
    shape = rf.residual_feature_table(
        frame, ["A1_x"], dict(params, magnitudes=False), FamilyInputs(healthy_reference=against)
    )
    sized = [n for n in rf.feature_names(["A1_x"], SHAFTS, 12) if n.endswith(rf.SIZED_FEATURES)]
    assert shape.attrs["referenced_columns"] == [
        n for n in rf.feature_names(["A1_x"], SHAFTS, 12) if n not in sized
    ]
    bands = [f"res_A1_x_pinion_b{k:02d}" for k in range(12)]
    np.testing.assert_allclose(shape[bands].to_numpy().mean(axis=1), 0.0, atol=1e-5)
    np.testing.assert_allclose(
        shape[bands].to_numpy(),
        (table[bands].to_numpy() - table[bands].to_numpy().mean(axis=1, keepdims=True)),
        atol=1e-5,
    )
    assert np.allclose(shape["res_A1_x_pinion_tooth_peak1"], table["res_A1_x_pinion_tooth_peak1"])


def test_a_grid_that_folds_into_the_kept_orders_is_refused():
    with pytest.raises(FeatureTableError, match="samples_per_revolution"):
        rf.check_resolution(5120.0, 450.0, SHAFTS, 256, 3)
    rf.check_resolution(5120.0, 450.0, SHAFTS, 1024, 3)


def test_a_packaged_model_takes_a_new_record_against_its_reference_waveforms():
    """`condmon predict`'s path: a SignalModel of the residual family computes a new record's
    features against the packaged reference waveforms, and the feature-level reference (which
    holds none of the family's columns) leaves them as they are."""
    from conftest import config_of

    from condmon.signal_model import SignalModel, complete_signal_table
    from condmon.systems import get_system

    rng = np.random.default_rng(6)
    fs, speed = 5120.0, 1100.0
    pinion, gear = (
        pitch_pattern(PINION, rng),
        rf.without_orders(pitch_pattern(GEAR, rng)[None, :], GEAR)[0],
    )
    rows = []
    for record_id, health, pattern, start in (
        ("vb-healthy-1100rpm-r00", "healthy", pinion, 0.0),
        ("new", "healthy", pinion, 0.4),
        ("new-pitted", "surface_fault", pinion + tooth_bump(PINION, 3, 0.3), 0.7),
    ):
        x, _ = in_time([pattern, gear], fs, speed, 0.6, start=(start, 0.2), noise=0.01, rng=rng)
        rows += signal_rows(record_id, health, speed, 0, x[0], fs)
    frame = pd.DataFrame(rows)
    params = dict(SETTINGS, damaged_shafts=["pinion"])
    spec = {
        "source": "measured",
        "healthy_state": "healthy",
        "condition": "speed_rpm",
        "reserve": {},
    }
    written = rf.residual_feature_table(
        frame.assign(source="measured"), ["A1_x"], params, FamilyInputs(healthy_reference=spec)
    )
    names = rf.feature_names(["A1_x"], SHAFTS[:1], 12)
    system = get_system(config_of("config/config.yaml")).job_spec("measured")
    features = {
        "kind": "residual",
        "channels": ["A1_x"],
        "spectrum": {},
        "statistical": None,
        "families": {
            "residual": dict(params, reference_patterns=written.attrs["references"].to_dict("list"))
        },
        "feature_names": names,
        "reference": {"condition": "speed_rpm", "table": {"speed_rpm": [1100.0]}},
    }

    class Peak:  # faulty where the worst tooth stands out
        classes_ = np.array(["healthy", "surface_fault"])

        def predict(self, x):
            return np.where(
                x[:, names.index("res_A1_x_pinion_tooth_peak1")] > 0.9, "surface_fault", "healthy"
            )

    model = SignalModel(
        Peak(),
        features,
        {
            "fs_hz": fs,
            "n_samples": len(rows[0]["signal"]),
            "channels": ["A1_x"],
            "speeds_rpm": [speed],
        },
        "healthy",
        system=system,
    )
    new = complete_signal_table(
        frame[frame["record_id"] != "vb-healthy-1100rpm-r00"].drop(columns=["source", "params"])
    )
    ids, x = model.feature_matrix(new)
    expected = written.set_index("record_id").loc[ids["record_id"], names].to_numpy()
    np.testing.assert_allclose(x, expected, atol=1e-5)
    segments = model.predict_segments(new)
    assert segments.set_index("record_id")["predicted_label"].to_dict() == {
        "new": "healthy",
        "new-pitted": "surface_fault",
    }
    # and where the pit sits: the tooth the written table names for the same record, on the
    # reference's tooth frame, in the record's health summary
    from condmon.signal_model import health_summary, record_predictions

    written_at = written.attrs["fault_locations"].set_index("record_id")
    pitted = segments.set_index("record_id").loc["new-pitted"]
    assert pitted["location_pinion"] == written_at.loc["new-pitted", "position"]
    summary = health_summary(
        record_predictions(segments, model.classes, "healthy"), model.classes, "healthy"
    )
    summary = summary.set_index("record_id")
    assert summary.loc["new-pitted", "location_pinion"] == pitted["location_pinion"]
    assert summary.loc["new-pitted", "location_agreement_pinion"] == 1.0
    assert np.isnan(summary.loc["new", "location_pinion"])  # called healthy: no location


def test_the_features_read_the_residual_on_the_bands_orders_only():
    """Above the bands' orders a low-speed record holds more of its tracked angle's error than
    pattern: a residual's content there (here a burst on one tooth about order 200, ten times the
    residual's RMS there) leaves every feature as it was, a pit on one tooth within them does not."""
    rng = np.random.default_rng(4)
    reference = pitch_pattern(PINION, rng)[None, :]
    residual = rf.band_limited(0.01 * rng.normal(size=(1, P)), 1, 87)
    angle = np.arange(P) / P
    burst = -0.5 * tooth_bump(PINION, 5, 1.0)[None, :] * np.cos(2 * np.pi * 200 * angle)
    burst = burst - rf.band_limited(burst, 1, 87)  # nothing left on the bands' orders
    plain = rf.residual_signatures(residual, reference, PINION, PINION / 4, 12)
    with_burst = rf.residual_signatures(residual + burst, reference, PINION, PINION / 4, 12)
    for name, value in plain.items():
        np.testing.assert_allclose(with_burst[name], value, rtol=1e-9, err_msg=name)
    pitted = rf.residual_signatures(
        residual + rf.band_limited(tooth_bump(PINION, 5, 0.3)[None, :], 1, 87),
        reference,
        PINION,
        PINION / 4,
        12,
    )
    assert pitted["tooth_peak1"][0] > 3 * plain["tooth_peak1"][0]


# -- the window: where the bands reach ---------------------------------------------------------
CFRP_SHAFTS = [("pinion", 1.0, 20), ("gear", 20 / 30, 30)]


def orders_pattern(orders, rng, amplitude=1.0) -> np.ndarray:
    """One revolution (1, P) of lines of equal amplitude at `orders`, random phases."""
    angle = np.arange(P) / P
    return sum(
        amplitude * np.cos(2 * np.pi * o * angle + rng.uniform(0, 2 * np.pi)) for o in orders
    )[None, :]


def test_the_window_reaches_where_the_healthy_power_lies_within_the_passband():
    """The bands reach the mesh harmonic at or above the order below which 95 % of the healthy
    records' power lies at the lowest speed, bounded at the highest speed by an analyser's usable
    band (the sampling rate / 2.56): a 20-tooth pinion sampled at 5120 Hz up to 1100 rpm keeps 5
    harmonics (order 101 at 1852 Hz, below 2000 Hz), a 29-tooth one 3 (order 88)."""
    rng = np.random.default_rng(4)
    fs = 5120.0
    angle = 450.0 / 60.0 * np.arange(int(1.5 * fs)) / fs

    def segments(top_order):
        pattern = orders_pattern(range(20, top_order + 1, 20), rng)
        return rf.pattern_at(pattern, angle)[None]  # (1 segment, 1 channel, n)

    assert rf.window_harmonics({450.0: segments(100)}, fs, CFRP_SHAFTS)[0] == 5
    assert (
        rf.window_harmonics({450.0: segments(100), 1100.0: segments(100)}, fs, CFRP_SHAFTS)[0] == 5
    )
    # vibration up to order 300 at 450 rpm (2250 Hz): the passband at 1100 rpm bounds it
    harmonics, order, limit = rf.window_harmonics(
        {450.0: segments(300), 1100.0: segments(100)}, fs, CFRP_SHAFTS
    )
    assert (harmonics, limit) == (5, 5) and order > 280
    assert rf.passband_harmonics(fs, 1100.0, PINION) == 3
    with pytest.raises(FeatureTableError, match="mesh harmonic"):
        rf.window_harmonics({450.0: segments(100), 8000.0: segments(100)}, fs, CFRP_SHAFTS)


def test_a_fault_whose_change_lies_above_the_old_window_is_inside_the_new_one():
    """A rig whose vibration reaches its sixth mesh harmonic, a fault that changes only orders
    65-115 (above the old fixed window of three harmonics, order 60): with the window from the
    rig (`mesh_harmonics: auto`) the faulty record's residual stands far above a healthy one's,
    the window packaged with the references; with three harmonics it is a healthy record's."""
    rng = np.random.default_rng(8)
    fs, speed = 5120.0, 450.0
    pinion = orders_pattern(range(20, 121, 20), rng) + orders_pattern([1, 2, 3, 7, 11], rng, 0.3)
    gear = rf.without_orders(orders_pattern([1, 2, 5], rng, 0.3), 30)
    impulse = np.zeros((1, P))
    impulse[0, int(6.5 * P / 20)] = 1.0  # at tooth 6, then only its orders 65-115
    change = rf.band_limited(impulse, 1, 115) - rf.band_limited(impulse, 1, 64)
    change *= 0.3 / change.std()
    t = np.arange(int(1.5 * fs)) / fs

    def record(pattern, start):
        angle = speed / 60.0 * t + start
        x = rf.pattern_at(pattern, angle)[0] + rf.pattern_at(gear, angle * 20 / 30 + 0.3)[0]
        return x + rng.normal(0.0, 0.01, x.shape)

    rows = []
    for segment in range(2):  # the calibration record: two segments that follow one another
        rows += signal_rows(
            "vb-healthy-450rpm-r00", "healthy", speed, segment, record(pinion, 11.25 * segment), fs
        )
    rows += signal_rows("vb-healthy-450rpm-r01", "healthy", speed, 0, record(pinion, 0.37), fs)
    rows += signal_rows("vb-spall-450rpm-r00", "spall", speed, 0, record(pinion + change, 0.71), fs)
    frame = pd.DataFrame(rows).assign(source="virtual_bench")
    params = {
        "shafts": [list(s) for s in CFRP_SHAFTS],
        "samples_per_revolution": P,
        "bands_per_mesh": 4,
        "shaft_orders": 2,
        "phase_harmonic": 1,
        "phase_band_orders": 0.3,
        "phase_min_snr": 5.0,
    }
    spec = {
        "source": "measured",
        "healthy_state": "healthy",
        "condition": "speed_rpm",
        "reserve": {},
    }

    def rms_ratio(mesh_harmonics):
        table = rf.residual_feature_table(
            frame,
            ["A1_x"],
            dict(params, mesh_harmonics=mesh_harmonics),
            FamilyInputs(healthy_reference=spec),
        )
        return table.set_index("record_id")["res_A1_x_pinion_rms_ratio"], table

    new, table = rms_ratio("auto")
    assert rf.window_from_table(table.attrs["references"]) == 6
    assert len([c for c in table.columns if c.startswith("res_A1_x_pinion_b")]) == 24
    assert (
        new["vb-spall-450rpm-r00"] > new["vb-healthy-450rpm-r01"] + 1.0
    )  # ten times the healthy residual
    old, _ = rms_ratio(3)
    assert abs(old["vb-spall-450rpm-r00"] - old["vb-healthy-450rpm-r01"]) < 0.3
    # the simulated job and a packaged model take the measured job's window
    packaged = rf.residual_feature_table(
        frame,
        ["A1_x"],
        dict(params, mesh_harmonics="auto"),
        FamilyInputs(packaged_references=table.attrs["references"].to_dict("list")),
    )
    assert list(packaged.columns) == list(table.columns)
    with pytest.raises(FeatureTableError, match="auto"):
        rf.resolved_window(
            "auto", table.attrs["references"].query("shaft != @rf.WINDOW_ROW"), "the references"
        )


def test_settings_and_run_time_inputs_stay_apart():
    """The family's settings are features.residual and what the system adds; a reference or the
    job's cores in them is refused by name (they are `FamilyInputs`), and the gear system declares
    what its families take on their entries."""
    from condmon.features import SystemFamily
    from conftest import system_of

    params = dict(SETTINGS)
    for leaked in (
        {"against": {"source": "measured"}},
        {"processes": 2},
        {"reference_patterns": {}},
    ):
        with pytest.raises(FeatureTableError, match=f"unknown parameter.*{next(iter(leaked))}"):
            rf.residual_feature_table(
                pd.DataFrame(),
                ["A1_x"],
                {**params, **leaked},
                FamilyInputs(healthy_reference={"source": "measured"}),
            )
    families = system_of(".test/config/smoke.yaml").feature_families()
    assert all(isinstance(family, SystemFamily) for family in families.values())
    assert (families["residual"].references, families["residual"].parallel) == (True, True)
    assert (families["order"].references, families["order"].parallel) == (False, False)


def test_a_packaged_models_families_carry_their_references_and_give_them_back_as_inputs():
    from condmon.features import SystemFamily
    from condmon.signal_model import PACKAGED_REFERENCES, packaged_features, unpacked_families

    features = {
        "kind": "residual",
        "families": {"residual": {"bands_per_mesh": 4}, "order": {"order_max": 9}},
    }
    own = {
        "residual": SystemFamily(rf.residual_feature_table, references=True),
        "order": SystemFamily(lambda *a: None),
    }
    references = pd.DataFrame({"shaft": ["pinion"], "pattern": [[0.0, 1.0]]})
    packaged = packaged_features(
        features, {"bpfo": 3.6}, own, {"condition": "speed_rpm", "table": {}}, references
    )
    assert features == {
        "kind": "residual",
        "families": {"residual": {"bands_per_mesh": 4}, "order": {"order_max": 9}},
    }
    assert packaged["families"]["residual"][PACKAGED_REFERENCES] == references.to_dict("list")
    assert PACKAGED_REFERENCES not in packaged["families"]["order"]
    assert (
        packaged["defect_orders"] == {"bpfo": 3.6}
        and packaged["reference"]["condition"] == "speed_rpm"
    )
    settings, inputs = unpacked_families(packaged["families"])
    assert settings == features["families"]
    assert (
        inputs.packaged_references == references.to_dict("list")
        and inputs.healthy_reference is None
    )


def test_a_strong_fault_does_not_pull_the_alignment_off_its_teeth():
    """Pitting on four neighbouring teeth far stronger than the healthy pitch pattern (a gearbox at
    its load): aligned on the whole pattern, the fault's correlation with the reference picks a
    wrong whole-tooth shift in about half the draws, so its teeth would be named wrong; with the
    fault's pitches left out of the alignment (`fault_masked_shift`), the right one in nearly
    all. A healthy segment has no such pitch: its shift is the plain alignment's, to the bit."""
    top = rf.top_band_order(PINION / 4, 12)
    true_shift = P - (7 * P // PINION + 3)

    def whole_tooth_off(shift):
        return abs((shift - true_shift + P / 2) % P - P / 2) > P / PINION / 2

    plain_wrong = masked_wrong = 0
    for seed in range(20):
        rng = np.random.default_rng(seed)
        healthy = pitch_pattern(PINION, rng, pitch_rms=0.05)[None, :]
        pitting = sum(tooth_bump(PINION, t, d) for t, d in zip(range(3, 7), rng.uniform(0.5, 2, 4)))
        record = np.roll(healthy + pitting, true_shift, axis=-1) + rng.normal(0, 0.01, (1, P))
        plain_wrong += whole_tooth_off(rf.alignment_shift(record, healthy, PINION, top))
        masked = rf.fault_masked_shift(record, healthy, PINION, top)
        masked_wrong += whole_tooth_off(masked)
        # the damaged teeth named where they are
        if not whole_tooth_off(masked):
            residual = rf.shifted(record, masked) - healthy
            excess = rf.damaged_pitches(rf.residual_signal(residual, PINION, 2, 3), PINION)
            assert rf.located_tooth(excess)[0] in range(3, 7), seed
    assert plain_wrong >= 6 and masked_wrong <= 1, (plain_wrong, masked_wrong)
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        healthy = pitch_pattern(PINION, rng, pitch_rms=0.05)[None, :]
        record = np.roll(healthy, 123, axis=-1) + rng.normal(0, 0.05, (1, P))
        assert rf.fault_masked_shift(record, healthy, PINION, top) == rf.alignment_shift(
            record, healthy, PINION, top
        )


def test_a_condition_far_from_the_first_takes_its_tooth_from_the_steps_between():
    """Three conditions of one machine whose pitch patterns change with the load: the first and
    the last share the tooth-bound part H, and each has a load-bound part (W, V) of its own that
    correlates with the other's at a wrong whole tooth more than H does at the right one. The
    middle condition holds half of both. Aligned to the first directly, the last lands 7 teeth
    off; step by step through the middle, on its own tooth."""
    rng = np.random.default_rng(4)
    top = rf.top_band_order(PINION / 4, 12)
    healthy = pitch_pattern(PINION, rng, pitch_rms=0.2)[None, :]
    h = rf.band_limited(healthy, 1, top, PINION, lowest_order=3)
    w = noise_above(2, 1.0, rng)[None, :]
    w = (
        rf.band_limited(w, 1, top, PINION, lowest_order=3)
        * 1.5
        * h.std()
        / rf.band_limited(w, 1, top, PINION, lowest_order=3).std()
    )
    v = 1.3 * np.roll(w, 7 * P // PINION, axis=-1)
    starts = {150.0: 0, 300.0: 311, 450.0: 617}  # where each calibration record began
    in_frame = {150.0: healthy + w, 300.0: healthy + 0.5 * (w + v), 450.0: healthy + v}
    references = {c: [np.roll(x, -starts[c], axis=-1)] for c, x in in_frame.items()}
    frames = rf.reference_frames(references, [("pinion", 1.0, PINION)], [top])

    def teeth_off(condition, turns):
        return abs((turns * P - starts[condition] + P / 2) % P - P / 2) / (P / PINION)

    direct = -rf.alignment_shift(references[450.0][0], references[150.0][0], PINION, top) / P
    assert teeth_off(450.0, direct) > 6
    assert teeth_off(300.0, frames[300.0][0]) < 0.5 and teeth_off(450.0, frames[450.0][0]) < 0.5

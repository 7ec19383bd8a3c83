"""The speed fluctuation read off healthy records (`model.variability.speed_fluctuation_source`)."""

import math

import numpy as np
import pytest

from condmon.systems.gear.fluctuation import fluctuation_of, speed_fluctuation
from condmon.systems.gear.parameters import measured_fluctuation_fields

FS, TEETH = 5120.0, 29


def mesh_records(
    amplitude, frequency_hz, speed_rpm=775.0, segments=2, seconds=1.5, noise=0.05, seed=0
):
    """Segments (n, 4 channels, samples) of a mesh line on a shaft whose speed is
    speed x (1 + amplitude sin(2 pi f t + phase)), each channel its own gain and noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * FS)) / FS
    shaft_hz = speed_rpm / 60.0
    out = []
    for _ in range(segments):
        phase = rng.uniform(0, 2 * math.pi)
        # the angle (revolutions) of speed shaft_hz (1 + a sin(2 pi f t + phase))
        angle = shaft_hz * t + shaft_hz * amplitude * (
            math.cos(phase) - np.cos(2 * math.pi * frequency_hz * t + phase)
        ) / (2 * math.pi * frequency_hz)
        line = np.sin(2 * math.pi * TEETH * angle) + 0.3 * np.sin(4 * math.pi * TEETH * angle)
        out.append(
            [gain * line + noise * rng.standard_normal(len(t)) for gain in (1.0, 0.6, 0.8, 0.4)]
        )
    return np.array(out)


def test_a_sinusoid_gives_its_amplitude_and_frequency():
    t = np.arange(int(3 * FS)) / FS
    amplitude, frequency = fluctuation_of(0.003 * np.sin(2 * math.pi * 1.7 * t + 0.4), FS)
    assert amplitude == pytest.approx(0.003, rel=0.03)
    assert frequency == pytest.approx(1.7, abs=0.05)


@pytest.mark.parametrize("amplitude, frequency_hz", [(0.002, 1.5), (0.004, 2.5)])
def test_the_tracked_speed_of_healthy_records_gives_the_fluctuation(amplitude, frequency_hz):
    estimate = speed_fluctuation(mesh_records(amplitude, frequency_hz), FS, 775.0, TEETH)
    low, high = estimate["amplitude"]
    assert 0.85 * amplitude <= low <= high <= 1.15 * amplitude
    assert (
        estimate["frequency_hz"][0] >= frequency_hz - 0.2
        and estimate["frequency_hz"][1] <= frequency_hz + 0.2
    )
    assert estimate["segments"] == 2 and estimate["band_hz"] == pytest.approx(
        0.3 * 775 / 60, abs=1e-3
    )


def test_a_fluctuation_faster_than_the_tracking_band_is_not_read():
    # at 450 rpm the mesh phase is followed within +/- 0.3 orders = 2.25 Hz: a 3 Hz wobble is cut
    assert speed_fluctuation(mesh_records(0.004, 3.0, speed_rpm=450.0), FS, 450.0, TEETH) is None
    # a quarter-second segment holds no period of a 1.5 Hz fluctuation
    assert speed_fluctuation(mesh_records(0.002, 1.5, seconds=0.25), FS, 775.0, TEETH) is None
    # shorter than the filter's two edges: nothing left to read
    assert speed_fluctuation(mesh_records(0.002, 1.5, seconds=0.15), FS, 775.0, TEETH) is None
    # no mesh line to follow at all
    assert (
        speed_fluctuation(np.random.default_rng(1).standard_normal((2, 4, 7680)), FS, 775.0, TEETH)
        is None
    )


def test_samples_draw_within_the_measured_fluctuation_of_the_nearest_speed():
    measured = {
        "450": None,
        "775": {"amplitude": [0.0030, 0.0035], "frequency_hz": [2.4, 2.6]},
        "1100": {"amplitude": [0.0038, 0.0040], "frequency_hz": [2.5, 2.5]},
    }
    fields = [measured_fluctuation_fields(measured, 450.0, seed) for seed in range(20)]
    assert all(
        0.0030 <= f["speed_fluctuation"] <= 0.0035 and 2.4 <= f["speed_fluctuation_hz"] <= 2.6
        for f in fields
    )
    assert measured_fluctuation_fields(measured, 1000.0, 3)["speed_fluctuation"] >= 0.0038
    assert measured_fluctuation_fields(measured, 450.0, 3) == measured_fluctuation_fields(
        measured, 450.0, 3
    )
    assert len({f["speed_fluctuation"] for f in fields}) == 20
    assert measured_fluctuation_fields({"450": None}, 450.0, 3) == {}


def test_the_report_calls_a_fluctuation_read_off_the_healthy_records_calibrated():
    from conftest import system_of

    rows = system_of("config/config.yaml").bench_differences()  # its source: healthy_records
    speed = next(row for row in rows if row["difference"].startswith("speed fluctuation"))
    load = next(row for row in rows if row["difference"].startswith("load fluctuation"))
    assert speed["handled"] == "calibrated" and load["handled"] == "randomised"

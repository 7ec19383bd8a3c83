"""features.healthy_reference: each machine's features against its own healthy reference."""

import numpy as np
import pandas as pd
import pytest

from condmon.reference import (
    ReferenceError,
    measured_reference,
    nearest_reference,
    refer_measured,
    reference_length_mismatches,
    refer_simulated,
)
from condmon.features import compute_feature_table, feature_columns
from condmon.signal_model import SignalModel, complete_signal_table
from condmon.simulate import machine_of

NAMES = ["f1", "f2"]


def segments(rows):
    return pd.DataFrame(rows, columns=["record_id", "segment", "health_state", "speed_rpm", *NAMES])


def test_a_measured_segment_is_taken_against_the_calibration_set_at_its_speed():
    # two healthy records per speed: the first (by id) is the calibration set (hybrid.measured_layout)
    frame = segments(
        [
            ("h1", 0, "healthy", 450.0, 1.0, 10.0),
            ("h1", 1, "healthy", 450.0, 3.0, 12.0),
            ("h2", 0, "healthy", 450.0, 2.5, 11.0),
            ("f1", 0, "fault", 450.0, 7.0, 11.0),
            ("h3", 0, "healthy", 900.0, 5.0, 0.0),
            ("h4", 0, "healthy", 900.0, 6.0, 1.0),
            ("f2", 0, "fault", 900.0, 9.0, 4.0),
        ]
    )
    reference = measured_reference(frame, NAMES, "healthy", "speed_rpm", {})
    assert reference.loc[450.0].tolist() == [2.0, 11.0] and reference.loc[900.0].tolist() == [
        5.0,
        0.0,
    ]
    out = refer_measured(frame, NAMES, reference, "speed_rpm").set_index("record_id")
    assert out.loc["f1", NAMES].tolist() == [5.0, 0.0] and out.loc["f2", NAMES].tolist() == [
        4.0,
        4.0,
    ]
    assert out.loc["h2", NAMES].tolist() == [0.5, 0.0]


def test_a_simulated_reference_shorter_than_the_calibration_set_is_named_per_condition():
    # 450 rpm: the calibration record h1 holds two segments; 900 rpm: h3 holds one
    frame = segments(
        [
            ("h1", 0, "healthy", 450.0, 1.0, 10.0),
            ("h1", 1, "healthy", 450.0, 3.0, 12.0),
            ("h2", 0, "healthy", 450.0, 2.5, 11.0),
            ("h3", 0, "healthy", 900.0, 5.0, 0.0),
            ("h4", 0, "healthy", 900.0, 6.0, 1.0),
        ]
    )
    one = reference_length_mismatches(frame, "healthy", "speed_rpm", {}, 1)
    assert (
        len(one) == 1
        and "speed_rpm 450 holds 2 segment(s)" in one[0]
        and "simulated_segments to 2" in one[0]
    )
    two = reference_length_mismatches(frame, "healthy", "speed_rpm", {}, 2)
    assert len(two) == 1 and "speed_rpm 900 holds 1 segment(s)" in two[0]


def test_a_speed_without_calibration_records_is_refused_by_name():
    frame = segments(
        [
            ("h1", 0, "healthy", 450.0, 1.0, 1.0),
            ("h2", 0, "healthy", 450.0, 1.0, 1.0),
            ("f1", 0, "fault", 900.0, 2.0, 2.0),
        ]
    )
    with pytest.raises(ReferenceError, match=r"no calibration records at speed_rpm \[900.0\]"):
        measured_reference(frame, NAMES, "healthy", "speed_rpm", {})


def test_a_simulated_sample_is_taken_against_its_healthy_twin_whose_reference_is_dropped():
    frame = segments(
        [
            ("sim-healthy-450rpm-b000-s000", 0, "healthy", 450.0, 1.0, 1.0),
            ("sim-healthy-450rpm-b000-s000", 1, "healthy", 450.0, 2.0, 4.0),  # its reference
            ("sim-fault-450rpm-b000-s000", 0, "fault", 450.0, 5.0, 5.0),
            ("sim-healthy-450rpm-b000-s001", 0, "healthy", 450.0, 0.0, 0.0),
            ("sim-healthy-450rpm-b000-s001", 1, "healthy", 450.0, -1.0, 0.0),
            ("sim-fault-450rpm-b000-s002", 0, "fault", 450.0, 9.0, 9.0),  # its healthy twin failed
        ]
    )
    out = refer_simulated(frame, NAMES, "healthy", segments_per_sample=1).set_index("record_id")
    assert sorted(out.index) == [
        "sim-fault-450rpm-b000-s000",
        "sim-healthy-450rpm-b000-s000",
        "sim-healthy-450rpm-b000-s001",
    ]
    assert out.loc["sim-fault-450rpm-b000-s000", NAMES].tolist() == [3.0, 1.0]
    assert out.loc["sim-healthy-450rpm-b000-s000", NAMES].tolist() == [-1.0, -3.0]
    with pytest.raises(ReferenceError, match="no healthy reference segments"):
        refer_simulated(frame[frame["segment"] == 0], NAMES, "healthy", segments_per_sample=1)


def test_machine_ids_read_from_simulated_record_ids_only():
    assert machine_of("sim-surface_fault-775rpm-b001-s012") == "775rpm-b001-s012"
    with pytest.raises(ValueError, match="not a simulated record id"):
        machine_of("bench-healthy-450rpm-r0")


def test_a_condition_far_from_every_reference_or_unknown_is_reported():
    reference = pd.DataFrame({"f1": [0.0, 1.0]}, index=pd.Index([450.0, 1100.0], name="speed_rpm"))
    nearest, far = nearest_reference(reference, [452.0, 1100.0, 775.0, np.nan], 0.02)
    assert nearest[:2].tolist() == [0, 1] and far == ["775.0", "nan"]


class Identity:
    classes_ = np.array(["fault", "healthy"])

    def predict(self, x):
        return np.where(np.abs(x).max(axis=1) > 1e-3, "fault", "healthy")


def test_a_packaged_model_takes_new_records_against_the_stored_reference():
    """The SignalModel subtracts the reference at each record's speed before its estimator, and
    refuses a record at a speed with no reference."""
    n, fs = 256, 1024.0
    signal = np.random.default_rng(0).normal(size=n).astype(np.float32)
    table = complete_signal_table(
        pd.DataFrame(
            [
                dict(
                    record_id=rid,
                    segment=0,
                    speed_rpm=450.0,
                    fs_hz=fs,
                    channel="acc",
                    signal=signal * gain,
                )
                for rid, gain in (("same", 1.0), ("louder", 3.0))
            ]
        )
    )
    spectrum = {
        "f_min_hz": 0.0,
        "f_max_hz": 512.0,
        "resolution_hz": 64.0,
        "scale": "log",
        "band_statistic": "rms",
    }
    wide = compute_feature_table(table, ["acc"], spectrum)
    names = feature_columns(wide)
    reference = {
        "condition": "speed_rpm",
        "table": {
            "speed_rpm": [450.0],
            **{k: [float(v)] for k, v in wide.set_index("record_id").loc["same", names].items()},
        },
    }
    model = SignalModel(
        Identity(),
        {
            "kind": "spectrum",
            "channels": ["acc"],
            "spectrum": spectrum,
            "statistical": None,
            "feature_names": names,
            "reference": reference,
        },
        {"fs_hz": fs, "n_samples": n, "channels": ["acc"], "speeds_rpm": [450.0, 900.0]},
        "healthy",
    )
    segments = model.predict_segments(table).set_index("record_id")["predicted_label"]
    assert segments.to_dict() == {"same": "healthy", "louder": "fault"}
    with pytest.raises(
        ValueError, match=r"speed_rpm 900: the model's healthy reference was taken at \[450.0\]"
    ):
        model.check(table.assign(speed_rpm=900.0))

"""How a gear fault is spread over the teeth and which tooth it sits on (residual_features:
`damaged_pitches`, `teeth_features`, `located_tooth`, the machine's tooth frame) and the report's
scoring of it (report/fault_location.py)."""

import numpy as np
import pandas as pd
import pytest

from condmon.features import FamilyInputs
from condmon.models.gear.drivetrain import GearDrivetrainParameters, SimulationSettings, simulate
from condmon.models.gear.errors import draw_gear_errors
from condmon.models.gear.mesh_force import mesh_phase_at
from condmon.report.fault_location import named_right, record_locations
from condmon.signals import make_rows
from condmon.systems.gear import residual_features as rf

P = 1024


def tooth_event(teeth: int, tooth: int, depth: float) -> np.ndarray:
    """One revolution (1, P): a dip over one tooth's pitch, smooth at its ends."""
    angle = np.arange(P) / P
    distance = (angle - (tooth + 0.5) / teeth + 0.5) % 1.0 - 0.5
    return -depth * np.exp(-0.5 * (distance * teeth / 0.2) ** 2)[None, :]


def test_a_broken_tooth_and_a_pitted_band_of_equal_energy_are_told_apart():
    """A broken tooth is one tooth's loss of contact, pitting a band of a few neighbouring teeth:
    with the same residual energy (no noise), the change spreads over about one pitch against
    about four, and its largest pitch holds most of it against about a quarter."""
    teeth = 29
    broken = tooth_event(teeth, 7, 1.0)
    pitted = sum(tooth_event(teeth, 7 + k, 1.0) for k in range(4))
    pitted *= np.sqrt(np.sum(broken**2) / np.sum(pitted**2))  # the same residual energy
    floor = 1e-3 * np.random.default_rng(0).normal(size=(1, P))  # a floor for the median pitch
    found = {
        name: rf.teeth_features(rf.damaged_pitches(signal + floor, teeth))
        for name, signal in (("broken", broken), ("pitted", pitted))
    }
    assert found["broken"]["participation"] < 1.5 < 3.0 < found["pitted"]["participation"] < 5.0
    assert found["broken"]["share1"] > 0.6 > 0.35 > found["pitted"]["share1"]
    assert found["pitted"]["share3"] > 0.65  # three of its four teeth
    assert rf.located_tooth(rf.damaged_pitches(broken + floor, teeth))[0] == 7
    # every tooth alike (wear) or nothing: spread over all of them
    assert rf.teeth_participation(np.ones(teeth)) == pytest.approx(teeth)
    assert rf.teeth_participation(np.zeros(teeth)) == teeth


def test_the_tooth_frame_turns_a_pattern_to_its_machines_reference():
    """A pattern that starts a quarter turn into the reference frame, turned back, is the
    reference's; the frames of two conditions whose references start a fifth of a turn apart are
    that far apart."""
    rng = np.random.default_rng(2)
    spectrum = np.zeros(P // 2 + 1, complex)
    spectrum[1:60] = rng.normal(size=59) + 1j * rng.normal(size=59)
    reference = np.fft.irfft(spectrum, n=P)[None, :]
    later = rf.shifted(reference, 0.25 * P)  # starts a quarter turn in
    np.testing.assert_allclose(rf.in_reference_frame(later, 0.25), reference, atol=1e-9)
    frames = rf.reference_frames(
        {450.0: [reference], 775.0: [rf.shifted(reference, 0.2 * P)]}, [("pinion", 1.0, 29)], [87]
    )
    assert frames[450.0][0] == pytest.approx(0.0, abs=1e-6)
    assert frames[775.0][0] % 1.0 == pytest.approx(0.2, abs=1e-3)


@pytest.mark.slow
def test_a_missing_tooth_is_located_on_its_tooth_on_a_pair_with_grade_6_errors():
    """The gear model with ISO grade-6 gears, tooth 3, 17 or 25 of the pinion missing: the
    residual against the same pair's healthy hunting cycle names a pitch the missing tooth meshes
    over, counted in the machine's tooth frame from where the healthy reference record starts (the
    truth from the mesh phase the model starts each record at), and not one further on."""
    rng = np.random.default_rng(6)
    base = GearDrivetrainParameters(speed_rpm=1100.0)
    g = base.geometry
    errors = {}
    for name, teeth in (("pinion", g.teeth_pinion), ("gear", g.teeth_gear)):
        gear = draw_gear_errors(
            rng, 6.0, teeth, g.normal_module, 2 * g.pitch_radius(teeth), g.face_width, 0.8
        )
        errors.update(
            {
                f"pitch_errors_{name}": gear.pitch_deviations,
                f"runout_{name}": gear.eccentricity,
                f"runout_phase_{name}": gear.eccentricity_phase,
            }
        )
    settings = SimulationSettings(
        duration=2.6, output_rate=5120.0, oversampling=6
    )  # a hunting cycle and more
    rows, fs = [], settings.output_rate
    half = int(1.3 * fs)
    records = [
        ("vb-healthy-1100rpm-r00", "healthy", 3.3, 0),
        ("vb-healthy-1100rpm-r01", "healthy", 21.9, 0),
    ]
    records += [
        (f"vb-missing_tooth-1100rpm-r{k:02d}", "missing_tooth", start, tooth)
        for k, (start, tooth) in enumerate([(40.7, 3), (7.2, 17), (1000.4, 25)])
    ]
    for record, state, start, tooth in records:
        params = base.replace(
            health_state=state, faulty_tooth=tooth, start_mesh_phase=start, **errors
        )
        signals = simulate(params, settings)
        truth = {
            "mesh_phase": mesh_phase_at(params, settings.settle_time),
            "damaged_teeth": [tooth] if state != "healthy" else [],
        }
        rows += make_rows(
            record,
            "virtual_bench",
            state,
            1100.0,
            params.load_torque,
            fs,
            {k: v[: 2 * half] for k, v in signals.items() if k in ("A1_x", "A1_y")},
            segment_length=half,
            params=truth,
        )
    frame = pd.DataFrame(rows)
    reserve = {
        "records": [],
        "healthy_records": 1,
        "calibration_segments": 4,
        "guard_segments": 1,
        "blocks": 2,
    }
    spec = {
        "source": "measured",
        "healthy_state": "healthy",
        "condition": "speed_rpm",
        "reserve": reserve,
    }
    table = rf.residual_feature_table(
        frame,
        ["A1_x", "A1_y"],
        {
            "shafts": [
                ["pinion", 1.0, g.teeth_pinion],
                ["gear", g.teeth_pinion / g.teeth_gear, g.teeth_gear],
            ],
            "damaged_shafts": ["pinion"],
            "contact_ratio": g.total_contact_ratio,
            "samples_per_revolution": P,
            "bands_per_mesh": 4,
            "mesh_harmonics": 3,
            "shaft_orders": 2,
            "phase_harmonic": 1,
            "phase_band_orders": 0.3,
            "phase_min_snr": 5.0,
        },
        FamilyInputs(healthy_reference=spec),
    )
    located = record_locations(
        table.attrs["fault_locations"].query("health_state == 'missing_tooth'")
    )
    ratio = g.total_contact_ratio
    for row in located.itertuples():
        assert row.agreement == 1.0 and row.share > 0.4
        assert row.named_right, (row.position, row.true_positions)
        # a pitch beyond those the tooth meshes over is not this one
        assert not named_right(
            (row.position + int(ratio) + 2) % g.teeth_pinion,
            row.true_positions,
            g.teeth_pinion,
            ratio,
        )

"""Gear trains of several pairs (`models/gear/drivetrain.py`: `GearStage`, `stage_parameters`):
each pair carries the torque its ratio gives, a fault repeats with the shaft of the pinion it
sits on, and a train the model cannot build is named."""

import json
import re

import numpy as np
import pandas as pd
import pytest
from scipy.signal import resample

from condmon.models.gear.drivetrain import (
    Drivetrain,
    GearDrivetrainParameters,
    GearStage,
    ShaftLayout,
    SimulationSettings,
    shaft_speeds,
    simulate,
    stage_parameters,
)
from condmon.models.gear.mesh import GearGeometry

RATE = 5120.0
SECOND_PAIR = GearGeometry(
    teeth_pinion=23, teeth_gear=47, normal_module=3.0e-3, helix_angle_deg=20.0, face_width=0.03
)


def two_stage(**changes) -> GearDrivetrainParameters:
    """The default pair driving a second, coarser pair (23 / 47 teeth) on a third shaft, one
    accelerometer on a housing of each shaft."""
    stage = GearStage(
        SECOND_PAIR,
        ShaftLayout(0.30, 0.040, (0.04, 0.22), 0.20, 0.30),
        pinion_mass=1.2,
        pinion_inertia=1.2e-3,
        gear_mass=4.0,
        gear_inertia=2.5e-2,
        mesh_stiffness=6.0e8,
    )
    return GearDrivetrainParameters(
        speed_rpm=1200.0,
        output_shaft=ShaftLayout(0.26, 0.030, (0.04, 0.24), 0.12, 0.20),
        stages=(stage,),
        sensors=(("A1", 0), ("A2", 2), ("A3", 4)),
        load_torque=40.0,
    ).replace(**changes)


def settled_deflections(p, seconds=0.4) -> np.ndarray:
    diagnostics = {}
    simulate(p, SimulationSettings(duration=seconds), diagnostics=diagnostics)
    deflections = diagnostics["deflections"]
    return deflections[len(deflections) // 3 :].mean(axis=0)


def test_each_pair_carries_the_torque_its_ratio_gives():
    """The train's mean mesh deflections are those of each pair alone, at the speed and the
    torque on its gear shaft the later pairs' ratios give (a wrong brake sense or torque would
    unload the second mesh or overload the first)."""
    p = two_stage(speed_rpm=300.0)
    first, second = stage_parameters(p)
    assert first.load_torque == pytest.approx(
        40.0 * SECOND_PAIR.base_radius(23) / SECOND_PAIR.base_radius(47)
    )
    assert second.speed_rpm == pytest.approx(300.0 * 29 / 44)
    assert shaft_speeds(p, 1.0) == pytest.approx([1.0, 29 / 44, 29 / 44 * 23 / 47])
    # the bench's bearing tones: a one-pair rig's shaft speed as it always was, to the bit
    one_pair = GearDrivetrainParameters()
    assert shaft_speeds(one_pair, 775 / 60) == [775 / 60, 775 / 60 * 29 / 44]
    in_train = settled_deflections(p)
    alone = [
        settled_deflections(
            GearDrivetrainParameters(
                speed_rpm=view.speed_rpm,
                geometry=view.geometry,
                mesh_stiffness=view.mesh_stiffness,
                load_torque=view.load_torque,
            )
        )[0]
        for view in (first, second)
    ]
    assert in_train == pytest.approx(alone, rel=0.01)
    assert in_train[1] > 5e-7  # loaded, not the back flank


def synchronous_share(signal: np.ndarray, shaft_hz: float) -> float:
    """The share of a signal's energy its average over the shaft's revolutions keeps."""
    per_revolution = RATE / shaft_hz
    revolutions = int(len(signal) / per_revolution)
    cycles = resample(
        signal[: int(round(revolutions * per_revolution))], revolutions * 256
    ).reshape(revolutions, 256)
    return float(np.sum(cycles.mean(axis=0) ** 2) * revolutions / np.sum(cycles**2))


@pytest.mark.slow
def test_a_spall_repeats_with_the_shaft_of_the_pinion_it_sits_on():
    """A spall on the first pair's pinion repeats with the input shaft, one on the second pair's
    pinion with the intermediate shaft, and the latter shows most at the output shaft's housing."""
    settings = SimulationSettings(duration=0.5)
    healthy = simulate(two_stage(), settings)
    shafts_hz = [20.0 * ratio for ratio in shaft_speeds(two_stage(), 1.0)[:2]]
    change = {}
    for stage in (0, 1):
        spalled = simulate(two_stage(health_state="spall", faulty_stage=stage), settings)
        change[stage] = {channel: spalled[channel] - healthy[channel] for channel in healthy}
        for channel, difference in change[stage].items():
            on_its_shaft = synchronous_share(difference, shafts_hz[stage])
            on_the_other = synchronous_share(difference, shafts_hz[1 - stage])
            assert on_its_shaft > 0.9 and on_the_other < 0.5, (stage, channel)

    def level(stage, channel):
        return np.std(change[stage][channel]) / np.std(healthy[channel])

    assert level(1, "A3_y") > 2 * level(0, "A3_y")


def test_a_train_the_model_cannot_build_is_named():
    with pytest.raises(ValueError, match="faulty_stage 2: the train has pairs 0..1"):
        stage_parameters(two_stage(faulty_stage=2))
    with pytest.raises(ValueError, match="faulty_stage 1: the train has one pair"):
        stage_parameters(GearDrivetrainParameters(faulty_stage=1))
    stage = two_stage().stages[0]
    off_plane = two_stage(
        stages=(
            GearStage(
                **{**stage.__dict__, "shaft": ShaftLayout(0.3, 0.04, (0.04, 0.22), 0.1, 0.3)}
            ),
        )
    )
    with pytest.raises(ValueError, match=r"stages\[0\]: its pinion .* one plane"):
        Drivetrain(off_plane)
    with pytest.raises(ValueError, match=r"damaged_shaft: 0 \(input shaft\) to 2"):
        Drivetrain(two_stage(shaft_model="flexible", health_state="shaft_crack", damaged_shaft=3))
    with pytest.raises(ValueError, match=r"stages\[0\].shaft.gear: position"):
        Drivetrain(
            two_stage(
                stages=(
                    GearStage(
                        **{
                            **stage.__dict__,
                            "shaft": ShaftLayout(0.3, 0.04, (0.04, 0.22), 0.4, 0.3),
                        }
                    ),
                )
            )
        )


def test_a_crack_in_the_intermediate_shaft_breathes_with_it():
    """Shaft damage on any shaft of the train: the crack's breathing follows its own shaft."""
    p = two_stage(
        shaft_model="flexible",
        health_state="shaft_crack",
        damaged_shaft=1,
        shaft_crack_position=0.08,
    )
    drivetrain = Drivetrain(p)
    (_, _, element), *_ = drivetrain.damaged_elements
    assert element.spin_hz == pytest.approx(20.0 * 29 / 44)
    assert len(drivetrain.housings) == 6


# -- the gear system's train: config, draws, bench ------------------------------------------------
TWO_STAGE = "config/benches/two-stage.yaml"


def test_a_train_from_its_config_names_every_gear_and_the_pinions_faults_sit_on():
    from conftest import system_of

    system = system_of(TWO_STAGE)
    assert system.shafts() == [
        ("pinion", 1.0, 29),
        ("gear", pytest.approx(29 / 44), 44),
        ("pinion_2", pytest.approx(29 / 44), 23),
        ("gear_2", pytest.approx(29 / 44 * 23 / 47), 47),
    ]
    assert system.damaged_shafts() == ["pinion", "pinion_2"]
    assert system.channels == ["a1", "a2", "a3"]
    p = system.parameters()
    (stage,) = p.stages
    assert (stage.geometry.teeth_pinion, stage.geometry.face_width) == (23, 0.030)
    # the material and angles the stage leaves out are the first pair's
    assert stage.geometry.pressure_angle_deg == p.geometry.pressure_angle_deg
    # a further pair's mesh stiffness follows the first pair's (calibration, a bench's truth)
    doubled = system.parameters(mesh_stiffness=2 * p.mesh_stiffness)
    assert doubled.stages[0].mesh_stiffness == pytest.approx(2 * stage.mesh_stiffness)
    assert system.problems() == []


@pytest.mark.parametrize(
    "changes, named",
    [
        ({"model": {"faulty_stages": [0, 2]}}, "model.faulty_stages: pair 2 of a train of 2"),
        ({"model": {"damaged_shaft": 3}}, "model.damaged_shaft: shaft 3 of a train of 3 shafts"),
        (
            {
                "virtual_bench": {
                    "faults": {
                        "missing_tooth": {"form": "broken_tooth", "broken_height": 0.5, "stage": 2}
                    }
                }
            },
            "virtual_bench.faults.missing_tooth.stage: pair 2 of a train of 2",
        ),
        (
            {"model": {"sensors": {"a1": {"housing": 6, "directions": ["y"]}}}},
            "sensors: a1 on housing 6; the rig has housings 0..5",
        ),
    ],
)
def test_a_pair_shaft_or_housing_the_train_lacks_is_named_before_any_job(changes, named):
    from conftest import system_of

    from condmon.config import ConfigError

    with pytest.raises(ConfigError, match=re.escape(named)):
        system_of(TWO_STAGE, changes)


def test_each_simulated_train_draws_its_own_pairs_and_the_pair_its_fault_sits_on():
    """The first pair's draws stay a one-pair drivetrain's; each further pair gets gears of its
    own; the faulty pair is drawn over `model.faulty_stages`."""
    from conftest import system_of

    from condmon.systems.gear.parameters import sample_effects

    system = system_of(TWO_STAGE)
    model, p = system.config["model"], system.parameters()
    effects = [
        sample_effects(model, p.geometry, np.random.default_rng(k), p.stages) for k in range(12)
    ]
    alone = sample_effects(model, p.geometry, np.random.default_rng(0))
    assert effects[0]["pitch_errors_pinion"] == alone["pitch_errors_pinion"]
    assert effects[0]["start_mesh_phase"] == alone["start_mesh_phase"]
    (stage,) = effects[0]["stages"]
    assert len(stage.pitch_errors_pinion) == 23 and len(stage.flank_maps_pinion) == 23
    assert stage.pitch_errors_pinion != effects[1]["stages"][0].pitch_errors_pinion
    assert {e["faulty_stage"] for e in effects} == {0, 1}


def test_the_bench_damages_the_pair_its_fault_names_and_records_which():
    """A broken tooth on the second pair's pinion repeats with the intermediate shaft; its
    records carry the pair as truth."""
    from conftest import system_of

    from condmon.systems.gear import BENCH_NUMERICS
    from condmon.systems.gear.bench import virtual_bench_rows

    system = system_of(TWO_STAGE)
    bench = dict(system.config["virtual_bench"], records_per_state=1, record_seconds=1.5)
    numerics = dict(system.numerics, **{k: bench[k] for k in BENCH_NUMERICS})
    point = [p for p in system.operating_points if p.load == 300.0]
    rows = virtual_bench_rows(
        system.parameters,
        bench,
        ["missing_tooth"],
        point,
        numerics,
        1.5,
        load_torque=system.load_torque,
        table_load=system.table_load,
    )
    truth = json.loads(rows[0]["params"])
    assert truth["damaged_stage"] == 1 and truth["damaged_teeth"] == [bench["faulty_tooth"]]
    assert {row["load"] for row in rows} == {300.0}


def test_the_part_holding_the_most_change_is_where_the_report_places_the_fault():
    """Per record, the located part whose change is largest holds the fault; scored against the
    bench's damaged part (a record of one part, or without truth, is not scored)."""
    from condmon.report.fault_location import part_named_right, record_locations

    def segment(record, part, level, true_part):
        return {
            "record_id": record,
            "health_state": "missing_tooth",
            "speed_rpm": 900.0,
            "part": part,
            "positions": 23,
            "span": 1.6,
            "position": 3,
            "share": 0.5,
            "true_positions": "[]",
            "level": level,
            "true_part": true_part,
        }

    located = pd.DataFrame(
        [
            segment("right", "pinion", 0.2, False),
            segment("right", "pinion_2", 4.0, True),
            segment("right", "pinion_2", 2.0, True),
            segment("wrong", "pinion", 5.0, False),
            segment("wrong", "pinion_2", 1.0, True),
            segment("alone", "pinion", 5.0, True),
            segment("unknown", "pinion", 1.0, None),
            segment("unknown", "pinion_2", 3.0, None),
        ]
    )
    table = record_locations(located).set_index(["record_id", "part"])
    assert table.loc[("right", "pinion_2"), "holds_change"]
    assert table.loc[("right", "pinion_2"), "level"] == pytest.approx(3.0)
    assert not table.loc[("wrong", "pinion_2"), "holds_change"]
    assert part_named_right(table.reset_index()) == pytest.approx(0.5)


def test_the_damaged_part_a_bench_record_carries_is_its_pairs_pinion():
    from condmon.systems.gear.residual_features import true_parts, true_positions

    shafts = [("pinion", 1.0, 29), ("gear", 0.66, 44), ("pinion_2", 0.66, 23), ("gear_2", 0.3, 47)]
    frame = pd.DataFrame(
        {
            "record_id": ["a", "b", "c"],
            "params": [
                json.dumps({"mesh_phase": 1.0, "damaged_teeth": [3]}),
                json.dumps({"mesh_phase": 2.0, "damaged_teeth": [5], "damaged_stage": 1}),
                "",
            ],
        }
    )
    assert true_parts(frame, shafts) == {"a": "pinion", "b": "pinion_2"}
    # the tooth frame is the first pair's: a further pair's tooth is not scored against it
    assert true_positions(frame, 0.0, 29) == {"a": [3.0]}


def test_the_two_gears_of_the_intermediate_shaft_share_its_one_pattern():
    """A train's shafts kept apart in a record far shorter than its hunting cycle: the input
    shaft's pattern as for a pair, the intermediate shaft's one pattern given to both its gears
    (two patterns of one shaft would split it between them at random)."""
    from condmon.systems.gear import residual_features as rf

    P, fs, speed = 256, 5120.0, 900.0
    gears = [("pinion", 1.0, 29), ("gear", 29 / 44, 44), ("pinion_2", 29 / 44, 23)]
    gears.append(("gear_2", 29 / 44 * 23 / 47, 47))
    rng = np.random.default_rng(5)
    grid = np.arange(P) / P

    def pattern(teeth):
        orders = [o for o in range(1, 40) if o % teeth]
        return sum(
            rng.normal(0, 1 / o) * np.cos(2 * np.pi * o * grid + rng.uniform(0, 6.3))
            for o in orders
        )

    truth = {ratio: pattern(teeth) for _, ratio, teeth in gears[:2] + gears[3:]}
    t = np.arange(int(3.0 * fs)) / fs
    angle = speed / 60 * t
    x = sum(
        np.interp((angle * ratio) % 1.0, np.append(grid, 1.0), np.append(p, p[0]))
        for ratio, p in truth.items()
    )
    x = (x + rng.normal(0, 0.05, len(t)))[None, :]
    patterns = rf.shaft_patterns(x, angle, gears, P)
    assert patterns[1] is patterns[2]

    def error(estimate, ratio):
        reference = truth[ratio] - truth[ratio].mean()
        return np.sqrt(np.mean((estimate[0] - reference) ** 2)) / reference.std()

    assert error(patterns[0], 1.0) < 0.1
    assert error(patterns[1], 29 / 44) < 0.2


def test_a_trains_drawn_mesh_compliance_is_its_first_pairs_deflection_under_its_own_torque():
    from conftest import system_of

    from condmon.models.gear.mesh_force import operating_deflection
    from condmon.systems.gear.parameters import draw_mesh_compliance

    system = system_of(TWO_STAGE)
    compliance = {"deflection": [8.0e-7, 8.0e-7], "contact_exponent": [1.5, 1.5]}
    drawn = draw_mesh_compliance(compliance, system.parameters(), np.random.default_rng(0))
    first = stage_parameters(system.parameters(**drawn))[0]
    assert operating_deflection(first) == pytest.approx(8.0e-7)


def test_an_auto_deflection_range_follows_iso_6336_at_the_rigs_load():
    """`mesh_compliance.deflection: auto` holds the standard's estimate at any load (with its
    light-load reduction below 100 N/mm only), as the default run's hand-set range does at its
    10 N m; a train takes its first pair under that pair's own torque."""
    from conftest import system_of

    from condmon.models.gear.mesh_force import iso6336_deflections
    from condmon.systems.gear.parameters import deflection_range

    auto = {"deflection": "auto", "contact_exponent": [1.0, 1.5]}
    light = system_of("config/config.yaml")  # 10 N m: 9 N/mm of face width
    low, high = deflection_range(auto, light.parameters())
    linear, reduced = iso6336_deflections(light.parameters())
    assert reduced > 1.5 * linear  # the standard's light-load reduction applies
    assert low < linear < reduced < high
    assert (low, high) == pytest.approx(
        light.config["model"]["mesh_compliance"]["deflection"], rel=0.05
    )
    train = system_of(TWO_STAGE)  # 300 N m on the output: 133 N/mm on both pairs
    first = stage_parameters(train.parameters())[0]
    linear, reduced = iso6336_deflections(first)
    assert reduced == linear  # above 100 N/mm: no reduction
    low, high = deflection_range(auto, train.parameters())
    assert low < linear < high and 2.5 < high / low < 4.0
    # the same range whatever the output torque's way through the later pair: the first pair's own
    assert deflection_range(auto, train.parameters()) == deflection_range(auto, first)


def test_a_deflection_range_kept_from_another_load_is_refused_naming_the_standards():
    from conftest import system_of

    from condmon.config import ConfigError

    light_range = {"mesh_compliance": {"deflection": [3.7e-7, 1.33e-6]}}
    with pytest.raises(ConfigError, match=r"ISO 6336-1 puts the first pair at 3.18-10.6 um"):
        system_of(TWO_STAGE, {"model": light_range})


def test_a_trains_bench_mesh_is_compared_with_the_drawn_range_at_its_first_pairs_torque():
    from conftest import system_of

    (mesh,) = [
        row
        for row in system_of(TWO_STAGE).bench_differences()
        if "mesh_stiffness" in row["difference"]
    ]
    # the bench's first pair under 146.8 N m (not the output's 300 N m): 3.57 um
    assert mesh["difference"].endswith("a static deflection of 3.57 um")
    assert "[3.18, 10.6] um" in mesh["how"] and mesh["within_range"]


def test_a_calibrated_deflection_range_is_where_the_cost_profile_is_lowest():
    """`mesh_compliance.deflection: calibrated`: the profile of a cost lowest at a known deflection
    (its mesh as `deflection_profile` sets it) keeps the grid points about it, a grid step either
    side; the simulation then draws only there, and without the calibration's profile it stops
    naming the key."""
    from conftest import system_of

    from condmon.models.gear.mesh_force import operating_deflection
    from condmon.systems.gear.parameters import (
        deflection_profile,
        deflection_range,
        draw_mesh_compliance,
        profile_range,
    )

    assert profile_range([1, 2, 3, 4, 5], [0.5, 0.3, 0.2, 0.21, 0.4]) == (2.0, 5.0)
    assert profile_range([1, 2, 3], [0.1, 0.5, 0.6]) == (1.0, 2.0)  # within the grid
    train = system_of(TWO_STAGE)
    compliance = {"deflection": "calibrated", "contact_exponent": [1.0, 1.5]}
    params = train.parameters()
    truth = 4.0e-6

    def cost(values):  # lowest where the first pair deflects `truth` under its torque
        first = stage_parameters(train.parameters(**values))[0]
        return abs(np.log(operating_deflection(first) / truth))

    profile = deflection_profile(cost, compliance, params)
    grid = np.array(profile["deflection"])
    assert (grid[0], grid[-1]) == pytest.approx(deflection_range(compliance, params))
    low, high = profile["range"]
    assert low < truth < high and high / low < 1.7  # two grid steps of a 9-point grid
    rng = np.random.default_rng(0)
    for _ in range(5):
        drawn = draw_mesh_compliance(compliance, params, rng, profile["range"])
        first = stage_parameters(train.parameters(**drawn))[0]
        assert low * 0.999 <= operating_deflection(first) <= high * 1.001
    with pytest.raises(ValueError, match="deflection: calibrated, but the calibration"):
        draw_mesh_compliance(compliance, params, rng)
    # the bench's mesh is compared with the range the calibration searched
    calibrated = system_of(TWO_STAGE, {"model": {"mesh_compliance": {"deflection": "calibrated"}}})
    (mesh,) = [r for r in calibrated.bench_differences() if "mesh_stiffness" in r["difference"]]
    assert "calibrated within [3.18, 10.6] um" in mesh["how"]
    # its calibration job takes the profile, so it sees the compliance; an `auto` one's does not
    assert "mesh_compliance" in calibrated.job_config("calibrate")["model"]
    auto = system_of(TWO_STAGE, {"model": {"mesh_compliance": {"deflection": "auto"}}})
    assert "mesh_compliance" not in auto.job_config("calibrate")["model"]

"""Gear trains of several pairs (`models/gear/drivetrain.py`: `GearStage`, `stage_parameters`):
each pair carries the torque its ratio gives, a fault repeats with the shaft of the pinion it
sits on, and a train the model cannot build is named."""

import numpy as np
import pytest
from scipy.signal import resample

from condmon.models.gear.drivetrain import (
    Drivetrain,
    GearDrivetrainParameters,
    GearStage,
    ShaftLayout,
    SimulationSettings,
    shaft_speed_ratios,
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
    assert shaft_speed_ratios(p) == pytest.approx([1.0, 29 / 44, 29 / 44 * 23 / 47])
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
    shafts_hz = [20.0 * ratio for ratio in shaft_speed_ratios(two_stage())[:2]]
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

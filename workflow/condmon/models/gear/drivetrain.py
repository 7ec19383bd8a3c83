"""3-D multibody model of the helical-gear test rig (pinion 29 / gear 44 teeth) in exudyn.

Pure: parameters in, housing accelerations out. Knows nothing of Snakemake or MLflow.

The rig (`structure.py` building blocks, shafts along z, the gear shaft beside the pinion shaft at
the centre distance along x):
- two shafts (one pair; `stages` adds a pair and a shaft each, side by side along x, the
  brake on the last shaft), each a rigid body with 6 coordinates (`shaft_model: rigid`) or a
  Timoshenko beam through nodes at its ends, bearings and gear (`flexible`); the gear bodies and
  the coupling and brake hubs are masses with inertia on them;
- each shaft on two bearings at their axial positions: bushings with radial x, radial y and axial
  stiffness and damping to a bearing housing; each housing a point mass on the base with its own
  stiffness per axis (`housing_model: point`), or a rigid block on four feet with rocking modes
  (`block`, the virtual bench's);
- the motor drives the pinion shaft through a torsional coupling at the nominal speed; the brake
  loads the gear shaft with a torque that may fluctuate slowly (a compiled exudyn load function);
- each mesh acts at its pitch point along the helical pair's line of action
  n = n_t + tan(beta_b) e_z (transverse line of action plus the axial component), so its axial
  force and the tilting moments of both components reach the shafts and bearings. Its deflection
  is the transverse-equivalent mesh deflection, a linear function of the coordinates (`mesh_rows`).

exudyn holds the linear structure in one sparse ObjectGenericODE2 (why not one item per body:
`structure.py`), with the mesh deflection in place of one of its coordinates so the whole nonlinear
mesh (`mesh_force.py`: potential-energy TVMS, damping ratio, impact laws, damage, pitch errors,
run-out, speed fluctuation) is one scalar ObjectConnectorCoordinateSpringDamper per pair, each
pair's mesh built as a one-pair drivetrain's from `stage_parameters` (its speed, torque, deviations
and fault). Angles are
deviations from the nominal rotation, so the mesh stiffness is a function of time. Sensors record
all accelerations above the output rate; the housing channels (`sensors`: which housings carry an
accelerometer) are low-pass filtered and decimated to the output rate (no aliasing) and checked
finite.

The same model is the CFRP rig (`systems/cfrp`): tube shafts of a laminate (`shaft_sections`,
`models/cfrp/laminate.py`), spur gears, four accelerometers, and shaft damage (`shaft_crack`,
`delamination`; `shaft_damage.py`) on flexible shafts. `numerics.modal_cutoff_hz` reduces the
structure by Craig-Bampton (`model_matrices`), which the flexible shafts need to keep one step
per sensor sample.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np
from scipy.signal import resample_poly

from condmon.models.gear.mesh import GearGeometry
from condmon.models.gear.mesh_force import (
    HEALTH_STATES,
    MESH_HEALTH_STATES,
    MESH_STIFFNESS_MODELS,
    MeshForce,
    mesh_damping,
    operating_stiffness,
)
from condmon.models.gear.shaft_damage import (
    RELATIVE_ROTATION,
    SHAFT_HEALTH_STATES,
    DamagedElement,
    ShaftDamageForce,
    crack_section_ratios,
    delamination_section_ratios,
    removed_rotational_stiffness,
)
from condmon.models.numerics import SimulationError, decimation_filter, exudyn_system, solve_rk44
from condmon.models.structure import BENDING_PLANES, LinearStructure, Section

SHAFT_MODELS = ("rigid", "flexible")
HOUSING_MODELS = ("point", "block")
# Accelerometers: (name, bearing housing[, directions]), housings 0 and 1 carry the pinion shaft's
# bearings, 2 and 3 the gear shaft's. The helical rig: A1 on the pinion shaft's drive-side bearing,
# A2 on the gear shaft's first bearing, each along x and y.
SENSORS = (("A1", 0), ("A2", 2))
AXES = ("x", "y")


def sensor_directions(sensor) -> tuple:
    """The directions one accelerometer (name, housing[, directions]) measures along: "x", "y"
    (the housing's horizontal and vertical axes, across the shaft) or an angle in degrees from x
    towards y; x and y when none are given."""
    directions = tuple(sensor[2]) if len(sensor) > 2 else AXES
    for direction in directions:
        if direction not in AXES and not isinstance(direction, (int, float)):
            raise ValueError(
                f"sensors: {sensor[0]} direction {direction!r}; give x, y or an angle in degrees"
            )
    if not directions or len(set(directions)) != len(directions):
        raise ValueError(
            f"sensors: {sensor[0]} directions {list(directions)}: one or more, distinct"
        )
    return directions


def direction_weights(direction) -> tuple[float, float]:
    """(x, y) weights of the housing's acceleration an accelerometer along `direction` reads (exact
    for x and y: their channels are the housing's own coordinates to the last bit)."""
    if direction in AXES:
        return (1.0, 0.0) if direction == "x" else (0.0, 1.0)
    angle = math.radians(direction)
    return math.cos(angle), math.sin(angle)


def sensor_outputs(sensors=SENSORS) -> list[tuple[str, str, tuple]]:
    """(channel, sensor name, direction) of every channel a set of accelerometers records: a
    one-axis sensor's channel is its name; a sensor of several axes gives <name>_<axis> each."""
    outputs = []
    for sensor in sensors:
        directions = sensor_directions(sensor)
        for direction in directions:
            suffix = direction if isinstance(direction, str) else f"{direction:g}"
            channel = sensor[0] if len(directions) == 1 else f"{sensor[0]}_{suffix}"
            outputs.append((channel, sensor[0], direction))
    channels = [channel for channel, _, _ in outputs]
    if len(set(channels)) != len(channels):
        raise ValueError(f"sensors: channels {channels} are not distinct")
    return outputs


def sensor_channels(sensors=SENSORS) -> tuple[str, ...]:
    """The channels a set of accelerometers records (`sensor_outputs`)."""
    return tuple(channel for channel, _, _ in sensor_outputs(sensors))


CHANNELS = sensor_channels()

__all__ = [
    "CHANNELS",
    "HEALTH_STATES",
    "MESH_STIFFNESS_MODELS",
    "GearDrivetrainParameters",
    "GearStage",
    "ShaftLayout",
    "SimulationSettings",
    "PeriodicLoad",
    "Drivetrain",
    "simulate",
    "operating_mesh_stiffness",
    "shaft_speeds",
    "stage_parameters",
]


@dataclass(frozen=True)
class ShaftLayout:
    """A shaft along z from 0 to `length` (m): solid diameter, bearing and gear positions, and
    the position of its coupling (pinion shaft) or brake (gear shaft) hub."""

    length: float
    diameter: float
    bearings: tuple
    gear: float
    hub: float
    inner_diameter: float = 0.0  # a tube's bore (0: solid)

    def check(self, name: str) -> None:
        for label, z in (
            ("bearings", self.bearings[0]),
            ("bearings", self.bearings[1]),
            ("gear", self.gear),
            ("hub", self.hub),
        ):
            if not 0.0 <= z <= self.length:
                raise ValueError(
                    f"{name}.{label}: position {z} m outside the shaft (0..{self.length} m)"
                )
        if len(self.bearings) != 2 or self.bearings[0] >= self.bearings[1]:
            raise ValueError(
                f"{name}.bearings: two increasing axial positions, got {self.bearings}"
            )
        if not 0.0 <= self.inner_diameter < self.diameter:
            raise ValueError(
                f"{name}.inner_diameter: {self.inner_diameter} m must lie in [0, diameter "
                f"{self.diameter} m)"
            )


@dataclass(frozen=True)
class GearStage:
    """A further gear pair of the train. Its pinion sits on the previous stage's gear shaft, at
    that shaft's `hub` position; its gear on a shaft of its own (`shaft`, beside the previous one
    along x at the pair's centre distance), whose `hub` carries the next stage's pinion or, on the
    last shaft, the brake. The pair's own deviations (empty: none) and mesh; the contact law,
    damping, backlash and slicing are the train's."""

    geometry: GearGeometry
    shaft: ShaftLayout
    pinion_mass: float
    pinion_inertia: float
    gear_mass: float
    gear_inertia: float
    mesh_stiffness: float
    pitch_errors_pinion: tuple = ()
    pitch_errors_gear: tuple = ()
    flank_maps_pinion: tuple = ()
    runout_pinion: float = 0.0
    runout_gear: float = 0.0
    runout_phase_pinion: float = 0.0
    runout_phase_gear: float = 0.0
    start_mesh_phase: float = 0.0


class DamageZone(NamedTuple):
    """The damaged stretch of a shaft: its section (with the damage's shear loss) and the
    `DamagedElement` of an element of a given length in it."""

    shaft: int
    start: float
    end: float
    section: Section
    element: Callable[[float], DamagedElement]


@dataclass(frozen=True)
class PeriodicLoad:
    """A sinusoidal generalized force on one coordinate: `target` is ("motor", None) for a torque
    on the pinion shaft's coupling node, or ("housing", i) for a radial (y) force on housing i."""

    target: tuple
    amplitude: float
    frequency_hz: float
    phase: float = 0.0


@dataclass
class GearDrivetrainParameters:
    """Physical parameters; SI units. Defaults are the nominal (uncalibrated) rig."""

    geometry: GearGeometry = field(default_factory=GearGeometry)
    # Shafts (steel) and what sits on them.
    input_shaft: ShaftLayout = ShaftLayout(0.24, 0.025, (0.04, 0.16), 0.12, 0.0)
    output_shaft: ShaftLayout = ShaftLayout(0.26, 0.030, (0.04, 0.18), 0.12, 0.26)
    shaft_model: str = "rigid"
    # Sections (structure.Section) of the input and output shafts when not steel tubes of the
    # layouts' diameters (the CFRP rig's laminate tubes); empty: steel.
    shaft_sections: tuple = ()
    shaft_youngs_modulus: float = 2.1e11
    shaft_poisson_ratio: float = 0.3
    shaft_density: float = 7850.0
    shaft_element_length: float = 0.08  # longest beam element of a flexible shaft, m
    shaft_damping: float = 2.0e-6  # flexible shafts: C = shaft_damping x K (s)
    pinion_mass: float = 0.57  # gear bodies (without shaft), kg
    pinion_inertia: float = 4.2e-4  # polar, kg m^2 (transverse: half)
    gear_mass: float = 1.38
    gear_inertia: float = 2.2e-3
    coupling_mass: float = 0.5  # coupling half on the pinion shaft
    coupling_inertia: float = 3.0e-4
    brake_mass: float = 0.8  # brake hub on the gear shaft
    brake_inertia: float = 1.0e-3
    # Bearings as bushings (CFRP study Table 3: 1.825e5 N/mm, 12.3 N s/mm radial).
    bushing_stiffness: float = 1.825e8
    bushing_damping: float = 1.23e4
    bushing_axial_stiffness: float = 5.0e7
    bushing_axial_damping: float = 3.0e3
    # Bearing housings on the base, stiffness and damping per axis (x horizontal, y vertical, z).
    housing_model: str = "point"
    housing_mass: float = 2.0
    housing_stiffness: tuple = (4.0e7, 1.2e8, 6.0e7)
    housing_damping: tuple = (2.0e3, 3.0e3, 2.0e3)
    # Block housings (housing_model: block): inertia, and the feet relative to the bearing centre.
    housing_inertia: tuple = (4.0e-3, 3.0e-3, 4.0e-3)
    housing_foot_height: float = 0.06  # bearing centre above the feet, m
    housing_foot_span: tuple = (0.05, 0.03)  # half distances of the four feet in x and z, m
    sensor_height: float = 0.04  # accelerometer above the bearing centre, m
    sensors: tuple = SENSORS
    # Drive and load.
    coupling_stiffness: float = 2.0e3  # N m/rad, motor to pinion shaft
    coupling_damping: float = 0.5  # N m s/rad
    load_torque: float = 10.0  # on the gear shaft, N m
    load_fluctuation: float = 0.0  # relative amplitude of a slow sinusoidal load variation
    load_fluctuation_hz: float = 0.8
    load_fluctuation_phase: float = 0.0
    speed_rpm: float = 1100.0  # input shaft
    speed_fluctuation: float = 0.0  # relative amplitude of a slow sinusoidal speed variation
    speed_fluctuation_hz: float = 1.5
    speed_fluctuation_phase: float = 0.0
    # Mesh periods already run at t = 0: which tooth pair meshes when the run starts (an acquisition
    # starts at any shaft angle; 0: tooth 0 of both gears entering mesh).
    start_mesh_phase: float = 0.0
    # Gear mesh: F = K delta^n per pair, viscous damping of ratio zeta, Table-1 law on impacts.
    mesh_stiffness_model: str = "potential_energy"
    helix_slices: int = 80
    # Face strips a flank's contact line splits into, in fractions of the operating deflection
    # (0: the line touches at its slices' mean deviation); see GearMesh.contact_step.
    flank_contact_step: float = 0.0
    contact_law: str = "lankarani_nikravesh"
    mesh_stiffness: float = 4.0e8  # mean mesh stiffness at 1 um deflection, N/m
    contact_exponent: float = 1.5
    restitution: float = 0.9
    mesh_damping_ratio: float = 0.05
    backlash: float = 1.0e-4  # along the line of action, m
    transmission_error: float = 0.3e-6  # static TE amplitude at mesh frequency, m
    tip_relief: float = 0.0
    # Manufacturing: run-out (eccentricity) of each shaft along the line of action and the
    # single pitch deviation of every tooth (empty: none), m.
    runout_pinion: float = 0.0
    runout_gear: float = 0.0
    runout_phase_pinion: float = 0.0
    runout_phase_gear: float = 0.0
    pitch_errors_pinion: tuple = ()
    pitch_errors_gear: tuple = ()
    # Flank deviations of every pinion tooth (`errors.FlankMap`, material removed; empty:
    # none): profile and helix deviations and misalignment.
    flank_maps_pinion: tuple = ()
    # Damage of every pinion tooth beyond its health state's own (`errors.FlankMap`, material
    # removed; empty: none): a bench's own damage. Its contact is split by depth (`GearMesh`).
    damage_maps_pinion: tuple = ()
    # Further gear pairs (`GearStage`), the first pair's gear shaft driving the second's pinion
    # and so on; the brake and `load_torque` then sit on the last shaft (empty: one pair).
    stages: tuple = ()
    # Health.
    health_state: str = "healthy"
    # the pair whose pinion carries a gear fault (0: the first; shaft faults: `damaged_shaft`)
    faulty_stage: int = 0
    faulty_tooth: int = 0
    surface_fault_teeth: int = 3
    surface_fault_model: str = (
        "pitting"  # or "stiffness_loss" / "mesh_stiffness_loss" (the CFRP study's)
    )
    wear_depth: float = 2.0e-5  # wear: material removed at root and tip, m
    wear_roughness: float = 2.0e-6  # rms of the worn surface, m
    pit_depth: float = 3.0e-5  # pitting: the deepest crater, m
    pitted_area: float = 0.3  # pitting: share of the contact-fatigue band pitted
    pitting_growth: float = 0.0  # pitting: roll fraction it spread beyond that band, each side
    wear_seed: int = 0  # the damaged surfaces' draw
    surface_fault_stiffness_loss: float = 0.15
    spall_profile: tuple = (0.35, 0.65)
    spall_face: tuple = (0.25, 0.75)
    spall_depth: float = 2.0e-5
    # missing_tooth: the share of the faulty tooth's active profile broken off, from the tip (1: the
    # whole tooth is gone; below 1 a fracture across the face, errors.broken_tooth_flank_map)
    missing_share: float = 1.0
    chip_profile: float = 0.6
    chip_face: tuple = (0.0, 0.5)
    crack_depth: float = 0.5
    # Shaft damage (flexible shafts, `shaft_damage.py`) on shaft 0 (pinion) or 1 (gear): a
    # breathing crack of relative depth a / D at an axial position, its mouth at an angle from x at
    # t = 0; a delamination over a length, at a depth of the wall (fraction from the outside) and
    # over an arc of the circumference.
    damaged_shaft: int = 0
    shaft_crack_position: float = 0.08
    shaft_crack_depth: float = 0.3
    shaft_crack_angle_deg: float = 0.0
    delamination_start: float = 0.06
    delamination_length: float = 0.04
    delamination_interface_depth: float = 0.5
    delamination_arc_deg: float = 120.0

    def replace(self, **changes) -> "GearDrivetrainParameters":
        return dataclasses.replace(self, **changes)


def operating_mesh_stiffness(p: GearDrivetrainParameters) -> float:
    """Linearised mean mesh stiffness (N/m) of the first pair under the static load of `p`."""
    return operating_stiffness(stage_parameters(p)[0])


def shaft_speeds(p: GearDrivetrainParameters, input_speed: float) -> list[float]:
    """Each shaft's speed (input shaft first) when the input shaft turns at `input_speed` (any
    unit): `input_speed` times the pinions' teeth over the gears' teeth up to that shaft."""
    speeds, pinions, gears = [input_speed], 1, 1
    for g in [p.geometry] + [stage.geometry for stage in p.stages]:
        pinions, gears = pinions * g.teeth_pinion, gears * g.teeth_gear
        speeds.append(input_speed * pinions / gears)
    return speeds


def stage_parameters(p: GearDrivetrainParameters) -> list[GearDrivetrainParameters]:
    """One parameter set per gear pair, as a one-pair drivetrain sees its mesh: the pair's
    geometry, deviations and mesh stiffness, its pinion's speed, the torque on its gear shaft
    (the output torque through the later pairs' ratios) and the gear fault only on the pair
    `faulty_stage` names. One pair: `p` itself."""
    if not p.stages:
        if p.faulty_stage != 0:
            raise ValueError(f"faulty_stage {p.faulty_stage}: the train has one pair (stage 0)")
        return [p]
    if not 0 <= p.faulty_stage <= len(p.stages):
        raise ValueError(f"faulty_stage {p.faulty_stage}: the train has pairs 0..{len(p.stages)}")
    ratios = shaft_speeds(p, 1.0)
    geometries = [p.geometry] + [stage.geometry for stage in p.stages]
    torques = [p.load_torque]  # on each pair's gear shaft, the last pair's first
    for g in reversed(geometries[1:]):
        torques.insert(0, torques[0] * g.base_radius(g.teeth_pinion) / g.base_radius(g.teeth_gear))
    views = []
    for k, g in enumerate(geometries):
        fault_elsewhere = p.health_state in MESH_HEALTH_STATES and k != p.faulty_stage
        changes = dict(
            speed_rpm=p.speed_rpm * ratios[k],
            load_torque=torques[k],
            health_state="healthy" if fault_elsewhere else p.health_state,
            damage_maps_pinion=() if k != p.faulty_stage else p.damage_maps_pinion,
            stages=(),
            faulty_stage=0,
        )
        if k:  # a further pair's own fields (its shaft aside) are parameters of the same names
            stage = p.stages[k - 1]
            changes.update(
                {
                    f.name: getattr(stage, f.name)
                    for f in dataclasses.fields(stage)
                    if f.name != "shaft"
                }
            )
        views.append(p.replace(**changes))
    return views


class Drivetrain:
    """The assembled linear structure of `p` and where the mesh, loads and sensors attach."""

    def __init__(self, p: GearDrivetrainParameters):
        if p.shaft_model not in SHAFT_MODELS:
            raise ValueError(
                f"unknown shaft_model {p.shaft_model!r}; choose one of {list(SHAFT_MODELS)}"
            )
        if p.housing_model not in HOUSING_MODELS:
            raise ValueError(
                f"unknown housing_model {p.housing_model!r}; choose one of {list(HOUSING_MODELS)}"
            )
        p.input_shaft.check("input_shaft")
        p.output_shaft.check("output_shaft")
        for k, stage in enumerate(p.stages, start=1):
            stage.shaft.check(f"stages[{k - 1}].shaft")
        self.p = p
        self.stages = stage_parameters(p)
        s = self.structure = LinearStructure()
        # The shafts side by side along x, each pair's gear shaft at its centre distance beyond
        # its pinion's; on each shaft its pinion or gear body and at its hub the coupling (input),
        # the next pair's pinion or, on the last shaft, the brake.
        layouts = self.layouts = [p.input_shaft, p.output_shaft] + [
            stage.shaft for stage in p.stages
        ]
        wheels = [(p.pinion_mass, p.pinion_inertia), (p.gear_mass, p.gear_inertia)] + [
            (stage.gear_mass, stage.gear_inertia) for stage in p.stages
        ]
        hubs = (
            [(p.coupling_mass, p.coupling_inertia)]
            + [(stage.pinion_mass, stage.pinion_inertia) for stage in p.stages]
            + [(p.brake_mass, p.brake_inertia)]
        )
        self.shaft_x = [0.0]
        for view in self.stages:
            g = view.geometry
            self.shaft_x.append(
                self.shaft_x[-1] + g.pitch_radius(g.teeth_pinion) + g.pitch_radius(g.teeth_gear)
            )
        self.sections = self._shaft_sections()
        self.damage = self._damage_zone()
        self.damaged_elements = []  # (node a, node b, DamagedElement)
        self.shaft_nodes = [
            self._add_shaft(shaft, x, layout, wheel, hub)
            for shaft, (x, layout, wheel, hub) in enumerate(
                zip(self.shaft_x, layouts, wheels, hubs)
            )
        ]
        self.housings = []
        for shaft, (x, layout) in enumerate(zip(self.shaft_x, layouts)):
            for z in layout.bearings:
                housing = self._add_housing((x, 0.0, z))
                self.housings.append(housing)
                s.add_spring(
                    (self.node_at(shaft, z), (x, 0.0, z)),
                    (housing, (x, 0.0, z)),
                    [p.bushing_stiffness, p.bushing_stiffness, p.bushing_axial_stiffness],
                    [p.bushing_damping, p.bushing_damping, p.bushing_axial_damping],
                )
        self.coupling_node = self.node_at(0, p.input_shaft.hub)
        s.add_coordinate_spring(self.coupling_node, 5, p.coupling_stiffness, p.coupling_damping)
        self.load_dof = s.dof(self.node_at(len(layouts) - 1, layouts[-1].hub), 5)
        # A resisting torque opposes the last shaft's rotation, whose sense alternates pair by pair
        self.load_sign = 1.0 if len(self.stages) % 2 else -1.0
        # Each mesh at its pitch point: transverse line of action (radial x separating the gears,
        # tangential y) plus the axial component of the helix; a pair driven by a shaft turning the
        # other way presses the other flanks (y and z mirrored).
        self.mesh_rows, self.mesh_dofs = [], []
        pinion_positions = [p.input_shaft.gear] + [layout.hub for layout in layouts[1:-1]]
        for k, view in enumerate(self.stages):
            g = view.geometry
            sense = 1.0 if k % 2 == 0 else -1.0
            alpha, beta_b = g.transverse_pressure_angle, g.base_helix_angle
            direction = np.array(
                [math.sin(alpha), sense * math.cos(alpha), sense * math.tan(beta_b)]
            )
            z = pinion_positions[k]
            if abs(z - layouts[k + 1].gear) > 1e-12:
                raise ValueError(
                    "input_shaft.gear and output_shaft.gear: the gears must sit in one plane"
                    if k == 0
                    else f"stages[{k - 1}]: its pinion (the previous shaft's hub, {z} m) and "
                    f"its shaft's gear ({layouts[k + 1].gear} m) must sit in one plane"
                )
            pitch_point = (self.shaft_x[k] + g.pitch_radius(g.teeth_pinion), 0.0, z)
            self.mesh_rows.append(
                direction
                @ (
                    s.point_rows(self.node_at(k, z), pitch_point)
                    - s.point_rows(self.node_at(k + 1, z), pitch_point)
                )
            )
            # The model coordinate replaced by delta: the pinion's radial x, which carries no load
            # (the motor and brake torques and the bench's bearing forces stay on plain coordinates).
            self.mesh_dofs.append(s.dof(self.node_at(k, z), 0))
        self.sensor_rows = {}
        for name, housing, *_ in p.sensors:
            if not 0 <= housing < len(self.housings):
                raise ValueError(
                    f"sensors: {name} on housing {housing}; the rig has housings 0..{len(self.housings) - 1}"
                )
            node = self.housings[housing]
            top = s.positions[node] + np.array(
                [0.0, p.sensor_height if p.housing_model == "block" else 0.0, 0.0]
            )
            self.sensor_rows[name] = s.point_rows(node, top)[:2]  # x, y

    # -- building --------------------------------------------------------------------------
    def _shaft_sections(self) -> list[Section]:
        p = self.p
        layouts = self.layouts
        if p.shaft_sections:
            if len(p.shaft_sections) != len(layouts):
                raise ValueError(
                    f"shaft_sections: one Section per shaft ({len(layouts)}), got "
                    f"{len(p.shaft_sections)}"
                )
            return list(p.shaft_sections)
        return [
            Section.tube(
                layout.diameter,
                layout.inner_diameter,
                p.shaft_youngs_modulus,
                p.shaft_poisson_ratio,
                p.shaft_density,
            )
            for layout in layouts
        ]

    def _damage_zone(self) -> DamageZone | None:
        """The `DamageZone` of a shaft_crack or delamination state, else None. Its section carries
        the shear loss, the same in every direction."""
        p = self.p
        if p.health_state not in SHAFT_HEALTH_STATES:
            return None
        if p.shaft_model != "flexible":
            raise ValueError(
                f"health state {p.health_state}: a damaged shaft needs shaft_model: flexible"
            )
        if not 0 <= p.damaged_shaft < len(self.layouts):
            raise ValueError(
                f"damaged_shaft: 0 (input shaft) to {len(self.layouts) - 1} (output shaft), got "
                f"{p.damaged_shaft}"
            )
        layout = self.layouts[p.damaged_shaft]
        section = self.sections[p.damaged_shaft]
        spin_hz = p.speed_rpm / 60 * shaft_speeds(p, 1.0)[p.damaged_shaft]
        if p.health_state == "shaft_crack":
            start = p.shaft_crack_position - layout.diameter / 2
            end = p.shaft_crack_position + layout.diameter / 2
            ratios = crack_section_ratios(
                layout.diameter, layout.inner_diameter, p.shaft_crack_depth
            )
            breathing, angle = True, math.radians(p.shaft_crack_angle_deg)
        else:
            start, end = p.delamination_start, p.delamination_start + p.delamination_length
            ratios = delamination_section_ratios(
                layout.diameter,
                layout.inner_diameter,
                p.delamination_interface_depth,
                p.delamination_arc_deg,
            )
            breathing, angle = False, 0.0
        if not (0.0 <= start < end <= layout.length):
            raise ValueError(
                f"{p.health_state}: the damaged stretch {start:.4g}..{end:.4g} m lies outside the "
                f"shaft (0..{layout.length} m)"
            )
        bending_xi, bending_eta, area = ratios
        # a crack's shear loss exists only while it is open: its bending flexibility is the model
        damaged_section = (
            section if breathing else dataclasses.replace(section, shear=section.shear * area)
        )

        def element(length: float) -> DamagedElement:
            return DamagedElement(
                removed_rotational_stiffness(length, section.bending, bending_xi),
                removed_rotational_stiffness(length, section.bending, bending_eta),
                breathing,
                angle,
                spin_hz,
            )

        return DamageZone(p.damaged_shaft, start, end, damaged_section, element)

    def _add_shaft(
        self, shaft: int, x: float, layout: ShaftLayout, gear: tuple, hub: tuple
    ) -> dict:
        """Nodes of one shaft {z: node}; masses of the shaft, its gear and hub ((mass, polar
        inertia) each); its damaged elements, if any, in `damaged_elements`."""
        p, s = self.p, self.structure
        section = self.sections[shaft]
        (gear_mass, gear_inertia), (hub_mass, hub_inertia) = gear, hub
        damage = self.damage if self.damage is not None and self.damage.shaft == shaft else None
        if p.shaft_model == "rigid":
            node = s.add_node((x, 0.0, layout.gear))
            mass = section.mass_per_length * layout.length
            radius_of_gyration2 = section.rotary_inertia_per_length / section.mass_per_length
            transverse = mass * (radius_of_gyration2 + layout.length**2 / 12)
            s.add_rigid_mass(
                node,
                mass,
                (x, 0.0, layout.length / 2),
                (transverse, transverse, section.polar_inertia_per_length * layout.length),
            )
            nodes = {None: node}
        else:
            damaged = () if damage is None else (damage.start, damage.end)
            stations = sorted(
                {0.0, layout.length, layout.gear, layout.hub, *layout.bearings, *damaged}
            )
            points = [stations[0]]
            for a, b in zip(stations[:-1], stations[1:]):
                pieces = max(1, math.ceil((b - a) / p.shaft_element_length - 1e-9))
                points += [a + (b - a) * (k + 1) / pieces for k in range(pieces)]
            nodes = {z: s.add_node((x, 0.0, z)) for z in points}
            for a, b in zip(points[:-1], points[1:]):
                damaged = (
                    damage is not None and damage.start - 1e-12 <= a and b <= damage.end + 1e-12
                )
                s.add_beam(
                    nodes[a],
                    nodes[b],
                    damage.section if damaged else section,
                    damping_ratio_per_hz=p.shaft_damping * math.pi,
                )
                if damaged:
                    self.damaged_elements.append((nodes[a], nodes[b], damage.element(b - a)))
        s.add_rigid_mass(
            self._node(nodes, layout.gear),
            gear_mass,
            (x, 0.0, layout.gear),
            (gear_inertia / 2, gear_inertia / 2, gear_inertia),
        )
        s.add_rigid_mass(
            self._node(nodes, layout.hub),
            hub_mass,
            (x, 0.0, layout.hub),
            (hub_inertia / 2, hub_inertia / 2, hub_inertia),
        )
        return nodes

    @staticmethod
    def _node(nodes: dict, z: float) -> int:
        if None in nodes:
            return nodes[None]
        return nodes[min(nodes, key=lambda station: abs(station - z))]

    def node_at(self, shaft: int, z: float) -> int:
        """The node of shaft `shaft` (0: input) that carries the point at axial position z."""
        return self._node(self.shaft_nodes[shaft], z)

    def _add_housing(self, bearing_centre) -> int:
        p, s = self.p, self.structure
        if p.housing_model == "point":
            node = s.add_node(bearing_centre, rotations=False)
            s.add_rigid_mass(node, p.housing_mass)
            s.add_spring((node, bearing_centre), None, p.housing_stiffness, p.housing_damping)
            return node
        node = s.add_node(bearing_centre)
        s.add_rigid_mass(node, p.housing_mass, inertia=p.housing_inertia)
        x0, y0, z0 = bearing_centre
        for dx in (-p.housing_foot_span[0], p.housing_foot_span[0]):
            for dz in (-p.housing_foot_span[1], p.housing_foot_span[1]):
                foot = (x0 + dx, y0 - p.housing_foot_height, z0 + dz)
                s.add_spring(
                    (node, foot),
                    None,
                    np.asarray(p.housing_stiffness) / 4,
                    np.asarray(p.housing_damping) / 4,
                )
        return node

    # -- the linear system in model coordinates ---------------------------------------------
    def mesh_transform(self) -> np.ndarray:
        """T with q_physical = T q_model: q_model has each mesh deflection in place of its pinion's
        x (delta_k = mesh_rows[k] . q_physical)."""
        n = self.structure.n
        if len(self.mesh_dofs) > 1:
            rows = np.eye(n)
            rows[self.mesh_dofs] = self.mesh_rows
            return np.linalg.inv(rows)
        (i,), (row,) = self.mesh_dofs, self.mesh_rows
        transform = np.eye(n)
        transform[i, :] = -row / row[i]
        transform[i, i] = 1.0 / row[i]
        return transform

    def damage_rows(self) -> np.ndarray:
        """(2 per damaged element) x n: the elements' relative rotations (d_x, d_y;
        `shaft_damage.py`) as functions of the physical coordinates."""
        s = self.structure
        rows = []
        for node_a, node_b, _ in self.damaged_elements:
            for plane, sign in BENDING_PLANES:
                plane_rows = np.zeros((4, s.n))
                for r, (local, factor) in enumerate(zip(plane, (1.0, sign, 1.0, sign))):
                    node, coordinate = (node_a, local) if local < 6 else (node_b, local - 6)
                    plane_rows[r, s.dof(node, coordinate)] = factor
                rows.append(RELATIVE_ROTATION @ plane_rows)
        return np.array(rows).reshape(-1, s.n)

    def natural_frequencies(self, mesh_stiffness=None) -> np.ndarray:
        """Undamped natural frequencies (Hz) with linear meshes of `mesh_stiffness` (N/m: one for
        every pair or one per pair; default: each pair's operating stiffness under the static
        load)."""
        from scipy.linalg import eigh

        stiffness = self.structure.stiffness_matrix()
        for k_mesh, row in zip(self.mesh_stiffnesses(mesh_stiffness), self.mesh_rows):
            stiffness = stiffness + k_mesh * np.outer(row, row)
        values = eigh(stiffness, self.structure.mass_matrix(), eigvals_only=True)
        return np.sqrt(np.clip(values, 0.0, None)) / (2 * math.pi)

    def mesh_stiffnesses(self, mesh_stiffness=None) -> list[float]:
        """Each pair's linear mesh stiffness: `mesh_stiffness` (one for every pair, or one per
        pair), or its operating stiffness."""
        if mesh_stiffness is None:
            return [operating_stiffness(view) for view in self.stages]
        if np.ndim(mesh_stiffness) == 0:
            return [mesh_stiffness] * len(self.stages)
        if len(mesh_stiffness) != len(self.stages):
            raise ValueError(
                f"mesh_stiffness: one per pair ({len(self.stages)}), got {len(mesh_stiffness)}"
            )
        return list(mesh_stiffness)

    def polar_inertias(self) -> tuple[float, ...]:
        """Rotational inertia of each shaft assembly (input first) about its axis."""
        mass = self.structure.mass_matrix()
        return tuple(
            float(
                sum(
                    mass[self.structure.dof(node, 5), self.structure.dof(other, 5)]
                    for node in set(nodes.values())
                    for other in set(nodes.values())
                )
            )
            for nodes in self.shaft_nodes
        )


@dataclass
class SimulationSettings:
    """Numerical settings of one run."""

    duration: float = 1.0  # recorded seconds (after settling)
    settle_time: float = 0.15  # simulated then discarded, s
    output_rate: float = 5120.0  # Hz of the returned signals
    oversampling: int = 10  # sensors record at output_rate * oversampling
    steps_per_sensor_sample: int = (
        1  # integrator steps per sensor sample at least (h = 19.5 us at the defaults)
    )
    max_deflection: float = 1.0e-3  # |mesh deflection| beyond this is divergence, m
    # Craig-Bampton reduction: keep the structure's fixed-interface modes up to this frequency
    # (None: every coordinate). Flexible shafts' axial and torsion modes of short elements reach
    # tens of kHz and would set the step; they carry nothing below the output Nyquist frequency.
    modal_cutoff_hz: float | None = None
    # a step this many times smaller than the run would otherwise take (convergence checks, the
    # retry of a failed sample): it divides the chosen step, whatever set it
    step_refinement: int = 1
    # rk44 (four force calls a step) or central_difference (exudyn's velocity Verlet with h/2 x
    # the damping matrix in the mass matrix: one force call a step, stable to omega h = 2)
    integrator: str = "rk44"


# RK44 is stable for omega h up to 2.78, the central difference up to 2 (undamped); keep a
# margin for the mesh stiffness peaks.
STABLE_OMEGA_STEP = {"rk44": 2.0, "central_difference": 1.6}
MAX_STEPS_PER_SENSOR_SAMPLE = 16  # beyond this a parameter is out of any physical range


@dataclass
class ModelMatrices:
    """The linear structure in the coordinates exudyn integrates: q_physical = transform q.
    The mesh deflections are the first coordinates, one per pair (`meshes`); `plain` maps a physical coordinate that loads act on
    to its model coordinate; the last `n_damage` coordinates are the damaged shaft elements'
    deformations (`shaft_damage.py`)."""

    transform: np.ndarray
    mass: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    meshes: tuple
    plain: dict
    n_damage: int

    @property
    def n(self) -> int:
        return self.transform.shape[1]

    def highest_rate(self, mesh_stiffnesses) -> float:
        """Largest |eigenvalue| (1/s) of the damped linear system with linear meshes of
        `mesh_stiffnesses` (one per pair): what limits the explicit step. Undamped it is the
        highest circular frequency; a light node on a damped bushing decays faster than any mode
        oscillates (the CFRP rig's: c / m of the bearing nodes)."""
        stiffness = self.stiffness.copy()
        for mesh, mesh_stiffness in zip(self.meshes, mesh_stiffnesses):
            stiffness[mesh, mesh] += mesh_stiffness
        n = self.n
        state = np.zeros((2 * n, 2 * n))
        state[:n, n:] = np.eye(n)
        state[n:, :n] = -np.linalg.solve(self.mass, stiffness)
        state[n:, n:] = -np.linalg.solve(self.mass, self.damping)
        return float(np.abs(np.linalg.eigvals(state)).max())


def model_matrices(
    drivetrain: Drivetrain, load_dofs, modal_cutoff_hz: float | None = None
) -> ModelMatrices:
    """The structure in model coordinates: each mesh deflection (mesh_rows[k] . q) in place of its
    pinion's x, the loaded coordinates, and each damaged element's relative rotations d_x, d_y
    (`damage_rows`) as coordinates of their own, last.

    Without a cutoff every coordinate stays (the relative rotations replace the tilts of the
    element's node away from the mesh). With one, Craig-Bampton: the mesh deflection and the
    loaded coordinates stay (boundary), the rest become the static shapes they drag along plus
    fixed-interface modes up to `modal_cutoff_hz`. A damaged shaft needs more than the intact
    modes: a crack's kink is not in them (they put an open 30 % crack's second mode 12 % high).
    So the basis also holds the modes with the damage open, and is cut again at the cutoff by the
    Ritz modes of the mean of intact and open stiffness (open-crack modes below 2.5 kHz within
    5 %): the combined basis alone holds local shapes near 80 kHz that would need five steps per
    sensor sample. The relative rotations are then made coordinates of that basis."""

    s, n = drivetrain.structure, drivetrain.structure.n
    damage_rows = drivetrain.damage_rows()
    if modal_cutoff_hz is None:
        rows = np.eye(n)
        rows[drivetrain.mesh_dofs] = drivetrain.mesh_rows
        damage_dofs = []
        for k, (node_a, node_b, _) in enumerate(drivetrain.damaged_elements):
            node = (
                node_b
                if all(s.dof(node_b, c) not in drivetrain.mesh_dofs for c in range(6))
                else node_a
            )
            # d_x (x-z plane) replaces the node's ry, d_y (y-z plane) its rx
            for row, coordinate in zip(damage_rows[2 * k : 2 * k + 2], (4, 3)):
                rows[s.dof(node, coordinate)] = row
                damage_dofs.append(s.dof(node, coordinate))
        if np.linalg.cond(rows) > 1e12:
            raise ValueError(
                "the damaged shaft element's coordinates clash with the mesh's: move the damage "
                "away from the gear"
            )
        to_physical = np.linalg.inv(rows)
        first = boundary_dofs(drivetrain, load_dofs)
        order = (
            first + [i for i in range(n) if i not in set(first) | set(damage_dofs)] + damage_dofs
        )
        transform = to_physical[:, order]
    else:
        transform, first = _craig_bampton(drivetrain, load_dofs, modal_cutoff_hz, damage_rows)
    mass, stiffness, damping = (
        transform.T @ m @ transform
        for m in (s.mass_matrix(), s.stiffness_matrix(), s.damping_matrix())
    )
    return ModelMatrices(
        transform,
        mass,
        stiffness,
        damping,
        tuple(range(len(drivetrain.mesh_dofs))),
        {dof: first.index(dof) for dof in load_dofs},
        len(damage_rows),
    )


def boundary_dofs(drivetrain: Drivetrain, load_dofs) -> list[int]:
    """The physical coordinates the model keeps first and plain: the mesh deflections' (in pair
    order), then the loaded ones."""
    meshes = list(drivetrain.mesh_dofs)
    return meshes + [dof for dof in dict.fromkeys(load_dofs) if dof not in meshes]


def _craig_bampton(drivetrain: Drivetrain, load_dofs, cutoff_hz: float, damage_rows: np.ndarray):
    """(transform, boundary coordinates) of `model_matrices` with a cutoff."""
    from scipy.linalg import eigh, null_space

    s = drivetrain.structure
    mesh_t = drivetrain.mesh_transform()
    mass, stiffness = mesh_t.T @ s.mass_matrix() @ mesh_t, mesh_t.T @ s.stiffness_matrix() @ mesh_t
    damage = damage_rows @ mesh_t
    first = boundary_dofs(drivetrain, load_dofs)
    interior = [i for i in range(s.n) if i not in set(first)]
    ii, ib = np.ix_(interior, interior), np.ix_(interior, first)
    static_shapes = -np.linalg.solve(stiffness[ii], stiffness[ib])

    def modes(k):
        values, vectors = eigh(k[ii], mass[ii])
        return vectors[:, np.sqrt(np.clip(values, 0.0, None)) / (2 * math.pi) <= cutoff_hz]

    basis = modes(stiffness)
    if len(damage):
        # the damage open in both planes (a crack at its most flexible)
        open_stiffness = stiffness.copy()
        for k, (_, _, element) in enumerate(drivetrain.damaged_elements):
            removed = max(element.removed_xi, element.removed_eta)
            open_stiffness -= removed * (
                np.outer(damage[2 * k], damage[2 * k])
                + np.outer(damage[2 * k + 1], damage[2 * k + 1])
            )
        basis = np.hstack([basis, modes(open_stiffness)])
        gram_values, gram_vectors = eigh(basis.T @ mass[ii] @ basis)
        independent = gram_values > 1e-10 * gram_values.max()
        basis = basis @ gram_vectors[:, independent] / np.sqrt(gram_values[independent])
        values, vectors = eigh(
            basis.T @ (stiffness[ii] + open_stiffness[ii]) @ basis / 2, basis.T @ mass[ii] @ basis
        )
        basis = basis @ vectors[:, np.sqrt(np.clip(values, 0.0, None)) / (2 * math.pi) <= cutoff_hz]
        # make the relative rotations coordinates: boundary shapes free of them, then a basis
        # change inside the modes whose last coordinates are d_x, d_y
        damage_modes = damage[:, interior] @ basis
        damage_boundary = damage[:, first] + damage[:, interior] @ static_shapes
        to_damage = np.linalg.pinv(damage_modes)
        static_shapes = static_shapes - basis @ to_damage @ damage_boundary
        basis = np.hstack([basis @ null_space(damage_modes), basis @ to_damage])
    reduction = np.zeros((s.n, len(first) + basis.shape[1]))
    reduction[first, range(len(first))] = 1.0
    reduction[np.ix_(interior, range(len(first)))] = static_shapes
    reduction[np.ix_(interior, range(len(first), reduction.shape[1]))] = basis
    return mesh_t @ reduction, first


def steps_per_sensor_sample(
    drivetrain: Drivetrain, settings: SimulationSettings, matrices: ModelMatrices | None = None
) -> int:
    """Integrator steps per sensor sample: the setting, or more where the highest mode (with the
    mesh at twice its operating stiffness, the peaks of the TVMS; with `matrices`, the damped
    system's fastest eigenvalue) needs a smaller step; times `step_refinement`."""
    peaks = [2 * k for k in drivetrain.mesh_stiffnesses()]
    omega_max = (
        2 * math.pi * drivetrain.natural_frequencies(peaks)[-1]
        if matrices is None
        else matrices.highest_rate(peaks)
    )
    if settings.integrator not in STABLE_OMEGA_STEP:
        raise ValueError(
            f"integrator {settings.integrator!r}: choose one of {list(STABLE_OMEGA_STEP)}"
        )
    needed = math.ceil(
        omega_max
        / (settings.output_rate * settings.oversampling)
        / STABLE_OMEGA_STEP[settings.integrator]
    )
    if needed > MAX_STEPS_PER_SENSOR_SAMPLE:
        raise SimulationError(
            f"the fastest mode ({omega_max / 2 / math.pi:.3g} Hz) needs {needed} {settings.integrator} steps per sensor sample "
            f"(at most {MAX_STEPS_PER_SENSOR_SAMPLE}): a stiffness is out of range "
            f"(mesh_stiffness {', '.join(f'{v.mesh_stiffness:.3g}' for v in drivetrain.stages)} N/m)"
        )
    return max(int(settings.steps_per_sensor_sample), needed) * int(settings.step_refinement)


def simulate(
    params: GearDrivetrainParameters,
    settings: SimulationSettings = SimulationSettings(),
    diagnostics: dict | None = None,
    extra_loads=(),
):
    """Run the model; return {channel: acceleration in m/s^2 at settings.output_rate}.

    extra_loads: `PeriodicLoad`s (the virtual bench's motor ripple and bearing tones).
    diagnostics: a dict to receive `time`, the mesh `deflection` (m, at the sensor rate,
    settling included), `mesh_force` at the end state, `steps_per_sensor_sample`, `mesh_calls`."""
    import exudyn as exu  # imported here so the geometry helpers work without exudyn
    import exudyn.itemInterface as eii
    from exudyn.utilities import CreateSymbolicUserFunction

    drivetrain = Drivetrain(params)
    structure = drivetrain.structure
    # Loads: the brake torque (with its slow fluctuation) and any extra periodic loads; their
    # coordinates stay plain coordinates of the model.
    brake = drivetrain.load_sign * params.load_torque
    loads = [
        (
            drivetrain.load_dof,
            brake,
            brake * params.load_fluctuation,
            params.load_fluctuation_hz,
            params.load_fluctuation_phase,
        )
    ]
    for extra in extra_loads:
        kind, index = extra.target
        dof = (
            structure.dof(drivetrain.coupling_node, 5)
            if kind == "motor"
            else structure.dof(drivetrain.housings[index], 1)
        )
        loads.append((dof, 0.0, extra.amplitude, extra.frequency_hz, extra.phase))
    if any(dof in drivetrain.mesh_dofs for dof, *_ in loads):
        raise ValueError(
            "a load acts on a pinion's x, which the model replaces by the mesh deflection"
        )
    matrices = model_matrices(drivetrain, [dof for dof, *_ in loads], settings.modal_cutoff_hz)
    steps = steps_per_sensor_sample(
        drivetrain, settings, matrices
    )  # fails fast on an out-of-range stiffness
    n, transform = matrices.n, matrices.transform
    polar = drivetrain.polar_inertias()
    meshes = [
        MeshForce(view, mesh_damping(view, polar[k], polar[k + 1]))
        for k, view in enumerate(drivetrain.stages)
    ]

    # Static equilibrium as initial condition (short transient): each mesh at the deflection its
    # teeth in contact at t = 0 carry the load at (their pitch errors and deviations included).
    load = np.zeros(n)
    load[matrices.plain[drivetrain.load_dof]] = brake  # a resisting load presses the gears together
    free = [i for i in range(n) if i not in matrices.meshes]
    stiffness = matrices.stiffness
    q0 = np.zeros(n)
    rhs = load[free]
    for mesh_dof, mesh, view in zip(matrices.meshes, meshes, drivetrain.stages):
        rb2 = view.geometry.base_radius(view.geometry.teeth_gear)
        q0[mesh_dof] = mesh.starting_deflection(view.load_torque / rb2)
        rhs = rhs - stiffness[free, mesh_dof] * q0[mesh_dof]
    q0[free] = np.linalg.solve(stiffness[np.ix_(free, free)], rhs)

    with exudyn_system() as mbs:
        # The damaged shaft elements' deformation coordinates (the last ones) get a node of their own,
        # so that their Python force function sees those two per element only.
        n_damage = matrices.n_damage
        nodes = [
            mbs.AddNode(
                eii.NodeGenericODE2(
                    referenceCoordinates=[0.0] * size,
                    initialCoordinates=q0[first : first + size].tolist(),
                    initialCoordinates_t=[0.0] * size,
                    numberOfODE2Coordinates=size,
                )
            )
            for first, size in ((0, n - n_damage), (n - n_damage, n_damage))
            if size
        ]
        node = nodes[0]
        mass = matrices.mass
        if settings.integrator == "central_difference":
            # exudyn's velocity Verlet takes the damping forces at the half-step velocity: with
            # h/2 C in the mass matrix its step is the central difference (second order)
            mass = (
                mass
                + 0.5 / (settings.output_rate * settings.oversampling * steps) * matrices.damping
            )
        mbs.AddObject(
            eii.ObjectGenericODE2(
                nodeNumbers=nodes,
                massMatrix=_sparse(mass),
                stiffnessMatrix=_sparse(stiffness),
                dampingMatrix=_sparse(matrices.damping),
            )
        )
        if n_damage:
            damage = ShaftDamageForce([element for *_, element in drivetrain.damaged_elements])

            def damage_force(mbs_, t, item, q, q_t):
                return damage(t, q)

            mbs.AddObject(
                eii.ObjectGenericODE2(nodeNumbers=[nodes[1]], forceUserFunction=damage_force)
            )
        ground = mbs.AddNode(eii.NodePointGround())
        ground_marker = mbs.AddMarker(eii.MarkerNodeCoordinate(nodeNumber=ground, coordinate=0))
        calls = [0]

        def counted(mesh):
            def counted_mesh_force(mbs_, t, item, displacement, velocity, k, d, offset):
                calls[0] += 1
                return mesh(t, displacement, velocity)

            return counted_mesh_force

        for mesh_dof, mesh in zip(matrices.meshes, meshes):
            mesh_marker = mbs.AddMarker(
                eii.MarkerNodeCoordinate(nodeNumber=node, coordinate=mesh_dof)
            )
            mbs.AddObject(
                eii.ObjectConnectorCoordinateSpringDamper(
                    markerNumbers=[ground_marker, mesh_marker],
                    springForceUserFunction=mesh.spring_force
                    if diagnostics is None
                    else counted(mesh),
                )
            )

        keep = []  # the symbolic load functions live as long as the system
        for dof, mean, amplitude, frequency, phase in loads:  # compiled symbolic functions of time
            marker = mbs.AddMarker(
                eii.MarkerNodeCoordinate(nodeNumber=node, coordinate=matrices.plain[dof])
            )
            item = mbs.AddLoad(eii.LoadCoordinate(markerNumber=marker, load=mean))
            if amplitude:
                function = CreateSymbolicUserFunction(
                    mbs, _sine_load(mean, amplitude, frequency, phase), "loadUserFunction", item
                )
                mbs.SetLoadParameter(item, "loadUserFunction", function)
                keep.append(function)

        # Velocities, not accelerations: their differences are the mean acceleration over each
        # sensor period, a boxcar whose nulls sit at the multiples of the sensor rate, where the
        # content that would alias into the output band lies. A point sample of the acceleration
        # folds the mesh's harmonics near the sensor rate into the band (how much depends on the
        # step: the convergence check measured that aliasing, not the model).
        sensors = [
            mbs.AddSensor(
                eii.SensorNode(
                    nodeNumber=each,
                    storeInternal=True,
                    writeToFile=False,
                    outputVariableType=exu.OutputVariableType.Coordinates_t,
                )
            )
            for each in nodes
        ]
        if diagnostics is not None:
            position_sensor = mbs.AddSensor(
                eii.SensorNode(
                    nodeNumber=node,
                    storeInternal=True,
                    writeToFile=False,
                    outputVariableType=exu.OutputVariableType.Coordinates,
                )
            )
        mbs.Assemble()

        try:
            solve_rk44(
                mbs,
                settings.output_rate * settings.oversampling,
                steps,
                settings.settle_time + settings.duration,
                sparse=True,
                sensed_accelerations=False,
                solver="VelocityVerlet" if settings.integrator == "central_difference" else "RK44",
            )
        except Exception as exc:
            message = " ".join(str(exc).split())  # one line: exudyn appends the Python traceback
            raise SimulationError(
                f"exudyn solver failed ({params.health_state}, {params.speed_rpm} rpm): {message}"
            ) from exc

        velocities = (
            np.hstack([mbs.GetSensorStoredData(each)[:, 1:] for each in sensors]) @ transform.T
        )  # physical
        acc = np.diff(velocities, axis=0) * (settings.output_rate * settings.oversampling)
        deflections = mbs.GetNodeOutput(node, exu.OutputVariableType.Coordinates)[
            list(matrices.meshes)
        ]
        if diagnostics is not None:
            positions = mbs.GetSensorStoredData(position_sensor)
            diagnostics.update(
                time=positions[:, 0],
                deflection=positions[:, 1],
                deflections=positions[:, [1 + m for m in matrices.meshes]],
                mesh_calls=calls[0],
                steps_per_sensor_sample=steps,
                accelerations=acc,
                drivetrain=drivetrain,
            )
        worst = float(np.abs(deflections).max())
        if not np.isfinite(acc).all() or not worst <= settings.max_deflection:
            raise SimulationError(
                f"simulation diverged ({params.health_state}, {params.speed_rpm} rpm): "
                f"non-finite accelerations or mesh deflection {worst:.3g} m"
            )
    lowpass = decimation_filter(settings.oversampling)
    first = int(round(settings.settle_time * settings.output_rate))
    n_out = int(round(settings.duration * settings.output_rate))
    signals = {}
    for channel, sensor_name, direction in sensor_outputs(params.sensors):
        rows = drivetrain.sensor_rows[sensor_name]
        along_x, along_y = direction_weights(direction)
        # Filter the whole run (settling included) so filter edge effects fall in the discarded
        # part, then decimate to the output rate.
        along = along_x * rows[0] + along_y * rows[1]
        out = resample_poly(acc @ along, 1, settings.oversampling, window=lowpass)
        signals[channel] = out[first : first + n_out]
    for name, signal in signals.items():
        if not np.isfinite(signal).all():
            raise SimulationError(f"channel {name}: non-finite samples after filtering")
    return signals


def _sparse(matrix: np.ndarray):
    """An exudyn sparse matrix container (the explicit solver factorises the mass matrix every
    stage: sparse keeps that cheap)."""
    import exudyn as exu

    rows, cols = np.nonzero(matrix)
    container = exu.MatrixContainer()
    container.SetWithSparseMatrixCSR(
        matrix.shape[0],
        matrix.shape[1],
        np.column_stack([rows, cols, matrix[rows, cols]]),
        useDenseMatrix=False,
    )
    return container


def _sine_load(mean: float, amplitude: float, frequency_hz: float, phase: float):
    """A symbolic load function mean + amplitude sin(2 pi f t + phase) of exudyn's signature."""
    omega = 2 * math.pi * frequency_hz

    def load(mbs, t, value):
        import exudyn as exu

        esym = exu.symbolic
        return esym.Real(mean) + esym.Real(amplitude) * esym.sin(t * omega + phase)

    return load

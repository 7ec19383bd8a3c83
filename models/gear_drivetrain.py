"""Lumped multibody model of the helical-gear test rig (pinion 29 / gear 44 teeth) in exudyn.

Pure: parameters in, housing accelerations out. Knows nothing of Snakemake or MLflow.

Degrees of freedom (14): pinion x, y, rotation; gear x, y, rotation; four bearing housings x, y.
Each gear sits on a rigid shaft carried by two bearings, modelled as linear bushings
F = -k delta - c delta_dot between the gear centre and a housing mass; each housing stands on the
gearbox base through a spring-damper. The motor drives the pinion through a torsional coupling at
constant speed; a constant load torque acts on the output shaft. Angles are deviations from the
nominal rotation, so everything time-dependent in the mesh is a function of time only.

All linear parts live in one ObjectGenericODE2. The gear rotation coordinate is replaced by the
mesh deflection along the line of action, so the whole nonlinear mesh is one scalar
ObjectConnectorCoordinateSpringDamper whose user function sums the tooth-pair forces
(see `MeshForce`). Sensors record housing accelerations above the output rate; the signals are
low-pass filtered and decimated to the output rate (no aliasing) and checked finite.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import firwin, resample_poly

from models.contact_laws import hysteresis_factor

HEALTH_STATES = ("healthy", "surface_fault", "missing_tooth")
CHANNELS = ("A1_x", "A1_y", "A2_x", "A2_y")

# Coordinate indices in the physical ordering.
PINION_X, PINION_Y, PINION_ROT, GEAR_X, GEAR_Y, GEAR_ROT = range(6)
HOUSING_X = (6, 8, 10, 12)  # housings 1, 2 carry the input shaft, 3, 4 the output shaft
N_COORDINATES = 14
# A1 above the input shaft (housing 1), A2 above the output shaft (housing 3).
SENSOR_HOUSINGS = {"A1": 0, "A2": 2}


class SimulationError(RuntimeError):
    """A simulation diverged or produced non-finite output."""


@dataclass
class GearGeometry:
    """Helical gear pair of the helical-gear study (Table 2); lengths in metres."""
    teeth_pinion: int = 29
    teeth_gear: int = 44
    normal_module: float = 2.25e-3
    pressure_angle_deg: float = 20.0
    helix_angle_deg: float = 26.0
    face_width: float = 0.020   # not given by the study: an assumption of this model
    addendum_factor: float = 1.0

    @property
    def transverse_module(self) -> float:
        return self.normal_module / math.cos(math.radians(self.helix_angle_deg))

    @property
    def transverse_pressure_angle(self) -> float:
        return math.atan(math.tan(math.radians(self.pressure_angle_deg))
                         / math.cos(math.radians(self.helix_angle_deg)))

    def pitch_radius(self, teeth: int) -> float:
        return teeth * self.transverse_module / 2.0

    def base_radius(self, teeth: int) -> float:
        return self.pitch_radius(teeth) * math.cos(self.transverse_pressure_angle)

    @property
    def base_pitch(self) -> float:
        """Distance along the line of action from one tooth pair to the next."""
        return math.pi * self.transverse_module * math.cos(self.transverse_pressure_angle)

    @property
    def contact_ratio(self) -> float:
        """Transverse contact ratio of the standard (unshifted) pair."""
        r1, r2 = self.pitch_radius(self.teeth_pinion), self.pitch_radius(self.teeth_gear)
        rb1, rb2 = self.base_radius(self.teeth_pinion), self.base_radius(self.teeth_gear)
        addendum = self.addendum_factor * self.normal_module
        path = (math.sqrt((r1 + addendum) ** 2 - rb1 ** 2) + math.sqrt((r2 + addendum) ** 2 - rb2 ** 2)
                - (r1 + r2) * math.sin(self.transverse_pressure_angle))
        return path / self.base_pitch


@dataclass
class GearDrivetrainParameters:
    """Physical parameters; SI units. Defaults are the nominal (uncalibrated) rig."""
    geometry: GearGeometry = field(default_factory=GearGeometry)
    # Inertia of each shaft assembly (gear, shaft, coupling half).
    pinion_mass: float = 1.2
    pinion_inertia: float = 6.0e-4
    gear_mass: float = 2.0
    gear_inertia: float = 3.3e-3
    housing_mass: float = 2.0
    # Bearings as bushings (CFRP study Table 3: 1.825e5 N/mm, 12.3 N s/mm).
    bushing_stiffness: float = 1.825e8
    bushing_damping: float = 1.23e4
    housing_stiffness: float = 5.0e7
    housing_damping: float = 2.0e3
    coupling_stiffness: float = 2.0e3      # N m/rad, motor to pinion
    coupling_damping: float = 0.5          # N m s/rad
    # Gear mesh: F = K delta^n + chi delta^n delta_dot, per tooth pair.
    contact_law: str = "lankarani_nikravesh"
    mesh_stiffness: float = 4.0e8          # mean mesh stiffness at 1 um deflection, N/m
    contact_exponent: float = 1.5
    restitution: float = 0.9
    approach_velocity: float = 0.02        # delta_dot(-) of a tooth engagement, m/s
    backlash: float = 1.0e-4               # along the line of action, m
    transmission_error: float = 0.3e-6     # amplitude of the static TE at mesh frequency, m
    # Load and speed.
    load_torque: float = 10.0              # on the output shaft, N m
    speed_rpm: float = 1100.0              # input shaft
    # Health.
    health_state: str = "healthy"
    faulty_tooth: int = 0                  # pinion tooth index of the damage
    surface_fault_teeth: int = 3           # consecutive pinion teeth with reduced stiffness
    surface_fault_stiffness_loss: float = 0.15
    # Effects of a real bench that the calibrated model leaves out (zero in the model).
    speed_fluctuation: float = 0.0         # relative amplitude of a sinusoidal speed variation
    speed_fluctuation_hz: float = 2.0
    runout_pinion: float = 0.0             # shaft run-out (eccentricity), m
    runout_gear: float = 0.0
    runout_phase: float = 0.0              # rad, phase of the pinion run-out at t = 0 (gear: + pi/3)

    def replace(self, **changes) -> "GearDrivetrainParameters":
        return dataclasses.replace(self, **changes)


DEFLECTION_REF = 1.0e-6  # m; K = mesh stiffness at this deflection keeps K's unit N/m for any n


class MeshForce:
    """Sum of the tooth-pair contact forces along the line of action, a function of
    (time, mesh deflection, deflection rate).

    Each tooth pair j is nominally in contact while the mesh phase (in mesh periods) is in
    [j, j + contact ratio). Outside that window the pair still touches once the deflection
    exceeds the gap of its tooth tip to the flank, which grows quadratically with the distance s
    outside the window (g = s^2 / (2 rho)): this is the extended contact that catches the gears
    when a tooth is missing, instead of free flight. Damaged pinion teeth scale their pair
    stiffness. A back-flank contact closes the backlash.
    """

    def __init__(self, p: GearDrivetrainParameters):
        g = p.geometry
        self.contact_ratio = g.contact_ratio
        self.mesh_frequency = p.speed_rpm / 60.0 * g.teeth_pinion
        self.shaft_frequency = p.speed_rpm / 60.0
        self.gear_frequency = self.shaft_frequency * g.teeth_pinion / g.teeth_gear
        self.base_pitch = g.base_pitch
        self.tip_radius = g.base_radius(g.teeth_pinion)
        self.teeth = g.teeth_pinion
        self.gear_ratio = g.teeth_pinion / g.teeth_gear
        # Per pair K with delta in um-normalised form: F = K_ref * (delta/delta_ref)^n.
        self.pair_force_ref = p.mesh_stiffness * DEFLECTION_REF / self.contact_ratio
        self.mean_force_ref = p.mesh_stiffness * DEFLECTION_REF
        self.exponent = p.contact_exponent
        self.hysteresis = hysteresis_factor(p.contact_law, p.restitution)
        self.approach_velocity = p.approach_velocity
        self.contact_start = {}  # contact (pair index or "back") -> delta_dot(-) when it began
        self.backlash = p.backlash
        self.te_amplitude = p.transmission_error
        self.fluct = p.speed_fluctuation
        self.fluct_w = 2 * math.pi * p.speed_fluctuation_hz
        self.runout = (p.runout_pinion, p.runout_gear)
        self.runout_phase = p.runout_phase
        self.tooth_factor = np.ones(self.teeth)
        if p.health_state == "surface_fault":
            for k in range(p.surface_fault_teeth):
                self.tooth_factor[(p.faulty_tooth + k) % self.teeth] = 1.0 - p.surface_fault_stiffness_loss
        elif p.health_state == "missing_tooth":
            self.tooth_factor[p.faulty_tooth % self.teeth] = 0.0
        elif p.health_state != "healthy":
            raise ValueError(f"unknown health state {p.health_state!r}; choose one of {list(HEALTH_STATES)}")
        self.tooth_factor = self.tooth_factor.tolist()

    def phase(self, t):
        """Mesh phase in mesh periods and its rate, with the (bench) speed fluctuation."""
        if self.fluct:
            s = math.sin(self.fluct_w * t)
            c = math.cos(self.fluct_w * t)
            return (self.mesh_frequency * (t + self.fluct * (1.0 - c) / self.fluct_w),
                    self.mesh_frequency * (1.0 + self.fluct * s))
        return self.mesh_frequency * t, self.mesh_frequency

    def excitation(self, t, phase, phase_rate):
        """Static transmission error and run-out along the line of action, and its rate."""
        w = 2 * math.pi
        e = self.te_amplitude * math.sin(w * phase)
        e_t = self.te_amplitude * w * phase_rate * math.cos(w * phase)
        if self.runout[0] or self.runout[1]:
            shaft_phase = phase / self.teeth
            for amplitude, ratio, offset in ((self.runout[0], 1.0, 0.0),
                                              (self.runout[1], self.gear_ratio, math.pi / 3)):
                angle = w * shaft_phase * ratio + self.runout_phase + offset
                e += amplitude * math.sin(angle)
                e_t += amplitude * w * phase_rate / self.teeth * ratio * math.cos(angle)
        return e, e_t

    def _force(self, key, stiffness_ref, d, d_t):
        """Contact force of one pair (or the back flank) at deflection d > 0.

        The law's delta_dot(-) is the approach velocity when this contact began: at least
        `approach_velocity` (the gentle engagement of a tooth pair rolling into mesh), and the
        real approach speed after a loss of contact (rattle, the gap of a missing tooth).
        That keeps each Table-1 law what it was built for, an impact with a restitution c_r.
        """
        v_minus = self.contact_start.get(key)
        if v_minus is None:
            v_minus = self.contact_start[key] = max(self.approach_velocity, d_t)
        force = stiffness_ref * (d / DEFLECTION_REF) ** self.exponent * (
            1.0 + self.hysteresis * d_t / v_minus)
        return force if force > 0.0 else 0.0

    def __call__(self, t, deflection, rate):
        phase, phase_rate = self.phase(t)
        e, e_t = self.excitation(t, phase, phase_rate)
        d = deflection - e
        d_t = rate - e_t
        back = -d - self.backlash
        if back > 0.0:  # back flank contact closes the backlash
            return -self._force("back", self.mean_force_ref, back, -d_t)
        self.contact_start.pop("back", None)
        # Pairs more than one base pitch outside their window have a gap of about a millimetre:
        # they never touch, so only the pairs from u = -1 to u = contact ratio + 1 are summed.
        first = math.floor(phase - self.contact_ratio)
        last = math.floor(phase) + 2
        total = 0.0
        pitch_rate = self.base_pitch * phase_rate
        for j in range(first, last):
            u = phase - j
            if u < 0.0:            # approaching: gap closes as the pair nears its start of contact
                s = -u * self.base_pitch
                gap, gap_t = s * s / (2 * self.tip_radius), -s * pitch_rate / self.tip_radius
            elif u > self.contact_ratio:  # receding
                s = (u - self.contact_ratio) * self.base_pitch
                gap, gap_t = s * s / (2 * self.tip_radius), s * pitch_rate / self.tip_radius
            else:
                gap, gap_t = 0.0, 0.0
            factor = self.tooth_factor[j % self.teeth]
            pair_d = d - gap
            if pair_d <= 0.0 or factor == 0.0:
                self.contact_start.pop(j, None)
                continue
            total += self._force(j, factor * self.pair_force_ref, pair_d, d_t - gap_t)
        for j in [k for k in self.contact_start if k != "back" and not first <= k < last]:
            del self.contact_start[j]
        return total

    def static_deflection(self, force):
        """Deflection that carries `force` with the mean mesh stiffness (for initial conditions)."""
        return DEFLECTION_REF * (force / self.mean_force_ref) ** (1.0 / self.exponent)

    def static_stiffness(self, force):
        """dF/d(delta) of the mean mesh at the deflection that carries `force`: the stiffness the
        vibration sees. K and n trade off against each other at one load; this does not."""
        deflection = self.static_deflection(force)
        return self.exponent * self.mean_force_ref / DEFLECTION_REF * (deflection / DEFLECTION_REF) ** (
            self.exponent - 1.0)


def operating_mesh_stiffness(p: GearDrivetrainParameters) -> float:
    """Linearised mean mesh stiffness (N/m) under the static load of `p`."""
    g = p.geometry
    return MeshForce(p).static_stiffness(p.load_torque / g.base_radius(g.teeth_gear))


def linear_matrices(p: GearDrivetrainParameters):
    """Mass, stiffness and damping matrices of the linear parts in physical coordinates."""
    n = N_COORDINATES
    mass = np.diag([p.pinion_mass, p.pinion_mass, p.pinion_inertia,
                    p.gear_mass, p.gear_mass, p.gear_inertia] + [p.housing_mass] * 8)
    stiffness = np.zeros((n, n))
    damping = np.zeros((n, n))

    def spring(i, j, k, c):  # between coordinates i and j (j None: to ground)
        for matrix, value in ((stiffness, k), (damping, c)):
            matrix[i, i] += value
            if j is not None:
                matrix[j, j] += value
                matrix[i, j] -= value
                matrix[j, i] -= value

    for gear_x, housings in ((PINION_X, (0, 1)), (GEAR_X, (2, 3))):
        for h in housings:
            for axis in (0, 1):
                spring(gear_x + axis, HOUSING_X[h] + axis, p.bushing_stiffness, p.bushing_damping)
    for h in range(4):
        for axis in (0, 1):
            spring(HOUSING_X[h] + axis, None, p.housing_stiffness, p.housing_damping)
    spring(PINION_ROT, None, p.coupling_stiffness, p.coupling_damping)
    return mass, stiffness, damping


def mesh_coordinate_transform(p: GearDrivetrainParameters) -> np.ndarray:
    """T with q_physical = T q_model, where q_model has the mesh deflection in place of the gear
    rotation: delta = n.(u_pinion - u_gear) + rb1 theta_pinion + rb2 theta_gear."""
    g = p.geometry
    alpha = g.transverse_pressure_angle
    normal = np.array([math.sin(alpha), math.cos(alpha)])  # line of action, transverse plane
    rb1, rb2 = g.base_radius(g.teeth_pinion), g.base_radius(g.teeth_gear)
    row = np.zeros(N_COORDINATES)   # delta = row . q_physical
    row[[PINION_X, PINION_Y]] = normal
    row[[GEAR_X, GEAR_Y]] = -normal
    row[PINION_ROT] = rb1
    row[GEAR_ROT] = rb2
    transform = np.eye(N_COORDINATES)
    transform[GEAR_ROT, :] = -row / rb2
    transform[GEAR_ROT, GEAR_ROT] = 1.0 / rb2
    return transform


@dataclass
class SimulationSettings:
    """Numerical settings of one run."""
    duration: float = 1.0            # recorded seconds (after settling)
    settle_time: float = 0.15        # simulated then discarded, s
    output_rate: float = 5120.0      # Hz of the returned signals
    oversampling: int = 10           # sensors record at output_rate * oversampling
    steps_per_sensor_sample: int = 1  # RK44 steps per sensor sample (h = 19.5 us at the defaults)
    max_deflection: float = 1.0e-3   # |mesh deflection| beyond this is divergence, m


def decimation_filter(factor: int, passband: float = 0.8, attenuation_db: float = 80.0) -> np.ndarray:
    """FIR low-pass for decimation by `factor`: flat to `passband` x the output Nyquist and at
    least `attenuation_db` down from the output Nyquist on, so no mesh harmonic above it folds
    back into the band (scipy's default decimation filter lets them through at -20 dB)."""
    transition = (1.0 - passband) / factor  # as a fraction of the input Nyquist
    beta = 0.1102 * (attenuation_db - 8.7)
    numtaps = int(math.ceil((attenuation_db - 7.95) / (2.285 * math.pi * transition))) | 1
    return firwin(numtaps, (1.0 + passband) / 2.0 / factor, window=("kaiser", beta))


def simulate(params: GearDrivetrainParameters, settings: SimulationSettings = SimulationSettings()):
    """Run the model; return {channel: acceleration in m/s^2 at settings.output_rate}."""
    import exudyn as exu  # imported here so the geometry helpers work without exudyn

    mesh = MeshForce(params)
    mass, stiffness, damping = linear_matrices(params)
    transform = mesh_coordinate_transform(params)
    mass_m = transform.T @ mass @ transform
    stiffness_m = transform.T @ stiffness @ transform
    damping_m = transform.T @ damping @ transform
    load = np.zeros(N_COORDINATES)
    load[GEAR_ROT] = params.load_torque  # a resisting load presses the gear onto the pinion
    load_m = transform.T @ load

    # Static equilibrium with the mean mesh force as initial condition (short transient).
    rb2 = params.geometry.base_radius(params.geometry.teeth_gear)
    delta0 = mesh.static_deflection(params.load_torque / rb2)
    free = [i for i in range(N_COORDINATES) if i != GEAR_ROT]
    q0 = np.zeros(N_COORDINATES)
    q0[GEAR_ROT] = delta0
    q0[free] = np.linalg.solve(stiffness_m[np.ix_(free, free)],
                               load_m[free] - stiffness_m[free, GEAR_ROT] * delta0)

    system = exu.SystemContainer()
    mbs = system.AddSystem()
    node = mbs.AddNode(exu.itemInterface.NodeGenericODE2(
        referenceCoordinates=[0.0] * N_COORDINATES, initialCoordinates=q0.tolist(),
        initialCoordinates_t=[0.0] * N_COORDINATES, numberOfODE2Coordinates=N_COORDINATES))
    mbs.AddObject(exu.itemInterface.ObjectGenericODE2(
        nodeNumbers=[node], massMatrix=exu.MatrixContainer(mass_m),
        stiffnessMatrix=exu.MatrixContainer(stiffness_m), dampingMatrix=exu.MatrixContainer(damping_m),
        forceVector=load_m.tolist()))
    ground = mbs.AddNode(exu.itemInterface.NodePointGround())
    ground_marker = mbs.AddMarker(exu.itemInterface.MarkerNodeCoordinate(nodeNumber=ground, coordinate=0))
    mesh_marker = mbs.AddMarker(exu.itemInterface.MarkerNodeCoordinate(nodeNumber=node, coordinate=GEAR_ROT))

    def mesh_force(mbs_, t, item, displacement, velocity, k, d, offset):
        return mesh(t, displacement, velocity)

    mbs.AddObject(exu.itemInterface.ObjectConnectorCoordinateSpringDamper(
        markerNumbers=[ground_marker, mesh_marker], springForceUserFunction=mesh_force))
    sensor = mbs.AddSensor(exu.itemInterface.SensorNode(
        nodeNumber=node, storeInternal=True, writeToFile=False,
        outputVariableType=exu.OutputVariableType.Coordinates_tt))
    mbs.Assemble()

    sensor_rate = settings.output_rate * settings.oversampling
    step = 1.0 / (sensor_rate * settings.steps_per_sensor_sample)
    end_time = settings.settle_time + settings.duration
    sim = exu.SimulationSettings()
    sim.timeIntegration.numberOfSteps = int(round(end_time / step))
    sim.timeIntegration.endTime = sim.timeIntegration.numberOfSteps * step
    sim.timeIntegration.verboseMode = 0
    sim.solution.file.write = False
    sim.solution.sensors.writePeriod = 1.0 / sensor_rate
    try:
        mbs.SolveDynamic(sim, solverType=exu.DynamicSolverType.RK44)
    except Exception as exc:
        raise SimulationError(f"exudyn solver failed: {exc}") from exc

    data = mbs.GetSensorStoredData(sensor)  # columns: time, 14 accelerations
    acc = data[:, 1:]
    deflection = mbs.GetNodeOutput(node, exu.OutputVariableType.Coordinates)[GEAR_ROT]
    if not np.isfinite(acc).all() or abs(deflection) > settings.max_deflection:
        raise SimulationError(
            f"simulation diverged ({params.health_state}, {params.speed_rpm} rpm): "
            f"non-finite accelerations or mesh deflection {deflection:.3g} m")
    lowpass = decimation_filter(settings.oversampling)
    first = int(round(settings.settle_time * settings.output_rate))
    n_out = int(round(settings.duration * settings.output_rate))
    signals = {}
    for sensor_name, housing in SENSOR_HOUSINGS.items():
        for axis, suffix in ((0, "x"), (1, "y")):
            # Filter the whole run (settling included) so filter edge effects fall in the
            # discarded part, then decimate to the output rate.
            out = resample_poly(acc[:, HOUSING_X[housing] + axis], 1, settings.oversampling, window=lowpass)
            signals[f"{sensor_name}_{suffix}"] = out[first:first + n_out]
    for name, signal in signals.items():
        if not np.isfinite(signal).all():
            raise SimulationError(f"channel {name}: non-finite samples after filtering")
    return signals

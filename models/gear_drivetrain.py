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
(Algorithm 1 of the helical-gear study). Two mesh stiffness models (`mesh_stiffness_model`):
`potential_energy` (`TVMSMeshForce`: the pair stiffness over the mesh phase from the
potential-energy method with helical slicing, `models/gear_mesh.py`, precomputed as tables) and
`simple` (`MeshForce`: rectangular contact windows of equal pairs). Sensors record housing
accelerations above the output rate; the signals are low-pass filtered and decimated to the output
rate (no aliasing) and checked finite.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import resample_poly

from condmon.models.contact_laws import hysteresis_factor
from condmon.models.numerics import SimulationError, decimation_filter, solve_rk44
from condmon.models.gear_mesh import GearGeometry, GearMesh, ProfileDeviation, ToothDamage

HEALTH_STATES = ("healthy", "surface_fault", "missing_tooth", "chipped_tooth", "root_crack")
MESH_STIFFNESS_MODELS = ("potential_energy", "simple")
CHANNELS = ("A1_x", "A1_y", "A2_x", "A2_y")

# Coordinate indices in the physical ordering.
PINION_X, PINION_Y, PINION_ROT, GEAR_X, GEAR_Y, GEAR_ROT = range(6)
HOUSING_X = (6, 8, 10, 12)  # housings 1, 2 carry the input shaft, 3, 4 the output shaft
N_COORDINATES = 14
# A1 above the input shaft (housing 1), A2 above the output shaft (housing 3).
SENSOR_HOUSINGS = {"A1": 0, "A2": 2}


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
    mesh_stiffness_model: str = "potential_energy"  # or "simple" (rectangular windows)
    helix_slices: int = 80                 # slices of the face width (potential_energy)
    contact_law: str = "lankarani_nikravesh"
    mesh_stiffness: float = 4.0e8          # mean mesh stiffness at 1 um deflection, N/m
    contact_exponent: float = 1.5
    restitution: float = 0.9
    approach_velocity: float = 0.02        # delta_dot(-) of a tooth engagement, m/s
    backlash: float = 1.0e-4               # along the line of action, m
    # Static TE at mesh frequency: simple model, TE = amplitude sin(2 pi mesh phase);
    # potential_energy, a sinusoidal profile deviation of every flank (one period per base pitch)
    # whose amplitude gives this static TE once averaged over the contact lines (a helical pair
    # filters a profile deviation by about |sinc(eps_beta)|), plus linear tip relief.
    transmission_error: float = 0.3e-6     # amplitude, m
    tip_relief: float = 0.0                # depth at both tips, from the HPSTC/LPSTC on, m
    # Load and speed.
    load_torque: float = 10.0              # on the output shaft, N m
    speed_rpm: float = 1100.0              # input shaft
    # Health.
    health_state: str = "healthy"
    faulty_tooth: int = 0                  # pinion tooth index of the damage
    surface_fault_teeth: int = 3           # consecutive pinion teeth with a surface fault
    surface_fault_stiffness_loss: float = 0.15  # simple: of the whole tooth; potential_energy: in the spall
    # Spall (potential_energy): region of the flank in fractions of the active profile (0 = pinion
    # root contact, 1 = tip) and of the face width, and its depth below the flank.
    surface_fault_profile: tuple = (0.35, 0.65)
    surface_fault_face: tuple = (0.25, 0.75)
    surface_fault_depth: float = 2.0e-5
    # Chipped tooth: flank lost above this profile fraction over `chip_face` of the face width.
    chip_profile: float = 0.6
    chip_face: tuple = (0.0, 0.5)
    # Root crack: fraction of the root half thickness the crack cuts (through the face).
    crack_depth: float = 0.5
    # Effects of a real bench that the calibrated model leaves out (zero in the model).
    speed_fluctuation: float = 0.0         # relative amplitude of a sinusoidal speed variation
    speed_fluctuation_hz: float = 2.0
    runout_pinion: float = 0.0             # shaft run-out (eccentricity), m
    runout_gear: float = 0.0
    runout_phase: float = 0.0              # rad, phase of the pinion run-out at t = 0 (gear: + pi/3)

    def replace(self, **changes) -> "GearDrivetrainParameters":
        return dataclasses.replace(self, **changes)


DEFLECTION_REF = 1.0e-6  # m; K = mesh stiffness at this deflection keeps K's unit N/m for any n


def tooth_damage(p: GearDrivetrainParameters) -> ToothDamage | None:
    """The health state of `p` as tooth geometry (None when healthy)."""
    if p.health_state not in HEALTH_STATES:
        raise ValueError(f"unknown health state {p.health_state!r}; choose one of {list(HEALTH_STATES)}")
    tooth = p.faulty_tooth
    if p.health_state == "healthy":
        return None
    if p.health_state == "missing_tooth":
        return ToothDamage("missing", teeth=(tooth,))
    if p.health_state == "surface_fault":
        return ToothDamage("spall", teeth=tuple(tooth + k for k in range(p.surface_fault_teeth)),
                           profile=tuple(p.surface_fault_profile), face=tuple(p.surface_fault_face),
                           depth=p.surface_fault_depth, stiffness_loss=p.surface_fault_stiffness_loss)
    if p.health_state == "chipped_tooth":
        return ToothDamage("chip", teeth=(tooth,), profile=(p.chip_profile, 1.0), face=tuple(p.chip_face))
    return ToothDamage("crack", teeth=(tooth,), crack_depth=p.crack_depth)


def gear_mesh(p: GearDrivetrainParameters) -> GearMesh:
    """The potential-energy TVMS tables of `p` (geometry, slices, profile deviations, damage)."""
    return GearMesh(p.geometry, slices=p.helix_slices, damage=tooth_damage(p),
                    profile_deviation=ProfileDeviation(tip_relief=p.tip_relief),
                    transmission_error=p.transmission_error)


class MeshForce:
    """Sum of the tooth-pair contact forces along the line of action, a function of
    (time, mesh deflection, deflection rate): the `simple` mesh stiffness model.

    `MeshForce(p)` builds the model `p.mesh_stiffness_model` names (`TVMSMeshForce` for
    `potential_energy`).

    Each tooth pair j is nominally in contact while the mesh phase (in mesh periods) is in
    [j, j + contact ratio), all pairs equally stiff. Outside that window the pair still touches once
    the deflection exceeds the gap of its tooth tip to the flank, which grows quadratically with the
    distance s outside the window (g = s^2 / (2 rho)): this is the extended contact that catches the
    gears when a tooth is missing, instead of free flight. Damaged pinion teeth scale their pair
    stiffness (a chipped tooth or root crack by the loss the potential-energy model gives for the
    tooth's mean stiffness). A back-flank contact closes the backlash.
    """

    def __new__(cls, p: GearDrivetrainParameters):
        if p.mesh_stiffness_model not in MESH_STIFFNESS_MODELS:
            raise ValueError(f"unknown mesh_stiffness_model {p.mesh_stiffness_model!r}; "
                             f"choose one of {list(MESH_STIFFNESS_MODELS)}")
        if cls is MeshForce and p.mesh_stiffness_model == "potential_energy":
            cls = TVMSMeshForce
        return super().__new__(cls)

    def _common(self, p: GearDrivetrainParameters):
        g = p.geometry
        self.contact_ratio = g.contact_ratio
        self.mesh_frequency = p.speed_rpm / 60.0 * g.teeth_pinion
        self.shaft_frequency = p.speed_rpm / 60.0
        self.gear_frequency = self.shaft_frequency * g.teeth_pinion / g.teeth_gear
        self.base_pitch = g.base_pitch
        self.tip_radius = g.base_radius(g.teeth_pinion)  # rho of the tip gap s^2 / (2 rho)
        self.teeth = g.teeth_pinion
        self.gear_ratio = g.teeth_pinion / g.teeth_gear
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
        self.damage = tooth_damage(p)

    def __init__(self, p: GearDrivetrainParameters):
        self._common(p)
        # Per pair K with delta in um-normalised form: F = K_ref * (delta/delta_ref)^n.
        self.pair_force_ref = p.mesh_stiffness * DEFLECTION_REF / self.contact_ratio
        self.tooth_factor = np.ones(self.teeth)
        if p.health_state == "surface_fault":
            for k in range(p.surface_fault_teeth):
                self.tooth_factor[(p.faulty_tooth + k) % self.teeth] = 1.0 - p.surface_fault_stiffness_loss
        elif p.health_state == "missing_tooth":
            self.tooth_factor[p.faulty_tooth % self.teeth] = 0.0
        elif p.health_state in ("chipped_tooth", "root_crack"):
            tvms = GearMesh(p.geometry, slices=p.helix_slices, damage=self.damage)
            self.tooth_factor[p.faulty_tooth % self.teeth] = (
                sum(grp.stiffness.sum() for grp in tvms.groups(p.faulty_tooth))
                / sum(grp.stiffness.sum() for grp in tvms.healthy_groups))
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


class TVMSMeshForce(MeshForce):
    """Algorithm 1 of the helical-gear study with the potential-energy TVMS (`potential_energy`).

    Every tooth pair j (pinion tooth j mod z1) meshes while its phase u = phase - j is in
    [0, eps_alpha + eps_beta); its contact groups (one per pair; a spall adds a second one, the
    pit, `depth` below the flank) carry F = K(u) delta^n (1 + f(c_r) delta_dot / delta_dot(-)) with
    K(u) from the precomputed table (linear interpolation on a uniform grid in pure Python; no
    energy integral at run time) and delta = mesh deflection - profile deviation e(u) (static
    transmission error). The tables are scaled so that the healthy mean mesh stiffness at 1 um is
    `mesh_stiffness` (the calibrated quantity keeps its meaning; the potential-energy method sets
    the shape over the mesh cycle, the load sharing and the damage). A pair whose stiffness does
    not vanish at the edge of its window (spur gears) keeps the extended contact of the simple
    model beyond it (tip gap s^2 / (2 rho)); a helical pair enters and leaves gradually, slice by
    slice, so its neighbours carry the load over a missing tooth. The back flank closes the backlash
    with the mean stiffness.
    """

    def __init__(self, p: GearDrivetrainParameters):
        self._common(p)
        self.te_amplitude = 0.0  # the static TE comes from the profile deviation tables
        tvms = gear_mesh(p)
        self.tvms = tvms
        self.window = tvms.window
        self.points_per_pitch = tvms.points_per_pitch
        scale = p.mesh_stiffness * DEFLECTION_REF / tvms.mean_stiffness
        edge = int(math.floor(self.window * self.points_per_pitch))

        def compile_group(group):
            k = (group.stiffness * scale).tolist()
            e = group.deviation.tolist()
            rows = [(k[i], k[i + 1] - k[i], e[i], e[i + 1] - e[i]) for i in range(len(k) - 1)]
            return rows, (k[0], e[0], k[edge], e[edge])

        compiled = {}
        self.tooth_groups = []
        for tooth in range(self.teeth):
            groups = tvms.groups(tooth)
            if id(groups) not in compiled:
                compiled[id(groups)] = tuple(compile_group(g) for g in groups)
            self.tooth_groups.append(compiled[id(groups)])
        self.extended = any(edges[0] > 0 or edges[2] > 0
                            for groups in self.tooth_groups for _, edges in groups)
        healthy = tvms.healthy_groups[0]
        self.mean_deviation = float((healthy.stiffness * healthy.deviation).sum() / healthy.stiffness.sum())

    def __call__(self, t, deflection, rate):
        phase, phase_rate = self.phase(t)
        if self.runout[0] or self.runout[1]:
            e, e_t = self.excitation(t, phase, phase_rate)  # run-out only
            d, d_t = deflection - e, rate - e_t
        else:
            d, d_t = deflection, rate
        starts = self.contact_start
        back = -d - self.backlash
        if back > 0.0:  # back flank contact closes the backlash
            return -self._force("back", self.mean_force_ref, back, -d_t)
        if "back" in starts:
            del starts["back"]
        window, ppp, pitch = self.window, self.points_per_pitch, self.base_pitch
        ext = math.sqrt(2.0 * self.tip_radius * d) / pitch if (self.extended and d > 0.0) else 0.0
        first = math.floor(phase - window - ext) + 1
        if len(starts) > 16:  # forget contacts of pairs that have left the mesh
            for key in [k for k in starts if k < 4 * first]:
                del starts[key]
        n, hyst, v_min, ref_inv = self.exponent, self.hysteresis, self.approach_velocity, 1.0 / DEFLECTION_REF
        rho = self.tip_radius
        total = 0.0
        for j in range(first, math.floor(phase + ext) + 1):
            u = phase - j
            key = 4 * j
            for rows, edges in self.tooth_groups[j % self.teeth]:
                if 0.0 <= u < window:
                    x = u * ppp
                    i = int(x)
                    k0, dk, e0, de = rows[i]
                    k = k0 + (x - i) * dk
                    gd = d - e0 - (x - i) * de
                    gd_t = d_t - de * ppp * phase_rate
                else:  # extended contact beyond the window: tip gap s^2 / (2 rho)
                    if u < 0.0:
                        s = -u * pitch
                        k, e0 = edges[0], edges[1]
                        gd, gd_t = d - e0 - s * s / (2 * rho), d_t + s * pitch * phase_rate / rho
                    else:
                        s = (u - window) * pitch
                        k, e0 = edges[2], edges[3]
                        gd, gd_t = d - e0 - s * s / (2 * rho), d_t - s * pitch * phase_rate / rho
                if k <= 0.0 or gd <= 0.0:
                    if key in starts:
                        del starts[key]
                    key += 1
                    continue
                # Contact law (Table 1): delta_dot(-) is the approach speed when this contact began,
                # at least `approach_velocity` (see MeshForce._force).
                v_minus = starts.get(key)
                if v_minus is None:
                    v_minus = starts[key] = gd_t if gd_t > v_min else v_min
                force = k * (gd * ref_inv) ** n * (1.0 + hyst * gd_t / v_minus)
                if force > 0.0:
                    total += force
                key += 1
        return total

    def static_deflection(self, force):
        return super().static_deflection(force) + self.mean_deviation


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


def simulate(params: GearDrivetrainParameters, settings: SimulationSettings = SimulationSettings(),
             diagnostics: dict | None = None):
    """Run the model; return {channel: acceleration in m/s^2 at settings.output_rate}.

    diagnostics: a dict to receive `time` and the mesh `deflection` (m, along the line of action,
    at the sensor rate, settling included) and `mesh_calls` (calls of the mesh force function)."""
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

    calls = [0]

    def mesh_force(mbs_, t, item, displacement, velocity, k, d, offset):
        return mesh(t, displacement, velocity)

    def counted_mesh_force(mbs_, t, item, displacement, velocity, k, d, offset):
        calls[0] += 1
        return mesh(t, displacement, velocity)

    mbs.AddObject(exu.itemInterface.ObjectConnectorCoordinateSpringDamper(
        markerNumbers=[ground_marker, mesh_marker],
        springForceUserFunction=mesh_force if diagnostics is None else counted_mesh_force))
    sensor = mbs.AddSensor(exu.itemInterface.SensorNode(
        nodeNumber=node, storeInternal=True, writeToFile=False,
        outputVariableType=exu.OutputVariableType.Coordinates_tt))
    if diagnostics is not None:
        position_sensor = mbs.AddSensor(exu.itemInterface.SensorNode(
            nodeNumber=node, storeInternal=True, writeToFile=False,
            outputVariableType=exu.OutputVariableType.Coordinates))
    mbs.Assemble()

    try:
        solve_rk44(mbs, settings.output_rate * settings.oversampling,
                   settings.steps_per_sensor_sample, settings.settle_time + settings.duration)
    except Exception as exc:
        raise SimulationError(f"exudyn solver failed: {exc}") from exc

    data = mbs.GetSensorStoredData(sensor)  # columns: time, 14 accelerations
    acc = data[:, 1:]
    if diagnostics is not None:
        positions = mbs.GetSensorStoredData(position_sensor)
        diagnostics.update(time=positions[:, 0], deflection=positions[:, 1 + GEAR_ROT], mesh_calls=calls[0])
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

"""Lumped multibody model of the CWRU bearing rig (2 HP motor, SKF 6205 drive end, SKF 6203 fan
end) in exudyn, with a defect on the drive-end bearing and the measurement chain to the drive-end
housing accelerometer.

Pure: parameters in, signals out. Knows nothing of Snakemake, MLflow or the config.

Mechanics (exudyn, plane x horizontal / y vertical, 8 DOF plus 2 a mode, the central difference
by default, or RK44: `RigSettings.integrator`):
- rotor (shaft and motor rotor) as two point masses at the drive-end (DE) and fan-end (FE)
  journals, joined by the shaft's bending stiffness (linear spring-damper); gravity, a radial load
  on the DE journal and a rotating unbalance force act on them;
- each bearing housing (motor end shield) a point mass on a spring-damper to the motor frame
  (modal damping ratio `housing_damping_ratio`);
- each ball bearing one `ObjectConnectorCartesianSpringDamper` between journal and housing whose
  *symbolic* force function (compiled by exudyn, no Python call per step) sums the Hertzian
  ball-race forces F_j = K max(delta_j, 0)^1.5 of every ball at its cage-rotating angle
  phi_j = Omega_cage t + 2 pi j / Z, delta_j = u . e_j - c_r (u journal minus housing
  displacement, c_r the radial clearance), plus a linear bearing damping;
- the defect (DE bearing only) is a local loss of contact deflection p(t) of the ball that is in
  it: the connector adds K [max(delta_d - p, 0)^1.5 - max(delta_d, 0)^1.5] along the line through
  the defect (`_DefectProfile`): at the fixed clock position for the outer race, rotating with the
  shaft for the inner race, carried by the cage (ball 0) for a ball defect, which meets the outer
  and the inner race in turn, once each per spin (strikes at 2 x BSF; the convex inner race lets
  the ball sink deeper than the concave outer one, so the strikes alternate in strength and the
  envelope shows BSF too). The defect has a width (the ball can only sink by
  w^2/(8 R_b) (1 +/- R_b/R_race) into a narrow slot, at most the depth), raised-cosine entry and
  exit ramps (`defect_entry`, `defect_exit` as fractions of the width: a gradual entry/exit is
  far less impulsive than a square pit), and per-passage randomness from a hash of the passage
  index evaluated inside the symbolic function: depth variation and, for a ball whose spin axis
  wanders, a strike probability. Slip is cumulative: the passage rate wanders around the
  kinematic one (a slow random slip rate of std `slip_std`, `SLIP_COMPONENTS` sinusoids between
  `SLIP_BAND_HZ`), and the passage phase is its integral, so a passage late once stays late and
  the defect lines spread around the kinematic frequencies by about the slip instead of sitting
  exactly on them. The outer-race defect sits at `defect_clock` (CWRU rigs: 3:00, 6:00, 12:00;
  the load pushes the journal down, so away from 6:00 its balls carry less load and strike
  weaker, and above the load zone they strike only if an axial preload (`axial_preload`)
  keeps them pressed).

Structure and measurement chain: the DE housing (end shield and motor frame) carries several
light structural modes (`resonances`: frequency, damping ratio, gain in m/s^2 per N, and
optionally the mode's tilt in degrees), each a modal mass (`modal_mass_share` of the housing
mass) on a spring-damper to the housing, tuned to its frequency and damping. The bearing force
moves the housing and the housing drives the modes; their reaction acts back on the housing and
so on the bearing, as in the structure. The accelerometer reads the housing's acceleration
(`housing_path_gain`) plus each mode's relative acceleration with a participation g m_housing:
above the housing's mount and contact modes the housing moves as its mass under the bearing
force F, so a mode's share of the reading is close to g s^2 / (s^2 + 2 zeta w s + w^2) F, which
is what `gain` means. A mode's motion at the sensor need not be vertical: it reads the mode's
relative motion along its tilt (degrees from vertical, towards 3 o'clock), so a horizontal
bearing force (a defect at 3:00) reaches the 12 o'clock accelerometer through the tilted modes,
as through a real end shield, where the vertical housing motion alone would never show it. The
rough running of a damaged contact (`defect_roughness`) is a random force on the DE housing and journal inside the model
too, so it reaches the sensor along the same paths as the impacts. The integration step resolves
the modes: the central difference at 96 kHz (omega h <= 0.33 up to 5 kHz: frequency error
(omega h)^2 / 24 under 0.5 %, no numerical damping), or RK44 at 48 kHz (omega h <= 0.7: numerical
damping under 1e-3 of critical).
Then the FIR low-pass and decimation to the output rate (no aliasing), the sensor gain, and
broadband background (white noise plus random band-limited components, `background`) that
stands in for everything else on a real motor (electromagnetic, fan, coupling, base).
The accelerometer is at 12 o'clock on the DE housing: channel "DE" is +y acceleration, m/s^2.

Speed (measured on the 2-core CI machine, exudyn 1.13.6, one process): 1.2-1.35 s of CPU per
simulated second with the modes as filters after the run (defaults, oversampling 4, h = 20.8 us,
load-zone ball sums; 96 randomised samples of 0.78 s took 100 s of CPU); the modes and the rough
running in the model cost about 10 % more (about 20 % with rough running), measured side by side.
Summing every ball of both bearings costs about 40 % more (an axial preload presses every
DE ball, so such a run sums all of the DE's), and the defect term is gated by a cheap
`IfThenElse` so it costs nothing between passages. Oversampling 4 (not 10) keeps the cost: against
oversampling 8 (h/2), an outer-race run agrees within 0.4 % in RMS and 0.3 % in kurtosis, a
ball-defect run with rough running within 0.7 % in RMS, kurtosis and the 2 x BSF envelope-line
ratio (the outer race's BPFO line ratio, over a floor of a few bins, moves by 20 %; it moved by
40 % with the modes as filters) (`SPEED_NOTE`).

Speed at solver depth (issue 51; exudyn's timers and counters, healthy benchmark sample of 0.78 s,
axial preload drawn, so every DE ball is summed): RK44 has no Newton iterations nor Jacobians;
at h = 20.8 us it took 37568 steps of 5 force calls (4 stages and the end-of-step accelerations the
sensors read), 83 % of the time in ODE2RHS, of which about 70 % the two bearings' symbolic ball
sums (linear connectors in their place: 0.35 against 1.17 s per simulated second), and 14 % in
writing sensors: a sensor on the DE connector (force, displacement) evaluated its force function
again per sample, so the displacement now comes from the two nodes' positions (bitwise the same)
and the force only for diagnostics. RK44 at 20.8 us is far finer than the features need (0.001 dB
against h/4), so the default is the central difference (`central_difference_mass`), one force
call a step: at h = 10.4 us, 2.4 calls per sensor sample against 5 (measured 1.24 -> 0.52 s per
simulated second, step check 0.027 dB against h/4; the defect runs' kurtosis and envelope line
ratios as close to RK44 at h/4 as RK44 at 20.8 us's: within 0.04 and 0.23 in log, against 0.04
and 0.21). At 20.8 us it runs 2.9x faster than RK44 (step check 0.11 dB) but its defect runs' line
ratios move up to 0.45 in log, twice RK44's.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq
from scipy.signal import bilinear, lfilter, resample_poly

from condmon.models.numerics import SimulationError, decimation_filter, exudyn_system, solve_rk44

SPEED_NOTE = (
    "0.5 s of wall time per simulated second on one core of an idle 2-core machine (defaults: "
    "central difference, oversampling 4, h = 10.4 us, axial preload, modes and rough running in the "
    "model; RK44 at 20.8 us: 1.1-1.2), up to 2x when the 2 cores are shared"
)
DEFECT_KINDS = ("none", "outer_race", "inner_race", "ball")
CHANNELS = ("DE",)
INCH = 0.0254


@dataclass(frozen=True)
class BearingGeometry:
    """Deep-groove ball bearing geometry; lengths in m."""

    n_balls: int
    ball_diameter: float
    pitch_diameter: float
    contact_angle_deg: float = 0.0

    def orders(self) -> dict:
        """Kinematic defect frequencies in orders of the shaft speed (fixed outer race):
        BPFO = Z/2 (1 - r), BPFI = Z/2 (1 + r), FTF = (1 - r)/2, BSF = D/(2d) (1 - r^2)
        (ball spin relative to the cage, as the CWRU table defines it), r = d/D cos(alpha)."""
        r = (
            self.ball_diameter
            / self.pitch_diameter
            * math.cos(math.radians(self.contact_angle_deg))
        )
        z = self.n_balls
        return dict(
            bpfo=z / 2 * (1 - r),
            bpfi=z / 2 * (1 + r),
            ftf=(1 - r) / 2,
            bsf=self.pitch_diameter / (2 * self.ball_diameter) * (1 - r**2),
        )

    @property
    def outer_race_radius(self) -> float:  # ball-outer race contact radius
        return (self.pitch_diameter + self.ball_diameter) / 2

    @property
    def inner_race_radius(self) -> float:  # ball-inner race contact radius
        return (self.pitch_diameter - self.ball_diameter) / 2


SKF_6205 = BearingGeometry(9, 7.94e-3, 39.04e-3, 0.0)  # drive end (CWRU)
SKF_6203 = BearingGeometry(8, 0.2656 * INCH, 1.122 * INCH, 0.0)  # fan end (CWRU)


def _resonances_default():
    # no source: the bands the shared CWRU fault records ring in (105, 130: 2.9, 3.4, 3.6-3.7 kHz)
    return ((2900.0, 0.04, 0.6), (3400.0, 0.03, 1.0), (3700.0, 0.04, 0.5))


def _background_default():
    # no source: the strongest line (4146 Hz) and a 650-690 Hz band of the healthy CWRU record 97
    return ((4150.0, 0.01, 0.45), (650.0, 0.15, 0.25))


@dataclass
class BearingRigParameters:
    """Physical parameters of the rig, SI units. Defaults: the nominal (uncalibrated) CWRU rig;
    where each comes from (the CWRU site, an assumption, the records it was read off):
    ARCHITECTURE.md, "Nominal rig values and where they come from"."""

    speed_rpm: float = 1797.0  # shaft speed
    de_geometry: BearingGeometry = SKF_6205
    fe_geometry: BearingGeometry = SKF_6203
    # Rotor (shaft + motor rotor), lumped at the two journals.
    rotor_mass: float = 8.0  # kg, total
    de_mass_share: float = 0.5  # share of the rotor mass at the DE journal
    shaft_stiffness: float = 5.0e7  # N/m, bending stiffness between the journals
    shaft_damping_ratio: float = 0.02  # modal damping ratio of the shaft bending mode
    gravity: float = 9.81  # m/s^2, acts on rotor and housings (-y)
    radial_load: float = 0.0  # N, extra downward load on the DE journal
    unbalance: float = 2.0e-5  # kg m, rotating unbalance m e (split over the journals)
    # Ball-race contact (Hertz, point contact, both races in series): F = K delta^1.5.
    contact_stiffness: float = 8.0e9  # N/m^1.5, DE (6205); FE scaled by (d_FE/d_DE)^0.5
    radial_clearance: float = 5.0e-6  # m, radial internal clearance (both bearings)
    # N, axial preload of a spring-loaded bearing arrangement (a wave spring on one outer ring):
    # it shifts the rings axially until every DE ball touches both races (`preload_deflection`),
    # so balls away from the load zone stay pressed and an outer-race defect at 12:00 or 3:00
    # still strikes (weaker); 0: no spring, the radial clearance stays
    axial_preload: float = 0.0
    bearing_damping: float = 300.0  # N s/m, linear viscous damping journal-housing
    # Housings (end shields) on the motor frame.
    housing_mass: float = 3.0  # kg, each
    housing_stiffness: float = 1.5e8  # N/m, each, both directions
    housing_damping_ratio: float = 0.05  # modal damping ratio of the housing mode
    # Defect on the DE bearing.
    defect_kind: str = "none"  # none | outer_race | inner_race | ball
    defect_width: float = 0.007 * INCH  # m, extent along the rolling direction
    defect_depth: float = 0.011 * INCH  # m (CWRU EDM pits are 0.011 in deep)
    defect_drop_scale: float = 1.0  # factor on the drop the ball can reach (edge rounding, wear)
    defect_clock: float = 6.0  # clock position of an outer-race defect, hours (12 = top)
    defect_entry: float = 0.3  # entry ramp, fraction of the width (raised cosine)
    defect_exit: float = 0.1  # exit ramp, fraction of the width
    defect_depth_variation: float = 0.2  # per-passage depth spread, +/- fraction (uniform)
    # chance that a passage strikes; None: a race defect every passage, a ball defect the share of
    # its spin turns on which its pit crosses the rolling track (`ball_strike_probability`)
    defect_strike_probability: float | None = None
    defect_phase: float = 0.0  # rad: inner-race defect angle / ball defect spin angle at t=0
    slip_std: float = 0.01  # std of the wandering slip rate, fraction of the passage rate
    # Rough running of the damaged contact (rough pit floor, debris, a ball pit rubbing obliquely):
    # a random force (N rms, white up to 24 kHz) between the DE journal and housing, modulated
    # at the defect's passage rate with depth `defect_roughness_modulation` (0 stationary, 1 gated).
    defect_roughness: float = 0.0
    defect_roughness_modulation: float = 0.5
    # Structural modes of the DE housing (frequency Hz, damping ratio, gain m/s^2 per N of DE
    # bearing force at the sensor, optionally the tilt in degrees from vertical of the mode's
    # motion at the sensor, default 0), each a modal mass of modal_mass_share x housing_mass on
    # the housing; the housing's own acceleration enters the sensor with housing_path_gain.
    resonances: tuple = field(default_factory=_resonances_default)
    modal_mass_share: float = 0.01
    housing_path_gain: float = 1.0
    sensor_gain: float = 1.0  # multiplies the whole mechanical signal
    noise_rms: float = 0.3  # m/s^2, white broadband noise
    # Background bands (frequency Hz, damping ratio, RMS m/s^2): random noise through a resonance.
    background: tuple = field(default_factory=_background_default)

    def replace(self, **changes) -> "BearingRigParameters":
        return dataclasses.replace(self, **changes)

    @property
    def shaft_hz(self) -> float:
        return self.speed_rpm / 60.0


@dataclass
class RigSettings:
    """Numerical settings of one run."""

    output_rate_hz: float = 12000.0
    oversampling: int = 4  # sensor rate = oversampling x output rate
    # step = 1 / (sensor rate x this); 2 with the central difference: 10.4 us, one force call a
    # step (2.4 a sensor sample against RK44's 5 at 20.8 us), its defect features as close to
    # RK44 at h/4 as RK44 at 20.8 us's are
    steps_per_sensor_sample: int = 2
    settle_time: float = 0.1  # simulated then discarded, s
    duration: float = 1.0  # recorded seconds
    max_penetration: float = 2.0e-4  # |journal - housing| beyond clearance + this is divergence, m
    load_zone_only: bool = True  # sum only the balls near the bottom (checked; else rerun with all)
    # "rk44" (four force calls a step, a fifth for the sensed accelerations) or
    # "central_difference" (one a step, accelerations included: exudyn's velocity Verlet with the
    # damping correction of `central_difference_mass`, second order)
    integrator: str = "central_difference"


def clock_angle(hours: float) -> float:
    """Angle (rad, from +x = 3 o'clock, counter-clockwise) of a clock position (12 = top)."""
    return math.radians(90.0 - 30.0 * hours)


def preload_deflection(p: BearingRigParameters) -> float:
    """Contact deflection (m) every DE ball carries from the axial preload `axial_preload` (0
    without one). A deep-groove bearing under a pure axial load F_a takes up its radial clearance
    c_r by an axial shift, each ball then contacts at the angle alpha with
    cos alpha = A cos alpha_0 / (A + delta), cos alpha_0 = 1 - c_r / A, A = (f_i + f_o - 1) D the
    distance of the groove curvature centres, and carries Q = K delta^1.5 with
    Z Q sin alpha = F_a (Harris and Kotzalas, Rolling Bearing Analysis, ch. 2 and 7), solved for
    delta (Z K delta^1.5 sin alpha grows with delta)."""
    if p.axial_preload <= 0:
        return 0.0
    g = p.de_geometry
    curvature_centres = (2 * GROOVE_CONFORMITY - 1) * g.ball_diameter
    cos_free = 1.0 - p.radial_clearance / curvature_centres
    if not cos_free > 0:
        raise ValueError(
            f"radial_clearance {p.radial_clearance:g} m exceeds the groove geometry's "
            f"{curvature_centres:g} m: no contact angle"
        )

    def axial_force(delta):
        cos_alpha = curvature_centres * cos_free / (curvature_centres + delta)
        return (
            g.n_balls * p.contact_stiffness * delta**1.5 * math.sqrt(max(1.0 - cos_alpha**2, 0.0))
        )

    if axial_force(1e-3) < p.axial_preload:
        raise ValueError(f"axial_preload {p.axial_preload:g} N: beyond 1 mm of contact deflection")
    return float(brentq(lambda delta: axial_force(delta) - p.axial_preload, 0.0, 1e-3, xtol=1e-18))


def de_clearance(p: BearingRigParameters) -> float:
    """The DE bearing's running clearance in the planar model: the radial clearance, or with an
    axial preload minus its `preload_deflection` (every ball pressed at rest; the deflection acts
    along the contact line, whose radial share cos alpha > 0.95 here the planar model takes as 1)."""
    return p.radial_clearance if p.axial_preload <= 0 else -preload_deflection(p)


def effective_defect_depth(p: BearingRigParameters, race: str | None = None) -> float:
    """How far the ball centre can sink into the defect: a ball of radius R_b spanning a slot of
    width w sinks w^2/(8 R_b) against a flat race, more on the convex inner race and less on the
    concave outer race (relative curvature 1/R_b +/- 1/R_race), and never deeper than the pit.
    A race defect meets its own race; a ball defect meets both in turn, so `race` ("outer" or
    "inner") names the one it meets."""
    g = p.de_geometry
    rb = g.ball_diameter / 2
    race = race or {"outer_race": "outer", "inner_race": "inner"}.get(p.defect_kind)
    if race == "outer":
        curvature = 1 / rb - 1 / g.outer_race_radius
    elif race == "inner":
        curvature = 1 / rb + 1 / g.inner_race_radius
    else:
        raise ValueError(
            f"defect {p.defect_kind!r}: name the race it meets ('outer' or 'inner'), got {race!r}"
        )
    return float(min(p.defect_depth, p.defect_drop_scale * p.defect_width**2 / 8 * curvature))


# Hertz contact of steel balls on steel races, and the races' groove radius over the ball diameter
# (deep-groove ball bearings: 0.515-0.53; Harris and Kotzalas, Rolling Bearing Analysis, ch. 2)
STEEL_YOUNGS_MODULUS = 2.08e11
STEEL_POISSON_RATIO = 0.3
GROOVE_CONFORMITY = 0.52


def contact_half_width(geometry: BearingGeometry, ball_load: float, race: str) -> float:
    """Semi-axis of the Hertz contact ellipse across the rolling direction (m) of a ball pressed
    with `ball_load` N on the "inner" or "outer" race: the half-width of the track the ball rolls
    on (Hamrock and Brewe 1983: ellipticity k = 1.0339 (Ry/Rx)^0.636, elliptic integral
    E = 1.0003 + 0.5968 Rx/Ry, semi-axis (6 k^2 E W R / (pi E'))^(1/3))."""
    if race not in ("inner", "outer"):
        raise ValueError(f"race {race!r}: 'inner' or 'outer'")
    rb = geometry.ball_diameter / 2
    race_radius = geometry.inner_race_radius if race == "inner" else -geometry.outer_race_radius
    rx = 1 / (1 / rb + 1 / race_radius)  # rolling direction
    ry = 1 / (1 / rb - 1 / (GROOVE_CONFORMITY * geometry.ball_diameter))  # across, in the groove
    k = 1.0339 * (ry / rx) ** 0.636
    elliptic = 1.0003 + 0.5968 * rx / ry
    reduced_modulus = STEEL_YOUNGS_MODULUS / (1 - STEEL_POISSON_RATIO**2)
    radius = 1 / (1 / rx + 1 / ry)
    return float(
        (6 * k**2 * elliptic * ball_load * radius / (math.pi * reduced_modulus)) ** (1 / 3)
    )


def ball_deflection_at(p: BearingRigParameters, clock: float) -> float:
    """Contact deflection (m) of a drive-end ball at a clock position at rest: the load-zone law
    (Stribeck's distribution, Harris) from the model's own static equilibrium. The journal sinks
    by the sag s until the balls carry its load (gravity and `radial_load`, straight down, 6:00);
    a ball at the angle psi from 6:00 is pressed by s cos(psi) - c, c the running clearance
    (`de_clearance`: the radial clearance, or negative with every ball pressed by the axial
    preload), and none where that is negative (outside the load zone)."""
    journal_load = p.rotor_mass * p.de_mass_share * p.gravity + p.radial_load
    clearance = de_clearance(p)
    sag = -_static_sag(p.de_geometry, p.contact_stiffness, clearance, journal_load)
    psi = clock_angle(clock) - clock_angle(6.0)
    return max(sag * math.cos(psi) - clearance, 0.0)


def most_loaded_ball_load(p: BearingRigParameters) -> float:
    """Load (N) of the drive end's most loaded ball at rest, the bottom one's (6:00, right under
    the load): K delta^1.5 of its `ball_deflection_at`."""
    return float(p.contact_stiffness * ball_deflection_at(p, 6.0) ** 1.5)


def outer_race_strike(p: BearingRigParameters, clock: float | None = None) -> float:
    """The load (N) a ball stops carrying as it rolls over an outer-race defect at `clock`
    (default `defect_clock`): its deflection there by the load-zone law (`ball_deflection_at`)
    less the depth it sinks into the defect (`effective_defect_depth`), K (delta^1.5 -
    max(delta - depth, 0)^1.5). A defect away from 6:00 sees less load and strikes weaker; one
    outside the load zone does not strike."""
    delta = ball_deflection_at(p, p.defect_clock if clock is None else clock)
    depth = effective_defect_depth(p, "outer")
    return float(p.contact_stiffness * (delta**1.5 - max(delta - depth, 0.0) ** 1.5))


def ball_strike_probability(p: BearingRigParameters) -> float:
    """Share of a defective ball's spin turns on which its pit meets the races. The ball rolls on
    a band about its spin equator as wide as the contact (`contact_half_width`, at the most
    loaded ball's load, `most_loaded_ball_load`); the pit strikes while its centre is within that
    half-width plus its own radius of the equator. A real ball's spin axis wanders (cage and race
    friction), so over many turns every orientation is taken: the share of the sphere within an
    angle beta of a great circle is sin(beta)."""
    g = p.de_geometry
    ball_load = max(most_loaded_ball_load(p), 1e-3)
    half_width = np.mean([contact_half_width(g, ball_load, race) for race in ("inner", "outer")])
    beta = (half_width + p.defect_width / 2) / (g.ball_diameter / 2)
    return float(min(1.0, math.sin(min(beta, math.pi / 2))))


def _check(p: BearingRigParameters, s: RigSettings) -> None:
    if p.defect_kind not in DEFECT_KINDS:
        raise ValueError(f"defect_kind {p.defect_kind!r}; choose one of {list(DEFECT_KINDS)}")
    positive = dict(
        speed_rpm=p.speed_rpm,
        rotor_mass=p.rotor_mass,
        contact_stiffness=p.contact_stiffness,
        housing_mass=p.housing_mass,
        housing_stiffness=p.housing_stiffness,
        shaft_stiffness=p.shaft_stiffness,
    )
    for name, value in positive.items():
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"{name} must be a positive number, got {value}")
    if not 0 < p.de_mass_share < 1:
        raise ValueError(f"de_mass_share must lie in (0, 1), got {p.de_mass_share}")
    if p.defect_kind != "none":
        if not (p.defect_width > 0 and p.defect_depth > 0 and p.defect_drop_scale > 0):
            raise ValueError(
                "defect_width, defect_depth and defect_drop_scale must be positive for a defect"
            )
        if not (0 < p.defect_entry <= 1 and 0 < p.defect_exit <= 1):
            raise ValueError("defect_entry and defect_exit must lie in (0, 1]")
        if p.defect_strike_probability is not None and not 0 < p.defect_strike_probability <= 1:
            raise ValueError(
                "defect_strike_probability must lie in (0, 1] (or be None: from the contact)"
            )
        if not (p.defect_roughness >= 0 and 0 <= p.defect_roughness_modulation <= 1):
            raise ValueError(
                "defect_roughness must be >= 0 and defect_roughness_modulation in [0, 1]"
            )
        if not 0 <= p.defect_depth_variation < 1:
            raise ValueError("defect_depth_variation must lie in [0, 1)")
    if not 0 <= p.slip_std < 0.2:
        raise ValueError(
            f"slip_std must lie in [0, 0.2) (fraction of the passage rate), got {p.slip_std}"
        )
    if not (np.isfinite(p.radial_clearance) and p.radial_clearance >= 0):
        raise ValueError(f"radial_clearance must be >= 0 m, got {p.radial_clearance}")
    if not (np.isfinite(p.axial_preload) and p.axial_preload >= 0):
        raise ValueError(f"axial_preload must be >= 0 N, got {p.axial_preload}")
    if not 0 <= p.defect_clock <= 12:
        raise ValueError(f"defect_clock must lie in [0, 12] hours, got {p.defect_clock}")
    # the step must resolve every mode: RK44 at omega h <= 1 keeps its numerical damping small
    # (under 1/144 of an amplitude a step), the central difference at omega h <= 0.5 its
    # frequency error ((omega h)^2 / 24, no numerical damping) about 1 %
    step_hz = s.output_rate_hz * s.oversampling * s.steps_per_sensor_sample
    for mode in p.resonances:
        if len(mode) not in (3, 4):
            raise ValueError(
                f"resonance {mode}: need (frequency Hz, damping ratio, gain[, tilt deg])"
            )
        f, zeta = mode[0], mode[1]
        limit = MODE_STEP_LIMIT.get(s.integrator, 1.0)
        if not (0 < f <= limit * step_hz / (2 * math.pi) and 0 < zeta < 1):
            raise ValueError(
                f"resonance ({f}, {zeta}): need 0 < f <= {limit * step_hz / (2 * math.pi):.0f} Hz "
                f"(omega h <= {limit} for {s.integrator} at this step) and 0 < zeta < 1"
            )
        if len(mode) == 4 and not -90 <= mode[3] <= 90:
            raise ValueError(
                f"resonance {mode}: the tilt must lie in [-90, 90] degrees from vertical"
            )
    if p.resonances and not 0 < p.modal_mass_share <= 0.2:
        raise ValueError(
            f"modal_mass_share must lie in (0, 0.2] (light modes), got {p.modal_mass_share}"
        )
    for f, zeta, level in p.background:
        if not (0 < f < s.output_rate_hz / 2 and 0 < zeta < 1 and level >= 0):
            raise ValueError(
                f"background band ({f}, {zeta}, {level}): need 0 < f < output Nyquist, "
                "0 < zeta < 1, rms >= 0"
            )
    if s.integrator not in INTEGRATORS:
        raise ValueError(f"integrator {s.integrator!r}; choose one of {list(INTEGRATORS)}")
    if s.oversampling < 2 or s.steps_per_sensor_sample < 1:
        raise ValueError("oversampling must be >= 2 and steps_per_sensor_sample >= 1")


# -- symbolic force functions -----------------------------------------------------------------
def _hash01(esym, k, a: float, b: float):
    """A pseudo-random number in [0, 1) of an integer-valued symbolic k (sine hash)."""
    z = esym.sin(k * a + b) * 43758.5453
    return z - esym.floor(z)


# Cumulative slip: the slip rate is a sum of this many sinusoids of random frequency in this band
# (slow against the passages, as load and lubrication change) and random phase.
SLIP_COMPONENTS = 4
SLIP_BAND_HZ = (0.5, 4.0)


class _DefectProfile:
    """Builds the symbolic defect term: the passage phase psi(t) (one unit per ball passage or
    strike, with the integrated slip), the local coordinate across the defect, the raised-cosine
    depth profile and the line along which it acts."""

    def __init__(self, p: BearingRigParameters, hash_seed: float):
        g = p.de_geometry
        o = g.orders()
        w_s = 2 * math.pi * p.shaft_hz
        w_c = o["ftf"] * w_s
        self.kind = p.defect_kind
        # passage k's drop: a race defect's own; a ball defect's alternates, outer race on even k
        self.depth = self.inner_extra = 0.0
        if self.kind in ("outer_race", "inner_race"):
            self.depth = effective_defect_depth(p)
        elif self.kind == "ball":
            self.depth = effective_defect_depth(p, "outer")
            self.inner_extra = effective_defect_depth(p, "inner") - self.depth
        self.width = p.defect_width
        self.entry, self.exit = p.defect_entry, p.defect_exit
        self.variation, self.strike = p.defect_depth_variation, p.defect_strike_probability
        if self.strike is None:
            self.strike = ball_strike_probability(p) if self.kind == "ball" else 1.0
        self.seed = hash_seed
        z = g.n_balls
        if self.kind == "outer_race":
            theta = clock_angle(p.defect_clock)
            self.theta = theta
            # ball j at the defect when w_c t + 2 pi j / Z = theta: psi integer
            self.psi_rate, self.psi0 = z * w_c / (2 * math.pi), -z * theta / (2 * math.pi)
            self.arc_per_unit = g.outer_race_radius * 2 * math.pi / z
            self.direction = None
        elif self.kind == "inner_race":
            self.psi_rate = z * (w_s - w_c) / (2 * math.pi)
            self.psi0 = z * p.defect_phase / (2 * math.pi)
            self.arc_per_unit = g.inner_race_radius * 2 * math.pi / z
            self.direction = (w_s, p.defect_phase)  # rotates with the shaft
        elif self.kind == "ball":
            # two strikes per spin revolution (outer race on even passages, inner race on odd
            # ones), spin = BSF x shaft
            self.psi_rate = 2 * o["bsf"] * p.shaft_hz
            self.psi0 = p.defect_phase / math.pi
            self.arc_per_unit = g.ball_diameter / 2 * math.pi
            self.direction = (w_c, 0.0)  # carried by the cage (ball 0)
        self.period = 1.0 / self.psi_rate if self.kind != "none" else float("nan")
        # slip rate s(t) = sum a cos(w t + phase), std slip_std; psi gains rate x its integral
        wander = np.random.default_rng(int(hash_seed * 1e6))
        omega = 2 * math.pi * wander.uniform(*SLIP_BAND_HZ, SLIP_COMPONENTS)
        phases = wander.uniform(0.0, 2 * math.pi, SLIP_COMPONENTS)
        amplitude = p.slip_std * math.sqrt(2.0 / SLIP_COMPONENTS)
        self.slip_terms = (
            [
                (float(self.psi_rate * amplitude / w), float(w), float(f))
                for w, f in zip(omega, phases)
            ]
            if self.kind != "none"
            else []
        )

    def phase(self, t, sin):
        """psi(t): passages since the reference, slip included (`sin`: esym.sin or np.sin)."""
        psi = t * self.psi_rate + self.psi0
        for amplitude, omega, phase in self.slip_terms:
            psi = psi + sin(t * omega + phase) * amplitude
        return psi

    def near_expr(self, esym, t):
        """Symbolic condition: the nearest passage is within the defect's reach, a cheap test
        that gates the costly profile."""
        psi = self.phase(t, esym.sin)
        u = psi - esym.floor(psi + 0.5)
        reach = 0.5 * self.width / self.arc_per_unit + 1e-3
        return esym.abs(u) < esym.Real(reach)

    def depth_expr(self, esym, t):
        R = esym.Real
        psi = self.phase(t, esym.sin)
        k = esym.floor(psi + 0.5)  # index of the nearest passage
        u = psi - k  # in [-0.5, 0.5): passages from it
        x = u * (self.arc_per_unit / self.width) + 0.5  # 0..1 across the defect
        ramp_in = esym.min(esym.max(x * (1.0 / self.entry), R(0.0)), R(1.0))
        ramp_out = esym.min(esym.max((1.0 - x) * (1.0 / self.exit), R(0.0)), R(1.0))
        shape = esym.min(
            0.5 - 0.5 * esym.cos(ramp_in * math.pi), 0.5 - 0.5 * esym.cos(ramp_out * math.pi)
        )
        scale = 1.0 + (_hash01(esym, k, 78.233, self.seed + 1.7) - 0.5) * (2 * self.variation)
        if self.strike < 1.0:
            hit = esym.IfThenElse(
                _hash01(esym, k, 39.3468, self.seed + 3.1) < R(self.strike), R(1.0), R(0.0)
            )
            scale = scale * hit
        depth = R(self.depth)
        if self.inner_extra:
            inner = k - esym.floor(k * 0.5) * 2.0  # 1 on odd passages: the inner race
            depth = depth + inner * self.inner_extra
        return shape * scale * depth

    def angle_terms(self, esym, t):
        """cos and sin of the line through the defect (the ball in it)."""
        if self.direction is None:
            return math.cos(self.theta), math.sin(self.theta)
        rate, phase = self.direction
        angle = t * rate + phase
        return esym.cos(angle), esym.sin(angle)


# The rough-running window: cos(pi u)^8 of the passage offset u, about a fifth of the period wide,
# scaled to unit mean square (mean of cos^16 over a period: C(16, 8) / 2^16).
ROUGHNESS_WINDOW_POWER = 8
ROUGHNESS_WINDOW_RMS = math.sqrt(math.comb(16, 8) / 2**16)
# The rough-running force is white up to 24 kHz (held over 1/48000 s), whatever the step, so
# a finer step does not spread the same force over a wider band.
ROUGHNESS_HOLD_RATE_HZ = 48000.0


def _roughness_force_function(
    profile: _DefectProfile, level: float, modulation: float, seed: float
):
    """A Python function of exudyn's Cartesian spring-damper signature, recorded symbolically: the
    vertical rough-running force of the damaged contact, level x envelope(t) x n(t), on the
    housing (and its reaction on the journal). n is white up to half of
    ROUGHNESS_HOLD_RATE_HZ (held over each 1/ROUGHNESS_HOLD_RATE_HZ), nearly normal with unit
    variance (the sum of three sine-hash uniforms of the hold index, scaled); the envelope (1 - m) + m window(psi) gates it at the
    defect's passages, slip included."""

    def force(mbs, t, item, u, v, k, d, offset):
        import exudyn as exu

        esym = exu.symbolic
        R = esym.Real
        k = esym.floor(t * ROUGHNESS_HOLD_RATE_HZ)
        normal = (
            _hash01(esym, k, 12.9898, seed)
            + _hash01(esym, k, 78.233, seed + 0.37)
            + _hash01(esym, k, 37.719, seed + 1.91)
            - 1.5
        ) * 2.0
        psi = profile.phase(t, esym.sin)
        u = psi - esym.floor(psi + 0.5)
        window = esym.pow(esym.cos(u * math.pi), R(ROUGHNESS_WINDOW_POWER)) * (
            1.0 / ROUGHNESS_WINDOW_RMS
        )
        envelope = window * modulation + (1.0 - modulation)
        return esym.Vector([R(0.0), normal * envelope * level, R(0.0)])

    return force


LOAD_ZONE_DEG = 80.0  # zone_only sums every ball within this angle of the bottom (and a few more)


def load_zone_reach(geometry: BearingGeometry) -> int:
    """Balls on each side of the one nearest the bottom that the load-zone sum includes: every
    ball within LOAD_ZONE_DEG of the bottom is always included."""
    spacing = 360.0 / geometry.n_balls
    return min(
        int(math.floor((LOAD_ZONE_DEG + spacing / 2) / spacing)), (geometry.n_balls - 1) // 2
    )


def _bearing_force_function(
    geometry: BearingGeometry,
    stiffness: float,
    clearance: float,
    damping: float,
    shaft_hz: float,
    defect: _DefectProfile | None,
    zone_only: bool,
):
    """A Python function of exudyn's Cartesian spring-damper signature, recorded symbolically.

    zone_only: sum only the balls near the bottom (`load_zone_reach`), the ones the downward
    net load (gravity, radial load > unbalance) can press: about half the cost. The run checks
    afterwards that no ball outside the zone could have touched (`_check_load_zone`)."""
    w_c = geometry.orders()["ftf"] * 2 * math.pi * shaft_hz
    z = geometry.n_balls
    spacing = 2 * math.pi / z
    reach = load_zone_reach(geometry)

    def force(mbs, t, item, u, v, k, d, offset):
        import exudyn as exu

        esym = exu.symbolic
        R = esym.Real
        zero = R(0.0)
        fx = v[0] * damping
        fy = v[1] * damping
        if zone_only:
            # offset of the ball nearest the bottom (load direction -y), in [-a/2, a/2)
            psi = (
                esym.mod(t * w_c + (math.pi / 2 + spacing / 2 + 200 * math.pi), R(spacing))
                - spacing / 2
            )
            angles = [psi + (-math.pi / 2 + m * spacing) for m in range(-reach, reach + 1)]
        else:
            angles = [t * w_c + 2 * math.pi * j / z for j in range(z)]
        for phi in angles:
            c, s = esym.cos(phi), esym.sin(phi)
            f = esym.pow(esym.max(u[0] * c + u[1] * s - clearance, zero), R(1.5)) * stiffness
            fx = fx + f * c
            fy = fy + f * s
        if defect is not None and defect.kind != "none":
            c, s = defect.angle_terms(esym, t)
            delta = u[0] * c + u[1] * s - clearance
            p = defect.depth_expr(esym, t)
            corr = (
                esym.pow(esym.max(delta - p, zero), R(1.5))
                - esym.pow(esym.max(delta, zero), R(1.5))
            ) * stiffness
            # evaluated only while a ball is near the defect (IfThenElse evaluates one branch)
            near = defect.near_expr(esym, t)
            fx = fx + esym.IfThenElse(near, corr * c, zero)
            fy = fy + esym.IfThenElse(near, corr * s, zero)
        return esym.Vector([fx, fy, R(0.0)])

    return force


def _load_zone_ok(displacement: np.ndarray, clearance: float, tolerance: float = 0.136) -> bool:
    """True when no ball outside the load-zone sum (more than LOAD_ZONE_DEG from the bottom) was
    pressed by more than `tolerance` x the most loaded ball's deflection (5 % of its force).
    displacement: (n, 2) journal minus housing, x and y."""
    r = np.hypot(displacement[:, 0], displacement[:, 1])
    beta = np.degrees(
        np.abs(np.arctan2(displacement[:, 0], -displacement[:, 1]))
    )  # from the bottom
    outside = r * np.cos(np.radians(np.clip(LOAD_ZONE_DEG - beta, 0.0, 180.0))) - clearance
    return bool(np.all(outside <= tolerance * np.maximum(r - clearance, 0.0) + 1e-12))


# -- static equilibrium (initial condition) ---------------------------------------------------
def _bearing_static_force(geometry, stiffness, clearance, uy):
    z = geometry.n_balls
    phi = 2 * np.pi * np.arange(z) / z
    delta = np.maximum(uy * np.sin(phi) - clearance, 0.0)
    return float((stiffness * delta**1.5 * np.sin(phi)).sum())


def _static_sag(geometry, stiffness, clearance, load):
    """Vertical journal displacement (negative: down) carrying `load` N downward."""
    lo, hi = -1e-3, 0.0
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if _bearing_static_force(geometry, stiffness, clearance, mid) < -load:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _resonance_filter(freq, zeta, gain, fs):
    """Discrete s^2 g / (s^2 + 2 zeta w s + w^2) by the bilinear transform with the resonance
    pre-warped: shapes the machine background's random bands (not the bearing's modes, which
    are in the model)."""
    w = 2 * np.pi * freq
    warp = 2 * fs * np.tan(w / (2 * fs)) / w
    wn = w * warp
    return bilinear([gain, 0.0, 0.0], [1.0, 2 * zeta * wn, wn**2], fs)


# -- the run ----------------------------------------------------------------------------------
INTEGRATORS = ("rk44", "central_difference")
MODE_STEP_LIMIT = {"rk44": 1.0, "central_difference": 0.5}  # largest omega h of a mode (`_check`)


def central_difference_mass(nodes: list, dampers: list, step: float) -> np.ndarray:
    """The mass matrix (over the 2D point nodes `nodes`, x and y each) that turns exudyn's
    velocity Verlet into the central difference method (Newmark beta 0, gamma 1/2): h/2 x the
    damping matrix of the linear `dampers` ((node, node or None for the ground, N s/m) each).
    exudyn evaluates the damping forces at the half-step velocity v_{n+1/2} = v_{n+1} - h/2
    a_{n+1}, so with M + h/2 C its step solves (M + h/2 C) a_{n+1} = F - K x - C v_{n+1/2}, which
    is M a + C v + K x = F at the step's end: second order (without, first order in the
    damping: measured on a damped oscillator, the error halves with the step)."""
    index = {node: i for i, node in enumerate(nodes)}
    matrix = np.zeros((2 * len(nodes), 2 * len(nodes)))
    for a, b, c in dampers:
        for axis in (0, 1):
            ia = 2 * index[a] + axis
            matrix[ia, ia] += c
            if b is not None:
                ib = 2 * index[b] + axis
                matrix[ib, ib] += c
                matrix[ia, ib] -= c
                matrix[ib, ia] -= c
    return 0.5 * step * matrix


def _run_mechanics(
    p: BearingRigParameters,
    s: RigSettings,
    hash_seed: float,
    unbalance_phase: float,
    rough_seed: float,
    zone_only: tuple[bool, bool],
    where: str,
    record_force: bool = False,
):
    """The exudyn part: returns (housing acceleration, DE bearing force, DE bearing displacement)
    sensor arrays (time in column 0) and the modes' accelerations (shape (samples, modes, 2): x
    and y) at the sensor rate, settling included. zone_only: whether the DE and the FE bearing
    sum only their load-zone balls. record_force: record the DE bearing force (else None)."""
    import exudyn as exu
    from exudyn.utilities import CreateSymbolicUserFunction

    g = p.gravity
    m_de, m_fe = p.rotor_mass * p.de_mass_share, p.rotor_mass * (1 - p.de_mass_share)
    k_fe = p.contact_stiffness * math.sqrt(
        p.fe_geometry.ball_diameter / p.de_geometry.ball_diameter
    )
    c_h = 2 * p.housing_damping_ratio * math.sqrt(p.housing_stiffness * p.housing_mass)
    c_shaft = 2 * p.shaft_damping_ratio * math.sqrt(p.shaft_stiffness * min(m_de, m_fe))
    # static sag of the journals in their bearings and of the housings on the frame
    load_de, load_fe = m_de * g + p.radial_load, m_fe * g
    clearance_de = de_clearance(p)
    sag_de = _static_sag(p.de_geometry, p.contact_stiffness, clearance_de, load_de)
    sag_fe = _static_sag(p.fe_geometry, k_fe, p.radial_clearance, load_fe)
    modal_mass = p.modal_mass_share * p.housing_mass
    modes_mass = modal_mass * len(p.resonances)
    h_de = -(load_de + (p.housing_mass + modes_mass) * g) / p.housing_stiffness
    h_fe = -(load_fe + p.housing_mass * g) / p.housing_stiffness

    with exudyn_system() as mbs:
        eii = exu.itemInterface

        def point(mass, y0, force_y):
            node = mbs.AddNode(
                eii.NodePoint2D(referenceCoordinates=[0.0, 0.0], initialCoordinates=[0.0, y0])
            )
            mbs.AddObject(eii.ObjectMassPoint2D(mass=mass, nodeNumber=node))
            marker = mbs.AddMarker(eii.MarkerNodePosition(nodeNumber=node))
            mbs.AddLoad(eii.LoadForceVector(markerNumber=marker, loadVector=[0.0, force_y, 0.0]))
            return node, marker

        hde_node, hde = point(p.housing_mass, h_de, -p.housing_mass * g)
        hfe_node, hfe = point(p.housing_mass, h_fe, -p.housing_mass * g)
        rde_node, rde = point(m_de, h_de + sag_de, -m_de * g - p.radial_load)
        rfe_node, rfe = point(m_fe, h_fe + sag_fe, -m_fe * g)
        # every linear damper (node, node or None for the ground, N s/m in x and y), for the
        # central difference's mass correction
        dampers = [
            (hde_node, None, c_h),
            (hfe_node, None, c_h),
            (rde_node, rfe_node, c_shaft),
            (hde_node, rde_node, p.bearing_damping),
            (hfe_node, rfe_node, p.bearing_damping),
        ]
        ground = mbs.AddObject(eii.ObjectGround())
        ground_marker = mbs.AddMarker(
            eii.MarkerBodyPosition(bodyNumber=ground, localPosition=[0.0, 0.0, 0.0])
        )
        for marker in (hde, hfe):
            mbs.AddObject(
                eii.ObjectConnectorCartesianSpringDamper(
                    markerNumbers=[ground_marker, marker],
                    stiffness=[p.housing_stiffness] * 2 + [0.0],
                    damping=[c_h] * 2 + [0.0],
                )
            )
        mbs.AddObject(
            eii.ObjectConnectorCartesianSpringDamper(
                markerNumbers=[rde, rfe],
                stiffness=[p.shaft_stiffness] * 2 + [0.0],
                damping=[c_shaft] * 2 + [0.0],
                offset=[0.0, (h_fe + sag_fe) - (h_de + sag_de), 0.0],
            )
        )
        # Rotating unbalance, split over the journals: symbolic load functions (compiled).
        w_s = 2 * np.pi * p.shaft_hz
        f_unb = p.unbalance * w_s**2 / 2
        keep = []  # symbolic functions must live as long as the system

        def unbalance_load(mbs_, t, load):
            esym = exu.symbolic
            return esym.Vector(
                [
                    esym.cos(t * w_s + unbalance_phase) * f_unb,
                    esym.sin(t * w_s + unbalance_phase) * f_unb,
                    esym.Real(0.0),
                ]
            )

        if f_unb > 0:
            for marker in (rde, rfe):
                load = mbs.AddLoad(
                    eii.LoadForceVector(markerNumber=marker, loadVector=[0.0, 0.0, 0.0])
                )
                fn = CreateSymbolicUserFunction(mbs, unbalance_load, "loadVectorUserFunction", load)
                mbs.SetLoadParameter(load, "loadVectorUserFunction", fn)
                keep.append(fn)
        # Structural modes of the DE housing: modal masses on spring-dampers tuned to each mode.
        mode_nodes = []
        for freq, zeta, *_ in p.resonances:
            omega = 2 * math.pi * freq
            node, mode = point(modal_mass, h_de - g / omega**2, -modal_mass * g)
            mbs.AddObject(
                eii.ObjectConnectorCartesianSpringDamper(
                    markerNumbers=[hde, mode],
                    stiffness=[modal_mass * omega**2] * 2 + [0.0],
                    damping=[2 * zeta * omega * modal_mass] * 2 + [0.0],
                )
            )
            mode_nodes.append(node)
            dampers.append((hde_node, node, 2 * zeta * omega * modal_mass))
        defect = _DefectProfile(p, hash_seed) if p.defect_kind != "none" else None
        if defect is not None and p.defect_roughness > 0:
            # rough running: a random force between the DE housing and journal, evaluated once a
            # stage by a force-only connector (action on the housing, reaction on the journal)
            item = mbs.AddObject(
                eii.ObjectConnectorCartesianSpringDamper(
                    markerNumbers=[hde, rde], stiffness=[0.0, 0.0, 0.0], damping=[0.0, 0.0, 0.0]
                )
            )
            fn = CreateSymbolicUserFunction(
                mbs,
                _roughness_force_function(
                    defect, p.defect_roughness, p.defect_roughness_modulation, rough_seed
                ),
                "springForceUserFunction",
                item,
            )
            mbs.SetObjectParameter(item, "springForceUserFunction", fn)
            keep.append(fn)
        bearings = []
        for housing, journal, geometry, stiffness, clearance, dfct, zone in (
            (hde, rde, p.de_geometry, p.contact_stiffness, clearance_de, defect, zone_only[0]),
            (hfe, rfe, p.fe_geometry, k_fe, p.radial_clearance, None, zone_only[1]),
        ):
            item = mbs.AddObject(
                eii.ObjectConnectorCartesianSpringDamper(
                    markerNumbers=[housing, journal],
                    stiffness=[0.0, 0.0, 0.0],
                    damping=[0.0, 0.0, 0.0],
                )
            )
            fn = CreateSymbolicUserFunction(
                mbs,
                _bearing_force_function(
                    geometry, stiffness, clearance, p.bearing_damping, p.shaft_hz, dfct, zone
                ),
                "springForceUserFunction",
                item,
            )
            mbs.SetObjectParameter(item, "springForceUserFunction", fn)
            keep.append(fn)
            bearings.append(item)

        def node_sensor(node, variable):
            return mbs.AddSensor(
                eii.SensorNode(
                    nodeNumber=node,
                    storeInternal=True,
                    writeToFile=False,
                    outputVariableType=variable,
                )
            )

        # the DE bearing's displacement from its two nodes' positions (a sensor on the connector
        # evaluates its force function once more per sample); its force only for diagnostics
        sensors = [
            node_sensor(hde_node, exu.OutputVariableType.Acceleration),
            node_sensor(rde_node, exu.OutputVariableType.Position),
            node_sensor(hde_node, exu.OutputVariableType.Position),
        ]
        if record_force:
            sensors.append(
                mbs.AddSensor(
                    eii.SensorObject(
                        objectNumber=bearings[0],
                        storeInternal=True,
                        writeToFile=False,
                        outputVariableType=exu.OutputVariableType.Force,
                    )
                )
            )
        mode_sensors = [
            mbs.AddSensor(
                eii.SensorNode(
                    nodeNumber=node,
                    storeInternal=True,
                    writeToFile=False,
                    outputVariableType=exu.OutputVariableType.Acceleration,
                )
            )
            for node in mode_nodes
        ]
        sensor_rate = s.output_rate_hz * s.oversampling
        if s.integrator == "central_difference":
            nodes = [hde_node, hfe_node, rde_node, rfe_node, *mode_nodes]
            step = 1.0 / (sensor_rate * s.steps_per_sensor_sample)
            # no stiffness or damping: the correction's mass alone, added to the point masses'
            mbs.AddObject(
                eii.ObjectGenericODE2(
                    nodeNumbers=nodes, massMatrix=central_difference_mass(nodes, dampers, step)
                )
            )
        mbs.Assemble()

        try:
            solve_rk44(
                mbs,
                sensor_rate,
                s.steps_per_sensor_sample,
                s.settle_time + s.duration,
                solver="VelocityVerlet" if s.integrator == "central_difference" else "RK44",
            )
        except Exception as exc:
            raise SimulationError(f"exudyn solver failed ({where}): {exc}") from exc
        acc, journal, housing, *force = (mbs.GetSensorStoredData(sensor) for sensor in sensors)
        disp = np.column_stack([journal[:, 0], journal[:, 1:] - housing[:, 1:]])
        force = force[0] if force else None
        modes = (
            np.stack([mbs.GetSensorStoredData(sensor)[:, 1:3] for sensor in mode_sensors], axis=1)
            if mode_sensors
            else np.empty((len(acc), 0, 2))
        )
    del keep
    if not (
        np.isfinite(acc).all()
        and np.isfinite(disp).all()
        and np.isfinite(modes).all()
        and (force is None or np.isfinite(force).all())
    ):
        raise SimulationError(f"simulation diverged ({where}): non-finite states")
    radial = np.hypot(disp[:, 1], disp[:, 2])
    if radial.max() > max(clearance_de, 0.0) + s.max_penetration:
        raise SimulationError(
            f"simulation diverged ({where}): journal displacement {radial.max():.3g} m "
            f"beyond the clearance + {s.max_penetration:g} m"
        )
    return acc, force, disp, modes


def simulate_rig(
    params: BearingRigParameters,
    settings: RigSettings | None = None,
    rng: np.random.Generator | None = None,
    diagnostics: dict | None = None,
) -> dict:
    """Run the rig; return {"DE": drive-end housing acceleration at 12 o'clock, m/s^2, at
    settings.output_rate_hz, settings.duration long}. `rng` draws the per-run random parts
    (defect hash seed, unbalance phase, background noise): equal seeds give identical arrays.

    diagnostics: a dict to receive `time`, `de_force` (N, force of the DE bearing on its housing, x
    and y; `de_force_y` its y), `de_displacement` (m, journal minus housing, x and y) at the sensor
    rate, settling included, and `load_zone_only` (whether the load-zone ball sum was kept)."""
    p = params
    s = settings or RigSettings()
    rng = rng if rng is not None else np.random.default_rng(0)
    _check(p, s)
    hash_seed = float(rng.uniform(0.0, 100.0))
    unbalance_phase = float(rng.uniform(0.0, 2 * np.pi))
    noise_seed = int(rng.integers(2**32))
    rough_seed = float(rng.uniform(0.0, 100.0))
    sensor_rate = s.output_rate_hz * s.oversampling
    where = (
        f"defect {p.defect_kind}, {p.speed_rpm:g} rpm, contact_stiffness={p.contact_stiffness:.3g}, "
        f"radial_clearance={p.radial_clearance:.3g}, axial_preload={p.axial_preload:.3g}, "
        f"radial_load={p.radial_load:.3g}, "
        f"defect_width={p.defect_width:.3g}, h={1 / (sensor_rate * s.steps_per_sensor_sample):.3g} s"
    )
    # an axial preload presses every DE ball: its load-zone sum cannot hold (the fan end keeps
    # its clearance in the model)
    clearance_de = de_clearance(p)
    zone_only = s.load_zone_only and clearance_de > 0
    record_force = diagnostics is not None
    acc, force, disp, modes = _run_mechanics(
        p,
        s,
        hash_seed,
        unbalance_phase,
        rough_seed,
        (zone_only, s.load_zone_only),
        where,
        record_force,
    )
    if zone_only and not _load_zone_ok(disp[:, 1:3], clearance_de):
        zone_only = False  # a ball outside the zone would have touched: run again with all balls
        acc, force, disp, modes = _run_mechanics(
            p, s, hash_seed, unbalance_phase, rough_seed, (False, False), where, record_force
        )
    if diagnostics is not None:
        diagnostics.update(
            time=acc[:, 0],
            de_force=force[:, 1:3],
            de_force_y=force[:, 2],
            de_displacement=disp[:, 1:3],
            load_zone_only=zone_only,
        )

    # The accelerometer (+y = 12 o'clock): the housing's acceleration and each mode's relative
    # acceleration along its tilt, with its participation (the mode's gain per N times the
    # housing mass).
    signal = p.housing_path_gain * acc[:, 2]
    for m, (_, _, gain, *tilt) in enumerate(p.resonances):
        tilt_rad = math.radians(tilt[0]) if tilt else 0.0
        relative = modes[:, m, :] - acc[:, 1:3]
        along = relative[:, 0] * math.sin(tilt_rad) + relative[:, 1] * math.cos(tilt_rad)
        signal = signal - gain * p.housing_mass * along
    # Filter the whole run (settling included) so the filter's edge effects fall in the
    # discarded part, then decimate.
    out = resample_poly(signal, 1, s.oversampling, window=decimation_filter(s.oversampling))
    first = int(round(s.settle_time * s.output_rate_hz))
    n_out = int(round(s.duration * s.output_rate_hz))
    out = p.sensor_gain * out[first : first + n_out]
    if len(out) < n_out:
        raise SimulationError(f"simulation too short ({where}): {len(out)} of {n_out} samples")
    # Background: sensor/electronic white noise and band-limited random vibration from the rest
    # of the machine, independent of the bearing (added at the output rate).
    noise = np.random.default_rng(noise_seed)
    if p.noise_rms > 0:
        out = out + noise.normal(0.0, p.noise_rms, n_out)
    for freq, zeta, level in p.background:
        if level <= 0:
            continue
        white = noise.normal(0.0, 1.0, n_out + 2000)
        b, a = _resonance_filter(freq, zeta, 1.0, s.output_rate_hz)
        band = lfilter(b, a, white)[2000:]
        out = out + band * (level / max(float(np.std(band)), 1e-30))
    if not np.isfinite(out).all():
        raise SimulationError(f"simulation diverged ({where}): non-finite output samples")
    return {"DE": out}

"""Time-varying mesh stiffness (TVMS) of a spur or helical gear pair by the potential-energy method.

Pure physics: geometry in, stiffness tables out. No exudyn, no files. The drivetrain model
(`drivetrain.py`) turns the tables into contact forces; everything costly (the energy
integrals) happens once, here, when the tables are built.

Method (helical-gear study, eqs. 1-13; Yang & Lin 1987, Tian 2004, Chaari et al. 2009):
- each tooth is a non-uniform cantilever on the base circle (or on the root circle), loaded along
  the line of action at its contact point. Its compliance has a bending, a shear and an axial
  compressive part (K_b, K_s, K_a: strain energies of the beam) and the fillet-foundation part
  K_f (Sainsot et al. 2004); the pair adds the Hertzian contact K_h (eq. 1);
- both cases of base vs root circle: a root circle below the base circle (case 1) adds a straight
  part of the base-circle thickness between root and base circle (study eqs. 4-6); a root circle
  above the base circle (case 2) removes the involute part below the root circle (eqs. 7-9). The
  case is chosen by comparing the two radii, which is the criterion the study's z_min stands for
  (see `root_below_base`);
- the strain energies are integrated numerically (Gauss-Legendre) over the tooth's sections, which
  is eqs. 2-4 with x and the section as functions of the angle; shear uses the section 2 h L and
  G = E / (2 (1 + nu)), i.e. Tian's 1/K_s with EL in the denominator (the study's eq. 3 prints 2EL);
- single pair: the five compliances in series, of both gears (eq. 10); the pairs in contact in
  parallel (eq. 11);
- helical gears: the face width is cut into M slices, each a spur gear with the transverse
  profile, shifted along the line of action by z tan(beta_b); slice stiffnesses add (eq. 13).

The mesh phase u of a tooth pair is measured in transverse base pitches from the moment its first
slice enters the path of contact, so pair j of a mesh is at u = phase - j and a pair meshes for
u in [0, eps_alpha + eps_beta) (contact ratio and load sharing follow from the geometry alone).

Damage is geometry (`ToothDamage`): a missing tooth has no stiffness over its mesh; a spall removes
a region of one flank to a depth (contact only once the deflection exceeds it) with a local loss of
contact stiffness; a chipped tooth loses the flank above a roll position over part of the face;
a root crack weakens the tooth's section (Tian 2004 / Chaari et al. 2009 crack model) and so its
bending, shear and axial stiffness. Material removed is a map over the flank: manufacturing
deviations (`flank_maps`, averaged over each contact line: small against the deflection) and
damage (`damage_maps`: wear, pits, a broken-off part, far deeper than the deflection, so a
damaged tooth's slices are grouped by the depth removed and each group touches on its own).

Units: SI (m, N, Pa); stiffness in N/m along the transverse line of action.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from condmon.models.gear.errors import FlankPoints

# Fillet-foundation coefficients of Sainsot, Velex & Duverger (2004), "Contribution of gear body to
# tooth deflections - a new bidimensional analytical formula", J. Mech. Design 126(4): 748-752,
# Table 1: X* = A/theta_f^2 + B h_f^2 + C h_f/theta_f + D/theta_f + E h_f + F for X = L, M, P, Q.
SAINSOT_COEFFICIENTS = {
    #      A            B            C            D            E        F
    "L": (-5.574e-5, -1.9986e-3, -2.3015e-4, 4.7702e-3, 0.0271, 6.8045),
    "M": (60.111e-5, 28.100e-3, -83.431e-4, -9.9256e-3, 0.1624, 0.9086),
    "P": (-50.952e-5, 185.50e-3, 0.0538e-4, 53.300e-3, 0.2895, 0.9236),
    "Q": (-6.2042e-5, 9.0889e-3, -4.0964e-4, 7.8297e-3, -0.1472, 0.6904),
}

QUADRATURE_POINTS = 48


def involute(angle: float) -> float:
    return math.tan(angle) - angle


@dataclass
class GearGeometry:
    """Gear pair geometry and material; lengths in metres. Defaults: the helical-gear study's rig
    (Table 2), with the face width, bores and dedendum as assumptions of this model."""

    teeth_pinion: int = 29
    teeth_gear: int = 44
    normal_module: float = 2.25e-3
    pressure_angle_deg: float = 20.0
    helix_angle_deg: float = 26.0
    face_width: float = 0.020  # not given by the study: an assumption of this model
    addendum_factor: float = 1.0
    dedendum_factor: float = 1.25  # (h_a + c) / m_n of the standard basic rack (tip clearance 0.25)
    youngs_modulus: float = 2.08e11  # Pa; the study's calibrated value (Table 3: 2.08e5 N/mm^2)
    poisson_ratio: float = 0.3
    bore_radius_pinion: float = 0.0125  # inner rim (shaft bore) radii for the fillet foundation
    bore_radius_gear: float = 0.015

    # --- transverse plane -------------------------------------------------------------------
    @property
    def helix_angle(self) -> float:
        return math.radians(self.helix_angle_deg)

    @property
    def transverse_module(self) -> float:
        return self.normal_module / math.cos(self.helix_angle)

    @property
    def transverse_pressure_angle(self) -> float:
        return math.atan(
            math.tan(math.radians(self.pressure_angle_deg)) / math.cos(self.helix_angle)
        )

    @property
    def base_helix_angle(self) -> float:
        return math.asin(
            math.sin(self.helix_angle) * math.cos(math.radians(self.pressure_angle_deg))
        )

    def pitch_radius(self, teeth: int) -> float:
        return teeth * self.transverse_module / 2.0

    def base_radius(self, teeth: int) -> float:
        return self.pitch_radius(teeth) * math.cos(self.transverse_pressure_angle)

    def tip_radius(self, teeth: int) -> float:
        return self.pitch_radius(teeth) + self.addendum_factor * self.normal_module

    def root_radius(self, teeth: int) -> float:
        return self.pitch_radius(teeth) - self.dedendum_factor * self.normal_module

    def half_tooth_angle(self, teeth: int) -> float:
        """alpha_2: half the angle the tooth subtends at the base circle (unshifted tooth)."""
        return math.pi / (2 * teeth) + involute(self.transverse_pressure_angle)

    def root_below_base(self, teeth: int) -> bool:
        """Case 1 of the study (root circle inside the base circle) or case 2.

        The study writes the criterion as z < z_min = 2 h_a / sin^2(alpha) and says it can as well
        be decided from the root and base radii (its eqs. 2-3). The radii are the geometric fact,
        so they decide here: for the standard rack (h_f = 1.25 m, 20 deg) the root circle lies
        inside the base circle below about 42 teeth, while 2 h_a / sin^2(alpha) (17 teeth) is the
        undercut limit (`undercut_limit`)."""
        return self.root_radius(teeth) < self.base_radius(teeth)

    def undercut_limit(self) -> float:
        """z_min = 2 h_a / sin^2(alpha_t) of the study, in teeth (h_a as a multiple of m_n)."""
        return 2 * self.addendum_factor / math.sin(self.transverse_pressure_angle) ** 2

    # --- path of contact ----------------------------------------------------------------------
    @property
    def base_pitch(self) -> float:
        """Transverse base pitch: distance along the line of action from one tooth pair to the next."""
        return math.pi * self.transverse_module * math.cos(self.transverse_pressure_angle)

    @property
    def line_of_action_length(self) -> float:
        """T1 T2: between the tangent points on the two base circles (standard centre distance)."""
        return (self.base_radius(self.teeth_pinion) + self.base_radius(self.teeth_gear)) * math.tan(
            self.transverse_pressure_angle
        )

    @property
    def path_start(self) -> float:
        """Start of contact A (gear tip on the pinion root), as distance from T1."""
        rb2, ra2 = self.base_radius(self.teeth_gear), self.tip_radius(self.teeth_gear)
        return self.line_of_action_length - math.sqrt(ra2**2 - rb2**2)

    @property
    def path_end(self) -> float:
        """End of contact E (pinion tip), as distance from T1."""
        rb1, ra1 = self.base_radius(self.teeth_pinion), self.tip_radius(self.teeth_pinion)
        return math.sqrt(ra1**2 - rb1**2)

    @property
    def pitch_point(self) -> float:
        return self.base_radius(self.teeth_pinion) * math.tan(self.transverse_pressure_angle)

    def roll_fraction(self, position):
        """Where a point of the path of contact (distance from T1 along the line of action; a
        number or an array) lies on the pinion's active profile: 0 at the start of contact A (the
        pinion's root), 1 at its tip E. Flank maps are on this scale."""
        return (position - self.path_start) / (self.path_end - self.path_start)

    @property
    def contact_ratio(self) -> float:
        """Transverse contact ratio eps_alpha of the standard (unshifted) pair."""
        return (self.path_end - self.path_start) / self.base_pitch

    @property
    def overlap_ratio(self) -> float:
        """Face (overlap) ratio eps_beta = b tan(beta_b) / p_bt."""
        return self.face_width * math.tan(self.base_helix_angle) / self.base_pitch

    @property
    def total_contact_ratio(self) -> float:
        return self.contact_ratio + self.overlap_ratio

    def check(self) -> None:
        if self.path_start <= 0.0:
            raise ValueError(
                "the gear tip reaches below the pinion's base circle (interference); "
                "this geometry is outside the model"
            )
        if self.contact_ratio < 1.0:
            raise ValueError(f"transverse contact ratio {self.contact_ratio:.3f} < 1")


# --- tooth compliance by the potential-energy method -------------------------------------------


@dataclass(frozen=True)
class ToothDamage:
    """Damage of pinion teeth as geometry.

    kind: "missing" (no stiffness over the tooth's mesh), "spall" (over `profile` x `face` of the
    flank the surface lies `depth` lower and its contact stiffness is reduced by `stiffness_loss`),
    "chip" (the flank above roll fraction `profile[0]` is gone over `face`), "crack" (root crack
    cutting `crack_depth` of the root half-thickness, through the face).
    profile: fractions of the active profile, 0 = start of contact at the pinion root, 1 = tip.
    face: fractions of the face width.
    """

    kind: str
    teeth: tuple = (0,)
    profile: tuple = (0.0, 1.0)
    face: tuple = (0.0, 1.0)
    depth: float = 0.0
    stiffness_loss: float = 0.0
    crack_depth: float = 0.0

    def __post_init__(self):
        if self.kind not in ("missing", "spall", "chip", "crack"):
            raise ValueError(f"unknown tooth damage {self.kind!r}")
        for name in ("profile", "face"):
            a, b = getattr(self, name)
            if not 0.0 <= a < b <= 1.0:
                raise ValueError(
                    f"damage {name} range must satisfy 0 <= start < end <= 1, got {(a, b)}"
                )
        if not 0.0 <= self.crack_depth < 1.0:
            raise ValueError(f"crack_depth must be in [0, 1), got {self.crack_depth}")


def _sections(g: GearGeometry, teeth: int, alpha1: np.ndarray, n: int = QUADRATURE_POINTS):
    """Gauss-Legendre sections of the tooth between its clamp and the contact points.

    Returns x (position along the tooth centre line from the gear centre), h (half thickness) and
    w (quadrature weight in x), each (positions, sections), and the clamp's half thickness.
    Involute part in Tian's angle variable alpha in [-alpha1, alpha_end]:
    x = rb [cos a - (a2 - a) sin a], h = rb [sin a + (a2 - a) cos a], dx = rb (a2 - a) cos a da.
    """
    rb, rr, a2 = g.base_radius(teeth), g.root_radius(teeth), g.half_tooth_angle(teeth)
    nodes, weights = np.polynomial.legendre.leggauss(n)
    if g.root_below_base(teeth):
        a_end = a2
    else:  # case 2: the tooth is clamped on the root circle; no involute below it
        a_end = a2 - math.sqrt((rr / rb) ** 2 - 1.0)
    lo = -alpha1[:, None]
    half = (a_end - lo) / 2.0
    a = lo + half * (nodes[None, :] + 1.0)
    roll = a2 - a
    x = rb * (np.cos(a) - roll * np.sin(a))
    h = rb * (np.sin(a) + roll * np.cos(a))
    w = half * weights[None, :] * rb * roll * np.cos(a)
    if g.root_below_base(teeth):
        # Case 1: a straight part of the base-circle half thickness from the root circle to the base.
        hb = rb * math.sin(a2)
        x_root, x_base = rr * math.cos(math.asin(hb / rr)), rb * math.cos(a2)
        xs = x_root + (x_base - x_root) * (nodes + 1.0) / 2.0
        ws = weights * (x_base - x_root) / 2.0
        x = np.concatenate([x, np.broadcast_to(xs, (len(alpha1), n))], axis=1)
        h = np.concatenate([h, np.full((len(alpha1), n), hb)], axis=1)
        w = np.concatenate([w, np.broadcast_to(ws, (len(alpha1), n))], axis=1)
    return x, h, w


def root_geometry(g: GearGeometry, teeth: int):
    """(root radius r_f, half angle theta_f of the tooth on the root circle, its half thickness)."""
    rb, rr, a2 = g.base_radius(teeth), g.root_radius(teeth), g.half_tooth_angle(teeth)
    if g.root_below_base(teeth):
        theta = math.asin(rb * math.sin(a2) / rr)
    else:
        roll = math.sqrt((rr / rb) ** 2 - 1.0)
        theta = a2 - (roll - math.atan(roll))
    return rr, theta, rr * math.sin(theta)


def tooth_compliances(
    g: GearGeometry,
    teeth: int,
    alpha1,
    width: float = 1.0,
    crack_depth: float = 0.0,
    bore_radius: float | None = None,
) -> dict:
    """Bending, shear, axial and fillet-foundation compliances (1/K_b, 1/K_s, 1/K_a, 1/K_f in m/N) of
    one tooth of `width`, loaded along the line of action at the contact points given by alpha1
    (angle between the load and the normal of the tooth centre line; alpha1 = tan(alpha_r) - alpha2
    for a contact point of pressure angle alpha_r).

    crack_depth: root crack cutting this fraction of the root half thickness h_r on the loaded side;
    as in Tian (2004) / Chaari et al. (2009) the material of the cracked side beyond h_q = (1 -
    depth) h_r is lost in every section thicker than h_q: section thickness h + min(h, h_q)."""
    alpha1 = np.atleast_1d(np.asarray(alpha1, dtype=float))
    e_mod, nu = g.youngs_modulus, g.poisson_ratio
    shear_mod = e_mod / (2 * (1 + nu))
    rb, a2 = g.base_radius(teeth), g.half_tooth_angle(teeth)
    x, h, w = _sections(g, teeth, alpha1)
    rr, theta_f, h_root = root_geometry(g, teeth)
    thickness = 2 * h if crack_depth <= 0 else h + np.minimum(h, (1.0 - crack_depth) * h_root)
    area = thickness * width
    inertia = thickness**3 * width / 12.0
    c1, s1 = np.cos(alpha1)[:, None], np.sin(alpha1)[:, None]
    # Contact point: x_c along the centre line, h_c off it.
    x_c = rb * (np.cos(alpha1) + (alpha1 + a2) * np.sin(alpha1))[:, None]
    h_c = rb * ((alpha1 + a2) * np.cos(alpha1) - np.sin(alpha1))[:, None]
    moment = c1 * (x_c - x) - s1 * h_c  # bending moment per unit load at section x
    bending = np.sum(w * moment**2 / (e_mod * inertia), axis=1)
    shear = np.sum(w * 1.2 * c1**2 / (shear_mod * area), axis=1)
    axial = np.sum(w * s1**2 / (e_mod * area), axis=1)
    # Fillet foundation (Sainsot et al. 2004): u_f from the root circle to where the load line
    # crosses the centre line, S_f the tooth thickness (arc) on the root circle.
    bore = (
        bore_radius
        if bore_radius is not None
        else (g.bore_radius_pinion if teeth == g.teeth_pinion else g.bore_radius_gear)
    )
    h_f = rr / bore
    coeff = {
        k: a / theta_f**2 + b * h_f**2 + c * h_f / theta_f + d / theta_f + e * h_f + f
        for k, (a, b, c, d, e, f) in SAINSOT_COEFFICIENTS.items()
    }
    u_f = (x_c - h_c * np.tan(alpha1)[:, None])[:, 0] - rr * math.cos(theta_f)
    ratio = u_f / (2 * rr * theta_f)
    fillet = (
        np.cos(alpha1) ** 2
        / (e_mod * width)
        * (
            coeff["L"] * ratio**2
            + coeff["M"] * ratio
            + coeff["P"] * (1 + coeff["Q"] * np.tan(alpha1) ** 2)
        )
    )
    return {"bending": bending, "shear": shear, "axial": axial, "fillet": fillet}


def hertz_compliance(g: GearGeometry, width: float = 1.0) -> float:
    """1/K_h of the study's eq. 1, K_h = pi E L / (4 (1 - nu^2)), both gears of the same material."""
    return 4 * (1 - g.poisson_ratio**2) / (math.pi * g.youngs_modulus * width)


def pair_stiffness_per_width(g: GearGeometry, s, pinion_crack: float = 0.0) -> np.ndarray:
    """Stiffness (N/m per m of face) of one tooth pair in contact at distance s from T1 along the
    line of action: the five compliances of both teeth in series (eq. 10)."""
    s = np.atleast_1d(np.asarray(s, dtype=float))
    rb1, rb2 = g.base_radius(g.teeth_pinion), g.base_radius(g.teeth_gear)
    alpha1_p = s / rb1 - g.half_tooth_angle(g.teeth_pinion)
    alpha1_g = (g.line_of_action_length - s) / rb2 - g.half_tooth_angle(g.teeth_gear)
    pinion = tooth_compliances(g, g.teeth_pinion, alpha1_p, crack_depth=pinion_crack)
    gear = tooth_compliances(g, g.teeth_gear, alpha1_g)
    compliance = hertz_compliance(g) + sum(pinion.values()) + sum(gear.values())
    return 1.0 / compliance


def iso6336_mesh_stiffness(g: GearGeometry) -> float:
    """Mean mesh stiffness c_gamma_alpha * b (N/m) by ISO 6336-1:2006, method B (eqs. for q', c',
    c_gamma_alpha), solid gears (C_R = 1), C_M = 0.8, unshifted teeth, and no light-load
    reduction (the linear-elastic value the potential-energy method computes)."""
    beta, beta_b = g.helix_angle, g.base_helix_angle
    zn1 = g.teeth_pinion / (math.cos(beta_b) ** 2 * math.cos(beta))
    zn2 = g.teeth_gear / (math.cos(beta_b) ** 2 * math.cos(beta))
    q_min = 0.04723 + 0.15551 / zn1 + 0.25791 / zn2  # mm um / N, x1 = x2 = 0
    c_th = 1.0 / q_min
    c_b = (1 + 0.5 * (1.2 - g.dedendum_factor)) * (1 - 0.02 * (20.0 - g.pressure_angle_deg))
    c_single = c_th * 0.8 * 1.0 * c_b * math.cos(beta)  # c', N/(mm um)
    c_gamma_alpha = c_single * (0.75 * g.contact_ratio + 0.25)  # N/(mm um)
    return c_gamma_alpha * 1e9 * g.face_width  # N/(mm um) = 1e9 N/m per m


# --- tables over the mesh phase -------------------------------------------------------------------

# Depths removed (m) that bound the contact groups of a damaged flank: intact (up to 0.1 um),
# then levels a factor two apart up to 0.4 mm; deeper is one group (it never touches).
DAMAGE_DEPTH_LEVELS = 1.0e-7 * 2.0 ** np.arange(13)


@dataclass
class ContactGroup:
    """One contact of a tooth pair over its mesh phase u = i / points_per_pitch:
    stiffness K(u) (N/m, linear TVMS of this group) and profile deviation e(u) (m; the group's
    deflection is the mesh deflection minus e)."""

    stiffness: np.ndarray
    deviation: np.ndarray


@dataclass
class ProfileDeviation:
    """Profile deviations of every tooth pair (static transmission error): a sinusoid of
    `amplitude` with one period per base pitch (zero at the pitch point) and linear tip relief of
    `tip_relief` depth at both tips, from the highest / lowest point of single tooth contact."""

    amplitude: float = 0.0
    tip_relief: float = 0.0

    def __call__(self, g: GearGeometry, s: np.ndarray) -> np.ndarray:
        e = self.amplitude * np.sin(2 * math.pi * (s - g.pitch_point) / g.base_pitch)
        if self.tip_relief:
            start, end, pb = g.path_start, g.path_end, g.base_pitch
            e = e + self.tip_relief * (
                np.clip((s - (start + pb)) / (end - start - pb), 0, 1)
                + np.clip(((end - pb) - s) / (end - start - pb), 0, 1)
            )
        return e


@dataclass
class GearMesh:
    """Potential-energy TVMS of a gear pair, sliced over the face width, as tables over the mesh
    phase of one tooth pair. Build once per parameter set; `groups(tooth)` are what the
    drivetrain's mesh force interpolates."""

    geometry: GearGeometry = field(default_factory=GearGeometry)
    slices: int = 80
    points_per_pitch: int = 200
    profile_samples: int = 241
    damage: ToothDamage | None = None
    profile_deviation: ProfileDeviation = field(default_factory=ProfileDeviation)
    # If set: the static transmission error (m) at mesh frequency the sinusoidal profile deviation
    # must produce; its flank amplitude is then transmission_error / `sine_te_gain`.
    transmission_error: float | None = None
    # Per pinion tooth (empty: none): a `errors.FlankMap` of its manufacturing deviations (profile,
    # helix, misalignment: small against the deflection, averaged over each contact line) or None.
    flank_maps: tuple = ()
    # Per pinion tooth (empty: none): a `errors.FlankMap` of the material its damage removed (wear,
    # pits, a spall, a broken-off part; usually far deeper than the deflection) or None. Each tooth's
    # contact line is split by the depth removed (`DAMAGE_DEPTH_LEVELS`): a slice that lies deeper
    # than the deflection leaves the contact, and the rest of the line carries the load.
    damage_maps: tuple = ()
    # If set (m): each tooth's contact line is split into face strips whose flank deviation
    # (`flank_maps`) lies within this step of each other, each strip a contact of its own, so a
    # flank standing proud of the rest carries the load alone (edge contact under a lead slope
    # many times the deflection). None: the line touches at its slices' mean deviation.
    contact_step: float | None = None
    # Strips above a flank's proudest that are contacts of their own; the slices deeper than
    # that (they never touch) are one contact.
    contact_strips: int = 16

    def __post_init__(self):
        g = self.geometry
        g.check()
        if self.slices < 1:
            raise ValueError("slices must be at least 1")
        if self.contact_step is not None and not self.contact_step > 0.0:
            raise ValueError(f"contact_step {self.contact_step} m: a step must be positive")
        self.s = np.linspace(g.path_start, g.path_end, self.profile_samples)
        self.k_per_width = pair_stiffness_per_width(g, self.s)
        self.window = g.total_contact_ratio  # phase range of one pair's mesh, base pitches
        n = int(math.ceil(self.window * self.points_per_pitch)) + 2
        self.u = np.arange(n) / self.points_per_pitch
        dz = g.face_width / self.slices
        self.z = (np.arange(self.slices) + 0.5) * dz
        # Contact position of every slice's centre at every phase (n, M), and the share of its
        # contact line inside the path of contact
        shift = self.z * math.tan(g.base_helix_angle)
        self.slice_span = dz * math.tan(
            g.base_helix_angle
        )  # the positions one slice's contact line covers
        self.s_slice = g.path_start + self.u[:, None] * g.base_pitch - shift[None, :]
        self.inside = self._profile_coverage(g.path_start, g.path_end)
        self.slice_stiffness = self.inside * np.interp(self.s_slice, self.s, self.k_per_width) * dz
        self.unit_sine = ProfileDeviation(amplitude=1.0)(g, self.s_slice)
        self.sine_te_gain = self._sine_te_gain()
        deviation = self.profile_deviation
        if self.transmission_error is not None:
            if self.transmission_error and self.sine_te_gain < 0.05:
                raise ValueError(
                    f"overlap ratio {g.overlap_ratio:.3f} (near a whole number) averages a sinusoidal "
                    f"profile deviation out of the transmission error (gain {self.sine_te_gain:.3f}); "
                    "set transmission_error to 0 or change the face width"
                )
            deviation = ProfileDeviation(
                self.transmission_error / self.sine_te_gain, deviation.tip_relief
            )
        self.flank_amplitude = deviation.amplitude
        self.slice_deviation = deviation(g, self.s_slice)
        self._healthy = self._groups_from(self.slice_stiffness, None, None)
        self._damaged = self._damaged_groups() if self.damage is not None else None
        self.mean_stiffness = float(self._healthy[0].stiffness.sum() / self.points_per_pitch)
        self._tooth_groups = self._flank_groups() if (self.flank_maps or self.damage_maps) else None

    def _flank_groups(self) -> list[list[ContactGroup]]:
        """Every pinion tooth's contact groups with its flank map and damage map: each slice's
        contact lowered by the maps at its contact point (roll fraction along the path, fraction of
        the face); a damaged tooth's slices grouped by the depth its damage removed there."""
        g = self.geometry
        for name in ("flank_maps", "damage_maps"):
            maps = getattr(self, name)
            if maps and len(maps) != g.teeth_pinion:
                raise ValueError(f"{name}: {len(maps)} maps for {g.teeth_pinion} pinion teeth")
        flanks = self.flank_maps or (None,) * g.teeth_pinion
        damages = self.damage_maps or (None,) * g.teeth_pinion
        roll = g.roll_fraction(self.s_slice)
        points = FlankPoints(roll, np.broadcast_to(self.z[None, :] / g.face_width, roll.shape))
        cache, groups = {}, []
        for tooth, (flank, damage) in enumerate(zip(flanks, damages)):
            damaged = self._is_damaged(tooth)
            key = (flank, damage, damaged)
            if key not in cache:
                extra = None if flank is None else points.values(flank)
                if damage is not None:
                    if damaged:
                        raise ValueError(
                            f"pinion tooth {tooth}: a damage map and a {self.damage.kind} at once"
                        )
                    cache[key] = self._damage_groups(extra, points.values(damage))
                else:
                    cache[key] = (
                        self._damaged_groups(extra)
                        if damaged
                        else self._groups_from(self.slice_stiffness, extra, extra)
                    )
            groups.append(cache[key])
        return groups

    def _damage_groups(self, extra, removed: np.ndarray) -> list[ContactGroup]:
        """A damaged flank's contact groups: its slices by the depth removed (`DAMAGE_DEPTH_LEVELS`),
        each level a contact of its own at its slices' mean deviation. A group averages only
        slices within a factor two of each other's depth, so a pit or a spall deeper than the
        deflection takes its slices out of contact instead of lowering the whole line by its
        share of the face (what one averaged group would do)."""
        deviation = removed if extra is None else extra + removed
        level = np.searchsorted(DAMAGE_DEPTH_LEVELS, removed)
        groups = []
        for index in np.unique(level[self.slice_stiffness > 0]):
            stiffness = self.slice_stiffness * (level == index)
            groups += self._groups_from(stiffness, deviation, flank=extra)
        return groups

    def _is_damaged(self, tooth: int) -> bool:
        z1 = self.geometry.teeth_pinion
        return self.damage is not None and tooth % z1 in [t % z1 for t in self.damage.teeth]

    def _sine_te_gain(self) -> float:
        """First-harmonic amplitude of the unloaded static TE (the stiffness-weighted deviation of
        the contact lines in mesh) per unit amplitude of the sinusoidal profile deviation: 1 for a
        spur pair, about |sinc(eps_beta)| for a helical one (the contact lines cross the profile)."""
        ppp = self.points_per_pitch
        k = self.slice_stiffness.sum(axis=1)
        ke = (self.slice_stiffness * self.unit_sine).sum(axis=1)
        k_mesh, ke_mesh = np.zeros(ppp), np.zeros(ppp)
        for shift in range(0, len(k), ppp):  # pairs j = 0, -1, ... at u = phase + |j|
            part = slice(shift, min(shift + ppp, len(k)))
            k_mesh[: part.stop - part.start] += k[part]
            ke_mesh[: part.stop - part.start] += ke[part]
        te = ke_mesh / k_mesh
        return float(2 * abs(np.fft.rfft(te)[1]) / ppp)

    def _groups_from(self, stiffness: np.ndarray, extra_deviation, flank) -> list[ContactGroup]:
        """The contact groups of slices `stiffness` (n, M) lowered by `extra_deviation` (n, M or
        None): one group, or with `contact_step` one per face strip of the flank deviation
        `flank` (n, M or None: no strips) within a step."""
        deviation = (
            self.slice_deviation
            if extra_deviation is None
            else self.slice_deviation + extra_deviation
        )
        if self.contact_step is None or flank is None:
            return [self._group(stiffness, deviation)]
        return [
            self._group(stiffness * strip[None, :], deviation)
            for strip in self._face_strips(stiffness, flank)
        ]

    def _face_strips(self, stiffness: np.ndarray, flank: np.ndarray) -> list[np.ndarray]:
        """Masks (M,) of the slices whose flank deviation (their stiffness-weighted mean over the
        mesh phase, so a slice stays in one strip) lies in the same `contact_step` above the
        lowest slice's; slices over `contact_strips` steps above it (they never touch) are one."""
        weight = stiffness.sum(axis=0)
        touching = weight > 0
        if not touching.any():
            return [touching]
        level_of = np.zeros(self.slices)
        level_of[touching] = (stiffness * flank).sum(axis=0)[touching] / weight[touching]
        lowest = level_of[touching].min()
        level = np.minimum(np.floor((level_of - lowest) / self.contact_step), self.contact_strips)
        return [touching & (level == index) for index in np.unique(level[touching])]

    def _group(self, stiffness: np.ndarray, deviation: np.ndarray) -> ContactGroup:
        """One contact of slices `stiffness` (n, M) at their stiffness-weighted mean deviation."""
        total = stiffness.sum(axis=1)
        weighted = np.divide(
            (stiffness * deviation).sum(axis=1), total, out=np.zeros_like(total), where=total > 0
        )
        # Outside the group's contact, hold the nearest deviation (no jumps at the edges).
        if np.any(total > 0):
            idx = np.flatnonzero(total > 0)
            weighted = np.interp(np.arange(len(total)), idx, weighted[idx])
        return ContactGroup(total, weighted)

    def _profile_coverage(self, low: float, high: float) -> np.ndarray:
        """Share of every slice's contact line (n, M) whose position along the path lies in
        [low, high]. A helical slice enters and leaves contact gradually as its line sweeps across
        an edge: with the centre's position alone (all or nothing) the pair stiffness would be a
        staircase, a step per slice, whose fast ripple the integrator cannot follow at the chosen
        step (the features then depend on the step). A spur pair (no span) is all or nothing."""
        if self.slice_span <= 0.0:
            return ((self.s_slice >= low) & (self.s_slice <= high)).astype(float)
        start, end = self.s_slice - self.slice_span / 2, self.s_slice + self.slice_span / 2
        return np.clip(np.minimum(end, high) - np.maximum(start, low), 0.0, None) / self.slice_span

    def _face_coverage(self, face) -> np.ndarray:
        """Share of every slice's width inside the face range (fractions of the face width)."""
        b, m = self.geometry.face_width, self.slices
        lo, hi = face[0] * b, face[1] * b
        edges = np.arange(m + 1) * b / m
        return np.clip(np.minimum(edges[1:], hi) - np.maximum(edges[:-1], lo), 0, None) / (b / m)

    def _damaged_groups(self, extra=None) -> list[ContactGroup]:
        """The damaged tooth's contact groups; `extra`: its flank map's deviation per slice."""
        d = self.damage
        if d.kind == "missing":
            return []
        if d.kind == "crack":
            k = pair_stiffness_per_width(self.geometry, self.s, pinion_crack=d.crack_depth)
            dz = self.geometry.face_width / self.slices
            stiffness = self.inside * np.interp(self.s_slice, self.s, k) * dz
            return self._groups_from(stiffness, extra, extra)
        coverage = self._face_coverage(d.face)[None, :]
        g = self.geometry
        at = [
            g.path_start + fraction * (g.path_end - g.path_start) for fraction in d.profile
        ]  # along the path
        if d.kind == "chip":
            region = coverage * self._profile_coverage(at[0], g.path_end)
            return self._groups_from(self.slice_stiffness * (1 - region), extra, extra)
        # Spall: the region is a separate contact, `depth` below the flank, softer by stiffness_loss.
        region = coverage * self._profile_coverage(at[0], at[1])
        groups = self._groups_from(self.slice_stiffness * (1 - region), extra, extra)
        pit = self.slice_stiffness * region * (1 - d.stiffness_loss)
        if pit.sum() > 0:
            groups += self._groups_from(pit, d.depth if extra is None else d.depth + extra, extra)
        return groups

    @property
    def healthy_groups(self) -> list[ContactGroup]:
        return self._healthy

    def groups(self, tooth: int) -> list[ContactGroup]:
        """Contact groups of the pair in which pinion tooth `tooth` meshes."""
        if self._tooth_groups is not None:
            return self._tooth_groups[tooth % self.geometry.teeth_pinion]
        if self._is_damaged(tooth):
            return self._damaged
        return self._healthy

    def pair_stiffness(self, u, tooth: int = 1) -> np.ndarray:
        """Linear stiffness of the pair of pinion tooth `tooth` at pair phase(s) u (all groups)."""
        u = np.asarray(u, dtype=float)
        out = np.zeros_like(u)
        for group in self.groups(tooth):
            out += np.interp(u, self.u, group.stiffness, left=0.0, right=0.0)
        return out

    def mesh_stiffness(self, phase) -> np.ndarray:
        """Total linear TVMS at mesh phase(s) (in mesh periods; pair j meshes at u = phase - j, with
        pinion tooth j mod z1): the pairs in contact in parallel (eq. 11)."""
        phase = np.atleast_1d(np.asarray(phase, dtype=float))
        total = np.zeros_like(phase)
        first = int(math.floor(phase.min() - self.window)) - 1
        for j in range(first, int(math.floor(phase.max())) + 1):
            total += self.pair_stiffness(phase - j, tooth=j)
        return total

    def pairs_in_contact(self, phase) -> np.ndarray:
        """Number of tooth pairs with any slice in contact at mesh phase(s)."""
        phase = np.atleast_1d(np.asarray(phase, dtype=float))
        count = np.zeros_like(phase, dtype=int)
        first = int(math.floor(phase.min() - self.window)) - 1
        for j in range(first, int(math.floor(phase.max())) + 1):
            count += self.pair_stiffness(phase - j, tooth=j) > 0
        return count

    def loaded_transmission_error(self, phase, load: float) -> np.ndarray:
        """Static transmission error (m, along the line of action) under `load` (N) at mesh phase(s),
        linear elastic: the deflection delta with sum_g K_g max(delta - e_g, 0) = load over the
        contact groups in mesh (a group lying deeper than delta does not touch)."""
        phase = np.atleast_1d(np.asarray(phase, dtype=float))
        stiffness, deviation = [], []
        first = int(math.floor(phase.min() - self.window)) - 1
        for j in range(first, int(math.floor(phase.max())) + 1):
            for group in self.groups(j):
                stiffness.append(np.interp(phase - j, self.u, group.stiffness, left=0.0, right=0.0))
                deviation.append(np.interp(phase - j, self.u, group.deviation))
        k, e = np.array(stiffness), np.array(deviation)
        # the force grows with delta: bisect between the least deviation (no force) and the
        # largest plus load / K (every group touching, at least the load)
        low = np.where(k > 0, e, np.inf).min(axis=0)
        high = np.where(k > 0, e, -np.inf).max(axis=0) + load / np.maximum(k.sum(axis=0), 1e-30)
        for _ in range(80):
            mid = 0.5 * (low + high)
            short = (k * np.maximum(mid - e, 0.0)).sum(axis=0) < load
            low, high = np.where(short, mid, low), np.where(short, high, mid)
        return 0.5 * (low + high)

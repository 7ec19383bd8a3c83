"""The gear mesh force along the transverse line of action: a function of (time, mesh deflection,
deflection rate) summing the tooth-pair contact forces (Algorithm 1 of the helical-gear study).

Pure: parameters in, a force function out (no exudyn; the drivetrain calls it from a connector).
The steady pair sums run compiled (`mesh_kernel.py`); the impacts' state stays here.

Per tooth pair j (pinion tooth j mod z1, gear tooth j mod z2) at pair phase u = phase - j:
    F_j = K_j(u) (d_j / d_ref)^n  +  c K_j(u) / K_mean S(d_j / d_op) d_j'  [+ impact term]
with the pair deflection d_j = mesh deflection - profile deviation e(u) + pitch errors of both
teeth - (outside the contact window) the tip gap s^2 / (2 rho). The steady mesh damping is viscous,
from a damping ratio (`mesh_damping_ratio`, calibrated), shared by the pairs in proportion to their
stiffness. It grows in as a pair closes, by a smooth step S from 0 at contact to 1 at the operating
deflection d_op (the static load on the mean mesh), as multibody contact codes do: a damping force
that jumps at contact onset makes RK4 first order, and a mesh that loses contact (a lightly loaded
one rattles) then converges with the step only slowly. A damping that grew with the elastic force
(Hunt-Crossley) would also be continuous, but would multiply the calibrated damping wherever a
pair is deflected many times its operating deflection (impacts, large pitch errors).

The Table-1 contact laws (`contact_laws.py`) act where they were built for, impacts: a contact that
closes after the whole mesh lost contact (a missing tooth's gap, rattle) or on the back flank
carries K d^n f(c_r) d' / d'(-) with d'(-) its real approach speed, for as long as that contact
lasts.

Two stiffness models (`mesh_stiffness_model`): `potential_energy` (`TVMSMeshForce`, the pair
stiffness over the mesh phase from `mesh.py`, precomputed as tables) and `simple`
(`MeshForce`: equal pairs in rectangular contact windows). Health: a surface fault removes
material (wear or pitting, `damage_maps`) or, as the CFRP study did, scales the contact stiffness
of its pinion teeth by (1 - loss) over the whole flank; a tooth broken short of its root is a
damage map too; a whole missing tooth, spall, chipped tooth and root crack are tooth geometry
(`mesh.ToothDamage`).

Effects of a real drivetrain, per sample: a slow speed fluctuation (in the mesh phase), shaft
run-out (eccentricity along the line of action at the shaft frequencies: it displaces the mesh and
shifts its phase by e / base pitch, so the mesh is modulated at the shaft orders; the centre-distance
part, which changes the contact ratio by about 0.3 % at 10 um, is left out), tooth pitch errors and
flank maps (`errors.FlankMap`: profile and helix deviations); a bench's own damage comes as damage
maps (`damage_maps_pinion`).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from condmon.models.gear.contact_laws import hysteresis_factor
from condmon.models.gear.errors import (
    add_flank_maps,
    broken_tooth_flank_map,
    contact_fatigue_band,
    pitted_flank_map,
    wear_flank_map,
)
from condmon.models.gear.mesh import (
    GearMesh,
    ProfileDeviation,
    ToothDamage,
    iso6336_mesh_stiffness,
)

# DEFLECTION_REF: K = mesh stiffness at this deflection keeps K's unit N/m for any n
from condmon.models.gear.mesh_kernel import (
    BACK_FLANK,
    DEFLECTION_REF,
    SEPARATED,
    TOO_MANY_CONTACTS,
    TRACKING,
    ArrayBlock,
    entry_point,
    mesh_excitation,
    simple_contacts,
    simple_gated_force,
    simple_steady_force,
    tvms_contacts,
    tvms_gated_force,
    tvms_steady_force,
)
from condmon.models.numerics import SimulationError

MESH_HEALTH_STATES = (
    "healthy",
    "surface_fault",
    "wear",
    "missing_tooth",
    "spall",
    "chipped_tooth",
    "root_crack",
)
# States of a drivetrain whose mesh is healthy: the damage is in a shaft (drivetrain.py).
SHAFT_HEALTH_STATES = ("shaft_crack", "delamination")
HEALTH_STATES = MESH_HEALTH_STATES + SHAFT_HEALTH_STATES
MESH_STIFFNESS_MODELS = ("potential_energy", "simple")
# A surface fault as a gear engineer names it: localised pitting (contact fatigue on
# `surface_fault_teeth` teeth, `pit_depth`, `pitted_area`; ISO 10825), or as the CFRP study's loss of
# contact stiffness (`surface_fault_stiffness_loss`), on the surface fault's teeth (`stiffness_loss`)
# or on every tooth of the mesh (`mesh_stiffness_loss`, the study's whole-mesh -15 %), kept to
# compare with it. Sliding wear of every tooth is a health state of its own (`wear`), never a
# surface fault: it is another kind of damage (ISO 10825) with another signature.
SURFACE_FAULT_MODELS = ("pitting", "stiffness_loss", "mesh_stiffness_loss")
MAX_DEFLECTION = 1.0e-3  # m; a mesh deflection beyond this is divergence
EDGE_CONTACT = (
    0.02  # a pair stiffness at its window's edge above this share of the peak: extended contact
)
# How deep below a flank's proudest strip (in operating deflections) its strips still touch on
# their own (the dynamic mesh force reaches a few times the static one); deeper ones are one contact
CONTACT_DEPTH = 8.0
# tooth contacts one call can hold (a helical pair: about 3; with face strips up to 17 a pair)
MAX_CONTACTS = 256


def whole_tooth_missing(p) -> bool:
    return p.health_state == "missing_tooth" and p.missing_share >= 1.0


def tooth_damage(p) -> ToothDamage | None:
    """The health state of `p` as tooth geometry (None when healthy, a pure stiffness loss or a
    flank map: surface wear and pitting, a tooth broken off short of its root)."""
    if p.health_state not in HEALTH_STATES:
        raise ValueError(
            f"unknown health state {p.health_state!r}; choose one of {list(HEALTH_STATES)}"
        )
    tooth = p.faulty_tooth
    if whole_tooth_missing(p):
        return ToothDamage("missing", teeth=(tooth,))
    if p.health_state == "spall":
        # the pit: `spall_depth` below the flank, its pitted surface softer like a surface fault
        return ToothDamage(
            "spall",
            teeth=(tooth,),
            profile=tuple(p.spall_profile),
            face=tuple(p.spall_face),
            depth=p.spall_depth,
            stiffness_loss=p.surface_fault_stiffness_loss,
        )
    if p.health_state == "chipped_tooth":
        return ToothDamage(
            "chip", teeth=(tooth,), profile=(p.chip_profile, 1.0), face=tuple(p.chip_face)
        )
    if p.health_state == "root_crack":
        return ToothDamage("crack", teeth=(tooth,), crack_depth=p.crack_depth)
    return None


def surface_fault_teeth(p) -> list[int]:
    """The pinion teeth of a surface fault: `surface_fault_teeth` in a row from `faulty_tooth`."""
    return [(p.faulty_tooth + k) % p.geometry.teeth_pinion for k in range(p.surface_fault_teeth)]


def surface_fault_form(p) -> str:
    """The surface fault's form in `p`: its `surface_fault_model`."""
    if p.surface_fault_model not in SURFACE_FAULT_MODELS:
        raise ValueError(
            f"unknown surface_fault_model {p.surface_fault_model!r}; "
            f"choose one of {list(SURFACE_FAULT_MODELS)}"
        )
    return p.surface_fault_model


def contact_stiffness_factors(p) -> list[float]:
    """Factor on the contact stiffness of every pinion tooth: 1 - surface_fault_stiffness_loss on
    the surface fault's teeth (`surface_fault_model: stiffness_loss`) or on every tooth
    (`mesh_stiffness_loss`, the CFRP study's whole mesh), 1 elsewhere."""
    factors = [1.0] * p.geometry.teeth_pinion
    if p.health_state != "surface_fault":
        return factors
    form = surface_fault_form(p)
    weakened = {
        "stiffness_loss": surface_fault_teeth(p),
        "mesh_stiffness_loss": range(len(factors)),
    }.get(form, ())
    for tooth in weakened:
        factors[tooth] = 1.0 - p.surface_fault_stiffness_loss
    return factors


def pitting_band(p) -> tuple[float, float]:
    """The roll fractions pitting covers: the contact-fatigue band where it starts (from the lowest
    point of single tooth contact up to the pitch point), grown by `pitting_growth` on either
    side, as progressive pitting spreads over the dedendum and across the pitch line."""
    low, high = contact_fatigue_band(p.geometry)
    return max(0.0, low - p.pitting_growth), min(1.0, high + p.pitting_growth)


def damage_maps(p) -> tuple:
    """Every pinion tooth's damage map (material removed, `errors.FlankMap`, or None): a bench's own
    damage `damage_maps_pinion` plus, for a surface fault, pitting of its teeth, for wear, sliding
    wear of every tooth (each tooth its own surface, from `wear_seed`), or for a tooth broken off
    short of its root (`missing_share` < 1) the part gone."""
    teeth = p.geometry.teeth_pinion
    damage = [None] * teeth
    rng = np.random.default_rng([int(p.wear_seed), 0x3EA2])
    if p.health_state == "missing_tooth" and not whole_tooth_missing(p):
        damage[p.faulty_tooth % teeth] = broken_tooth_flank_map(p.missing_share)
    elif p.health_state == "wear":
        # wear removes material where the flanks slide, and every tooth slides alike (Archard): all
        # teeth wear, each its own rough surface
        if p.wear_depth <= 0:
            raise ValueError(f"wear: a worn flank has lost material (depth {p.wear_depth} m, > 0)")
        pitch_line = p.geometry.roll_fraction(p.geometry.pitch_point)
        damage = [
            wear_flank_map(p.wear_depth, p.wear_roughness, rng, pitch_line=pitch_line)
            for _ in range(teeth)
        ]
    elif p.health_state == "surface_fault" and surface_fault_form(p) == "pitting":
        # contact fatigue starts on a few teeth (surface_fault_teeth), each its own craters
        if p.pit_depth <= 0:
            raise ValueError(
                f"pitting: a pitted flank has lost material (depth {p.pit_depth} m, > 0)"
            )
        band = pitting_band(p)
        for tooth in surface_fault_teeth(p):
            damage[tooth] = pitted_flank_map(p.pit_depth, p.pitted_area, band, rng)
    else:
        return tuple(p.damage_maps_pinion)
    return add_flank_maps(tuple(p.damage_maps_pinion), tuple(damage))


def gear_mesh(p) -> GearMesh:
    """The potential-energy TVMS tables of `p` (geometry, slices, profile deviations, flank and damage maps, damage)."""
    return GearMesh(
        p.geometry,
        slices=p.helix_slices,
        damage=tooth_damage(p),
        profile_deviation=ProfileDeviation(tip_relief=p.tip_relief),
        transmission_error=p.transmission_error,
        flank_maps=tuple(p.flank_maps_pinion),
        damage_maps=damage_maps(p),
        contact_step=(
            p.flank_contact_step * operating_deflection(p) if p.flank_contact_step else None
        ),
        # face strips down to CONTACT_DEPTH operating deflections below a flank's proudest
        contact_strips=math.ceil(CONTACT_DEPTH / p.flank_contact_step)
        if p.flank_contact_step
        else 0,
    )


def excitation_tables(p) -> tuple[np.ndarray, np.ndarray]:
    """(the mesh excitation's constants in mesh_kernel's layout (START_PHASE, MESH_FREQUENCY, ...),
    the run-out of each shaft that has one: (amplitude, shaft angle per mesh period, phase))."""
    g = p.geometry
    mesh_frequency = p.speed_rpm / 60.0 * g.teeth_pinion
    constants = np.array(
        [
            float(p.start_mesh_phase),
            mesh_frequency,
            p.speed_fluctuation,
            2 * math.pi * p.speed_fluctuation_hz,
            p.speed_fluctuation_phase,
            math.cos(p.speed_fluctuation_phase),
            1.0 / g.base_pitch,
        ],
        dtype=float,
    )
    runout = np.array(
        [
            (amplitude, 2 * math.pi / g.teeth_pinion * ratio, offset)
            for amplitude, ratio, offset in (
                (p.runout_pinion, 1.0, p.runout_phase_pinion),
                (p.runout_gear, g.teeth_pinion / g.teeth_gear, p.runout_phase_gear),
            )
            if amplitude
        ],
        dtype=float,
    ).reshape(-1, 3)
    return constants, runout


def mesh_phase_at(p, t: float) -> float:
    """The mesh phase (mesh periods: pair j, pinion tooth j mod z1, enters mesh at phase j) the
    model's excitation has at time `t` of a run of `p`: where the teeth stand at a record's first
    sample (`t` the settling time)."""
    return float(mesh_excitation(float(t), *excitation_tables(p))[0])


class MeshForce:
    """The `simple` mesh: pair j nominally in contact while its phase is in [0, contact ratio),
    all pairs equally stiff, the extended contact (tip gap) outside the window; the chipped tooth
    and root crack scale their pair by the loss the potential-energy model gives for the tooth's
    mean stiffness. `MeshForce(p, damping)` builds the model `p.mesh_stiffness_model` names.

    damping: the steady viscous mesh damping (N s/m) at the mean mesh stiffness.
    """

    def __new__(cls, p, damping: float = 0.0):
        if p.mesh_stiffness_model not in MESH_STIFFNESS_MODELS:
            raise ValueError(
                f"unknown mesh_stiffness_model {p.mesh_stiffness_model!r}; "
                f"choose one of {list(MESH_STIFFNESS_MODELS)}"
            )
        if cls is MeshForce and p.mesh_stiffness_model == "potential_energy":
            cls = TVMSMeshForce
        return super().__new__(cls)

    def _common(self, p, damping: float):
        g = p.geometry
        self.teeth = g.teeth_pinion
        self.contact_ratio = g.contact_ratio
        self.mesh_frequency = p.speed_rpm / 60.0 * g.teeth_pinion
        self.base_pitch = g.base_pitch
        self.inverse_base_pitch = 1.0 / g.base_pitch
        self.tip_radius = g.base_radius(g.teeth_pinion)  # rho of the tip gap s^2 / (2 rho)
        self.gear_ratio = g.teeth_pinion / g.teeth_gear
        self.mean_force_ref = p.mesh_stiffness * DEFLECTION_REF
        self.exponent = p.contact_exponent
        self.hysteresis = hysteresis_factor(p.contact_law, p.restitution)
        # viscous damping per unit of pair stiffness (pair stiffness in force-at-d_ref units), and
        # the pair deflection over which it grows in
        self.damping_per_stiffness = damping / self.mean_force_ref
        self.inverse_damping_onset = 1.0 / operating_deflection(p) if damping else 0.0
        self.backlash = p.backlash
        self.te_amplitude = p.transmission_error
        self.excitation_constants, self.runout = excitation_tables(p)
        pinion = _pitch_errors(p.pitch_errors_pinion, g.teeth_pinion, "pinion")
        gear = _pitch_errors(p.pitch_errors_gear, g.teeth_gear, "gear")
        # pair j meets pinion tooth j mod z1 and gear tooth j mod z2: periodic in lcm(z1, z2)
        self.pitch_period = math.lcm(g.teeth_pinion, g.teeth_gear)
        self.pair_pitch_error = [
            pinion[j % g.teeth_pinion] + gear[j % g.teeth_gear] for j in range(self.pitch_period)
        ]
        self.stiffness_factor = contact_stiffness_factors(p)
        # the callback's gate, shared with the compiled kernel (mesh_kernel.SEPARATED, TRACKING)
        self._state = np.zeros(2)
        self.impacts = {}  # contact key -> approach speed d'(-) of an impact still in contact
        self.separated = False  # the whole mesh was out of contact at the last call

    def __init__(self, p, damping: float = 0.0):
        self._common(p, damping)
        self.pair_force_ref = p.mesh_stiffness * DEFLECTION_REF / self.contact_ratio
        # equal pairs have no flank: a tooth's flank and damage maps count by their mean, as a later
        # contact
        maps = add_flank_maps(tuple(p.flank_maps_pinion), damage_maps(p))
        if maps:
            z1 = p.geometry.teeth_pinion
            mean = [0.0 if m is None else float(m.array().mean()) for m in maps]
            self.pair_pitch_error = [e - mean[j % z1] for j, e in enumerate(self.pair_pitch_error)]
        if whole_tooth_missing(p):
            self.stiffness_factor[p.faulty_tooth % self.teeth] = 0.0
        elif p.health_state in ("chipped_tooth", "root_crack", "spall"):
            tvms = GearMesh(p.geometry, slices=p.helix_slices, damage=tooth_damage(p))
            self.stiffness_factor[p.faulty_tooth % self.teeth] = sum(
                grp.stiffness.sum() for grp in tvms.groups(p.faulty_tooth)
            ) / sum(grp.stiffness.sum() for grp in tvms.healthy_groups)
        # mesh_kernel's layout (S_BACKLASH, S_CONTACT_RATIO, ...)
        constants = np.array(
            [
                self.backlash,
                self.contact_ratio,
                self.base_pitch,
                self.tip_radius,
                self.pair_force_ref,
                self.exponent,
                self.damping_per_stiffness,
                self.inverse_damping_onset,
                self.te_amplitude,
            ],
            dtype=float,
        )
        self._bind(
            simple_contacts,
            simple_steady_force,
            simple_gated_force,
            constants,
            np.array(self.stiffness_factor, dtype=float),
            np.array(self.pair_pitch_error, dtype=float),
        )

    def _bind(self, contacts, steady_force, gated_force, *tables):
        """Bind the compiled contact enumerator and steady force to this mesh's tables and its
        contacts' scratch space (mesh_kernel: tables first, then the call's t, deflection, rate),
        and make `spring_force`, the callback, on the gated kernel."""
        self.contacts = np.zeros((MAX_CONTACTS, 4))
        self.find_contacts = functools.partial(
            entry_point(contacts), self.excitation_constants, self.runout, *tables
        )
        self.steady_force = functools.partial(
            entry_point(steady_force),
            self.excitation_constants,
            self.runout,
            *tables,
            self.contacts,
        )
        self.kernel_arrays = ArrayBlock(
            self._state, self.excitation_constants, self.runout, *tables, self.contacts
        )
        gated, address, tracked = (
            entry_point(gated_force),
            self.kernel_arrays.address,
            self.tracked_force,
        )

        def spring_force(mbs, t, item, deflection, rate, stiffness, damping, offset):
            """The force as exudyn's springForceUserFunction takes it (the connector's own
            stiffness, damping and offset unused). The hot path, four calls per RK44 step: in
            steady contact one compiled call; the impacts' state in Python (`tracked_force`)."""
            total = gated(address, t, deflection, rate)
            return total if total >= 0.0 else tracked(t, deflection, rate)

        self.spring_force = spring_force

    @property
    def separated(self) -> bool:
        """Whether the whole mesh was out of contact at the last call."""
        return self._state[SEPARATED] != 0.0

    @separated.setter
    def separated(self, value: bool):
        self._state[SEPARATED] = 1.0 if value else 0.0

    # -- excitation --------------------------------------------------------------------------
    def excitation(self, t):
        """(mesh phase in mesh periods, its rate, run-out of both shafts along the line of action
        (m), its rate) at time t (`mesh_kernel.mesh_excitation`)."""
        return mesh_excitation(t, self.excitation_constants, self.runout)

    def pitch_error(self, j) -> float:
        """Pitch errors of the pinion and gear teeth of pair j (m; > 0 closes the pair earlier)."""
        return self.pair_pitch_error[j % self.pitch_period]

    # -- contact -----------------------------------------------------------------------------
    # The hot path: called four times per RK44 step, so plain floats and few calls. `touching`
    # collects the keys in contact only while an impact is tracked (a list, or None).
    def _contact(self, key, stiffness_ref, d, d_t, touching):
        """Force of one contact (pair group) at deflection d > 0."""
        elastic = stiffness_ref * (d / DEFLECTION_REF) ** self.exponent
        onset = damping_onset(d * self.inverse_damping_onset)
        force = elastic + self.damping_per_stiffness * stiffness_ref * onset * d_t
        if touching is not None:
            touching.append(key)
            if self.separated and d_t > 0.0:
                self.impacts[key] = d_t  # closes after the whole mesh lost contact: an impact
            v_minus = self.impacts.get(key)
            if v_minus is not None:
                force += elastic * self.hysteresis * d_t / v_minus
        return force if force > 0.0 else 0.0

    def _back_flank(self, back, d_t):
        """Back-flank contact closing the backlash by `back` > 0 (rattle): always an impact."""
        if "back" not in self.impacts and -d_t > 0.0:
            self.impacts["back"] = -d_t
        elastic = self.mean_force_ref * (back / DEFLECTION_REF) ** self.exponent
        v_minus = self.impacts.get("back")
        force = elastic * (1.0 + (self.hysteresis * -d_t / v_minus if v_minus else 0.0))
        self._finish(["back"], True)
        return -force if force > 0.0 else 0.0

    def _finish(self, touching, touched):
        """Remember whether the mesh is in contact; forget impacts whose contact has ended."""
        if touching is not None:
            for key in [k for k in self.impacts if k not in touching]:
                del self.impacts[key]
        self.separated = not touched
        self._state[TRACKING] = 1.0 if self.impacts else 0.0

    def __call__(self, t, deflection, rate):
        """The mesh force (N) at time t, mesh deflection (m) and its rate (m/s)."""
        return self.spring_force(None, t, None, deflection, rate, None, None, None)

    def tracked_force(self, t, deflection, rate):
        """The force with the impacts' state (Python): the back flank, a contact that closes after
        the whole mesh lost contact (the Table-1 law's hysteresis); the contacts are the compiled
        enumerator's, so in steady contact this is the compiled sum."""
        if not abs(deflection) < MAX_DEFLECTION:
            # a diverging run: stop at once (the extended contact's pair range grows with the
            # deflection and would eat the memory before the run's end check)
            raise SimulationError(
                f"mesh deflection {deflection:.3g} m at t = {t:.4g} s: the simulation diverged"
            )
        count = self.find_contacts(t, deflection, rate, self.contacts)
        if count == BACK_FLANK:
            d, d_t = self.contacts[0, 2], self.contacts[0, 3]
            return self._back_flank(-d - self.backlash, d_t)
        if count == TOO_MANY_CONTACTS:
            raise SimulationError(
                f"over {MAX_CONTACTS} tooth contacts at once at t = {t:.4g} s (mesh deflection "
                f"{deflection:.3g} m): the simulation diverged"
            )
        touching = [] if (self.impacts or self.separated) else None
        total = 0.0
        for key, stiffness, d, d_t in self.contacts[:count].tolist():
            total += self._contact(int(key), stiffness, d, d_t, touching)
        self._finish(touching, total > 0.0)
        return total

    def static_deflection(self, force):
        """Deflection that carries `force` with the mean mesh stiffness (for initial conditions)."""
        return DEFLECTION_REF * (force / self.mean_force_ref) ** (1.0 / self.exponent)

    def starting_deflection(self, force: float, t: float = 0.0) -> float:
        """The deflection at which the pairs in contact at time `t` carry `force` (N): where the
        run starts. The mean mesh's `static_deflection` misses it by how far the engaged teeth's
        pitch errors and flank deviations at `t` lie from the mean, tens of micrometres on coarse
        gears at a light load against a deflection well under one: the first step then meets an
        impact the step cannot resolve. Found on the mesh's own steady-contact force (monotone
        in the deflection), searching out from the mean mesh's value; that value itself where
        none within half of MAX_DEFLECTION carries the force (the run then says it diverged)."""
        from scipy.optimize import brentq

        guess = self.static_deflection(force)
        if not abs(guess) < MAX_DEFLECTION / 2:  # a mesh too soft to carry it: the run says so
            return guess

        def excess(deflection):
            # the steady contact's force: no impact remembered from the search's last call
            self.impacts.clear()
            self._finish(None, True)
            return self(t, deflection, 0.0) - force

        try:
            low = high = guess
            step = DEFLECTION_REF
            while excess(low) > 0.0:
                low -= step
                step *= 2.0
                if low < -MAX_DEFLECTION / 2:
                    return guess
            step = DEFLECTION_REF
            while excess(high) < 0.0:
                high += step
                step *= 2.0
                if high > MAX_DEFLECTION / 2:
                    return guess
            return guess if low == high else float(brentq(excess, low, high, xtol=1e-12))
        finally:
            # the search touched the impact state: the run starts in steady contact
            self.impacts.clear()
            self._finish(None, True)


def damping_onset(x: float) -> float:
    """The smooth step 3 x^2 - 2 x^3 from 0 at x = 0 to 1 at x >= 1 (continuous, with its slope)."""
    return x * x * (3.0 - 2.0 * x) if x < 1.0 else 1.0


def _pitch_errors(values, teeth: int, name: str) -> list[float]:
    if not values:
        return [0.0] * teeth
    if len(values) != teeth:
        raise ValueError(f"pitch_errors_{name}: {len(values)} values for {teeth} teeth")
    return [float(v) for v in values]


class TVMSMeshForce(MeshForce):
    """The `potential_energy` mesh: every pair's contact groups (one per pair; a spall adds the
    pit, `depth` below the flank) carry the table stiffness K(u) (linear interpolation on a uniform
    grid, no energy integral at run time). The tables are scaled so the healthy mean mesh
    stiffness at 1 um is `mesh_stiffness` (the calibrated quantity keeps its meaning; the
    potential-energy method sets the shape over the mesh cycle, the load sharing and the damage).
    A pair whose stiffness does not vanish at its window's edge (spur gears) keeps the extended
    contact beyond it; a helical pair enters and leaves slice by slice."""

    def __init__(self, p, damping: float = 0.0):
        self._common(p, damping)
        self.te_amplitude = 0.0  # the static TE comes from the profile deviation tables
        tvms = gear_mesh(p)
        self.tvms = tvms
        self.window = tvms.window
        self.points_per_pitch = tvms.points_per_pitch
        scale = p.mesh_stiffness * DEFLECTION_REF / tvms.mean_stiffness
        edge = int(math.floor(self.window * self.points_per_pitch))

        def compile_group(group, factor):
            k = (group.stiffness * scale * factor).tolist()
            e = group.deviation.tolist()
            rows = [(k[i], k[i + 1] - k[i], e[i], e[i + 1] - e[i]) for i in range(len(k) - 1)]
            return rows, (k[0], e[0], k[edge], e[edge])

        compiled = {}
        self.tooth_groups = []
        for tooth in range(self.teeth):
            groups, factor = tvms.groups(tooth), self.stiffness_factor[tooth]
            if (id(groups), factor) not in compiled:
                compiled[id(groups), factor] = tuple(compile_group(g, factor) for g in groups)
            self.tooth_groups.append(compiled[id(groups), factor])
        # a spur pair carries load at its window's edges: the extended contact beyond them; a helical
        # pair's edge values are the last partial slice before its stiffness reaches zero
        peak = max(row[0] for groups in self.tooth_groups for rows, _ in groups for row in rows)
        self.extended = any(
            max(edges[0], edges[2]) > EDGE_CONTACT * peak
            for groups in self.tooth_groups
            for _, edges in groups
        )
        # per pair j mod lcm(z1, z2): its pinion tooth's contact groups and its pitch errors
        self.pairs = [
            (self.tooth_groups[j % self.teeth], self.pair_pitch_error[j])
            for j in range(self.pitch_period)
        ]
        # how far a pair's flank can stand proud of the mesh deflection at its window's edges (its
        # pitch errors less the edge deviation): the extended contact reaches that much further
        self.edge_excess = max(
            0.0,
            max(
                error - min(edges[1], edges[3])
                for groups, error in self.pairs
                for _, edges in groups
            ),
        )
        healthy = tvms.healthy_groups[0]
        self.mean_deviation = float(
            (healthy.stiffness * healthy.deviation).sum() / healthy.stiffness.sum()
        )
        self._pack()

    def _pack(self):
        """The tables and constants as mesh_kernel.tvms_contacts takes them."""
        groups = {}  # id of a compiled group -> its row in `tables`
        for tooth_groups in self.tooth_groups:
            for group in tooth_groups:
                groups.setdefault(id(group), group)
        index = {key: row for row, key in enumerate(groups)}
        length = max(len(rows) for rows, _ in groups.values())
        tables, edges = np.zeros((len(groups), length, 4)), np.zeros((len(groups), 4))
        for key, (group_rows, group_edges) in groups.items():
            tables[index[key], : len(group_rows)] = group_rows
            edges[index[key]] = group_edges
        slots = max(len(g) for g in self.tooth_groups)
        group_of_tooth = np.full((self.teeth, slots), -1, dtype=np.int64)
        for tooth, tooth_groups in enumerate(self.tooth_groups):
            group_of_tooth[tooth, : len(tooth_groups)] = [
                index[id(group)] for group in tooth_groups
            ]
        # mesh_kernel's layout (T_BACKLASH, T_WINDOW, ...)
        constants = np.array(
            [
                self.backlash,
                self.window,
                self.points_per_pitch,
                self.base_pitch,
                self.tip_radius,
                self.exponent,
                self.damping_per_stiffness,
                self.inverse_damping_onset,
                self.edge_excess,
                float(self.extended),
                MAX_DEFLECTION,
            ],
            dtype=float,
        )
        self._bind(
            tvms_contacts,
            tvms_steady_force,
            tvms_gated_force,
            constants,
            tables,
            edges,
            group_of_tooth,
            np.array(self.pair_pitch_error, dtype=float),
        )

    def static_deflection(self, force):
        return super().static_deflection(force) + self.mean_deviation


def mesh_equivalent_mass(geometry, pinion_polar_inertia: float, gear_polar_inertia: float) -> float:
    """Equivalent mass of the pair along the transverse line of action (torsional)."""
    rb1, rb2 = (
        geometry.base_radius(geometry.teeth_pinion),
        geometry.base_radius(geometry.teeth_gear),
    )
    return 1.0 / (rb1**2 / pinion_polar_inertia + rb2**2 / gear_polar_inertia)


def static_mesh_force(p) -> float:
    """The mesh force (N, along the line of action) that carries the static load of `p` (> 0)."""
    if not p.load_torque > 0.0:
        raise ValueError(
            f"load_torque {p.load_torque} N m: the mesh's operating point needs a load (> 0)"
        )
    return p.load_torque / p.geometry.base_radius(p.geometry.teeth_gear)


def operating_deflection(p) -> float:
    """Deflection (m) of the mean mesh that carries the static load of `p` (> 0)."""
    return deflection_of(static_mesh_force(p), p.mesh_stiffness, p.contact_exponent)


# ISO 6336-1: below this line load (N/mm of face width) the mesh stiffness is reduced
LIGHT_LINE_LOAD = 100.0


def iso6336_deflections(p) -> tuple[float, float]:
    """The static deflection (m) of the pair of `p` under its load by ISO 6336-1's mesh stiffness
    (`mesh.iso6336_mesh_stiffness`): (the linear-elastic one, the one with the standard's
    reduction (F_t / b / 100 N/mm)^0.25 below 100 N/mm of face width, where the flanks' roughness
    and deviations leave less of them in contact)."""
    g = p.geometry
    linear = static_mesh_force(p) / iso6336_mesh_stiffness(g)
    line_load = p.load_torque / g.pitch_radius(g.teeth_gear) / (g.face_width * 1.0e3)
    return linear, linear / min(1.0, line_load / LIGHT_LINE_LOAD) ** 0.25


def deflection_of(force: float, stiffness: float, exponent: float) -> float:
    """The deflection (m) at which a mesh of `mesh_stiffness` `stiffness` (N/m at 1 um) and contact
    exponent `exponent` carries `force` (N)."""
    return DEFLECTION_REF * (force / (stiffness * DEFLECTION_REF)) ** (1.0 / exponent)


def stiffness_for_deflection(p, deflection: float, exponent: float) -> float:
    """The `mesh_stiffness` (N/m at 1 um) whose mean mesh of contact exponent `exponent` carries the
    static load of `p` at `deflection` (m): the inverse of `operating_deflection`."""
    if not (deflection > 0.0 and exponent > 0.0):
        raise ValueError(
            f"deflection {deflection} m and exponent {exponent}: both must be positive"
        )
    return static_mesh_force(p) / DEFLECTION_REF / (deflection / DEFLECTION_REF) ** exponent


def operating_stiffness(p) -> float:
    """dF/d(delta) of the mean mesh at the deflection that carries the static load of `p`: the
    stiffness the vibration sees. K and n trade off against each other at one load; this does not."""
    return (
        p.contact_exponent
        * p.mesh_stiffness
        * (operating_deflection(p) / DEFLECTION_REF) ** (p.contact_exponent - 1.0)
    )


def mesh_damping(p, pinion_polar_inertia: float, gear_polar_inertia: float) -> float:
    """Viscous mesh damping c = 2 zeta sqrt(k_op m_eq) (N s/m) of the damping ratio
    `p.mesh_damping_ratio` at the operating mesh stiffness."""
    return (
        2.0
        * p.mesh_damping_ratio
        * math.sqrt(
            operating_stiffness(p)
            * mesh_equivalent_mass(p.geometry, pinion_polar_inertia, gear_polar_inertia)
        )
    )


def random_pitch_errors(rng: np.random.Generator, teeth: int, rms: float) -> list[float]:
    """Independent Gaussian single pitch deviations of every tooth, `rms` (m) each."""
    return (rng.normal(0.0, rms, teeth) if rms > 0 else np.zeros(teeth)).tolist()

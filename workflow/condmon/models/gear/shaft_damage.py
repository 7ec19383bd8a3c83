"""Damage of a flexible shaft that turns with it: a breathing transverse crack and a delamination.

Pure: section geometry in, the stiffness the damage removes out; `ShaftDamageForce` is the force
law the drivetrain hands to exudyn.

A damaged stretch of shaft is a Timoshenko element (`structure.py`) whose section is weaker about
one axis than the other, and that axis turns with the shaft. The assembled structure keeps the
intact element's bending; the damage takes bending stiffness away in the rotating frame, as the
local rotational flexibility of the classical cracked-rotor models (Dimarogonas; Gasch):
- an element's bending under a constant moment is its relative end rotation
  d = w2' - w1' in each plane, with stiffness EI / L; a section of EI_d lacks (EI - EI_d) / L on d
  (`removed_rotational_stiffness`);
- at shaft angle phi the damage direction is xi = (cos phi, sin phi): d_xi = c d_x + s d_y and
  d_eta = -s d_x + c d_y, and the removed energy 1/2 k_xi d_xi^2 + 1/2 k_eta d_eta^2 gives forces
  on (d_x, d_y) at twice the shaft frequency (and once, through the breathing);
- a crack (`crack_section_ratios`): the open crack removes the material beyond its front
  (`cracked_tube_geometry`); it breathes: open while the bending strain at its mouth is
  tensile (d_xi < 0, the mouth at +xi), closed and intact otherwise. The element spans one outer
  diameter around the crack, about the length over which a crack's stress field relaxes;
- a delamination (`delamination_section_ratios`): the outer sublaminate over an arc slides on the
  inner one and carries no axial stress ("free mode"), over the delaminated length, always. Its
  shear stiffness loss (the area ratio) is the same in every direction, so the structure carries
  it directly (`Drivetrain`); only the bending loss turns.
The relative rotations are coordinates of the drivetrain's reduced model
(`drivetrain.model_matrices`), so this force sees two numbers per element.

Damaged sections (`cracked_tube_geometry`, `delaminated_tube_geometry`; a solid shaft is a tube
with no bore): the area and second moments of an annulus with material missing on one side (the
+xi side), from exact closed forms for circular segments and annular sectors. Missing material
carries no axial stress: an open crack, or an outer sublaminate that slides on the inner one
('free mode' delamination).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from condmon.models.gear.mesh_force import SHAFT_HEALTH_STATES

__all__ = [
    "SHAFT_HEALTH_STATES",
    "DamagedElement",
    "ShaftDamageForce",
    "crack_section_ratios",
    "delamination_section_ratios",
    "RELATIVE_ROTATION",
    "removed_rotational_stiffness",
    "SectionGeometry",
    "cracked_tube_geometry",
    "delaminated_tube_geometry",
]


@dataclass(frozen=True)
class SectionGeometry:
    """Area and second moments of a (damaged) tube cross-section.

    Coordinates in the section plane: xi points from the tube's centre toward the damage (the
    crack mouth, the delaminated arc), eta is perpendicular to it; the section is symmetric
    about the xi axis.
    - centroid_offset: xi of the remaining section's centroid from the tube's centre (negative
      when material on the +xi side is missing);
    - second_moment_xi = integral of (xi - centroid_offset)^2 dA: the stiffness against bending
      that moves the section along xi (curvature in the xi-z plane), whose axial stress varies
      along xi, i.e. the bending that opens and closes a crack lying at +xi;
    - second_moment_eta = integral of eta^2 dA: bending along eta (the crack sits on the neutral
      axis of that bending).
    Both are about axes through the remaining section's centroid."""

    area: float
    centroid_offset: float
    second_moment_xi: float
    second_moment_eta: float


def _disc_beyond(radius: float, cut: float) -> np.ndarray:
    """(area, integral xi dA, integral xi^2 dA, integral eta^2 dA) about the disc's centre of the
    part of a disc of `radius` with xi > cut (a circular segment; the whole disc for cut <= -radius)."""
    if radius == 0:
        return np.zeros(4)
    alpha = math.acos(min(1.0, max(-1.0, cut / radius)))  # half angle of the segment
    return np.array(
        [
            radius**2 * (alpha - math.sin(alpha) * math.cos(alpha)),
            2 / 3 * radius**3 * math.sin(alpha) ** 3,
            radius**4 / 4 * (alpha - math.sin(4 * alpha) / 4),
            2
            / 3
            * radius**4
            * (3 * alpha / 8 - math.sin(2 * alpha) / 4 + math.sin(4 * alpha) / 32),
        ]
    )


def _annular_sector(inner_radius: float, outer_radius: float, arc: float) -> np.ndarray:
    """(area, integral xi dA, integral xi^2 dA, integral eta^2 dA) about the centre of the sector
    inner_radius < rho < outer_radius, |theta| < arc / 2 (radians, theta from +xi)."""
    r2, r3, r4 = (outer_radius**p - inner_radius**p for p in (2, 3, 4))
    return np.array(
        [
            arc / 2 * r2,
            r3 / 3 * 2 * math.sin(arc / 2),
            r4 / 4 * (arc + math.sin(arc)) / 2,
            r4 / 4 * (arc - math.sin(arc)) / 2,
        ]
    )


def _geometry(moments: np.ndarray) -> SectionGeometry:
    """SectionGeometry from moments about the tube's centre (shifted to the centroid)."""
    area, first, xi2, eta2 = (float(m) for m in moments)
    centroid = first / area
    return SectionGeometry(
        area=area,
        centroid_offset=centroid,
        second_moment_xi=xi2 - area * centroid**2,
        second_moment_eta=eta2,
    )


def _check_annulus(outer_diameter: float, inner_diameter: float) -> None:
    if not outer_diameter > 0:
        raise ValueError(f"outer_diameter must be positive, got {outer_diameter}")
    if not 0 <= inner_diameter < outer_diameter:
        raise ValueError(
            f"inner_diameter {inner_diameter} must be in [0, outer_diameter = {outer_diameter})"
        )


def cracked_tube_geometry(
    outer_diameter: float, inner_diameter: float, depth: float
) -> SectionGeometry:
    """Section of a tube (inner_diameter 0: a solid shaft) with an open, straight-fronted
    transverse crack entering from the outer surface at +xi: material with xi > R - a is missing,
    depth = a / outer_diameter in [0, 1) (0: intact, 0.5: crack front on the centre line)."""
    _check_annulus(outer_diameter, inner_diameter)
    if not 0 <= depth < 1:
        raise ValueError(f"depth {depth} must be in [0, 1) (crack depth / outer diameter)")
    R, r = outer_diameter / 2, inner_diameter / 2
    front = R - depth * outer_diameter
    # remaining = (outer disc with xi <= front) - (bore with xi <= front)
    remaining = (_disc_beyond(R, -R) - _disc_beyond(R, front)) - (
        _disc_beyond(r, -r) - _disc_beyond(r, front)
    )
    return _geometry(remaining)


def delaminated_tube_geometry(
    outer_diameter: float, inner_diameter: float, interface_depth: float, arc_deg: float
) -> SectionGeometry:
    """Section of a tube with a 'free mode' delamination: the outer sublaminate, radius
    R - interface_depth (R - r) to R, over an arc of `arc_deg` centred on +xi slides on the
    inner one and carries no axial stress, so it is left out.

    interface_depth is the fraction of the wall thickness from the outer surface to the
    delaminated interface, in [0, 1) (a real interface lies between plies: k / n_plies;
    1 would be the bore, where there is no interface). arc_deg is in [0, 360]. Leaving the
    sublaminate out entirely is the lower bound of the stiffness: beyond the delamination's
    ends and at the arc's edges the sublaminate still takes some load."""
    _check_annulus(outer_diameter, inner_diameter)
    if not 0 <= interface_depth < 1:
        raise ValueError(
            f"interface_depth {interface_depth} must be in [0, 1) (fraction of the wall thickness)"
        )
    if not 0 <= arc_deg <= 360:
        raise ValueError(f"arc_deg {arc_deg} must be in [0, 360]")
    R, r = outer_diameter / 2, inner_diameter / 2
    interface_radius = R - interface_depth * (R - r)
    remaining = _annular_sector(r, R, 2 * math.pi) - _annular_sector(
        interface_radius, R, math.radians(arc_deg)
    )
    return _geometry(remaining)


# d = RELATIVE_ROTATION . (w1, w1', w2, w2'): an element's relative end rotation in one plane
RELATIVE_ROTATION = np.array([0.0, -1.0, 0.0, 1.0])


def removed_rotational_stiffness(length: float, bending: float, bending_ratio: float) -> float:
    """Stiffness (N m/rad) on the relative rotation that a section of bending_ratio x EI lacks
    against the intact one over an element of `length`."""
    return bending * (1.0 - bending_ratio) / length


def crack_section_ratios(
    outer_diameter: float, inner_diameter: float, depth: float
) -> tuple[float, float, float]:
    """(I_xi, I_eta, area) of a tube with an open crack of relative depth a / D over the intact."""
    return _ratios(
        cracked_tube_geometry(outer_diameter, inner_diameter, depth),
        cracked_tube_geometry(outer_diameter, inner_diameter, 0.0),
    )


def delamination_section_ratios(
    outer_diameter: float, inner_diameter: float, interface_depth: float, arc_deg: float
) -> tuple[float, float, float]:
    """(I_xi, I_eta, area) of a tube whose outer sublaminate over `arc_deg` carries no stress."""
    return _ratios(
        delaminated_tube_geometry(outer_diameter, inner_diameter, interface_depth, arc_deg),
        delaminated_tube_geometry(outer_diameter, inner_diameter, 0.0, 0.0),
    )


def _ratios(damaged, intact) -> tuple[float, float, float]:
    return (
        damaged.second_moment_xi / intact.second_moment_xi,
        damaged.second_moment_eta / intact.second_moment_eta,
        damaged.area / intact.area,
    )


@dataclass(frozen=True)
class DamagedElement:
    """One damaged shaft element: the rotational stiffness removed in the damage's own plane (xi,
    where a crack opens) and across it (eta), whether it breathes, and how its direction turns:
    phi(t) = angle + spin_hz 2 pi t."""

    removed_xi: float
    removed_eta: float
    breathing: bool
    angle: float
    spin_hz: float


class ShaftDamageForce:
    """Moments on the damaged elements' relative rotations (d_x, d_y per element) that take away
    the bending stiffness the damage removes (the structure holds the intact shaft).

    Called by exudyn at every solver stage, so it works on plain floats: numpy's per-call
    overhead on 2-vectors would cost more than the whole structure's solve."""

    def __init__(self, elements: list[DamagedElement]):
        self.elements = [
            (e.removed_xi, e.removed_eta, e.breathing, e.angle, 2 * math.pi * e.spin_hz)
            for e in elements
        ]

    def __call__(self, t: float, d) -> list[float]:
        force = [0.0] * (2 * len(self.elements))
        for k, (removed_xi, removed_eta, breathing, angle, omega) in enumerate(self.elements):
            d_x, d_y = d[2 * k], d[2 * k + 1]
            phi = angle + omega * t
            c, s = math.cos(phi), math.sin(phi)
            d_xi = c * d_x + s * d_y
            if breathing and d_xi >= 0.0:
                continue  # the crack's mouth is in compression: closed, the section intact
            f_xi, f_eta = removed_xi * d_xi, removed_eta * (c * d_y - s * d_x)
            force[2 * k] = c * f_xi - s * f_eta
            force[2 * k + 1] = s * f_xi + c * f_eta
        return force

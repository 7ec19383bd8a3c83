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
  (`laminate.cracked_tube_geometry`); it breathes: open while the bending strain at its mouth is
  tensile (d_xi < 0, the mouth at +xi), closed and intact otherwise. The element spans one outer
  diameter around the crack, about the length over which a crack's stress field relaxes;
- a delamination (`delamination_section_ratios`): the outer sublaminate over an arc slides on the
  inner one and carries no axial stress ("free mode"), over the delaminated length, always. Its
  shear stiffness loss (the area ratio) is the same in every direction, so the structure carries
  it directly (`Drivetrain`); only the bending loss turns.
The relative rotations are coordinates of the drivetrain's reduced model
(`drivetrain.model_matrices`), so this force sees two numbers per element.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from condmon.models.cfrp.laminate import cracked_tube_geometry, delaminated_tube_geometry
from condmon.models.gear.mesh_force import SHAFT_HEALTH_STATES

__all__ = ["SHAFT_HEALTH_STATES", "DamagedElement", "ShaftDamageForce", "crack_section_ratios",
           "delamination_section_ratios", "RELATIVE_ROTATION", "removed_rotational_stiffness"]


# d = RELATIVE_ROTATION . (w1, w1', w2, w2'): an element's relative end rotation in one plane
RELATIVE_ROTATION = np.array([0.0, -1.0, 0.0, 1.0])


def removed_rotational_stiffness(length: float, bending: float, bending_ratio: float) -> float:
    """Stiffness (N m/rad) on the relative rotation that a section of bending_ratio x EI lacks
    against the intact one over an element of `length`."""
    return bending * (1.0 - bending_ratio) / length


def crack_section_ratios(outer_diameter: float, inner_diameter: float, depth: float) -> tuple[float, float, float]:
    """(I_xi, I_eta, area) of a tube with an open crack of relative depth a / D over the intact."""
    return _ratios(cracked_tube_geometry(outer_diameter, inner_diameter, depth),
                   cracked_tube_geometry(outer_diameter, inner_diameter, 0.0))


def delamination_section_ratios(outer_diameter: float, inner_diameter: float, interface_depth: float,
                                arc_deg: float) -> tuple[float, float, float]:
    """(I_xi, I_eta, area) of a tube whose outer sublaminate over `arc_deg` carries no stress."""
    return _ratios(delaminated_tube_geometry(outer_diameter, inner_diameter, interface_depth, arc_deg),
                   delaminated_tube_geometry(outer_diameter, inner_diameter, 0.0, 0.0))


def _ratios(damaged, intact) -> tuple[float, float, float]:
    return (damaged.second_moment_xi / intact.second_moment_xi, damaged.second_moment_eta / intact.second_moment_eta,
            damaged.area / intact.area)


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
        self.elements = [(e.removed_xi, e.removed_eta, e.breathing, e.angle, 2 * math.pi * e.spin_hz)
                         for e in elements]

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

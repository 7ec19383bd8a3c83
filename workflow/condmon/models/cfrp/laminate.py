"""Carbon-fibre (CFRP) tube shafts by classical laminate theory.

Pure numpy / math: ply properties in, `Section`s (see models/structure.py) out.

Laminate (classical laminate theory, CLT; Jones 1999, Reddy 2004):
- each ply is a homogeneous orthotropic layer in plane stress (1 = fibre, 2 = transverse);
- ply angles are measured in the wall's own coordinates: x = the shaft axis (z of structure.py),
  y = the hoop direction; a positive angle turns the fibre from x toward y;
- plies are stacked from the inner surface outward, z is measured outward from the mid-surface;
- the effective engineering constants E_x, G_xy, nu_xy come from the membrane compliance inv(A),
  i.e. with the wall's own curvature restrained (the closed tube keeps its wall from curling).

Tube section (`laminate_tube_section`): thin-walled. Beam bending of a thin tube stretches and
compresses the wall in its plane, so the laminate's membrane moduli give EA, EI, GJ; the B and D
matrices govern bending of the wall itself (ovalisation, local buckling), not beam bending.

The damaged sections of a tube (a crack, a delamination) are the shaft damage's: `gear/shaft_damage.py`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from condmon.models.structure import Section


@dataclass(frozen=True)
class Ply:
    """A unidirectional ply: moduli E1 (fibre), E2 (transverse), in-plane shear G12, major
    Poisson ratio nu12, density (kg/m^3), transverse shear moduli G1z, G2z (Pa). G1z and G2z
    are kept for shell models; the membrane (thin-tube) stiffness here does not use them."""

    E1: float
    E2: float
    G12: float
    nu12: float
    density: float
    G1z: float
    G2z: float

    def __post_init__(self):
        for name in ("E1", "E2", "G12", "density", "G1z", "G2z"):
            if not getattr(self, name) > 0:
                raise ValueError(f"Ply: {name} must be positive, got {getattr(self, name)}")
        # positive definite plane-stress compliance needs nu12^2 < E1 / E2
        if not abs(self.nu12) < math.sqrt(self.E1 / self.E2):
            raise ValueError(f"Ply: |nu12| = {abs(self.nu12)} must be below sqrt(E1/E2)")


# The CFRP study's Table 2. Table 2 gives no Poisson ratio: nu12 = 0.3 is a typical
# carbon/epoxy value (T300/5208: 0.28); between 0.25 and 0.35 the laminate moduli change by ~1 % at most.
CFRP_STUDY_PLY = Ply(
    E1=138.945e9, E2=6.6154e9, G12=3.387e9, nu12=0.3, density=1560.0, G1z=3.387e9, G2z=2.2864e9
)


def reduced_stiffness(ply: Ply) -> np.ndarray:
    """Plane-stress reduced stiffness Q (3 x 3, Voigt order 11, 22, 12 with engineering shear
    strain) of a ply in its own axes."""
    nu21 = ply.nu12 * ply.E2 / ply.E1
    denominator = 1 - ply.nu12 * nu21
    return np.array(
        [
            [ply.E1 / denominator, ply.nu12 * ply.E2 / denominator, 0.0],
            [ply.nu12 * ply.E2 / denominator, ply.E2 / denominator, 0.0],
            [0.0, 0.0, ply.G12],
        ]
    )


def transformed_reduced_stiffness(ply: Ply, angle_deg: float) -> np.ndarray:
    """Q-bar of a ply whose fibres lie at `angle_deg` from the x axis toward y (Jones 1999,
    eq. 2.85)."""
    Q = reduced_stiffness(ply)
    Q11, Q12, Q22, Q66 = Q[0, 0], Q[0, 1], Q[1, 1], Q[2, 2]
    m, n = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    Qb11 = Q11 * m**4 + 2 * (Q12 + 2 * Q66) * m**2 * n**2 + Q22 * n**4
    Qb22 = Q11 * n**4 + 2 * (Q12 + 2 * Q66) * m**2 * n**2 + Q22 * m**4
    Qb12 = (Q11 + Q22 - 4 * Q66) * m**2 * n**2 + Q12 * (m**4 + n**4)
    Qb66 = (Q11 + Q22 - 2 * Q12 - 2 * Q66) * m**2 * n**2 + Q66 * (m**4 + n**4)
    Qb16 = (Q11 - Q12 - 2 * Q66) * m**3 * n + (Q12 - Q22 + 2 * Q66) * m * n**3
    Qb26 = (Q11 - Q12 - 2 * Q66) * m * n**3 + (Q12 - Q22 + 2 * Q66) * m**3 * n
    return np.array([[Qb11, Qb12, Qb16], [Qb12, Qb22, Qb26], [Qb16, Qb26, Qb66]])


@dataclass(frozen=True)
class Laminate:
    """Plies of one material and thickness at `angles_deg` (degrees from the shaft axis toward
    the hoop direction), stacked from the inner surface outward."""

    ply: Ply
    angles_deg: tuple
    ply_thickness: float

    def __post_init__(self):
        object.__setattr__(self, "angles_deg", tuple(float(a) for a in self.angles_deg))
        if not self.angles_deg:
            raise ValueError("Laminate: angles_deg is empty; a laminate needs at least one ply")
        if not self.ply_thickness > 0:
            raise ValueError(f"Laminate: ply_thickness must be positive, got {self.ply_thickness}")

    @property
    def thickness(self) -> float:
        return len(self.angles_deg) * self.ply_thickness

    def abd(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Extensional A (N/m), coupling B (N) and bending D (N m) stiffness matrices, z from the
        mid-surface (positive outward)."""
        A, B, D = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 3))
        for k, angle in enumerate(self.angles_deg):
            z0 = -self.thickness / 2 + k * self.ply_thickness
            z1 = z0 + self.ply_thickness
            Qbar = transformed_reduced_stiffness(self.ply, angle)
            A += Qbar * (z1 - z0)
            B += Qbar * (z1**2 - z0**2) / 2
            D += Qbar * (z1**3 - z0**3) / 3
        return A, B, D

    def _membrane_compliance(self) -> np.ndarray:
        return np.linalg.inv(self.abd()[0])

    @property
    def axial_modulus(self) -> float:
        """Effective membrane Young's modulus along x (the shaft axis), E_x = 1 / (t a11)."""
        return float(1 / (self.thickness * self._membrane_compliance()[0, 0]))

    @property
    def shear_modulus(self) -> float:
        """Effective membrane shear modulus G_xy = 1 / (t a66)."""
        return float(1 / (self.thickness * self._membrane_compliance()[2, 2]))

    @property
    def poisson_ratio(self) -> float:
        """Effective membrane Poisson ratio nu_xy = -a12 / a11 (hoop contraction per axial strain)."""
        a = self._membrane_compliance()
        return float(-a[0, 1] / a[0, 0])


def laminate_tube_section(outer_diameter: float, laminate: Laminate) -> Section:
    """Section of a thin-walled tube whose wall is `laminate` (inner diameter = outer - 2 t).

    EA = E_x A, EI = E_x I, GJ = G_xy J with I = pi/64 (Do^4 - Di^4), J = 2 I; shear
    kappa G_xy A with kappa = 0.5, the shear coefficient of a thin-walled circular tube (the
    wall's shear stress goes as sin(theta) around the circumference)."""
    if not outer_diameter > 0:
        raise ValueError(
            f"laminate_tube_section: outer_diameter must be positive, got {outer_diameter}"
        )
    if laminate.thickness > outer_diameter / 2:
        raise ValueError(
            f"laminate_tube_section: wall thickness {laminate.thickness} exceeds the "
            f"outer radius {outer_diameter / 2}"
        )
    inner_diameter = outer_diameter - 2 * laminate.thickness
    area = math.pi / 4 * (outer_diameter**2 - inner_diameter**2)
    second_moment = math.pi / 64 * (outer_diameter**4 - inner_diameter**4)
    # the wall's membrane stiffness carries the tube's beam bending (thin-wall assumption)
    E_x, G_xy, rho = laminate.axial_modulus, laminate.shear_modulus, laminate.ply.density
    return Section(
        axial=E_x * area,
        bending=E_x * second_moment,
        torsion=G_xy * 2 * second_moment,
        shear=0.5 * G_xy * area,
        mass_per_length=rho * area,
        rotary_inertia_per_length=rho * second_moment,
        polar_inertia_per_length=rho * 2 * second_moment,
    )


QUASI_ISOTROPIC_LAYUP = (0, 45, -45, 90, 90, -45, 45, 0)


def quasi_isotropic_modulus(ply: Ply) -> float:
    """In-plane Young's modulus of a quasi-isotropic [0/45/-45/90]s laminate of `ply`: the
    3D-printed gears' material (printed fibres lie in the gear plane in all directions)."""
    return Laminate(ply, QUASI_ISOTROPIC_LAYUP, ply_thickness=1.0).axial_modulus


def quasi_isotropic_poisson_ratio(ply: Ply) -> float:
    """In-plane Poisson ratio of the quasi-isotropic [0/45/-45/90]s laminate of `ply`."""
    return Laminate(ply, QUASI_ISOTROPIC_LAYUP, ply_thickness=1.0).poisson_ratio

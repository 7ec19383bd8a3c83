"""Linear multibody structure of a drivetrain: shaft bodies, housings, bearings, beams.

Pure: geometry and stiffness in, mass / stiffness / damping matrices out (no exudyn here; the
drivetrain models hand the matrices to one exudyn ObjectGenericODE2).

Every body is a *node* at a position in space with 6 coordinates (x, y, z displacements and the
small rotations rx, ry, rz about the global axes) or, for a point mass, 3. Shafts run along z.
Rotations are deviations from the nominal spin (the shafts' rotation at speed is carried by time
in the mesh law), so a point rigidly attached to a node moves by u + theta x r: everything here
is linear and exact to first order. Gyroscopic moments are left out: at these speeds they are a
few per cent of the tilting inertia terms (Omega I_p / (omega I_d) < 0.05 at 1100 rpm).

Building blocks:
- `add_rigid_mass`: mass and principal inertia about a centre of mass attached to a node;
- `add_spring`: a Cartesian spring-damper between two attached points (or a point and the base),
  with stiffness and damping per global axis: bearings / bushings (radial x, radial y, axial) and
  housing mounts;
- `add_coordinate_spring`: a spring on one coordinate against the base (the motor coupling);
- `add_beam`: a 3-D Timoshenko beam element along z between two 6-coordinate nodes, from a
  `Section` (isotropic tube here; the CFRP rig builds its sections from the laminate).

Why matrices and not exudyn rigid bodies and connectors: both give the same natural frequencies
(tests/test_gear_model.py builds the rigid rig from exudyn's NodeRigidBodyRxyz, ObjectRigidBody and
Cartesian spring-dampers and compares), but exudyn's item version costs 2.1 s of wall time per
simulated second before any mesh force, the assembled sparse ObjectGenericODE2 0.2-0.4 s
(measured on this 2-core machine, RK44 at 19.5 us).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Section:
    """Stiffness and inertia per unit length of a straight shaft section along z.

    axial EA (N), bending EI (N m^2, the same about x and y), torsion GJ (N m^2), shear kappa G A
    (N), mass per length rho A (kg/m), rotary inertia per length rho I (kg m, about a transverse
    axis) and rho J (kg m, polar)."""

    axial: float
    bending: float
    torsion: float
    shear: float
    mass_per_length: float
    rotary_inertia_per_length: float
    polar_inertia_per_length: float

    @classmethod
    def tube(
        cls,
        outer_diameter: float,
        inner_diameter: float,
        youngs_modulus: float,
        poisson_ratio: float,
        density: float,
    ) -> "Section":
        """An isotropic circular tube (inner_diameter 0: a solid shaft). The shear coefficient
        kappa is Cowper's for a thin or solid circular section."""
        if not 0.0 <= inner_diameter < outer_diameter:
            raise ValueError(
                f"tube: inner diameter {inner_diameter} must be in [0, {outer_diameter})"
            )
        area = math.pi / 4 * (outer_diameter**2 - inner_diameter**2)
        second_moment = math.pi / 64 * (outer_diameter**4 - inner_diameter**4)
        shear_modulus = youngs_modulus / (2 * (1 + poisson_ratio))
        m = inner_diameter / outer_diameter
        kappa = (
            6
            * (1 + poisson_ratio)
            * (1 + m * m) ** 2
            / ((7 + 6 * poisson_ratio) * (1 + m * m) ** 2 + (20 + 12 * poisson_ratio) * m * m)
        )
        return cls(
            axial=youngs_modulus * area,
            bending=youngs_modulus * second_moment,
            torsion=shear_modulus * 2 * second_moment,
            shear=kappa * shear_modulus * area,
            mass_per_length=density * area,
            rotary_inertia_per_length=density * second_moment,
            polar_inertia_per_length=density * 2 * second_moment,
        )


# The element coordinates of each bending plane, (w1, w1', w2, w2') = sign pattern x coordinates:
# x-z plane (x, ry; dx/dz = ry) and y-z plane (y, rx; dy/dz = -rx).
BENDING_PLANES = (((0, 4, 6, 10), 1.0), ((1, 3, 7, 9), -1.0))


def bending_stiffness(length: float, bending: float, shear: float) -> np.ndarray:
    """4 x 4 Timoshenko bending stiffness in one plane, coordinates (w1, w1', w2, w2') with
    bending stiffness EI and shear stiffness kappa G A (Przemieniecki 1968)."""
    L = length
    phi = 12 * bending / (shear * L * L)  # shear flexibility
    return (
        bending
        / ((1 + phi) * L**3)
        * np.array(
            [
                [12, 6 * L, -12, 6 * L],
                [6 * L, (4 + phi) * L * L, -6 * L, (2 - phi) * L * L],
                [-12, -6 * L, 12, -6 * L],
                [6 * L, (2 - phi) * L * L, -6 * L, (4 + phi) * L * L],
            ]
        )
    )


def timoshenko_beam(length: float, section: Section) -> tuple[np.ndarray, np.ndarray]:
    """12 x 12 stiffness and mass matrices of a Timoshenko beam element along z, coordinates
    (x, y, z, rx, ry, rz) of node 1 then node 2 (Przemieniecki 1968; consistent translational
    mass plus rotary inertia). Bending in the x-z plane pairs x with ry (dx/dz = ry), in the y-z
    plane y with -rx."""
    L = length
    kb = bending_stiffness(L, section.bending, section.shear)
    mt = (
        section.mass_per_length
        * L
        / 420
        * np.array(
            [
                [156, 22 * L, 54, -13 * L],
                [22 * L, 4 * L * L, 13 * L, -3 * L * L],
                [54, 13 * L, 156, -22 * L],
                [-13 * L, -3 * L * L, -22 * L, 4 * L * L],
            ]
        )
    )
    mr = (
        section.rotary_inertia_per_length
        / (30 * L)
        * np.array(
            [
                [36, 3 * L, -36, 3 * L],
                [3 * L, 4 * L * L, -3 * L, -L * L],
                [-36, -3 * L, 36, -3 * L],
                [3 * L, -L * L, -3 * L, 4 * L * L],
            ]
        )
    )
    stiffness, mass = np.zeros((12, 12)), np.zeros((12, 12))
    for dofs, sign in BENDING_PLANES:
        flip = np.diag([1.0, sign, 1.0, sign])
        stiffness[np.ix_(dofs, dofs)] += flip @ kb @ flip
        mass[np.ix_(dofs, dofs)] += flip @ (mt + mr) @ flip
    pair = np.array([[1.0, -1.0], [-1.0, 1.0]])
    consistent = np.array([[2.0, 1.0], [1.0, 2.0]]) / 6
    for dofs, k, m in (
        ((2, 8), section.axial / L, section.mass_per_length * L),
        ((5, 11), section.torsion / L, section.polar_inertia_per_length * L),
    ):
        stiffness[np.ix_(dofs, dofs)] += k * pair
        mass[np.ix_(dofs, dofs)] += m * consistent
    return stiffness, mass


class LinearStructure:
    """Nodes, masses, springs and beams assembled into M, K and C (see the module docstring)."""

    def __init__(self):
        self.positions: list[np.ndarray] = []
        self.offsets: list[int] = []
        self.sizes: list[int] = []
        self._mass: list[tuple] = []
        self._stiffness: list[tuple] = []
        self._damping: list[tuple] = []
        self.n = 0

    def add_node(self, position, rotations: bool = True) -> int:
        """A body reference point; 6 coordinates, or 3 for a point mass (rotations=False)."""
        self.positions.append(np.asarray(position, dtype=float))
        self.offsets.append(self.n)
        self.sizes.append(6 if rotations else 3)
        self.n += self.sizes[-1]
        return len(self.positions) - 1

    def dof(self, node: int, coordinate: int) -> int:
        """Global index of coordinate 0..5 (x, y, z, rx, ry, rz) of `node`."""
        if coordinate >= self.sizes[node]:
            raise ValueError(f"node {node} has no coordinate {coordinate}")
        return self.offsets[node] + coordinate

    def point_rows(self, node: int, point) -> np.ndarray:
        """3 x n matrix: displacement of `point` (global position, rigidly attached to `node`)."""
        rows = np.zeros((3, self.n))
        start = self.offsets[node]
        rows[:, start : start + 3] = np.eye(3)
        if self.sizes[node] == 6:
            rx, ry, rz = np.asarray(point, dtype=float) - self.positions[node]
            # theta x r = [ry_ rz - rz_ ry, rz_ rx - rx_ rz, rx_ ry - ry_ rx] with theta = (rx_, ry_, rz_)
            rows[:, start + 3 : start + 6] = np.array(
                [[0.0, rz, -ry], [-rz, 0.0, rx], [ry, -rx, 0.0]]
            )
        return rows

    def rotation_rows(self, node: int) -> np.ndarray:
        rows = np.zeros((3, self.n))
        rows[:, self.offsets[node] + 3 : self.offsets[node] + 6] = np.eye(3)
        return rows

    def add_rigid_mass(self, node: int, mass: float, center=None, inertia=(0.0, 0.0, 0.0)) -> None:
        """Mass `mass` at `center` (default: the node) with principal inertia (Ixx, Iyy, Izz)
        about its centre, rigidly attached to `node`."""
        center = self.positions[node] if center is None else center
        self._mass.append(("point", node, np.asarray(center, dtype=float), float(mass)))
        if any(inertia):
            if self.sizes[node] != 6:
                raise ValueError(f"node {node} has no rotations to carry an inertia")
            self._mass.append(("rotary", node, np.asarray(inertia, dtype=float)))

    def add_spring(self, a, b, stiffness, damping) -> None:
        """Spring-damper between attached points a = (node, point) and b (None: the base), with
        stiffness and damping per global axis (x, y, z)."""
        self._stiffness.append((a, b, np.asarray(stiffness, dtype=float)))
        self._damping.append((a, b, np.asarray(damping, dtype=float)))

    def add_coordinate_spring(
        self, node: int, coordinate: int, stiffness: float, damping: float
    ) -> None:
        """Spring-damper on one coordinate of `node` against the base."""
        self._stiffness.append(("coordinate", self.dof(node, coordinate), float(stiffness)))
        self._damping.append(("coordinate", self.dof(node, coordinate), float(damping)))

    def add_beam(
        self, node_a: int, node_b: int, section: Section, damping_ratio_per_hz: float = 0.0
    ) -> None:
        """Timoshenko beam between two 6-coordinate nodes on one line along z; stiffness-
        proportional damping C = damping_ratio_per_hz / pi * K (damping ratio x frequency in Hz)."""
        pa, pb = self.positions[node_a], self.positions[node_b]
        if (
            self.sizes[node_a] != 6
            or self.sizes[node_b] != 6
            or not np.allclose(pa[:2], pb[:2])
            or pb[2] <= pa[2]
        ):
            raise ValueError(f"beam {node_a}-{node_b}: nodes must have rotations and lie along +z")
        stiffness, mass = timoshenko_beam(float(pb[2] - pa[2]), section)
        dofs = [self.offsets[node_a] + i for i in range(6)] + [
            self.offsets[node_b] + i for i in range(6)
        ]
        self._stiffness.append(("block", dofs, stiffness))
        self._damping.append(("block", dofs, stiffness * damping_ratio_per_hz / math.pi))
        self._mass.append(("block", dofs, mass))

    # -- assembly ----------------------------------------------------------------------------
    def _rows(self, attachment) -> np.ndarray:
        node, point = attachment
        return self.point_rows(node, point)

    def _assemble(self, items) -> np.ndarray:
        matrix = np.zeros((self.n, self.n))
        for item in items:
            if item[0] == "coordinate":
                matrix[item[1], item[1]] += item[2]
            elif item[0] == "block":
                matrix[np.ix_(item[1], item[1])] += item[2]
            else:
                a, b, values = item
                rows = self._rows(a) - (self._rows(b) if b is not None else 0.0)
                matrix += rows.T @ np.diag(values) @ rows
        return matrix

    def mass_matrix(self) -> np.ndarray:
        matrix = np.zeros((self.n, self.n))
        for item in self._mass:
            if item[0] == "point":
                rows = self.point_rows(item[1], item[2])
                matrix += item[3] * rows.T @ rows
            elif item[0] == "rotary":
                rows = self.rotation_rows(item[1])
                matrix += rows.T @ np.diag(item[2]) @ rows
            else:
                matrix[np.ix_(item[1], item[1])] += item[2]
        return matrix

    def stiffness_matrix(self) -> np.ndarray:
        return self._assemble(self._stiffness)

    def damping_matrix(self) -> np.ndarray:
        return self._assemble(self._damping)

    def natural_frequencies(self) -> np.ndarray:
        """Undamped natural frequencies in Hz, ascending (rigid-body modes give ~0)."""
        from scipy.linalg import eigh

        values = eigh(self.stiffness_matrix(), self.mass_matrix(), eigvals_only=True)
        return np.sqrt(np.clip(values, 0.0, None)) / (2 * math.pi)

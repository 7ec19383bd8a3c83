"""Classical laminate theory (models/cfrp/laminate.py) and damaged tube sections
(models/gear/shaft_damage.py) against hand formulas, closed forms and independent numerical
integration."""

import math

import numpy as np
import pytest
from scipy.integrate import dblquad

from condmon.models.cfrp.laminate import (
    CFRP_STUDY_PLY,
    Laminate,
    Ply,
    laminate_tube_section,
    quasi_isotropic_modulus,
    quasi_isotropic_poisson_ratio,
    reduced_stiffness,
    transformed_reduced_stiffness,
)
from condmon.models.gear.shaft_damage import cracked_tube_geometry, delaminated_tube_geometry
from condmon.models.structure import Section

PLY = CFRP_STUDY_PLY
T_PLY = 0.125e-3  # a typical prepreg ply thickness, m


def q_entries(ply=PLY):
    """Q11, Q12, Q22, Q66 by hand: Q11 = E1 / (1 - nu12 nu21), nu21 = nu12 E2 / E1, ..."""
    nu21 = ply.nu12 * ply.E2 / ply.E1
    d = 1 - ply.nu12 * nu21
    return ply.E1 / d, ply.nu12 * ply.E2 / d, ply.E2 / d, ply.G12


def test_reduced_stiffness_by_hand():
    Q11, Q12, Q22, Q66 = q_entries()
    expected = np.array([[Q11, Q12, 0], [Q12, Q22, 0], [0, 0, Q66]])
    np.testing.assert_allclose(reduced_stiffness(PLY), expected, rtol=1e-12)


def test_transformation_matches_strain_transformation_and_swaps_axes_at_90():
    # independent route: ply strains eps_12 = T eps_xy (engineering shear), energy gives T^T Q T
    angle = 30.0
    m, n = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    T = np.array(
        [[m * m, n * n, m * n], [n * n, m * m, -m * n], [-2 * m * n, 2 * m * n, m * m - n * n]]
    )
    Q = reduced_stiffness(PLY)
    np.testing.assert_allclose(
        transformed_reduced_stiffness(PLY, angle), T.T @ Q @ T, rtol=1e-12, atol=1e-9 * Q[0, 0]
    )
    Q11, Q12, Q22, Q66 = q_entries()
    np.testing.assert_allclose(
        transformed_reduced_stiffness(PLY, 90.0),
        [[Q22, Q12, 0], [Q12, Q11, 0], [0, 0, Q66]],
        rtol=1e-12,
        atol=1e-6 * Q11,
    )


def test_single_ply_laminates_give_the_ply_constants():
    zero = Laminate(PLY, (0,), T_PLY)
    assert zero.axial_modulus == pytest.approx(138.945e9, rel=1e-12)
    assert zero.shear_modulus == pytest.approx(3.387e9, rel=1e-12)
    assert zero.poisson_ratio == pytest.approx(0.3, rel=1e-12)
    assert Laminate(PLY, (90,), T_PLY).axial_modulus == pytest.approx(6.6154e9, rel=1e-12)


def test_cross_ply_by_hand():
    Q11, Q12, Q22, Q66 = q_entries()
    laminate = Laminate(PLY, (0, 90, 90, 0), T_PLY)
    t = laminate.thickness
    # half the plies at 0 deg, half at 90 deg: A11 = A22 = t/2 (Q11 + Q22), A12 = t Q12, A66 = t Q66
    A11, A12, A66 = t / 2 * (Q11 + Q22), t * Q12, t * Q66
    A, B, _ = laminate.abd()
    np.testing.assert_allclose(
        A, [[A11, A12, 0], [A12, A11, 0], [0, 0, A66]], rtol=1e-12, atol=1e-9 * A11
    )
    # E_x = 1 / (t a11), a11 = A22 / (A11 A22 - A12^2)
    assert laminate.axial_modulus == pytest.approx((A11**2 - A12**2) / (A11 * t), rel=1e-12)
    assert laminate.shear_modulus == pytest.approx(Q66, rel=1e-12)
    assert laminate.poisson_ratio == pytest.approx(A12 / A11, rel=1e-12)
    assert np.abs(B).max() < 1e-9 * A11 * T_PLY


def test_angle_ply_by_hand():
    Q11, Q12, Q22, Q66 = q_entries()
    # Jones transformation at 45 deg (m^4 = n^4 = m^2 n^2 = 1/4):
    Qb11 = (Q11 + Q22 + 2 * Q12 + 4 * Q66) / 4  # = Qb22
    Qb12 = (Q11 + Q22 + 2 * Q12 - 4 * Q66) / 4
    Qb66 = (Q11 + Q22 - 2 * Q12) / 4
    Qb16 = (Q11 - Q22) / 4  # sign flips at -45 deg, so A16 cancels in a balanced laminate
    np.testing.assert_allclose(
        transformed_reduced_stiffness(PLY, 45.0),
        [[Qb11, Qb12, Qb16], [Qb12, Qb11, Qb16], [Qb16, Qb16, Qb66]],
        rtol=1e-12,
    )
    laminate = Laminate(PLY, (45, -45, -45, 45), T_PLY)
    A, B, _ = laminate.abd()
    assert abs(A[0, 2]) < 1e-9 * A[0, 0]
    # E_x = (A11 A22 - A12^2) / (A22 t) with A = t Qbar
    assert laminate.axial_modulus == pytest.approx((Qb11**2 - Qb12**2) / Qb11, rel=1e-12)
    assert laminate.shear_modulus == pytest.approx(Qb66, rel=1e-12)
    assert np.abs(B).max() < 1e-9 * A[0, 0] * T_PLY
    # and a far cry from the fibre modulus: +-45 plies are shear-dominated
    assert laminate.axial_modulus < 0.15 * PLY.E1


def test_unsymmetric_cross_ply_has_coupling():
    Q11, _, Q22, _ = q_entries()
    # 0 deg ply at z in (-t, 0), 90 deg ply at (0, t): B = 1/2 sum Qbar (z1^2 - z0^2)
    _, B, _ = Laminate(PLY, (0, 90), T_PLY).abd()
    expected = np.zeros((3, 3))
    expected[0, 0] = -(T_PLY**2) / 2 * (Q11 - Q22)
    expected[1, 1] = +(T_PLY**2) / 2 * (Q11 - Q22)
    np.testing.assert_allclose(B, expected, rtol=1e-12, atol=1e-9 * abs(expected[0, 0]))


def test_single_ply_bending_stiffness():
    _, _, D = Laminate(PLY, (0,), T_PLY).abd()
    np.testing.assert_allclose(D, reduced_stiffness(PLY) * T_PLY**3 / 12, rtol=1e-12)


def test_invalid_laminates_are_refused():
    with pytest.raises(ValueError, match="angles_deg"):
        Laminate(PLY, (), T_PLY)
    with pytest.raises(ValueError, match="ply_thickness"):
        Laminate(PLY, (0,), 0.0)
    with pytest.raises(ValueError, match="wall thickness"):
        laminate_tube_section(2e-3, Laminate(PLY, (0,) * 10, T_PLY))


def test_tube_section():
    laminate = Laminate(PLY, (0, 90, 90, 0), T_PLY)
    Do = 0.03
    Di = Do - 2 * 4 * T_PLY
    Q11, Q12, Q22, Q66 = q_entries()
    E_x = ((Q11 + Q22) ** 2 / 4 - Q12**2) / (
        (Q11 + Q22) / 2
    )  # cross-ply, as in test_cross_ply_by_hand
    area, second_moment = math.pi / 4 * (Do**2 - Di**2), math.pi / 64 * (Do**4 - Di**4)
    section = laminate_tube_section(Do, laminate)
    assert section.axial == pytest.approx(E_x * area, rel=1e-12)
    assert section.bending == pytest.approx(E_x * second_moment, rel=1e-12)
    assert section.torsion == pytest.approx(Q66 * 2 * second_moment, rel=1e-12)
    assert section.shear == pytest.approx(0.5 * Q66 * area, rel=1e-12)
    assert section.mass_per_length == pytest.approx(1560 * area, rel=1e-12)
    assert section.rotary_inertia_per_length == pytest.approx(1560 * second_moment, rel=1e-12)
    assert section.polar_inertia_per_length == pytest.approx(1560 * 2 * second_moment, rel=1e-12)


def test_isotropic_plies_reproduce_the_steel_tube():
    E, nu = 210e9, 0.3
    steel = Ply(E1=E, E2=E, G12=E / (2 * (1 + nu)), nu12=nu, density=7850, G1z=1.0, G2z=1.0)
    cfrp_like = laminate_tube_section(0.04, Laminate(steel, (0, 30, 77), 1e-3))
    tube = Section.tube(0.04, 0.034, E, nu, 7850)
    for name in (
        "axial",
        "bending",
        "torsion",
        "mass_per_length",
        "rotary_inertia_per_length",
        "polar_inertia_per_length",
    ):
        assert getattr(cfrp_like, name) == pytest.approx(getattr(tube, name), rel=1e-12), name


def test_quasi_isotropic_constants():
    Q11, Q12, Q22, Q66 = q_entries()
    # Tsai-Pagano invariants: a quasi-isotropic laminate has E = (U1^2 - U4^2) / U1, nu = U4 / U1
    U1 = (3 * Q11 + 3 * Q22 + 2 * Q12 + 4 * Q66) / 8
    U4 = (Q11 + Q22 + 6 * Q12 - 4 * Q66) / 8
    E, nu = quasi_isotropic_modulus(PLY), quasi_isotropic_poisson_ratio(PLY)
    assert E == pytest.approx((U1**2 - U4**2) / U1, rel=1e-12)
    assert nu == pytest.approx(U4 / U1, rel=1e-12)
    assert PLY.E2 < E < PLY.E1
    pi_over_3 = Laminate(PLY, (0, 60, -60, -60, 60, 0), T_PLY)
    assert pi_over_3.axial_modulus == pytest.approx(E, rel=1e-6)
    assert pi_over_3.poisson_ratio == pytest.approx(nu, rel=1e-6)
    assert pi_over_3.shear_modulus == pytest.approx(
        E / (2 * (1 + nu)), rel=1e-6
    )  # isotropic in-plane


def numerical_moments(radii, theta_range):
    """(area, centroid xi, I_xi about the centroid, I_eta) of the region radii[0] < rho < radii[-1],
    theta_range(rho)[0] < theta < theta_range(rho)[1] (theta from +xi), by adaptive quadrature in
    polar coordinates; `radii` also lists the radii where theta_range has a kink."""

    def integral(f):
        return sum(
            dblquad(
                lambda th, rho: f(rho * math.cos(th), rho * math.sin(th)) * rho,
                lo,
                hi,
                lambda rho: theta_range(rho)[0],
                lambda rho: theta_range(rho)[1],
                epsabs=1e-14,
                epsrel=1e-10,
            )[0]
            for lo, hi in zip(radii[:-1], radii[1:])
        )

    area = integral(lambda x, y: 1.0)
    centroid = integral(lambda x, y: x) / area
    return area, centroid, integral(lambda x, y: (x - centroid) ** 2), integral(lambda x, y: y * y)


def assert_geometry(geometry, expected, rel):
    area, centroid, i_xi, i_eta = expected
    assert geometry.area == pytest.approx(area, rel=rel)
    assert geometry.centroid_offset == pytest.approx(centroid, rel=rel, abs=rel * 1e-3)
    assert geometry.second_moment_xi == pytest.approx(i_xi, rel=rel)
    assert geometry.second_moment_eta == pytest.approx(i_eta, rel=rel)


DO, DI = 0.04, 0.03
R, r = DO / 2, DI / 2
ANNULUS = (
    math.pi * (R**2 - r**2),
    0.0,
    math.pi / 64 * (DO**4 - DI**4),
    math.pi / 64 * (DO**4 - DI**4),
)


def test_cracked_tube_intact_and_half():
    assert_geometry(cracked_tube_geometry(DO, DI, 0.0), ANNULUS, rel=1e-12)
    for outer, inner in ((R, r), (R, 0.0)):  # half annulus, half disc
        half_area = math.pi * (outer**2 - inner**2) / 2
        ybar = 4 * (outer**3 - inner**3) / (3 * math.pi * (outer**2 - inner**2))
        i_centre = math.pi / 8 * (outer**4 - inner**4)
        assert_geometry(
            cracked_tube_geometry(2 * outer, 2 * inner, 0.5),
            (half_area, -ybar, i_centre - half_area * ybar**2, i_centre),
            rel=1e-12,
        )


@pytest.mark.parametrize("depth", [0.1, 0.3, 0.8])  # front outside the bore, cutting it, past it
def test_cracked_tube_against_quadrature(depth):
    front = R - depth * DO

    def material(rho):  # at radius rho: xi = rho cos(theta) <= front
        start = math.acos(max(-1.0, min(1.0, front / rho)))
        return start, 2 * math.pi - start

    radii = (r, abs(front), R) if r < abs(front) < R else (r, R)
    assert_geometry(
        cracked_tube_geometry(DO, DI, depth), numerical_moments(radii, material), rel=1e-8
    )


def test_cracked_bending_stiffness_falls_with_depth():
    depths = np.linspace(0, 0.95, 40)
    geometries = [cracked_tube_geometry(DO, DI, d) for d in depths]
    assert np.all(np.diff([g.second_moment_xi for g in geometries]) < 0)
    assert np.all(np.diff([g.second_moment_eta for g in geometries]) <= 0)
    assert np.all(np.diff([g.area for g in geometries]) <= 0)


def test_delaminated_tube_closed_forms():
    assert_geometry(delaminated_tube_geometry(DO, DI, 0.5, 0.0), ANNULUS, rel=1e-12)
    assert_geometry(delaminated_tube_geometry(DO, DI, 0.0, 120.0), ANNULUS, rel=1e-12)
    # all the way round: the outer half of the wall is gone, an annulus of outer radius R - (R - r) / 2
    remaining = R - 0.5 * (R - r)
    i_ring = math.pi / 4 * (remaining**4 - r**4)
    assert_geometry(
        delaminated_tube_geometry(DO, DI, 0.5, 360.0),
        (math.pi * (remaining**2 - r**2), 0.0, i_ring, i_ring),
        rel=1e-12,
    )


def test_delaminated_tube_against_quadrature():
    interface_depth, arc = 0.4, math.radians(100.0)
    interface = R - interface_depth * (R - r)

    def material(rho):  # the outer sublaminate is missing for |theta| < arc / 2
        return (0.0, 2 * math.pi) if rho < interface else (arc / 2, 2 * math.pi - arc / 2)

    assert_geometry(
        delaminated_tube_geometry(DO, DI, interface_depth, 100.0),
        numerical_moments((r, interface, R), material),
        rel=1e-8,
    )


def test_delaminated_bending_stiffness_falls_with_arc():
    arcs = np.linspace(0, 360, 37)
    geometries = [delaminated_tube_geometry(DO, DI, 0.5, a) for a in arcs]
    assert np.all(np.diff([g.second_moment_xi for g in geometries]) < 0)
    assert np.all(np.diff([g.second_moment_eta for g in geometries]) < 0)


def test_damaged_geometry_refuses_out_of_range_inputs():
    with pytest.raises(ValueError, match="depth"):
        cracked_tube_geometry(DO, DI, 1.0)
    with pytest.raises(ValueError, match="depth"):
        cracked_tube_geometry(DO, DI, -0.1)
    with pytest.raises(ValueError, match="inner_diameter"):
        cracked_tube_geometry(DO, DO, 0.2)
    with pytest.raises(ValueError, match="interface_depth"):
        delaminated_tube_geometry(DO, DI, 1.0, 90.0)
    with pytest.raises(ValueError, match="arc_deg"):
        delaminated_tube_geometry(DO, DI, 0.5, 361.0)

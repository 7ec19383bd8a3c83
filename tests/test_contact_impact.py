"""Impact tests of the eight Table-1 contact laws: two bodies meet at speed v, F = K d^n + chi d^n d',
chi = f(c_r) K / v. Does each rebound with the restitution it is built for, and is c_r = 1 lossless?

The laws differ only in f(c_r). The rebound of any such law obeys f (1 + e) = ln((1 + f) / (1 - f e))
(`rebound_restitution`), whatever K, n, the masses and v: the integrations below check that
relation and the force implementation, and the per-law tests assert the accuracy each law's paper
states for its domain. References (the papers' own claims; not re-read here, see the report):
- Hunt & Crossley (1975), J. Appl. Mech. 42: c_r = 1 - alpha v, damping small: c_r near 1.
- Lankarani & Nikravesh (1990), J. Mech. Des. 112: energy balance assuming the dissipated energy is
  small against the maximum elastic energy: c_r close to 1.
- Herbert & McWhannell (1977), J. Eng. Ind. 99: c_r near 1.
- Flores, Machado, Silva & Martins (2011), Multibody Syst. Dyn. 25: the whole range, soft and hard
  contacts.
- Gonthier, McPhee, Lange & Piedboeuf (2004), Multibody Syst. Dyn. 11: an approximation over the
  whole range.
- Zhiying & Qishao (2006): Lankarani-Nikravesh extended to lower c_r.
- Gharib & Hurmuzlu (2012), J. Appl. Mech. 79: a model for LOW coefficients of restitution.
- Lee & Wang (1983), J. Mech. Transm. Autom. Des. 105: as tabulated (3 (1 - c_r) / 4, half of Hunt &
  Crossley's factor) it does not return c_r; asserted as what it does.
"""

import pytest
from scipy.integrate import solve_ivp

from condmon.models.gear.contact_laws import (
    CONTACT_LAWS,
    contact_force,
    hysteresis_factor,
    rebound_restitution,
)
from condmon.models.gear.drivetrain import GearDrivetrainParameters
from condmon.models.gear.mesh_force import MeshForce


def impact(
    law: str, restitution: float, exponent=1.5, stiffness=2.0e9, masses=(0.7, 1.9), speed=0.4
):
    """Two bodies on a line, body 1 at `speed` towards body 2 at rest: integrate through the
    contact and return (rebound restitution, kinetic energy after / before)."""
    m1, m2 = masses
    factor = hysteresis_factor(law, restitution)

    def rhs(t, y):
        x1, x2, v1, v2 = y
        f = contact_force(x1 - x2, v1 - v2, stiffness, exponent, factor, speed)
        return [v1, v2, -f / m1, f / m2]

    def separated(t, y):
        return y[0] - y[1] if t > 0 else 1.0

    separated.terminal, separated.direction = True, -1
    # Contact lasts about (m / K)^(1/(n+1)) v^(...)-ish: a generous end time and tight tolerances.
    t_end = 50.0 * (min(masses) / stiffness) ** 0.5 * (1 + (speed * 1e6) ** 0.25)
    sol = solve_ivp(
        rhs,
        (0.0, t_end),
        [0.0, 0.0, speed, 0.0],
        method="DOP853",
        events=separated,
        rtol=1e-11,
        atol=1e-15,
        max_step=t_end / 2000,
    )
    assert sol.status == 1, "the bodies did not separate"
    x1, x2, v1, v2 = sol.y[:, -1]
    e = (v2 - v1) / speed
    energy = (m1 * v1**2 + m2 * v2**2) / (m1 * speed**2)
    return e, energy


@pytest.mark.parametrize("law", CONTACT_LAWS)
def test_integrated_rebound_matches_the_closed_form(law):
    for restitution, exponent in ((0.8, 1.5), (0.6, 1.0), (0.95, 2.13)):
        e, energy = impact(law, restitution, exponent=exponent)
        assert e == pytest.approx(
            rebound_restitution(hysteresis_factor(law, restitution)), abs=2e-6
        )
        # Momentum is conserved, so the energy left is that of the rebound: 1 - (1 - e^2) m2 / (m1 + m2).
        assert energy == pytest.approx(1 - (1 - e**2) * 1.9 / 2.6, abs=1e-5)


@pytest.mark.parametrize("law", [law for law in CONTACT_LAWS if law != "gharib_hurmuzlu"])
def test_no_energy_is_dissipated_at_restitution_one(law):
    e, energy = impact(law, 1.0, speed=1.3)
    assert e == pytest.approx(1.0, abs=1e-7)
    assert energy == pytest.approx(1.0, abs=1e-7)


def test_gharib_hurmuzlu_as_tabulated_is_a_low_restitution_law():
    # Table 1 of both studies: chi = (1 / c_r) K / v. Accurate for low c_r (its paper's domain) ...
    for restitution in (0.05, 0.1, 0.2, 0.3):
        assert rebound_restitution(
            hysteresis_factor("gharib_hurmuzlu", restitution)
        ) == pytest.approx(restitution, rel=0.07)
    # ... but not lossless at c_r = 1: it rebounds at about 0.59 there (reported as a concern).
    e, energy = impact("gharib_hurmuzlu", 1.0)
    assert e == pytest.approx(0.5936, abs=1e-3) and energy < 0.8


@pytest.mark.parametrize("law", ["hunt_crossley", "lankarani_nikravesh", "herbert_mcwhannel"])
def test_laws_built_for_restitution_near_one(law):
    for restitution in (0.9, 0.95, 0.99):
        e = rebound_restitution(hysteresis_factor(law, restitution))
        assert abs(e - restitution) <= 0.15 * (1 - restitution), (restitution, e)
    # ... and only there: at c_r = 0.5 they rebound far too fast.
    assert rebound_restitution(hysteresis_factor(law, 0.5)) > 0.55


@pytest.mark.parametrize("law", ["flores", "zhiying_qishao"])
def test_laws_built_for_the_whole_range(law):
    for restitution in (0.3, 0.5, 0.7, 0.9, 0.95, 0.99):
        e = rebound_restitution(hysteresis_factor(law, restitution))
        assert abs(e - restitution) <= 0.1 * (1 - restitution), (restitution, e)


def test_gonthier_approximates_the_whole_range():
    for restitution in (0.1, 0.3, 0.5, 0.7, 0.9, 0.95, 0.99):
        e = rebound_restitution(hysteresis_factor("gonthier", restitution))
        assert abs(e - restitution) <= 0.035, (restitution, e)


def test_lee_wang_as_tabulated_dissipates_half_of_hunt_crossley():
    # First order in 1 - c_r the rebound is (1 + c_r) / 2, not c_r.
    for restitution in (0.9, 0.95, 0.99):
        e = rebound_restitution(hysteresis_factor("lee_wang", restitution))
        assert e == pytest.approx((1 + restitution) / 2, abs=0.05 * (1 - restitution))


@pytest.mark.parametrize(
    "law, restitution",
    [("lankarani_nikravesh", 0.9), ("flores", 0.7), ("hunt_crossley", 1.0), ("gonthier", 0.95)],
)
def test_gear_mesh_force_rebounds_with_the_law(law, restitution):
    """Algorithm 1 in the drivetrain: the tooth pairs in contact (potential-energy TVMS, frozen mesh
    phase) hit together at 0.3 m/s along the line of action and rebound with the law's restitution:
    delta_dot(-) of every pair is the impact speed."""
    p = GearDrivetrainParameters(
        contact_law=law, restitution=restitution, transmission_error=0.0, speed_rpm=600.0
    )
    mesh = MeshForce(p)
    t0 = 1.37 / mesh.mesh_frequency  # 2 or 3 pairs in contact
    mass, speed = 0.5, 0.3

    def rhs(t, y):
        return [y[1], -mesh(t0, y[0], y[1]) / mass]

    def separated(t, y):
        return y[0] if t > 1e-7 else 1.0

    separated.terminal, separated.direction = True, -1
    sol = solve_ivp(
        rhs,
        (0.0, 1e-3),
        [0.0, speed],
        method="DOP853",
        events=separated,
        rtol=1e-10,
        atol=1e-16,
        max_step=2e-7,
    )
    assert sol.status == 1
    e = -sol.y[1, -1] / speed
    assert e == pytest.approx(rebound_restitution(hysteresis_factor(law, restitution)), abs=1e-4)
    assert len(mesh.impacts) == 0  # every contact ended
    if restitution == 1.0:
        assert e == pytest.approx(1.0, abs=1e-6)

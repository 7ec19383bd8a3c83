"""Hysteresis-damping contact laws F = K delta^n + chi delta^n delta_dot (Table 1 of the studies).

Every law gives chi = factor(c_r) * K / delta_dot_minus, where c_r is the coefficient of
restitution and delta_dot_minus the indentation velocity at the start of contact. The laws only
differ in factor(c_r), so this module stores that dimensionless factor per law.

References (as cited by the CFRP and helical-gear studies):
Gharib & Hurmuzlu (2012), Herbert & McWhannell (1977), Flores et al. (2011), Lee & Wang (1983),
Hunt & Crossley (1975), Lankarani & Nikravesh (1990), Zhiying & Qishao (2006), Gonthier et al. (2004).
"""

from __future__ import annotations

import math

HYSTERESIS_FACTORS = {
    "gharib_hurmuzlu": lambda cr: 1.0 / cr,
    "herbert_mcwhannel": lambda cr: 6.0 * (1.0 - cr) / ((2.0 * cr - 1.0) ** 2 + 3.0),
    "flores": lambda cr: 8.0 * (1.0 - cr) / (5.0 * cr),
    "lee_wang": lambda cr: 3.0 * (1.0 - cr) / 4.0,
    "hunt_crossley": lambda cr: 3.0 * (1.0 - cr) / 2.0,
    "lankarani_nikravesh": lambda cr: 3.0 * (1.0 - cr**2) / 4.0,
    "zhiying_qishao": lambda cr: 3.0 * (1.0 - cr**2) * math.exp(2.0 * (1.0 - cr)) / 4.0,
    "gonthier": lambda cr: (1.0 - cr**2) / cr,
}
CONTACT_LAWS = tuple(HYSTERESIS_FACTORS)


def hysteresis_factor(law: str, restitution: float) -> float:
    """Dimensionless factor f with chi = f * K / delta_dot_minus for the named law."""
    if law not in HYSTERESIS_FACTORS:
        raise ValueError(f"unknown contact law {law!r}; choose one of {list(CONTACT_LAWS)}")
    if not 0.0 < restitution <= 1.0:
        raise ValueError(f"coefficient of restitution must be in (0, 1], got {restitution}")
    return HYSTERESIS_FACTORS[law](restitution)


def rebound_restitution(factor: float) -> float:
    """Restitution a law of damping factor f = chi delta_dot(-) / K actually gives.

    For a free impact m delta'' = -K delta^n (1 + f delta'/v), m w dw/(1 + f w/v) = -K delta^n d delta
    integrates over the closed contact to f (1 + e) = ln((1 + f) / (1 - f e)) for the rebound
    e = -delta'_end / v: independent of K, n, the mass and the impact speed, so each law's e(c_r)
    is a property of its factor alone (1 - f e > 0: the force never needs clamping before
    separation). Solved for L = ln(1 - f e) in L - exp(L) = ln(1 + f) - f - 1, robust for any f >= 0."""
    if factor < 0.0:
        raise ValueError(f"damping factor must be >= 0, got {factor}")
    if factor == 0.0:
        return 1.0
    from scipy.optimize import brentq

    right = math.log1p(factor) - factor - 1.0
    log_y = brentq(lambda L: L - math.exp(L) - right, right - 1.0, 0.0, xtol=1e-15)
    return -math.expm1(log_y) / factor


def contact_force(
    deflection, deflection_rate, stiffness, exponent, damping_factor, approach_velocity
):
    """Compressive contact force K d^n (1 + f d_dot / v-), zero when apart and never pulling."""
    if deflection <= 0.0:
        return 0.0
    force = (
        stiffness
        * deflection**exponent
        * (1.0 + damping_factor * deflection_rate / approach_velocity)
    )
    return force if force > 0.0 else 0.0

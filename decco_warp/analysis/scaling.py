"""The Leinhardt & Stewart (2012) universal law for the largest remnant, to compare runs with.

LS12 (ApJ 745, 79) describe the mass of the largest remnant of a collision between
gravity-dominated bodies by one line in the specific impact energy
Q_R = 1/2 mu V^2 / M_tot (mu the reduced mass, V the impact speed), scaled by the
catastrophic disruption criterion Q'*_RD of the collision (the Q_R that leaves half of M_tot
in the largest remnant):

    M_lr / M_tot = 1 - 1/2 Q_R / Q'*_RD                          for Q_R < 1.8 Q'*_RD
    M_lr / M_tot = 0.1 / 1.8^-1.5 (Q_R / Q'*_RD)^-1.5            beyond (super-catastrophic)

with, for equal masses, Q*_RD,1 = c* 4/5 pi rho1 G R_C1^2 (R_C1 the radius of M_tot at
rho1 = 1 g/cm^3), for projectile-to-target mass ratio gamma
Q*_RD = Q*_RD,1 ((gamma + 1)^2 / (4 gamma))^(2 / (3 mu_bar) - 1), and for an oblique impact
Q'*_RD = Q*_RD (mu / mu_alpha)^(2 - 3 mu_bar / 2), mu_alpha the reduced mass of the target and
the interacting fraction alpha of the projectile.  The small-body values are c* = 1.9 and
mu_bar = 0.36 (their rubble-pile simulations).  The law describes disruption; for grazing
impacts that end in hit-and-run it does not apply, and at low energy it tends to a perfect merger.
"""

from __future__ import annotations

import math

from ..params import G_CGS

#: LS12 small-body fit: c* and mu_bar.
C_STAR = 1.9
MU_BAR = 0.36
#: LS12's reference density [g/cm^3].
RHO_1 = 1.0


def interacting_fraction(target_radius: float, projectile_radius: float, theta_deg: float) -> float:
    """alpha: the fraction of the projectile's mass that overlaps the target along its path (LS12)."""
    length = (target_radius + projectile_radius) * (1.0 - math.sin(math.radians(theta_deg)))
    if length >= 2.0 * projectile_radius:
        return 1.0
    return (3.0 * projectile_radius * length**2 - length**3) / (4.0 * projectile_radius**3)


def disruption_energy(target_mass: float, projectile_mass: float, target_radius: float, projectile_radius: float,
                      theta_deg: float, G: float = G_CGS) -> float:  # fmt: skip
    """Q'*_RD [erg/g]: the specific impact energy that disperses half the total mass (LS12, small bodies)."""
    total = target_mass + projectile_mass
    gamma = projectile_mass / target_mass
    reduced = target_mass * projectile_mass / total
    alpha = interacting_fraction(target_radius, projectile_radius, theta_deg)
    reduced_alpha = alpha * projectile_mass * target_mass / (alpha * projectile_mass + target_mass)
    radius_c1 = (3.0 * total / (4.0 * math.pi * RHO_1)) ** (1.0 / 3.0)
    equal_mass = C_STAR * 0.8 * math.pi * RHO_1 * G * radius_c1**2
    unequal = equal_mass * ((gamma + 1.0) ** 2 / (4.0 * gamma)) ** (2.0 / (3.0 * MU_BAR) - 1.0)
    return unequal * (reduced / reduced_alpha) ** (2.0 - 1.5 * MU_BAR)


def largest_remnant_fraction(specific_energy: float, disruption: float) -> float:
    """M_lr / M_tot from Q_R / Q'*_RD by the universal law."""
    ratio = specific_energy / disruption
    if ratio < 1.8:
        return 1.0 - 0.5 * ratio
    return 0.1 / 1.8**-1.5 * ratio**-1.5


def largest_mass_ratio(collision: dict, G: float = G_CGS) -> float:
    """m_lf / m_t that the LS12 law gives for a run's collision set-up (its recorded metadata:
    target and projectile mass and radius, theta_deg, kinetic_energy in the centre-of-mass frame)."""
    m_t, m_p = collision["target_mass"], collision["projectile_mass"]
    specific_energy = collision["kinetic_energy"] / (m_t + m_p)
    disruption = disruption_energy(m_t, m_p, collision["target_radius"], collision["projectile_radius"], collision["theta_deg"], G)
    return largest_remnant_fraction(specific_energy, disruption) * (m_t + m_p) / m_t

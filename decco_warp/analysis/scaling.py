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
the interacting fraction alpha of the projectile.

LS12 fit two sets of constants (docs/model.md): c* = 5 +- 2 with mu_bar = 0.37 for small,
strengthless bodies (their pkdgrav rubble piles: the kind of body simulated here, and the
reference of every comparison), and c* = 1.9 +- 0.3 with mu_bar = 0.36 for planets (their
hydrocode bodies).  The law describes disruption; for grazing impacts that end in hit-and-run
it does not apply, and at low energy it tends to a perfect merger.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..params import G_CGS


@dataclass(frozen=True)
class Law:
    """One fit of the universal law: its constants and what it describes."""

    name: str
    c_star: float
    """Dimensionless dissipation constant of Q*_RD,1."""
    mu_bar: float
    """Velocity exponent of the coupling parameter."""
    c_star_range: tuple[float, float]
    """c* within the fit's quoted uncertainty (the band drawn around the law)."""


#: LS12's fit for small, strengthless bodies (rubble piles): the reference here.
SMALL_BODIES = Law("small bodies", 5.0, 0.37, (3.0, 7.0))
#: LS12's fit for planet-sized (hydrocode) bodies, for comparison only.
PLANETS = Law("planets", 1.9, 0.36, (1.6, 2.2))
#: LS12's reference density [g/cm^3].
RHO_1 = 1.0


def interacting_fraction(target_radius: float, projectile_radius: float, theta_deg: float) -> float:
    """alpha: the fraction of the projectile's mass that overlaps the target along its path (LS12)."""
    length = (target_radius + projectile_radius) * (1.0 - math.sin(math.radians(theta_deg)))
    if length >= 2.0 * projectile_radius:
        return 1.0
    return (3.0 * projectile_radius * length**2 - length**3) / (4.0 * projectile_radius**3)


def equal_mass_threshold(total_mass: float, c_star: float, G: float = G_CGS) -> float:
    """LS12's Q*_RD,1 = c* 4/5 pi rho1 G R_C1^2 [erg/g], R_C1 the radius of ``total_mass`` at rho1."""
    radius_c1 = (3.0 * total_mass / (4.0 * math.pi * RHO_1)) ** (1.0 / 3.0)
    return c_star * 0.8 * math.pi * RHO_1 * G * radius_c1**2


def mass_ratio_factor(mass_ratio: float) -> float:
    """(gamma + 1)^2 / (4 gamma): Q*_RD / Q*_RD,1 is this to the power 2 / (3 mu_bar) - 1 (LS12)."""
    return (mass_ratio + 1.0) ** 2 / (4.0 * mass_ratio)


def disruption_energy(target_mass: float, projectile_mass: float, target_radius: float, projectile_radius: float,
                      theta_deg: float, G: float = G_CGS, law: Law = SMALL_BODIES,
                      c_star: float | None = None) -> float:  # fmt: skip
    """Q'*_RD [erg/g]: the specific impact energy that disperses half the total mass (LS12), by
    ``law`` (``c_star`` replaces its c*, e.g. an end of its band)."""
    c_star = law.c_star if c_star is None else c_star
    total = target_mass + projectile_mass
    gamma = projectile_mass / target_mass
    reduced = target_mass * projectile_mass / total
    alpha = interacting_fraction(target_radius, projectile_radius, theta_deg)
    reduced_alpha = alpha * projectile_mass * target_mass / (alpha * projectile_mass + target_mass)
    unequal = equal_mass_threshold(total, c_star, G) * mass_ratio_factor(gamma) ** (2.0 / (3.0 * law.mu_bar) - 1.0)
    return unequal * (reduced / reduced_alpha) ** (2.0 - 1.5 * law.mu_bar)


def largest_remnant_fraction(specific_energy: float, disruption: float) -> float:
    """M_lr / M_tot from Q_R / Q'*_RD by the universal law."""
    ratio = specific_energy / disruption
    if ratio < 1.8:
        return 1.0 - 0.5 * ratio
    return 0.1 / 1.8**-1.5 * ratio**-1.5


def largest_mass_ratio(collision: dict, G: float = G_CGS, law: Law = SMALL_BODIES, c_star: float | None = None) -> float:
    """m_lf / m_t that the LS12 law (``law``, c* replaced by ``c_star`` if given) gives for a run's
    collision set-up (its recorded metadata: target and projectile mass and radius, theta_deg,
    kinetic_energy in the centre-of-mass frame)."""
    m_t, m_p = collision["target_mass"], collision["projectile_mass"]
    specific_energy = collision["kinetic_energy"] / (m_t + m_p)
    disruption = disruption_energy(
        m_t, m_p, collision["target_radius"], collision["projectile_radius"], collision["theta_deg"], G, law, c_star
    )
    return largest_remnant_fraction(specific_energy, disruption) * (m_t + m_p) / m_t


#: The summary columns of the law at a run's set-up: (column, law, c*).  The band's low end is the
#: weaker body (smaller c*: it disrupts at lower energy), so it gives the smaller remnant.
LAW_COLUMNS = (
    ("ls12_largest_mass_ratio", SMALL_BODIES, None),
    ("ls12_band_low", SMALL_BODIES, SMALL_BODIES.c_star_range[0]),
    ("ls12_band_high", SMALL_BODIES, SMALL_BODIES.c_star_range[1]),
    ("ls12_planets_largest_mass_ratio", PLANETS, None),
)


#: What a collision record must hold for the law's columns.
LAW_NEEDS = ("target_mass", "projectile_mass", "target_radius", "projectile_radius", "theta_deg", "kinetic_energy")


def law_columns(collision: dict, G: float = G_CGS) -> dict:
    """The LAW_COLUMNS for a run's collision record (None each without its metadata)."""
    if not all(key in collision for key in LAW_NEEDS):
        return {column: None for column, _, _ in LAW_COLUMNS}
    return {column: float(largest_mass_ratio(collision, G, law, c_star)) for column, law, c_star in LAW_COLUMNS}


def mutual_escape_speed(total_mass: float, target_radius: float, projectile_radius: float, G: float = G_CGS) -> float:
    """v_esc = sqrt(2 G M_tot / (R_t + R_p)) [cm/s]: the two bodies' escape speed at touching (LS12's
    v_esc, by which impact speeds are measured)."""
    return math.sqrt(2.0 * G * total_mass / (target_radius + projectile_radius))


#: The impact's own columns (:func:`impact_columns`), by a pkdgrav or REBOUND user's yardsticks.
IMPACT_COLUMNS = ("speed_over_escape", "q_r", "q_rd_star", "q_r_over_q_rd_star")


def impact_columns(collision: dict, G: float = G_CGS) -> dict:
    """A collision in LS12's terms: ``speed_over_escape`` (the relative speed at set-up over
    :func:`mutual_escape_speed`), ``q_r`` (Q_R = KE / M_tot, the specific impact energy in the
    centre-of-mass frame [erg/g]), ``q_rd_star`` (Q'*_RD of the small-body law at the collision's
    mass ratio and angle [erg/g]) and their ratio ``q_r_over_q_rd_star`` (1: half the mass stays in
    the largest remnant by the law).  None each without the record's metadata."""
    if not all(key in collision for key in (*LAW_NEEDS, "speed")):
        return dict.fromkeys(IMPACT_COLUMNS)
    m_t, m_p = collision["target_mass"], collision["projectile_mass"]
    r_t, r_p = collision["target_radius"], collision["projectile_radius"]
    specific = collision["kinetic_energy"] / (m_t + m_p)
    q_star = disruption_energy(m_t, m_p, r_t, r_p, collision["theta_deg"], G)
    gravitating = G > 0  # without gravity there is no escape speed, and Q*_RD is 0
    speed = float(collision["speed"] / mutual_escape_speed(m_t + m_p, r_t, r_p, G)) if gravitating else None
    return {"speed_over_escape": speed, "q_r": float(specific), "q_rd_star": float(q_star) if gravitating else None,
            "q_r_over_q_rd_star": float(specific / q_star) if gravitating else None}  # fmt: skip

"""The Leinhardt & Stewart (2012) universal law, checked by hand at points where it is simple."""

import math

import pytest

from decco_warp.analysis import scaling
from decco_warp.params import G_CGS


def test_interacting_fraction():
    assert scaling.interacting_fraction(2e7, 1e7, 0.0) == 1.0  # head-on: the whole projectile
    # Grazing so that the projectile's path overlaps the target by half its diameter: l = R_p.
    theta = math.degrees(math.asin(1 - 1e7 / 3e7))
    assert scaling.interacting_fraction(2e7, 1e7, theta) == pytest.approx((3 - 1) / 4, rel=1e-12)
    assert scaling.interacting_fraction(2e7, 1e7, 89.999999) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("law, c_star, mu_bar", [(scaling.SMALL_BODIES, 5.0, 0.37), (scaling.PLANETS, 1.9, 0.36)])
def test_equal_mass_head_on_disruption_energy_is_the_principal_curve(law, c_star, mu_bar):
    """LS12's two fits (physics.md): small bodies c* = 5, mu_bar = 0.37 (the default), planets 1.9, 0.36."""
    mass = 6e22
    radius_c1 = (3 * 2 * mass / (4 * math.pi * 1.0)) ** (1 / 3)
    expected = c_star * 0.8 * math.pi * 1.0 * G_CGS * radius_c1**2
    assert scaling.disruption_energy(mass, mass, 2e7, 2e7, 0.0, law=law) == pytest.approx(expected, rel=1e-12)
    if law is scaling.SMALL_BODIES:
        assert scaling.disruption_energy(mass, mass, 2e7, 2e7, 0.0) == pytest.approx(expected, rel=1e-12)
    # A smaller projectile needs more specific energy: ((1 + g)^2 / 4g)^(2/(3 mu) - 1).
    quarter = scaling.disruption_energy(mass, mass / 4, 2e7, 1.3e7, 0.0, law=law)
    radius_c1 = (3 * 1.25 * mass / (4 * math.pi)) ** (1 / 3)
    principal = c_star * 0.8 * math.pi * G_CGS * radius_c1**2
    assert quarter == pytest.approx(principal * (1.25**2 / 1.0) ** (2 / (3 * mu_bar) - 1), rel=1e-12)


def test_the_small_body_band_brackets_the_law_and_the_planets_fit_lies_below():
    """c* = 3 (weaker) gives a smaller remnant than c* = 5, c* = 7 a larger one; the planets' c* = 1.9
    gives a smaller remnant still.  A collision past the criterion, where all four differ."""
    collision = {"target_mass": 6e22, "projectile_mass": 1.5e22, "target_radius": 2.03e7, "projectile_radius": 1.29e7, "theta_deg": 0.0}
    collision["kinetic_energy"] = 1.2 * scaling.disruption_energy(6e22, 1.5e22, 2.03e7, 1.29e7, 0.0) * 7.5e22
    columns = scaling.law_columns(collision)
    assert columns["ls12_largest_mass_ratio"] == pytest.approx((1 - 0.6) * 7.5 / 6, rel=1e-12)
    assert columns["ls12_planets_largest_mass_ratio"] < columns["ls12_band_low"] < columns["ls12_largest_mass_ratio"] < columns["ls12_band_high"]
    assert scaling.law_columns({"theta_deg": 0.0}) == dict.fromkeys(columns)


def test_universal_law_half_mass_at_the_criterion_and_continuous_at_1_8():
    assert scaling.largest_remnant_fraction(1.0, 1.0) == pytest.approx(0.5)
    assert scaling.largest_remnant_fraction(0.0, 1.0) == 1.0
    below, above = scaling.largest_remnant_fraction(1.8 - 1e-9, 1.0), scaling.largest_remnant_fraction(1.8, 1.0)
    assert below == pytest.approx(0.1, rel=1e-8) and above == pytest.approx(0.1, rel=1e-12)
    assert scaling.largest_remnant_fraction(3.6, 1.0) == pytest.approx(0.1 * 2**-1.5, rel=1e-12)


def test_largest_mass_ratio_from_a_collision_record():
    collision = {"target_mass": 6e22, "projectile_mass": 1.5e22, "target_radius": 2.03e7, "projectile_radius": 1.29e7, "theta_deg": 0.0}
    q_star = scaling.disruption_energy(6e22, 1.5e22, 2.03e7, 1.29e7, 0.0)
    collision["kinetic_energy"] = q_star * 7.5e22  # Q_R = Q*: half the total mass stays
    assert scaling.largest_mass_ratio(collision) == pytest.approx(0.5 * 7.5e22 / 6e22, rel=1e-12)


def test_the_impact_in_ls12_terms_from_a_collision_record():
    """Equal masses head-on at twice the mutual escape speed: Q_R = 1/2 (M/4) V^2 / M, and against
    Q*_RD,1 by hand; without gravity there is no escape speed nor Q*_RD; without the record, None."""
    mass, radius = 6e22, 2e7
    escape = math.sqrt(2 * G_CGS * 2 * mass / (2 * radius))
    speed = 2 * escape
    collision = {"target_mass": mass, "projectile_mass": mass, "target_radius": radius, "projectile_radius": radius,
                 "theta_deg": 0.0, "speed": speed, "kinetic_energy": 0.5 * (mass / 2) * speed**2}  # fmt: skip
    columns = scaling.impact_columns(collision)
    q_r = 0.5 * (mass / 2) * speed**2 / (2 * mass)
    q_star = 5.0 * 0.8 * math.pi * G_CGS * (3 * 2 * mass / (4 * math.pi)) ** (2 / 3)
    assert columns["speed_over_escape"] == pytest.approx(2.0, rel=1e-12) and columns["q_r"] == pytest.approx(q_r, rel=1e-12)
    assert columns["q_rd_star"] == pytest.approx(q_star, rel=1e-12) and columns["q_r_over_q_rd_star"] == pytest.approx(q_r / q_star, rel=1e-12)
    assert scaling.impact_columns(collision, G=0.0) == {"speed_over_escape": None, "q_r": pytest.approx(q_r), "q_rd_star": None, "q_r_over_q_rd_star": None}
    assert scaling.impact_columns({"theta_deg": 0.0}) == dict.fromkeys(scaling.IMPACT_COLUMNS)

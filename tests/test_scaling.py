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


def test_equal_mass_head_on_disruption_energy_is_the_principal_curve():
    mass = 6e22
    radius_c1 = (3 * 2 * mass / (4 * math.pi * 1.0)) ** (1 / 3)
    expected = 1.9 * 0.8 * math.pi * 1.0 * G_CGS * radius_c1**2
    assert scaling.disruption_energy(mass, mass, 2e7, 2e7, 0.0) == pytest.approx(expected, rel=1e-12)
    # A smaller projectile needs more specific energy: ((1 + g)^2 / 4g)^(2/(3 mu) - 1).
    quarter = scaling.disruption_energy(mass, mass / 4, 2e7, 1.3e7, 0.0)
    radius_c1 = (3 * 1.25 * mass / (4 * math.pi)) ** (1 / 3)
    principal = 1.9 * 0.8 * math.pi * G_CGS * radius_c1**2
    assert quarter == pytest.approx(principal * (1.25**2 / 1.0) ** (2 / (3 * 0.36) - 1), rel=1e-12)


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

"""Collision set-up: eta, impact parameter, gap, spin, centre-of-mass frame (docs/model.md)."""

import math

import numpy as np
import pytest
from oracle import energies

import decco_warp as dw
from decco_warp.collision import breakup_spin, pile_radius
from decco_warp.run import builtin_pile

#: Set-up quantities match the request to this relative precision.
SETUP_TOLERANCE = 1e-9


@pytest.fixture(scope="module")
def piles():
    return dw.load_pile(builtin_pile("target")), dw.load_pile(builtin_pile("projectile"))


def _self_potential(state):
    _, _, potential, _ = energies(
        state.positions, state.velocities, state.omegas, state.radii, state.masses, 1e18, 0.9, dw.G_CGS
    )
    return potential


def _pile(state, k):
    return state.subset(state.pile_id == k)


@pytest.mark.parametrize("theta", [0.0, 22.0, 44.0])
def test_eta_impact_parameter_and_gap(piles, theta):
    target, projectile = piles
    s = dw.setup_collision(target, projectile, eta=2.0, theta_deg=theta, gap=1e5)
    t, p = _pile(s, 0), _pile(s, 1)
    assert t.n == target.n and p.n == projectile.n
    # Centre-of-mass frame, centre at the origin.
    assert np.linalg.norm(s.bulk_velocity) <= 1e-12 * np.linalg.norm(p.bulk_velocity)
    assert np.linalg.norm(s.centre_of_mass) <= 1e-9 * pile_radius(t)
    # eta = KE of the piles' centres / |U_t + U_p|, both computed here independently.
    kinetic = 0.5 * t.total_mass * t.bulk_velocity @ t.bulk_velocity + 0.5 * p.total_mass * p.bulk_velocity @ p.bulk_velocity
    eta = kinetic / abs(_self_potential(t) + _self_potential(p))
    assert eta == pytest.approx(2.0, rel=SETUP_TOLERANCE)
    # Relative velocity along +x only, projectile moving towards the target.
    relative = p.bulk_velocity - t.bulk_velocity
    assert relative[0] > 0 and np.allclose(relative[1:], 0, atol=1e-12 * relative[0])
    offset = p.centre_of_mass - t.centre_of_mass
    r_sum = pile_radius(t) + pile_radius(p)
    assert offset[1] == pytest.approx(r_sum * math.sin(math.radians(theta)), rel=SETUP_TOLERANCE, abs=1e-6)
    assert -offset[0] == pytest.approx(r_sum * math.cos(math.radians(theta)) + 1e5, rel=SETUP_TOLERANCE)
    assert offset[2] == pytest.approx(0.0, abs=1e-6)
    meta = s.metadata
    assert meta["eta"] == pytest.approx(2.0, rel=1e-12)
    total_potential = _self_potential(s)
    assert meta["target_potential"] + meta["projectile_potential"] + meta["cross_potential"] == pytest.approx(
        total_potential, rel=1e-9
    )
    assert meta["cross_potential"] < 0


def test_explicit_speed(piles):
    s = dw.setup_collision(*piles, speed=2.5e4, theta_deg=0.0)
    relative = _pile(s, 1).bulk_velocity - _pile(s, 0).bulk_velocity
    assert relative[0] == pytest.approx(2.5e4, rel=SETUP_TOLERANCE)


@pytest.mark.parametrize("axis, vector", [("+z", (0, 0, 1)), ("-x", (-1, 0, 0)), ("+y", (0, 1, 0))])
def test_spin_is_the_requested_fraction_of_breakup(piles, axis, vector):
    target, projectile = piles
    s = dw.setup_collision(target, projectile, eta=1.0, target_spin=None, projectile_spin=(0.5, axis))
    p = _pile(s, 1)
    expected = 0.5 * math.sqrt(dw.G_CGS * projectile.total_mass / pile_radius(projectile) ** 3) * np.array(vector)
    assert breakup_spin(projectile) == pytest.approx(np.linalg.norm(expected) / 0.5, rel=1e-12)
    np.testing.assert_allclose(p.omegas, np.broadcast_to(expected, p.omegas.shape), rtol=SETUP_TOLERANCE, atol=0)
    # Velocities about the pile's centre are the rigid rotation plus the pile's own (settled) motion.
    r = p.positions - p.centre_of_mass
    internal = p.velocities - p.bulk_velocity - np.cross(expected, r)
    own = projectile.velocities - projectile.bulk_velocity
    np.testing.assert_allclose(internal, own, rtol=0, atol=SETUP_TOLERANCE * np.linalg.norm(expected) * pile_radius(projectile))
    assert np.all(_pile(s, 0).omegas == target.omegas)


def test_bad_setups_are_refused(piles):
    target, projectile = piles
    for kwargs, match in [
        (dict(eta=-1.0), "eta must be > 0"),
        (dict(eta=1.0, speed=1e4), "exactly one of eta"),
        (dict(eta=1.0, theta_deg=90.0), r"theta_deg must be in \[0, 90\)"),
        (dict(eta=1.0, gap=-5.0), "gap must be >= 0"),
        (dict(eta=1.0, projectile_spin=(2.0, "+z")), r"fraction of breakup must be in \[0, 1\]"),
        (dict(eta=1.0, projectile_spin=(0.5, "up")), "axis must be one of"),
        (dict(eta=1.0, projectile_spin=(0.5, (0, 0, 0))), "not all zero"),
        (dict(eta=1.0, projectile_spin=(0.5, (1, 2))), "vector of three numbers"),
        (dict(eta=1.0, eta_potential="both"), "eta_potential must be one of self, all"),
    ]:
        with pytest.raises(ValueError, match=match):
            dw.setup_collision(target, projectile, **kwargs)
    with pytest.raises(ValueError, match="target must be the more massive"):
        dw.setup_collision(projectile, target, eta=1.0)


def test_both_readings_of_eta(piles):
    """eta_potential "self" (each pile's own pairs) and "all" (every pair at set-up), each computed
    here from float64 NumPy potentials: the run's eta is its reading's, and both are recorded."""
    target, projectile = piles
    own = dw.setup_collision(target, projectile, eta=2.0, theta_deg=22.0)
    every = dw.setup_collision(target, projectile, eta=2.0, theta_deg=22.0, eta_potential="all")
    for s, reading in ((own, "self"), (every, "all")):
        t, p = _pile(s, 0), _pile(s, 1)
        kinetic = 0.5 * t.total_mass * t.bulk_velocity @ t.bulk_velocity + 0.5 * p.total_mass * p.bulk_velocity @ p.bulk_velocity
        u_self = _self_potential(t) + _self_potential(p)
        u_all = _self_potential(s)
        meta = s.metadata
        assert meta["eta_potential"] == reading
        assert meta["eta_self"] == pytest.approx(kinetic / abs(u_self), rel=1e-9)
        assert meta["eta_all"] == pytest.approx(kinetic / abs(u_all), rel=1e-9)
        assert meta["eta"] == pytest.approx(2.0, rel=1e-12)
        assert meta["eta_" + reading] == pytest.approx(2.0, rel=1e-9)
    # The cross term deepens U, so at the same eta the "all" reading is the faster impact, by
    # sqrt(|U_all| / |U_self|); the piles sit where they sat.
    ratio = 1 + own.metadata["cross_potential"] / (own.metadata["target_potential"] + own.metadata["projectile_potential"])
    assert every.metadata["speed"] / own.metadata["speed"] == pytest.approx(math.sqrt(ratio), rel=1e-9)
    np.testing.assert_array_equal(every.positions, own.positions)


def test_surface_motion_at_the_first_contact_by_kind_of_spin():
    """Head-on, contact along -x from the target: spins about z shear the contact (parallel: the
    surfaces pass at w (R_t + R_p); anti-parallel: they roll together, w |R_t - R_p|); spins about x
    do not shear it, and twist it only when opposed (2 w)."""
    from decco_warp.collision import first_contact_motion

    w, r_t, r_p = 1e-4, 2e7, 1e7
    base = {"theta_deg": 0.0, "target_radius": r_t, "projectile_radius": r_p}

    def motion(target_axis, projectile_axis):
        return first_contact_motion({**base, "target_spin": w * np.array(target_axis), "projectile_spin": w * np.array(projectile_axis)})

    z, x = (0, 0, 1), (1, 0, 0)
    minus = lambda axis: tuple(-c for c in axis)  # noqa: E731
    assert motion(z, z)["contact_surface_speed"] == pytest.approx(w * (r_t + r_p), rel=1e-12)
    assert motion(z, minus(z))["contact_surface_speed"] == pytest.approx(w * (r_t - r_p), rel=1e-12)
    assert motion(x, x) == {"contact_surface_speed": 0.0, "contact_twist_rate": 0.0}
    assert motion(x, minus(x)) == pytest.approx({"contact_surface_speed": 0.0, "contact_twist_rate": 2 * w}, rel=1e-12)
    assert motion(z, x)["contact_surface_speed"] == pytest.approx(w * r_t, rel=1e-12)  # only the target's spin shears
    assert motion(z, x)["contact_twist_rate"] == pytest.approx(w, rel=1e-12)
    # Oblique: the contact normal turns with theta; a spin about z still shears it by w (R_t + R_p).
    assert first_contact_motion({**base, "theta_deg": 30.0, "target_spin": w * np.array(z), "projectile_spin": w * np.array(z)})[
        "contact_surface_speed"
    ] == pytest.approx(w * (r_t + r_p), rel=1e-12)


def test_a_spin_axis_may_be_any_vector(piles):
    """An axis given as a vector is normalised: (1, 0, 1) spins at the requested fraction of breakup
    about the diagonal, as +x and +z together would at 1/sqrt(2) each."""
    target, projectile = piles
    s = dw.setup_collision(target, projectile, eta=1.0, projectile_spin=(0.5, (1, 0, 1)))
    omega = 0.5 * breakup_spin(projectile) / math.sqrt(2)
    np.testing.assert_allclose(_pile(s, 1).omegas[0], [omega, 0, omega], rtol=1e-12)
    named = dw.setup_collision(target, projectile, eta=1.0, projectile_spin=(0.5, "+z"))
    along = dw.setup_collision(target, projectile, eta=1.0, projectile_spin=(0.5, (0, 0, 3.5)))
    np.testing.assert_array_equal(named.omegas, along.omegas)

"""A self-gravitating clump in contact: momentum, angular momentum and energy over 2000 steps."""

import numpy as np
import pytest
from oracle import energies
from scenes import contact_cluster

import decco_warp as dw

STEPS = 2000
#: float64 mode: relative drift of linear and angular momentum (the paper promises < 1e-6).
MOMENTUM_TOLERANCE_FLOAT64 = 1e-9
#: default mode: the force sums are float32, so momentum closes to ~1e-7 per step, not to round-off.
MOMENTUM_TOLERANCE_MIXED = 1e-5
#: elastic, frictionless run: relative drift of the total energy.
ENERGY_TOLERANCE = 1e-4


def _momenta(state):
    p = (state.masses[:, None] * state.velocities).sum(axis=0)
    orbital = state.masses[:, None] * np.cross(state.positions, state.velocities)
    spin = state.inertia[:, None] * state.omegas
    # Scales: what the sums are made of, so that a drift is relative to real motion.
    p_scale = np.linalg.norm(state.masses[:, None] * state.velocities, axis=1).sum()
    l_scale = np.linalg.norm(orbital, axis=1).sum() + np.linalg.norm(spin, axis=1).sum()
    return p, orbital.sum(axis=0) + spin.sum(axis=0), p_scale, l_scale


@pytest.fixture(scope="module")
def clump():
    # Overlaps of 1 to 1e3 cm and slow motion: ~200 live contacts, stable under the paper's dt.
    return contact_cluster(200, seed=7, overlap_range=(1.0, 1e3), speed=20.0, spin=1e-5)


@pytest.mark.parametrize("precision", ["float64", "mixed"])
def test_clump_conserves_momentum_and_angular_momentum(clump, precision, device):
    params = dw.Params()
    sim = dw.Simulation(clump, params, device=device, precision=precision)
    sim.step(STEPS)
    final = sim.state
    assert final.step == STEPS and final.time == pytest.approx(STEPS * params.dt)
    p0, l0, p_scale, l_scale = _momenta(clump)
    p1, l1, _, _ = _momenta(final)
    tolerance = MOMENTUM_TOLERANCE_FLOAT64 if precision == "float64" else MOMENTUM_TOLERANCE_MIXED
    assert np.linalg.norm(p1 - p0) <= tolerance * p_scale
    assert np.linalg.norm(l1 - l0) <= tolerance * l_scale
    # The run did something: every particle started in contact, and gravity and contacts reshaped the clump.
    assert dw.diagnostics(clump, params, device=device)["number_of_contacts"] >= clump.n - 1
    assert np.abs(final.positions - clump.positions).max() > 1e4


def test_elastic_frictionless_clump_conserves_energy(clump, device):
    params = dw.Params(restitution=1.0, mu_k=0.0, mu_r=0.0)
    sim = dw.Simulation(clump, params, device=device, precision="float64")
    before = dw.diagnostics(clump, params, device=device)
    sim.step(STEPS)
    after = dw.diagnostics(sim.state, params, device=device)
    assert abs(after["total_energy"] - before["total_energy"]) <= ENERGY_TOLERANCE * abs(before["total_energy"])
    # The kinetic energy really changed: energy was exchanged, not frozen.
    assert abs(after["kinetic_translational"] - before["kinetic_translational"]) > 1e-2 * before["kinetic_translational"]


def test_diagnostics_match_independent_energies(clump, device):
    params = dw.Params()
    got = dw.diagnostics(clump, params, device=device)
    kinetic, rotational, potential, elastic = energies(
        clump.positions, clump.velocities, clump.omegas, clump.radii, clump.masses, params.k_in, params.restitution, params.G
    )
    assert got["kinetic_translational"] == pytest.approx(kinetic, rel=1e-12)
    assert got["kinetic_rotational"] == pytest.approx(rotational, rel=1e-12)
    assert got["potential"] == pytest.approx(potential, rel=1e-12)
    assert got["elastic"] == pytest.approx(elastic, rel=1e-9)
    p, l, _, _ = _momenta(clump)
    np.testing.assert_allclose(got["momentum"], p, rtol=1e-12)
    np.testing.assert_allclose(got["angular_momentum"], l, rtol=1e-12)

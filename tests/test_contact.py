"""Contact physics in small scenes with known answers: restitution, friction, rolling."""

import numpy as np
import pytest
import warp as wp
from scenes import overlapping_cloud, sphere_mass, two_spheres

import decco_warp as dw
from decco_warp.kernels import pair

NO_GRAVITY = dict(G=0.0)


@wp.kernel
def _reach_of_pairs(
    # In:
    radius_i_in: wp.array(dtype=wp.float64),
    radius_j_in: wp.array(dtype=wp.float64),
    skin: wp.float64,
    margin: wp.float64,
    d2_in: wp.array(dtype=wp.float64),
    # Out:
    reach_out: wp.array(dtype=wp.float64),
    within_out: wp.array(dtype=wp.int32),
    touching_out: wp.array(dtype=wp.int32),
):
    k = wp.tid()
    reach = pair.reach(radius_i_in[k], radius_j_in[k], skin, margin)
    reach_out[k] = reach
    within_out[k] = wp.where(pair.within_reach(d2_in[k], reach, wp.float64(1.0)), 1, 0)
    touching_out[k] = wp.where(pair.in_contact(d2_in[k], radius_i_in[k], radius_j_in[k]), 1, 0)


@pytest.mark.parametrize("skin, margin", [(0.0, 1.0), (0.3, pair.NEIGHBOUR_LIST_MARGIN), (0.0, pair.TREE_GRID_MARGIN)])
def test_reach_is_one_function_on_device_and_host(device, skin, margin):
    """Who interacts is pair.reach: its host twin gives the same bits, a pair is within reach strictly
    inside it, and a contact is the reach of skin 0 and margin 1 (delta > 0)."""
    rng = np.random.default_rng(5)
    ri, rj = rng.uniform(0.5, 2.0, 64), rng.uniform(0.5, 2.0, 64)
    host = pair.host_reach(ri, rj, skin, margin)
    touch = ri + rj
    d2 = np.concatenate([host[:16] ** 2, np.nextafter(host[16:32] ** 2, 0), rng.uniform(0.0, 16.0, 32)])
    arrays = [wp.array(a, dtype=wp.float64, device=device) for a in (ri, rj)]
    out = [wp.zeros(64, dtype=t, device=device) for t in (wp.float64, wp.int32, wp.int32)]
    wp.launch(_reach_of_pairs, dim=64, inputs=[*arrays, skin, margin, wp.array(d2, dtype=wp.float64, device=device)],
              outputs=out, device=device)  # fmt: skip
    reach, within, touching = (a.numpy() for a in out)
    assert np.array_equal(reach, host)
    assert np.array_equal(within, d2 < host * host)
    assert np.array_equal(touching, d2 < touch * touch)
    assert not within[:16].any() and within[16:32].all()


def _relative_normal_speed(state):
    n = state.positions[0] - state.positions[1]
    n /= np.linalg.norm(n)
    return float(np.dot(state.velocities[0] - state.velocities[1], n))


def test_head_on_restitution_and_spring_switch(device):
    """Two equal spheres meet head on: v_out / v_in = eps, loading with k_in and unloading with k_out."""
    radius = 1.5e6
    params = dw.Params(restitution=0.9, mu_k=0.3, mu_r=1e-3, **NO_GRAVITY)
    state = two_spheres(2 * radius + 1e3, velocity_i=(100.0, 0, 0), velocity_j=(-100.0, 0, 0), radius=radius)
    sim = dw.Simulation(state, params, device=device, precision="float64")
    v_in = _relative_normal_speed(state)
    stiffness_seen = []
    for _ in range(2000):
        sim.step(1)
        now = sim.state
        d = np.linalg.norm(now.positions[0] - now.positions[1])
        overlap = 2 * radius - d
        if overlap > 0:
            force, _ = sim.forces()
            # |F| = (k/2) overlap: recover k at this step.
            stiffness_seen.append(2 * np.linalg.norm(force[0]) / overlap)
        elif stiffness_seen:
            break
    v_out = _relative_normal_speed(sim.state)
    assert v_in < 0 < v_out
    assert abs(v_out / -v_in - params.restitution) <= 0.01 * params.restitution
    stiffness_seen = np.array(stiffness_seen)
    loading = np.isclose(stiffness_seen, params.k_in, rtol=1e-9)
    unloading = np.isclose(stiffness_seen, params.k_out, rtol=1e-9)
    assert np.all(loading | unloading)
    # One switch, from k_in while approaching to k_out while receding.
    first_unloading = np.argmax(unloading)
    assert loading[:first_unloading].all() and unloading[first_unloading:].all()
    assert 50 < first_unloading < len(stiffness_seen) - 50


def _contact_pair(omega_i=(0, 0, 0), velocity_i=(0, 0, 0), overlap=100.0, radius=1.5e6):
    return two_spheres(2 * radius - overlap, velocity_i=velocity_i, omega_i=omega_i, radius=radius)


def test_sliding_friction_opposes_slip_with_magnitude_mu_k_times_normal(device):
    radius = 1.5e6
    params = dw.Params(mu_r=0.0, **NO_GRAVITY)
    # i on the left, sliding along +y and spinning about z: slip at the contact along y.
    state = _contact_pair(omega_i=(0, 0, 2e-5), velocity_i=(-1.0, 30.0, 0), radius=radius)
    force, torque = dw.compute_forces(state, params, device=device, precision="float64")
    n = np.array([-1.0, 0, 0])  # from j to i
    normal = np.dot(force[0], n)
    tangential = force[0] - normal * n
    assert normal > 0  # repulsion
    assert np.isclose(np.linalg.norm(tangential), params.mu_k * normal, rtol=1e-12)
    # Slip of i's surface relative to j's at the contact point.
    arm_i = np.array([radius, 0, 0]) - 50.0 * np.array([1, 0, 0])
    arm_j = -arm_i
    slip = state.velocities[0] + np.cross(state.omegas[0], arm_i)
    slip -= np.dot(slip, n) * n
    assert np.dot(tangential, slip) < 0
    # The forces and torques on both spheres make the slip shrink.
    inertia = state.inertia
    accel = force[0] / state.masses[0] - force[1] / state.masses[1]
    spin = np.cross(torque[0] / inertia[0], arm_i) - np.cross(torque[1] / inertia[1], arm_j)
    slip_rate = accel + spin
    slip_rate -= np.dot(slip_rate, n) * n
    assert np.dot(slip_rate, slip) < 0


def test_oblique_contact_friction_never_adds_energy(device):
    """Elastic spring (eps = 1), so only friction can change the energy: it falls, never rises."""
    radius = 1.5e6
    offset = 1.2 * radius  # impact parameter: an oblique, sliding contact
    state = two_spheres(
        np.sqrt((2 * radius + 1e3) ** 2 - offset**2), velocity_i=(100.0, 0, 0), velocity_j=(-100.0, 0, 0), radius=radius
    )
    state.positions[0, 1] -= offset / 2
    state.positions[1, 1] += offset / 2

    def run(mu_k, mu_r):
        params = dw.Params(restitution=1.0, mu_k=mu_k, mu_r=mu_r, **NO_GRAVITY)
        sim = dw.Simulation(state, params, device=device, precision="float64")
        energy = []
        for _ in range(60):
            sim.step(20)
            e = dw.diagnostics(sim.state, params, device=device)
            energy.append(e["kinetic_translational"] + e["kinetic_rotational"] + e["elastic"])
        return np.array(energy), sim.state

    e0 = dw.diagnostics(state, dw.Params(**NO_GRAVITY))["kinetic_translational"]
    frictionless, _ = run(0.0, 0.0)
    with_friction, final = run(0.3, 1e-3)
    # Verlet's energy fluctuation during an elastic contact (~1e-5 of e0): the noise floor of this check.
    noise = max(np.abs(frictionless - e0).max(), np.abs(np.diff(frictionless)).max())
    assert 0 < noise < 1e-4 * e0
    assert np.all(with_friction <= e0 + noise)
    assert np.all(np.diff(with_friction) <= 2 * noise)
    assert with_friction[-1] < e0 - 100 * noise  # friction really acted
    assert np.linalg.norm(final.omegas, axis=1).min() > 0  # and spun the spheres up


def test_friction_power_is_never_positive_in_a_cluster(device):
    """Sum over particles of the friction forces' power: exactly the dissipation, always <= 0."""
    state = overlapping_cloud(200, seed=11)
    base = dw.Params(mu_k=0.0, mu_r=0.0)
    f0, t0 = dw.compute_forces(state, base, device=device, precision="float64")
    for mu_k, mu_r in [(0.3, 0.0), (0.0, 1e-3), (0.3, 1e-3)]:
        params = dw.Params(mu_k=mu_k, mu_r=mu_r)
        f, t = dw.compute_forces(state, params, device=device, precision="float64")
        power = np.sum((f - f0) * state.velocities) + np.sum((t - t0) * state.omegas)
        assert power < 0


def test_rolling_couple_opposes_relative_rolling(device):
    radius = 1.5e6
    overlap = 100.0
    params = dw.Params(mu_k=0.0, mu_r=1e-3, **NO_GRAVITY)
    omega = np.array([0.0, 0.0, 1e-3])
    state = _contact_pair(omega_i=omega, overlap=overlap, radius=radius)
    force, torque = dw.compute_forces(state, params, device=device, precision="float64")
    normal = 0.5 * params.k_out * overlap  # at rest: k_out
    expected = -params.mu_r * normal * (radius / 2) * omega / np.linalg.norm(omega)
    np.testing.assert_allclose(torque[0], expected, rtol=1e-12)
    np.testing.assert_allclose(torque[1], -expected, rtol=1e-12)  # a pure couple
    np.testing.assert_allclose(force[0], [-normal, 0, 0], rtol=1e-12)  # and no force
    assert np.dot(torque[0], state.omegas[0]) + np.dot(torque[1], state.omegas[1]) < 0


def test_rolling_couple_slows_relative_rotation_at_the_analytic_rate(device):
    """Two spheres held in contact by gravity: |w_i - w_j| falls at mu_r F_N R* (1/I_i + 1/I_j)."""
    radius = 1.5e6
    params = dw.Params(mu_k=0.0, mu_r=1e-3)
    mass = float(sphere_mass(radius))
    # Equilibrium overlap: (k_out / 2) delta = G m^2 / d^2.
    normal = params.G * mass**2 / (2 * radius) ** 2
    overlap = normal / (0.5 * params.k_out)
    state = _contact_pair(omega_i=(0, 0, 1e-3), overlap=overlap, radius=radius)
    sim = dw.Simulation(state, params, device=device, precision="float64")
    steps = 2000
    rates = []
    for _ in range(10):
        sim.step(steps // 10)
        w = sim.state.omegas
        rates.append(np.linalg.norm(w[0] - w[1]))
    assert np.all(np.diff(rates) < 0)
    inertia = 0.4 * mass * radius**2
    expected = params.mu_r * normal * (radius / 2) * (2 / inertia) * steps * params.dt
    assert 1e-3 - rates[-1] == pytest.approx(expected, rel=0.02)


def test_printed_rolling_form_is_the_papers_force_at_the_contact(device):
    radius = 1.5e6
    overlap = 100.0
    params = dw.Params(mu_k=0.0, mu_r=1e-3, rolling_friction="paper", **NO_GRAVITY)
    state = _contact_pair(omega_i=(0, 0, 1e-3), overlap=overlap, radius=radius)
    force, torque = dw.compute_forces(state, params, device=device, precision="float64")
    normal = 0.5 * params.k_out * overlap
    r_ij = state.positions[0] - state.positions[1]
    direction = np.cross(state.omegas[0] - state.omegas[1], r_ij)
    rolling = -params.mu_r * normal * direction / np.linalg.norm(direction)
    n = r_ij / np.linalg.norm(r_ij)
    np.testing.assert_allclose(force[0], normal * n + rolling, rtol=1e-12)
    np.testing.assert_allclose(force[1], -(normal * n + rolling), rtol=1e-12)
    arm_i = -0.5 * r_ij
    np.testing.assert_allclose(torque[0], np.cross(arm_i, rolling), rtol=1e-12)


def _rigidly_spinning_cluster(fraction=0.5, seed=5):
    """A clump of touching spheres of the paper's radii (ratio 3 between the largest and smallest),
    turning rigidly at ``fraction`` of its breakup spin sqrt(G M / R^3) about a tilted axis, as
    collision.setup_collision spins a pile: v = w x (x - x_cm), every sphere's spin w."""
    from scenes import contact_cluster

    state = contact_cluster(80, seed=seed, overlap_range=(1.0, 1e3), speed=0.0, spin=0.0)
    assert state.radii.max() / state.radii.min() == 3.0
    offset = state.positions - state.centre_of_mass
    radius = (np.linalg.norm(offset, axis=1) + state.radii).max()
    axis = np.array([0.3, -0.5, 1.0]) / np.linalg.norm([0.3, -0.5, 1.0])
    omega = fraction * np.sqrt(dw.G_CGS * state.total_mass / radius**3) * axis
    state.velocities = np.cross(omega, offset) + np.array([3.0e3, -1.0e3, 2.0e3])  # and a bulk motion
    state.omegas = np.tile(omega, (state.n, 1))
    return state, omega


@pytest.mark.parametrize("kernel", ["tiled", "reference"])
def test_a_rigidly_spinning_cluster_feels_no_sliding_friction(device, kernel):
    """A rigidly turning clump (half its breakup spin) has no slip but round-off: no contact slides,
    so the sliding channel is zero on every sphere (an exact |slip| > 0 test gave every contact the
    full mu_k |F_N|, here up to 1e20 dyne against springs of 3.5e20, in a direction of round-off),
    no sphere feels a torque (equal spins: no rolling either), and the forces are bit for bit those
    without friction."""
    state, omega = _rigidly_spinning_cluster()
    forces = {}
    for mu_k in (0.3, 0.0):
        sim = dw.Simulation(state, dw.Params(mu_k=mu_k), device=device, force_kernel=kernel, ledger=True, allow_unstable=True)
        assert sim.diagnostics()["number_of_contacts"] >= state.n - 1
        channels = sim.engine.channels.numpy()
        assert np.all(channels[:, 1] == 0) and np.all(channels[:, 2] == 0)  # sliding force and its torque
        forces[mu_k] = sim.forces()
    assert np.array_equal(forces[0.3][0], forces[0.0][0]) and np.all(forces[0.3][1] == 0)


def test_sliding_friction_lies_in_the_tangent_plane_and_vanishes_below_the_slip_threshold():
    """A slip along the tangent plane gives a friction force with no normal part (to round-off of its
    size); a slip below 1e-10 of the pair's velocity scale gives none, one just above it the full
    mu_k |F_N| (the NumPy oracle agrees on both sides)."""
    from oracle import pair_loop_forces

    radii = np.array([0.75e6, 2.25e6])
    x = np.array([[1.0e7, -2.0e7, 3.0e6], [1.0e7 + radii.sum() - 100.0, -2.0e7, 3.0e6]])
    for slip, slides in ((5e-8, True), (1e-8, False)):  # the scale: |v_i| + |v_j| = 2 x 1e2 cm/s, so 2e-8
        velocities = np.array([[1e2, slip, 0.0], [1e2, 0.0, 0.0]])
        state = dw.State.from_arrays(x, velocities, np.zeros((2, 3)), radii, sphere_mass(radii))
        params = dw.Params(G=0.0)
        force, torque = dw.compute_forces(state, params, device="cpu", precision="float64", force_kernel="reference")
        expected, _, _, _ = pair_loop_forces(state.positions, state.velocities, state.omegas, state.radii, state.masses,
                                             params.k_in, params.restitution, params.mu_k, params.mu_r, 0.0)  # fmt: skip
        n = (state.positions[0] - state.positions[1]) / np.linalg.norm(state.positions[0] - state.positions[1])
        tangential = force[0] - np.dot(force[0], n) * n
        normal = 0.5 * params.k_out * 100.0
        assert np.allclose(force, expected, rtol=1e-12, atol=1e-9 * normal)
        if slides:
            assert np.linalg.norm(tangential) == pytest.approx(params.mu_k * normal, rel=1e-9)
            assert abs(np.dot(tangential, n)) < 1e-15 * np.linalg.norm(tangential)
        else:
            assert np.linalg.norm(tangential) < 1e-9 * normal


def _spinning_pair(ratio, spin=(0.0, 0.0, 2e-4), other_spin=(1e-4, -5e-5, 0.0), slip=(0.0, 40.0, 10.0)):
    """Two touching spheres of radii 0.75e6 and ratio x that, with spins and a slip."""
    radii = np.array([0.75e6, 0.75e6 * ratio])
    x = np.array([[2.0e7, -1.0e7, 3.0e6], [2.0e7 + radii.sum() - 300.0, -1.0e7 + 2e4, 3.0e6 - 1e4]])
    v = np.array([[0.0, 0.0, 0.0], slip])
    w = np.array([spin, other_spin])
    return dw.State.from_arrays(x, v, w, radii, sphere_mass(radii))


@pytest.mark.parametrize("precision", ["mixed", "float64"])
@pytest.mark.parametrize("kernel", ["tiled", "reference"])
def test_decco_code_law_is_deccos_loop(device, kernel, precision):
    """contact_law = "decco-code" gives, on a spinning, sliding clump of the paper's three radii, the
    forces and torques of DECCO's own loop transcribed in NumPy (tests/oracle.py), particle by particle
    (to 1e-9 of the largest in float64, 1e-5 in mixed precision)."""
    from oracle import decco_code_forces
    from scenes import contact_cluster

    state = contact_cluster(60, seed=9, overlap_range=(10.0, 1e4), speed=50.0, spin=3e-4)
    params = dw.Params(contact_law="decco-code", mu_r=0.05)
    force, torque = dw.compute_forces(state, params, device=device, precision=precision, force_kernel=kernel)
    expected_force, expected_torque = decco_code_forces(state.positions, state.velocities, state.omegas, state.radii, state.masses,
                                                        params.k_in, params.restitution, params.mu_k, params.mu_r, params.G)  # fmt: skip
    scale = np.abs(expected_force).max()
    tolerance = 1e-5 if precision == "mixed" else 1e-9  # mixed: float32 gravity, and the fused layout's float32 sums
    np.testing.assert_allclose(force, expected_force, rtol=0, atol=tolerance * scale)
    np.testing.assert_allclose(torque, expected_torque, rtol=0, atol=tolerance * np.abs(expected_torque).max())
    paper, _ = dw.compute_forces(state, dw.Params(mu_r=0.05), device=device, precision=precision, force_kernel=kernel)
    assert np.abs(paper - force).max() > 1e-3 * scale  # the laws differ on this clump


def test_decco_code_law_differs_from_the_paper_law_only_at_unequal_radii():
    """DECCO's slip puts the second sphere's spin on the first one's lever arm: for equal radii its
    sliding force is the paper law's; at radius ratio 3 it is not.  Its rolling friction is a torque
    mu_r |F_N| R_i on each sphere, not the couple's mu_r |F_N| R* (twice it for equal radii)."""
    for ratio, same_sliding in ((1.0, True), (3.0, False)):
        state = _spinning_pair(ratio)
        channels = {}
        for law in ("paper", "decco-code"):
            sim = dw.Simulation(state, dw.Params(contact_law=law, G=0.0, mu_r=0.02), device="cpu", precision="float64",
                                force_kernel="reference", ledger=True, allow_unstable=True)  # fmt: skip
            channels[law] = sim.engine.channels.numpy().copy(), sim.forces()[1]
        sliding = {law: channels[law][0][:, 1] for law in channels}
        assert np.allclose(sliding["paper"], sliding["decco-code"], rtol=1e-12, atol=0) == same_sliding
        rolling = {law: channels[law][1] - channels[law][0][:, 2] for law in channels}  # torque beside sliding's
        reduced = state.radii.prod() / state.radii.sum()
        d = np.linalg.norm(state.positions[0] - state.positions[1])
        for k in range(2):  # DECCO's lever arm reaches the contact point: R_i d / (R_i + R_j)
            expected = state.radii[k] * d / state.radii.sum() / reduced
            assert np.linalg.norm(rolling["decco-code"][k]) / np.linalg.norm(rolling["paper"][k]) == pytest.approx(expected, rel=1e-9)


@pytest.mark.parametrize("ratio", [1.0, 2.0, 3.0])
def test_decco_code_rolling_friction_leaks_angular_momentum_at_unequal_radii(ratio):
    """The paper law's rolling couple conserves angular momentum; DECCO's torques on each sphere
    change the pair's by mu_r |F_N| |R_i - R_j| d / (R_i + R_j) (zero for equal radii)."""
    state = _spinning_pair(ratio, slip=(0.0, 0.0, 0.0), other_spin=(0.0, 0.0, -2e-4))
    x = state.positions
    for law in ("paper", "decco-code"):
        params = dw.Params(contact_law=law, G=0.0, mu_k=0.0, mu_r=0.02)
        force, torque = dw.compute_forces(state, params, device="cpu", precision="float64", force_kernel="reference")
        rate = np.cross(x, force).sum(axis=0) + torque.sum(axis=0)  # dL/dt about the origin
        d = np.linalg.norm(x[0] - x[1])
        normal = 0.5 * params.k_out * (state.radii.sum() - d)  # at rest along the normal: k_out
        expected = 0.0 if law == "paper" else params.mu_r * normal * abs(state.radii[0] - state.radii[1]) * d / state.radii.sum()
        assert np.linalg.norm(rate) == pytest.approx(expected, abs=1e-9 * params.mu_r * normal * state.radii.max())

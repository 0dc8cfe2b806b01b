"""The cluster finder (paper sect. 2.7, docs/model.md) on snapshots with known answers."""

import math

import numpy as np
import pytest

import decco_warp as dw
from decco_warp.collision import pile_radius
from decco_warp.run import builtin_pile


@pytest.fixture(scope="module")
def piles():
    return dw.load_pile(builtin_pile("target")), dw.load_pile(builtin_pile("projectile"))


def _escape_speed(pile, distance):
    return math.sqrt(2 * dw.G_CGS * pile.total_mass / distance)


def _combine(*parts):
    """Concatenate States (positions, velocities already placed)."""
    return dw.State.from_arrays(
        np.concatenate([p.positions for p in parts]),
        np.concatenate([p.velocities for p in parts]),
        np.concatenate([p.omegas for p in parts]),
        np.concatenate([p.radii for p in parts]),
        np.concatenate([p.masses for p in parts]),
    )


def _moved(pile, offset, velocity):
    moved = pile.copy()
    moved.positions += np.asarray(offset, dtype=float)
    moved.velocities += np.asarray(velocity, dtype=float)
    return moved


def test_two_separating_piles_are_two_clusters_largest_first(piles):
    target, projectile = piles
    distance = 10 * (pile_radius(target) + pile_radius(projectile))
    fast = 5 * _escape_speed(target, distance)  # moving apart well above escape speed
    state = _combine(_moved(projectile, (0, 0, 0), (0, 0, 0)), _moved(target, (distance, 0, 0), (fast, 0, 0)))
    clusters = dw.find_clusters(state, min_members=50)
    assert len(clusters) == 2
    big, small = clusters
    assert big.members.tolist() == list(range(projectile.n, projectile.n + target.n))
    assert small.members.tolist() == list(range(projectile.n))
    assert big.mass == pytest.approx(target.total_mass, rel=1e-12)
    np.testing.assert_allclose(big.com, target.centre_of_mass + [distance, 0, 0], rtol=1e-9, atol=1e-3)
    np.testing.assert_allclose(big.velocity, [fast, 0, 0], atol=1e-6 * fast)


def test_same_piles_at_rest_bind_into_one(piles):
    target, projectile = piles
    distance = 10 * (pile_radius(target) + pile_radius(projectile))
    state = _combine(target, _moved(projectile, (distance, 0, 0), (0, 0, 0)))
    clusters = dw.find_clusters(state, min_members=50)
    assert len(clusters) == 1 and clusters[0].members.size == state.n


def _escapers(pile, count, speed_factor, seed=0):
    """``count`` small particles outside the pile, flying radially away at speed_factor x escape speed."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    distance = 3 * pile_radius(pile) * (1 + rng.uniform(size=(count, 1)))
    positions = pile.centre_of_mass + direction * distance
    speed = speed_factor * np.sqrt(2 * dw.G_CGS * pile.total_mass / distance)
    radii = np.full(count, 0.75e6)
    return dw.State.from_arrays(positions, direction * speed, np.zeros((count, 3)), radii, 4 / 3 * np.pi * 2.7 * radii**3)


def test_unbound_escaping_particles_are_left_out(piles):
    target, _ = piles
    state = _combine(target, _escapers(target, 30, speed_factor=3.0))
    clusters = dw.find_clusters(state, min_members=20)
    assert len(clusters) == 1
    assert clusters[0].members.tolist() == list(range(target.n))
    # Slow enough and they are bound: they join.
    slow = _combine(target, _escapers(target, 30, speed_factor=0.5))
    assert dw.find_clusters(slow, min_members=20)[0].members.size == target.n + 30


def test_a_fast_particle_touching_a_member_joins_by_contact(piles):
    target, _ = piles
    outermost = int(np.argmax(np.linalg.norm(target.positions - target.centre_of_mass, axis=1) + target.radii))
    direction = target.positions[outermost] - target.centre_of_mass
    direction /= np.linalg.norm(direction)
    radius = 0.75e6
    touching_at = target.positions[outermost] + direction * (target.radii[outermost] + radius - 10.0)
    speed = 10 * _escape_speed(target, pile_radius(target))
    stray = dw.State.from_arrays(
        touching_at[None], (direction * speed)[None], np.zeros((1, 3)), [radius], [4 / 3 * np.pi * 2.7 * radius**3]
    )
    clusters = dw.find_clusters(_combine(target, stray), min_members=50)
    assert clusters[0].members.size == target.n + 1
    # Moved just out of contact, the same particle is unbound.
    stray.positions += direction * 100.0
    assert dw.find_clusters(_combine(target, stray), min_members=50)[0].members.size == target.n


def test_minimum_member_count_cuts_off_small_clumps(piles):
    target, _ = piles
    clump = target.subset(np.argsort(np.linalg.norm(target.positions, axis=1))[:40])  # 40 touching particles
    distance = 20 * pile_radius(target)
    fast = 5 * _escape_speed(target, distance)
    state = _combine(target, _moved(clump, (distance, 0, 0), (fast, 0, 0)))
    assert [c.members.size for c in dw.find_clusters(state, min_members=50)] == [target.n]
    assert [c.members.size for c in dw.find_clusters(state, min_members=30)] == [target.n, 40]
    with pytest.raises(ValueError, match="min_members"):
        dw.find_clusters(state, min_members=0)


def _grains(positions, velocity, radius=1e5):
    """Equal spheres (radius [cm], rho 2.7) at ``positions``, all moving at ``velocity``."""
    positions = np.asarray(positions, dtype=float)
    count = len(positions)
    radii = np.full(count, radius)
    velocities = np.tile(np.asarray(velocity, dtype=float), (count, 1))
    return dw.State.from_arrays(positions, velocities, np.zeros((count, 3)), radii, 4 / 3 * np.pi * 2.7 * radii**3)


def _sparse_and_dense(offset, velocity):
    """A sparse cluster (100 grains 30 radii apart, at rest: bound only by the escape-speed rule, its
    smoothed density ~1 grain's) and a dense group (20 touching grains: ~17 grains' density) at
    ``offset`` from it, the sparse cluster moving at ``velocity`` relative to the group."""
    radius = 1e5
    lattice = np.stack(np.meshgrid(np.arange(5), np.arange(5), np.arange(4), indexing="ij"), axis=-1).reshape(-1, 3)
    sparse = _grains(30 * radius * lattice, velocity, radius)
    packed = np.stack(np.meshgrid(np.arange(3), np.arange(3), np.arange(2), indexing="ij"), axis=-1).reshape(-1, 3)
    packed = np.concatenate([packed, [[3, 0, 0], [3, 1, 0]]])  # 20 grains, neighbours 1.99 radii apart
    dense = _grains(sparse.centre_of_mass + np.asarray(offset) + 1.99 * radius * packed, (0, 0, 0), radius)
    return _combine(dense, sparse)


def test_a_small_dense_group_met_first_does_not_end_the_search():
    """The densest seed's group (20 grains) is short of min_members: the search goes on and finds
    the sparse cluster of 100 behind it (the paper's sentence read literally finds nothing)."""
    state = _sparse_and_dense(offset=(1e9, 0, 0), velocity=(1e3, 0, 0))  # far apart and unbound
    clusters = dw.find_clusters(state, min_members=50)
    assert [c.members.size for c in clusters] == [100]
    assert clusters[0].members.tolist() == list(range(20, 120))


def test_a_short_groups_grains_join_a_later_cluster_but_never_seed_again():
    """The dense group alone cannot hold the sparse grains (they pass it at 45 cm/s, above its escape
    speed of <= 30 cm/s), so its seed fails; the sparse cluster, seeded next, is heavy enough to bind
    the group (61 cm/s at its distance): one cluster of all 120."""
    state = _sparse_and_dense(offset=(4e7, 0, 0), velocity=(45.0, 0, 0))
    clusters = dw.find_clusters(state, min_members=50)
    assert [c.members.size for c in clusters] == [120]
    # With the sparse grains fast enough to escape both, each part stands alone: one cluster of 100,
    # and the dense group (a failed seed) stays free, never seeded again.
    fast = _sparse_and_dense(offset=(4e7, 0, 0), velocity=(200.0, 0, 0))
    assert [c.members.tolist() for c in dw.find_clusters(fast, min_members=50)] == [list(range(20, 120))]
    assert [c.members.size for c in dw.find_clusters(fast, min_members=20)] == [100, 20]


def test_result_does_not_depend_on_particle_order(piles):
    target, projectile = piles
    distance = 3 * (pile_radius(target) + pile_radius(projectile))
    fast = 3 * _escape_speed(target, distance)
    state = _combine(target, _moved(projectile, (distance, 0, 0), (fast, 0, 0)), _escapers(target, 25, 2.0, seed=4))
    order = np.random.default_rng(7).permutation(state.n)
    shuffled = state.subset(order)
    a = dw.find_clusters(state, min_members=50)
    b = dw.find_clusters(shuffled, min_members=50)
    assert len(a) == len(b) == 2
    for ca, cb in zip(a, b):
        assert sorted(order[cb.members].tolist()) == ca.members.tolist()
        assert ca.mass == pytest.approx(cb.mass, rel=1e-12)


def test_smoothed_density_equals_the_plain_gaussian_sum_in_any_block_size(piles, monkeypatch):
    """sum_j m_j N(y - x_j; sigma_j), written out pair by pair in float64, at the particles and at
    other points; blocks of a few rows (forced small here) change nothing but the order of work."""
    from decco_warp.analysis import clusters

    target, _ = piles
    x, m, sigma = target.positions + 3e8, target.masses, 10.0 * target.radii  # far from the origin: the centring matters
    at = x[:37] + np.array([1e6, -2e6, 5e5])
    d2 = ((at[:, None, :] - x[None, :, :]) ** 2).sum(axis=2)
    plain = (m / ((2 * np.pi) ** 1.5 * sigma**3) * np.exp(-d2 / (2 * sigma**2))).sum(axis=1)
    for elements in (clusters._CHUNK_ELEMENTS, 7 * target.n):
        monkeypatch.setattr(clusters, "_CHUNK_ELEMENTS", elements)
        np.testing.assert_allclose(clusters.smoothed_density(x, m, sigma, at=at), plain, rtol=1e-9)
        np.testing.assert_allclose(clusters.smoothed_density(x, m, sigma)[:37], clusters.smoothed_density(x, m, sigma, at=x[:37]), rtol=1e-12)


def test_the_smoothed_density_on_a_warp_device_equals_numpys_and_finds_the_same_clusters(piles, device):
    """The O(N^2) smoothed density summed by a Warp kernel (what a GPU runs) against the NumPy sum,
    at the particles and at other points, to float64 round-off; on CUDA the cluster finder through
    it finds the NumPy path's clusters, member for member."""
    from decco_warp.analysis.clusters import SMOOTHING_RADII, smoothed_density
    from decco_warp.engine import smoothed_density as warp_sum

    target, projectile = piles
    distance = 3 * (pile_radius(target) + pile_radius(projectile))
    fast = 5 * _escape_speed(target, distance)  # two clusters: moving apart well above escape speed
    state = _combine(_moved(projectile, (0, 0, 0), (0, 0, 0)), _moved(target, (distance, 0, 0), (fast, 0, 0)))
    x, m, sigmas = state.positions, state.masses, SMOOTHING_RADII * state.radii
    elsewhere = x[::7] + 0.3 * sigmas[::7, None]
    norm, inv_two_var = m / ((2.0 * math.pi) ** 1.5 * sigmas**3), 0.5 / sigmas**2
    for at in (x, elsewhere):
        want = smoothed_density(x, m, sigmas, at=at)
        np.testing.assert_allclose(warp_sum(x, norm, inv_two_var, at, device), want, rtol=1e-12, atol=0)
    if device.startswith("cuda"):
        np.testing.assert_allclose(smoothed_density(x, m, sigmas, device=device), smoothed_density(x, m, sigmas), rtol=1e-12, atol=0)
        on_gpu, in_numpy = dw.find_clusters(state, min_members=50, device=device), dw.find_clusters(state, min_members=50)
        assert len(on_gpu) == len(in_numpy) == 2
        assert all(np.array_equal(a.members, b.members) for a, b in zip(on_gpu, in_numpy))


def test_screening_lone_seeds_changes_no_cluster(piles, monkeypatch):
    """Seeds screened out as standing alone (touching and binding nobody) would fall short anyway:
    the finder with the screen finds the same clusters, member for member, as without it, on a pile
    with a receding one, slow and fast escapers, and a sparse cluster behind a dense group."""
    from decco_warp.analysis import clusters as finder

    target, projectile = piles
    distance = 3 * (pile_radius(target) + pile_radius(projectile))
    state = _combine(
        target,
        _moved(projectile, (distance, 0, 0), (3 * _escape_speed(target, distance), 0, 0)),
        _escapers(target, 40, 2.0, seed=3),
        _escapers(target, 40, 0.7, seed=5),
        _moved(_sparse_and_dense(offset=(4e7, 0, 0), velocity=(45.0, 0, 0)), (50 * distance, 0, 0), (0, 0, 0)),
    )
    screened = dw.find_clusters(state, min_members=20)
    # The screen is its definition, computed over every pair in float64 (_alone_oracle).
    x, v, m, radii = state.positions, state.velocities, state.masses, state.radii
    alone = finder._alone(x, v, m, radii, finder.contact_graph(x, radii), dw.G_CGS)
    assert np.array_equal(alone, _alone_oracle(state))
    assert finder._alone(state.positions, state.velocities, state.masses, state.radii,
                         finder.contact_graph(state.positions, state.radii), dw.G_CGS).sum() >= 40  # fmt: skip
    monkeypatch.setattr(finder, "_alone", lambda x, *rest: np.zeros(len(x), dtype=bool))
    plain = dw.find_clusters(state, min_members=20)
    assert [c.members.tolist() for c in screened] == [c.members.tolist() for c in plain]
    assert len(plain) >= 2


def _debris_field(pile, seed, pairs=80):
    """A debris cloud just after impact: ``pile`` spread 1.3-fold about its centre (nobody touching,
    thousands within NEAR_RADII of each other) flying apart at ~30 m/s in random directions, and
    ``pairs`` particles each set near one of the largest grains, at a distance from just past
    touching to NEAR_RADII of the largest radius (log-uniform, so that every distance shell of the
    screen is met), moving at 0.9 to 1.1 of that grain's escape speed at that distance relative to it."""
    from decco_warp.analysis import clusters as finder

    rng = np.random.default_rng(seed)
    centre = pile.centre_of_mass
    x = centre + 1.3 * (pile.positions - centre)
    v = 1e-3 * (x - centre) + rng.normal(scale=3000.0, size=x.shape)
    radii, m = pile.radii, pile.masses
    largest = np.flatnonzero(m == m.max())
    seeds = rng.choice(largest, size=pairs, replace=False)
    others = rng.choice(np.setdiff1d(np.arange(pile.n), seeds), size=pairs, replace=False)
    for s, j in zip(seeds, others):
        direction, heading = np.eye(3)[rng.integers(3, size=2)] * rng.choice([-1.0, 1.0], size=(2, 1))
        closest = 1.05 * (radii[s] + radii[j])
        distance = math.exp(rng.uniform(math.log(closest), math.log(finder.NEAR_RADII * radii.max())))
        x[j] = x[s] + distance * direction
        v[j] = v[s] + rng.uniform(0.9, 1.1) * math.sqrt(2 * dw.G_CGS * m[s] / distance) * heading
    return dw.State.from_arrays(x, v, pile.omegas, radii, m)


def _alone_oracle(state):
    """The lone-seed screen by its definition over every pair, in float64: touching nobody, binding
    nobody within NEAR_RADII of the largest radius by its own escape speed, and no other particle
    slower relative to it than escape from the heaviest at that distance."""
    from decco_warp.analysis import clusters as finder

    x, v, m, radii = state.positions, state.velocities, state.masses, state.radii
    d = np.linalg.norm(x[:, None] - x[None], axis=-1)
    dv2 = ((v[:, None] - v[None]) ** 2).sum(axis=-1)
    np.fill_diagonal(d, np.inf)
    np.fill_diagonal(dv2, np.inf)
    near = finder.NEAR_RADII * radii.max()
    touching = (d <= radii[:, None] + radii[None]).any(axis=1)
    binding = ((d <= near) & (dv2 * d < 2 * dw.G_CGS * m[:, None])).any(axis=1)
    slow_partner = (dv2 <= 2 * dw.G_CGS * m.max() / near).any(axis=1)
    return ~touching & ~binding & ~slow_partner


@pytest.mark.parametrize("seed", [1, 2])
def test_lone_seeds_of_a_debris_field_are_those_of_the_definition(seed):
    """In a debris cloud just after impact (no contacts, thousands of particles within NEAR_RADII of
    each seed, fast relative speeds; pairs bound near their threshold at every distance), the screen
    finds exactly the particles of its definition, and the finder the same clusters with it as
    without it."""
    from decco_warp.analysis import clusters as finder

    pile = dw.load_pile(builtin_pile("target"))
    state = _combine(*(_moved(pile, (k * 8 * pile_radius(pile), 0, 0), (0, 0, 0)) for k in range(8)))
    state = _debris_field(state, seed)
    x, v, m, radii = state.positions, state.velocities, state.masses, state.radii
    alone = finder._alone(x, v, m, radii, finder.contact_graph(x, radii), dw.G_CGS)
    oracle = _alone_oracle(state)
    assert np.array_equal(alone, oracle)
    assert 200 < alone.sum() < state.n - 100  # most particles lone, the near-threshold pairs split between bound and not
    screened = dw.find_clusters(state, min_members=2)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(finder, "_alone", lambda x, *rest: np.zeros(len(x), dtype=bool))
        plain = dw.find_clusters(state, min_members=2)
    assert [c.members.tolist() for c in screened] == [c.members.tolist() for c in plain]
    assert len(plain) >= 20


def _clumps(centre, spread, count, size, speed, seed):
    """``count`` clumps of ``size`` touching grains each (a row 1.99 radii apart), scattered within
    ``spread`` of ``centre`` with random velocities of ~``speed`` (add a bulk velocity with _moved):
    debris that falls short of 20."""
    rng = np.random.default_rng(seed)
    radius = 1e5
    parts = []
    for _ in range(count):
        start = np.asarray(centre) + rng.uniform(-spread, spread, size=3)
        row = start + 1.99 * radius * np.arange(size)[:, None] * np.array([1.0, 0.0, 0.0])
        parts.append(_grains(row, rng.normal(scale=speed, size=3), radius))
    return _combine(*parts)


def test_escape_speed_screen_changes_no_cluster(piles, monkeypatch):
    """A small group's escape-speed test asks k-d trees which free particles could pass it (those
    within the reach of its 64th nearest, or slower than escape from there); the finder with that
    screen on every test finds the same clusters, member for member, as with every free particle
    scanned, on a pile with slow and fast escapers, a sparse cluster behind a dense group, and 60
    small clumps of debris (each a failed seed)."""
    from decco_warp.analysis import clusters as finder

    target, projectile = piles
    distance = 3 * (pile_radius(target) + pile_radius(projectile))
    state = _combine(
        target,
        _escapers(target, 60, 2.0, seed=3),
        _escapers(target, 60, 0.7, seed=5),
        _moved(_sparse_and_dense(offset=(4e7, 0, 0), velocity=(45.0, 0, 0)), (50 * distance, 0, 0),
               (3 * _escape_speed(target, 50 * distance), 0, 0)),
        _moved(_clumps(target.centre_of_mass + np.array([0.0, 20 * distance, 0.0]), 5 * distance, 60, 4, 30.0, seed=7),
               (0, 0, 0), (0, 3 * _escape_speed(target, 15 * distance), 0)),
    )
    screened_groups = []
    could_bind = finder._FreeParticles.could_bind

    def counted(self, *args):
        found = could_bind(self, *args)
        screened_groups.append(found is not None)
        return found

    monkeypatch.setattr(finder._FreeParticles, "could_bind", counted)
    monkeypatch.setattr(finder, "_SCAN_BELOW", 0)
    screened = dw.find_clusters(state, min_members=20)
    assert sum(screened_groups) >= 60  # the screen answered for every clump at least
    monkeypatch.setattr(finder, "_SCAN_BELOW", 10**9)
    plain = dw.find_clusters(state, min_members=20)
    assert [c.members.tolist() for c in screened] == [c.members.tolist() for c in plain]
    sizes = [c.members.size for c in plain]
    assert sizes == [target.n + 60, 100, 20]  # pile + slow escapers, sparse, dense (45 cm/s apart, moving off): the clumps make none


def test_escape_speed_screen_holds_every_particle_a_group_binds():
    """could_bind returns a superset of the free particles that pass |v - V|^2 |x - X| < 2 G M,
    checked in float64 for groups from a grain's mass to a pile's, at random centres."""
    from decco_warp.analysis import clusters as finder

    rng = np.random.default_rng(11)
    n = 6000
    x = rng.normal(scale=1e8, size=(n, 3))
    v = rng.normal(scale=50.0, size=(n, 3))
    free = finder._FreeParticles(x, v, np.ones(n, dtype=bool))
    answered = binding = 0
    for mass in np.geomspace(1e16, 1e22, 13):
        for _ in range(5):
            com, velocity = x[rng.integers(n)] + rng.normal(scale=1e6, size=3), rng.normal(scale=50.0, size=3)
            bound = np.flatnonzero(((v - velocity) ** 2).sum(axis=1) * np.linalg.norm(x - com, axis=1) < 2 * dw.G_CGS * mass)
            found = free.could_bind(com, velocity, mass, dw.G_CGS)
            if found is None:
                continue
            answered += 1
            binding += bound.size > 0
            assert np.isin(bound, found).all()
            assert found.size <= n // 2
    assert answered >= 20 and binding >= 10  # most groups screened, many of them binding someone


def _alone_by_shells(x, v, m, radii, contacts, G):
    """The lone-seed screen as first written, the reference for its per-seed reach: every seed
    paired with the particles it could bind by the heaviest mass, shell by shell over every
    particle (six-dimensional box queries), then the exact test."""
    from scipy.spatial import cKDTree

    from decco_warp.analysis import clusters as finder

    alone = contacts.getnnz(axis=1) == 0
    near, reach = finder.NEAR_RADII * radii.max(), 2 * G * m.max()
    second, _ = cKDTree(v).query(v, k=2, distance_upper_bound=np.nextafter(math.sqrt(reach / near), np.inf))
    alone &= ~np.isfinite(second[:, 1])
    seeds = np.flatnonzero(alone)

    def ball(points, radius, p=2.0):
        around = cKDTree(points).query_ball_point(points[seeds], r=radius, p=p)
        return np.stack([np.repeat(seeds, [len(a) for a in around]), np.concatenate([np.asarray(a, dtype=np.int64) for a in around] + [np.zeros(0, np.int64)])])

    closest, widen = 2 * radii.min(), finder._WIDEN
    pairs, inner = [ball(x, closest * widen)], closest / widen
    while inner < near:
        pairs.append(ball(np.hstack([x / (2 * inner), v / math.sqrt(reach / inner)]), widen, p=np.inf))
        inner *= 2
    s, j = np.concatenate(pairs, axis=1)
    distance, speed2 = np.linalg.norm(x[j] - x[s], axis=1), ((v[j] - v[s]) ** 2).sum(axis=1)
    binds = np.zeros(len(m), dtype=bool)
    binds[s[(s != j) & (distance <= near) & (speed2 * distance < 2 * G * m[s])]] = True
    return alone & ~binds


def _remnant_in_debris(seed):
    """A compact remnant at rest (the shipped target: touching grains, and its co-moving neighbours)
    beside a debris cloud of six piles (:func:`_debris_field`, near-threshold pairs included)."""
    pile = dw.load_pile(builtin_pile("target"))
    cloud = _combine(*(_moved(pile, (k * 8 * pile_radius(pile), 0, 0), (0, 0, 0)) for k in range(1, 7)))
    return _combine(pile, _debris_field(cloud, seed, pairs=60))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_lone_seeds_by_each_seeds_reach_are_those_of_the_shells_over_every_particle(seed, monkeypatch):
    """The lone-seed screen pairs a seed only with the particles within the reach its slowest
    neighbour allows (2 G m_s / u_s^2), crowded seeds shell by shell: on debris fields with and
    without a remnant, every seed sent either way or as it comes (_CROWDED), it finds the lone seeds
    that the shells over every particle with the heaviest mass find, and the finder the same
    clusters with every screen as with none."""
    from decco_warp.analysis import clusters as finder

    pile = dw.load_pile(builtin_pile("target"))
    fields = [_debris_field(_combine(*(_moved(pile, (k * 8 * pile_radius(pile), 0, 0), (0, 0, 0)) for k in range(8))), seed), _remnant_in_debris(seed)]
    for state in fields:
        x, v, m, radii = state.positions, state.velocities, state.masses, state.radii
        contacts = finder.contact_graph(x, radii)
        reference = _alone_by_shells(x, v, m, radii, contacts, dw.G_CGS)
        assert 200 < reference.sum() < state.n - 100
        for crowded in (0, finder._CROWDED, 10**9):
            monkeypatch.setattr(finder, "_CROWDED", crowded)
            assert np.array_equal(finder._alone(x, v, m, radii, contacts, dw.G_CGS), reference)
    monkeypatch.undo()
    state = fields[1]
    screened = [c.members.tolist() for c in dw.find_clusters(state, min_members=20)]
    monkeypatch.setattr(finder, "_alone", lambda x, *rest: np.zeros(len(x), dtype=bool))
    monkeypatch.setattr(finder, "_SCAN_BELOW", 10**9)
    assert [c.members.tolist() for c in dw.find_clusters(state, min_members=20)] == screened
    assert screened and len(screened[0]) >= pile.n  # the remnant is found


@pytest.mark.parametrize("seed, values", [(0, 40), (1, 40), (2, 1)])
def test_seeds_come_in_the_order_of_argmax_over_the_particles_that_may_still_seed(seed, values):
    """The finder's seed queue hands out, one by one, what np.argmax of the density over the
    particles that may still seed gives (ties to the lowest index), in batches smaller than the
    ties (densities of a few values): with particles struck off between draws as short groups
    strike theirs, and the densities changed (reset) as a cluster's are taken off."""
    from decco_warp.analysis import clusters as finder

    rng = np.random.default_rng(seed)
    n = 3000
    density = rng.integers(0, values, size=n).astype(float)  # ~75 particles a value, or one for all: ties across every batch edge
    may_seed = rng.random(n) < 0.9
    reference = may_seed.copy()
    queue = finder._SeedQueue(may_seed, density)
    drawn = 0
    while True:
        got = queue.next()
        candidates = np.flatnonzero(reference)
        want = int(candidates[np.argmax(density[candidates])]) if candidates.size else None
        assert got == want
        if got is None:
            break
        drawn += 1
        struck = np.unique(np.concatenate([[got], rng.integers(0, n, size=rng.integers(0, 4))]))
        may_seed[struck] = reference[struck] = False
        if drawn % 97 == 0 and values > 1:  # a cluster taken: the densities change
            density -= rng.integers(0, 3, size=n)
            queue.reset()
    assert drawn > 100 and not reference.any()

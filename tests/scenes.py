"""Small particle scenes for tests, built with a seeded RNG.

Particle radii are the paper's three classes, density 2.7 g/cm^3: a pile of
these is ~1e7 cm across while contact overlaps are ~1e2 cm, the regime where
float32 positions fail.
"""

import numpy as np

import decco_warp as dw

RHO = 2.7
RADII = np.array([0.75e6, 1.5e6, 2.25e6])


def sphere_mass(radius):
    return 4.0 / 3.0 * np.pi * RHO * np.asarray(radius, dtype=float) ** 3


def contact_cluster(n, seed, overlap_range=(1.0, 1e3), offset=(2.0e7, -1.0e7, 5.0e6), speed=10.0, spin=1e-4):
    """A connected clump: each new sphere touches a random earlier one with a small overlap.

    Overlaps of the building contacts are drawn log-uniformly from ``overlap_range``
    [cm]; a new sphere that would overlap any other by more than the range is
    redrawn.  Velocities ~ ``speed`` cm/s and spins ~ ``spin`` rad/s, random.
    Returns a State whose centre sits at ``offset`` (far from the origin, so that
    absolute positions are large as in a collision).
    """
    rng = np.random.default_rng(seed)
    radii = rng.choice(RADII, size=n, p=[0.6, 0.25, 0.15])
    x = np.zeros((n, 3))
    lo, hi = np.log(overlap_range[0]), np.log(overlap_range[1])
    for k in range(1, n):
        for _ in range(1000):
            anchor = rng.integers(0, k)
            direction = rng.normal(size=3)
            direction /= np.linalg.norm(direction)
            delta = np.exp(rng.uniform(lo, hi))
            candidate = x[anchor] + (radii[anchor] + radii[k] - delta) * direction
            gaps = np.linalg.norm(x[:k] - candidate, axis=1) - (radii[:k] + radii[k])
            if gaps.min() >= -overlap_range[1]:
                x[k] = candidate
                break
        else:
            raise RuntimeError("could not place a sphere")
    x += np.asarray(offset) - x.mean(axis=0)
    v = rng.normal(size=(n, 3)) * speed
    w = rng.normal(size=(n, 3)) * spin
    return dw.State.from_arrays(x, v, w, radii, sphere_mass(radii))


def overlapping_cloud(n, seed, fill=0.6):
    """Random polydisperse spheres packed densely at random: many contacts, some deep."""
    rng = np.random.default_rng(seed)
    radii = rng.choice(RADII, size=n)
    volume = (4.0 / 3.0 * np.pi * radii**3).sum() / fill
    extent = (3.0 * volume / (4.0 * np.pi)) ** (1.0 / 3.0)
    direction = rng.normal(size=(n, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    x = direction * extent * rng.uniform(size=(n, 1)) ** (1.0 / 3.0) + np.array([1.0e7, 3.0e6, -2.0e7])
    v = rng.normal(size=(n, 3)) * 1e3
    w = rng.normal(size=(n, 3)) * 1e-3
    return dw.State.from_arrays(x, v, w, radii, sphere_mass(radii))


def two_spheres(separation, velocity_i, velocity_j=(0, 0, 0), omega_i=(0, 0, 0), omega_j=(0, 0, 0), radius=1.5e6):
    """Two equal spheres on the x axis, ``separation`` apart (centre to centre)."""
    x = np.array([[-separation / 2, 0, 0], [separation / 2, 0, 0]], dtype=float)
    v = np.array([velocity_i, velocity_j], dtype=float)
    w = np.array([omega_i, omega_j], dtype=float)
    radii = np.full(2, radius)
    return dw.State.from_arrays(x, v, w, radii, sphere_mass(radii))


def crowded_sphere(count, seed=4):
    """A large sphere touched by ``count`` small ones all round it (overlaps of 500 cm), random
    velocities and spins: more contacts on one particle than a candidate list holds."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    x = np.vstack([[0.0, 0.0, 0.0], direction * (2.25e6 + 0.75e6 - 500.0)]) + 1.5e7
    radii = np.array([2.25e6] + [0.75e6] * count)
    return dw.State.from_arrays(x, rng.normal(size=(count + 1, 3)), rng.normal(size=(count + 1, 3)) * 1e-4, radii, sphere_mass(radii))


def oracle_args(state, params):
    return (
        state.positions,
        state.velocities,
        state.omegas,
        state.radii,
        state.masses,
        params.k_in,
        params.restitution,
        params.mu_k,
        params.mu_r,
        params.G,
    )


def approaching_clumps(n=15, gap=10.0, approach=300.0, seed=3):
    """Two :func:`contact_cluster` clumps of ``n`` (internal speeds ~20 cm/s), the second beside the
    first along x with their nearest spheres ``gap`` cm apart, approaching at ``approach`` cm/s each:
    contacts inside each clump break as it flies apart, and contacts between them form."""
    from scipy.optimize import brentq

    a = contact_cluster(n, seed=seed, speed=20.0)
    b = contact_cluster(n, seed=seed + 1, speed=20.0)
    centred = b.positions - b.positions.mean(axis=0) + a.positions.mean(axis=0)

    def nearest_gap(shift):
        moved = centred + [shift, 0.0, 0.0]
        return (np.linalg.norm(a.positions[:, None] - moved[None], axis=2) - (a.radii[:, None] + b.radii[None])).min()

    shift = brentq(lambda s: nearest_gap(s) - gap, 0.0, 1e9)
    x = np.vstack([a.positions, centred + [shift, 0.0, 0.0]])
    v = np.vstack([a.velocities + [approach, 0.0, 0.0], b.velocities - [approach, 0.0, 0.0]])
    return dw.State.from_arrays(x, v, np.vstack([a.omegas, b.omegas]), np.concatenate([a.radii, b.radii]), np.concatenate([a.masses, b.masses]))

"""The cluster finder of paper sect. 2.7, exactly as docs/model.md states it.

1. Smooth the mass with a Gaussian of standard deviation 10 R_k around each
   particle k; the seed is the particle where the smoothed density is highest.
2. Add every particle in contact (delta >= 0) with a member; repeat until none is added.
3. Add every particle slower, relative to the cluster's centre of mass, than the
   escape speed sqrt(2 G M / |x - x_cm|); repeat until none is added (mass and
   centre of mass updated as members join).  Back to 2 while 3 added anyone.
4. Repeat 1-3 on the particles left.  A seed whose group ends with fewer than
   ``min_members`` members makes no cluster: its particles stay free to join a later
   cluster but never seed again.  Stop when no free particle is left to seed.  (Stopping at
   the first short group, the literal reading of the paper, loses the remnant whenever a
   small dense group holds the density peak.)

Vectorised: contacts come from a k-d tree (scipy.spatial.cKDTree) as a sparse
graph, growth follows the newcomers' contacts, binding is one array test per pass, over
the free particles that k-d trees of positions and velocities say could pass it (a
debris cloud's thousands of failed seeds each cost their neighbourhood, not O(N)).
The smoothed density, O(N^2), runs in NumPy on the CPU's cores, or on a GPU when
given one (``device="cuda"``: 1e5 particles in a fraction of a second instead of
half a minute on 16 cores).
"""

from __future__ import annotations

import itertools
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ..params import G_CGS
from ..processes import usable_cores
from ..state import State
from ..errors import InputError

#: The Gaussian's standard deviation, in particle radii (paper sect. 2.7).
SMOOTHING_RADII = 10.0
#: Pairs closer than this many of the largest radius are tested for binding one by one when screening
#: seeds that would stand alone (:func:`_alone`); farther ones by their relative speed.
NEAR_RADII = 20.0
#: Elements of the pairwise density sum handled at once (8 bytes each): 8 MB stays in cache
#: (20 000 particles: 0.9 s a frame on 2 cores, against 2.3 s for rows of 1024 at once).
_CHUNK_ELEMENTS = 2**20


@dataclass
class Cluster:
    """A gravitationally bound clump of particles."""

    members: np.ndarray
    """Indices of the member particles, increasing."""
    mass: float
    """Total mass [g]."""
    com: np.ndarray
    """Centre of mass [cm], (3,)."""
    velocity: np.ndarray
    """Velocity of the centre of mass [cm/s], (3,)."""


def smoothed_density(
    positions: np.ndarray, masses: np.ndarray, sigmas: np.ndarray, at: np.ndarray | None = None, device: str | None = None
) -> np.ndarray:
    """sum_j m_j N(y - x_j; sigma_j) at the points ``at`` (default: the particles themselves) [g/cm^3].

    The sum runs over the particles given (a particle's own mass included at its position).
    ``device``: None or "cpu" sums in NumPy; a CUDA device ("cuda", "cuda:1") in a Warp kernel there.
    """
    at = positions if at is None else at
    norm = masses / ((2.0 * math.pi) ** 1.5 * sigmas**3)
    inv_two_var = 0.5 / sigmas**2
    if device is not None and str(device).startswith("cuda"):
        from ..engine import smoothed_density as on_device

        return on_device(positions, norm, inv_two_var, at, device)
    # |a - b|^2 = |a|^2 + |b|^2 - 2 a.b through BLAS; centring first keeps the cancellation
    # error (~1e-16 of |x|^2) far below sigma^2 ~ (10 R)^2.
    centre = positions.mean(axis=0)
    sources = positions - centre
    targets = at - centre
    source_square = (sources * sources).sum(axis=1)
    target_square = (targets * targets).sum(axis=1)
    density = np.empty(targets.shape[0])
    # O(N^2) work (the Gaussian is 10 radii wide: it reaches across a whole pile), in blocks of
    # rows small enough to stay in cache, the blocks shared among the cores (NumPy lets go of the
    # GIL in exp and matmul): 1e5 particles take seconds a frame, not minutes.
    rows = max(1, _CHUNK_ELEMENTS // max(1, sources.shape[0]))

    def block(start: int) -> None:
        exponent = targets[start : start + rows] @ sources.T
        exponent *= -2.0
        exponent += target_square[start : start + rows, None]
        exponent += source_square[None, :]
        np.maximum(exponent, 0.0, out=exponent)
        exponent *= -inv_two_var[None, :]
        np.exp(exponent, out=exponent)
        density[start : start + rows] = exponent @ norm

    starts = range(0, targets.shape[0], rows)
    threads = usable_cores()  # an analysis worker's share of them
    if len(starts) < 4 or threads == 1:
        for start in starts:
            block(start)
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            list(pool.map(block, starts))
    return density


def contact_graph(positions: np.ndarray, radii: np.ndarray, tree: cKDTree | None = None) -> sparse.csr_matrix:
    """Symmetric adjacency of the pairs in contact (delta >= 0); ``tree``: a k-d tree of ``positions``, if made."""
    n = positions.shape[0]
    pairs = (cKDTree(positions) if tree is None else tree).query_pairs(r=2.0 * radii.max(), output_type="ndarray")
    if pairs.size:
        i, j = pairs[:, 0], pairs[:, 1]
        touching = np.linalg.norm(positions[i] - positions[j], axis=1) <= radii[i] + radii[j]
        i, j = i[touching], j[touching]
    else:
        i = j = np.zeros(0, dtype=np.int64)
    data = np.ones(2 * i.size, dtype=np.int8)
    return sparse.csr_matrix((data, (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(n, n))


def find_clusters(state: State, min_members: int = 50, G: float = G_CGS, device: str | None = None) -> list[Cluster]:
    """Clusters of ``state`` (paper sect. 2.7), largest mass first; ``device`` as for
    :func:`smoothed_density`.

    >>> clusters = find_clusters(state, min_members=50)
    >>> largest = clusters[0]; largest.mass, largest.members.size
    """
    if isinstance(min_members, bool) or not isinstance(min_members, (int, np.integer)) or min_members < 1:
        raise InputError(f"min_members must be an integer >= 1; got {min_members!r}")
    x, v, m, radii = state.positions, state.velocities, state.masses, state.radii
    n = state.n
    trees = _Trees(x, v)  # of every particle, made once: the contacts, the lone-seed screen and the first binding tests ask them
    contacts = contact_graph(x, radii, trees.positions)
    sigmas = SMOOTHING_RADII * radii
    # The density of the particles left: computed once, then each cluster's share is taken off.
    density = smoothed_density(x, m, sigmas, device=device)
    left = np.ones(n, dtype=bool)  # free: in no cluster yet
    free_count = n
    may_seed = np.ones(n, dtype=bool)  # free and never in a group that fell short
    if min_members > 1:  # a particle whose group is itself alone falls short wherever it is met
        may_seed &= ~_alone(x, v, m, radii, contacts, G, trees)
    clusters: list[Cluster] = []
    free = _FreeParticles(x, v, left, trees)
    seeds = _SeedQueue(may_seed, density)
    # The group being grown, as flags (reset after each group: a debris frame tries thousands of
    # short ones, each in O(its size) rather than O(N)) and as its sorted indices.
    member = np.zeros(n, dtype=bool)
    while free_count >= min_members:
        seed = seeds.next()
        if seed is None:
            break
        member[seed] = True
        indices = np.array([seed])
        frontier = indices
        while True:
            indices = _grow_by_contact(member, left, contacts, indices, frontier)
            before = indices
            indices = _bind_by_escape_speed(member, left, x, v, m, G, free, indices)
            if indices.size == before.size:
                break
            frontier = np.setdiff1d(indices, before, assume_unique=True)
        member[indices] = False
        if indices.size < min_members:
            may_seed[indices] = False  # free to join a later cluster, never a seed again
            continue
        mass = float(m[indices].sum())
        clusters.append(
            Cluster(
                members=indices,
                mass=mass,
                com=(m[indices, None] * x[indices]).sum(axis=0) / mass,
                velocity=(m[indices, None] * v[indices]).sum(axis=0) / mass,
            )
        )
        left[indices] = False
        may_seed[indices] = False
        free_count -= indices.size
        if free_count < free.indices.size // 2:  # the trees may hold taken particles (screened out); not too many
            free = _FreeParticles(x, v, left)
        rest = np.flatnonzero(left)
        if rest.size:
            density[rest] -= smoothed_density(x[indices], m[indices], sigmas[indices], at=x[rest], device=device)
            seeds.reset()
    clusters.sort(key=lambda c: (-c.mass, c.members[0]))
    return clusters


class _SeedQueue:
    """The particles that may seed a cluster, highest density first, ties by lowest index (as
    np.argmax over them picks): the seed of each group in turn.  Taken in batches of the BATCH
    densest, so that a run of short groups costs O(N) a batch rather than a seed; :meth:`reset` once
    the densities change (a cluster taken off them).  ``may_seed`` and ``density`` are the caller's,
    read as they are when a batch is drawn (a particle that may no longer seed is skipped)."""

    BATCH = 256

    def __init__(self, may_seed: np.ndarray, density: np.ndarray):
        self.may_seed, self.density = may_seed, density
        self.reset()

    def reset(self) -> None:
        self.below = math.inf  # the next batch: densities under this one
        self.batch: list[int] = []
        self.at = 0

    def next(self) -> int | None:
        """The next seed, or None when no particle may seed."""
        while True:
            while self.at < len(self.batch):
                seed = self.batch[self.at]
                self.at += 1
                if self.may_seed[seed]:
                    return seed
            candidates = np.flatnonzero(self.may_seed)
            candidates = candidates[self.density[candidates] < self.below]
            if candidates.size == 0:
                return None
            values = self.density[candidates]
            if candidates.size > self.BATCH:  # the BATCH densest, and every one equal to the last of them
                cut = np.partition(values, candidates.size - self.BATCH)[candidates.size - self.BATCH]
                keep = values >= cut
                candidates, values = candidates[keep], values[keep]
            order = np.lexsort((candidates, -values))
            self.batch, self.at = candidates[order].tolist(), 0
            self.below = float(values.min())


class _Trees:
    """k-d trees of a frame's positions and velocities, each made when first asked."""

    def __init__(self, x: np.ndarray, v: np.ndarray):
        self.x, self.v = x, v
        self._positions: cKDTree | None = None
        self._velocities: cKDTree | None = None

    @property
    def positions(self) -> cKDTree:
        if self._positions is None:
            self._positions = cKDTree(self.x)
        return self._positions

    @property
    def velocities(self) -> cKDTree:
        if self._velocities is None:
            self._velocities = cKDTree(self.v)
        return self._velocities


def _alone(x: np.ndarray, v: np.ndarray, m: np.ndarray, radii: np.ndarray, contacts: sparse.csr_matrix, G: float,
           trees: _Trees | None = None) -> np.ndarray:  # fmt: skip
    """Particles whose group, seeded by them alone, stays themselves: they touch nobody and bind
    nobody by their own escape speed (|v_j - v_s|^2 < 2 G m_s / |x_j - x_s|).  Such a seed falls
    short of any minimum above 1, before or after other clusters take their members, so it is
    never tried (a dispersed debris cloud has thousands of them, each an O(N) pass otherwise).

    Bound pairs within NEAR_RADII of the largest radius are tested exactly; a farther one needs
    |v_j - v_s| below sqrt(2 G m_max / that distance), so a particle with any other particle that
    slow relative to it is kept as a possible seed (conservative: it may still fall short)."""
    n = m.size
    alone = contacts.getnnz(axis=1) == 0
    near = NEAR_RADII * float(radii.max())
    reach = 2.0 * G * float(m.max())
    slow = math.sqrt(reach / near)
    # Another particle within ``slow`` in velocity space (itself is the nearest, at 0): the second
    # nearest, found or not, rather than counting every particle of a co-moving remnant.  Tested
    # first: it is cheap, and it clears the particles of a compact remnant that touch nobody (each
    # has thousands within NEAR_RADII: 2.5e7 pairs in a 100 000-particle remnant otherwise).
    trees = _Trees(x, v) if trees is None else trees
    second, _ = trees.velocities.query(v, k=2, distance_upper_bound=np.nextafter(slow, np.inf))
    alone &= ~np.isfinite(second[:, 1])
    seeds = np.flatnonzero(alone)
    if seeds.size:
        s, j = _pairs_that_could_bind(x, v, m, seeds, trees, 2.0 * float(radii.min()), near, G)
        distance = np.linalg.norm(x[j] - x[s], axis=1)
        speed2 = ((v[j] - v[s]) ** 2).sum(axis=1)
        binds = np.zeros(n, dtype=bool)
        binds[s[(distance <= near) & (speed2 * distance < 2.0 * G * m[s])]] = True
        alone &= ~binds
    return alone


def _pairs_that_could_bind(x, v, m, seeds: np.ndarray, trees: _Trees, closest: float, near: float, G: float):
    """Pairs (seed s, other j) holding every pair within ``near`` with |v_j - v_s|^2 |x_j - x_s| <
    2 G m_s, for seeds that touch nobody, so that no j lies closer than ``closest`` (the smallest
    sum of two radii); ``trees``: those of ``x`` and ``v``.

    No j is slower relative to s than u_s, the distance to s's nearest other particle in velocity
    space, so a pair binds only within far_s = 2 G m_s / u_s^2: a debris cloud's seeds, fast
    relative to all others, each need the few particles of that ball (a light seed's is a few
    radii: every other particle is at least ``slow`` of :func:`_alone` away).  A seed whose ball
    holds more than _CROWDED particles (a heavy one with a slow neighbour, in a dense cloud) is
    paired instead shell by shell: a pair at a distance in [D, 2 D] can bind only below
    sqrt(2 G m_s / D) in relative speed, so each such shell is one box query of a k-d tree in six
    dimensions, positions over 2 D and velocities over that speed (few pairs, where all within
    ``near`` can be ~1e7 a frame).  Pairs closer than ``closest`` (none where the contact graph is
    right) are found by position alone."""
    nearest, _ = trees.velocities.query(v[seeds], k=2)  # itself, then u_s
    with np.errstate(divide="ignore"):
        # Widened for rounding twice: u_s from the tree against |v_j - v_s| in NumPy, then the
        # tree's distances against np.linalg.norm.
        far = np.minimum(near, 2.0 * G * m[seeds] / nearest[:, 1] ** 2 * _WIDEN) * _WIDEN
    positions = trees.positions
    few = positions.query_ball_point(x[seeds], r=far, return_length=True) <= _CROWDED
    pairs = [_ball_pairs(positions, x[seeds[few]], far[few], seeds[few])]
    crowded = seeds[~few]
    if crowded.size:
        pairs.append(_ball_pairs(positions, x[crowded], closest * _WIDEN, crowded))
        reach = 2.0 * G * float(m[crowded].max())
        farthest = float(far[~few].max())
        inner = closest / _WIDEN
        while inner < farthest:
            outer = min(2.0 * inner, farthest)
            speed = math.sqrt(reach / inner)
            points = np.hstack([x / outer, v / speed])
            pairs.append(_ball_pairs(cKDTree(points), points[crowded], _WIDEN, crowded, p=np.inf))
            inner = 2.0 * inner
    s, j = np.concatenate(pairs, axis=1)
    other = s != j
    return s[other], j[other]


def _ball_pairs(tree: cKDTree, centres: np.ndarray, radius, owners: np.ndarray, p: float = 2.0) -> np.ndarray:
    """(2, pairs): the owner of each of ``centres`` with every point j of ``tree`` within ``radius``
    of it (one for all, or one a centre; Minkowski ``p``-norm)."""
    around = tree.query_ball_point(centres, r=radius, p=p)
    lengths = np.fromiter(map(len, around), dtype=np.int64, count=len(around))
    # One array from the lists at once (concatenating an array per centre costs several times more).
    j = np.fromiter(itertools.chain.from_iterable(around), dtype=np.int64, count=int(lengths.sum()))
    return np.stack([np.repeat(owners.astype(np.int64), lengths), j])


#: A seed whose ball of possible partners (:func:`_pairs_that_could_bind`) holds more particles than
#: this is paired shell by shell instead.
_CROWDED = 1024


class _FreeParticles:
    """The particles in no cluster yet when made, with k-d trees of their positions and velocities
    (built when first asked; ``every``: the frame's, used while all are free): a small group's
    escape-speed test looks only at those that could pass it.  Particles taken since stay in the
    trees; callers screen them out with ``left``."""

    def __init__(self, x: np.ndarray, v: np.ndarray, left: np.ndarray, every: _Trees | None = None):
        self.indices = np.flatnonzero(left)
        self.x, self.v = x[self.indices], v[self.indices]
        self._trees: tuple[cKDTree, cKDTree] | None = None
        if every is not None and self.indices.size == left.size:  # all free: the frame's own trees
            self._trees = (every.positions, every.velocities)

    def trees(self) -> tuple[cKDTree, cKDTree]:
        if self._trees is None:
            self._trees = (cKDTree(self.x), cKDTree(self.v))
        return self._trees

    def could_bind(self, com: np.ndarray, velocity: np.ndarray, mass: float, G: float) -> np.ndarray | None:
        """The free particles that a group of ``mass`` at (com, velocity) could bind, a superset of
        those it does (indices into the whole system), or None where that is most of them.

        |v - V|^2 |x - X| < 2 G M holds only within a distance D of the centre, or below
        sqrt(2 G M / D) in relative speed beyond it, for any D > 0; D is the distance to the centre's
        _NEAR_COUNT-th nearest particle, so that those within it are the nearest found, and the
        speed is widened by 1e-6 so that rounding never drops a particle the exact test takes.
        The nearest are asked once, as an array (not counted, then listed)."""
        count = self.indices.size
        if count < max(_SCAN_BELOW, _NEAR_COUNT):
            return None
        positions, velocities = self.trees()
        distance, close = positions.query(com, k=_NEAR_COUNT)
        near = float(distance[-1])
        if near == 0.0:  # the nearest all at the centre: no speed bound from there
            return None
        slow = math.sqrt(2.0 * G * mass / near) * _WIDEN
        if velocities.query_ball_point(velocity, slow, return_length=True) > count // 4:
            return None
        slow_ones = velocities.query_ball_point(velocity, slow)
        return self.indices[np.union1d(close, np.asarray(slow_ones, dtype=np.int64))]


#: Below this many free particles the escape-speed test scans them all; above it, a small group's
#: test first asks the k-d trees which could pass (:meth:`_FreeParticles.could_bind`): ~0.1 ms a test
#: either way at 1 000 free particles, the scan 2x and 3x the screen at 2 000 and 4 000 (2 CPU cores).
_SCAN_BELOW = 1024
#: The near reach of that screen: the distance to the group centre's this-many-th nearest free particle.
_NEAR_COUNT = 64
_WIDEN = 1.0 + 1e-6


def _grow_by_contact(member: np.ndarray, left: np.ndarray, contacts: sparse.csr_matrix, group: np.ndarray,
                     frontier: np.ndarray) -> np.ndarray:  # fmt: skip
    """Step 2: add every unassigned particle touching a member, until none is added; ``group``: the
    members' sorted indices (flagged in ``member``), ``frontier``: those whose contacts are not yet
    looked at.  Each pass looks at the last pass's newcomers' contacts only (O(their contacts), not
    O(N)).  Returns the group's sorted indices."""
    indptr, indices = contacts.indptr, contacts.indices
    added = []
    while frontier.size:
        starts, ends = indptr[frontier], indptr[frontier + 1]
        lengths = ends - starts
        total = int(lengths.sum())
        if total == 0:
            break
        # Every newcomer's contacts, their CSR ranges laid end to end.
        offsets = np.repeat(starts - np.cumsum(lengths) + lengths, lengths) + np.arange(total)
        reached = indices[offsets]
        reached = np.unique(reached[left[reached] & ~member[reached]])
        member[reached] = True
        added.append(reached)
        frontier = reached
    return np.union1d(group, np.concatenate(added)) if added else group


def _bind_by_escape_speed(member, left, x, v, m, G, free: _FreeParticles | None, group: np.ndarray) -> np.ndarray:
    """Step 3: add every unassigned particle below the escape speed, until none is added.
    ``free``: the particles of ``left`` with their trees, to screen a small group's candidates;
    ``group``: the members' sorted indices (flagged in ``member``).

    Returns the group's sorted indices (the same array where nobody joined).
    """
    while True:
        idx = group  # sorted, as np.flatnonzero(member): the sums below in the same order
        mass = m[idx].sum()
        com = (m[idx, None] * x[idx]).sum(axis=0) / mass
        velocity = (m[idx, None] * v[idx]).sum(axis=0) / mass
        screened = free.could_bind(com, velocity, float(mass), G) if free is not None else None
        if screened is None:
            candidates = np.flatnonzero(left & ~member)
        else:
            candidates = screened[left[screened] & ~member[screened]]
        if candidates.size == 0:
            return group
        distance = np.linalg.norm(x[candidates] - com, axis=1)
        speed2 = ((v[candidates] - velocity) ** 2).sum(axis=1)
        with np.errstate(divide="ignore"):
            bound = speed2 < 2.0 * G * mass / distance
        if not bound.any():
            return group
        member[candidates[bound]] = True
        group = np.union1d(group, candidates[bound])

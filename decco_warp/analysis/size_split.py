"""Fig. 6's size change split in two: what where a grain started explains, and what sorting by size
explains among grains that started alike (docs/validation.md, Fig. 6).

A pile's outer layers hold smaller grains than its mean (large grains cannot sit at the surface), so
a fragment that loses its piles' surfaces grows its mean grain with no sorting by size at all.  The
null model here is depth-conditional and size-blind: a grain's chance of ending in the fragment may
depend on its pile and on its starting shell (its depth, the distance from its pile's centre of
mass, cut into shells of equal mass) but not on its size within that shell.  Each shell's chance is
the run's own fraction of the shell's grains that ended in the fragment, so the model keeps the
fragment's grains per shell and draws them from the shell blind to size.  The model's size change is
the depth part; the observed minus the model's is the sorting part.

Both of the summaries' measures are split (:func:`.runs.particle_size_change`, per particle: the
fragment's mean grain mass; :func:`.runs.mass_weighted_size_change`, by mass: sum m^2 / sum m), each
as a change in % against both piles' grains before the collision.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..checks import InputError
from .compare import t_half_width
from .runs import _percent_change, mass_weighted_size_change, particle_size_change


def depth_shells(positions: np.ndarray, masses: np.ndarray, shells: int) -> np.ndarray:
    """Each grain's shell (0 the innermost, ``shells`` - 1 the outermost) by its distance from the
    pile's centre of mass: the grains ranked by distance and cut where the mass below a grain's
    middle passes each 1/``shells`` of the pile's mass, so each shell holds about an equal mass.
    A rotation of the pile about its centre leaves the shells as they are."""
    positions, masses = np.asarray(positions, dtype=float), np.asarray(masses, dtype=float)
    if shells < 1 or positions.shape != (masses.size, 3):
        raise InputError(f"depth_shells needs shells >= 1 and positions of shape (n, 3) for n masses; got {shells}, {positions.shape}")
    centre = masses @ positions / masses.sum()
    order = np.argsort(np.linalg.norm(positions - centre, axis=1), kind="stable")
    below_middle = np.cumsum(masses[order]) - 0.5 * masses[order]
    shell = np.empty(masses.size, dtype=np.int64)
    shell[order] = np.minimum((below_middle / masses.sum() * shells).astype(np.int64), shells - 1)
    return shell


@dataclass(frozen=True)
class SizeChangeSplit:
    """A fragment's size change [%] and its size-blind model's, per particle and by mass.
    ``null_sd``: the standard deviation [points] of the per-particle size change that drawing each
    group's fragment grains blind to size gives about the model (the noise of the sorting part)."""

    total: float
    depth: float
    total_mass_weighted: float
    depth_mass_weighted: float
    null_sd: float

    @property
    def sorting(self) -> float:
        return self.total - self.depth

    @property
    def sorting_mass_weighted(self) -> float:
        return self.total_mass_weighted - self.depth_mass_weighted


def size_change_split(masses: np.ndarray, in_fragment: np.ndarray, groups: np.ndarray) -> SizeChangeSplit:
    """The size change of the fragment ``in_fragment`` (a bool per grain) against all ``masses``,
    and that of the size-blind model where each grain of group g (``groups``: an integer per grain,
    e.g. pile and depth shell) is in the fragment with the chance p_g = the group's grains in the
    fragment over its grains.  The model keeps the fragment's count per group, so its per-particle
    mean is sum_g p_g M_g / sum_g p_g N_g (M_g, N_g: the group's mass and grains) and its mass-weighted
    one sum_g p_g Q_g / sum_g p_g M_g (Q_g: the group's sum of m^2)."""
    masses = np.asarray(masses, dtype=float)
    in_fragment = np.asarray(in_fragment, dtype=bool)
    groups = np.asarray(groups)
    if not (masses.shape == in_fragment.shape == groups.shape) or masses.ndim != 1:
        raise InputError(f"size_change_split needs one mass, fate and group per grain; got shapes {masses.shape}, {in_fragment.shape}, {groups.shape}")
    if not in_fragment.any():
        raise InputError("size_change_split: the fragment has no grain")
    _, index = np.unique(groups, return_inverse=True)
    count = np.bincount(index).astype(float)
    kept = np.bincount(index, weights=in_fragment.astype(float))
    mass = np.bincount(index, weights=masses)
    square = np.bincount(index, weights=masses**2)
    p = kept / count
    members = int(in_fragment.sum())
    parents_mean = masses.sum() / masses.size
    # Drawing k of a group's n grains blind to size: the variance of their summed mass.
    spread = np.where(count > 1, kept * (count - kept) / np.maximum(count - 1, 1) * (square / count - (mass / count) ** 2), 0.0)
    return SizeChangeSplit(
        total=particle_size_change(masses[in_fragment].sum(), members, masses.sum(), masses.size),
        depth=particle_size_change(p @ mass, members, masses.sum(), masses.size),
        total_mass_weighted=mass_weighted_size_change(masses[in_fragment], masses),
        depth_mass_weighted=_percent_change((p @ square / (p @ mass)) / (masses @ masses / masses.sum())),
        null_sd=float(100.0 * math.sqrt(max(spread.sum(), 0.0)) / members / parents_mean),
    )


def pile_shell_groups(pile_positions: list[np.ndarray], pile_masses: list[np.ndarray], shells: int) -> np.ndarray:
    """The group of each grain of the piles put one after another (a collision's order: the
    target's grains, then the projectile's): pile index * ``shells`` + its :func:`depth_shells` shell."""
    return np.concatenate([k * shells + depth_shells(x, m, shells) for k, (x, m) in enumerate(zip(pile_positions, pile_masses))])


def t_interval(values, confidence: float = 0.95) -> tuple[float, float]:
    """(mean, half-width) of Student's t ``confidence`` interval of the mean of ``values`` (>= 2)."""
    values = np.asarray(values, dtype=float)
    if values.size < 2:
        raise InputError("t_interval needs two values or more")
    return float(values.mean()), t_half_width(values, confidence)


def ratio_interval(numerators, denominators, confidence: float = 0.95) -> tuple[float, float | None, float | None]:
    """mean(numerators) / mean(denominators) of paired values, with Fieller's ``confidence``
    interval (Student's t, n - 1 degrees of freedom): (ratio, low, high), low and high None where the
    interval is unbounded (the denominators' mean not resolved from 0)."""
    a, b = np.asarray(numerators, dtype=float), np.asarray(denominators, dtype=float)
    if a.shape != b.shape or a.size < 2:
        raise InputError("ratio_interval needs two paired values or more")
    n = a.size
    q = stats.t.ppf(0.5 + confidence / 2, n - 1) ** 2 / n
    cov = np.cov(a, b, ddof=1)
    ma, mb = a.mean(), b.mean()
    # (ma - R mb)^2 <= q (s_aa - 2 R s_ab + R^2 s_bb): a quadratic A R^2 - 2 B R + C <= 0.
    A, B, C = mb**2 - q * cov[1, 1], ma * mb - q * cov[0, 1], ma**2 - q * cov[0, 0]
    ratio = float(ma / mb) if mb != 0 else math.nan
    disc = B**2 - A * C
    if A <= 0 or disc < 0:
        return ratio, None, None
    root = math.sqrt(disc)
    return ratio, float((B - root) / A), float((B + root) / A)

"""decco_warp.analysis.size_split: the size change split into what the grains' starting depth
explains and what sorting by size explains, on made-up piles whose fate depends on depth alone or on
size alone, its size-blind noise against drawing by hand, and on a committed run of Fig. 6."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from decco_warp.analysis import size_split as ss
from decco_warp.analysis.runs import mass_weighted_size_change, particle_size_change, read_analysis
from decco_warp.checks import InputError
from decco_warp.io import load_pile

ROOT = Path(__file__).parent.parent


def layered_pile(rng, n=6000, segregated=True):
    """A ball of grains of the paper's three radii (7.5, 15, 22.5 km: masses 1, 8, 27) in the paper's
    counts; ``segregated``: the large grains only in the inner 0.8 of the radius (a pile's surface
    holds small grains), else every grain anywhere."""
    counts = np.round(n * np.array([5379, 672, 199]) / 6250).astype(int)
    masses = np.repeat([1.0, 8.0, 27.0], counts)
    reach = np.where((masses > 1) & segregated, 0.8, 1.0)
    direction = rng.normal(size=(masses.size, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    positions = direction * (reach * rng.random(masses.size) ** (1 / 3))[:, None] + np.array([5.0, -2.0, 1.0])
    return positions, masses


def test_depth_shells_hold_equal_mass_in_order_and_ignore_a_turn():
    rng = np.random.default_rng(3)
    positions, masses = layered_pile(rng)
    shells = ss.depth_shells(positions, masses, 10)
    assert set(shells) == set(range(10))
    shell_mass = np.bincount(shells, weights=masses)
    assert np.abs(shell_mass - masses.sum() / 10).max() <= masses.max()
    centre = masses @ positions / masses.sum()
    distance = np.linalg.norm(positions - centre, axis=1)
    for k in range(9):
        assert distance[shells == k].max() <= distance[shells == k + 1].min()
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    np.testing.assert_array_equal(ss.depth_shells(centre + (positions - centre) @ q.T, masses, 10), shells)
    # The outermost fifth holds the small grains here, as a formed pile's does.
    outer = ss.depth_shells(positions, masses, 5) == 4
    assert masses[outer].mean() < 0.7 * masses.mean()


def test_fate_by_shell_alone_leaves_no_sorting():
    """The outer three of ten shells lost whole: the growth is all depth, to round-off."""
    rng = np.random.default_rng(4)
    positions, masses = layered_pile(rng)
    groups = ss.depth_shells(positions, masses, 10)
    kept = groups < 7
    split = ss.size_change_split(masses, kept, groups)
    assert split.total == particle_size_change(masses[kept].sum(), kept.sum(), masses.sum(), masses.size)
    assert split.total_mass_weighted == mass_weighted_size_change(masses[kept], masses)
    assert split.total > 10.0 and split.total_mass_weighted > 5.0
    assert abs(split.sorting) < 1e-9 and abs(split.sorting_mass_weighted) < 1e-9
    assert split.null_sd == 0.0  # each group wholly in or out: nothing to draw


def test_fate_drawn_by_shell_blind_to_size_sorts_only_within_its_noise():
    """Each grain kept with a chance set by its shell alone: the depth part carries the growth and
    the sorting part stays within four of its size-blind standard deviations, in each of 20 piles."""
    rng = np.random.default_rng(5)
    for _ in range(20):
        positions, masses = layered_pile(rng)
        groups = ss.depth_shells(positions, masses, 10)
        chance = np.where(groups < 6, 0.97, 0.35)
        split = ss.size_change_split(masses, rng.random(masses.size) < chance, groups)
        assert split.depth > 5.0 and split.null_sd > 0.1
        assert abs(split.sorting) < 4 * split.null_sd


def test_fate_by_size_alone_is_all_sorting():
    """Large grains kept more often than small ones in a pile not layered by size: the depth part is
    near 0 and the sorting part carries the growth."""
    rng = np.random.default_rng(6)
    positions, masses = layered_pile(rng, segregated=False)
    kept = rng.random(masses.size) < np.where(masses > 1, 0.95, 0.6)
    split = ss.size_change_split(masses, kept, ss.depth_shells(positions, masses, 10))
    assert split.total > 20.0
    assert abs(split.depth) < 0.05 * split.total and abs(split.depth_mass_weighted) < 0.05 * split.total_mass_weighted
    assert split.sorting > 0.95 * split.total
    # Only the pile told apart (one shell, both piles alike in size): no depth part at all.
    one = ss.size_change_split(masses, kept, np.zeros(masses.size, dtype=int))
    assert abs(one.depth) < 1e-9 and one.sorting == one.total


def test_null_sd_is_the_spread_of_drawing_blind_to_size():
    """null_sd against the spread of the size change over fragments drawn by hand: the same count
    per shell, grains chosen at random within it."""
    rng = np.random.default_rng(7)
    positions, masses = layered_pile(rng, n=2000)
    groups = ss.depth_shells(positions, masses, 5)
    kept = rng.random(masses.size) < np.where(groups < 3, 0.9, 0.3)
    split = ss.size_change_split(masses, kept, groups)
    drawn = []
    for _ in range(2000):
        fate = np.zeros(masses.size, dtype=bool)
        for g in range(5):
            members = np.flatnonzero(groups == g)
            fate[rng.choice(members, kept[members].sum(), replace=False)] = True
        drawn.append(ss.size_change_split(masses, fate, groups).total)
    assert np.mean(drawn) == pytest.approx(split.depth, abs=4 * split.null_sd / math.sqrt(len(drawn)))
    assert np.std(drawn) == pytest.approx(split.null_sd, rel=0.08)


def test_ratio_interval_covers_the_ratio_and_opens_when_the_denominator_is_unresolved():
    rng = np.random.default_rng(8)
    total = 4.0 + rng.normal(size=60)
    depth = 0.4 * total + 0.2 * rng.normal(size=60)
    ratio, low, high = ss.ratio_interval(depth, total)
    assert ratio == pytest.approx(depth.mean() / total.mean())
    assert low < 0.4 < high and high - low < 0.1
    _, low, high = ss.ratio_interval([1.0, 1.2, 0.9], [1.0, -1.1, 0.2])
    assert low is None and high is None
    mean, half = ss.t_interval([1.0, 2.0, 3.0])
    assert mean == 2.0 and half == pytest.approx(4.302653 * 1.0 / math.sqrt(3), rel=1e-6)


def test_bad_input_is_refused():
    with pytest.raises(InputError):
        ss.size_change_split(np.ones(3), np.zeros(3, dtype=bool), np.zeros(3))
    with pytest.raises(InputError):
        ss.size_change_split(np.ones(3), np.ones(2, dtype=bool), np.zeros(3))
    with pytest.raises(InputError):
        ss.depth_shells(np.zeros((3, 3)), np.ones(3), 0)


def test_a_committed_fig6_run_splits_its_summarys_size_change():
    """A committed run: its grains are its piles' (target then projectile, radii in order), label 0
    holds the summary's m_lf/m_t, and the split's totals are the summary's size changes."""
    run = ROOT / "runs/results/fig6_statistics/projectileproj500_eta9_r1"
    summary = json.loads((run / "summary.json").read_text())
    final = read_analysis(run / "analysis.h5")["final"]
    piles = [load_pile(ROOT / f"runs/paper/piles/{summary[f'{role}_pile']}.h5") for role in ("target", "projectile")]
    np.testing.assert_array_equal(np.concatenate([p.radii for p in piles]), final["radius"])
    masses, fragment = final["particle_mass"], final["label"] == 0
    assert masses[fragment].sum() / summary["target_mass"] == pytest.approx(summary["largest_mass_ratio"], rel=1e-12)
    groups = ss.pile_shell_groups([p.positions for p in piles], [p.masses for p in piles], 10)
    assert groups.max() == 19 and (groups[: piles[0].n] < 10).all()
    split = ss.size_change_split(masses, fragment, groups)
    assert split.total == pytest.approx(summary["particle_size_change"], abs=1e-9)
    assert split.total_mass_weighted == pytest.approx(summary["particle_size_change_mass_weighted"], abs=1e-9)
    assert 0 < split.depth < split.total

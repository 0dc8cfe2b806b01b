"""Piles with a power-law size distribution: the radii drawn against the law's own cumulative
distribution, the size classes against log-R bins computed here, what ``pile --check`` says of the
smallest and the largest grain, and contact lists wide enough for a large grain among many small ones."""

import math

import numpy as np
import pytest

import decco_warp as dw
from decco_warp.arrays import candidate_width
from decco_warp.engine import Engine
from decco_warp.errors import InputError
from decco_warp.kernels.contacts import CANDIDATES
from decco_warp.pile import Formation
from decco_warp.resolution import pile_entry
from decco_warp.sizes import PowerLaw, class_ranges, classify, contact_list_rule, parse_size_distribution, touching_limit
from decco_warp.spec import SpecError, check_pile_list
from helpers import cli_here

LAW = "power:q=-3.5:r_min=5e5:r_max=2.5e6"


@pytest.mark.parametrize("q", [-3.5, -1.0, 0.0, 2.0])
def test_radii_follow_the_power_law(q):
    """Kolmogorov-Smirnov against F(R) = (R^(q+1) - a^(q+1)) / (b^(q+1) - a^(q+1)) (log for q = -1):
    20 000 draws stay within 1.95 / sqrt(n) of it (the 0.1 % level)."""
    a, b, n = 5e5, 2.5e6, 20_000
    radii = PowerLaw(q, a, b).sample(n, seed=3)
    assert np.all(np.diff(radii) >= 0) and radii[0] >= a and radii[-1] <= b
    if q == -1.0:
        cdf = np.log(radii / a) / np.log(b / a)
    else:
        p = q + 1.0
        cdf = (radii**p - a**p) / (b**p - a**p)
    empirical = np.arange(1, n + 1) / n
    assert np.abs(cdf - empirical).max() < 1.95 / math.sqrt(n)
    np.testing.assert_array_equal(PowerLaw(q, a, b).sample(n, seed=3), radii)  # the seed gives the same radii
    assert not np.array_equal(PowerLaw(q, a, b).sample(n, seed=4), radii)


def test_the_form_reads_back_and_bad_forms_are_one_line():
    law = parse_size_distribution("power:q=-3.5:r_min=5e5:r_max=2.5e6:classes=4")
    assert law == PowerLaw(-3.5, 5e5, 2.5e6, 4) and parse_size_distribution(law.text()) == law
    assert parse_size_distribution(LAW).classes == 3
    for bad in ("pow:q=1", "power:q=-3:r_min=1e5", "power:q=x:r_min=1:r_max=2", "power:q=-3:r_min=2e5:r_max=1e5",
                "power:q=-3:r_min=1e5:r_max=2e5:classes=0", "power:q=-3:r_min=1e5:r_max=2e5:q=2", "power:q=-3:r_min=1e5:r_max=2e5:width=2"):  # fmt: skip
        with pytest.raises(InputError) as caught:
            parse_size_distribution(bad)
        assert "\n" not in str(caught.value) and "--size-distribution" in str(caught.value)


def test_classes_are_log_r_bins_and_the_analysis_states_them():
    law = PowerLaw(-3.5, 5e5, 2.5e6)
    radii = law.sample(500, seed=1)
    edges = 10 ** np.linspace(math.log10(5e5), math.log10(2.5e6), 4)  # float64 here, not np.geomspace
    np.testing.assert_allclose(law.edges(), edges, rtol=1e-14)
    want = np.clip(np.digitize(radii, edges[1:-1]), 0, 2)
    np.testing.assert_array_equal(classify(radii, law.edges()), want)
    assert classify(np.array([5e5, 2.5e6]), law.edges()).tolist() == [0, 2]  # both ends inside
    ranges = class_ranges(radii, want)
    for k in range(3):
        assert ranges["count"][k] == (want == k).sum()
        assert ranges["radius_min"][k] == radii[want == k].min() and ranges["radius_max"][k] == radii[want == k].max()
        assert edges[k] * (1 - 1e-12) <= ranges["radius_min"][k] <= ranges["radius_max"][k] <= edges[k + 1] * (1 + 1e-12)


def test_the_largest_grain_and_the_width_of_the_contact_lists():
    # Caps of half-angle asin(r / (R + r)) on the sphere of centres: their count cannot pass 4 pi / cap.
    for ratio in (1.0, 3.0, 5.0, 10.0):
        cap = 2.0 * math.pi * (1.0 - math.cos(math.asin(1.0 / (ratio + 1.0))))
        assert touching_limit(ratio * 1e6, 1e6) == math.floor(4.0 * math.pi / cap)
    assert touching_limit(1e6, 1e6) == 14 and touching_limit(3e6, 1e6) == 62  # 12 and ~57 are reached
    assert [contact_list_rule(r) for r in (1, 3, 5, 10)] == [12, 44, 108, 408]
    assert candidate_width(0.75e6, 2.25e6) == CANDIDATES  # the paper's piles keep their lists
    assert candidate_width(5e5, 2.5e6) == 108 and candidate_width(1e5, 1e6) == 408


def _large_among_small(count, ratio, seed=6):
    """One sphere touched by ``count`` spheres ``ratio`` times smaller (overlaps of 500 cm), random motion."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    small, large = 1e6, ratio * 1e6
    x = np.vstack([[0.0, 0.0, 0.0], direction * (large + small - 500.0)]) + 1.5e7
    radii = np.array([large] + [small] * count)
    masses = 4.0 / 3.0 * math.pi * 2.7 * radii**3
    return dw.State.from_arrays(x, rng.normal(size=(count + 1, 3)), rng.normal(size=(count + 1, 3)) * 1e-4, radii, masses)


@pytest.mark.parametrize("gravity, every", [("all-pairs", 1), ("tree", 1), ("all-pairs", 5)])
def test_lists_sized_for_the_radius_ratio_hold_a_large_grains_contacts(gravity, every):
    """100 grains on one five times larger: more than CANDIDATES, fewer than the 108 the ratio sizes
    the lists for. The Newton layout's list (all-pairs), the tree's grid list and the neighbour list
    of gravity on its own clock hold them all, and the forces are the plain loop's."""
    state = _large_among_small(100, 5.0)
    params = dw.Params() if gravity == "all-pairs" else dw.Params(G=0.0)
    scheme = dw.Scheme(gravity=gravity, gravity_every=every)
    engine = Engine(state, params, "cpu", "float64", layout=dw.Layout(1, 4, newton=True), scheme=scheme)
    engine.eval_forces()
    assert engine.candidates.shape[1] == 108
    assert engine.candidate_count.numpy()[0] == 100 > CANDIDATES and engine.candidate_overflows() == 0
    reference = dw.compute_forces(state, params, device="cpu", precision="float64", force_kernel="reference")
    for got, want in zip(engine.read_forces(), reference):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


def test_a_power_law_pile_forms_and_continues_with_the_same_sizes(tmp_path):
    formation = Formation(n_particles=60, seed=2, device="cpu", size_distribution=LAW, check_every=20)
    cloud = formation.state
    radii = cloud.radii
    assert radii.min() >= 5e5 and radii.max() <= 2.5e6 and np.all(np.diff(radii) >= 0)
    np.testing.assert_allclose(cloud.masses, 4.0 / 3.0 * math.pi * 2.7 * radii**3, rtol=1e-15)
    edges = 10 ** np.linspace(math.log10(5e5), math.log10(2.5e6), 4)
    assert cloud.size_class.tolist() == np.clip(np.digitize(radii, edges[1:-1]), 0, 2).tolist()
    gaps = np.linalg.norm(cloud.positions[:, None] - cloud.positions[None], axis=2) - radii[:, None] - radii[None]
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() >= 0  # seeded without overlaps
    formation.advance()
    snapshot = formation.snapshot()
    again = Formation(n_particles=60, seed=2, device="cpu", size_distribution=LAW, check_every=20, snapshot=snapshot)
    np.testing.assert_array_equal(again.state.positions, formation.state.positions)
    with pytest.raises(InputError, match="size_distribution"):
        Formation(n_particles=60, seed=2, device="cpu", size_distribution=LAW.replace("-3.5", "-3"), check_every=20, snapshot=snapshot)
    meta = formation.pile().metadata
    np.testing.assert_allclose(meta["size_class_edges"], edges, rtol=1e-14)
    assert meta["size_distribution"] == parse_size_distribution(LAW).text() and meta["size_counts"].sum() == 60
    assert "size_radii" not in meta


def test_check_says_what_the_smallest_grain_costs_and_what_the_largest_touches(tmp_path):
    radii = Formation(n_particles=300, seed=1, device="cpu", size_distribution=LAW).state.radii
    result = cli_here("pile", "--out", str(tmp_path / "p.h5"), "-n", "300", "--size-distribution", LAW, "--check", "--device", "cpu")
    assert result.returncode == 0, result.stderr
    m_min = 4.0 / 3.0 * math.pi * 2.7 * radii.min() ** 3
    scale = math.sqrt(m_min / 1e18)
    assert f"sqrt(m/k_in) = {scale:.3g} s: dt = 0.04 s has a margin of {scale / 0.04:.3g} (need >= 10)" in result.stdout
    width = max(64, math.ceil(8 + 4 * (radii.max() / radii.min()) ** 2))
    assert f"largest grain: radius {radii.max() / 1e5:.4g} km" in result.stdout and f"the contact lists hold {width} a particle" in result.stdout
    counts = np.bincount(np.clip(np.digitize(radii, 10 ** np.linspace(math.log10(5e5), math.log10(2.5e6), 4)[1:-1]), 0, 2))
    assert f"of {', '.join(str(c) for c in counts)} particles" in result.stdout and not (tmp_path / "p.h5").exists()
    # Grains of 1 km want a shorter step than the paper's 0.04 s: said before any work, exit 2.
    small = "power:q=-3.5:r_min=1e5:r_max=2.5e6"
    result = cli_here("pile", "--out", str(tmp_path / "p.h5"), "-n", "300", "--size-distribution", small, "--device", "cpu")
    assert result.returncode == 2 and "too long for the smallest grain" in result.stderr and result.stderr.count("\n") == 1
    result = cli_here("pile", "--out", str(tmp_path / "p.h5"), "--radii", "1e6", "--size-distribution", LAW, "--check")
    assert result.returncode == 2 and "--radii or --size-distribution, not both" in result.stderr


def test_pile_lists_take_a_power_law_and_scale_it_with_the_resolution(tmp_path):
    entry = {"out": "p.h5", "particles": 100, "size_distribution": LAW}
    assert check_pile_list({"pile": [entry]}, "piles.toml") == [entry]
    with pytest.raises(SpecError, match="radii or size_distribution, not both"):
        check_pile_list({"pile": [{**entry, "radii": [1e6]}]}, "piles.toml")
    scaled = pile_entry(entry, 8.0, "0.75e6,1.5e6,2.25e6")
    assert scaled["particles"] == 800 and scaled["out"] == "p_x8.h5"
    law = parse_size_distribution(scaled["size_distribution"])
    assert (law.q, law.r_min, law.r_max) == (-3.5, pytest.approx(2.5e5), pytest.approx(1.25e6))

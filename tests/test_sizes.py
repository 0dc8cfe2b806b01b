"""Contact lists wide enough for a large grain among many small ones."""

import math

import numpy as np
import pytest

import decco_warp as dw
from decco_warp.engine import Engine, candidate_width
from decco_warp.kernels.contacts import CANDIDATES
from decco_warp.sizes import contact_list_rule, touching_limit

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


@pytest.mark.parametrize("gravity", ["all-pairs", "tree"])
def test_lists_sized_for_the_radius_ratio_hold_a_large_grains_contacts(gravity):
    """100 grains on one five times larger: more than CANDIDATES, fewer than the 108 the ratio sizes
    the lists for. The Newton layout's list (all-pairs) and the tree's grid list hold them all, and
    the forces are the plain loop's."""
    state = _large_among_small(100, 5.0)
    params = dw.Params() if gravity == "all-pairs" else dw.Params(G=0.0, gravity="tree")
    engine = Engine(state, params, "cpu", "float64", layout=dw.Layout(1, 4, newton=True))
    engine.eval_forces()
    assert engine.candidates.shape[1] == 108
    assert engine.candidate_count.numpy()[0] == 100 > CANDIDATES and engine.candidate_overflows() == 0
    reference = dw.compute_forces(state, params, device="cpu", precision="float64", force_kernel="reference")
    for got, want in zip(engine.read_forces(), reference):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())

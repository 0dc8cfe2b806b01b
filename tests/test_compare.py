"""decco_warp.analysis.compare: intervals that cover the truth at the stated rate, the runs-needed
formula by hand, grouping and filtering."""

import math

import numpy as np
import pytest
from scipy import stats

from decco_warp.analysis import compare as cmp

#: Coverage over TRIALS seeded trials must lie within this many binomial standard deviations of
#: 95 %: sqrt(0.95 0.05 / 400) = 1.09 %, so 3 of them admit 91.7 % to 98.3 %.
TRIALS = 400
COVERAGE_SIGMAS = 3
COVERAGE_TOLERANCE = COVERAGE_SIGMAS * math.sqrt(0.95 * 0.05 / TRIALS)
#: The set-up every fake run shares (equal masses, head-on, the paper's k_in and dt).
SETUP = {"mass_ratio": 1.0, "theta_deg": 0.0, "k_in": 1e18, "dt": 0.04, "eta_potential": "self", "n_particles": 10000}


def fake_rows(groups: dict, eta: float = 6.0, **setup) -> list[dict]:
    """Summary rows: {spin_kind: metric values}, one run per value."""
    return [
        {"run": f"{kind}_eta{eta:g}_r{k}", "spin_kind": kind, "eta": eta, **SETUP, **setup, "largest_mass_ratio": float(value), "status": "ok"}
        for kind, values in groups.items()
        for k, value in enumerate(values)
    ]


def coverage(sizes: tuple[int, int], spreads: tuple[float, float], truth: float, resamples: int) -> float:
    """The fraction of TRIALS seeded pairs of normal groups (``sizes``, ``spreads``, means
    ``truth`` apart) whose interval of the difference, from compare(), holds ``truth``."""
    covered = 0
    for trial in range(TRIALS):
        rng = np.random.default_rng(trial)
        rows = fake_rows({"none": rng.normal(1.39, spreads[0], sizes[0]), "parallel": rng.normal(1.39 + truth, spreads[1], sizes[1])})
        (difference,) = cmp.compare(rows, "spin_kind", "largest_mass_ratio", resamples=resamples).points[0].differences
        covered += difference.low <= truth <= difference.high
    return covered / TRIALS


def test_welch_intervals_of_small_groups_cover_the_true_difference_95_percent_of_the_time():
    rate = coverage((3, 5), (0.01, 0.02), truth=0.01, resamples=cmp.RESAMPLES)
    assert abs(rate - 0.95) <= COVERAGE_TOLERANCE, rate


def test_bootstrap_intervals_of_large_groups_cover_the_true_difference_95_percent_of_the_time():
    # 2 000 resamples instead of 9 999 to keep the test fast: past ~1 000 the resamples only
    # smooth the interval's ends; its coverage is set by the groups' sizes.
    rate = coverage((cmp.BOOTSTRAP_FROM, cmp.BOOTSTRAP_FROM + 5), (0.01, 0.02), truth=0.01, resamples=2000)
    assert abs(rate - 0.95) <= COVERAGE_TOLERANCE, rate


def test_the_method_follows_the_group_sizes_and_the_bootstrap_is_reproducible():
    rng = np.random.default_rng(7)
    small = fake_rows({"none": rng.normal(0, 1, cmp.BOOTSTRAP_FROM - 1), "parallel": rng.normal(0, 1, 40)})
    large = fake_rows({"none": rng.normal(0, 1, cmp.BOOTSTRAP_FROM), "parallel": rng.normal(3, 1, 40)})
    assert cmp.compare(small, "spin_kind", "largest_mass_ratio").points[0].differences[0].method == "Welch t"
    first, again = (cmp.compare(large, "spin_kind", "largest_mass_ratio").points[0].differences[0] for _ in range(2))
    assert first.method == "bootstrap" and (first.low, first.high) == (again.low, again.high)
    assert first.resolved and first.verdict == "resolved"


def test_welch_interval_by_hand():
    a, b = np.array([1.0, 2.0, 3.0]), np.array([2.0, 4.0, 6.0, 8.0])
    # Variances of the means 1/3 and 5/3: se^2 = 2; Welch-Satterthwaite dof 4 / (1/18 + 25/27).
    freedom = 4 / (1 / 18 + 25 / 27)
    half = stats.t.ppf(0.975, freedom) * math.sqrt(2)
    low, high = cmp.welch_interval(a, b)
    assert low == pytest.approx(-3 - half, rel=1e-12) and high == pytest.approx(-3 + half, rel=1e-12)
    assert half == pytest.approx(3.898, abs=1e-3)  # t_0.975 at 4.08 dof is 2.756 (a table gives 2.776 at 4)
    scipy_interval = stats.ttest_ind(a, b, equal_var=False).confidence_interval(0.95)
    assert (low, high) == pytest.approx((scipy_interval.low, scipy_interval.high), rel=1e-12)


def test_runs_needed_by_hand():
    # 2 (z_0.975 + z_0.8)^2 = 2 (1.959964 + 0.841621)^2 = 15.698
    assert cmp.runs_needed(0.01, 0.01) == 16  # 15.70, rounded up
    assert cmp.runs_needed(0.007, 0.01) == 8  # 15.698 x 0.49 = 7.69 (the 8 to 16 for 0.01 apart)
    assert cmp.runs_needed(0.011, 0.02) == 5  # 15.698 x 0.3025 = 4.75
    assert cmp.runs_needed(0.05, 0.02) == 99  # 15.698 x 6.25 = 98.1
    assert cmp.runs_needed(0.001, 1.0) == 2  # a group needs two runs for any spread
    assert cmp.runs_needed(0.01, 0.0) is None  # no difference is ever resolved


def test_the_table_groups_points_by_rounded_values_and_leaves_out_failed_runs():
    rows = fake_rows({"none": [1.0, 1.2], "parallel": [1.5, 1.7]}, eta=3.0000000000000004)
    rows += fake_rows({"none": [1.1], "anti-parallel": [0.9, 1.0]}, eta=3.0)
    rows += fake_rows({"none": [5.0, 6.0]}, eta=9.0)
    rows += [{**rows[0], "run": "broken", "status": "failed", "largest_mass_ratio": None}, {**rows[0], "run": "blank", "largest_mass_ratio": None}]
    result = cmp.compare(rows, "spin_kind", "largest_mass_ratio", at="eta", resolve=0.1)
    assert [p.at for p in result.points] == [3.0, 9.0]
    three = result.points[0]
    assert [g.group for g in three.groups] == ["none", "anti-parallel", "parallel"]  # the reference first
    none = three.groups[0]
    assert none.n == 3 and none.mean == pytest.approx(1.1) and none.std == pytest.approx(0.1)
    parallel = {d.group: d for d in three.differences}["parallel"]
    assert parallel.difference == pytest.approx(0.5)
    # s^2 = (0.02 + 0.01) / 2: 15.698 x 0.015 / 0.01 = 23.5
    assert parallel.runs_needed == 24 and parallel.delta == 0.1
    assert result.points[1].differences == []  # the reference alone there
    assert (result.read, result.failed, result.missing) == (11, 1, {"largest_mass_ratio": 1})


def test_where_picks_numbers_within_a_tolerance_and_the_reference_can_be_named():
    rows = fake_rows({"none": [0.6, 0.7], "parallel": [0.8, 0.9]}, mass_ratio=0.10031007751937988)
    rows += fake_rows({"none": [1.3, 1.4], "parallel": [1.5, 1.6]})
    result = cmp.compare(rows, "spin_kind", "largest_mass_ratio", where=cmp.parse_where(["mass_ratio=0.1"]), reference="parallel")
    assert result.met == {"mass_ratio": [0.10031]} and result.reference == "parallel"
    assert [g.mean for g in result.points[0].groups] == pytest.approx([0.85, 0.65])
    both = cmp.parse_where(["mass_ratio=0.1", "mass_ratio=1", "spin_kind=none"])
    assert both == {"mass_ratio": [0.1, 1.0], "spin_kind": ["none"]}
    assert cmp.compare(rows, "spin_kind", "largest_mass_ratio", where=both, allow_mixed=True).points[0].groups[0].n == 4


def test_error_bars_are_the_mean_and_its_t_interval():
    rows = fake_rows({"none": [1.0, 2.0, 3.0], "parallel": [5.0]})
    bars = cmp.error_bars(rows, "spin_kind", "largest_mass_ratio", at="eta")
    half = stats.t.ppf(0.975, 2) * 1.0 / math.sqrt(3)
    assert bars["none"]["at"].tolist() == [6.0] and bars["none"]["mean"].tolist() == [2.0]
    assert bars["none"]["minus"] == pytest.approx([half]) and bars["none"]["plus"] == pytest.approx([half])
    assert bars["none"]["method"] == ["t"] and np.isnan(bars["parallel"]["minus"]).all()

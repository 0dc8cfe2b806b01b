"""The resolution limit and the power-law slope (decco_warp/analysis/convergence.py) against known
synthetic ladders and independent NumPy arithmetic."""

import numpy as np
import pytest

from decco_warp.analysis.convergence import power_law_slope, resolution_limit, rung_scatter
from decco_warp.checks import InputError

RUNGS = np.array([1562.0, 6250.0, 25000.0, 100000.0])


def _ladder(rng, m_inf=0.9, c=40.0, beta=0.7, per_rung=(3, 3, 3, 2), scatter=0.5):
    """Runs of m(N) = m_inf - c N^-beta with a scatter falling as N^-1/2 (as the realizations' does)."""
    n = np.repeat(RUNGS, per_rung)
    truth = m_inf - c * n**-beta
    return n, truth + rng.normal(0.0, scatter * n**-0.5)


def test_the_limit_of_an_exact_ladder_is_its_m_inf():
    n = np.repeat(RUNGS, 2)
    values = 1.13 - 9.0 * n**-0.6
    values = values + np.tile([1e-6, -1e-6], RUNGS.size)  # a scatter to weigh by
    limit = resolution_limit(n, values)
    assert limit.value == pytest.approx(1.13, abs=1e-5)
    assert limit.beta == pytest.approx(0.6, rel=1e-3)
    assert limit.low < 1.13 < limit.high
    assert limit.at(25000.0) == pytest.approx(1.13 - 9.0 * 25000.0**-0.6, abs=1e-5)
    assert (limit.runs, limit.rungs) == (8, 4)


def test_the_limit_s_interval_covers_the_truth_about_as_often_as_it_says():
    rng = np.random.default_rng(7)
    hits = 0
    trials = 300
    for _ in range(trials):
        limit = resolution_limit(*_ladder(rng))
        hits += limit.low <= 0.9 <= limit.high
    # 95 % asked; ~91 % given (the weights are estimated from three runs a rung: with the true
    # scatter the same fit covers 96 %), as the module says; a z interval covers ~87 %, and equal
    # weights ~100 % with intervals wider than need be.
    assert 0.87 <= hits / trials <= 0.99, hits / trials


def test_the_weights_are_the_realizations_scatter_as_a_power_of_n():
    n = np.array([1562, 1562, 6250, 6250, 25000, 25000, 25000, 100000], dtype=float)
    v = np.array([0.4, 0.6, 0.78, 0.82, 0.875, 0.88, 0.885, 0.9])
    sigma = rung_scatter(n, v)
    sds = [np.std(g, ddof=1) for g in ([0.4, 0.6], [0.78, 0.82], [0.875, 0.88, 0.885])]
    slope, intercept = np.polyfit(np.log([1562, 6250, 25000]), np.log(sds), 1)
    assert sigma == pytest.approx(np.exp(intercept + slope * np.log(n)))
    assert sigma[-1] < sigma[4] < sigma[2] < sigma[0]  # the lone top rung takes the line's value there
    one = rung_scatter([1562, 6250, 6250, 25000.0], [0.5, 0.7, 0.8, 0.9])
    assert one == pytest.approx(np.full(4, np.std([0.7, 0.8], ddof=1)))


def test_the_slope_is_the_least_squares_line_in_log_log_with_a_t_interval():
    rng = np.random.default_rng(3)
    n = np.repeat(RUNGS[1:], 3)
    y = 2.5 * (n / 6250.0) ** -0.5 * np.exp(rng.normal(0.0, 0.15, n.size))
    slope = power_law_slope(n, y)
    x, ly = np.log(n), np.log(y)
    b, a = np.polyfit(x, ly, 1)
    residual = ly - (a + b * x)
    se = np.sqrt(residual @ residual / (n.size - 2) / ((x - x.mean()) @ (x - x.mean())))
    from scipy import stats

    half = stats.t.ppf(0.975, n.size - 2) * se
    assert slope.value == pytest.approx(b, rel=1e-12)
    assert (slope.low, slope.high) == pytest.approx((b - half, b + half), rel=1e-10)
    assert slope.per_fourfold == pytest.approx(4.0**b)
    assert slope.low < -0.5 < slope.high


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: resolution_limit([1562, 6250, 6250, 25000.0][:2] * 2, [0.5, 0.8, 0.5, 0.8]), "three or more particle counts"),
        (lambda: resolution_limit([1562, 6250, 25000.0], [0.5, 0.8, 0.9]), "four or more runs"),
        (lambda: resolution_limit([1562, 6250, 25000.0, 0.0], [0.5, 0.8, 0.9, 1.0]), "positive"),
        # steps that grow with N (0.05, then 0.15): no approach to a limit
        (lambda: resolution_limit(np.repeat([1562, 6250, 25000.0], 2), [0.45, 0.47, 0.51, 0.49, 0.65, 0.66]), "approach no limit"),
        (lambda: power_law_slope([6250, 25000, 100000.0], [2.0, -1.0, 0.5]), "positive"),
        (lambda: power_law_slope([6250, 6250, 6250.0], [2.0, 1.0, 0.5]), "two or more particle counts"),
    ],
)
def test_too_little_or_bad_input_is_refused_in_one_line(call, message):
    with pytest.raises(InputError) as raised:
        call()
    assert message in str(raised.value) and "\n" not in str(raised.value)

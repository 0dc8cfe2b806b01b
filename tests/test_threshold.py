"""Q*_RD from runs and LS12's constants from thresholds (decco_warp/analysis/threshold.py): against
the law's own formulas (analysis/scaling.py), a brute-force interval, and the interval's coverage."""

import math

import numpy as np
import pytest
from scipy import stats

from decco_warp.analysis import scaling, threshold
from decco_warp.checks import InputError

TARGET = 6.16e22
RADII = {0.1: 1.04e7, 0.25: 1.36e7, 1.0: 2.17e7}
TARGET_RADIUS = 2.17e7


def _law_rows(ratio, energies_over_qstar, scatter=0.0, seed=0, per_energy=1, law=scaling.SMALL_BODIES):
    """Summary rows of head-on runs that land on LS12's law (``law``) at Q_R = the given multiples of
    its Q*_RD, the remnant fraction shifted by normal ``scatter``."""
    rng = np.random.default_rng(seed)
    projectile = ratio * TARGET
    q_star = scaling.disruption_energy(TARGET, projectile, TARGET_RADIUS, RADII[ratio], 0.0, law=law)
    total = TARGET + projectile
    reduced = TARGET * projectile / total
    rows = []
    for multiple in energies_over_qstar:
        for _ in range(per_energy):
            q_r = multiple * q_star
            speed = math.sqrt(2 * q_r * total / reduced)
            fraction = scaling.largest_remnant_fraction(q_r, q_star) + scatter * rng.normal()
            rows.append({"run": f"r{len(rows)}", "target_mass": TARGET, "mass_ratio": ratio, "speed": speed,
                         "largest_mass_ratio": fraction * total / TARGET, "theta_deg": 0.0})  # fmt: skip
    return rows, q_star


def test_runs_on_the_law_give_its_threshold_intercept_one_and_its_slope():
    """Runs exactly on the law (no scatter) give the law's Q*_RD, an intercept of 1 and its slope;
    runs off the linear regime (a merger, the super-catastrophic tail) are left out of the fit."""
    rows, q_star = _law_rows(0.25, [0.02, 0.4, 0.8, 1.2, 1.6, 2.5])
    found = threshold.thresholds(rows)[0.25]
    assert found.q_star == pytest.approx(q_star, rel=1e-9)
    assert found.intercept == pytest.approx(1.0, abs=1e-9)
    assert found.law_slope_ratio == pytest.approx(1.0, rel=1e-9)
    assert found.runs == 4 and found.energies == 4  # 0.02 (0.99 kept) and 2.5 (below 0.1) dropped
    assert found.low == pytest.approx(q_star, rel=1e-9) and found.high == pytest.approx(q_star, rel=1e-9)


def test_the_interval_is_the_set_of_crossings_the_line_cannot_exclude():
    """Fieller's interval against its definition, by brute force: the Q_R at which the fitted mean's
    t-band (its 95 % confidence band) holds 1/2."""
    rows, _ = _law_rows(0.1, [0.5, 0.9, 1.3], scatter=0.03, seed=4, per_energy=5)
    found = threshold.thresholds(rows)[0.1]
    q_r = np.array([threshold.specific_impact_energy(r["target_mass"], r["mass_ratio"], r["speed"]) for r in rows])
    y = np.array([threshold.remnant_fraction(r["largest_mass_ratio"], r["mass_ratio"]) for r in rows])
    b, a = np.polyfit(q_r, y, 1)
    s = math.sqrt(((y - a - b * q_r) ** 2).sum() / (y.size - 2))
    t = stats.t.ppf(0.975, y.size - 2)
    grid = np.linspace(0.5 * found.q_star, 1.5 * found.q_star, 400_001)
    band = t * s * np.sqrt(1 / y.size + (grid - q_r.mean()) ** 2 / ((q_r - q_r.mean()) ** 2).sum())
    inside = grid[np.abs(0.5 - (a + b * grid)) <= band]
    step = grid[1] - grid[0]
    assert found.low == pytest.approx(inside.min(), abs=2 * step) and found.high == pytest.approx(inside.max(), abs=2 * step)
    assert found.q_star == pytest.approx((0.5 - a) / b, rel=1e-9)


def test_the_interval_covers_the_true_threshold_as_often_as_it_says():
    """Over 600 sets of 15 runs (three energies, five realizations, scatter 0.03 as the R = 4 runs
    show) the 95 % interval holds the law's Q*_RD in 95 % of them (binomial: 92.5 % to 97 %)."""
    hits = 0
    trials = 600
    for seed in range(trials):
        rows, q_star = _law_rows(1.0, [0.6, 1.0, 1.4], scatter=0.03, seed=seed, per_energy=5)
        found = threshold.thresholds(rows)[1.0]
        hits += found.low <= q_star <= found.high
    assert 0.925 <= hits / trials <= 0.97


def test_a_ratio_of_two_sets_thresholds_covers_the_true_ratio_as_often_as_it_says():
    """One set of runs on the law with c* = 3.3 (friction off, say) over another with c* = 5, each
    15 runs (three energies, five realizations, scatter 0.03): the ratio is the thresholds' ratio,
    and over 500 such pairs its 95 % interval holds the true 0.66 in 92 % to 97.5 % of them. Runs
    exactly on the law give the ratio with no width."""
    from dataclasses import replace

    softer = replace(scaling.SMALL_BODIES, c_star=3.3)
    hits, trials = 0, 500
    for seed in range(trials):
        rows_a, q_a = _law_rows(0.25, [0.6, 1.0, 1.4], scatter=0.03, seed=seed, per_energy=5, law=softer)
        rows_b, q_b = _law_rows(0.25, [0.6, 1.0, 1.4], scatter=0.03, seed=10_000 + seed, per_energy=5)
        a, b = threshold.thresholds(rows_a)[0.25], threshold.thresholds(rows_b)[0.25]
        r = threshold.threshold_ratio(a, b)
        assert r.ratio == pytest.approx(a.q_star / b.q_star, rel=1e-12) and r.low < r.ratio < r.high
        hits += r.low <= q_a / q_b <= r.high
    assert q_a / q_b == pytest.approx(0.66, rel=1e-9)
    assert 0.92 <= hits / trials <= 0.975
    exact = threshold.threshold_ratio(*(threshold.thresholds(_law_rows(0.25, [0.6, 1.0, 1.4], law=law)[0])[0.25] for law in (softer, scaling.SMALL_BODIES)))
    assert (exact.ratio, exact.low, exact.high) == pytest.approx((0.66, 0.66, 0.66), rel=1e-9)  # the lines' round-off alone


def test_law_constants_recover_c_star_and_mu_bar_from_the_laws_thresholds():
    """Thresholds made by the law's own formula for c* = 4.2, mu_bar = 0.45 (two and three mass
    ratios) give those constants back; equal masses alone give c* and no mu_bar; one unequal ratio
    alone is refused."""
    law = scaling.Law("test", 4.2, 0.45, (4.0, 4.4))
    found = []
    for ratio in (0.1, 0.25, 1.0):
        rows, q_star = _law_rows(ratio, [0.5, 0.9, 1.3], scatter=0.0, law=law)
        one = threshold.thresholds(rows)[ratio]
        found.append(threshold.Threshold(**{**one.__dict__, "std": 0.01 * one.q_star}))  # as if measured to 1 %
        assert one.q_star == pytest.approx(q_star, rel=1e-9)
    for subset in (found[:2], found):
        fit = threshold.law_constants(subset)
        assert fit.c_star == pytest.approx(4.2, rel=1e-9) and fit.mu_bar == pytest.approx(0.45, rel=1e-9)
        assert fit.c_star_low < 4.2 < fit.c_star_high and fit.mu_bar_low < 0.45 < fit.mu_bar_high
    equal = threshold.law_constants(found[2:])
    assert equal.c_star == pytest.approx(4.2, rel=1e-9) and math.isnan(equal.mu_bar)
    assert threshold.implied_c_star(found[0], 0.45) == pytest.approx(4.2, rel=1e-9)
    with pytest.raises(InputError, match="equal masses"):
        threshold.law_constants(found[:1])


def test_law_constants_interval_from_the_thresholds_errors():
    """c*'s interval is the weighted fit's: from two thresholds of known relative errors, ln c* =
    (k2 y1 - k1 y2) / (k2 - k1) has variance (k2^2 v1 + k1^2 v2) / (k2 - k1)^2."""
    law = scaling.SMALL_BODIES
    found = []
    for ratio, error in ((0.1, 0.02), (0.25, 0.03)):
        rows, _ = _law_rows(ratio, [0.5, 1.0, 1.5], law=law)
        one = threshold.thresholds(rows)[ratio]
        found.append(threshold.Threshold(**{**one.__dict__, "std": error * one.q_star}))
    fit = threshold.law_constants(found)
    k1, k2 = (math.log(threshold.mass_ratio_factor(t.mass_ratio)) for t in found)
    sd = math.sqrt(k2**2 * 0.02**2 + k1**2 * 0.03**2) / abs(k2 - k1)
    z = stats.norm.ppf(0.975)
    assert fit.c_star_low == pytest.approx(5.0 * math.exp(-z * sd), rel=1e-6)
    assert fit.c_star_high == pytest.approx(5.0 * math.exp(z * sd), rel=1e-6)


def test_too_few_runs_mixed_angles_and_missing_columns_are_refused():
    rows, _ = _law_rows(0.25, [0.5, 0.9])
    with pytest.raises(InputError, match="at least three runs at two impact energies"):
        threshold.thresholds(rows)
    rows, _ = _law_rows(0.25, [0.5, 0.9, 1.3])
    rows[0]["theta_deg"] = 22.0
    with pytest.raises(InputError, match="one impact angle at a time"):
        threshold.thresholds(rows)
    rows[0].pop("speed")
    with pytest.raises(InputError, match="needs target_mass, mass_ratio, speed"):
        threshold.thresholds(rows)
    rising, _ = _law_rows(0.25, [0.5, 0.9, 1.3])
    for row, fraction in zip(rising, (0.3, 0.5, 0.7)):
        row["largest_mass_ratio"] = fraction * 1.25
    with pytest.raises(InputError, match="does not fall with impact energy"):
        threshold.thresholds(rising)


def test_the_threshold_command_prints_each_ratio_and_the_constants(tmp_path):
    """`decco-warp threshold` over run folders (their summary.json): a line per mass ratio with the
    law's Q*_RD inside its interval, then c* and mu_bar; a summary.csv (no masses) is refused in one line."""
    import json

    from helpers import cli_here

    expected = {}
    for ratio in (0.1, 0.25):
        rows, expected[ratio] = _law_rows(ratio, [0.6, 1.0, 1.4], scatter=0.02, seed=int(ratio * 100), per_energy=4)
        for k, row in enumerate(rows):
            folder = tmp_path / f"m{ratio}_{k}"
            folder.mkdir()
            (folder / "summary.json").write_text(json.dumps({**row, "run": folder.name}))
    result = cli_here("threshold", str(tmp_path))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    for ratio, q_star in expected.items():
        line = next(line for line in lines if line.strip().startswith(f"mass ratio {ratio:g}:"))
        value, low, high = (float(v) for v in line.split(":")[1].replace("(", "").replace("),", "").replace(" to ", " ").split()[:3])
        assert low <= q_star <= high and value == pytest.approx(q_star, rel=0.05)
    assert "c* = " in lines[-1] and "mu_bar = " in lines[-1]
    # --against: each ratio's threshold over another set's (here the 1/4 runs alone: 1/10 has none there).
    quarter = tmp_path / "quarter"
    quarter.mkdir()
    for folder in tmp_path.glob("m0.25_*"):
        folder.rename(quarter / folder.name)
    result = cli_here("threshold", str(tmp_path), str(quarter), "--against", str(quarter))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[-3].startswith(f"over the Q*_RD of {quarter} (95 % intervals")
    assert lines[-2] == "  mass ratio 0.1: not among its thresholds"
    ratio, low, high = (float(v) for v in lines[-1].split(":")[1].replace("(", "").replace(")", "").replace(" to ", " ").split())
    assert lines[-1].startswith("  mass ratio 0.25:") and ratio == 1.0 and low < 1.0 < high
    (tmp_path / "summary.csv").write_text("run,mass_ratio,speed,largest_mass_ratio\nx,0.25,1e5,0.5\n")
    result = cli_here("threshold", str(tmp_path / "summary.csv"))
    assert result.returncode == 2 and "summary.json and its sweep's summary.csv hold them" in result.stderr and len(result.stderr.strip().splitlines()) == 1

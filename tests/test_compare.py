"""decco_warp.analysis.compare and ``decco-warp compare``: intervals that cover the truth at the
stated rate, the runs-needed formula by hand, grouping, and each bad input as one line (exit 2)."""

import csv
import json
import math

import numpy as np
import pytest
from scipy import stats

from decco_warp.analysis import compare as cmp
from decco_warp.durable import json_text

from helpers import cli, cli_here

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


def test_intervals_against_a_value_cover_the_true_mean_95_percent_of_the_time():
    """--against: each small group's mean against the value it was drawn about (Student's t)."""
    covered = 0
    for trial in range(TRIALS):
        rng = np.random.default_rng(trial)
        rows = fake_rows({"none": rng.normal(2.5, 1.0, 5)})
        (difference,) = cmp.compare(rows, "spin_kind", "largest_mass_ratio", against=2.5).points[0].differences
        covered += difference.low <= 0.0 <= difference.high
    assert abs(covered / TRIALS - 0.95) <= COVERAGE_TOLERANCE, covered / TRIALS


def test_a_bonferroni_level_keeps_three_comparisons_at_95_percent_together():
    """Three groups drawn like the reference (no effect at all), each compared on its own
    (per_comparison): at --confidence 1 - 0.05/3 a trial resolves none of its three differences at
    least 95 % of the time (Bonferroni bounds the family's error by 5 %; the shared reference makes
    it a little conservative); at 0.95 each alone errs 5 %."""
    level = 1 - 0.05 / 3
    clean = {level: 0, 0.95: 0}
    for trial in range(TRIALS):
        rng = np.random.default_rng(1000 + trial)
        rows = fake_rows({kind: rng.normal(1.39, 0.02, 8) for kind in ("none", "parallel", "anti-parallel", "perpendicular")})
        for confidence in clean:
            result = cmp.compare(rows, "spin_kind", "largest_mass_ratio", confidence=confidence, per_comparison=True)
            clean[confidence] += not any(d.resolved for d in result.points[0].differences)
    assert clean[level] / TRIALS >= 0.95 - COVERAGE_TOLERANCE, clean
    assert clean[0.95] / TRIALS < 0.92, clean  # three comparisons at 95 % each err together ~13 % of the time


def test_dunnett_s_intervals_are_scipy_s_and_the_default_where_several_groups_meet_the_reference():
    """Three kinds against none at one point: compare()'s intervals are scipy.stats.dunnett's on the
    same values (seeded as compare seeds it), at 95 % and at 90 %; --per-comparison gives Welch's;
    the header says which. A group of one leaves the family; two groups left is one comparison."""
    rng = np.random.default_rng(11)
    values = {"none": rng.normal(1.39, 0.02, 9), "parallel": rng.normal(1.35, 0.03, 10),
              "anti-parallel": rng.normal(1.38, 0.02, 7), "perpendicular": rng.normal(1.36, 0.01, 10)}  # fmt: skip
    rows = fake_rows(values)
    kinds = ["anti-parallel", "parallel", "perpendicular"]  # the order of the table's rows
    for confidence in (0.95, 0.9):
        result = cmp.compare(rows, "spin_kind", "largest_mass_ratio", confidence=confidence)
        differences = result.points[0].differences
        assert [d.group for d in differences] == kinds and {(d.method, d.family) for d in differences} == {("Dunnett", 3)}
        scipy_result = stats.dunnett(*(values[k] for k in kinds), control=values["none"], random_state=np.random.default_rng(cmp.SEED))
        interval = scipy_result.confidence_interval(confidence)
        assert [d.low for d in differences] == pytest.approx(interval.low, rel=1e-9)
        assert [d.high for d in differences] == pytest.approx(interval.high, rel=1e-9)
        assert [d.difference for d in differences] == pytest.approx([values[k].mean() - values["none"].mean() for k in kinds], rel=1e-12)
        # Wider than each comparison's own t interval at the pooled spread: the price of holding three together.
        pooled = cmp.pooled_std(list(values.values()))
        for d, k in zip(differences, kinds):
            half = stats.t.ppf(0.5 + confidence / 2, 32) * pooled * math.sqrt(1 / values[k].size + 1 / 9)
            assert (d.high - d.low) / 2 > half
    assert "95 % simultaneous intervals by Dunnett's test" in cmp.compare(rows, "spin_kind", "largest_mass_ratio").lines()[2]
    alone = cmp.compare(rows, "spin_kind", "largest_mass_ratio", per_comparison=True)
    assert "interval of each comparison on its own (--per-comparison) by Welch's t" in alone.lines()[2]
    for d, k in zip(alone.points[0].differences, kinds):
        assert (d.method, d.family) == ("Welch t", 1) and (d.low, d.high) == pytest.approx(cmp.welch_interval(values[k], values["none"]), rel=1e-12)
    lone = fake_rows({"none": values["none"], "parallel": values["parallel"], "anti-parallel": values["anti-parallel"][:1]})
    parallel = {d.group: d for d in cmp.compare(lone, "spin_kind", "largest_mass_ratio", allow_single=True).points[0].differences}["parallel"]
    assert (parallel.method, parallel.family) == ("Welch t", 1)


def test_dunnett_keeps_the_family_wise_error_near_5_percent_where_per_comparison_intervals_exceed_it():
    """TRIALS sets of a reference and three groups drawn alike (normal, one spread: no difference at
    all): Dunnett's intervals resolve some difference in 5.5 % of the sets (its family-wise error,
    5 % in expectation), the per-comparison ones in 11 %; each of Dunnett's alone errs in 1 %."""
    wrong = {"Dunnett": 0, "per comparison": 0}
    single = 0
    for trial in range(TRIALS):
        rng = np.random.default_rng(2000 + trial)
        rows = fake_rows({kind: rng.normal(1.39, 0.02, 6) for kind in ("none", "parallel", "anti-parallel", "perpendicular")})
        dunnett = cmp.compare(rows, "spin_kind", "largest_mass_ratio").points[0].differences
        alone = cmp.compare(rows, "spin_kind", "largest_mass_ratio", per_comparison=True).points[0].differences
        assert {d.method for d in dunnett} == {"Dunnett"} and {d.method for d in alone} == {"Welch t"}
        wrong["Dunnett"] += any(d.resolved for d in dunnett)
        wrong["per comparison"] += any(d.resolved for d in alone)
        single += dunnett[0].resolved
    assert abs(wrong["Dunnett"] / TRIALS - 0.05) <= COVERAGE_TOLERANCE, wrong
    assert wrong["per comparison"] / TRIALS > 0.05 + COVERAGE_TOLERANCE, wrong
    assert single / TRIALS < 0.05, single


def test_dunnett_is_used_at_any_group_size_and_the_bootstrap_only_for_a_lone_comparison():
    """From 30 runs a group a lone comparison gets the bootstrap; several groups there still get
    Dunnett's (a t method, one pooled spread), and per_comparison the bootstrap for each."""
    rng = np.random.default_rng(12)
    big = {kind: rng.normal(0.0, 1.0, cmp.BOOTSTRAP_FROM) for kind in ("none", "parallel", "perpendicular")}
    methods = lambda result: [d.method for d in result.points[0].differences]  # noqa: E731
    assert methods(cmp.compare(fake_rows(big), "spin_kind", "largest_mass_ratio")) == ["Dunnett", "Dunnett"]
    assert methods(cmp.compare(fake_rows(big), "spin_kind", "largest_mass_ratio", per_comparison=True, resamples=500)) == ["bootstrap"] * 2
    del big["perpendicular"]
    assert methods(cmp.compare(fake_rows(big), "spin_kind", "largest_mass_ratio", resamples=500)) == ["bootstrap"]


def test_the_level_sets_the_t_quantile_and_the_runs_needed():
    rows = fake_rows({"none": [1.0, 2.0, 3.0], "parallel": [2.0, 4.0, 6.0, 8.0]})
    for confidence in (0.9, 0.99):
        result = cmp.compare(rows, "spin_kind", "largest_mass_ratio", confidence=confidence)
        none, (difference,) = result.points[0].groups[0], result.points[0].differences
        half = stats.t.ppf(0.5 + confidence / 2, 2) / math.sqrt(3)
        assert (none.low, none.high) == pytest.approx((2 - half, 2 + half), rel=1e-12)
        assert (difference.low, difference.high) == pytest.approx(cmp.welch_interval(np.array([2.0, 4, 6, 8]), np.array([1.0, 2, 3]), confidence), rel=1e-12)
        assert difference.runs_needed == cmp.runs_needed(math.sqrt((1 + 20 / 3) / 2), 3.0, confidence)
        assert result.as_dict()["confidence"] == confidence
    against = cmp.compare(rows, "spin_kind", "largest_mass_ratio", against=1.0).points[0]
    assert [d.group for d in against.differences] == ["none", "parallel"]  # every group, none a reference
    none = against.differences[0]
    assert none.difference == pytest.approx(1.0) and none.method == "t"
    assert (none.low, none.high) == pytest.approx((1 - stats.t.ppf(0.975, 2) / math.sqrt(3), 1 + stats.t.ppf(0.975, 2) / math.sqrt(3)))
    assert none.runs_needed == cmp.runs_needed(1.0, 1.0, samples=1) == 8  # (1.959964 + 0.841621)^2 = 7.85


def test_against_a_value_checks_the_set_up_within_each_group_only():
    """Groups of different set-ups (the three mass ratios) may each be held against a value; runs
    of two set-ups within one group are still refused."""
    rows = fake_rows({"none": [1.0, 1.1]}, n_particles=5500) + fake_rows({"parallel": [1.2, 1.3]}, n_particles=10000)
    with pytest.raises(cmp.MixedSetups):
        cmp.compare(rows, "spin_kind", "largest_mass_ratio")
    assert len(cmp.compare(rows, "spin_kind", "largest_mass_ratio", against=0.0).points[0].differences) == 2
    with pytest.raises(cmp.MixedSetups):
        cmp.compare(rows, "eta", "largest_mass_ratio", against=0.0)  # one group of 5 500 and 10 000 particles


def test_the_method_follows_the_group_sizes_and_the_bootstrap_is_reproducible():
    rng = np.random.default_rng(7)
    small = fake_rows({"none": rng.normal(0, 1, cmp.BOOTSTRAP_FROM - 1), "parallel": rng.normal(0, 1, 40)})
    large = fake_rows({"none": rng.normal(0, 1, cmp.BOOTSTRAP_FROM), "parallel": rng.normal(3, 1, 40)})
    assert cmp.compare(small, "spin_kind", "largest_mass_ratio").points[0].differences[0].method == "Welch t"
    first, again = (cmp.compare(large, "spin_kind", "largest_mass_ratio").points[0].differences[0] for _ in range(2))
    assert first.method == "bootstrap" and (first.low, first.high) == (again.low, again.high)
    assert first.resolved and first.verdict == "resolved"


def twin_rows(values: dict, eta: float = 12.0, **setup) -> list[dict]:
    """Summary rows of twins: {gravity_every: values}, the k-th value of each clock run on the k-th
    set-up (realization k, its orientation seed and piles), as fig6_clock pairs with fig6_statistics."""
    return [
        {"run": f"k{clock}_r{k}", "gravity_every": clock, "spin_kind": "none", "eta": eta, **SETUP, **setup, "realization": k,
         "orientation_seed": None if k == 0 else 1000 + k, "target_pile": f"target_s{k % 3}", "projectile_pile": "proj",
         "largest_mass_ratio": float(value), "status": "ok"}  # fmt: skip
        for clock, column in values.items()
        for k, value in enumerate(column)
    ]


def test_paired_differences_are_scipy_s_ttest_rel_and_far_narrower_than_welch_s_for_correlated_twins():
    """Twins that share a realization's outcome (spread 0.05) and differ by 0.01 +- 0.004: the paired
    interval is scipy.stats.ttest_rel's (at 95 % and 90 %), its r Pearson's, its detectable
    difference at n - 1 dof; Welch's interval on the same runs is ten times as wide and misses the
    0.01 that the pairs resolve. The rows' order does not matter: twins are found by their columns."""
    rng = np.random.default_rng(21)
    shared = rng.normal(0.5, 0.05, 8)
    k1, k10 = shared + rng.normal(0, 0.002, 8), shared + 0.01 + rng.normal(0, 0.002, 8)
    rows = twin_rows({1: k1, 10: k10})
    rows = [rows[k] for k in rng.permutation(len(rows))]
    for confidence in (0.95, 0.9):
        result = cmp.compare(rows, "gravity_every", "largest_mass_ratio", reference=1, paired=True, confidence=confidence)
        (d,) = result.points[0].differences
        scipy_interval = stats.ttest_rel(k10, k1).confidence_interval(confidence)
        assert (d.low, d.high) == pytest.approx((scipy_interval.low, scipy_interval.high), rel=1e-12)
        assert d.difference == pytest.approx(np.mean(k10 - k1), rel=1e-12) and d.pairs == 8 and d.method == "paired t"
        assert d.correlation == pytest.approx(stats.pearsonr(k10, k1).statistic, rel=1e-12) and d.correlation > 0.99
        spread = np.std(k10 - k1, ddof=1)
        assert d.detectable == pytest.approx((stats.t.ppf(0.5 + confidence / 2, 7) + stats.t.ppf(0.8, 7)) * spread / math.sqrt(8), rel=1e-12)
        assert d.runs_needed == cmp.runs_needed(spread, abs(d.difference), confidence, samples=1)
    welch = cmp.compare(rows, "gravity_every", "largest_mass_ratio", reference=1).points[0].differences[0]
    assert (welch.high - welch.low) > 10 * (d.high - d.low) and d.resolved and not welch.resolved
    assert result.paired and result.unpaired == [] and "pairs: 8 twins; every run has its twin" in result.lines()
    assert result.as_dict()["pair_columns"] == [c for c in cmp.PAIR_COLUMNS if c != "gravity_every"]


def test_paired_intervals_cover_the_true_difference_95_percent_of_the_time():
    """TRIALS seeded sets of five twins (shared outcome spread 0.05, own noise 0.01, true difference
    0.01): the paired t interval holds 0.01 ~95 % of the time."""
    covered = 0
    for trial in range(TRIALS):
        rng = np.random.default_rng(3000 + trial)
        shared = rng.normal(0.5, 0.05, 5)
        rows = twin_rows({1: shared + rng.normal(0, 0.01, 5), 10: shared + 0.01 + rng.normal(0, 0.01, 5)})
        (d,) = cmp.compare(rows, "gravity_every", "largest_mass_ratio", reference=1, paired=True).points[0].differences
        covered += d.low <= 0.01 <= d.high
    assert abs(covered / TRIALS - 0.95) <= COVERAGE_TOLERANCE, covered / TRIALS


def test_twins_agree_in_every_pairing_column_and_the_rest_are_named_or_refused():
    """A run whose realization, piles or set-up has no counterpart is left out and named in the pairs
    line; a group with one twin, two runs of one side alike in every column, several groups without
    --per-comparison and --paired with --against are each refused in one line."""
    rows = twin_rows({1: [0.50, 0.60, 0.55, 0.52], 10: [0.51, 0.62, 0.56, 0.50]})
    rows[3] = {**rows[3], "realization": 7}  # k1_r3: realization 7 has no K = 10 run
    rows[6] = {**rows[6], "target_pile": "other"}  # k10_r2: other piles
    result = cmp.compare(rows, "gravity_every", "largest_mass_ratio", reference=1, paired=True)
    (d,) = result.points[0].differences
    assert d.pairs == 2 and d.difference == pytest.approx(((0.51 - 0.50) + (0.62 - 0.60)) / 2)
    assert sorted(result.unpaired) == ["k10_r2 (gravity_every 10)", "k10_r3 (gravity_every 10)", "k1_r2 (gravity_every 1)", "k1_r3 (gravity_every 1)"]
    (line,) = [line for line in result.lines() if line.startswith("pairs:")]
    assert line.startswith("pairs: 2 twins; 4 run(s) without a twin left out: ") and "k1_r3 (gravity_every 1)" in line
    assert [g.n for g in result.points[0].groups] == [4, 4]  # the groups' own statistics keep every run
    # Twins at a point of --at: the at column is the point's, not a pairing column.
    two = twin_rows({1: [0.5, 0.6], 10: [0.52, 0.61]}) + twin_rows({1: [0.3, 0.35], 10: [0.33, 0.36]}, eta=9.0)
    assert [p.differences[0].pairs for p in cmp.compare(two, "gravity_every", "largest_mass_ratio", at="eta", reference=1, paired=True).points] == [2, 2]
    with pytest.raises(cmp.UnpairedRuns, match=r"gravity_every 10 at eta 12 has 1 twin\(s\) among the gravity_every 1 runs .*without a twin: k1_r1"):
        cmp.compare(two[:3] + two[4:], "gravity_every", "largest_mass_ratio", at="eta", reference=1, paired=True)  # k10_r1 of eta 12 gone
    alike = twin_rows({1: [0.5, 0.6, 0.7], 10: [0.52, 0.61, 0.7]})
    alike[1] = {**alike[1], "realization": 0, "orientation_seed": None, "target_pile": "target_s0"}
    with pytest.raises(cmp.UnpairedRuns, match="runs k1_r0 and k1_r1 agree in every pairing column"):
        cmp.compare(alike, "gravity_every", "largest_mass_ratio", reference=1, paired=True)
    three = rows + [{**row, "run": row["run"].replace("k10", "k50"), "gravity_every": 50} for row in rows if row["gravity_every"] == 10]
    with pytest.raises(cmp.CompareError, match="--paired: 2 groups meet 1 .10, 50.; Dunnett's"):
        cmp.compare(three, "gravity_every", "largest_mass_ratio", reference=1, paired=True)
    each = cmp.compare(three, "gravity_every", "largest_mass_ratio", reference=1, paired=True, per_comparison=True).points[0].differences
    assert [(d.group, d.pairs, d.method) for d in each] == [(10.0, 2, "paired t"), (50.0, 2, "paired t")]
    with pytest.raises(cmp.CompareError, match="--paired and --against"):
        cmp.compare(rows, "gravity_every", "largest_mass_ratio", against=0.0, paired=True)


def test_twins_are_matched_on_their_spin_axes_and_not_on_a_column_one_side_does_not_record():
    """A kind of spin holds two axis pairs: their runs of one realization are two set-ups, paired each
    with its own twin by the axes. A pairing column that one group's runs do not record (an older
    summary without restitution) matches nothing, as the set-up check treats it, and the pairs line
    names it; one that both record still parts runs (the axes)."""
    rows = []
    for law, values in (("paper", [0.50, 0.60, 0.70, 0.80]), ("decco-code", [0.45, 0.56, 0.64, 0.77])):
        for k, value in enumerate(values):
            axes = ("+z", "+z") if k % 2 == 0 else ("+x", "+x")
            rows.append({"run": f"{law}_{axes[0]}_r{k // 2}", "spin_kind": "parallel", "eta": 6.0, **SETUP, "contact_law": law,
                         "target_spin": 0.5, "projectile_spin": 0.5, "target_spin_axis": axes[0], "projectile_spin_axis": axes[1],
                         "realization": k // 2, "largest_mass_ratio": value, "status": "ok"})  # fmt: skip
    rows[4] = {**rows[4], "restitution": 0.9}  # the decco-code runs record restitution, the paper runs do not
    for row in rows[5:]:
        row["restitution"] = 0.9
    result = cmp.compare(rows, "contact_law", "largest_mass_ratio", reference="paper", paired=True)
    (d,) = result.points[0].differences
    assert d.pairs == 4 and d.difference == pytest.approx(np.mean([-0.05, -0.04, -0.06, -0.03]))
    (line,) = [line for line in result.lines() if line.startswith("pairs:")]
    assert line == "pairs: 4 twins; every run has its twin; not matched on restitution (recorded by one side's runs only)"
    third = [{**row, "run": row["run"].replace("decco-code", "ssdem"), "contact_law": "ssdem",
              "largest_mass_ratio": row["largest_mass_ratio"] + 0.01} for row in rows[4:]]  # fmt: skip
    each = cmp.compare(rows + third, "contact_law", "largest_mass_ratio", reference="paper", paired=True, per_comparison=True)
    assert [(d.group, d.pairs) for d in each.points[0].differences] == [("decco-code", 4), ("ssdem", 4)]  # each group its own columns
    assert "restitution" not in each.pair_columns and "target_spin_axis" in each.pair_columns
    rows[6] = {**rows[6], "target_spin_axis": "+y"}  # decco-code's +z r1 now has no twin, and paper's +z r1 none either
    result = cmp.compare(rows, "contact_law", "largest_mass_ratio", reference="paper", paired=True)
    assert result.points[0].differences[0].pairs == 3 and len(result.unpaired) == 2


def test_the_folder_column_names_each_sweep_folder_apart(tmp_path):
    """Each row's folder is its sweep folder's name, with as many parent names as tell two folders
    of one name apart: the same sweep file made in two places is two groups, never one."""
    for place, values in (("v1", [1.0, 1.1]), ("v2", [1.2, 1.3])):
        (tmp_path / place).mkdir()
        write_runs(tmp_path / place / "fig9", fake_rows({"none": values}))
    write_runs(tmp_path / "other", fake_rows({"none": [0.9, 0.95]}))
    rows = cmp.read_rows([tmp_path / "v1" / "fig9" / "summary.csv", tmp_path / "v2" / "fig9", tmp_path / "other" / "summary.csv"])
    assert sorted({row["folder"] for row in rows}) == ["other", "v1/fig9", "v2/fig9"]
    result = cmp.compare(rows, "folder", "largest_mass_ratio", reference="v1/fig9", paired=True, per_comparison=True, allow_mixed=True)
    assert [(d.group, d.pairs) for d in result.points[0].differences] == [("other", 2), ("v2/fig9", 2)]
    assert cmp.folder_names([tmp_path / "a" / "x4", tmp_path / "b" / "x4", tmp_path / "c"]) == {
        tmp_path / "a" / "x4": "a/x4", tmp_path / "b" / "x4": "b/x4", tmp_path / "c": "c"}


def test_one_sweep_file_run_twice_pairs_by_folder_and_run_name(tmp_path):
    """The committed Fig. 9 campaign at eta 6 before sliding friction's zero-slip rule and the same
    sweep file rerun with it: no set-up column tells them apart, the folder does (--by folder), and
    twins are runs of one name. Each kind's paired difference is scipy.stats.ttest_rel's on the
    runs that the csv module reads from the two summary.csv files and matches by name."""
    from pathlib import Path

    root = Path(__file__).parent.parent / "runs" / "results"
    tables = [root / "fig9_statistics" / "summary.csv", root / "fig9_zero_slip" / "summary.csv"]
    made = cli_here("compare", *map(str, tables), "--by", "folder", "--reference", "fig9_statistics", "--metric", "largest_mass_ratio",
                    "--at", "spin_kind", "--where", "eta=6", "--paired", "--json", str(tmp_path / "paired.json"))  # fmt: skip
    assert made.returncode == 0, made.stderr
    assert "pairs: 39 twins; every run has its twin; not matched on restitution" in made.stdout
    before, after = ({row["run"]: row for row in csv.DictReader(path.open(newline="")) if abs(float(row["eta"]) - 6) < 0.01} for path in tables)
    assert sorted(before) == sorted(after) and len(before) == 39
    table = json.loads((tmp_path / "paired.json").read_text())
    for point in table["points"]:
        names = [name for name, row in after.items() if row["spin_kind"] == point["at"]]
        new, old = (np.array([float(side[name]["largest_mass_ratio"]) for name in names]) for side in (after, before))
        (d,) = point["differences"]
        interval = stats.ttest_rel(new, old).confidence_interval()
        assert d["group"] == "fig9_zero_slip" and d["pairs"] == len(names) in (9, 10)
        assert d["difference"] == pytest.approx((new - old).mean(), rel=1e-12)
        assert (d["low"], d["high"]) == pytest.approx((interval.low, interval.high), rel=1e-12)


def test_folders_of_two_laws_pair_across_the_law_and_name_it(tmp_path):
    """One sweep file made under two laws (and restitutions) in two folders: each folder's runs hold
    one law, so by folder the law is what is compared (no mix of set-ups); twins pair across it by
    run name, and the pairs line says so. A folder whose runs hold two laws is no such campaign:
    it is a mix unless asked, and there the law stays a pairing column, so that only runs of one
    law find twins."""
    paper = fake_rows({"none": [0.50, 0.60, 0.55]}, contact_law="paper", restitution=0.9)
    decco = fake_rows({"none": [0.47, 0.58, 0.51]}, contact_law="decco-code", restitution=0.894)
    write_runs(tmp_path / "zero_slip", paper)
    write_runs(tmp_path / "decco_code", decco)
    rows = cmp.read_rows([tmp_path / "zero_slip" / "summary.csv", tmp_path / "decco_code" / "summary.csv"])
    result = cmp.compare(rows, "folder", "largest_mass_ratio", reference="zero_slip", paired=True)
    (d,) = result.points[0].differences
    assert d.pairs == 3 and d.difference == pytest.approx(np.mean([-0.03, -0.02, -0.04]))
    assert sorted(result.varied) == ["contact_law", "restitution"] and "contact_law" not in result.pair_columns
    (line,) = [line for line in result.lines() if line.startswith("pairs:")]
    assert line.endswith("paired across restitution, contact_law (one value in each folder, another in the reference: what the folders compare)")
    unpaired = cmp.compare(rows, "folder", "largest_mass_ratio", reference="zero_slip")  # Welch's, and the header says what parts them
    assert sorted(unpaired.varied) == ["contact_law", "restitution"]
    assert "the folders differ in restitution, contact_law (one value in each folder: what they compare)" in unpaired.lines()
    # A run that does not record the law is no second value: the folders still pair across it.
    blank = [{**row, "folder": "zero_slip", **({"contact_law": None} if row["run"].endswith("r1") else {})} for row in paper]
    (d,) = cmp.compare(blank + [{**row, "folder": "decco_code"} for row in decco], "folder", "largest_mass_ratio",
                       reference="zero_slip", paired=True).points[0].differences  # fmt: skip
    assert d.pairs == 3
    # Piles (no set-up column) are never what folders compare: runs of other piles find no twin.
    moved = [{**row, "folder": "decco_code", "target_pile": "other"} for row in decco]
    with pytest.raises(cmp.UnpairedRuns, match=r"folder decco_code has 0 twin\(s\).*share no value of target_pile"):
        cmp.compare([{**row, "folder": "zero_slip", "target_pile": "target"} for row in paper] + moved, "folder", "largest_mass_ratio",
                    reference="zero_slip", paired=True)  # fmt: skip
    # Folders that each differ from the reference in their own columns: the pairs line names each's.
    cor = fake_rows({"none": [0.49, 0.59, 0.52]}, contact_law="paper", restitution=0.894)
    write_runs(tmp_path / "cor", cor)
    rows = cmp.read_rows([tmp_path / name / "summary.csv" for name in ("zero_slip", "decco_code", "cor")])
    three = cmp.compare(rows, "folder", "largest_mass_ratio", reference="zero_slip", paired=True, per_comparison=True)
    assert [(d.group, d.pairs) for d in three.points[0].differences] == [("cor", 3), ("decco_code", 3)]
    assert three.paired_across == {"cor": ["restitution"], "decco_code": ["restitution", "contact_law"]}
    (line,) = [line for line in three.lines() if line.startswith("pairs:")]
    assert "paired across cor: restitution; decco_code: restitution, contact_law (one value in each folder" in line
    assert result.paired_across == {"decco_code": ["restitution", "contact_law"]}  # one group: the pooled wording above
    mixed = [{**row, "contact_law": "paper", "restitution": 0.9} if row["run"].endswith("r0") else row for row in decco]
    write_runs(tmp_path / "mixed", mixed)
    rows = cmp.read_rows([tmp_path / "zero_slip" / "summary.csv", tmp_path / "mixed" / "summary.csv"])
    with pytest.raises(cmp.UnpairedRuns, match=r"folder mixed has 1 twin\(s\)"):
        cmp.compare(rows, "folder", "largest_mass_ratio", reference="zero_slip", paired=True, allow_mixed=True)
    with pytest.raises(cmp.MixedSetups, match="differ in restitution .0.894, 0.9., not only in folder"):  # unless asked, a folder of two laws is a mix
        cmp.compare(rows, "folder", "largest_mass_ratio", reference="zero_slip")


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


def test_the_minimum_detectable_difference_by_hand_and_never_from_the_difference_seen():
    """detectable = (the interval's quantile + the power's) x the difference's standard error: with
    normal quantiles (a bootstrap's) the delta whose runs_needed is n for two groups of n; for
    Welch's t at its Welch-Satterthwaite dof, for a mean against a value at n - 1; from the groups'
    spreads and sizes alone, the same for groups 0.3 apart as for equal ones, and always beyond the
    interval's own half-width."""
    z = stats.norm.ppf(0.975) + stats.norm.ppf(0.8)  # 2.801585
    assert cmp.detectable_difference(1.0) == pytest.approx(2.801585, abs=1e-6)
    for n in (2, 5, 16, 40):
        delta = cmp.detectable_difference(0.03 * math.sqrt(2 / n))
        assert 2 * z**2 * 0.03**2 / delta**2 == pytest.approx(n, rel=1e-12)  # runs_needed's n, before rounding up
        assert cmp.runs_needed(0.03, delta * (1 + 1e-9)) == max(2, n)
    assert cmp.detectable_difference(1.0, confidence=0.99) == pytest.approx(stats.norm.ppf(0.995) + stats.norm.ppf(0.8))
    assert cmp.detectable_difference(1.0, 4) == pytest.approx(2.776445 + 0.940965, abs=1e-6)  # t_0.975 and t_0.8 at 4 dof
    a, b = np.array([1.0, 2.0, 3.0]), np.array([2.0, 4.0, 6.0, 8.0])
    error, freedom = math.sqrt(1 / 3 + (20 / 3) / 4), 4 / (1 / 18 + 25 / 27)  # as in test_welch_interval_by_hand
    seen = {}
    for shift in (0.0, 0.3):
        (d,) = cmp.compare(fake_rows({"none": a, "parallel": b + shift}), "spin_kind", "largest_mass_ratio").points[0].differences
        seen[shift] = d.detectable
        assert d.detectable > (d.high - d.low) / 2
    assert seen[0.0] == pytest.approx(seen[0.3], rel=1e-12)
    assert seen[0.0] == pytest.approx((stats.t.ppf(0.975, freedom) + stats.t.ppf(0.8, freedom)) * error, rel=1e-12)
    (none,) = cmp.compare(fake_rows({"none": b}), "spin_kind", "largest_mass_ratio", against=0.0).points[0].differences
    assert none.detectable == pytest.approx((stats.t.ppf(0.975, 3) + stats.t.ppf(0.8, 3)) * math.sqrt(20 / 3) / 2, rel=1e-12)


def test_a_true_difference_of_the_detectable_size_is_resolved_at_about_the_stated_power():
    """Groups of 4 runs (Welch's t) whose true difference is the detectable one of the design at its
    t quantiles (Welch's dof 6 for equal spreads): resolved in 75 % of TRIALS seeded trials (near the
    80 % asked: the estimated spread and Welch's dof, often below 6, cost a little); the normal
    figure, (z_0.975 + z_0.8) x error, in 57 %: at 4 runs a group it claims more than they give."""
    n, sigma = 4, 0.02
    error = sigma * math.sqrt(2 / n)
    resolved = {}
    for name, delta in (("t", cmp.detectable_difference(error, 2 * n - 2)), ("z", cmp.detectable_difference(error))):
        resolved[name] = 0
        for trial in range(TRIALS):
            rng = np.random.default_rng(5000 + trial)
            rows = fake_rows({"none": rng.normal(1.0, sigma, n), "parallel": rng.normal(1.0 + delta, sigma, n)})
            resolved[name] += cmp.compare(rows, "spin_kind", "largest_mass_ratio").points[0].differences[0].resolved
    assert 0.70 <= resolved["t"] / TRIALS <= 0.88, resolved
    assert resolved["z"] / TRIALS < 0.65, resolved


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


def test_values_a_rounding_apart_are_one_group_and_one_point():
    """eta as set-up arithmetic writes it (2.9999999999999996, 3.0000000000000004, 3.0) is one point
    under --at and one group under --by; the committed fig6_statistics table, whose eta column holds
    all three and their like at 6, 9 and 12, gives four points of five runs a mass ratio."""
    from pathlib import Path

    rows = fake_rows({"none": [1.0], "parallel": [1.5]}, eta=2.9999999999999996)
    rows += fake_rows({"none": [1.2], "parallel": [1.7]}, eta=3.0000000000000004)
    rows += fake_rows({"none": [1.1], "parallel": [1.6]}, eta=3.0)
    (point,) = cmp.compare(rows, "spin_kind", "largest_mass_ratio", at="eta").points
    assert point.at == 3.0 and [(g.group, g.n) for g in point.groups] == [("none", 3), ("parallel", 3)]
    (point,) = cmp.compare(rows, "eta", "largest_mass_ratio", at="spin_kind", where={"spin_kind": ["none"]}).points
    assert [(g.group, g.n) for g in point.groups] == [(3.0, 3)]
    assert cmp.value_key(2.9999999999999996) == cmp.value_key(3.0000000000000004) == 3.0
    table = Path(__file__).parent.parent / "runs" / "results" / "fig6_statistics" / "summary.csv"
    with table.open(newline="") as f:
        assert {"2.9999999999999996", "3.0000000000000004", "3.0"} <= {row["eta"] for row in csv.DictReader(f)}
    committed = cmp.compare(cmp.read_rows([table]), "mass_ratio", "size_change_late", at="eta", against=0.0)
    assert [p.at for p in committed.points] == [3.0, 6.0, 9.0, 12.0]
    assert [g.n for p in committed.points for g in p.groups] == [5] * 12


def test_rows_of_a_csv_dict_reader_give_the_numbers_of_typed_rows(tmp_path):
    """The Python API takes csv.DictReader's rows (every cell text) as summary.csv is read: the same
    comparison as of the rows as summary.json types them; a value of no summary type is refused."""
    import io

    rows = fake_rows({"none": [1.0, 1.2, 1.1], "parallel": [1.5, 1.7, 1.4]}, eta=3.0) + fake_rows({"none": [0.7, 0.8]}, eta=6.0)
    rows[0]["settled"], rows[1]["reason"] = True, None
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=list(dict.fromkeys(k for row in rows for k in row)))
    writer.writeheader()
    writer.writerows(rows)
    texts = list(csv.DictReader(io.StringIO(table.getvalue())))
    assert all(isinstance(value, str) for value in texts[0].values())
    typed = cmp.compare(rows, "spin_kind", "largest_mass_ratio", at="eta", allow_single=True).as_dict()
    assert cmp.compare(texts, "spin_kind", "largest_mass_ratio", at="eta", allow_single=True).as_dict() == typed
    assert cmp.typed_row(texts[0])["settled"] is True and cmp.typed_row(texts[1])["reason"] is None
    with pytest.raises(cmp.CompareError, match="run none_eta3_r0: column largest_mass_ratio holds a dict"):
        cmp.compare([{**rows[0], "largest_mass_ratio": {"value": 1.0}}, *rows[1:]], "spin_kind", "largest_mass_ratio")
    # A vector spin axis (a list in summary.json) names a group as any value does.
    axes = [{**row, "axis": [1.0, 0.0, 1.0] if row["spin_kind"] == "none" else "+z"} for row in rows]
    groups = {g.group for p in cmp.compare(axes, "axis", "largest_mass_ratio", allow_single=True, allow_mixed=True).points for g in p.groups}
    assert groups == {(1.0, 0.0, 1.0), "+z"}


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


# --- the command -------------------------------------------------------------------------------


def write_runs(folder, rows):
    """A sweep's folder as analyze leaves it: a run folder with summary.json per row, and summary.csv."""
    folder.mkdir()
    for row in rows:
        (folder / row["run"]).mkdir()
        (folder / row["run"] / "summary.json").write_text(json_text({k: v for k, v in row.items() if k != "status"}))
    with (folder / "summary.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({k: ("" if v is None else v) for k, v in row.items()} for row in rows)
    return folder


@pytest.fixture
def sweep(tmp_path):
    """Groups 0.05 apart at eta 6 (resolved) and equal at eta 9 (not), eta as a run set up writes it."""
    rng = np.random.default_rng(3)
    rows = fake_rows({"none": rng.normal(1.39, 0.005, 4), "parallel": rng.normal(1.34, 0.005, 3)}, eta=6.000000000000001)
    rows += fake_rows({"none": rng.normal(0.75, 0.05, 3), "parallel": rng.normal(0.75, 0.05, 3)}, eta=9.0)
    return write_runs(tmp_path / "fig9", rows)


def test_compare_end_to_end_on_run_folders_and_on_summary_csv(sweep, tmp_path):
    out = tmp_path / "compare.json"
    args = ["--by", "spin_kind", "--metric", "largest_mass_ratio", "--at", "eta", "--resolve", "0.01"]
    folders = cli("compare", str(sweep), *args, "--json", str(out))
    assert folders.returncode == 0, folders.stderr
    lines = folders.stdout.splitlines()
    assert lines[0] == "largest_mass_ratio by spin_kind at eta; reference: none"
    assert lines[1] == "runs: 13 read, 13 kept"
    at6, at9 = lines.index("eta 6:"), lines.index("eta 9:")
    assert lines[at6 + 2].split()[:2] == ["none", "4"] and lines[at6 + 2].endswith("reference")
    parallel = lines[at6 + 3]
    assert parallel.split()[:2] == ["parallel", "3"] and "Welch t" in parallel and parallel.endswith("  resolved")
    assert lines[at9 + 3].endswith("not resolved at n = 3 and 3")
    table = json.loads(out.read_text())
    rows = cmp.read_rows([sweep])
    expected = cmp.compare(rows, "spin_kind", "largest_mass_ratio", at="eta", resolve=0.01).as_dict()
    assert table == json.loads(json_text(expected))
    assert table["points"][0]["differences"][0]["runs_needed"] == cmp.runs_needed(
        math.sqrt(sum(g["std"] ** 2 for g in table["points"][0]["groups"]) / 2), 0.01
    )
    # The sweep's table gives the same numbers, from its text.
    sheet = cli_here("compare", str(sweep / "summary.csv"), *args)
    assert sheet.returncode == 0, sheet.stderr
    assert sheet.stdout.splitlines()[1:] == lines[1:-1] and lines[-1] == f"wrote {out}"


def test_paired_clocks_of_the_committed_runs(tmp_path):
    """The review's case: fig6_clock's K = 1 runs and their K = 10 twins of fig6_statistics at eta 12
    (1/10 and 1/4, realizations 0 to 2). --paired gives scipy.stats.ttest_rel's interval on the
    twins as the csv module reads them and pairs them by realization, r 0.986 at 1/10 and its
    interval a quarter of Welch's (+-0.035 against +-0.147); at 1/4 the twins anti-correlate (r
    -0.87) and pairing widens it. No difference is resolved either way."""
    from pathlib import Path

    root = Path(__file__).parent.parent / "runs" / "results"
    tables = [root / "fig6_statistics" / "summary.csv", root / "fig6_clock" / "summary.csv"]
    args = [*map(str, tables), "--by", "gravity_every", "--metric", "largest_mass_ratio", "--at", "mass_ratio", "--where", "eta=12",
            "--where", "mass_ratio=0.1,0.25", "--where", "realization=0,1,2", "--reference", "1"]  # fmt: skip
    paired, welch = cli_here("compare", *args, "--paired", "--json", str(tmp_path / "paired.json")), cli_here("compare", *args)
    assert paired.returncode == welch.returncode == 0, (paired.stderr, welch.stderr)
    assert "pairs: 6 twins; every run has its twin" in paired.stdout.splitlines()
    table = json.loads((tmp_path / "paired.json").read_text())
    values = {}
    for path in tables:
        with path.open(newline="") as f:
            for row in csv.DictReader(f):
                if abs(float(row["eta"]) - 12) < 0.01 and row["realization"] in "012" and float(row["mass_ratio"]) < 0.3:
                    values[(round(float(row["mass_ratio"]), 2), int(row["gravity_every"]), int(row["realization"]))] = float(row["largest_mass_ratio"])
    half = {}
    for point, welch_point, ratio in zip(table["points"], cmp.compare(cmp.read_rows(tables), "gravity_every", "largest_mass_ratio", at="mass_ratio",
                                         where=cmp.parse_where(["eta=12", "mass_ratio=0.1,0.25", "realization=0,1,2"]), reference=1).points, (0.1, 0.25)):  # fmt: skip
        k1, k10 = (np.array([values[(ratio, clock, k)] for k in range(3)]) for clock in (1, 10))
        (d,), (w,) = point["differences"], welch_point.differences
        scipy_interval = stats.ttest_rel(k10, k1).confidence_interval()
        assert (d["low"], d["high"]) == pytest.approx((scipy_interval.low, scipy_interval.high), rel=1e-12)
        assert d["pairs"] == 3 and d["correlation"] == pytest.approx(stats.pearsonr(k10, k1).statistic, rel=1e-9) and not d["resolved"]
        half[ratio] = ((d["high"] - d["low"]) / 2, (w.high - w.low) / 2)
    assert half[0.1][0] == pytest.approx(0.035, abs=5e-4) and half[0.1][1] == pytest.approx(0.147, abs=5e-4)
    assert half[0.25][0] > half[0.25][1]  # anti-correlated twins: pairing costs
    assert table["points"][0]["differences"][0]["correlation"] > 0.98 and table["points"][1]["differences"][0]["correlation"] < -0.8


@pytest.fixture
def bad_inputs(sweep, tmp_path):
    """{case: (decco-warp arguments, words its error line must hold)}: each bad input of compare."""
    base = ["--by", "spin_kind", "--metric", "largest_mass_ratio"]
    lone = write_runs(tmp_path / "lone", fake_rows({"none": [1.0, 1.1], "parallel": [1.2]}))
    mixed = write_runs(tmp_path / "mixed", fake_rows({"none": [1.0, 1.1]}) + fake_rows({"parallel": [1.2, 1.3]}, mass_ratio=0.25))
    clocks = write_runs(tmp_path / "clocks", fake_rows({"none": [1.0, 1.1]}, gravity_every=1) + fake_rows({"parallel": [1.2, 1.3]}, gravity_every=10))
    (tmp_path / "empty").mkdir()
    outcome = {"particle_size_change": 2.5, "deepest_overlap": 0.61, "momentum_drift": 1.2e-9}
    twice = fake_rows({"none": [1.0, 1.1, 1.2], "parallel": [1.3, 1.3]})
    twice = write_runs(tmp_path / "twice", [{**row, **outcome} for row in twice])  # parallel_r0, parallel_r1: one run
    return {
        "unknown column": ([str(sweep), "--by", "spin_kind", "--metric", "largest_mass"], ["--metric largest_mass: no such column", "spin_kind"]),
        "unknown --at": ([str(sweep), *base, "--at", "etta"], ["--at etta: no such column", "eta"]),
        "a sweep's column of run folders": ([str(sweep / "parallel_eta6_r0"), *base, "--where", "realization=0"],
                                            ["--where realization: no such column (realization is a column of a sweep's summary.csv"]),
        "not numeric": ([str(sweep), "--by", "spin_kind", "--metric", "eta_potential"], ["--metric eta_potential is not numeric", "'self'"]),
        "group of one": ([str(lone), *base], ["1 group(s) of one run", "parallel", "--allow-single"]),
        "mixed set-ups": ([str(mixed), *base], ["differ in mass_ratio (0.25, 1)", "--allow-mixed"]),
        "mixed clocks": ([str(clocks), *base], ["differ in gravity_every (1, 10)", "--allow-mixed"]),
        "no runs": ([str(tmp_path / "empty"), *base], ["holds no summary.json"]),
        "no such path": ([str(tmp_path / "nowhere"), *base], ["does not exist"]),
        "nothing matches": ([str(sweep), *base, "--where", "eta=12"], ["no run matches --where eta=12"]),
        "bad --where": ([str(sweep), *base, "--where", "eta"], ["--where takes COLUMN=VALUE"]),
        "unknown reference": ([str(sweep), *base, "--reference", "oblique"], ["--reference oblique", "none, parallel"]),
        "read twice": ([str(sweep), str(sweep / "summary.csv"), *base], ["is read twice"]),
        "group and value": ([str(sweep), *base, "--reference", "none", "--against", "0"], ["--reference and --against", "not both"]),
        "per comparison against a value": ([str(sweep), *base, "--against", "0", "--per-comparison"], ["--per-comparison and --against"]),
        "paired against a value": ([str(sweep), *base, "--against", "0", "--paired"], ["--paired and --against"]),
        "twins not told apart": ([str(sweep), *base, "--at", "eta", "--paired"], ["runs parallel_eta6_r0 and parallel_eta6_r1 agree in every pairing column",
                                                                               "realization column"]),
        "bad level": ([str(sweep), *base, "--confidence", "95"], ["--confidence must be a level from 0.5 to 0.9999", "got 95"]),
        "one set-up twice": ([str(twice), *base], ["parallel_eta6_r0 and parallel_eta6_r1 have the same outcome", "give it once"]),
    }


def test_each_bad_comparison_is_one_line_naming_it_and_exit_2(bad_inputs):
    for case, (args, words) in bad_inputs.items():
        result = cli_here("compare", *args)
        assert result.returncode == 2, (case, result.stdout, result.stderr)
        assert len(result.stderr.splitlines()) == 1 and result.stderr.startswith("decco-warp: error: "), (case, result.stderr)
        for word in words:
            assert word in result.stderr, (case, word, result.stderr)
        if case != "group of one":
            assert result.stdout == "", case  # refused before any table


def test_a_group_of_one_still_shows_the_rest_and_the_allow_options_accept(bad_inputs):
    lone, _ = bad_inputs["group of one"]
    refused = cli_here("compare", *lone)
    assert "spread unknown: 1 run of parallel" in refused.stdout and refused.returncode == 2
    accepted = cli_here("compare", *lone, "--allow-single")
    assert accepted.returncode == 0 and accepted.stdout == refused.stdout
    mixed, _ = bad_inputs["mixed set-ups"]
    assert cli_here("compare", *mixed, "--allow-mixed").returncode == 0


def test_the_sweep_columns_are_those_a_sweep_adds_to_each_run_summary():
    """compare's SWEEP_COLUMNS (named when run folders are asked for one) are exactly the columns of
    a sweep's summary.csv that its runs' summary.json do not hold (a committed sweep's files)."""
    from pathlib import Path

    from decco_warp.sweep import SUMMARY_FIELDS

    folder = Path(__file__).parent.parent / "runs" / "results" / "fig6_statistics"
    run_keys = set().union(*(json.loads(p.read_text()) for p in folder.glob("*/summary.json")))
    with (folder / "summary.csv").open(newline="") as f:
        header = next(csv.reader(f))
    # The committed runs' summaries predate the columns of the run's set-up and of the impact in LS12
    # terms (runs/results/refresh.py adds them): those are run columns too.
    from decco_warp.analysis.runs import spec_columns
    from decco_warp.analysis.scaling import IMPACT_COLUMNS
    from decco_warp.spec import resolve_spec

    run_keys |= {*spec_columns(resolve_spec({})), *IMPACT_COLUMNS}
    assert set(header) <= set(SUMMARY_FIELDS)
    assert set(SUMMARY_FIELDS) - run_keys == set(cmp.SWEEP_COLUMNS)

"""Run analysis: paper metrics on constructed examples, analysis.h5, figures and cross-run output."""

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import cli, cli_here

import decco_warp as dw
from decco_warp.analysis.figures import RUN_FIGURES, line_data
from decco_warp.analysis.runs import (
    SETTLED_TOLERANCE,
    analyse_snapshot,
    late_statistics,
    mass_weighted_size_change,
    particle_size_change,
    read_analysis,
    refresh_summary,
)
from decco_warp.collision import pile_radius
from decco_warp.diagnostics import stress_shares
from decco_warp.run import builtin_pile




def test_stress_shares_by_hand():
    # 250 particles: 200 small, 40 medium, 10 large; the top 1 % is ceil(2.5) = 3 particles.
    size_class = np.repeat([0, 1, 2], [200, 40, 10])
    stress = np.zeros(250)
    stress[[245, 246]] = [9.0, 8.0]  # two large
    stress[[210]] = [7.0]  # one medium
    stress[[0, 1]] = [1.0, 1.0]  # smaller than the top three
    shares = stress_shares(stress, size_class, 3)
    np.testing.assert_allclose(shares, [100 * 0 / 200, 100 * 1 / 40, 100 * 2 / 10])
    # A class with no particles has no share.
    assert np.isnan(stress_shares(stress, size_class, 4)[3])
    # By default, and by name, the measure is the paper's: the largest overlap itself.
    np.testing.assert_array_equal(stress_shares(stress, size_class, 3, measure="overlap"), shares)
    with pytest.raises(ValueError, match="radii"):
        stress_shares(stress, size_class, 3, measure="per_area")
    with pytest.raises(ValueError, match="unknown stress measure"):
        stress_shares(stress, size_class, 3, np.ones(250), measure="force")


def _shares_by_hand(values, size_class, classes):
    """100 N_c,top / N_c of the top 1 % of ``values`` (ties to the lower index), counted in a loop."""
    n = len(values)
    top = -(-n // 100)
    ranked = sorted(range(n), key=lambda i: (-values[i], i))[:top]
    return np.array([100.0 * sum(size_class[i] == c for i in ranked) / np.sum(size_class == c) for c in range(classes)])


def test_the_three_stress_measures_rank_differently_by_hand():
    """With one spring constant the largest overlap delta ranks force, so the large grains lead; by
    delta / R^2 (force per cross-section) the small grains can lead, by delta / R (strain) the medium
    ones: three tops of 3 particles, each of another class, checked against shares counted by hand."""
    # 300 particles: 200 small (R = 1), 80 medium (R = 2), 20 large (R = 4); the top 1 % is 3.
    size_class = np.repeat([0, 1, 2], [200, 80, 20])
    radii = np.array([1.0, 2.0, 4.0])[size_class]
    stress = np.zeros(300)
    stress[[280, 281, 282]] = 1.0  # large: delta 1.0, delta/R 0.25, delta/R^2 0.0625
    stress[[200, 201, 202]] = 0.8  # medium: delta 0.8, delta/R 0.4, delta/R^2 0.2
    stress[[0, 1, 2]] = 0.3  # small: delta 0.3, delta/R 0.3, delta/R^2 0.3
    expected = {
        "overlap": [0.0, 0.0, 100 * 3 / 20],
        "strain": [0.0, 100 * 3 / 80, 0.0],
        "per_area": [100 * 3 / 200, 0.0, 0.0],
    }
    powers = {"overlap": 0, "strain": 1, "per_area": 2}
    for measure, shares in expected.items():
        got = stress_shares(stress, size_class, 3, radii, measure=measure)
        np.testing.assert_allclose(got, shares, err_msg=measure)
        np.testing.assert_allclose(got, _shares_by_hand(stress / radii ** powers[measure], size_class, 3), err_msg=measure)
    # A mixed top, and ties at the boundary to the lower index: the largest overlap is a large grain's,
    # the next two tie between a medium grain (index 203) and a small one (index 3), both 0.5 / R^2 ...
    stress[:] = 0.0
    stress[[283, 203, 3]] = [4.0, 2.0, 0.5]
    stress[4] = 0.5  # ... and a second small grain ties with the first; index 3 wins
    # per_area: 283 -> 0.25, 203 -> 0.5, 3 -> 0.5, 4 -> 0.5: the top is 203, 3, 4 (0.5 each, by index)
    np.testing.assert_allclose(stress_shares(stress, size_class, 3, radii, measure="per_area"), [100 * 2 / 200, 100 * 1 / 80, 0.0])
    # strain: 283 -> 1.0, 203 -> 1.0, 3 and 4 -> 0.5: the top is 203, 283 (1.0 each), then 3
    np.testing.assert_allclose(stress_shares(stress, size_class, 3, radii, measure="strain"), [100 * 1 / 200, 100 * 1 / 80, 100 * 1 / 20])
    # overlap: 283, 203, then 3 (ties with 4 at 0.5)
    np.testing.assert_allclose(stress_shares(stress, size_class, 3, radii), [100 * 1 / 200, 100 * 1 / 80, 100 * 1 / 20])
    for measure, power in powers.items():
        np.testing.assert_allclose(stress_shares(stress, size_class, 3, radii, measure=measure),
                                   _shares_by_hand(stress / radii**power, size_class, 3), err_msg=measure)  # fmt: skip


def test_particle_size_change_by_hand():
    # Parents: 10 particles of 2 g and 30 of 1 g -> mean 1.25 g; a fragment of 4 x 2 g + 2 x 1 g -> 10/6 g.
    assert particle_size_change(10.0, 6, 50.0, 40) == pytest.approx(100 * ((10 / 6) / 1.25 - 1))
    assert particle_size_change(5.0, 4, 50.0, 40) == pytest.approx(0.0)


def test_mass_weighted_size_change_by_hand():
    # Parents 10 x 2 g + 30 x 1 g: sum m^2 / sum m = (40 + 30) / 50 = 1.4 g; fragment 4 x 2 g + 2 x 1 g: 18 / 10.
    parents = np.array([2.0] * 10 + [1.0] * 30)
    fragment = np.array([2.0] * 4 + [1.0] * 2)
    assert mass_weighted_size_change(fragment, parents) == pytest.approx(100 * (1.8 / 1.4 - 1))
    assert mass_weighted_size_change(parents[::2], parents) == pytest.approx(0.0)


def _frames(time, ratio, clusters, change):
    return {"time": np.asarray(time, float), "largest_mass_ratio": np.asarray(ratio, float),
            "clusters": np.asarray(clusters), "particle_size_change": np.asarray(change, float)}  # fmt: skip


def test_late_window_means_and_the_settled_verdict():
    """The last 10 % of the run: t >= 900 s of 0..1000 s here, frames at 900, 950, 1000."""
    time = np.arange(0, 1001, 50)
    quiet = _frames(time, [1.2] * 18 + [0.80, 0.805, 0.802], [1] * 21, [9.0] * 18 + [2.0, 4.0, 3.0])
    stats = late_statistics(quiet)
    assert stats["late_frames"] == 3 and stats["late_from_time"] == 900.0
    assert stats["size_change_late"] == pytest.approx(3.0) and stats["size_change_late_std"] == pytest.approx(np.std([2.0, 4.0, 3.0]))
    assert stats["size_change_mass_weighted_late"] is None  # no such series: not measured
    assert (stats["largest_mass_ratio_late_low"], stats["largest_mass_ratio_late_high"]) == (0.80, 0.805)
    assert stats["settled"] is True and "0.8 to 0.805" in stats["settled_note"]
    # m_lf/m_t moving by more than the tolerance, a flickering cluster count, a frame without any
    # cluster (the debris still in flight), or too few frames: not settled, and the note says why.
    moving = _frames(time, [1.2] * 18 + [0.80, 0.80 + 2 * SETTLED_TOLERANCE, 0.80], [1] * 21, [1.0] * 21)
    flicker = _frames(time, [1.0] * 21, [1] * 18 + [1, 2, 1], [1.0] * 21)
    lost = _frames(time, [0.99] * 18 + [0.99, 0.0, 0.93], [1] * 18 + [1, 0, 1], [1.0] * 18 + [1.0, np.nan, 1.0])
    short = _frames([0, 500, 1000], [1.0] * 3, [1] * 3, [1.0] * 3)
    for frames, reason in ((moving, "0.8 to 0.82"), (flicker, "1 to 2 cluster(s)"), (lost, "no cluster in 1 of the 3"), (short, "1 analysed frame")):
        stats = late_statistics(frames)
        assert stats["settled"] is False and reason in stats["settled_note"], stats["settled_note"]
    assert late_statistics(lost)["size_change_late"] == pytest.approx(1.0)  # the frame without a fragment left out
    # Counted by mass, a clump of 0.5 % of the target that comes and goes changes nothing; one of 5 % does.
    masses = np.zeros((21, 2))
    masses[:, 0] = 1.0e22
    flicker["cluster_mass"] = masses.copy()
    flicker["cluster_mass"][19, 1] = 0.005e22
    assert late_statistics(flicker, target_mass=1e22)["settled"] is True
    flicker["cluster_mass"][19, 1] = 0.05e22
    stats = late_statistics(flicker, target_mass=1e22)
    assert stats["settled"] is False and "1 to 2 fragment(s) of >= 0.01 m_t" in stats["settled_note"]


def test_snapshot_analysis_of_a_spinning_pile_and_a_receding_one():
    target = dw.load_pile(builtin_pile("target"))
    projectile = dw.load_pile(builtin_pile("projectile"))
    s = dw.setup_collision(target, projectile, speed=5e5, theta_deg=0.0, gap=5e7, projectile_spin=(0.5, "+z"))
    result = analyse_snapshot(s, target.total_mass, min_members=50)
    big, small = result["clusters"]
    assert result["largest_mass_ratio"] == pytest.approx(1.0, rel=1e-12)
    assert big["members"] == target.n and small["members"] == projectile.n
    assert big["composition"].tolist() == np.bincount(target.size_class).tolist()
    omega = 0.5 * np.sqrt(dw.G_CGS * projectile.total_mass / pile_radius(projectile) ** 3)
    np.testing.assert_allclose(small["spin"], [0, 0, omega], rtol=0, atol=1e-3 * omega)
    assert np.linalg.norm(big["spin"]) < 1e-3 * omega
    assert result["label"].tolist() == [0] * target.n + [1] * projectile.n
    parents_mean = s.total_mass / s.n
    assert result["particle_size_change"] == pytest.approx(100 * ((target.total_mass / target.n) / parents_mean - 1))


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """Two short runs of the demo piles at different eta, analysed as a set."""
    out = tmp_path_factory.mktemp("sweep")
    for name, eta in (("eta0.5", "0.5"), ("eta1", "1.0")):
        result = cli("simulate", "--name", name, "--eta", eta, "--steps", "400", "--output-every", "100",
                      "--out", str(out), "--device", "cpu")
        assert result.returncode == 0, result.stderr
    result = cli("analyze", str(out), "--min-members", "20")
    assert result.returncode == 0, result.stderr
    return out, result


def test_analyze_writes_analysis_and_figures_that_show_its_data(sweep):
    out, result = sweep
    run_dir = out / "eta0.5"
    assert "m_lf/m_t" in result.stdout
    analysis = read_analysis(run_dir / "analysis.h5")
    summary = json.loads((run_dir / "summary.json").read_text())
    assert summary["largest_mass_ratio"] == pytest.approx(analysis["frames"]["largest_mass_ratio"][-1])
    assert analysis["frames"]["step"].tolist() == [0, 100, 200, 300, 400]
    # At the start, the two piles are separate clusters: the target and the projectile.
    assert analysis["frames"]["clusters"][0] == 2 and analysis["frames"]["largest_mass_ratio"][0] == pytest.approx(1.0)
    for name in RUN_FIGURES:
        for suffix in ("png", "pdf"):
            assert (run_dir / "figures" / f"{name}.{suffix}").stat().st_size > 1000
    # The figures plot exactly the analysis output.
    from decco_warp.analysis.figures import DRIFT_FLOOR

    lines = line_data(RUN_FIGURES["conservation"](analysis))  # on a log axis: an exact 0 drawn at the floor
    np.testing.assert_array_equal(lines[0][1], np.maximum(analysis["conservation"]["momentum_drift"], DRIFT_FLOOR))
    np.testing.assert_array_equal(lines[1][1], np.maximum(analysis["conservation"]["angular_momentum_drift"], DRIFT_FLOOR))
    # A panel for each stress measure, the paper's first: each class's series, then its value at t = 0.
    fig = RUN_FIGURES["stress_shares"](analysis)
    assert len(fig.axes) == 3
    for ax, name in zip(fig.axes, ("stress_share", "stress_share_per_area", "stress_share_strain")):
        for k in range(3):
            np.testing.assert_array_equal(ax.lines[2 * k].get_ydata(), analysis[name]["value"][:, k], err_msg=name)
            np.testing.assert_array_equal(ax.lines[2 * k + 1].get_ydata(), [analysis[name]["value"][0, k]] * 2, err_msg=name)
    # An analysis kept before the last two were recorded draws the paper's alone.
    older = {key: value for key, value in analysis.items() if key not in ("stress_share_per_area", "stress_share_strain")}
    fig = RUN_FIGURES["stress_shares"](older)
    assert len(fig.axes) == 1
    np.testing.assert_array_equal(line_data(fig)[0][1], analysis["stress_share"]["value"][:, 0])
    energy = analysis["energy"]
    lines = line_data(RUN_FIGURES["energy"](analysis))
    np.testing.assert_array_equal(lines[0][1], energy["kinetic_translational"] + energy["kinetic_rotational"])
    np.testing.assert_allclose(lines[-1][1], energy["total_energy"][0], rtol=1e-10)  # the books balance
    assert analysis["conservation"]["momentum_drift"].max() < 1e-6


def _strict(text: str):
    """JSON parsed as RFC 8259 has it: NaN and Infinity are not numbers there."""

    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")

    return json.loads(text, parse_constant=refuse)


def test_summary_is_strict_json_with_both_etas_the_laws_and_the_verdict(sweep):
    out, result = sweep
    for run_dir in (out / "eta0.5", out / "eta1"):
        summary = _strict((run_dir / "summary.json").read_text())
        assert summary["eta_potential"] == "self" and summary["eta_self"] == pytest.approx(summary["eta"], rel=1e-12)
        assert summary["cross_potential"] < 0 and summary["eta_all"] < summary["eta_self"]
        assert summary["ls12_band_low"] <= summary["ls12_largest_mass_ratio"] <= summary["ls12_band_high"]
        assert summary["ls12_planets_largest_mass_ratio"] <= summary["ls12_largest_mass_ratio"]
        assert summary["contact_surface_speed"] == 0.0  # no spins
        assert isinstance(summary["settled"], bool) and summary["settled_note"]
        assert ("settled" if summary["settled"] else "NOT SETTLED") in result.stdout
    _strict((out / "summaries.json").read_text())


def test_a_summary_carries_every_parameter_of_its_run_and_the_impact_in_ls12_terms(sweep):
    """Every key of the run's resolved [params] (and its [collision] and [run] set-up) is a column of
    summary.json with spec.toml's value; the impact speed over the mutual escape speed, Q_R and
    Q_R / Q*_RD agree with the same numbers computed here from the set-up's masses, radii and speed,
    and Q_R / Q*_RD with the LS12 column (below 1.8 Q*_RD the law is M_lr / M_tot = 1 - Q_R / 2 Q*_RD)."""
    import tomllib

    out, _ = sweep
    for run_dir in (out / "eta0.5", out / "eta1"):
        summary = _strict((run_dir / "summary.json").read_text())
        spec = tomllib.loads((run_dir / "spec.toml").read_text())
        for key, value in spec["params"].items():
            assert summary[key] == value, key
        for key in ("gap", "target_spin", "projectile_spin_axis", "eta_potential"):
            assert summary[key] == spec["collision"][key], key
        assert summary["run_device"] == spec["run"]["device"] and summary["precision"] == spec["run"]["precision"]
        meta = dw.read_trajectory(run_dir / "trajectory.h5").parameters["collision"]
        m_t, m_p, r_t, r_p = meta["target_mass"], meta["projectile_mass"], meta["target_radius"], meta["projectile_radius"]
        escape = np.sqrt(2 * spec["params"]["G"] * (m_t + m_p) / (r_t + r_p))
        assert summary["speed_over_escape"] == pytest.approx(meta["speed"] / escape, rel=1e-12)
        reduced = m_t * m_p / (m_t + m_p)
        assert summary["q_r"] == pytest.approx(0.5 * reduced * meta["speed"] ** 2 / (m_t + m_p), rel=1e-12)
        ratio = summary["q_r"] / summary["q_rd_star"]
        assert summary["q_r_over_q_rd_star"] == pytest.approx(ratio, rel=1e-12) and ratio < 1.8
        assert summary["ls12_largest_mass_ratio"] * m_t / (m_t + m_p) == pytest.approx(1 - ratio / 2, rel=1e-12)


def test_ratios_and_spreads_are_stored_without_round_off():
    """eta computed back from a set-up for eta 3 reads 2.9999999999999996: kept as 3; the spread of
    equal values (whose float mean is not always that value) is 0, any real spread its std."""
    from decco_warp.analysis.runs import rounded, spread

    assert rounded(2.9999999999999996) == 3.0 and rounded(0.1 + 0.2) == 0.3 and rounded(None) is None
    assert rounded(2.284224635012422) == pytest.approx(2.284224635012422, rel=1e-11)  # 12 significant digits
    equal = np.full(7, 0.1)
    assert np.std(equal) > 0 and spread(equal) == 0.0  # the float mean of seven 0.1 is not 0.1
    assert spread(np.array([1.0, 2.0, 4.0])) == np.std([1.0, 2.0, 4.0])
    assert 100 * ((0.1 * 7 / 7) / (0.1 * 3 / 3) - 1) != 0 and particle_size_change(0.1 * 7, 7, 0.1 * 3, 3) == 0.0
    assert particle_size_change(1.0, 1, 1.0, 2) == pytest.approx(100.0)


def test_a_run_without_any_cluster_writes_null_not_nan(tmp_path):
    """No cluster of min_members at the end: m_lf/m_t is 0 and the size change does not exist, which
    strict JSON says as null; the CLI line says the result is not settled."""
    result = cli("simulate", "--name", "a", "--eta", "0.5", "--steps", "400", "--output-every", "20", "--out", str(tmp_path), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    result = cli("analyze", str(tmp_path / "a"), "--min-members", "100000")
    assert result.returncode == 0, result.stderr
    summary = _strict((tmp_path / "a" / "summary.json").read_text())
    assert summary["largest_mass_ratio"] == 0.0 and summary["particle_size_change"] is None and summary["size_change_late"] is None
    assert summary["settled"] is False and "NOT SETTLED (no cluster" in result.stdout
    assert summary["gravity_every"] == 1 and summary["dt"] == 0.04  # the clocks, recorded for compare


def test_analysis_keeps_velocities_labels_per_frame_and_units(sweep):
    out, _ = sweep
    import h5py

    with h5py.File(out / "eta1" / "analysis.h5", "r") as f:
        frames, final = f["frames"], f["final"]
        assert frames["label"].shape == (5, final["positions"].shape[0]) and frames["label"].compression == "gzip"
        np.testing.assert_array_equal(frames["label"][-1], final["label"][()])
        assert final["velocities"].shape == final["positions"].shape
        assert final["velocities"].attrs["unit"] == "cm s-1" and frames["time"].attrs["unit"] == "s"
        members = final["label"][()] == 0
        composition = np.bincount(final["size_class"][()][members], minlength=frames["largest_composition"].shape[1])
        np.testing.assert_array_equal(frames["largest_composition"][-1], composition)
        masses = final["particle_mass"][()]
        assert frames["particle_size_change_mass_weighted"][-1] == pytest.approx(mass_weighted_size_change(masses[members], masses), rel=1e-12)


def test_a_summary_is_refreshed_from_analysis_h5_alone(sweep, tmp_path):
    """A run kept without its trajectory: its summary recomputed from analysis.h5 and its set-up gives
    the analysis's own numbers."""
    import shutil

    out, _ = sweep
    kept = tmp_path / "eta1"
    shutil.copytree(out / "eta1", kept, ignore=shutil.ignore_patterns("trajectory.h5", "checkpoint.h5"))
    before = json.loads((kept / "summary.json").read_text())
    parameters = dw.read_trajectory(out / "eta1" / "trajectory.h5").parameters
    spec = parameters["spec"]
    after = refresh_summary(kept, parameters["collision"], spec["params"], piles=spec["piles"], spec=spec)
    assert _strict((kept / "summary.json").read_text()) == after
    for key, value in before.items():
        assert after[key] == (pytest.approx(value, rel=1e-12) if isinstance(value, float) else value), key


def test_a_trajectory_without_the_newer_stress_shares_is_analysed_with_them_from_its_stress(tmp_path, monkeypatch):
    """A run written before stress_share_per_area and stress_share_strain were recorded (deleted
    here) is analysed with them, computed from each frame's recorded stress and the radii: the
    numbers the run records today.  Resumed, such a run gains the series with NaN for its earlier
    frames; the analysis fills those frames from their stress and keeps those recorded since (the
    stress read 3 frames at a time here, so that the reads come in several chunks)."""
    import h5py

    from decco_warp import spec as specs
    from decco_warp.analysis import runs
    from decco_warp.analysis.runs import analyse_run
    from decco_warp.run import resume_run, start_run

    monkeypatch.setattr(runs, "STRESS_CHUNK", 3)

    def run(name, steps):
        spec = specs.resolve_spec({"run": {"name": name, "out": str(tmp_path), "device": "cpu", "steps": steps,
                                           "output_every": 50, "checkpoint_every": 100}})  # fmt: skip
        start_run(spec)
        return tmp_path / name

    newer = ("stress_share_per_area", "stress_share_strain")
    today, old = run("today", 300), run("old", 150)
    recorded = dw.read_trajectory(today / "trajectory.h5")
    shares = {name: recorded.observables[name] for name in ("stress_share", *newer)}
    assert not np.array_equal(shares["stress_share"], shares["stress_share_per_area"])  # they rank differently here
    stress, radii, classes = recorded.particles["stress"], recorded.static["radius"], recorded.static["species"]
    for name, measure in (("stress_share_per_area", "per_area"), ("stress_share_strain", "strain")):
        np.testing.assert_array_equal(shares[name], [stress_shares(row, classes, 3, radii, measure=measure) for row in stress])
    analysis = analyse_run(today, min_members=20, workers=1)
    for name, value in shares.items():
        np.testing.assert_array_equal(analysis[name]["value"], value, err_msg=name)
        np.testing.assert_array_equal(analysis[name]["time"], recorded.time, err_msg=name)

    with h5py.File(old / "trajectory.h5", "r+") as f:
        for name in newer:
            del f[f"observables/{name}"]
    analysed = analyse_run(old, min_members=20, workers=1)
    for name, value in shares.items():
        np.testing.assert_array_equal(analysed[name]["value"], value[:4], err_msg=name)
    assert read_analysis(old / "analysis.h5")["stress_share_strain"]["value"].shape == (4, 3)

    resume_run(old, steps=300)
    data = dw.read_trajectory(old / "trajectory.h5")
    for name in newer:
        assert np.isnan(data.observables[name][:4]).all() and not np.isnan(data.observables[name][4:]).any()
    analysed = analyse_run(old, min_members=20, workers=1)
    for name, value in shares.items():
        np.testing.assert_array_equal(analysed[name]["value"], value, err_msg=name)


def test_analyze_of_a_set_of_runs_makes_the_cross_run_table_and_figures(sweep):
    out, _ = sweep
    rows = (out / "summary.csv").read_text().splitlines()
    columns = rows[0].split(",")
    assert columns[0] == "run" and len(rows) == 3
    assert {"n_particles", "eta", "speed", "theta_deg", "mass_ratio", "largest_mass_ratio", "deepest_overlap", "ledger_closure"} <= set(columns)
    for name in ("largest_fragment", "particle_size_change"):
        assert (out / "figures" / f"{name}.png").stat().st_size > 1000
    summaries = json.loads((out / "summaries.json").read_text())
    assert sorted(s["eta"] for s in summaries) == pytest.approx([0.5, 1.0])


def test_a_run_s_fragment_history_and_debris_figures_show_its_analysis(sweep):
    """largest_fragment_time draws the analysed frames' m_lf/m_t; debris_sizes every cluster and each
    lone grain as a fragment, largest first, whose cumulative mass ends at the run's whole mass."""
    from decco_warp.analysis.figures import debris_sizes

    out, _ = sweep
    analysis = read_analysis(out / "eta1" / "analysis.h5")
    frames, final = analysis["frames"], analysis["final"]
    (line,) = [line for line in line_data(RUN_FIGURES["largest_fragment_time"](analysis)) if line[0].size == frames["time"].size]
    np.testing.assert_array_equal(line[0], frames["time"] / 3600.0)
    np.testing.assert_array_equal(line[1], frames["largest_mass_ratio"])
    masses, cumulative = debris_sizes(final)
    lone = final["particle_mass"][final["label"] < 0]
    assert masses.size == final["mass"].size + lone.size and np.all(np.diff(masses) <= 0)
    assert masses[0] == final["mass"].max() and cumulative[-1] == pytest.approx(final["particle_mass"].sum(), rel=1e-12)
    total = final["particle_mass"].sum()
    drawn = line_data(RUN_FIGURES["debris_sizes"](analysis))
    np.testing.assert_allclose(drawn[-1][0], masses / total, rtol=1e-12)
    np.testing.assert_allclose(drawn[-1][1], cumulative / total, rtol=1e-12)
    for name in ("largest_fragment_time", "debris_sizes"):
        assert (out / "eta1" / "figures" / f"{name}.png").stat().st_size > 1000


def test_a_set_of_runs_is_drawn_overlaid_in_time_and_as_intervals_of_its_realizations(sweep):
    """The cross-run largest_fragment_time draws each run's own frames; largest_fragment_intervals
    each point's mean with the 95 % Student's t interval of its realizations, computed here by hand."""
    from scipy import stats

    from decco_warp.analysis.figures import plot_histories, plot_intervals
    from decco_warp.analysis.runs import read_history

    out, _ = sweep
    summaries = json.loads((out / "summaries.json").read_text())
    histories = {s["run"]: read_history(out / s["run"]) for s in summaries}
    lines = line_data(plot_histories(summaries, histories))
    for s in summaries:
        time, ratio = histories[s["run"]]
        assert any(np.array_equal(x, time / 3600.0) and np.array_equal(y, ratio) for x, y in lines)
    for name in ("largest_fragment_time", "largest_fragment_intervals"):
        assert (out / "figures" / f"{name}.png").stat().st_size > 1000
    rows = [{"run": f"r{k}", "mass_ratio": 0.5, "theta_deg": 22.0, "eta": eta, "mu_k": mu, "largest_mass_ratio": value}
            for k, (eta, mu, value) in enumerate([(3.0, 0.0, 1.0), (3.0, 0.0, 1.2), (3.0, 0.0, 1.1), (6.0, 0.0, 0.5), (3.0, 0.3, 1.4)])]  # fmt: skip
    fig = plot_intervals(rows, "largest_mass_ratio", "m_lf / m_t", split=["mu_k"])
    bars = {c.get_label(): c for c in fig.axes[0].containers}
    zero = bars["22 deg, mu_k 0"]
    means = zero.lines[0].get_ydata()
    np.testing.assert_allclose(means, [1.1, 0.5])
    half = stats.t.ppf(0.975, 2) * np.std([1.0, 1.2, 1.1], ddof=1) / np.sqrt(3)
    segments = zero.lines[2][0].get_segments()
    np.testing.assert_allclose([segments[0][0][1], segments[0][1][1]], [1.1 - half, 1.1 + half], rtol=1e-12)
    assert np.isnan(segments[1]).all() or len(segments) == 1  # one run at eta 6: no interval
    np.testing.assert_allclose(bars["22 deg, mu_k 0.3"].lines[0].get_ydata(), [1.4])


def test_a_run_is_analysed_again_with_the_smallest_cluster_it_knows(sweep, tmp_path, monkeypatch):
    """Without --min-members, analyze takes what the run was analysed with (summary.json: 20 here),
    else what the sweep that made it used (its folder's sweep.json), else 50; so does resume
    --until-settled, whose judgement would otherwise count other clusters."""
    import shutil

    from decco_warp.folder import MIN_MEMBERS, RunFolder

    out, _ = sweep
    analysed = tmp_path / "analysed"
    shutil.copytree(out / "eta1", analysed)
    swept = tmp_path / "sweep" / "eta1"
    shutil.copytree(out / "eta1", swept, ignore=shutil.ignore_patterns("summary.json", "analysis.h5", "figures"))
    (swept.parent / "sweep.json").write_text(json.dumps({"sweep": "s", "settings": {"min_members": 7}}))
    bare = tmp_path / "bare"
    shutil.copytree(swept, bare)
    assert [RunFolder(p).min_members() for p in (analysed, swept, bare)] == [20, 7, MIN_MEMBERS]
    for run_dir, expected in ((analysed, 20), (swept, 7), (bare, MIN_MEMBERS)):
        result = cli("analyze", str(run_dir))
        assert result.returncode == 0, result.stderr
        assert json.loads((run_dir / "summary.json").read_text())["min_members"] == expected
    import decco_warp.run

    asked = []
    monkeypatch.setattr(decco_warp.run, "resume_until_settled", lambda run_dir, advance, max_steps, min_members, *rest, **kw: asked.append(min_members))
    for run_dir, expected in ((analysed, 20), (swept, 7)):
        assert cli_here("resume", str(run_dir), "--until-settled").returncode == 0
        assert cli_here("resume", str(run_dir), "--until-settled", "--min-members", "3").returncode == 0
    assert asked == [20, 3, 7, 3]


def test_analyze_refuses_a_folder_without_runs(tmp_path):
    result = cli("analyze", str(tmp_path))
    assert result.returncode == 2 and "no trajectory.h5" in result.stderr


def test_resume_until_settled_extends_a_run_only_while_its_outcome_changes(tmp_path):
    """A run whose outcome holds still over its last 10 % is left as it is; one that cannot settle
    (no cluster of a million grains) is extended by a quarter of its steps at a time, to --max-steps,
    then ends with exit 6 and the numbers; its trajectory holds every step it was given."""
    result = cli("simulate", "--name", "a", "--eta", "0.5", "--steps", "400", "--output-every", "20", "--out", str(tmp_path), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    import shutil

    shutil.copytree(tmp_path / "a", tmp_path / "b")
    result = cli("resume", str(tmp_path / "a"), "--until-settled", "--min-members", "20")
    assert result.returncode == 0, result.stderr
    assert "settled at step 400" in result.stdout and "extending" not in result.stdout
    # The run's totals apart from this session's costs: a finished run resumed steps nothing.
    assert "done: the run is at step 400 (16 s simulated); this session stepped 0 steps in" in result.stdout
    import re

    times = re.search(r"this session stepped 0 steps in ([\d.]+) s wall.*\(([\d.]+) s wall over all the run's sessions\)", result.stdout)
    session, total = float(times[1]), float(times[2])
    assert session < 0.5 * total  # this session stepped nothing: the run's first session's time is not this one's
    result = cli("resume", str(tmp_path / "b"), "--until-settled", "--min-members", "1000000", "--max-steps", "600")
    assert result.returncode == 6, result.stderr
    assert "extending to step 500" in result.stdout and "extending to step 600" in result.stdout
    assert "not settled at step 600" in result.stderr and "raise --max-steps" in result.stderr
    assert dw.read_trajectory(tmp_path / "b" / "trajectory.h5")["step"][-1] == 600
    for args, message in ((["--until-settled", "--steps", "500"], "not both"), (["--max-steps", "500"], "goes with --until-settled")):
        result = cli("resume", str(tmp_path / "a"), *args)
        assert result.returncode == 2 and message in result.stderr


def test_ellipsoid_axes_of_a_uniform_ellipsoid_of_grains():
    """Grains filling an ellipsoid of semi-axes 3, 2, 1 (x 1e7 cm) uniformly: the inertia-equivalent
    ellipsoid has those axes (to the sampling noise of 20 000 grains and their own radius)."""
    from decco_warp.analysis.runs import ellipsoid_axes

    rng = np.random.default_rng(2)
    points = rng.uniform(-1, 1, size=(60_000, 3))
    points = points[(points**2).sum(axis=1) <= 1][:20_000] * np.array([3e7, 2e7, 1e7])
    radii = np.full(len(points), 1e4)
    grains = dw.State.from_arrays(points, np.zeros_like(points), np.zeros_like(points), radii, np.full(len(points), 1e15))
    np.testing.assert_allclose(ellipsoid_axes(grains), [3e7, 2e7, 1e7], rtol=0.02)


def test_the_fragment_catalogue_lists_every_cluster_of_every_analysed_frame(sweep):
    from decco_warp.analysis.runs import read_catalogue

    out, _ = sweep
    analysis = read_analysis(out / "eta1" / "analysis.h5")
    table = read_catalogue(out / "eta1" / "analysis.h5")
    frames = analysis["frames"]
    counts = np.bincount(np.searchsorted(frames["step"], table["step"]), minlength=len(frames["step"]))
    np.testing.assert_array_equal(counts, frames["clusters"])
    last = table["step"] == frames["step"][-1]
    np.testing.assert_allclose(table["mass"][last], analysis["final"]["mass"], rtol=1e-12)
    np.testing.assert_array_equal(np.stack([table[f"class_{k}"][last] for k in range(3)], axis=1), analysis["final"]["composition"])
    assert np.all((0 < table["axis_ratio_c_a"]) & (table["axis_ratio_c_a"] <= table["axis_ratio_b_a"]) & (table["axis_ratio_b_a"] <= 1))
    # A pile's bulk density lies below its grains' 2.7 g/cm^3 (voids) and well above nothing.
    assert np.all((0.5 < table["bulk_density"]) & (table["bulk_density"] < 2.7))
    np.testing.assert_allclose(table["spin_rate"], np.linalg.norm(np.stack([table[f"omega_{a}"] for a in "xyz"], axis=1), axis=1))
    # Every grain is in a cluster or free, per size class.
    members = np.stack([table[f"class_{k}"] for k in range(3)], axis=1)
    per_frame = np.zeros((len(frames["step"]), 3), dtype=np.int64)
    np.add.at(per_frame, np.searchsorted(frames["step"], table["step"]), members)
    np.testing.assert_array_equal((per_frame + frames["free_composition"]).sum(axis=1), analysis["final"]["label"].size)


def test_every_dataset_of_a_run_carries_its_unit_and_data_md_lists_it(sweep):
    """trajectory.h5's particle and observable values and every analysis.h5 dataset have a "unit"
    attribute, and docs/data.md names each of them; read_trajectory's fields read as attributes."""
    import h5py

    out, _ = sweep
    data_md = (Path(__file__).parent.parent / "docs" / "data.md").read_text()
    with h5py.File(out / "eta1" / "trajectory.h5", "r") as f:
        for name, group in f["observables"].items():
            assert "unit" in group["value"].attrs, name
            assert f"`{name}`" in data_md, name
        for name in ("position", "velocity", "omega", "stress"):
            assert "unit" in f["particles/all"][name]["value"].attrs and f"`{name}`" in data_md
    with h5py.File(out / "eta1" / "analysis.h5", "r") as f:
        for group in f.values():
            for name, dataset in group.items():
                assert "unit" in dataset.attrs, f"{group.name}/{name}"
                assert f"`{group.name[1:]}/{name}`" in data_md or f"`{name}`" in data_md, f"{group.name}/{name}"
        for key in f.attrs:
            assert f"`{key}`" in data_md, f"summary column {key}"
    data = dw.read_trajectory(out / "eta1" / "trajectory.h5")
    assert data.time is data["time"] and data.particles["position"].shape[1:] == (data.static["radius"].size, 3)


def test_a_trajectory_read_with_some_frames_holds_those_frames_bit_for_bit(sweep):
    """read_trajectory(particle_frames=...): the particles of the frames asked (in that order, -1
    the last, a frame asked twice given twice), the rest of the trajectory as a whole read; a frame
    it does not hold is refused in one line."""
    from decco_warp.checks import InputError

    out, _ = sweep
    path = out / "eta1" / "trajectory.h5"
    whole = dw.read_trajectory(path)
    last = len(whole.step) - 1
    some = dw.read_trajectory(path, particle_frames=[last, 0, -1, 2])
    for name, frames in whole.particles.items():
        assert np.array_equal(some.particles[name], frames[[last, 0, last, 2]]), name
    assert np.array_equal(some.time, whole.time) and np.array_equal(some.step, whole.step)
    assert some.parameters.keys() == whole.parameters.keys()
    assert all(np.array_equal(some.observables[k], v) for k, v in whole.observables.items())
    none = dw.read_trajectory(path, particle_frames=[])
    assert none.particles["position"].shape == (0, *whole.particles["position"].shape[1:])
    with pytest.raises(InputError) as raised:
        dw.read_trajectory(path, particle_frames=[last + 1])
    assert "whole frame(s)" in str(raised.value) and "\n" not in str(raised.value)


def test_the_runs_of_a_set_share_their_time_axis(sweep, monkeypatch):
    """draw_run with the set's end time sets every time axis from 0 to it (the clusters' map has no
    time axis); analyze of a folder takes the latest end its runs' spec.toml plan."""
    from decco_warp.analysis import figures
    from decco_warp.watch import planned_end

    out, _ = sweep
    assert planned_end([out / "eta0.5", out / "eta1"]) == pytest.approx(400 * 0.04)
    limits = {}
    monkeypatch.setattr(figures, "save", lambda fig, folder, name: limits.setdefault(name, [ax.get_xlim() for ax in fig.axes]) and [])
    figures.draw_run(read_analysis(out / "eta1" / "analysis.h5"), out / "eta1", end_time=7200.0)
    for name, panels in (("conservation", 1), ("stress_shares", 3), ("energy", 1)):
        assert limits[name] == [(0.0, 2.0)] * panels, name
    assert limits["clusters"] != [(0.0, 2.0)]


def test_cross_run_figures_draw_a_series_per_value_of_a_swept_key():
    """The cross-run figure splits runs by the swept columns that vary (mu_k here; eta is the x axis,
    never a series; 0.30000000000000004 is mu_k 0.3): each series' line goes through its own
    realizations' means, where without the split the two frictions were pooled."""
    from decco_warp.analysis.figures import plot_runs, split_columns

    summaries = []
    for mu_k, shift in ((0.0, 0.0), (0.1 + 0.2, 0.4)):
        for eta, base in ((3.0, 1.2), (6.0, 0.8)):
            for k, noise in enumerate((-0.01, 0.03)):
                summaries.append({"run": f"mu{mu_k}_eta{eta}_r{k}", "mass_ratio": 0.25, "theta_deg": 0.0, "spin_kind": "none",
                                  "eta": eta, "mu_k": mu_k, "restitution": 0.9, "largest_mass_ratio": base + shift + noise})  # fmt: skip
    split = split_columns(summaries, ["eta", "mu_k", "restitution"])
    assert split == ["mu_k"]
    fig = plot_runs(summaries, "largest_mass_ratio", "m_lf / m_t", split=split)
    labels = fig.axes[0].get_legend_handles_labels()[1]
    assert labels == ["0 deg, mu_k 0", "0 deg, mu_k 0.3"]
    means = [line for line in line_data(fig) if line[0].size == 2 and line[1].size == 2]
    np.testing.assert_allclose(means[0][1], [1.21, 0.81])
    assert any(np.allclose(y, [1.61, 1.21]) for _, y in means)
    pooled = plot_runs(summaries, "largest_mass_ratio", "m_lf / m_t")
    assert pooled.axes[0].get_legend_handles_labels()[1] == ["0 deg"]
    np.testing.assert_allclose(line_data(pooled)[0][1], [1.41, 1.01])



def test_frames_analysed_in_processes_give_the_results_of_one_process(tmp_path):
    """analyze --workers 2 (the frames in two spawned processes, each reading its share of the
    trajectory itself, merged in frame order) writes the analysis.h5 and summary.json of
    --workers 1 (frame by frame in the command's process), dataset for dataset: each frame's
    cluster of every particle, the catalogue, the last frame's members; the same lines printed."""
    result = cli("simulate", "--name", "a", "--eta", "0.5", "--steps", "400", "--output-every", "20", "--out", str(tmp_path), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    run, outputs = tmp_path / "a", []
    for workers in ("1", "2"):
        result = cli("analyze", str(run), "--min-members", "20", "--workers", workers)
        assert result.returncode == 0, result.stderr
        summary = json.loads((run / "summary.json").read_text())
        outputs.append((read_analysis(run / "analysis.h5"), summary, result.stdout.splitlines()[-1]))
    (serial, serial_summary, serial_line), (parallel, parallel_summary, parallel_line) = outputs
    assert serial.keys() == parallel.keys()
    for group in serial:
        if group == "summary":
            continue
        assert serial[group].keys() == parallel[group].keys(), group
        for name, value in serial[group].items():
            assert value.dtype == parallel[group][name].dtype and value.shape == parallel[group][name].shape, (group, name)
            assert np.array_equal(value, parallel[group][name], equal_nan=value.dtype.kind == "f"), (group, name)
    assert (serial["frames"]["label"] >= 0).any() and serial["frames"]["label"].shape[0] == 21  # clusters in every frame's labels
    for summary in (serial_summary, parallel_summary, serial["summary"], parallel["summary"]):
        summary.pop("analysis_seconds")
    assert serial_summary == parallel_summary and serial["summary"] == parallel["summary"]
    assert serial_line == parallel_line


def test_how_many_processes_analyse_a_runs_frames(monkeypatch):
    """One a core this process may use ($DECCO_CORES where set), at most 16 on a GPU and one a frame;
    one (here) for a small run, a process that may not start processes, or a single core; what is
    asked where asked."""
    from decco_warp.analysis import runs
    from decco_warp.errors import InputError

    monkeypatch.setenv("DECCO_CORES", "6")
    assert runs.frame_workers(1001, 6250) == 6 and runs.frame_workers(1001, 6250, device="cuda:0") == 6
    assert runs.frame_workers(4, 100_000) == 4  # one a frame at most
    assert runs.frame_workers(21, 450) == 1  # 9 450 particle-frames: a process's start costs more
    assert runs.frame_workers(21, 450, workers=2) == 2 and runs.frame_workers(3, 450, workers=8) == 3
    monkeypatch.setenv("DECCO_CORES", "64")
    assert runs.frame_workers(1001, 6250) == 64 and runs.frame_workers(1001, 6250, device="cuda") == runs.MAX_GPU_WORKERS
    monkeypatch.setenv("DECCO_CORES", "1")
    assert runs.frame_workers(1001, 6250) == 1
    monkeypatch.setenv("DECCO_CORES", "64")
    monkeypatch.setattr(runs, "can_start_processes", lambda: False)  # a daemonic process (a multiprocessing.Pool's worker)
    assert runs.frame_workers(1001, 6250) == 1
    monkeypatch.setenv("DECCO_CORES", "many")
    with pytest.raises(InputError, match="DECCO_CORES"):
        runs.usable_cores()


def test_a_sweeps_analysis_processes_each_have_their_share_of_the_cores(monkeypatch):
    """The analysis processes of a sweep (16 cores, 4 processes) are each told 4 cores: a run's frames
    are analysed in up to 4 processes of its own, never 16 x 16; its frame workers 4 / 4 = 1 core each."""
    import functools
    import os

    from decco_warp import processes, sweep

    pools = []

    class Pool:
        def __init__(self, max_workers, mp_context, initializer):
            self.size, self.initializer = max_workers, initializer
            pools.append(self)

        def submit(self, function, *args):
            return args

    monkeypatch.setenv("DECCO_CORES", "16")
    monkeypatch.setattr(sweep, "ProcessPoolExecutor", Pool)
    sweep.Analyses(4, {}).submit({"run_dir": "r0", "n_particles": 6250}, {"min_members": 50, "analyze_every": 1, "keep_trajectory": True})
    (pool,) = pools
    assert pool.size == 4 and isinstance(pool.initializer, functools.partial) and pool.initializer.args == (4,)
    monkeypatch.setattr("decco_warp.stops.ignore_stops", lambda: None)
    pool.initializer()  # as the process starts
    assert os.environ["DECCO_CORES"] == "4" and processes.usable_cores() == 4
    before = os.environ.get("OPENBLAS_NUM_THREADS")
    with processes.helpers_environment(processes.usable_cores() // 4):  # what its frame workers start with
        assert os.environ["DECCO_CORES"] == "1" and os.environ["OPENBLAS_NUM_THREADS"] == "1"
    assert os.environ["DECCO_CORES"] == "4" and os.environ.get("OPENBLAS_NUM_THREADS") == before  # restored

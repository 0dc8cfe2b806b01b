"""Run analysis: paper metrics on constructed examples, analysis.h5, figures and cross-run output."""

import json

import numpy as np
import pytest
from helpers import cli

import decco_warp as dw
from decco_warp.analysis.figures import RUN_FIGURES, line_data
from decco_warp.analysis.runs import analyse_snapshot, particle_size_change, read_analysis
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


def test_particle_size_change_by_hand():
    # Parents: 10 particles of 2 g and 30 of 1 g -> mean 1.25 g; a fragment of 4 x 2 g + 2 x 1 g -> 10/6 g.
    assert particle_size_change(10.0, 6, 50.0, 40) == pytest.approx(100 * ((10 / 6) / 1.25 - 1))
    assert particle_size_change(5.0, 4, 50.0, 40) == pytest.approx(0.0)


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
    lines = line_data(RUN_FIGURES["conservation"](analysis))
    np.testing.assert_array_equal(lines[0][1], analysis["conservation"]["momentum_drift"])
    np.testing.assert_array_equal(lines[1][1], analysis["conservation"]["angular_momentum_drift"])
    lines = line_data(RUN_FIGURES["stress_shares"](analysis))
    np.testing.assert_array_equal(lines[0][1], analysis["stress_share"]["value"][:, 0])
    energy = analysis["energy"]
    lines = line_data(RUN_FIGURES["energy"](analysis))
    np.testing.assert_array_equal(lines[0][1], energy["kinetic_translational"] + energy["kinetic_rotational"])
    np.testing.assert_allclose(lines[-1][1], energy["total_energy"][0], rtol=1e-10)  # the books balance
    assert analysis["conservation"]["momentum_drift"].max() < 1e-6


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


def test_analyze_refuses_a_folder_without_runs(tmp_path):
    result = cli("analyze", str(tmp_path))
    assert result.returncode == 2 and "no trajectory.h5" in result.stderr

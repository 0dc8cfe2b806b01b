"""Realizations: a collision repeated with its piles turned by random rotations (docs/model.md)."""

import csv

import numpy as np
import pytest
from helpers import cli
from scipy import stats

import decco_warp as dw
from decco_warp import spec as specs
from decco_warp.analysis.figures import line_data, plot_runs, realization_points
from decco_warp.analysis.runs import spin_kind
from decco_warp.collision import random_rotations, rotate_pile
from decco_warp.io import read_trajectory
from decco_warp.run import builtin_pile
from decco_warp.sweep import load_sweep, orientation_seed_of

#: A turned pile keeps its shape and centre to this relative precision (float64 round-off).
RIGID_TOLERANCE = 1e-12


@pytest.fixture(scope="module")
def piles():
    return dw.load_pile(builtin_pile("target")), dw.load_pile(builtin_pile("projectile"))


def _distances(positions):
    return np.linalg.norm(positions[:, None, :] - positions[None, :, :], axis=-1)


def test_a_seed_gives_the_same_proper_rotations_and_other_seeds_others():
    first, again, other = random_rotations(7), random_rotations(7), random_rotations(8)
    assert np.array_equal(first, again)
    assert not np.allclose(first, other)
    assert not np.allclose(first[0], first[1])  # target and projectile turned independently
    for rotation in np.concatenate([first, other]):
        assert np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(rotation) == pytest.approx(1.0, abs=1e-14)
    with pytest.raises(ValueError, match="orientation_seed"):
        random_rotations(-1)


def test_rotations_are_uniform_over_all_rotations():
    """Haar measure on SO(3): the rotation angle a has density (1 - cos a) / pi on [0, pi], and
    a rotation's mean is the zero matrix (every direction is sent everywhere alike)."""
    rotations = np.concatenate([random_rotations(seed, 2) for seed in range(1500)])
    angles = np.arccos(np.clip((np.trace(rotations, axis1=1, axis2=2) - 1) / 2, -1, 1))
    haar_cdf = lambda a: (a - np.sin(a)) / np.pi  # noqa: E731
    assert stats.kstest(angles, haar_cdf).pvalue > 1e-3
    # Each entry of a Haar rotation has mean 0 and variance 1/3: 3000 draws give a standard error of ~0.011.
    assert np.abs(rotations.mean(axis=0)).max() < 0.05


def test_a_turned_pile_keeps_its_distances_centre_and_bulk_motion(piles):
    target = piles[0].copy()
    target.velocities += np.array([3.0, -2.0, 1.0])  # a bulk motion, and a spin about the centre
    target.velocities += np.cross([0.0, 0.0, 1e-5], target.positions - target.centre_of_mass)
    rotation = random_rotations(3)[0]
    turned = rotate_pile(target, rotation)
    scale = np.abs(target.positions - target.centre_of_mass).max()
    assert np.allclose(turned.centre_of_mass, target.centre_of_mass, rtol=0, atol=RIGID_TOLERANCE * scale)
    assert np.allclose(_distances(turned.positions), _distances(target.positions), rtol=0, atol=RIGID_TOLERANCE * scale)
    assert np.allclose(turned.bulk_velocity, target.bulk_velocity, rtol=RIGID_TOLERANCE, atol=0)
    # Rigid: every relative position and velocity is the original one turned.
    relative = turned.positions - turned.centre_of_mass
    assert np.allclose(relative, (target.positions - target.centre_of_mass) @ rotation.T, rtol=0, atol=RIGID_TOLERANCE * scale)
    assert np.array_equal(turned.radii, target.radii) and np.array_equal(turned.masses, target.masses)


def test_a_seeded_set_up_turns_each_pile_about_its_centre_and_keeps_the_collision(piles):
    plain = dw.setup_collision(*piles, eta=2.0, theta_deg=22.0, device="cpu")
    turned = dw.setup_collision(*piles, eta=2.0, theta_deg=22.0, device="cpu", orientation_seed=11)
    assert turned.metadata["orientation_seed"] == 11
    rotations = random_rotations(11)
    for k in (0, 1):
        a, b = plain.subset(plain.pile_id == k), turned.subset(turned.pile_id == k)
        scale = np.abs(a.positions - a.centre_of_mass).max()
        assert np.allclose(b.centre_of_mass, a.centre_of_mass, rtol=0, atol=RIGID_TOLERANCE * scale)
        assert np.allclose(_distances(b.positions), _distances(a.positions), rtol=0, atol=RIGID_TOLERANCE * scale)
        assert np.allclose(b.positions - b.centre_of_mass, (a.positions - a.centre_of_mass) @ rotations[k].T, atol=RIGID_TOLERANCE * scale)
        assert np.array_equal(turned.metadata[("target_rotation", "projectile_rotation")[k]], rotations[k])
    for key in ("eta", "speed", "impact_parameter", "target_radius", "projectile_radius", "kinetic_energy", "target_potential"):
        assert turned.metadata[key] == pytest.approx(plain.metadata[key], rel=1e-9), key
    assert "orientation_seed" not in plain.metadata  # no seed: the piles as their files hold them


def test_spins_are_given_about_fixed_axes_after_the_turn(piles):
    turned = dw.setup_collision(*piles, eta=2.0, device="cpu", target_spin=(0.5, "+z"), orientation_seed=4)
    target = turned.subset(turned.pile_id == 0)
    assert np.allclose(target.omegas / np.linalg.norm(target.omegas, axis=1, keepdims=True), [0.0, 0.0, 1.0])


def test_two_seeds_give_different_outcomes_and_a_seed_the_same(tmp_path):
    """Two short collisions of the shipped piles, touching from the start: the same seed repeats the
    run bit for bit; another seed changes what happens (the energy lost to sliding friction), which no
    orientation-independent quantity of the set-up would."""
    outcomes = {}
    for name, seed in (("a", 1), ("b", 2), ("c", 1)):
        result = cli("simulate", "--name", name, "--out", str(tmp_path), "--steps", "400", "--output-every", "200",
                     "--gap", "0", "--eta", "2", "--theta", "0", "--orientation-seed", str(seed), "--device", "cpu")  # fmt: skip
        assert result.returncode == 0, result.stderr
        run = read_trajectory(tmp_path / name / "trajectory.h5")
        assert run["parameters"]["spec"]["collision"]["orientation_seed"] == seed
        assert np.array_equal(run["parameters"]["collision"]["target_rotation"], random_rotations(seed)[0])
        assert "orientation_seed = " in (tmp_path / name / "spec.toml").read_text()
        outcomes[name] = run
    observables = {name: outcomes[name]["observables"] for name in outcomes}
    assert np.array_equal(outcomes["a"]["particles"]["position"], outcomes["c"]["particles"]["position"])
    # The set-up's energies agree (they do not depend on the orientation) ...
    assert observables["a"]["kinetic_translational"][0] == pytest.approx(observables["b"]["kinetic_translational"][0], rel=1e-9)
    # ... and what the contacts did does not: the piles touch at other grains.
    lost = {name: observables[name]["dissipated_sliding"][-1] for name in ("a", "b")}
    assert lost["a"] > 0 and lost["b"] > 0
    assert abs(lost["a"] - lost["b"]) > 1e-3 * max(lost.values())


SWEEP = """
[sweep]
name = "grid"
out = "{out}"
realizations = {k}
[sweep.grid]
"collision.eta" = {etas}
[run]
steps = 100
output_every = 50
device = "cpu"
"""


def test_realizations_expand_each_point_with_seeds_that_adding_never_changes(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path, k=3, etas="[0.5, 1.0]"))
    _, runs = load_sweep(path)
    names = [r["run"]["name"] for r in runs]
    assert names == ["eta0.5", "eta0.5_r1", "eta0.5_r2", "eta1", "eta1_r1", "eta1_r2"]
    seeds = {r["run"]["name"]: r["collision"].get("orientation_seed") for r in runs}
    assert seeds["eta0.5"] is None and seeds["eta1"] is None  # realization 0: the runs made without realizations
    assert len({seeds[n] for n in names if "_r" in n}) == 4
    # More points and more realizations leave every run already listed as it was.
    path.write_text(SWEEP.format(out=tmp_path, k=4, etas="[0.25, 0.5, 1.0]"))
    _, more = load_sweep(path)
    wider = {r["run"]["name"]: r for r in more}
    assert all(wider[r["run"]["name"]] == r for r in runs)
    # The seed follows the point's piles and collision, not its [params]: a friction change meets the same orientations.
    point = specs.resolve_spec({"collision": {"eta": 1.0}})
    other_params = specs.resolve_spec({"collision": {"eta": 1.0}, "params": {"mu_k": 0.1}})
    assert orientation_seed_of(point, 1) == orientation_seed_of(other_params, 1) != orientation_seed_of(point, 2)
    path.write_text(SWEEP.format(out=tmp_path, k=2, etas="[0.5]") + "[collision]\norientation_seed = 3\n")
    with pytest.raises(specs.SpecError, match="realizations"):
        load_sweep(path)
    path.write_text(SWEEP.format(out=tmp_path, k=0, etas="[0.5]"))
    with pytest.raises(specs.SpecError, match="realizations"):
        load_sweep(path)


def test_realizations_draw_their_piles_from_the_alternatives_with_their_seed(tmp_path):
    """[sweep.pile_alternatives]: realization 0 keeps the files as written; each later one draws
    its target and projectile from the file and its stand-ins with its own seed (every stand-in
    drawn over enough realizations, the draw repeatable and independent of other points)."""
    import shutil

    from decco_warp.run import builtin_pile

    piles = {}
    for which in ("target", "projectile"):
        piles[which] = [str(tmp_path / f"{which}{k}.h5") for k in range(3)]
        for path in piles[which]:
            shutil.copy(builtin_pile(which), path)
    table = "".join(f'"{files[0]}" = {files[1:]!r}\n'.replace("'", '"') for files in piles.values())
    text = SWEEP.format(out=tmp_path, k=40, etas="[0.5, 1.0]") + "[sweep.pile_alternatives]\n" + table
    text += f'[piles]\ntarget = "{piles["target"][0]}"\nprojectile = "{piles["projectile"][0]}"\n'
    path = tmp_path / "s.toml"
    path.write_text(text)
    _, runs = load_sweep(path)
    first = {r["run"]["name"]: (r["piles"]["target"], r["piles"]["projectile"]) for r in runs}
    assert first["eta0.5"] == (piles["target"][0], piles["projectile"][0])
    drawn = [first[f"eta0.5_r{k}"] for k in range(1, 40)]  # all three of each drawn (a miss: 3 x (2/3)^39 ~ 5e-7)
    assert {t for t, _ in drawn} == set(piles["target"]) and {p for _, p in drawn} == set(piles["projectile"])
    assert load_sweep(path)[1] == runs  # the same draw every time
    for written, instead in (("realizations = 40", "realizations = 1"), (f'"{piles["target"][2]}"]', f'"{tmp_path}/nowhere.h5"]')):
        path.write_text(text.replace(written, instead))
        with pytest.raises(specs.SpecError, match="pile_alternatives"):
            load_sweep(path)


def test_a_sweep_of_realizations_adds_runs_to_those_made_and_records_them(tmp_path):
    """A sweep without realizations, its run kept without a checkpoint (as runs/results keeps them);
    the same sweep with two realizations skips that run and adds the second, both in its table."""
    pytest.importorskip("distributed")
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path, k=1, etas="[0.5]"))
    assert cli("sweep", str(path), "--workers", "1").returncode == 0
    (tmp_path / "grid" / "eta0.5" / "checkpoint.h5").unlink()
    made = (tmp_path / "grid" / "eta0.5" / "summary.json").read_text()
    path.write_text(SWEEP.format(out=tmp_path, k=2, etas="[0.5]"))
    result = cli("sweep", str(path), "--workers", "1")
    assert result.returncode == 0, result.stderr
    with open(tmp_path / "grid" / "summary.csv") as f:
        rows = {row["run"]: row for row in csv.DictReader(f)}
    assert {name: (row["realization"], row["status"]) for name, row in rows.items()} == {
        "eta0.5": ("0", "skipped (complete)"), "eta0.5_r1": ("1", "ok")
    }  # fmt: skip
    assert (tmp_path / "grid" / "eta0.5" / "summary.json").read_text() == made
    _, runs = load_sweep(path)
    assert rows["eta0.5_r1"]["orientation_seed"] == str(runs[1]["collision"]["orientation_seed"])
    assert rows["eta0.5"]["orientation_seed"] == "" and rows["eta0.5"]["spin_kind"] == "none"


def test_keys_that_go_together_are_one_grid_entry(tmp_path):
    path = tmp_path / "s.toml"
    pairs = '[["+z", "+z"], ["+z", "-z"], ["+x", "+z"]]'
    entry = f'"collision.target_spin_axis, collision.projectile_spin_axis" = {pairs}\n'
    spinning = "[collision]\ntarget_spin = 0.5\nprojectile_spin = 0.5\n"  # the axes of bodies that spin: distinct set-ups
    path.write_text(SWEEP.format(out=tmp_path, k=1, etas="[1.0, 2.0]").replace("[run]", entry + spinning + "[run]"))
    _, runs = load_sweep(path)
    axes = [(r["collision"]["target_spin_axis"], r["collision"]["projectile_spin_axis"], r["collision"]["eta"]) for r in runs]
    assert axes == [(t, p, eta) for eta in (1.0, 2.0) for t, p in (("+z", "+z"), ("+z", "-z"), ("+x", "+z"))]
    assert runs[1]["run"]["name"] == "eta1_target_spin_axispz_projectile_spin_axismz"
    path.write_text(SWEEP.format(out=tmp_path, k=1, etas="[1.0]").replace("[run]", entry.replace('["+x", "+z"]', '["+x"]') + "[run]"))
    with pytest.raises(specs.SpecError, match="list of 2"):
        load_sweep(path)


def _summary(eta, value, theta=0.0, ratio=0.25, spins="none"):
    return {"eta": eta, "largest_mass_ratio": value, "theta_deg": theta, "mass_ratio": ratio, "spin_kind": spins,
            "ls12_largest_mass_ratio": None, "particle_size_change": 0.0}  # fmt: skip


def test_cross_run_figures_draw_each_points_mean_and_its_spread():
    summaries = [_summary(1.0, 0.9), _summary(1.0, 0.8), _summary(1.0, 0.4), _summary(2.0, 0.5), _summary(2.0, 0.7)]
    summaries += [_summary(1.0, 0.1, spins="parallel")]  # another kind of spin: a line of its own, not a realization
    points = realization_points([s for s in summaries if s["spin_kind"] == "none"], "largest_mass_ratio")
    assert [(p["eta"], p["mean"], p["low"], p["high"]) for p in points] == [(1.0, pytest.approx(0.7), 0.4, 0.9), (2.0, pytest.approx(0.6), 0.5, 0.7)]
    lines = line_data(plot_runs(summaries, "largest_mass_ratio", "m_lf / m_t"))
    pairs = [[round(float(v), 12) for v in y] for x, y in lines if list(x) == [1.0, 2.0]]
    # The mean (line, markers and bar centres) and the bar's ends at the smallest and the largest realization.
    assert sorted(pairs) == [[0.4, 0.5], [0.7, 0.6], [0.7, 0.6], [0.7, 0.6], [0.9, 0.7]]
    faint = [sorted(zip(x, y)) for x, y in lines if len(x) == 5]
    assert faint == [sorted((s["eta"], s["largest_mass_ratio"]) for s in summaries[:5])]
    assert ([1.0], [0.1]) in [(list(x), list(y)) for x, y in lines]
    # A point with an unsettled run is drawn hollow (its value is not final), never left out.
    summaries[3]["settled"] = False
    fig = plot_runs(summaries, "largest_mass_ratio", "m_lf / m_t")
    hollow = [(list(line.get_xdata()), list(line.get_ydata())) for line in fig.axes[0].lines if line.get_markerfacecolor() == "white"]
    assert hollow == [([2.0], [pytest.approx(0.6)])]


@pytest.mark.parametrize(
    "target, projectile, kind",
    [
        (None, None, "none"), ((0, 0, 1), None, "target only"), ((0, 0, 1), (0, 0, 2), "parallel"),
        ((1, 0, 0), (-1, 0, 0), "anti-parallel"), ((0, 0, 1), (1, 0, 0), "perpendicular"), ((0, 0, 1), (1, 0, 1), "oblique"),
    ],
)  # fmt: skip
def test_spin_kinds_as_the_paper_consolidates_them(target, projectile, kind):
    assert spin_kind(target, projectile) == kind

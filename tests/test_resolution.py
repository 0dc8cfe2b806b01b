"""Runs at another resolution (decco_warp/resolution.py): piles of R x the particles with radii x
R^(-1/3), and collisions with k_in and dt x R^(-1/3) (the same predicted compression)."""

import math
import shutil

import pytest

from decco_warp import spec as specs
from decco_warp.pile import size_class_counts
from decco_warp.resolution import length_factor, pile_entry, pile_file
from decco_warp.run import builtin_pile
from decco_warp.sweep import load_sweep

SWEEP = """
[sweep]
name = "ladder"
out = "{out}"
resolution = {resolution}
{extra}
[sweep.grid]
"collision.eta" = [3.0, 6.0]
[piles]
target = "{target}"
projectile = "{projectile}"
[run]
duration = 4000.0
output_every = 1000
checkpoint_every = 10000
"""


def test_a_pile_recipe_at_another_resolution_keeps_its_mass_and_size():
    """R x the particles, radii x R^(-1/3): equal mass per size class as before, so each class's mass
    (count x r^3) and the body's mass stay to the rounding of the counts."""
    entry = {"out": "piles/target5000.h5", "particles": 5000, "seed": 1}
    scaled = pile_entry(entry, 8, "0.75e6,1.5e6,2.25e6")
    assert scaled["out"] == "piles/target5000_x8.h5" and scaled["particles"] == 40_000 and scaled["seed"] == 1
    assert scaled["radii"] == pytest.approx([0.375e6, 0.75e6, 1.125e6], rel=1e-12)
    before = size_class_counts(5000, [0.75e6, 1.5e6, 2.25e6]) * [0.75e6**3, 1.5e6**3, 2.25e6**3]
    after = size_class_counts(40_000, scaled["radii"]) * [r**3 for r in scaled["radii"]]
    assert after.sum() == pytest.approx(before.sum(), rel=2e-3)
    assert pile_file("a/b.h5", 1) == "a/b.h5"
    for bad in (0, -2, float("nan"), True):
        with pytest.raises(ValueError, match="resolution must be a number > 0"):
            length_factor(bad)
    with pytest.raises(ValueError, match="shipped pile"):
        pile_file("builtin:target", 4)


def _piles(tmp_path, resolution):
    files = {}
    for which in ("target", "projectile"):
        base = tmp_path / f"{which}.h5"
        shutil.copy(builtin_pile(which), base)
        shutil.copy(builtin_pile(which), pile_file(str(base), resolution))  # stands in for the built one
        files[which] = str(base)
    return files


def test_a_sweep_at_another_resolution_scales_piles_spring_and_step(tmp_path):
    files = _piles(tmp_path, 4)
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path, resolution=4, extra="", **files))
    _, runs = load_sweep(path)
    f = 4 ** (-1 / 3)
    run = runs[0]
    assert [r["run"]["name"] for r in runs] == ["eta3_x4", "eta6_x4"]
    assert run["piles"]["target"] == pile_file(files["target"], 4) and run["run"]["resolution"] == 4.0
    assert run["params"]["k_in"] == pytest.approx(1e18 * f, rel=1e-12) and run["params"]["dt"] == pytest.approx(0.04 * f, rel=1e-12)
    assert run["run"]["steps"] == math.ceil(4000.0 / (0.04 * f) - 1e-9)  # the same 4 000 s in more, shorter steps
    assert run["run"]["output_every"] == math.ceil(1000 / f)
    # The same contact physics: the spring scales with the radius (docs/model.md), so k_in / R_min stays.
    assert run["params"]["k_in"] / (0.75e6 * f) == pytest.approx(1e18 / 0.75e6, rel=1e-12)
    # Held at the paper's values: the second series of the ladder.
    path.write_text(SWEEP.format(out=tmp_path, resolution=4, extra="scale_contacts = false", **files))
    held = load_sweep(path)[1][0]
    assert held["params"]["k_in"] == 1e18 and held["params"]["dt"] == 0.04 and held["run"]["steps"] == 100_000
    assert specs.resolve_spec(held) == held  # what spec.toml records repeats the run


def test_auto_gravity_every_at_another_resolution_keeps_its_interval_in_whole_outer_steps(tmp_path):
    """gravity_every = "auto" at R = 4 with the contacts scaled: dt 0.0252 s, so K = 40 (gravity every
    1.0 s, as 25 steps of 0.04 s at R = 1), and scaled_run rounds the step counts to whole outer
    steps of 40; kept at the paper's dt (scale_contacts = false) it stays 25; with an "auto" dt the
    rounding waits for that dt (spec.settle_auto)."""
    from decco_warp.resolution import scaled_run

    defaults = specs.resolve_spec({})
    files = _piles(tmp_path, 4)
    given = {"piles": files, "params": {"gravity_every": "auto"}, "run": {"steps": 100_000, "output_every": 5000, "checkpoint_every": 50_000}}
    run = specs.resolve_spec(scaled_run(given, 4, True, defaults))
    f = length_factor(4)
    assert run["params"]["gravity_every"] == 40 and run["params"]["dt"] == pytest.approx(0.04 * f, rel=1e-12)
    for key, value in given["run"].items():
        assert run["run"][key] % 40 == 0 and run["run"][key] == 40 * math.ceil(value / f / 40), key
    assert (run["run"]["steps"], run["run"]["output_every"]) == (158_760, 7960)
    held = specs.resolve_spec(scaled_run(given, 4, False, defaults))
    assert held["params"]["gravity_every"] == 25 and held["run"]["steps"] == 100_000
    # A duration becomes whole outer steps of 40 by itself: 40 000 s, as throughput_r4_k40's runs.
    timed = specs.resolve_spec(scaled_run({**given, "run": {"duration": 40_000.0, "output_every": 5000}}, 4, True, defaults))
    assert (timed["params"]["gravity_every"], timed["run"]["steps"]) == (40, 1_587_440) and timed["run"]["steps"] % 40 == 0
    # R = 16: 63 steps of 0.0159 s.
    assert specs.resolve_spec(scaled_run(given, 16, True, defaults))["params"]["gravity_every"] == 63  # piles not read here
    # An "auto" dt: no K to round to yet; the spec keeps both "auto".
    auto = scaled_run({**given, "params": {"gravity_every": "auto", "dt": "auto", "k_in": "auto"}}, 4, True, defaults)
    assert auto["run"]["steps"] == math.ceil(100_000 / f) and specs.resolve_spec(auto)["params"]["gravity_every"] == "auto"
    # A sweep file at R = 4 through load_sweep: the same.
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path, resolution=4, extra="", **files) + '[params]\ngravity_every = "auto"\n')
    for swept in load_sweep(path)[1]:
        assert swept["params"]["gravity_every"] == 40 and all(swept["run"][key] % 40 == 0 for key in ("steps", "output_every", "checkpoint_every"))


def test_a_resolution_whose_piles_are_not_built_is_refused(tmp_path):
    files = _piles(tmp_path, 4)
    path = tmp_path / "s.toml"
    for resolution, message in ((8, "does not exist; build the piles at that resolution first"), (-1, "resolution must be a number > 0")):
        path.write_text(SWEEP.format(out=tmp_path, resolution=resolution, extra="", **files))
        with pytest.raises(specs.SpecError, match=message):
            load_sweep(path)


def test_piles_at_another_resolution_are_the_recipes_scaled(tmp_path):
    """decco-warp piles --resolution R builds NAME_xR.h5 for each [[pile]] (one already there is skipped)."""
    from helpers import cli

    (tmp_path / "piles.toml").write_text(f'[[pile]]\nout = "{tmp_path / "p.h5"}"\nparticles = 30\n')
    shutil.copy(builtin_pile("projectile"), tmp_path / "p_x2.h5")
    result = cli("piles", str(tmp_path / "piles.toml"), "--resolution", "2", "--device", "cpu")
    assert result.returncode == 0, result.stderr
    assert f"{tmp_path / 'p_x2.h5'}: exists, skipped" in result.stdout and not (tmp_path / "p.h5").exists()
    result = cli("piles", str(tmp_path / "piles.toml"), "--resolution", "0")
    assert result.returncode == 2 and "resolution must be a number > 0" in result.stderr

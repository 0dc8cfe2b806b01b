"""decco-warp bench: a smoke test on the CPU at tiny N (speed is measured by the benchmark, never by tests)."""

import json
import subprocess
import sys

import numpy as np
import pytest
from helpers import cli

import decco_warp as dw
from decco_warp.bench import lattice_pile, pile_mosaic
from decco_warp.run import builtin_pile


def test_lattice_pile_touches_its_neighbours_lightly():
    state = lattice_pile(64)
    d = dw.diagnostics(state, dw.Params())
    # 4 x 4 x 4 lattice: 3 * 4 * 4 * 3 = 144 neighbour contacts, overlaps of 300 +- 200 cm.
    assert d["number_of_contacts"] == 144
    assert 0 < d["max_overlap"] < 700


def _subset(state, count):
    return dw.State.from_arrays(*(values[:count] for values in (state.positions, state.velocities, state.omegas, state.radii, state.masses)))


def test_pile_mosaic_repeats_the_shipped_pile_turned_and_apart():
    """Two whole copies and a cut one: each copy keeps the pile's contacts (it is only turned and
    moved) and no copy touches another, so the mosaic has exactly their contacts."""
    pile = dw.load_pile(builtin_pile("target"))
    n = 2 * pile.n + 50
    state = pile_mosaic(n, seed=1)
    assert state.n == n
    np.testing.assert_array_equal(state.radii, np.concatenate([pile.radii, pile.radii, pile.radii[:50]]))
    contacts = dw.diagnostics(pile, dw.Params())["number_of_contacts"]
    cut = dw.diagnostics(_subset(pile, 50), dw.Params())["number_of_contacts"]
    assert contacts > pile.n  # a settled pile: ~2.5 contacts per particle
    assert dw.diagnostics(state, dw.Params())["number_of_contacts"] == 2 * contacts + cut
    second = state.positions[pile.n : 2 * pile.n]
    turned = np.linalg.norm(second[:, None] - second[None, :], axis=-1)
    original = np.linalg.norm(pile.positions[:, None] - pile.positions[None, :], axis=-1)
    np.testing.assert_allclose(turned, original, rtol=0, atol=1e-9 * original.max())
    assert not np.allclose(second - second.mean(axis=0), pile.positions - pile.positions.mean(axis=0))


def test_bench_cli_writes_a_table_with_its_baseline(tmp_path):
    out = tmp_path / "bench.json"
    result = subprocess.run(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "bench", "--device", "cpu", "--n", "64,100",
         "--seconds", "0.05", "--steps", "5", "--layouts", "1:2:8,1:4:4:0:newton", "--ensemble", "3", "--json", str(out)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert "baseline pairs/s" in result.stdout
    table = json.loads(out.read_text())
    assert table["device"] == "cpu" and table["limit_pairs_per_s"] is None
    rows = table["rows"]
    assert [r["n"] for r in rows] == [64] * 4 + [100] * 4
    assert [r["systems"] for r in rows] == [1, 1, 1, 3] * 2
    for row in rows:
        assert row["force_pairs_per_s"] > 0 and row["step_pairs_per_s"] > 0
        # An ensemble's pairs/s counts the pairs of all its systems.
        assert np.isclose(row["force_pairs_per_s"], row["systems"] * row["n"] ** 2 / row["force_seconds"])
    assert np.isclose(rows[0]["speedup"], rows[0]["baseline_seconds"] / rows[0]["force_seconds"])
    assert "2 per block" in rows[1]["layout"] and "each pair once" in rows[2]["layout"]
    ratio = float(rows[3]["layout"].split(": ")[-1].split("x")[0])
    assert "3 systems together" in rows[3]["layout"] and ratio == round(rows[3]["step_pairs_per_s"] / rows[0]["step_pairs_per_s"], 2)


def test_bench_gives_the_tree_in_its_own_terms(tmp_path):
    """A tree row: its step time, particles/s and its ratio to the all-pairs step of the same call;
    no pairs/s (it does not compute the pairs) and no fraction of the all-pairs limit."""
    out = tmp_path / "bench.json"
    result = cli("bench", "--device", "cpu", "--n", "300", "--seconds", "0.05", "--steps", "2", "--gravity", "all-pairs,tree", "--json", str(out))
    assert result.returncode == 0, result.stderr
    pairs, tree = json.loads(out.read_text())["rows"]
    assert pairs["gravity"] == "all-pairs" and tree["gravity"] == "tree"
    assert tree["step_pairs_per_s"] is None and tree["force_pairs_per_s"] is None and tree["fraction_of_limit"] is None
    for row in (pairs, tree):
        assert np.isclose(row["particles_per_s"], row["n"] / row["step_seconds"])
    assert np.isclose(tree["versus_all_pairs"], pairs["step_seconds"] / tree["step_seconds"])
    assert f"{tree['versus_all_pairs']:.2f}x the all-pairs step" in tree["layout"] and "particles/s" in result.stdout


def test_bench_cli_rejects_bad_layouts():
    for layouts in ("128:4", "1:4:4:0:split:newton"):
        result = subprocess.run(
            [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "bench", "--device", "cpu", "--layouts", layouts],
            capture_output=True,
            text=True,
        )
        assert result.returncode == 2 and "BLOCK_DIM 1 on CPU" in result.stderr and "newton" in result.stderr
    result = subprocess.run(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "bench", "--device", "cpu", "--ensemble", "1,x"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2 and "--ensemble must list system counts >= 2" in result.stderr
    result = subprocess.run(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "bench", "--device", "cpu", "--system", "lattice,dust"],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 2 and "--system must list lattice and/or piles" in result.stderr


def test_bench_cli_times_both_test_systems_side_by_side(tmp_path):
    out = tmp_path / "bench.json"
    result = subprocess.run(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "bench", "--device", "cpu", "--n", "320",
         "--seconds", "0.02", "--steps", "2", "--system", "lattice,piles", "--json", str(out)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    rows = json.loads(out.read_text())["rows"]
    assert [(r["system"], r["layout"].split(", ")[-1]) for r in rows] == [("lattice", "lattice"), ("piles", "piles")]
    assert all(r["baseline_pairs_per_s"] > 0 for r in rows)  # each system gets its own baseline


def test_bench_times_steps_with_their_kicks_unfused_beside_the_default(tmp_path):
    """``--layouts ...:unfused``: the CPU's default layout with each step's kicks and packing in
    launches of their own, timed in the same call as the default (fused) steps."""
    out = tmp_path / "bench.json"
    result = cli("bench", "--device", "cpu", "--n", "64", "--seconds", "0.02", "--steps", "2", "--layouts", "1:4:16:unfused", "--json", str(out))
    assert result.returncode == 0, result.stderr
    fused, unfused = json.loads(out.read_text())["rows"]
    assert (fused["fuse_kicks"], unfused["fuse_kicks"]) == (True, False)
    assert "kicks unfused" in unfused["layout"] and "kicks unfused" not in fused["layout"]
    assert fused["layout"] == unfused["layout"].replace(", kicks unfused", "")  # the same layout otherwise
    assert fused["step_seconds"] > 0 and unfused["step_seconds"] > 0


def test_bench_times_gravity_on_its_own_clock_beside_the_k1_step(tmp_path):
    """``--gravity-every 1,5``: a row at K = 5 (gravity every 5 steps, contacts from a neighbour
    list) beside the default K = 1 row of the same call, with its ratio to it and the list's builds
    per step; a bad list is refused with one line."""
    out = tmp_path / "bench.json"
    result = cli("bench", "--device", "cpu", "--n", "200", "--seconds", "0.02", "--steps", "3", "--system", "piles",
                 "--gravity-every", "1,5", "--json", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr
    every_step, clocked = json.loads(out.read_text())["rows"]
    assert (every_step["gravity_every"], clocked["gravity_every"]) == (1, 5)
    assert every_step["list_builds_per_step"] is None and 0 <= clocked["list_builds_per_step"] <= 1
    assert np.isclose(clocked["versus_every_step"], every_step["step_seconds"] / clocked["step_seconds"])
    assert np.isclose(clocked["step_pairs_per_s"], 200**2 / clocked["step_seconds"])
    assert "gravity every 5 steps (each pair once), neighbour-list contacts" in clocked["layout"] and "list builds a step" in result.stdout
    for bad in ("0", "5,x"):
        result = cli("bench", "--device", "cpu", "--gravity-every", bad)
        assert result.returncode == 2 and "--gravity-every must list integers >= 1" in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1


def test_bench_times_ensembles_at_each_clock_against_one_system_at_that_clock(tmp_path):
    """``--ensemble 2 --gravity-every 5``: the ensemble at K = 1 against one system at K = 1, and at
    K = 5 against one system at K = 5 (what fills the GPU changes with K)."""
    out = tmp_path / "bench.json"
    result = cli("bench", "--device", "cpu", "--n", "150", "--seconds", "0.02", "--steps", "5", "--system", "piles",
                 "--ensemble", "2", "--gravity-every", "5", "--json", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr
    rows = json.loads(out.read_text())["rows"]
    assert [(r["systems"], r["gravity_every"]) for r in rows] == [(1, 1), (2, 1), (1, 5), (2, 5)]
    for one, together in ((rows[0], rows[1]), (rows[2], rows[3])):
        ratio = together["step_pairs_per_s"] / one["step_pairs_per_s"]
        assert "2 systems together" in together["layout"] and f": {ratio:.2f}x one at a time" in together["layout"]
        assert np.isclose(together["step_pairs_per_s"], 2 * 150**2 / together["step_seconds"])
    assert "K = 1 step" not in rows[3]["layout"]  # an ensemble's ratio is to one system at its own clock


def test_bench_times_the_per_particle_block_beside_the_default(tmp_path):
    """``--particle-blocks 32`` with ``--gravity-every 5``: rows at K = 1 and K = 5 with 32 threads a
    block for the kernels of one thread a particle, each with its ratio to the default row of its K;
    the module's setting is as it was after the call; a bad list is refused with one line."""
    from decco_warp import bench as benchmarks
    from decco_warp import layouts

    out = tmp_path / "bench.json"
    result = cli("bench", "--device", "cpu", "--n", "200", "--seconds", "0.02", "--steps", "5", "--system", "piles",
                 "--gravity-every", "5", "--particle-blocks", "32", "--json", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr
    rows = json.loads(out.read_text())["rows"]
    assert [(r["gravity_every"], r["particle_block"]) for r in rows] == [(1, None), (5, None), (1, 32), (5, 32)]
    for default, blocked in zip(rows[:2], rows[2:]):
        assert np.isclose(blocked["versus_default_block"], default["step_seconds"] / blocked["step_seconds"])
        assert f"32 threads a block for the per-particle kernels: {blocked['versus_default_block']:.2f}x" in blocked["layout"]
    before = layouts.PARTICLE_BLOCK
    row = benchmarks.bench_size(100, "cpu", budget=0.01, steps=2, baseline=False, particle_block=before // 2)
    assert row.particle_block == before // 2 and layouts.PARTICLE_BLOCK == before
    for bad in ("0", "2000", "x"):
        result = cli("bench", "--device", "cpu", "--particle-blocks", bad)
        assert result.returncode == 2 and "--particle-blocks must list threads a block" in result.stderr
        assert len(result.stderr.strip().splitlines()) == 1


def test_the_fraction_of_the_limit_counts_the_pairs_a_step_evaluates(monkeypatch):
    """Gravity every K steps evaluates N^2 pairs a gravity step, N^2 / K a step: the fraction of the
    device's limit counts those (a K = 10 row read 2x to 3.5x its limit, counting N^2 a step), while
    pairs/s keeps counting N^2 a step, the rate an every-step code would need."""
    from decco_warp import bench as benchmarks

    monkeypatch.setattr(benchmarks, "device_limit_pairs_per_s", lambda device: (1e9, "a test limit"))
    for every in (1, 5):
        row = benchmarks.bench_size(120, "cpu", budget=0.01, steps=5, baseline=False, gravity_every=every)
        assert row.step_pairs_per_s == pytest.approx(120 * 120 / row.step_seconds, rel=1e-12)
        assert row.fraction_of_limit == pytest.approx(120 * 120 / every / row.step_seconds / 1e9, rel=1e-12)


def test_bench_times_each_contact_law_beside_the_first(tmp_path):
    """``--contact-law paper,ssdem``: each row again with the soft-sphere law (its contact history
    kept), with its ratio to the paper law's same row; an unknown law is refused with one line."""
    out = tmp_path / "bench.json"
    result = cli("bench", "--device", "cpu", "--n", "64", "--seconds", "0.02", "--steps", "2", "--contact-law", "paper,ssdem",
                 "--gravity-every", "1,5", "--json", str(out))  # fmt: skip
    assert result.returncode == 0, result.stderr
    rows = json.loads(out.read_text())["rows"]
    assert [(r["contact_law"], r["gravity_every"]) for r in rows] == [("paper", 1), ("paper", 5), ("ssdem", 1), ("ssdem", 5)]
    for paper, ssdem in zip(rows[:2], rows[2:]):
        assert paper["versus_first_law"] is None
        assert np.isclose(ssdem["versus_first_law"], paper["step_seconds"] / ssdem["step_seconds"])
        assert "contact law ssdem" in ssdem["layout"] and "x the paper law's step" in ssdem["layout"]
    result = cli("bench", "--device", "cpu", "--contact-law", "paper,hertz")
    assert result.returncode == 2 and "--contact-law must list paper, decco-code, ssdem" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1

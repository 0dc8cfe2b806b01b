"""The tree path (Scheme(gravity="tree")): gravity from a radix tree against all-pairs, contacts
from a hash grid identical to all-pairs, conservation figures, and a collision on both paths."""

import numpy as np
import pytest
from scenes import contact_cluster, overlapping_cloud

import decco_warp as dw
from decco_warp.run import builtin_pile

#: The default opening angle keeps the rms relative gravity error of a settled pile below this.
SETTLED_RMS = 1e-3


def _gravity(state, params, **options):
    """Gravity alone: the forces with G, less the same forces without (contacts cancel exactly)."""
    with_g = dw.compute_forces(state, params, precision="float64", **options)[0]
    without = dw.compute_forces(state, dw.Params(**{**params.to_dict(), "G": 0.0}), precision="float64", **options)[0]
    return with_g - without


def _errors(state, theta_open, device):
    exact = _gravity(state, dw.Params(), device=device, force_kernel="reference")
    tree = _gravity(state, dw.Params(), device=device, scheme=dw.Scheme(gravity="tree", theta_open=theta_open))
    relative = np.linalg.norm(tree - exact, axis=1) / np.linalg.norm(exact, axis=1)
    return float(np.sqrt((relative**2).mean())), float(relative.max())


@pytest.mark.parametrize("pile", ["target", "projectile"])
def test_tree_gravity_error_on_a_settled_pile_shrinks_with_theta_and_meets_the_default(pile, device):
    state = dw.load_pile(builtin_pile(pile))
    errors = {theta: _errors(state, theta, device) for theta in (0.2, 0.4, 0.7)}
    rms = [errors[theta][0] for theta in (0.2, 0.4, 0.7)]
    assert rms[0] < rms[1] < rms[2]  # a smaller angle opens more nodes
    assert errors[dw.Scheme().theta_open][0] <= SETTLED_RMS
    assert errors[0.2][1] < 2e-3 and errors[0.7][1] < 0.2  # the worst particle, near the centre where gravity cancels


def test_tree_gravity_on_clouds_with_duplicate_morton_cells_and_tiny_counts(device):
    """Two clumps 1000 radii apart share few Morton cells each (ties broken by index); 1 to 3 particles
    make degenerate trees. With theta_open -> small every node is opened: the sums equal all-pairs."""
    far = contact_cluster(60, seed=2)
    near = contact_cluster(40, seed=3, offset=(2.0e7 + 1.0e9, -1.0e7, 5.0e6))
    joined = dw.State.from_arrays(
        np.vstack([far.positions, near.positions]), np.vstack([far.velocities, near.velocities]),
        np.vstack([far.omegas, near.omegas]), np.concatenate([far.radii, near.radii]), np.concatenate([far.masses, near.masses]),
    )  # fmt: skip
    for state in (joined, contact_cluster(1, seed=0), contact_cluster(2, seed=1), contact_cluster(3, seed=1)):
        exact = _gravity(state, dw.Params(), device=device, force_kernel="reference")
        tree = _gravity(state, dw.Params(), device=device, scheme=dw.Scheme(gravity="tree", theta_open=1e-6))
        scale = np.abs(exact).max() or 1.0
        np.testing.assert_allclose(tree, exact, rtol=0, atol=1e-12 * scale)


def test_the_default_precision_walks_in_float32_within_its_round_off(device):
    """The default ("mixed") walk takes a leaf's separation in float64, a node's in float32 relative
    to the box's centre, and evaluates both in float32: per particle within 2e-6 of the float64 walk at the default theta_open (the tree's own
    error is ~1e-3), and with theta_open -> small within 2e-6 of float64 all-pairs."""

    def tree_gravity(state, theta_open, precision):
        scheme = dw.Scheme(gravity="tree", theta_open=theta_open)
        with_g = dw.compute_forces(state, dw.Params(), device=device, precision=precision, scheme=scheme)[0]
        return with_g - dw.compute_forces(state, dw.Params(G=0.0), device=device, precision=precision, scheme=scheme)[0]

    state = dw.load_pile(builtin_pile("target"))
    for theta_open, want in ((dw.Scheme().theta_open, tree_gravity(state, dw.Scheme().theta_open, "float64")),
                             (1e-6, _gravity(state, dw.Params(), device=device, force_kernel="reference"))):  # fmt: skip
        got = tree_gravity(state, theta_open, "mixed")
        relative = np.linalg.norm(got - want, axis=1) / np.linalg.norm(want, axis=1)
        assert 0.0 < relative.max() < 2e-6  # float32 terms: not bit-equal, well within the tree's error


@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_a_walk_split_into_parts_sums_the_same_pairs_and_nodes_no_worse(device, precision):
    """On a GPU each particle walks the tree in parts (subtrees, one thread each). The parts tile
    the sorted particles, with fewer particles than parts too. With every node opened (theta_open
    -> small) the summed field and potential equal one whole walk's to the round-off of the partial
    sums (float32 in "mixed"); at the default theta_open a part's ancestors can no longer be taken
    whole, so the gravity changes by the tree's error, and its rms error against all-pairs does not grow."""
    import warp as wp

    from decco_warp.gravity_tree import GravityTree

    def walk(state, parts, theta):
        position = wp.array(state.positions, dtype=wp.vec3d, device=device)
        mass = wp.array(state.masses, dtype=wp.float64, device=device)
        tree = GravityTree(state.n, device, precision, parts=parts)
        tree.build(position, mass)
        force, potential = wp.zeros(state.n, dtype=wp.vec3d, device=device), wp.zeros(state.n, dtype=wp.float64, device=device)
        tree.gravity(dw.Params().G, theta, mass, force)
        tree.potential(dw.Params().G, theta, mass, potential)
        links, roots = tree.links.numpy(), tree.roots.numpy()
        held = sorted((links[r, 0], links[r, 1]) for r in roots if r >= 0)
        assert len(held) == min(parts, state.n) and held[0][0] == 0 and held[-1][1] == state.n - 1
        assert all(a[1] + 1 == b[0] for a, b in zip(held, held[1:]))  # the parts tile the sorted particles
        return force.numpy(), potential.numpy()

    pile = dw.load_pile(builtin_pile("target"))
    for state in (pile, contact_cluster(5, seed=1), contact_cluster(1, seed=0)):
        whole_force, whole_potential = walk(state, 1, 1e-6)
        scale = np.abs(whole_force).max() or 1.0
        for parts in (3, 64):
            force, potential = walk(state, parts, 1e-6)
            np.testing.assert_allclose(force, whole_force, rtol=0, atol=(1e-6 if precision == "mixed" else 1e-13) * scale)
            np.testing.assert_allclose(potential, whole_potential, rtol=1e-13, atol=0)
    exact = _gravity(pile, dw.Params(), device=device, force_kernel="reference")

    def rms(force):
        return float(np.sqrt(np.mean((np.linalg.norm(force - exact, axis=1) / np.linalg.norm(exact, axis=1)) ** 2)))

    errors = [rms(walk(pile, parts, dw.Scheme().theta_open)[0]) for parts in (1, 8, 64)]
    assert errors[2] <= errors[1] * 1.05 and errors[1] <= errors[0] * 1.05 and errors[0] <= SETTLED_RMS, errors


def test_hash_grid_contacts_equal_all_pairs_contacts(device):
    """Without gravity only contacts remain: the grid finds the same pairs, so forces and torques
    are those of the all-pairs kernels to round-off of the summation order."""
    state = overlapping_cloud(300, seed=8)
    for rolling in ("couple", "paper"):
        params = dw.Params(G=0.0, rolling_friction=rolling)
        exact = dw.compute_forces(state, params, device=device, precision="float64", force_kernel="reference")
        tree = dw.compute_forces(state, params, device=device, precision="float64", scheme=dw.Scheme(gravity="tree"))
        for got, want in zip(tree, exact):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


def test_tree_momentum_figures_over_a_run(device):
    """A tree does not pair forces exactly: the net force is not zero. Stated figure: over 200 steps of
    the shipped target pile, the net gravity stays below 1e-3 of the summed |gravity|, and the
    momentum drift below 1e-3 of (summed |gravity| x time); the energy ledger still closes."""
    pile = dw.load_pile(builtin_pile("target"))
    sim = dw.Simulation(pile, dw.Params(), device=device, ledger=True, scheme=dw.Scheme(gravity="tree"))
    gravity = _gravity(pile, dw.Params(), device=device, scheme=dw.Scheme(gravity="tree"))
    assert np.linalg.norm(gravity.sum(axis=0)) <= 1e-3 * np.linalg.norm(gravity, axis=1).sum()
    p0 = (pile.masses[:, None] * pile.velocities).sum(axis=0)
    sim.step(200)
    drift = np.linalg.norm((pile.masses[:, None] * sim.state.velocities).sum(axis=0) - p0)
    assert drift <= 1e-3 * np.linalg.norm(gravity, axis=1).sum() * sim.time
    now = sim.diagnostics()
    from decco_warp.diagnostics import energy_ledger

    ledger = energy_ledger(now, sim.energy_start, sim.work())
    assert abs(now["total_energy"] + sum(ledger.values()) - sim.energy_start["total_energy"]) <= 1e-10 * abs(now["potential"])


def test_a_small_collision_ends_alike_on_both_paths(tmp_path):
    """The shipped piles at eta 0.5, 22 deg, 10 000 steps (400 s, by when they have merged): the same
    largest fragment within a few per cent."""
    from decco_warp import spec as specs
    from decco_warp.analysis.runs import analyse_run
    from decco_warp.run import start_run

    ratios = []
    for gravity in ("all-pairs", "tree"):
        spec = specs.resolve_spec(
            {"run": {"name": gravity, "out": str(tmp_path), "device": "cpu", "steps": 10000, "output_every": 5000},
             "params": {"gravity": gravity}}
        )  # fmt: skip
        start_run(spec)
        ratios.append(analyse_run(tmp_path / gravity, min_members=20)["summary"]["largest_mass_ratio"])
    assert ratios[0] > 1.0  # the piles merge
    assert ratios[1] == pytest.approx(ratios[0], rel=0.03)


def test_auto_gravity_takes_the_tree_from_the_crossover_and_the_spec_records_it(tmp_path):
    from types import SimpleNamespace

    from decco_warp import spec as specs
    from decco_warp.scheme import TREE_FROM, choose_gravity

    for device, kind in (("cpu", "cpu"), ("cuda:0", "cuda"), ("cuda:3", "cuda")):
        assert choose_gravity(TREE_FROM[kind] - 1, device) == "all-pairs"
        assert choose_gravity(TREE_FROM[kind], device) == "tree"
    spec = specs.resolve_spec({"run": {"name": "auto", "out": str(tmp_path), "device": "cpu", "steps": 10}, "params": {"gravity": "auto"}})
    with pytest.raises(specs.SpecError, match="settled"):
        specs.scheme_of(spec)
    for n, solver in ((TREE_FROM["cpu"] - 1, "all-pairs"), (TREE_FROM["cpu"], "tree")):
        settled, notes = specs.settle_auto(spec, SimpleNamespace(n=n), "cpu")
        assert specs.scheme_of(settled).gravity == solver and notes == [f'gravity = "auto": {solver} for {n} particles on cpu']
    with pytest.raises(specs.SpecError, match="gravity"):
        specs.resolve_spec({"params": {"gravity": "fmm"}})
    # Through the CLI: the shipped 450-particle collision stays on all-pairs, and says so.
    from helpers import cli

    result = cli("simulate", "--gravity", "auto", "--steps", "10", "--output-every", "10", "--device", "cpu", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    run_dir = tmp_path / "default"
    assert specs.load_spec_file(run_dir / "spec.toml")["params"]["gravity"] == "all-pairs"
    assert 'gravity = "auto": all-pairs for 450 particles on cpu' in (run_dir / "run.log").read_text()


@pytest.mark.parametrize("scene", ["pile", "cloud"])
def test_tree_frames_give_the_all_pairs_observables_in_n_log_n(device, scene):
    """A frame on the tree path costs O(N log N): the potential from the tree walk (per particle
    within 3e-4 rms of all-pairs at the default theta_open, falling with theta; the total within
    5e-5), and the contact observables from the hash grid's candidates, identical to all-pairs
    (the elastic energy to round-off on CUDA, where all-pairs sums each particle's pairs in a
    block's reduction order)."""
    state = dw.load_pile(builtin_pile("target")) if scene == "pile" else overlapping_cloud(300, seed=2, fill=0.7)
    exact = dw.Simulation(state, dw.Params(), device=device, allow_unstable=True).pair_observables()
    assert exact["contacts"].sum() > 500
    rms = {}
    for theta in (0.2, 0.4, 0.7):
        tree = dw.Simulation(state, dw.Params(), device=device, allow_unstable=True, scheme=dw.Scheme(gravity="tree", theta_open=theta)).pair_observables()
        for key in ("elastic", "contacts", "max_overlap", "overlap_depth", "overlap_partner"):
            if key == "elastic" and device.startswith("cuda"):
                np.testing.assert_allclose(tree[key], exact[key], rtol=1e-12, atol=0)
            else:
                assert np.array_equal(tree[key], exact[key]), key
        error = (tree["potential"] - exact["potential"]) / np.abs(exact["potential"])
        rms[theta] = float(np.sqrt(np.mean(error**2)))
        if theta == dw.Scheme().theta_open:
            assert rms[theta] < 3e-4 and abs(tree["potential"].sum() / exact["potential"].sum() - 1) < 5e-5
    assert rms[0.2] < rms[0.4] < rms[0.7]


def test_a_run_whose_contact_lists_overflow_says_so_once_in_its_log(tmp_path, monkeypatch):
    """A 75 km sphere touched by 150 small ones: the lists are sized for the radius ratio (408
    candidates at 10; the tree's and the neighbour list of gravity on its own clock alike) and hold
    them all.  Narrowed to 64, both overflow: the contacts stay right (the overflow walks the whole
    system, tests/test_forces.py), and a run's log says, once, that this slows it."""
    import decco_warp.arrays as arrays
    from scenes import sphere_mass
    from typer.testing import CliRunner

    from decco_warp.cli import app
    from decco_warp.engine import Engine

    count = 150
    k = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1 - 2 * k / count), np.pi * (1 + 5**0.5) * k  # a Fibonacci sphere
    direction = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], axis=1)
    radii = np.array([7.5e6] + [0.75e6] * count)
    x = np.vstack([[0.0, 0.0, 0.0], direction * (7.5e6 + 0.75e6 - 100.0)])
    pile = dw.State.from_arrays(x, np.zeros_like(x), np.zeros_like(x), radii, sphere_mass(radii))
    for every in (1, 5):
        listed = Engine(pile, dw.Params(), "cpu", scheme=dw.Scheme(gravity="tree", gravity_every=every))
        listed.eval_forces()
        assert listed.candidate_overflows() == 0 and listed.candidates.shape[1] == 408
    monkeypatch.setattr(arrays, "candidate_width", lambda r_min, r_max: 64)
    for every in (1, 5):
        engine = Engine(pile, dw.Params(), "cpu", scheme=dw.Scheme(gravity="tree", gravity_every=every))
        engine.eval_forces()
        assert engine.candidate_overflows() == 1  # the large sphere only
    dw.save_pile(pile, tmp_path / "urchin.h5")
    result = CliRunner().invoke(app, [
        "simulate", "--target", str(tmp_path / "urchin.h5"), "--projectile", str(builtin_pile("projectile")), "--gravity", "tree",
        "--gravity-every", "5", "--steps", "20", "--output-every", "10", "--device", "cpu", "--out", str(tmp_path), "--name", "urchin",
    ])  # fmt: skip
    assert result.exit_code == 0, result.stderr
    notes = [line for line in (tmp_path / "urchin" / "run.log").read_text().splitlines() if "more contact candidates" in line]
    assert len(notes) == 1 and "at step 10, 1 of the particles met" in notes[0]

"""Force and torque kernels against the float64 NumPy oracle of docs/model.md."""

import numpy as np
import pytest
from conftest import DEVICES
from oracle import pair_loop_forces
from scenes import contact_cluster, oracle_args, overlapping_cloud

import decco_warp as dw
from decco_warp.engine import Engine
from decco_warp.run import builtin_pile

#: float64 mode: relative error of each particle's force and torque.
FLOAT64_TOLERANCE = 1e-9
#: default (mixed) mode: error as a fraction of the particle's largest pair force (torque).
MIXED_TOLERANCE = 1e-4

SCENES = {
    "contact_cluster": lambda: contact_cluster(300, seed=1),
    "overlapping_cloud": lambda: overlapping_cloud(300, seed=2),
}


def _errors(state, params, device, precision, **options):
    force, torque = dw.compute_forces(state, params, device=device, precision=precision, **options)
    ref_force, ref_torque, force_scale, torque_scale = pair_loop_forces(
        *oracle_args(state, params), rolling=params.rolling_friction
    )
    return force, torque, ref_force, ref_torque, force_scale, torque_scale


@pytest.mark.parametrize("rolling", ["couple", "paper"])
@pytest.mark.parametrize("scene", sorted(SCENES))
def test_float64_forces_match_oracle(scene, rolling, device):
    state = SCENES[scene]()
    params = dw.Params(rolling_friction=rolling)
    force, torque, ref_force, ref_torque, _, torque_scale = _errors(state, params, device, "float64")
    force_error = np.linalg.norm(force - ref_force, axis=1) / np.linalg.norm(ref_force, axis=1)
    assert force_error.max() <= FLOAT64_TOLERANCE
    # Particles without contacts have exactly zero torque; compare the rest relatively.
    touching = torque_scale > 0
    assert touching.sum() > 0.5 * state.n
    torque_error = np.linalg.norm(torque - ref_torque, axis=1)[touching] / np.linalg.norm(ref_torque, axis=1)[touching]
    assert torque_error.max() <= FLOAT64_TOLERANCE
    assert np.all(torque[~touching] == 0.0)


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_default_precision_forces_match_oracle(scene, device):
    state = SCENES[scene]()
    params = dw.Params()
    force, torque, ref_force, ref_torque, force_scale, torque_scale = _errors(state, params, device, "mixed")
    assert (np.linalg.norm(force - ref_force, axis=1) / force_scale).max() <= MIXED_TOLERANCE
    touching = torque_scale > 0
    torque_error = np.linalg.norm(torque - ref_torque, axis=1)[touching] / torque_scale[touching]
    assert torque_error.max() <= MIXED_TOLERANCE


# Odd layouts make the remainder of the last tile and of the last block of particles non-trivial;
# one slot per particle forces the second look for contacts.  CPU layouts have one thread per block.
LAYOUTS = [
    ("cpu", dw.Layout(block_dim=1, particles_per_block=3, contact_slots=1)),
    ("cpu", dw.Layout(block_dim=1, particles_per_block=4, contact_slots=16)),
    ("cpu", dw.Layout(block_dim=1, particles_per_block=3, newton=True)),
    ("cpu", dw.Layout(block_dim=1, particles_per_block=1, newton=True)),
] + [
    (device, layout)
    for device in DEVICES
    if device.startswith("cuda")
    for layout in (
        dw.Layout(128, 4, 4), dw.Layout(32, 3, 1), dw.Layout(64, 1, 2),
        dw.Layout(32, 64, newton=True), dw.Layout(32, 32, newton=True),
    )  # fmt: skip
]


def _layout_id(case):
    device, layout = case
    contacts = "newton" if layout.newton else f"{layout.contact_slots}slots"
    return f"{device}-{layout.block_dim}x{layout.particles_per_block}-{contacts}"


@pytest.mark.parametrize("case", LAYOUTS, ids=_layout_id)
@pytest.mark.parametrize("n", [1, 2, 7, 129, 1000])
def test_tiled_kernel_equals_reference_kernel(n, case):
    """No particle skipped in a remainder tile: the tiled kernel sums every pair the plain loop sums."""
    device, layout = case
    state = overlapping_cloud(n, seed=n) if n > 1 else contact_cluster(1, seed=0)
    params = dw.Params()
    tiled = dw.compute_forces(state, params, device=device, precision="float64", layout=layout)
    reference = dw.compute_forces(state, params, device=device, precision="float64", force_kernel="reference")
    for got, want in zip(tiled, reference):
        scale = np.abs(want).max() or 1.0
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * scale)
    if n == 1:
        assert np.all(tiled[0] == 0.0) and np.all(tiled[1] == 0.0)
    if n <= 129:
        ref_force, _, _, _ = pair_loop_forces(*oracle_args(state, params))
        np.testing.assert_allclose(tiled[0], ref_force, rtol=1e-9, atol=1e-12 * np.abs(ref_force).max())


@pytest.mark.parametrize("case", LAYOUTS, ids=_layout_id)
@pytest.mark.parametrize("n", [1, 2, 7, 129])
def test_default_precision_kernel_sums_every_pair_in_remainder_tiles(n, case):
    device, layout = case
    state = overlapping_cloud(n, seed=n) if n > 1 else contact_cluster(1, seed=0)
    params = dw.Params()
    force, torque = dw.compute_forces(state, params, device=device, layout=layout)
    ref_force, ref_torque, force_scale, torque_scale = pair_loop_forces(*oracle_args(state, params))
    if n == 1:
        assert np.all(force == 0.0) and np.all(torque == 0.0)
        return
    assert (np.linalg.norm(force - ref_force, axis=1) / force_scale).max() <= MIXED_TOLERANCE
    touching = torque_scale > 0
    assert (np.linalg.norm(torque - ref_torque, axis=1)[touching] / torque_scale[touching]).max() <= MIXED_TOLERANCE


@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_newton_third_law_and_torque_balance(precision, device):
    """Total force and total torque about the origin (sum of x cross F plus couples) vanish."""
    state = overlapping_cloud(300, seed=5)
    force, torque = dw.compute_forces(state, dw.Params(), device=device, precision=precision)
    arm_torque = np.cross(state.positions, force)
    # Round-off of float64 sums over N ~ 300 terms, or of float32 sums in the default mode.
    tolerance = 1e-12 if precision == "float64" else 1e-5
    assert np.linalg.norm(force.sum(axis=0)) <= tolerance * np.linalg.norm(force, axis=1).sum()
    total_torque = arm_torque.sum(axis=0) + torque.sum(axis=0)
    assert np.linalg.norm(total_torque) <= tolerance * np.linalg.norm(arm_torque, axis=1).sum()


def test_pair_forces_are_exactly_opposite(device):
    """The two sides of a pair are computed separately; they must agree to the bit."""
    state = contact_cluster(2, seed=3)
    for precision in ("mixed", "float64"):
        force, _ = dw.compute_forces(state, dw.Params(), device=device, precision=precision)
        assert np.array_equal(force[0], -force[1])


@pytest.mark.parametrize("case", [c for c in LAYOUTS if c[1].newton], ids=_layout_id)
def test_contact_pass_handles_more_candidates_than_its_list_holds(case):
    """A 22.5 km sphere touched by more small ones than the list holds (they overlap each other
    too): the contact pass looks at every j for it; forces still equal the plain loop's, and the
    tree path's contacts (gravity off) too."""
    from decco_warp.kernels.contacts import CANDIDATES
    from scenes import crowded_sphere

    device, layout = case
    count = CANDIDATES + 6
    state = crowded_sphere(count)
    for params, scheme in ((dw.Params(), dw.Scheme()), (dw.Params(G=0.0), dw.Scheme(gravity="tree"))):
        engine = Engine(state, params, device, "float64", layout=layout, scheme=scheme)
        engine.eval_forces()
        assert engine.candidate_overflows() >= 1
        reference = dw.compute_forces(state, params, device=device, precision="float64", force_kernel="reference")
        for got, want in zip(engine.read_forces(), reference):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_each_pair_once_gives_both_sides_and_repeats_bit_for_bit(precision, device):
    """The Newton layout meets each pair once and hands its gravity to both particles: the forces
    equal the plain loop's, several systems stepped together each move as alone, and a step
    repeated from the same state gives the same bits (its sums have a fixed order)."""
    from scenes import contact_cluster

    layout = dw.Layout(32, 64, newton=True) if device.startswith("cuda") else dw.Layout(1, 4, newton=True)
    clouds = [overlapping_cloud(150, seed=21), contact_cluster(97, seed=22)]
    joined = dw.State.from_arrays(*[np.concatenate([getattr(c, name) for c in clouds])
                                    for name in ("positions", "velocities", "omegas", "radii", "masses")])  # fmt: skip
    params = dw.Params()
    tolerance = 1e-12 if precision == "float64" else 1e-5
    engine = Engine(joined, params, device, precision, layout=layout, systems=[150, 97])
    engine.eval_forces()
    together = engine.read_forces()
    # Its candidates come listed in increasing j, each system's own, and they are the contacts.
    counts, listed = engine.candidate_count.numpy(), engine.candidates.numpy()
    assert counts.sum() > 0 and counts.max() <= listed.shape[1]
    for i, count in enumerate(counts):
        row = listed[i, :count]
        assert np.all(np.diff(row) > 0) and np.all((row < 150) == (i < 150))
    first = 0
    for cloud in clouds:
        want = dw.compute_forces(cloud, params, device=device, precision="float64", force_kernel="reference")
        for got, expected in zip(together, want):
            part = got[first : first + cloud.n]
            assert np.abs(part - expected).max() <= tolerance * np.abs(expected).max()
        first += cloud.n
    runs = []
    for _ in range(2):
        sim = dw.Simulation(joined, params, device=device, precision=precision, layout=layout, ledger=True,
                            allow_unstable=True, systems=[150, 97])  # fmt: skip
        sim.step(5)
        runs.append((sim.state.positions, sim.state.omegas, sim.work()))
    for got, want in zip(*runs):
        np.testing.assert_array_equal(got, want)


def _fused_cases():
    """Every layout of LAYOUTS, the reference kernel and the tree path, on each device."""
    cases = [(_layout_id(case), case[0], {"layout": case[1]}) for case in LAYOUTS]
    for device in DEVICES:
        cases += [(f"{device}-reference", device, {"force_kernel": "reference"}), (f"{device}-tree", device, {"gravity": "tree"})]
    return cases


FUSED_CASES = _fused_cases()


@pytest.mark.parametrize("precision", ["mixed", "float64"])
@pytest.mark.parametrize(("device", "options"), [c[1:] for c in FUSED_CASES], ids=[c[0] for c in FUSED_CASES])
def test_steps_sharing_launches_equal_the_launches_of_a_step_bit_for_bit(device, options, precision):
    """Engine.advance fuses a step's last half kick, the next one's first half kick and drift and the
    packing of its bodies (kernels/integrate.py kick_drift): positions, velocities, spins,
    forces, torques, the ledger and the deepest contacts equal those of Engine.step, bit for bit,
    in every layout (the reference kernel and the tree path pack nothing: their kicks alone fuse).
    On CUDA too: both compile the same expressions, whose multiply-adds should contract alike."""
    from helpers import assert_fused_steps_equal_one_step_at_a_time

    options = dict(options)
    params, scheme = dw.Params(), dw.Scheme(gravity=options.pop("gravity", "all-pairs"))
    state = contact_cluster(40, seed=6, speed=1e3)

    def make():
        return dw.Simulation(state, params, device=device, precision=precision, ledger=True, allow_unstable=True, scheme=scheme, **options)

    assert_fused_steps_equal_one_step_at_a_time(make)


def _contact_counts(state, margin):
    """Per particle, how many others lie closer than (R_i + R_j) * margin (float64 NumPy)."""
    r = state.positions[:, None, :] - state.positions[None, :, :]
    distance = np.sqrt((r**2).sum(axis=-1))
    reach = (state.radii[:, None] + state.radii[None, :]) * margin
    np.fill_diagonal(distance, np.inf)
    return (distance < reach).sum(axis=1)


@pytest.mark.parametrize("gravity", ["tree", "newton"])
def test_a_squeezed_pile_notes_its_contacts_and_no_list_overflows(gravity, device):
    """The shipped target pile squeezed by 6 %: overlaps to ~0.25 of a radius, and its large grains
    touch ~30 small ones (a list of 24 overflowed here, and a merged pile stepped 10x slower).
    Each particle notes exactly its contacts (within the candidate margin), and every list holds."""
    pile = dw.load_pile(builtin_pile("target"))
    centre = pile.positions.mean(axis=0)
    state = dw.State.from_arrays(centre + 0.94 * (pile.positions - centre), pile.velocities, pile.omegas, pile.radii, pile.masses)
    # The Newton layout meets each pair once and notes it for both particles.
    layout = dw.Layout(32, 64, newton=True) if device.startswith("cuda") else dw.Layout(1, 4, newton=True)
    engine = Engine(state, dw.Params(), device, layout=layout, scheme=dw.Scheme(gravity="all-pairs" if gravity == "newton" else gravity))
    engine.eval_forces()
    noted = engine.candidate_count.numpy()
    contacts = _contact_counts(state, 1.0)
    assert contacts.max() > 24  # the case that overflowed
    assert (noted >= contacts).all() and (noted <= _contact_counts(state, 1.0002)).all()
    assert engine.candidate_overflows() == 0


CPU_BLOCK_LAYOUTS = """
import sys
from dataclasses import replace
import numpy as np, warp as wp
wp.config.enable_cpu_blocks = True  # the CPU runs every lane of a block, as a GPU does
wp.config.kernel_cache_dir = sys.argv[1]
sys.path.insert(0, sys.argv[2])
import decco_warp as dw
from decco_warp.engine import Engine
from scenes import overlapping_cloud
state = overlapping_cloud(401, seed=3)  # not a multiple of the contact pass's 4 particles a block
params = dw.Params()
for precision, tolerance in (("float64", 1e-12), ("mixed", 1e-5)):
    want = dw.compute_forces(state, params, device="cpu", precision="float64", force_kernel="reference")
    for layout in (dw.Layout(32, 3, 2), dw.Layout(16, 4, 1), dw.Layout(1, 4, newton=True)):
        got = dw.compute_forces(state, params, device="cpu", precision=precision, layout=layout)
        for g, w in zip(got, want):
            assert np.abs(g - w).max() <= tolerance * np.abs(w).max(), (precision, layout)
    # Gravity on its own clock: the contact pass's lanes (8 a particle, 4 particles a block) over the neighbour list.
    got = dw.compute_forces(state, params, device="cpu", precision=precision, scheme=dw.Scheme(gravity_every=5))
    for g, w in zip(got, want):
        assert np.abs(g - w).max() <= tolerance * np.abs(w).max(), (precision, "gravity_every")
# The tree path's contacts (8 lanes a particle over the hash grid's lists), without gravity: the tree's is approximate.
no_gravity = replace(params, G=0.0)
want = dw.compute_forces(state, no_gravity, device="cpu", precision="float64", force_kernel="reference")
got = dw.compute_forces(state, no_gravity, device="cpu", precision="float64", scheme=dw.Scheme(gravity="tree"))
for g, w in zip(got, want):
    assert np.abs(g - w).max() <= 1e-12 * np.abs(w).max(), "tree"
# The ledger's channels (float64 in either precision), summed over a block's lanes by the fused
# layout's own reduction: lanes past 32 (two warps on a GPU), four particles a block, slots overflowing.
def channels(precision, **options):
    engine = Engine(state, params, "cpu", precision, ledger=True, **options)
    engine.eval_forces()
    return engine.channels.numpy()
want = channels("float64", force_kernel="reference")
for precision in ("float64", "mixed"):
    for layout in (dw.Layout(64, 1, 2), dw.Layout(16, 4, 1)):
        got = channels(precision, layout=layout)
        assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max(), (precision, layout)
print("SAME")
"""


def test_gpu_layouts_run_lane_by_lane_on_the_cpu_equal_the_reference_kernel(tmp_path):
    """The GPU's layouts (blocks of 16 and 32 lanes striding over j, the slots' overflow, the Newton
    layout's, the neighbour list's and the tree's contact pass of 8 lanes a particle, 4 a block, the block reductions) run with Warp's CPU blocks in a fresh interpreter:
    forces and torques equal the plain kernel's (float64 to round-off; mixed within 1e-5), and so
    do the ledger's channels of the fused layout (float64 in both)."""
    import subprocess
    import sys
    from pathlib import Path

    tests = str(Path(__file__).parent)
    done = subprocess.run([sys.executable, "-c", CPU_BLOCK_LAYOUTS, str(tmp_path / "cache"), tests],
                          capture_output=True, text=True, timeout=900)  # fmt: skip
    assert done.returncode == 0 and "SAME" in done.stdout, (done.stdout + done.stderr)[-3000:]


def test_the_newton_gathers_rows_loaded_ahead_leave_the_forces_unchanged(monkeypatch):
    """The Newton gather loads several tiles' rows at once (kernels/newton.py GATHER_AHEAD) so that
    their waits overlap; it adds them in the tiles' order whatever the number, so the forces and the
    candidate lists are the same bit for bit at 16 (the default), 8 and 5 (a number that does not
    divide the tiles), in both precisions."""
    from decco_warp.kernels import newton

    state = overlapping_cloud(401, seed=3)  # 7 tiles of 64
    for precision in ("mixed", "float64"):
        got = {}
        for ahead in (16, 8, 5):
            monkeypatch.setattr(newton, "GATHER_AHEAD", ahead)
            engine = Engine(state, dw.Params(), "cpu", precision, layout=dw.Layout(1, 64, newton=True))
            engine.eval_forces()
            got[ahead] = (engine.force.numpy().copy(), engine.candidate_count.numpy().copy())
        for ahead in (8, 5):
            assert np.array_equal(got[ahead][0], got[16][0]) and np.array_equal(got[ahead][1], got[16][1]), (precision, ahead)


@pytest.fixture
def tree_by_another_name():
    """A toy gravity solver, added as any new one is: one class and its registration.  It sums the
    tree's gravity with the tree's own launches (gravity_tree.py) and has no potential of its own (frames
    sum it over all pairs); it lists its contacts with the finder its class names.  Unregistered after
    the test, so that no other test sees it."""
    from decco_warp.gravity_solvers import GRAVITY_SOLVERS, GravitySolver, gravity_solver
    from decco_warp.gravity_tree import GravityTree

    @gravity_solver
    class TreeByAnotherName(GravitySolver):
        name = "tree-by-another-name"
        finder = "hash-grid"  # the grid is placed in the box of the tree's build: it reads self.tree
        graph_conditionals = True  # the tree's moments loop on the device

        def __init__(self, model, scheme, listing=False):
            self.model, self.theta_open = model, scheme.theta_open
            self.tree = GravityTree(model.count, model.device, scheme.precision)

        def evaluate(self, state, force_out):
            m = self.model
            self.tree.build(state.position, m.mass)
            self.tree.gravity(m.params.G, self.theta_open, m.mass, force_out)

    try:
        yield TreeByAnotherName
    finally:
        del GRAVITY_SOLVERS[TreeByAnotherName.name]


@pytest.mark.parametrize(("finder", "gravity_every"), [("hash-grid", 1), ("neighbour-list", 1), ("hash-grid", 5)])
def test_a_registered_gravity_solver_is_named_by_a_scheme_and_moves_as_the_tree_bit_for_bit(
    tree_by_another_name, finder, gravity_every, monkeypatch
):
    """The solver seam: a scheme names the toy solver, the engine composes it with the contact finder
    its class names (gravity on its own clock: with the neighbour list), and the motion, ledger and
    deepest contacts are the tree path's bit for bit: the same launches for gravity, and candidates
    in increasing j whichever finder lists them (on the CPU's one lane a particle, the neighbour
    list's candidates that touch nothing add exact zeros)."""
    from decco_warp.contact_finders import CONTACT_FINDERS

    toy = tree_by_another_name
    monkeypatch.setattr(toy, "finder", finder)
    state = contact_cluster(200, seed=5, speed=1e3)

    def run(gravity):
        scheme = dw.Scheme(gravity=gravity, gravity_every=gravity_every)
        sim = dw.Simulation(state, dw.Params(), device="cpu", ledger=True, allow_unstable=True, scheme=scheme)
        sim.step(40)
        return sim

    mine, tree = run(toy.name), run("tree")
    assert type(mine.engine.path.gravity) is toy
    assert type(mine.engine.path.finder) is CONTACT_FINDERS[finder if gravity_every == 1 else "neighbour-list"]
    assert mine.diagnostics()["number_of_contacts"] > state.n / 2
    got, want = mine.snapshot(), tree.snapshot()
    for key in ("positions", "velocities", "omegas", "force", "torque", "channels", "work", "deepest_contact"):
        np.testing.assert_array_equal(got[key], want[key], err_msg=key)


def test_a_scheme_names_only_registered_gravity_solvers_each_name_once(tree_by_another_name):
    """An unknown solver is refused in one line listing those registered (an InputError: the CLI's
    exit code for bad input); a second solver under a name taken is refused at its registration."""
    from decco_warp.errors import InputError
    from decco_warp.gravity_solvers import GravitySolver, gravity_solver

    assert dw.Scheme(gravity=tree_by_another_name.name).gravity == tree_by_another_name.name
    with pytest.raises(InputError, match="^gravity must be one of all-pairs, tree, tree-by-another-name; got 'barnes-hut'$"):
        dw.Scheme(gravity="barnes-hut")
    with pytest.raises(ValueError, match="a gravity solver named 'tree' is registered already"):
        gravity_solver(type("AnotherTree", (GravitySolver,), {"name": "tree"}))


def test_a_scheme_refuses_an_unknown_gravity_solver_by_the_built_in_names():
    """Without a registration of its own (the toy's is undone after its tests) a scheme lists the built-in solvers."""
    from decco_warp.errors import InputError

    with pytest.raises(InputError, match="^gravity must be one of all-pairs, tree; got 'tree-by-another-name'$"):
        dw.Scheme(gravity="tree-by-another-name")

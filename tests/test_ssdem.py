"""contact_law = "ssdem", pkdgrav's soft-sphere law (Schwartz, Richardson & Michel 2012): its pair forces
and motion against the float64 NumPy oracle (tests/oracle.py ``ssdem_forces``), its contact history
(carried across list rebuilds, dropped when a contact breaks, saved in snapshots and checkpoints, the
same in an ensemble and on the GPU's layouts), its conservation and energy ledger, and benchmarks in
the style of Chung & Ooi (2011) with analytic answers (docs/ssdem-design.md sect. 13)."""

import numpy as np
import pytest
from conftest import DEVICES
from oracle import ssdem_constants, ssdem_forces, ssdem_run
from scenes import approaching_clumps, contact_cluster, sphere_mass
from test_conservation import _momenta

import decco_warp as dw
from decco_warp import contact_finders
from decco_warp.diagnostics import energy_ledger
from decco_warp.errors import InputError

#: Every branch acts: the tangential, rolling and twisting springs each stick at some contacts and
#: slide at others, with both dashpots.
SSDEM = dict(contact_law="ssdem", mu_s=0.3, mu_r=0.05, mu_t=0.3, eps_t=0.5, restitution=0.8)
#: float64: the kernels and the oracle agree to round-off (relative to the largest force or spin).
FLOAT64_TOLERANCE = 1e-12
#: mixed: gravity is summed in float32 (and the fused layout's contact sums), each contact in float64.
MIXED_TOLERANCE = 1e-4


def _clump(n=30, seed=3):
    return contact_cluster(n, seed=seed, overlap_range=(1.0, 1e3), speed=20.0, spin=1e-4)


def _oracle_args(state):
    return state.positions, state.velocities, state.omegas, state.radii, state.masses


# --- pair forces and motion against the oracle --------------------------------------------------


@pytest.mark.parametrize("precision", ["float64", "mixed"])
@pytest.mark.parametrize("kernel", ["tiled", "reference"])
def test_a_first_evaluation_matches_the_oracle(kernel, precision, device):
    """A state's first evaluation (no springs yet: each tangential spring is u_t dt): force and torque."""
    state = _clump()
    params = dw.Params(**SSDEM)
    force, torque = dw.compute_forces(state, params, device=device, precision=precision, force_kernel=kernel)
    want_force, want_torque, springs = ssdem_forces(*_oracle_args(state), ssdem_constants(params), params.G, {})
    assert len(springs) >= state.n - 1
    tolerance = FLOAT64_TOLERANCE if precision == "float64" else MIXED_TOLERANCE
    assert np.abs(force - want_force).max() <= tolerance * np.abs(want_force).max()
    # (The fused layout sums the contacts in the sweep's precision too.)
    assert np.abs(torque - want_torque).max() <= tolerance * np.abs(want_torque).max()


#: Force paths, each with the contacts' springs carried from step to step: the plain kernel, the
#: fused and Newton layouts, the tree's hash grid (found afresh at every step) and the neighbour list
#: of gravity on its own clock (rebuilt every few steps here: its skin made tiny).
PATHS = {
    "reference": {"force_kernel": "reference"},
    "fused": {},
    "newton": {"layout": dw.Layout(1, 4, newton=True)},
    "tree": {"scheme": dw.Scheme(gravity="tree")},
    "clocked": {"scheme": dw.Scheme(gravity_every=5)},
}


@pytest.mark.parametrize("path", sorted(PATHS))
def test_motion_with_the_contacts_springs_matches_the_oracle(path, monkeypatch):
    """150 steps of two clumps flying apart into each other, whose contacts stick, slide, break and form,
    without gravity (so that every path, the tree's and the clocked one's too, has the oracle's forces):
    positions, velocities and spins equal the oracle's to round-off, and so do the springs each
    contact holds at the end."""
    monkeypatch.setattr(contact_finders, "SKIN_FRACTION", 2e-4)  # the neighbour list rebuilt every few steps
    state = approaching_clumps()
    params = dw.Params(**SSDEM, G=0.0)
    steps = 150
    sim = dw.Simulation(state, params, device="cpu", precision="float64", **PATHS[path])
    sim.step(steps)
    x, v, w, springs = ssdem_run(*_oracle_args(state), ssdem_constants(params), 0.0, steps)
    got = sim.state
    assert np.abs(got.positions - x).max() <= 1e-9  # [cm], of ~200 cm moved
    assert np.abs(got.positions - state.positions).max() > 100.0
    assert np.abs(got.velocities - v).max() <= FLOAT64_TOLERANCE * np.abs(v).max()
    assert np.abs(got.omegas - w).max() <= FLOAT64_TOLERANCE * np.abs(w).max()
    # Contacts broke and formed on the way.
    _, _, first = ssdem_forces(*_oracle_args(state), ssdem_constants(params), 0.0, {})
    assert set(first) - set(springs) and set(springs) - set(first)
    # The history holds exactly the touching pairs, with the oracle's springs, on both sides.
    snapshot = sim.snapshot()
    count, partner = snapshot["contact_count"], snapshot["contact_partner"]
    held = {(i, int(partner[i, row])): row for i in range(state.n) for row in range(count[i])}
    assert len(held) == 2 * len(springs)
    for (p, q), (spring, normal, rolling, twist) in springs.items():
        for i, j in ((p, q), (q, p)):
            row = held[(i, j)]
            np.testing.assert_allclose(snapshot["contact_spring"][i, row], spring, rtol=0, atol=1e-9 * np.abs(spring).max())
            np.testing.assert_allclose(snapshot["contact_normal"][i, row], normal, rtol=0, atol=1e-12)
            np.testing.assert_allclose(snapshot["contact_rolling"][i, row], rolling, rtol=0, atol=1e-9 * np.abs(rolling).max())
            assert snapshot["contact_twist"][i, row] == pytest.approx(twist, rel=1e-9, abs=1e-18)
    if path == "clocked":
        assert sim.neighbour_list_builds() >= 5


def test_every_branch_of_the_law_acts_in_the_oracle_scene():
    """The scenes of the tests above are worth their name: each of the three springs sticks at some
    contact steps and slides at others."""
    state = approaching_clumps()
    params = dw.Params(**SSDEM, G=0.0)
    regimes = []
    ssdem_run(*_oracle_args(state), ssdem_constants(params), 0.0, 60, regimes)
    slid = np.array(regimes).mean(axis=0)
    assert np.all((0.05 < slid) & (slid < 0.95)), slid


# --- the contact history --------------------------------------------------------------------------


def _oblique_pair(radius=1.0, speed=50.0, theta_deg=45.0, gap=1e-6):
    """Two equal spheres (radius [cm], density 2.7) just apart on the x axis, approaching at ``speed``
    each, at ``theta_deg`` from the line of centres, without spin."""
    t = np.radians(theta_deg)
    x = np.array([[-radius - gap / 2, 0, 0], [radius + gap / 2, 0, 0]])
    v = speed * np.array([[np.cos(t), np.sin(t), 0], [-np.cos(t), -np.sin(t), 0]])
    radii = np.full(2, radius)
    return dw.State.from_arrays(x, v, np.zeros((2, 3)), radii, sphere_mass(radii))


def _impact_params(state, overlap=0.002, steps_per_contact=50, **constants):
    """Params of a pair's impact: k_n for a deepest overlap of ``overlap`` radii undamped, dt a
    ``steps_per_contact``-th of the undamped contact, no gravity."""
    reduced = state.masses[0] * state.masses[1] / state.masses.sum()
    approach = np.linalg.norm(state.velocities[1] - state.velocities[0])
    k_n = reduced * (approach / (overlap * state.radii[0])) ** 2
    dt = np.pi * np.sqrt(reduced / k_n) / steps_per_contact
    return dw.Params(**{"contact_law": "ssdem", "k_in": 2 * k_n, "dt": dt, "G": 0.0, "mu_r": 0.0, **constants})


def test_a_contact_is_held_once_on_each_side_the_same_bits_and_dropped_when_it_breaks(device):
    state = _oblique_pair()
    params = _impact_params(state, restitution=0.9, mu_s=0.1)
    sim = dw.Simulation(state, params, device=device, precision="float64")
    seen = 0
    for _ in range(120):
        sim.step(1)
        snap = sim.snapshot()
        touching = np.linalg.norm(sim.state.positions[1] - sim.state.positions[0]) < 2 * state.radii[0]
        assert list(snap["contact_count"]) == ([1, 1] if touching else [0, 0])
        if touching:
            seen += 1
            assert list(snap["contact_partner"][:, 0]) == [1, 0]
            for key in ("contact_spring", "contact_normal", "contact_rolling", "contact_twist"):
                assert np.array_equal(snap[key][0], snap[key][1]), key  # the pair's one copy, twice
            assert np.linalg.norm(snap["contact_spring"][0, 0]) > 0
    assert 40 < seen < 60  # the contact lasted its ~50 steps, and is gone
    assert sim.history_overflows() == 0


def test_the_history_is_kept_only_by_the_law_with_springs():
    state = _clump()
    for law, kept in (("paper", False), ("decco-code", False), ("ssdem", True)):
        sim = dw.Simulation(state, dw.Params(contact_law=law), device="cpu")
        assert ("contact_count" in sim.snapshot()) == kept
        assert ("elastic_tangential" in sim.pair_observables()) == kept


@pytest.mark.parametrize("scheme", [dw.Scheme(), dw.Scheme(gravity_every=5)], ids=["one-clock", "gravity-every-5"])
def test_a_resumed_run_with_springs_is_the_uninterrupted_one_bit_for_bit(scheme, tmp_path, device):
    """Through a snapshot, and through a checkpoint file (HDF5) as a run resumes."""
    from decco_warp.io import read_checkpoint, write_checkpoint

    state = _clump(40, seed=9)
    params = dw.Params(**SSDEM)
    straight = dw.Simulation(state, params, device=device, ledger=True, scheme=scheme)
    straight.step(130)
    first = dw.Simulation(state, params, device=device, ledger=True, scheme=scheme)
    first.step(55)
    write_checkpoint(tmp_path / "checkpoint.h5", first.snapshot(), first.state, {})
    del first
    snapshot, static, _ = read_checkpoint(tmp_path / "checkpoint.h5")
    second = dw.Simulation.from_snapshot(static, params, snapshot, device=device, scheme=scheme)
    second.step(75)
    a, b = straight.snapshot(), second.snapshot()
    assert a.keys() == b.keys() and "contact_spring" in a
    for key, value in a.items():
        if isinstance(value, np.ndarray):
            assert np.array_equal(value, b[key]), key
    assert a["energy_start"] == b["energy_start"]
    assert a["contact_count"].sum() > state.n  # contacts held their springs across the restart


#: (gravity_every, simulation.GRAPH_STEPS or None for its own, Simulation keywords): recorded blocks of
#: an even count of contact evaluations (8, 6) and an odd one (7, 9, and 49 at K = 7 by default).
GRAPH_CASES = {
    "one-clock-8": (1, 8, {}),
    "one-clock-7": (1, 7, {}),
    "reference-7": (1, 7, {"force_kernel": "reference"}),
    "newton-7": (1, 7, {"layout": "newton"}),
    "gravity-every-2-6": (2, 7, {}),
    "gravity-every-3-9": (3, 9, {}),
    "gravity-every-7-49": (7, None, {}),
}


def _snapshots_equal(a: dict, b: dict) -> None:
    assert a.keys() == b.keys() and "contact_spring" in a
    for key, value in a.items():
        assert np.array_equal(value, b[key]), key


@pytest.mark.parametrize("case", sorted(GRAPH_CASES))
def test_recorded_graphs_keep_the_springs_as_steps_one_at_a_time(case, monkeypatch):
    """The contact history's two buffers swap roles at each contact evaluation (arrays.ContactHistory),
    in Python, so a recorded graph holds the buffers of the roles it was recorded with.  Blocks of an
    even and an odd count of evaluations, replayed after an even and an odd count of steps launched
    one by one, give every array of the snapshot (positions, velocities, spins, forces, the ledger,
    the springs) bit for bit as the same steps taken an outer step at a time, outside any graph."""
    from decco_warp import simulation
    from decco_warp.arrays import ContactHistory
    from decco_warp.layouts import newton_layout

    every, graph_steps, options = GRAPH_CASES[case]
    if options.get("layout") == "newton":
        options = {"layout": newton_layout("cpu")}
    state = _clump(40, seed=9)
    params = dw.Params(**SSDEM)
    scheme = dw.Scheme(gravity_every=every)
    alone = dw.Simulation(state, params, device="cpu", ledger=True, scheme=scheme, **options)
    assert alone._graph_steps > every  # (its outer steps are never a recorded block)
    if graph_steps is not None:
        monkeypatch.setattr(simulation, "GRAPH_STEPS", graph_steps)
    recorded = dw.Simulation(state, params, device="cpu", ledger=True, scheme=scheme, **options)
    block = recorded._graph_steps
    turned = []  # per ContactHistory.settle: whether it copied the rows (the roles were the other way)
    settle = ContactHistory.settle

    def noted_settle(self, flipped):
        turned.append(self.flipped != flipped)
        settle(self, flipped)

    monkeypatch.setattr(ContactHistory, "settle", noted_settle)
    # An outer step, blocks with one left over, one block, three outer steps, two blocks.
    for steps in (every, 2 * block + every, block, 3 * every, 2 * block, every):
        recorded.step(steps)
        for _ in range(steps // every):
            alone.step(every)
        _snapshots_equal(alone.snapshot(), recorded.snapshot())
    assert recorded._graph is not None and alone._graph is None
    # The recording ends with a copy for an odd block; a replay after an odd count of evaluations
    # outside it copies (an even K takes none: each outer step is an even count).
    assert turned[0] == (block % 2 == 1) and any(turned[1:]) == (every % 2 == 1)
    assert recorded.snapshot()["contact_count"].sum() > 0  # contacts held springs to the end


def test_a_recording_that_fails_leaves_the_springs_where_they_were():
    """A graph capture that fails after some of its launches were recorded (the contact history's
    roles swapped in Python at each) stepped nothing: the steps then go on one by one from the same rows."""
    state = _clump(40, seed=9)
    params = dw.Params(**SSDEM)
    alone = dw.Simulation(state, params, device="cpu")
    refused = dw.Simulation(state, params, device="cpu")
    advance = refused.engine.advance

    def fails_while_recording(steps):
        if steps == refused._graph_steps:  # the recording: three steps' launches recorded, then an error
            advance(3)
            raise RuntimeError("the graph was refused")
        advance(steps)

    refused.engine.advance = fails_while_recording
    with pytest.warns(UserWarning, match="launched one by one.*refused"):
        refused.step(refused._graph_steps + 1)
    assert refused._graph is None
    for _ in range(refused._graph_steps + 1):
        alone.step(1)
    _snapshots_equal(alone.snapshot(), refused.snapshot())


def test_a_snapshot_without_the_history_is_refused_for_the_law_with_springs():
    state = _clump()
    params = dw.Params(**SSDEM)
    snapshot = dw.Simulation(state, params, device="cpu").snapshot()
    del snapshot["contact_spring"]
    with pytest.raises(InputError, match="contact history"):
        dw.Simulation.from_snapshot(state, params, snapshot, device="cpu")


ENSEMBLE_SIZES = (23, 31)


@pytest.mark.parametrize("scheme", [dw.Scheme(), dw.Scheme(gravity_every=5)], ids=["one-clock", "gravity-every-5"])
def test_each_system_of_an_ensemble_keeps_the_springs_it_would_keep_alone(scheme, device):
    """An ensemble made from its members' Simulations (as a sweep makes one) steps each system bit for
    bit as alone, and each system's view saves the snapshot (contact history included, in its own
    numbering) that it would save alone."""
    from decco_warp.ensemble import Ensemble

    states = [contact_cluster(n, seed=seed, speed=1e3) for seed, n in enumerate(ENSEMBLE_SIZES)]
    params = dw.Params(**SSDEM)
    members = [dw.Simulation(s, params, device=device, ledger=True, scheme=scheme) for s in states]
    for sim in members:
        sim.step(10)
    ensemble = Ensemble(members)
    alone = [dw.Simulation.from_snapshot(s, params, sim.snapshot(), device=device, scheme=scheme) for s, sim in zip(states, members)]
    ensemble.step(40)
    for view, sim in zip(ensemble.views, alone):
        sim.step(40)
        mine, own = view.snapshot(), sim.snapshot()
        for key, value in own.items():
            if isinstance(value, np.ndarray):
                assert np.array_equal(mine[key], value), key
        assert own["contact_count"].sum() > 0
        assert view.diagnostics()["elastic_tangential"] == sim.diagnostics()["elastic_tangential"] > 0


CPU_BLOCKS = """
import sys
import numpy as np, warp as wp
wp.config.enable_cpu_blocks = True  # the CPU runs every lane of a block, as a GPU does
wp.config.kernel_cache_dir = sys.argv[1]
sys.path.insert(0, sys.argv[2])
import decco_warp as dw
from scenes import contact_cluster
state = contact_cluster(45, seed=3, overlap_range=(1.0, 1e3), speed=20.0, spin=1e-4)
# (No gravity: the clock of gravity_every = 5 then changes nothing.)
params = dw.Params(contact_law="ssdem", mu_s=0.3, mu_r=0.05, mu_t=0.3, eps_t=0.5, restitution=0.8, G=0.0)

def run(**options):
    sim = dw.Simulation(state, params, device="cpu", precision="float64", **options)
    sim.step(60)
    snap = sim.snapshot()
    rows = {(i, int(snap["contact_partner"][i, r])): snap["contact_spring"][i, r] for i in range(state.n) for r in range(snap["contact_count"][i])}
    return sim.state, rows

want, want_rows = run(force_kernel="reference")
for name, options in (("32x3", {"layout": dw.Layout(32, 3, 2)}), ("16x4", {"layout": dw.Layout(16, 4, 1)}),
                      ("newton", {"layout": dw.Layout(1, 4, newton=True)}), ("clocked", {"scheme": dw.Scheme(gravity_every=5)})):
    got, rows = run(**options)
    moved = np.abs(want.positions - state.positions).max()
    assert np.abs(got.positions - want.positions).max() <= 1e-12 * moved, name
    assert np.abs(got.omegas - want.omegas).max() <= 1e-12 * np.abs(want.omegas).max(), name
    assert rows.keys() == want_rows.keys(), name
    for key, spring in want_rows.items():
        assert np.abs(rows[key] - spring).max() <= 1e-9 * np.abs(spring).max() + 1e-30, (name, key)
print("SAME", len(want_rows))
"""


def test_the_gpu_layouts_keep_the_springs_lane_by_lane_on_the_cpu(tmp_path):
    """The fused layout's lanes (blocks of 32 and 16 striding over j, rows placed by a scan of the lanes'
    counts, slots overflowing), the Newton layout's and the neighbour list's contact pass, run with
    Warp's CPU blocks in a fresh interpreter: 60 steps equal the plain kernel's to round-off, with the
    same contacts holding the same springs."""
    import subprocess
    import sys
    from pathlib import Path

    tests = str(Path(__file__).parent)
    done = subprocess.run([sys.executable, "-c", CPU_BLOCKS, str(tmp_path / "cache"), tests], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0 and "SAME" in done.stdout, (done.stdout + done.stderr)[-3000:]



LANES_AGAINST_ONE_LANE = """
import sys, warnings
from dataclasses import replace
import numpy as np, warp as wp
wp.config.enable_cpu_blocks = True  # the contact pass's 8 lanes a particle, 4 particles a block, as on a GPU
wp.config.kernel_cache_dir = sys.argv[1]
sys.path.insert(0, sys.argv[2])
import decco_warp as dw
from decco_warp import contact_finders, forces
from decco_warp.arrays import pair_history
from decco_warp.ensemble import Ensemble
from decco_warp.io import load_pile
from decco_warp.kernels.contacts import CANDIDATES, contact_pass
from decco_warp.plan import builtin_pile
from helpers import straight_and_resumed
from scenes import contact_cluster, crowded_sphere
warnings.simplefilter("ignore", UserWarning)  # (the check below reads arrays between launches: no graph)
params = dw.Params(contact_law="ssdem", mu_s=0.3, mu_r=0.05, mu_t=0.3, eps_t=0.5, restitution=0.8)
seen = dict(evaluations=0, contacts=0, longest=0, list_overflows=0, history_overflows=0, worst=0.0)
lanes_pass = forces.ContactPass.launch

def against_one_lane(self, state, finder):
    # The pass of one lane a particle on the same inputs, into arrays of its own; then the lanes' own.
    assert (self.lanes, self.particles) == (8, 4)
    m, h = self.model, state.history
    force, deepest = wp.clone(state.force), wp.clone(state.deepest_contact)
    torque, channels = wp.zeros_like(state.torque), wp.zeros_like(state.channels)
    one = pair_history(m.count, h.width, m.device)
    wp.launch_tiled(contact_pass(m.params.law, 1, 1, self.accumulate), dim=[m.count], block_dim=1,
                    inputs=[m.contact, m.ranges, m.radius, m.mass, *state.contact_inputs(), finder.candidate_count, finder.candidates],
                    outputs=[force, torque, channels, deepest, one], device=m.device)
    lanes_pass(self, state, finder)
    count, width = one.count.numpy(), h.width
    assert np.array_equal(h.current.count.numpy(), count)
    kept = np.arange(width)[None, :] < np.minimum(count, width)[:, None]
    for name in ("partner", "spring", "normal", "rolling", "twist"):  # the same rows, in the same order
        assert np.array_equal(getattr(h.current, name).numpy()[kept], getattr(one, name).numpy()[kept]), name
    assert np.array_equal(state.deepest_contact.numpy(), deepest.numpy())
    for got, want in ((state.force, force), (state.torque, torque), (state.channels, channels)):
        error = np.abs(got.numpy() - want.numpy()).max() / np.abs(want.numpy()).max()
        assert error <= 1e-13, error
        seen["worst"] = max(seen["worst"], error)
    noted = finder.candidate_count.numpy()
    listed = noted <= finder.candidates.shape[1]
    seen["evaluations"] += 1
    seen["contacts"] += int(count.sum())
    seen["longest"] = max(seen["longest"], int(noted[listed].max()))
    seen["list_overflows"] += int((~listed).sum())
    seen["history_overflows"] += int((count > width).sum())

# The shipped pile (lists of up to ~30) in a shear flow, its neighbour lists rebuilt every few steps;
# the Newton layout's and the tree's passes (gravity's force accumulated); a sphere touched by more
# than a list holds (its list and its rows overflow).
forces.ContactPass.launch = against_one_lane
pile = load_pile(builtin_pile("target"))
y = pile.positions[:, 1] - pile.positions[:, 1].mean()
flow = np.zeros_like(pile.velocities)
flow[:, 0] = contact_finders.SKIN_FRACTION * 7.5e5 * 0.3 * y / np.abs(y).max()
sheared = replace(pile, velocities=pile.velocities + flow)
contact_finders.SKIN_FRACTION *= 0.1
builds = 0
for options, steps in (({"scheme": dw.Scheme(gravity_every=5)}, 200), ({"layout": dw.Layout(1, 4, newton=True)}, 20),
                       ({"scheme": dw.Scheme(gravity="tree")}, 20)):
    sim = dw.Simulation(sheared, params, device="cpu", ledger=True, allow_unstable=True, **options)
    sim.step(steps)
    builds = max(builds, sim.neighbour_list_builds() or 0)
sim = dw.Simulation(crowded_sphere(CANDIDATES + 6), params, device="cpu", ledger=True, allow_unstable=True, scheme=dw.Scheme(gravity_every=3))
sim.step(30)
print("evaluations", seen["evaluations"], "contacts", seen["contacts"], "longest", seen["longest"], "list_overflows",
      seen["list_overflows"], "history_overflows", seen["history_overflows"], "builds", builds, "worst", seen["worst"])

# With the lanes alone: a resumed run and an ensemble's systems, bit for bit.
forces.ContactPass.launch = lanes_pass
contact_finders.SKIN_FRACTION *= 10.0
scheme = dw.Scheme(gravity_every=5)
def arrays(snapshot):
    # (A list's slots past its count hold whatever an earlier build or load left there, not the same
    # in an ensemble as alone, with one lane too; nothing reads them: compared up to the counts.)
    kept = np.arange(snapshot["neighbour_list"].shape[1])[None, :] < snapshot["neighbour_count"][:, None]
    listed = np.where(kept, snapshot["neighbour_list"], -1)
    return {key: listed if key == "neighbour_list" else value for key, value in snapshot.items() if isinstance(value, np.ndarray)}
def same(a, b):
    return a.keys() == b.keys() and all(np.array_equal(value, b[key]) for key, value in a.items())
straight, second = straight_and_resumed(sheared, params, 100, 40, scheme=scheme)
resumed = same(arrays(straight.snapshot()), arrays(second.snapshot()))
states = [contact_cluster(23, seed=0, speed=1e3), sheared, contact_cluster(31, seed=1, speed=1e3)]
members = [dw.Simulation(s, params, device="cpu", ledger=True, allow_unstable=True, scheme=scheme) for s in states]
for member in members:
    member.step(10)
alone = [dw.Simulation.from_snapshot(s, params, member.snapshot(), device="cpu", scheme=scheme) for s, member in zip(states, members)]
ensemble = Ensemble(members)
ensemble.step(60)
together = True
for view, sim in zip(ensemble.views, alone):
    sim.step(60)
    together &= same(arrays(view.snapshot()), arrays(sim.snapshot()))
print("resumed", resumed, "ensemble", together, "rows", int(straight.snapshot()["contact_count"].sum()))
"""


@pytest.fixture(scope="module")
def lanes_against_one_lane(tmp_path_factory):
    """LANES_AGAINST_ONE_LANE's two lines of verdicts (a fresh interpreter: Warp's CPU blocks on)."""
    import subprocess
    import sys
    from pathlib import Path

    cache, tests = str(tmp_path_factory.mktemp("lanes") / "cache"), str(Path(__file__).parent)
    done = subprocess.run([sys.executable, "-c", LANES_AGAINST_ONE_LANE, cache, tests], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
    lines = done.stdout.strip().splitlines()
    return [dict(zip(line.split()[::2], line.split()[1::2])) for line in lines[-2:]]


def test_the_contact_pass_s_lanes_keep_the_rows_of_one_lane(lanes_against_one_lane):
    """The contact pass with the GPU's lanes (8 a particle, 4 particles a block; Warp's CPU blocks), each
    evaluation checked against the pass of one lane a particle on the same inputs: every particle's
    contact count, and its rows (partners and springs) in the same order bit for bit; the deepest
    contact bit for bit; force, torque and the ledger's channels within 1e-13 of the largest (the lanes
    add a particle's contacts in another order: float64 rounding of ~30 terms, ~30 x 1.1e-16 of the
    largest contact, which these scenes' net forces are within a few times of; measured ~4e-16).  Over
    the neighbour lists of gravity on its own clock, rebuilt every few steps as a sheared pile's layers
    slide (lists of up to ~30: four rounds of the lanes), the Newton layout's and the tree's lists, and
    a sphere touched by more than a list or its rows hold (lane 0's walk over the system, the rows past
    their width counted as one lane counts them)."""
    seen = lanes_against_one_lane[0]
    assert int(seen["evaluations"]) > 250 and int(seen["contacts"]) > 100_000
    assert int(seen["longest"]) > 24  # four rounds of eight lanes
    assert int(seen["builds"]) >= 10  # the lists rebuilt, the springs carried by partner
    assert int(seen["list_overflows"]) > 0 and int(seen["history_overflows"]) > 0
    assert 0 < float(seen["worst"]) <= 1e-13  # the lanes did sum otherwise: they ran


def test_a_resumed_run_and_an_ensemble_with_the_contact_lanes_are_bit_for_bit(lanes_against_one_lane):
    """With the contact pass's lanes (Warp's CPU blocks, as on a GPU), gravity every 5 steps: a run
    resumed from a snapshot is the uninterrupted one, and each system of an ensemble (one of them the
    sheared pile, lists of ~30) the run alone, every array of the snapshot (springs included) bit for bit."""
    verdict = lanes_against_one_lane[1]
    assert verdict["resumed"] == "True" and verdict["ensemble"] == "True", verdict
    assert int(verdict["rows"]) > 600  # the pile's 300 grains held their contacts' springs through it


# --- conservation and the energy ledger -------------------------------------------------------------


def test_momentum_and_angular_momentum_are_conserved_to_round_off(device):
    """Each pair from its lower index, the same bits on either side: the contacts move no momentum or
    angular momentum (orbital and spin) out of the system; gravity on, float64, 1000 steps."""
    clump = contact_cluster(100, seed=7, overlap_range=(1.0, 1e3), speed=20.0, spin=1e-5)
    sim = dw.Simulation(clump, dw.Params(**SSDEM), device=device, precision="float64")
    sim.step(1000)
    p0, l0, p_scale, l_scale = _momenta(clump)
    p1, l1, _, _ = _momenta(sim.state)
    assert np.linalg.norm(p1 - p0) <= 1e-13 * p_scale
    assert np.linalg.norm(l1 - l0) <= 1e-13 * l_scale
    assert np.abs(sim.state.positions - clump.positions).max() > 1e3


def _books(sim):
    now = sim.diagnostics()
    ledger = energy_ledger(now, sim.energy_start, sim.work())
    return now, ledger, now["total_energy"] + sum(ledger.values())


def test_the_ledger_closes_with_the_springs_energy(device):
    clump = _clump(60, seed=5)
    sim = dw.Simulation(clump, dw.Params(**SSDEM), device=device, precision="float64", ledger=True)
    e0 = sim.energy_start["total_energy"]
    assert sim.energy_start["elastic_tangential"] > 0  # the first evaluation stretched the springs
    sim.step(600)
    now, ledger, balance = _books(sim)
    assert abs(balance - e0) <= 1e-10 * abs(e0)
    for channel in ("dissipated_sliding", "dissipated_rolling", "dissipated_hysteresis"):
        assert ledger[channel] > 0, channel
    assert now["elastic_tangential"] > 0 and now["elastic_rolling"] > 0


def test_a_sticking_contact_stores_its_tangential_work_and_dissipates_none(device):
    """Elastic, and sticking throughout (mu_s huge, no dashpots, no rolling): mid-contact the tangential
    force's work is held in the spring (elastic_tangential), not booked as dissipated; after the
    contact the spring is gone and the energy is back in motion."""
    state = _oblique_pair(theta_deg=30.0)
    params = _impact_params(state, restitution=1.0, eps_t=1.0, mu_s=1e6)
    sim = dw.Simulation(state, params, device=device, precision="float64", ledger=True)
    e0 = sim.energy_start["total_energy"]
    sim.step(25)  # about half the contact
    now, ledger, balance = _books(sim)
    assert now["elastic_tangential"] > 1e-3 * e0
    # The energy the tangential force took is the spring's, to the step's discretization (the whole of
    # it would be booked as dissipated without the spring's channel).
    sliding_work = -sim.work()[:, 2].sum()
    assert abs(sliding_work - now["elastic_tangential"]) <= 5e-3 * now["elastic_tangential"]
    assert abs(ledger["dissipated_sliding"]) <= 5e-3 * now["elastic_tangential"]
    assert abs(balance - e0) <= 1e-10 * e0
    sim.step(75)
    now, ledger, balance = _books(sim)
    assert now["number_of_contacts"] == 0 and now["elastic_tangential"] == 0.0
    assert abs(ledger["dissipated_sliding"]) <= 1e-3 * e0 and abs(balance - e0) <= 1e-10 * e0


def test_a_run_with_springs_records_their_energy_closes_its_books_and_resumes_bit_for_bit(tmp_path):
    """Through run.py, as decco-warp simulate and resume run it: the trajectory records the springs'
    energy beside the others, the books balance at every frame, and a run stopped halfway and resumed
    from its checkpoint (the contact history in it) is the uninterrupted run."""
    from helpers import assert_same_run

    from decco_warp import spec as specs
    from decco_warp.io import read_checkpoint
    from decco_warp.run import resume_run, start_run

    def spec(name, steps):
        run = {"name": name, "out": str(tmp_path), "device": "cpu", "steps": steps, "output_every": 50, "checkpoint_every": 100}
        return specs.resolve_spec({"run": run, "params": {"contact_law": "ssdem", "mu_t": 0.3}})

    start_run(spec("straight", 300))
    start_run(spec("parts", 150))
    resume_run(tmp_path / "parts", steps=300)
    frames = dw.read_trajectory(tmp_path / "straight" / "trajectory.h5")
    assert_same_run(frames, dw.read_trajectory(tmp_path / "parts" / "trajectory.h5"))
    a, _, _ = read_checkpoint(tmp_path / "straight" / "checkpoint.h5")
    b, _, _ = read_checkpoint(tmp_path / "parts" / "checkpoint.h5")
    assert a["contact_count"].sum() > 0
    for key, value in a.items():
        if isinstance(value, np.ndarray):
            assert np.array_equal(value, b[key]), key
    obs = frames["observables"]
    assert (obs["elastic_tangential"][1:] > 0).all() and (obs["elastic_rolling"][1:] > 0).all()
    books = obs["total_energy"] + obs["dissipated_sliding"] + obs["dissipated_rolling"] + obs["dissipated_hysteresis"] + obs["integration_error"]
    np.testing.assert_allclose(books, obs["total_energy"][0], rtol=1e-10)
    # The stress shares, by each measure, are of the recorded largest overlaps, whatever the law.
    from decco_warp.diagnostics import STRESS_SHARE_OBSERVABLES, stress_shares

    radii, classes, stress = frames["static"]["radius"], frames["static"]["species"], frames["particles"]["stress"]
    assert (stress[1:].max(axis=1) > 0).all()
    for name, measure in STRESS_SHARE_OBSERVABLES.items():
        shares = [stress_shares(stress[k], classes, obs[name].shape[1], radii, measure=measure) for k in range(len(stress))]
        np.testing.assert_array_equal(obs[name], shares, err_msg=name)


# --- benchmarks (Chung & Ooi 2011 style; analytic answers of docs/ssdem-design.md sect. 13) ----------


@pytest.mark.parametrize("restitution", [1.0, 0.9, 0.5])
def test_normal_impact_gives_the_restitution_asked_for(restitution):
    """Head on: the linear spring-dashpot's rebound is eps_n (Schwartz et al. 2012 eqs. 24-28, the force
    never clamped), its contact lasts pi / omega_1 and its deepest overlap is the damped oscillator's."""
    state = _oblique_pair(theta_deg=0.0, gap=2e-3)
    params = _impact_params(state, overlap=0.01, restitution=restitution)
    sim = dw.Simulation(state, params, device="cpu", precision="float64")
    inside, deepest = 0, 0.0
    for _ in range(400):
        sim.step(1)
        overlap = 2.0 - (sim.state.positions[1, 0] - sim.state.positions[0, 0])
        if overlap > 0:
            inside, deepest = inside + 1, max(deepest, overlap)
        elif inside:
            break
    v = sim.state.velocities
    rebound = (v[1, 0] - v[0, 0]) / 100.0
    reduced = state.masses[0] / 2
    k_n = params.k_n
    log = np.log(restitution)
    alpha = -log / np.sqrt(np.pi**2 + log**2) * np.sqrt(k_n / reduced)  # C_n / (2 mu)
    omega_1 = np.sqrt(k_n / reduced - alpha**2)
    assert rebound == pytest.approx(restitution, abs=0.006)
    assert abs(inside * params.dt - np.pi / omega_1) <= 2 * params.dt
    peak = np.arctan2(omega_1, alpha) / omega_1  # x(t) = (v0 / omega_1) exp(-alpha t) sin(omega_1 t)
    assert deepest == pytest.approx(100.0 / omega_1 * np.exp(-alpha * peak) * np.sin(omega_1 * peak), rel=0.01)


@pytest.mark.parametrize("theta_deg", [45.0, 60.0, 75.0])
def test_oblique_impact_in_gross_sliding_gives_the_rigid_impulse_answer(theta_deg):
    """Two equal spheres meeting at theta from their line of centres slide throughout when tan theta >
    3.5 mu_s (1 + e) (here 33.6 degrees): each sphere's tangential velocity falls to e_t = 1 - mu_s (1 +
    e) / tan theta of itself and it spins up to 2.5 mu_s (1 + e) v cos theta / R (docs/ssdem-design.md
    13.3).  pkdgrav's own slip rule (the spring zeroed) would give e_t ~0.94 at 50 degrees, not 0.84."""
    mu_s, e = 0.1, 0.9
    state = _oblique_pair(theta_deg=theta_deg)
    sim = dw.Simulation(state, _impact_params(state, restitution=e, mu_s=mu_s), device="cpu", precision="float64")
    sim.step(200)
    after = sim.state
    assert np.linalg.norm(after.positions[1] - after.positions[0]) > 2.0  # apart again
    t = np.radians(theta_deg)
    assert after.velocities[0, 1] / (50.0 * np.sin(t)) == pytest.approx(1 - mu_s * (1 + e) / np.tan(t), abs=0.003)
    assert -after.omegas[0, 2] == pytest.approx(2.5 * mu_s * (1 + e) * 50.0 * np.cos(t), rel=0.01)


def _sticking_restitution(params, reduced):
    """Schwartz et al. 2012 eq. 35: the contact point's tangential restitution of a sticking linear
    spring-dashpot over a normal contact; then each sphere's, 1 - (2/7)(1 - eps_t) (equal spheres)."""
    k_n, k_t = params.k_n, params.k_t
    log_n, log_t = np.log(params.restitution), np.log(params.eps_t)
    alpha_n = -log_n / np.sqrt(np.pi**2 + log_n**2) * np.sqrt(k_n / reduced)
    omega_n = np.sqrt(k_n / reduced - alpha_n**2)
    damping_t = -2 * log_t * np.sqrt(k_t * reduced / (np.pi**2 + log_t**2))
    alpha_t = 7 * damping_t / (4 * reduced)
    omega_t = np.sqrt(7 * k_t / (2 * reduced) - alpha_t**2)
    contact = np.exp(-alpha_t * np.pi / omega_n) * (np.cos(np.pi * omega_t / omega_n) - alpha_t / omega_t * np.sin(np.pi * omega_t / omega_n))
    return 1 - 2 / 7 * (1 - contact)


@pytest.mark.parametrize("eps_t", [1.0, 0.5])
@pytest.mark.parametrize("theta_deg", [5.0, 20.0])
def test_oblique_impact_while_sticking_gives_the_tangential_spring_s_answer(theta_deg, eps_t):
    """mu_s huge: the tangential spring stretches and gives back (with its dashpot), so that the contact
    point's tangential velocity reverses: each sphere keeps 0.43 of its tangential velocity at eps_t 1
    (eq. 35), where a rigid sticking contact (no spring) keeps 5/7; its spin is 5/2 of the tangential
    velocity lost over R (angular momentum about the contact point)."""
    state = _oblique_pair(theta_deg=theta_deg)
    params = _impact_params(state, restitution=0.9, mu_s=1e6, eps_t=eps_t)
    sim = dw.Simulation(state, params, device="cpu", precision="float64")
    sim.step(200)
    after = sim.state
    v_t = 50.0 * np.sin(np.radians(theta_deg))
    e_t = after.velocities[0, 1] / v_t
    assert e_t == pytest.approx(_sticking_restitution(params, state.masses[0] / 2), abs=0.004)
    assert -after.omegas[0, 2] == pytest.approx(2.5 * (1 - e_t) * v_t, rel=0.01)


def _sphere_on_two_spheres(spacing=1.2):
    """A sphere on two others that rest on a floor (a sphere of 1e3 cm under a field of g = 1e3 cm/s^2 at
    its surface), all of radius 1 cm, the bottom centres 2 ``spacing`` cm apart (not touching); nothing
    overlaps yet."""
    radius, floor, g = 1.0, 1000.0, 1000.0
    planet_mass = g * floor**2 / dw.G_CGS
    height = np.sqrt(4 * radius**2 - spacing**2)
    x = np.array([[0, 0, 0], [-spacing, 0, floor + radius], [spacing, 0, floor + radius], [0, 0, floor + radius + height]])
    radii = np.array([floor, radius, radius, radius])
    masses = np.array([planet_mass, *sphere_mass(radii[1:])])
    return dw.State.from_arrays(x, np.zeros((4, 3)), np.zeros((4, 3)), radii, masses), g


def test_a_sphere_on_two_spheres_stands_by_static_friction_and_falls_without():
    """The bottom spheres, free to roll and slide on the floor, are pushed apart by the top one: with no
    rolling resistance the three stand iff mu_s >= tan(alpha / 2) = 1/3 here (docs/ssdem-design.md 13.5).
    At mu_s = 0.45 they stand still, the springs holding; at 0.25 and 0 they fall apart.  The paper's
    law, with no spring, creeps apart at mu_k = 0.45."""
    state, g = _sphere_on_two_spheres()
    m = state.masses[1]
    k_n = 1.5 * m * g / 0.01  # a bottom sphere's floor contact 0.01 cm deep
    dt = np.pi * np.sqrt(m / 2 / k_n) / 50

    def heights(mu, law="ssdem"):
        params = dw.Params(contact_law=law, k_in=2 * k_n, restitution=0.3, dt=dt, mu_s=mu, mu_k=mu, mu_r=0.0)
        sim = dw.Simulation(state, params, device="cpu", precision="float64")
        out = []
        for _ in range(4):
            sim.step(1000)
            x = sim.state.positions
            out.append((x[3, 2] - state.positions[3, 2], x[2, 0] - x[1, 0] - 2.4))  # top's drop, bottoms' spread
        return np.array(out)

    standing = heights(0.45)
    assert np.abs(standing[0]).max() < 0.03  # settled into its contacts (~1 % of a radius)
    assert np.abs(standing[-1] - standing[0]).max() < 2e-3  # and stays
    for mu in (0.25, 0.0):
        falling = heights(mu)
        assert falling[1, 0] < -1.0 and falling[-1, 1] > 2.0, mu  # the top fell between the bottoms
    creeping = heights(0.45, law="paper")
    assert creeping[-1, 1] - creeping[0, 1] > 0.03  # slides on, slowly, with no static friction


@pytest.mark.parametrize("mu_t", [0.5, 0.25, 0.0])
def test_a_twisting_contact_s_relative_spin_decays_at_the_rate_mu_t_sets(mu_t):
    """Two spheres held together by their gravity, one spinning about the line of centres: the twisting
    couple slides at mu_t mu_s R_r N (pkdgrav's cap, R_r = beta R*), so that their relative spin falls
    at mu_t mu_s R_r N (1/I_1 + 1/I_2) until the twisting spring holds (none without mu_t)."""
    from scipy.optimize import brentq

    radius, normal, k_n, mu_s, beta = 1.0, 1e4, 1e6, 0.5, 0.5
    m = float(sphere_mass(radius))
    G = normal * (2 * radius) ** 2 / m**2
    d = brentq(lambda d: k_n * (2 * radius - d) - G * m * m / d**2, 2 * radius - 0.1, 2 * radius)  # at rest: spring = gravity
    dt = np.pi * np.sqrt(m / 2 / k_n) / 50
    params = dw.Params(contact_law="ssdem", k_in=2 * k_n, restitution=0.5, dt=dt, G=G, mu_s=mu_s, mu_t=mu_t, beta=beta, mu_r=0.1)
    x = np.array([[-d / 2, 0, 0], [d / 2, 0, 0]])
    w = np.array([[10.0, 0, 0], [0, 0, 0]])
    state = dw.State.from_arrays(x, np.zeros((2, 3)), w, np.full(2, radius), np.full(2, m))
    sim = dw.Simulation(state, params, device="cpu", precision="float64", allow_unstable=True)
    relative = []
    for _ in range(100):
        sim.step(1)
        relative.append(sim.state.omegas[0, 0] - sim.state.omegas[1, 0])
    inertia = 0.4 * m * radius**2
    rate = mu_t * mu_s * beta * radius / 2 * k_n * (2 * radius - d) * 2 / inertia
    slope = np.polyfit(dt * np.arange(10, 100), relative[10:], 1)[0]
    if mu_t == 0:
        assert np.all(np.array(relative) == 10.0)
    else:
        assert -slope == pytest.approx(rate, rel=0.01)
    assert np.abs(sim.state.velocities).max() < 1e-9  # the pure twist moves nothing else


# --- cohesion ----------------------------------------------------------------------------------------


def test_motion_with_cohesion_matches_the_oracle():
    """Cohesion (a pull of c 4 R_r^2 while touching, outside the caps) in the clumps of the oracle test."""
    state = approaching_clumps()
    params = dw.Params(**SSDEM, G=0.0, cohesion=3e8)  # ~1e20 dyne a contact: as strong as the springs
    sim = dw.Simulation(state, params, device="cpu", precision="float64")
    sim.step(150)
    x, v, w, springs = ssdem_run(*_oracle_args(state), ssdem_constants(params), 0.0, 150)
    assert np.abs(sim.state.positions - x).max() <= 1e-9
    assert np.abs(sim.state.velocities - v).max() <= FLOAT64_TOLERANCE * np.abs(v).max()
    without = dw.Simulation(state, dw.Params(**SSDEM, G=0.0), device="cpu", precision="float64")
    without.step(150)
    assert np.abs(without.state.positions - x).max() > 10.0  # cohesion changed the motion


@pytest.mark.parametrize("times_escape", [0.8, 1.25, 1.5])
def test_a_cohesive_pair_parts_only_above_its_escape_speed(times_escape):
    """Two spheres at the cohesive pair's equilibrium (k_n x = F_c), elastic, drawn apart at f times the
    speed that climbs the well's depth F_c^2 / (2 k_n): below it they never part, above it they
    leave at sqrt(f^2 - 1) of it (energy; within 2 %, the force's step at parting costing ~F_c v dt).
    The ledger keeps the well's energy: bound, nothing is booked as dissipated."""
    radius, k_n, beta, depth = 1.0, 1e6, 0.5, 0.005
    m = float(sphere_mass(radius))
    reduced = m / 2
    pull = k_n * depth
    escape = pull / np.sqrt(reduced * k_n)
    params = dw.Params(contact_law="ssdem", k_in=2 * k_n, restitution=1.0, dt=np.pi * np.sqrt(reduced / k_n) / 200, G=0.0,
                       beta=beta, cohesion=pull / (4 * (beta * radius / 2) ** 2))  # fmt: skip
    d = 2 * radius - depth
    speed = times_escape * escape
    state = dw.State.from_arrays(np.array([[-d / 2, 0, 0], [d / 2, 0, 0]]), np.array([[-speed / 2, 0, 0], [speed / 2, 0, 0]]),
                                 np.zeros((2, 3)), np.full(2, radius), np.full(2, m))  # fmt: skip
    sim = dw.Simulation(state, params, device="cpu", precision="float64", ledger=True)
    assert sim.energy_start["elastic"] == pytest.approx(-(pull**2) / (2 * k_n), rel=1e-9)  # the well: k_n x^2 / 2 - F_c x
    gap = []
    for _ in range(40):
        sim.step(50)
        gap.append(sim.state.positions[1, 0] - sim.state.positions[0, 0] - 2 * radius)
    parting = sim.state.velocities[1, 0] - sim.state.velocities[0, 0]
    if times_escape < 1:
        assert max(gap) <= 0
        ledger = energy_ledger(sim.diagnostics(), sim.energy_start, sim.work())
        assert abs(ledger["dissipated_hysteresis"]) <= 1e-6 * pull**2 / (2 * k_n)
    else:
        assert gap[-1] > 0.1
        assert parting == pytest.approx(np.sqrt(times_escape**2 - 1) * escape, rel=0.02 if times_escape < 1.4 else 0.005)


# --- the law's constants ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "constants, message",
    [
        ({"mu_s": -0.1}, "mu_s must be >= 0; got -0.1"),
        ({"mu_t": -1.0}, "mu_t must be >= 0; got -1.0"),
        ({"eps_t": 0.0}, "eps_t must be in (0, 1]; got 0.0"),
        ({"beta": -0.5}, "beta must be >= 0 [R_r / R*]; got -0.5"),
        ({"k_t_ratio": float("nan")}, "k_t_ratio must be >= 0 [k_t / k_n]; got nan"),
        ({"cohesion": -1.0}, "cohesion must be >= 0 [dyne/cm^2]; got -1.0"),
        ({"rolling_friction": "paper"}, "contact_law 'ssdem' has its own"),
    ],
)
def test_the_law_s_constants_are_checked_with_one_line(constants, message):
    with pytest.raises(InputError) as raised:
        dw.Params(contact_law="ssdem", **constants)
    assert str(raised.value) == message or message in str(raised.value)
    assert "\n" not in str(raised.value)


def test_the_law_s_stiffnesses_follow_k_in():
    params = dw.Params(contact_law="ssdem", k_in=3e17, k_t_ratio=0.5)
    assert params.k_n == 1.5e17 and params.k_t == 0.75e17 and params.keeps_springs
    assert dw.Params().k_t == pytest.approx(2 / 7 * 5e17) and not dw.Params().keeps_springs


@pytest.mark.skipif(len(DEVICES) < 2, reason="no CUDA device")
def test_cuda_keeps_the_springs_as_the_cpu_does():
    """One kernel source: 60 steps on CUDA equal the CPU's to round-off, with the same contacts."""
    state = _clump()
    params = dw.Params(**SSDEM)
    runs = []
    for device in ("cpu", DEVICES[1]):
        sim = dw.Simulation(state, params, device=device, precision="float64")
        sim.step(60)
        runs.append((sim.state, sim.snapshot()))
    (a, snap_a), (b, snap_b) = runs
    assert np.abs(a.positions - b.positions).max() <= 1e-12 * np.abs(a.positions - state.positions).max()
    assert np.array_equal(snap_a["contact_count"], snap_b["contact_count"])

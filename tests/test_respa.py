"""Gravity on its own clock (Scheme.gravity_every = K > 1, docs/model.md): impulse multiple time
stepping against a float64 NumPy RESPA step, the neighbour list that feeds the contacts, the energy
ledger, bit-exact restarts and ensembles."""

import math
import re
from dataclasses import replace

import numpy as np
import pytest
from helpers import assert_fused_steps_equal_one_step_at_a_time, straight_and_resumed
from oracle import pair_loop_forces
from scenes import contact_cluster

import decco_warp as dw
from decco_warp.diagnostics import energy_ledger
from decco_warp.contact_finders import SKIN_FRACTION

#: One outer step against NumPy, as a fraction of the largest change of each quantity over the
#: step: float64 to round-off; mixed within float32 gravity's error (measured ~1e-8 in velocity).
RESPA_FLOAT64_TOLERANCE = 1e-10
RESPA_MIXED_TOLERANCE = 1e-6
#: Ledger closure: the books balance to round-off of float64 sums, as with K = 1 (tests/test_ledger.py).
CLOSURE_TOLERANCE = 1e-10


def _oracle_forces(x, v, w, state, params, gravity: bool):
    """tests/oracle.py's forces, gravity alone (contacts off: k_in = 0) or the contacts alone (G = 0)."""
    args = (x, v, w, state.radii, state.masses)
    if gravity:
        return pair_loop_forces(*args, 0.0, params.restitution, 0.0, 0.0, params.G)[:2]
    return pair_loop_forces(*args, params.k_in, params.restitution, params.mu_k, params.mu_r, 0.0, rolling=params.rolling_friction)[:2]


def _numpy_respa_step(state, params, every):
    """One outer step in float64 NumPy, written from docs/model.md: a gravity half kick of K dt / 2,
    K kick-drift-kick steps of the contacts alone (forces at the new positions with the half-step
    velocities), gravity at the new positions, the second gravity half kick."""
    x, v, w = state.positions.copy(), state.velocities.copy(), state.omegas.copy()
    m, inertia, dt = state.masses[:, None], state.inertia[:, None], params.dt
    contact, couple = _oracle_forces(x, v, w, state, params, gravity=False)
    v = v + _oracle_forces(x, v, w, state, params, gravity=True)[0] / m * (every * dt / 2)
    for _ in range(every):
        v, w = v + contact / m * (dt / 2), w + couple / inertia * (dt / 2)
        x = x + v * dt
        contact, couple = _oracle_forces(x, v, w, state, params, gravity=False)
        v, w = v + contact / m * (dt / 2), w + couple / inertia * (dt / 2)
    v = v + _oracle_forces(x, v, w, state, params, gravity=True)[0] / m * (every * dt / 2)
    return x, v, w


def _relative_errors(got, want, start):
    """Per quantity: the largest error as a fraction of the largest change over the step."""
    return [np.abs(g - w).max() / np.abs(w - s).max() for g, w, s in zip(got, want, start)]


@pytest.mark.parametrize(("precision", "tolerance"), [("float64", RESPA_FLOAT64_TOLERANCE), ("mixed", RESPA_MIXED_TOLERANCE)])
def test_one_outer_step_equals_a_numpy_respa_step(precision, tolerance):
    """A contact clump whose gravity is as strong as its contacts (~1e20 dyne each): after one outer
    step of K = 5, positions, velocities and spins equal the NumPy RESPA step's; K plain velocity
    Verlet steps (gravity every step) differ from it ~1e5 times more in float64."""
    state = contact_cluster(40, seed=4, overlap_range=(1.0, 1e2), speed=1e3, spin=1e-3)
    every = 5
    params = dw.Params()
    contact = _oracle_forces(state.positions, state.velocities, state.omegas, state, params, gravity=False)[0]
    gravity = _oracle_forces(state.positions, state.velocities, state.omegas, state, params, gravity=True)[0]
    assert 0.1 < np.abs(gravity).max() / np.abs(contact).max() < 10
    want = _numpy_respa_step(state, params, every)
    sim = dw.Simulation(state, params, device="cpu", precision=precision, scheme=dw.Scheme(gravity_every=every))
    sim.step(every)
    after = sim.state
    start = (state.positions, state.velocities, state.omegas)
    errors = _relative_errors((after.positions, after.velocities, after.omegas), want, start)
    assert max(errors) <= tolerance, errors
    if precision == "float64":
        verlet = state
        for _ in range(every):
            verlet = replace(verlet, **dict(zip(("positions", "velocities", "omegas"), _numpy_respa_step(verlet, params, 1))))
        apart = _relative_errors((verlet.positions, verlet.velocities, verlet.omegas), want, start)
        assert min(apart[1:]) > 1e4 * tolerance, apart


def _fast_clump(n=80, seed=7):
    """A contact clump whose particles move fast against the skin (of the paper's smallest radius,
    7.5e5 cm): ~1/3 of it a second, 1/75 a step (dt = 0.04 s), past half the skin in a few tens of
    steps, so that the neighbour list is rebuilt again and again."""
    return contact_cluster(n, seed=seed, overlap_range=(1.0, 1e3), speed=SKIN_FRACTION * 7.5e5 / 3, spin=1e-3)


def _touching_pairs(positions, radii):
    r = positions[:, None, :] - positions[None, :, :]
    distance = np.sqrt((r**2).sum(axis=-1))
    np.fill_diagonal(distance, np.inf)
    return distance, radii[:, None] + radii[None, :]


def test_the_neighbour_list_holds_every_touching_pair_and_is_rebuilt_past_half_the_skin():
    """Stepped two steps at a time: every particle stays within skin / 2 of its position at the
    list's last build (the rebuild rule), each list is in increasing j and is exactly the pairs
    within R_i + R_j + skin at that build, so it holds every pair that touches now (NumPy, all
    pairs); the list is rebuilt as the particles travel, and kept while nothing moves far."""
    state = _fast_clump()
    sim = dw.Simulation(state, dw.Params(), device="cpu", allow_unstable=True, scheme=dw.Scheme(gravity_every=2))
    neighbours = sim.engine.path.finder
    skin = SKIN_FRACTION * state.radii.min()
    assert neighbours.skin == skin
    builds = [sim.neighbour_list_builds()]
    touched = 0
    for _ in range(40):
        sim.step(2)
        positions = sim.state.positions
        reference = neighbours.reference.numpy()
        assert np.linalg.norm(positions - reference, axis=1).max() <= skin / 2
        counts, lists = sim.engine.candidate_count.numpy(), sim.engine.candidates.numpy()
        assert counts.max() <= lists.shape[1]
        at_build, reach = _touching_pairs(reference, state.radii)
        now, contact = _touching_pairs(positions, state.radii)
        for i in range(state.n):
            row = lists[i, : counts[i]]
            assert np.all(np.diff(row) > 0)
            near = np.flatnonzero(at_build[i] < reach[i] + skin)
            # Pairs at the reach to within its margin may fall either way.
            edge = np.flatnonzero(np.abs(at_build[i] - reach[i] - skin) < 1e-6 * (reach[i] + skin))
            assert set(near) - set(edge) <= set(row) <= set(near) | set(edge)
            touching = np.flatnonzero(now[i] < contact[i])
            assert set(touching) <= set(row)
            touched += len(touching)
        builds.append(sim.neighbour_list_builds())
    travelled = np.linalg.norm(sim.state.positions - state.positions, axis=1).max()
    assert touched > state.n and travelled > 2 * skin  # contacts all along, and particles far travelled
    assert builds[0] == 1 and builds[-1] >= travelled / (skin / 2) / 2 and builds[-1] < 80
    # A clump at rest lists once and keeps its list.
    slow = dw.Simulation(replace(state, velocities=state.velocities * 1e-4), dw.Params(G=0.0), device="cpu", allow_unstable=True, scheme=dw.Scheme(gravity_every=2))
    slow.step(40)
    assert slow.neighbour_list_builds() == 1


def _sheared_pile(seed):
    """The shipped pile (lists of up to ~30 neighbours) in a shear flow: its layers slide past each
    other, so that its lists are rebuilt every few steps."""
    from decco_warp.io import load_pile
    from decco_warp.plan import builtin_pile

    pile = load_pile(builtin_pile("target"))
    y = pile.positions[:, 1] - pile.positions[:, 1].mean()
    flow = np.zeros_like(pile.velocities)
    flow[:, 0] = SKIN_FRACTION * 7.5e5 * (0.2 + 0.1 * (seed % 3)) * y / np.abs(y).max()
    return replace(pile, velocities=pile.velocities + flow)


def _list_build_scenes():
    """name: (state, systems): a fast clump (rebuilt again and again), the sheared pile (long lists),
    a sphere crowded past its list's width (an overflow), and the three as an ensemble, whose systems
    go stale at different steps (builds of some systems' lists only)."""
    from decco_warp.kernels.contacts import CANDIDATES
    from scenes import crowded_sphere

    parts = [_fast_clump(37, seed=0), _sheared_pile(1), crowded_sphere(CANDIDATES + 6)]
    joined = dw.State.from_arrays(*[np.concatenate([getattr(s, name) for s in parts])
                                    for name in ("positions", "velocities", "omegas", "radii", "masses")])  # fmt: skip
    return {"clump": (parts[0], None), "sheared": (parts[1], None), "crowded": (parts[2], None), "ensemble": (joined, [s.n for s in parts])}


@pytest.mark.parametrize("scene", ["clump", "sheared", "crowded", "ensemble"])
def test_a_list_build_by_cell_lists_what_a_build_by_particle_lists(scene, device, monkeypatch):
    """NeighbourList.scan "by cell" (a GPU's default: a thread per particle and cell, then each row put
    in order) and "by particle" (the CPU's: a thread per particle walking its 27 cells) build the same lists: after
    100 steps of K = 5, with lists rebuilt along the way (in the ensemble, some systems' alone), the
    whole candidate array (columns past a row's count too, and an overflowing row's first ``width``
    met), the counts, the positions of the builds and every array of the state are bit for bit the same."""
    from decco_warp import contact_finders

    state, systems = _list_build_scenes()[scene]
    ends = {}
    for scan in ("by particle", "by cell"):
        monkeypatch.setattr(contact_finders.NeighbourList, "scan", scan)
        sim = dw.Simulation(state, dw.Params(), device=device, ledger=True, allow_unstable=True, systems=systems, scheme=dw.Scheme(gravity_every=5))
        builds = [sim.neighbour_list_builds(k) for k in range(len(systems or [0]))]
        sim.step(100)
        finder = sim.engine.path.finder
        assert finder.scan == scan
        ends[scan] = (sim.snapshot(), finder.candidates.numpy().copy(), [sim.neighbour_list_builds(k) - b for k, b in enumerate(builds)])
    (want, want_rows, want_builds), (got, got_rows, got_builds) = ends["by particle"], ends["by cell"]
    assert np.array_equal(got_rows, want_rows)
    for key, values in want.items():
        if isinstance(values, np.ndarray):
            assert np.array_equal(got[key], values), key
    assert got_builds == want_builds and max(want_builds) >= 1
    if scene == "crowded":
        assert sim.candidate_overflows() >= 1
    if scene == "ensemble":
        assert len(set(want_builds)) > 1  # some builds listed some systems alone


@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_forces_on_two_clocks_are_gravity_plus_the_listed_contacts_even_past_a_full_list(precision):
    """A 22.5 km sphere touched by more small ones than a list holds: its list overflows (counted,
    and its whole system walked), and the force at the start (gravity into its own array plus the
    contacts from the list) equals the plain loop's, as the torque does."""
    from decco_warp.engine import Engine
    from decco_warp.kernels.contacts import CANDIDATES
    from scenes import crowded_sphere

    count = CANDIDATES + 6
    state = crowded_sphere(count)
    engine = Engine(state, dw.Params(), "cpu", precision, scheme=dw.Scheme(gravity_every=3))
    engine.eval_forces()
    assert engine.candidate_overflows() >= 1
    want = dw.compute_forces(state, dw.Params(), device="cpu", precision="float64", force_kernel="reference")
    tolerance = 1e-12 if precision == "float64" else 1e-5
    for got, expected in zip(engine.read_forces(), want):
        np.testing.assert_allclose(got, expected, rtol=0, atol=tolerance * np.abs(expected).max())


def _books(sim):
    now = sim.diagnostics()
    ledger = energy_ledger(now, sim.energy_start, sim.work())
    return ledger, now["total_energy"] + sum(ledger.values())


@pytest.mark.parametrize("gravity", ["all-pairs", "tree"])
@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_the_ledger_closes_with_gravity_booked_at_the_outer_kicks(precision, gravity):
    """K = 10 on a dissipative clump: the books balance to round-off (gravity's work booked at the
    outer kicks as the exact kinetic-energy change of each, the contact channels at the inner ones),
    every dissipation channel counts, and gravity did work."""
    clump = contact_cluster(100, seed=3, overlap_range=(1.0, 1e3), speed=20.0, spin=1e-4)
    sim = dw.Simulation(clump, dw.Params(), device="cpu", precision=precision, ledger=True, scheme=dw.Scheme(gravity_every=10, gravity=gravity))
    sim.step(1000)
    ledger, balance = _books(sim)
    start = sim.energy_start["total_energy"]
    assert abs(balance - start) <= CLOSURE_TOLERANCE * abs(start)
    for channel in ("dissipated_sliding", "dissipated_rolling", "dissipated_hysteresis"):
        assert ledger[channel] > 0, channel
    assert abs(sim.work()[:, 0]).max() > 0


def test_elastic_frictionless_clump_dissipates_nothing_on_two_clocks():
    """Restitution 1, no friction, K = 5: nothing is dissipated, and what the books call the
    integration error stays tiny against the kinetic energy exchanged."""
    clump = contact_cluster(100, seed=3, overlap_range=(1.0, 1e3), speed=20.0)
    sim = dw.Simulation(clump, dw.Params(restitution=1.0, mu_k=0.0, mu_r=0.0), device="cpu", precision="float64", ledger=True, scheme=dw.Scheme(gravity_every=5))
    sim.step(1000)
    ledger, balance = _books(sim)
    kinetic = sim.diagnostics()["kinetic_translational"]
    assert abs(balance - sim.energy_start["total_energy"]) <= CLOSURE_TOLERANCE * abs(sim.energy_start["total_energy"])
    assert ledger["dissipated_sliding"] == 0.0 and ledger["dissipated_rolling"] == 0.0
    assert abs(ledger["dissipated_hysteresis"]) < 1e-4 * kinetic and abs(ledger["integration_error"]) < 1e-4 * kinetic


@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_a_restart_from_a_snapshot_is_bit_identical(precision, device):
    """Stopped at step 60 and restored (gravity evaluated anew at the restored positions, the
    neighbour lists and the positions of their build from the snapshot), then stepped to 150: every
    array the next step depends on, bit for bit."""
    clump, params, scheme = _fast_clump(), dw.Params(), dw.Scheme(gravity_every=5)
    straight, second = straight_and_resumed(clump, params, 150, 60, device=device, precision=precision, scheme=scheme)
    a, b = straight.snapshot(), second.snapshot()
    for key in ("positions", "velocities", "omegas", "force", "torque", "channels", "work", "deepest_contact"):
        assert np.array_equal(a[key], b[key]), key
    assert straight.time == second.time and second.step_count == 150
    assert straight.neighbour_list_builds() > 2  # lists were rebuilt, at other steps in the two


def test_a_snapshot_without_neighbour_lists_restarts_with_lists_built_afresh():
    """A checkpoint of decco-warp 0.2 holds no neighbour lists: the restart builds them at the
    restored positions and steps on (the lists hold every touching pair)."""
    from decco_warp.contact_finders import NEIGHBOUR_ARRAYS

    clump, params, scheme = _fast_clump(), dw.Params(), dw.Scheme(gravity_every=5)
    first = dw.Simulation(clump, params, device="cpu", ledger=True, allow_unstable=True, scheme=scheme)
    first.step(60)
    snap = first.snapshot()
    assert all(key in snap for key in NEIGHBOUR_ARRAYS)
    old = {key: value for key, value in snap.items() if key not in NEIGHBOUR_ARRAYS}
    second = dw.Simulation.from_snapshot(clump, params, old, device="cpu", scheme=scheme)
    reference = second.engine.path.finder.reference.numpy()
    assert np.array_equal(reference, snap["positions"])  # built at the restored positions
    second.step(20)
    distance, reach = _touching_pairs(second.state.positions, clump.radii)
    count, listed = second.engine.candidate_count.numpy(), second.engine.candidates.numpy()
    for i, j in zip(*np.nonzero(distance < reach)):
        assert j in listed[i, : count[i]]


@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_steps_sharing_launches_equal_the_launches_of_an_outer_step(precision):
    """Engine.advance (the kicks closing and opening outer and inner steps, the drift, the packing
    and the displacement check in one launch per inner step) equals Engine.step's launches one after
    another, bit for bit, also over recorded graphs (blocks of 50 steps)."""
    every = 5
    state = _fast_clump(40, seed=6)

    def make():
        return dw.Simulation(state, dw.Params(), device="cpu", precision=precision, ledger=True, allow_unstable=True, scheme=dw.Scheme(gravity_every=every))

    assert_fused_steps_equal_one_step_at_a_time(make, pieces=(every, 0, 10 * every + every))


def test_an_ensemble_on_two_clocks_moves_each_system_as_alone(device):
    """Three clumps centred on the same point (the neighbour list's hash grid groups each system
    apart) stepped together at K = 4: each moves bit for bit as it would alone."""
    sizes = (37, 64, 23)
    states = [_fast_clump(n, seed=seed) for seed, n in enumerate(sizes)]
    joined = dw.State.from_arrays(*[np.concatenate([getattr(s, name) for s in states])
                                    for name in ("positions", "velocities", "omegas", "radii", "masses")])  # fmt: skip
    params, scheme = dw.Params(), dw.Scheme(gravity_every=4)
    ensemble = dw.Simulation(joined, params, device=device, systems=sizes, ledger=True, allow_unstable=True, scheme=scheme)
    ensemble.step(60)
    cuts = np.cumsum((0, *sizes))
    force, torque = ensemble.forces()
    for k, state in enumerate(states):
        alone = dw.Simulation(state, params, device=device, ledger=True, allow_unstable=True, scheme=scheme)
        alone.step(60)
        part = slice(cuts[k], cuts[k + 1])
        assert np.array_equal(ensemble.state.positions[part], alone.state.positions)
        assert np.array_equal(ensemble.state.velocities[part], alone.state.velocities)
        assert np.array_equal(ensemble.work()[part], alone.work())
        own_force, own_torque = alone.forces()
        assert np.array_equal(force[part], own_force) and np.array_equal(torque[part], own_torque)


def test_bad_clocks_are_refused_with_one_line():
    state = contact_cluster(10, seed=1)
    for bad in (0, -1, 2.5, "x", True, None):
        with pytest.raises(ValueError, match="gravity_every must be an integer >= 1") as error:
            dw.Scheme(gravity_every=bad)
        assert "\n" not in str(error.value)
    sim = dw.Simulation(state, dw.Params(), device="cpu", scheme=dw.Scheme(gravity_every=5))
    with pytest.raises(ValueError, match="with gravity_every = 5 the step count must be a multiple of 5.*got 7"):
        sim.step(7)
    assert sim.step_count == 0
    with pytest.raises(ValueError, match="reference kernel .* gravity_every = 1 only"):
        dw.Simulation(state, dw.Params(), device="cpu", force_kernel="reference", scheme=dw.Scheme(gravity_every=5))
    # Observables of one state do not depend on the clock: diagnostics take any K.
    clocked, plain = dw.Simulation(state, dw.Params(), device="cpu", scheme=dw.Scheme(gravity_every=5)).diagnostics(), dw.diagnostics(state, dw.Params())
    for key, value in plain.items():
        assert np.array_equal(clocked[key], value), key


# --- runs: the specification, run folders, resume ------------------------------------------------


def _spec(tmp_path, name, params=None, **run):
    from decco_warp import spec as specs

    values = {"name": name, "out": str(tmp_path), "device": "cpu", "steps": 300, "output_every": 100, "checkpoint_every": 100, **run}
    values = {key: value for key, value in values.items() if value is not None}  # None: not given
    return specs.resolve_spec({"run": values, "params": {"gravity_every": 5, **(params or {})}})


def test_a_run_on_two_clocks_records_its_clock_and_resumes_bit_identically(tmp_path):
    """The shipped collision at gravity_every = 5: spec.toml and the trajectory's parameters record
    it, run.log says it, and a run stopped at step 200 and resumed (its neighbour lists from the
    checkpoint, gravity evaluated anew) writes the frames and checkpoint of a run never stopped."""
    from helpers import assert_same_run

    from decco_warp import spec as specs
    from decco_warp.io import read_checkpoint
    from decco_warp.run import prepare_resume, resume_run, start_run

    straight = start_run(_spec(tmp_path, "straight"))
    start_run(_spec(tmp_path, "parts", steps=200))
    resume_run(tmp_path / "parts", steps=300)
    a, b = dw.read_trajectory(straight.run_dir / "trajectory.h5"), dw.read_trajectory(tmp_path / "parts" / "trajectory.h5")
    assert_same_run(a, b)
    for key, values in read_checkpoint(straight.run_dir / "checkpoint.h5")[0].items():
        if isinstance(values, np.ndarray):
            assert np.array_equal(read_checkpoint(tmp_path / "parts" / "checkpoint.h5")[0][key], values), key
    assert specs.load_spec_file(tmp_path / "parts" / "spec.toml")["params"]["gravity_every"] == 5
    assert a["parameters"]["spec"]["params"]["gravity_every"] == 5
    log = (straight.run_dir / "run.log").read_text()
    assert "gravity every 5 steps" in log and re.search(r"neighbour list built \d+ times in 300 steps", log)
    books = sum(a["observables"][k] for k in ("total_energy", "dissipated_sliding", "dissipated_rolling", "dissipated_hysteresis", "integration_error"))
    np.testing.assert_allclose(books, a["observables"]["total_energy"][0], rtol=CLOSURE_TOLERANCE)
    with pytest.raises(specs.SpecError, match=r"\[run\] steps = 333: with \[params\] gravity_every = 5"):
        prepare_resume(tmp_path / "parts", steps=333)


@pytest.mark.parametrize(
    ("params", "run", "message"),
    [
        ({"gravity_every": 0}, {}, r"\[params\] gravity_every = 0: must be an integer >= 1"),
        ({"gravity_every": -1}, {}, r"\[params\] gravity_every = -1: must be an integer >= 1"),
        ({"gravity_every": 2.5}, {}, r"\[params\] gravity_every = 2.5: must be int an integer >= 1"),
        ({"gravity_every": "x"}, {}, r"\[params\] gravity_every = 'x': must be int an integer >= 1"),
        ({"gravity_every": True}, {}, r"\[params\] gravity_every = True: must be int an integer >= 1"),
        ({}, {"steps": 302}, r"\[run\] steps = 302: with \[params\] gravity_every = 5, steps, output_every and checkpoint_every must be multiples of 5"),
        ({}, {"output_every": 7, "checkpoint_every": 12}, r"\[run\] output_every = 7, checkpoint_every = 12: with \[params\] gravity_every = 5"),
    ],
)
def test_a_bad_clock_in_a_specification_is_one_clear_line(tmp_path, params, run, message):
    from decco_warp import spec as specs

    with pytest.raises(specs.SpecError, match=message) as error:
        _spec(tmp_path, "bad", params, **run)
    assert "\n" not in str(error.value)


def test_auto_gravity_every_is_the_k_of_the_equivalence_table_and_the_spec_records_it(tmp_path):
    """gravity_every = "auto" at the paper's dt resolves to K = 25 (GRAVITY_INTERVAL_AUTO / 0.04 s: the
    table of docs/benchmarks.md supports K up to 50), the resolved spec holding the number, and a
    duration becomes whole outer steps of it."""
    from decco_warp.scheme import GRAVITY_INTERVAL_AUTO

    spec = _spec(tmp_path, "auto", {"gravity_every": "auto"}, steps=None, duration=1.1, output_every=25, checkpoint_every=25)
    assert GRAVITY_INTERVAL_AUTO == 1.0
    assert spec["params"]["gravity_every"] == 25
    assert spec["run"]["steps"] == 25 * math.ceil(1.1 / 0.04 / 25) == 50


def test_the_scheme_answers_for_its_clock():
    """Code outside scheme.py learns K from the Scheme: its step multiple, its number of clocks, and
    the K of a specification's [params] table as given ("auto" by its dt, absent)."""
    from decco_warp.scheme import Scheme, step_multiple_of

    assert (Scheme().step_multiple, Scheme().clocks) == (1, 1)
    assert (Scheme(gravity_every=5).step_multiple, Scheme(gravity_every=5).clocks) == (5, 2)
    assert step_multiple_of({}) == 1 and step_multiple_of({"gravity_every": 20}) == 20
    assert step_multiple_of({"gravity_every": "auto"}) == 25  # Params' dt, the paper's 0.04 s
    assert step_multiple_of({"gravity_every": "auto", "dt": 0.02}) == 50
    # An "auto" dt (given, or implied by k_in = "auto"): K is settled with it.
    assert step_multiple_of({"gravity_every": "auto", "dt": "auto"}) is None
    assert step_multiple_of({"gravity_every": "auto", "k_in": "auto"}) is None
    assert step_multiple_of({"gravity_every": "auto", "k_in": "auto", "dt": 0.04}) == 25


def test_auto_gravity_every_is_an_interval_k_of_dt():
    """gravity_every = "auto" holds gravity every GRAVITY_INTERVAL_AUTO seconds: K is the whole number
    of steps of dt nearest it, at least 1 (halves up).  Round-off: the paper's dt gives 25, and the
    dts that resolution.scaled_run makes at R = 4 and R = 16 (0.04 x R^(-1/3), as it computes them)
    give 40 and 63."""
    from decco_warp.errors import InputError
    from decco_warp.resolution import length_factor
    from decco_warp.scheme import GRAVITY_INTERVAL_AUTO, auto_gravity_every

    assert GRAVITY_INTERVAL_AUTO == 1.0
    assert auto_gravity_every(0.04) == 25 and auto_gravity_every(1.0 / 25) == 25
    assert auto_gravity_every(float(0.04) * length_factor(4)) == 40  # 39.69 steps of 0.0252 s
    assert auto_gravity_every(float(0.04) * length_factor(16)) == 63  # 63.00 steps of 0.0159 s
    assert auto_gravity_every(0.04 * 4 ** (-1 / 3)) == 40 and auto_gravity_every(0.04 * 16 ** (-1 / 3)) == 63
    assert [auto_gravity_every(dt) for dt in (0.02, 0.01, 0.08, 0.16, 0.4, 1.0, 100.0)] == [50, 100, 13, 6, 3, 1, 1]  # 0.08, 0.4: 12.5, 2.5 up
    for bad in (0.0, -0.04, float("nan"), float("inf"), "auto", True):
        with pytest.raises(InputError, match='gravity_every = "auto" needs a time step > 0'):
            auto_gravity_every(bad)


def test_a_specification_resolves_auto_gravity_every_by_its_dt(tmp_path):
    """resolve_spec takes K from the final dt: the file's, an override's (the command line's), a
    sweep grid's; the paper's dt keeps 25; and with an "auto" dt (k_in = "auto") K stays "auto" with
    it, unchecked, until the set-up settles both (test_an_auto_dt_settles_its_auto_clock_with_it)."""
    from decco_warp import spec as specs
    from decco_warp.sweep import load_sweep

    def clock(params, overrides=None, **run):
        spec = specs.resolve_spec({"params": {"gravity_every": "auto", **params}, "run": run}, overrides)
        return spec["params"]["gravity_every"], spec["run"].get("steps")

    assert clock({}, steps=50_000) == (25, 50_000)  # the paper's dt
    assert clock({"dt": 0.04}, duration=1.1, output_every=25, checkpoint_every=25) == (25, 50)  # 28 steps, up to 2 outer steps
    assert clock({"dt": 0.02}, steps=100, output_every=50, checkpoint_every=100) == (50, 100)
    assert clock({"dt": 0.02}, duration=1.5, output_every=50, checkpoint_every=100) == (50, 100)  # 75 steps, up to 2 outer steps
    assert clock({"dt": 0.04}, {"params": {"dt": 0.02}}, steps=100, output_every=50, checkpoint_every=100) == (50, 100)  # the override's dt
    assert clock({"dt": 0.02}, {"params": {"gravity_every": 4}}, steps=100, output_every=20, checkpoint_every=100) == (4, 100)
    # A step count that is no whole outer step of an "auto" K: one line, saying where K came from.
    with pytest.raises(specs.SpecError, match=r'\[run\] steps = 120: with \[params\] gravity_every = 50 \("auto": gravity every 1 s at dt = 0.02 s') as error:
        clock({"dt": 0.02}, steps=120, output_every=50, checkpoint_every=100)
    assert "\n" not in str(error.value)
    # An "auto" dt: K waits for it, and so does the check of the step counts.
    spec = specs.resolve_spec({"params": {"gravity_every": "auto", "k_in": "auto"}, "run": {"steps": 1009, "output_every": 101}})
    assert (spec["params"]["dt"], spec["params"]["gravity_every"], spec["run"]["steps"]) == ("auto", "auto", 1009)
    assert specs.resolve_spec(spec) == spec
    # A sweep over dt: each run's K from its own dt.
    path = tmp_path / "s.toml"
    path.write_text(f'[sweep]\nout = "{tmp_path}"\n[sweep.grid]\n"params.dt" = [0.04, 0.02, 0.01]\n[params]\ngravity_every = "auto"\n'
                    '[run]\nduration = 100.0\noutput_every = 100\ncheckpoint_every = 1000\n')  # fmt: skip
    runs = load_sweep(path)[1]
    assert [(r["params"]["gravity_every"], r["run"]["steps"]) for r in runs] == [(25, 2500), (50, 5000), (100, 10000)]


def test_an_auto_dt_settles_its_auto_clock_with_it(tmp_path):
    """k_in = "auto" (and so dt = "auto") with gravity_every = "auto": the plan settles dt from the
    set-up, then K from that dt, and rounds the step counts up to whole outer steps of it (they
    could not be given as multiples of a K not yet known), saying so; the plan's scheme and its cost
    are of that K."""
    from decco_warp import spec as specs
    from decco_warp.costs import run_cost
    from decco_warp.plan import plan_start
    from decco_warp.scheme import auto_gravity_every

    given = {"steps": 1009, "output_every": 101, "checkpoint_every": 503}
    spec = specs.resolve_spec({"run": {"out": str(tmp_path), "device": "cpu", **given}, "params": {"k_in": "auto", "gravity_every": "auto"}})
    plan = plan_start(spec)
    every = plan.scheme.step_multiple
    assert every == auto_gravity_every(plan.params.dt) == plan.spec["params"]["gravity_every"] > 1
    notes = "\n".join(plan.notes)
    assert f'gravity_every = "auto": {every}, gravity every {every * plan.params.dt:.3g} s' in notes
    for key, value in given.items():
        settled = plan.spec["run"][key]
        assert settled % every == 0 and value <= settled < value + every, key
        assert (f"{key} {value} rounded up to {settled}: whole outer steps of gravity_every = {every}" in notes) == (settled != value), key
    assert plan.steps == plan.spec["run"]["steps"] != 1009  # 1009 is prime: a K > 1 rounds it
    assert f"at gravity every {every} steps" in run_cost(plan.state.n, plan.scheme, plan.device, plan.steps)
    assert specs.resolve_spec(plan.spec) == plan.spec  # spec.toml records the settled K: a resume keeps it


def test_the_command_line_resolves_auto_gravity_every_by_dt(tmp_path):
    """``simulate --gravity-every auto``: K = 25 at the paper's dt, 50 at --dt 0.02 (the plan's clock
    and its cost), and a step count that is no whole outer step of it refused in one line."""
    from helpers import cli

    common = ("--gravity-every", "auto", "--output-every", "50", "--checkpoint-every", "100", "--out", str(tmp_path), "--device", "cpu")
    result = cli("simulate", "--check", "--steps", "100", *common)
    assert result.returncode == 0, result.stderr
    assert "100 steps (4 s), gravity every 25 steps" in result.stdout and "steps at gravity every 25 steps" in result.stdout
    result = cli("simulate", "--check", "--dt", "0.02", "--steps", "100", *common)
    assert result.returncode == 0, result.stderr
    assert "100 steps (2 s), gravity every 50 steps" in result.stdout and "steps at gravity every 50 steps" in result.stdout
    result = cli("simulate", "--dt", "0.02", "--steps", "120", *common)
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert '[run] steps = 120: with [params] gravity_every = 50 ("auto": gravity every 1 s at dt = 0.02 s' in result.stderr


def test_a_run_of_auto_gravity_every_resumes_at_the_k_it_started_with(tmp_path):
    """A run at gravity_every = "auto" and dt = 0.02 s records K = 50 in spec.toml; resumed, it
    steps on at 50 (the resolved K, not one chosen again) and refuses a total that is no whole outer step."""
    from decco_warp import spec as specs
    from decco_warp.run import prepare_resume, resume_run, start_run

    run = {"name": "auto", "out": str(tmp_path), "device": "cpu", "steps": 50, "output_every": 50, "checkpoint_every": 50}
    result = start_run(specs.resolve_spec({"run": run, "params": {"gravity_every": "auto", "dt": 0.02}}))
    assert specs.load_spec_file(result.run_dir / "spec.toml")["params"]["gravity_every"] == 50
    resume_run(result.run_dir, steps=100)
    assert specs.load_spec_file(result.run_dir / "spec.toml")["run"]["steps"] == 100
    with pytest.raises(specs.SpecError, match=r"\[run\] steps = 120: with \[params\] gravity_every = 50,"):
        prepare_resume(result.run_dir, steps=120)


def test_a_duration_becomes_whole_outer_steps():
    """A duration that is not a whole number of outer steps rounds up to the next one."""
    from decco_warp import spec as specs

    spec = specs.resolve_spec({"run": {"duration": 10.0}, "params": {"gravity_every": 20, "dt": 0.04}})
    assert spec["run"]["steps"] == 260  # 250 steps of 0.04 s, rounded up to 13 outer steps of 20


def test_the_command_line_takes_the_clock_and_refuses_bad_ones(tmp_path):
    from helpers import cli

    for option, message in (("0", "[params] gravity_every = 0: must be an integer >= 1"), ("x", '--gravity-every must be an integer or "auto"; got \'x\'')):
        result = cli("simulate", "--gravity-every", option, "--steps", "10", "--out", str(tmp_path), "--device", "cpu")
        assert result.returncode == 2 and message in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    result = cli("simulate", "--check", "--gravity-every", "5", "--steps", "100", "--output-every", "50", "--checkpoint-every", "100",
                 "--out", str(tmp_path), "--device", "cpu")  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "100 steps (4 s), gravity every 5 steps" in result.stdout and "contacts every step from a neighbour list" in result.stdout
    result = cli("simulate", "--gravity-every", "5", "--steps", "12", "--out", str(tmp_path), "--device", "cpu")
    assert result.returncode == 2 and "[run] steps = 12: with [params] gravity_every = 5" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_runs_on_two_clocks_stepped_as_an_ensemble_write_what_they_would_alone(tmp_path):
    """Two runs of the shipped collision at gravity_every = 5 and different eta, stepped together:
    each run folder holds the frames and checkpoint it holds when run alone, bit for bit."""
    from helpers import assert_same_run

    from decco_warp import spec as specs
    from decco_warp.io import read_checkpoint
    from decco_warp.run import RunResult, execute_ensemble, prepare_start, start_run

    def spec(where, name, eta):
        run = {"name": name, "out": str(tmp_path / where), "device": "cpu", "steps": 200, "output_every": 100, "checkpoint_every": 100}
        return specs.resolve_spec({"run": run, "params": {"gravity_every": 5}, "collision": {"eta": eta}})

    runs = (("slow", 0.5), ("fast", 2.0))
    for name, eta in runs:
        start_run(spec("alone", name, eta))
    outcomes = execute_ensemble([prepare_start(spec("together", name, eta)) for name, eta in runs])
    assert all(isinstance(o, RunResult) for o in outcomes)
    for name, _ in runs:
        alone, together = tmp_path / "alone" / name, tmp_path / "together" / name
        assert_same_run(dw.read_trajectory(alone / "trajectory.h5"), dw.read_trajectory(together / "trajectory.h5"))
        mine, theirs = read_checkpoint(together / "checkpoint.h5")[0], read_checkpoint(alone / "checkpoint.h5")[0]
        for key, values in theirs.items():
            if isinstance(values, np.ndarray):
                assert np.array_equal(mine[key], values), key


@pytest.mark.parametrize("every", [1, 5])
def test_the_per_particle_block_size_leaves_the_motion_unchanged(device, every, monkeypatch):
    """layouts.PARTICLE_BLOCK (threads a block of the kernels of one thread a particle) changes
    where threads run on a GPU, not what they compute: 150 steps at 32 and at 256 end bit for bit
    alike, at K = 1 (the Newton sweep's gather) and K = 5 (the neighbour list's build, rebuilt many
    times).  The CPU runs a launch's threads one by one whatever the block: nothing to test there."""
    from decco_warp import layouts

    if device == "cpu":
        pytest.skip("a block shapes GPU launches only")

    clump = _fast_clump(300, seed=3)
    ends = []
    for block in (256, 32):
        monkeypatch.setattr(layouts, "PARTICLE_BLOCK", block)
        sim = dw.Simulation(clump, dw.Params(), device=device, ledger=True, allow_unstable=True, scheme=dw.Scheme(gravity_every=every))
        sim.step(150)
        ends.append(sim.snapshot())
    for key in ("positions", "velocities", "omegas", "force", "torque", "channels", "work", "deepest_contact"):
        assert np.array_equal(ends[0][key], ends[1][key]), key


LANES_ON_THE_CPU = """
import sys
import numpy as np, warp as wp
wp.config.enable_cpu_blocks = True  # the contact pass's 8 lanes a particle, as on a GPU
wp.config.kernel_cache_dir = sys.argv[1]
sys.path.insert(0, sys.argv[2])
import decco_warp as dw
from decco_warp import contact_finders
from helpers import straight_and_resumed
from test_respa import _fast_clump
KEYS = ("positions", "velocities", "omegas", "force", "torque", "channels", "work", "deepest_contact")
if len(sys.argv) > 3:  # the check of the check: lists built afresh on restore, every system's lists at every build
    contact_finders.NEIGHBOUR_ARRAYS = ("none",)
    build = contact_finders.NeighbourList.build
    contact_finders.NeighbourList.build = lambda self, state, everything=False: build(self, state, True)
from dataclasses import replace
from decco_warp.io import load_pile
from decco_warp.plan import builtin_pile
params, scheme = dw.Params(), dw.Scheme(gravity_every=5)
def sheared(seed):  # the shipped pile (lists of up to ~30 neighbours) in a shear flow: its layers slide past each other
    pile = load_pile(builtin_pile("target"))
    y = pile.positions[:, 1] - pile.positions[:, 1].mean()
    flow = np.zeros_like(pile.velocities)
    flow[:, 0] = contact_finders.SKIN_FRACTION * 7.5e5 * (0.2 + 0.1 * (seed % 3)) * y / np.abs(y).max()
    return replace(pile, velocities=pile.velocities + flow)
clump = sheared(11)
straight, second = straight_and_resumed(clump, params, 300, 60, scheme=scheme)
a, b = straight.snapshot(), second.snapshot()
restart = all(np.array_equal(a[key], b[key]) for key in KEYS)
states = [_fast_clump(37, seed=0), sheared(1), _fast_clump(64, seed=2)]
sizes = [s.n for s in states]
joined = dw.State.from_arrays(*[np.concatenate([getattr(s, name) for s in states]) for name in ("positions", "velocities", "omegas", "radii", "masses")])
ensemble = dw.Simulation(joined, params, device="cpu", systems=sizes, ledger=True, allow_unstable=True, scheme=scheme)
ensemble.step(300)
cuts = np.cumsum((0, *sizes))
together, builds = True, True
for k, state in enumerate(states):
    alone = dw.Simulation(state, params, device="cpu", ledger=True, allow_unstable=True, scheme=scheme)
    alone.step(300)
    part = slice(cuts[k], cuts[k + 1])
    together &= np.array_equal(ensemble.state.positions[part], alone.state.positions)
    together &= np.array_equal(ensemble.work()[part], alone.work())
    builds &= ensemble.neighbour_list_builds(k) == alone.neighbour_list_builds()
longest = int(straight.engine.candidate_count.numpy().max())
print("restart", restart, "ensemble", together, "builds", builds, "longest list", longest)
"""


@pytest.fixture(scope="module")
def lanes_on_the_cpu(tmp_path_factory):
    """LANES_ON_THE_CPU's verdicts as it stands and with its check of the check (lists built afresh)."""
    import subprocess
    import sys
    from pathlib import Path

    cache, tests = str(tmp_path_factory.mktemp("lanes") / "cache"), str(Path(__file__).parent)
    runs = {}
    for name, extra in (("kept", []), ("afresh", ["afresh"])):
        done = subprocess.run([sys.executable, "-c", LANES_ON_THE_CPU, cache, tests, *extra], capture_output=True, text=True, timeout=900)
        assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]
        runs[name] = done.stdout.strip().splitlines()[-1]
    return runs


def test_restarts_and_ensembles_keep_the_lists_that_order_the_contact_lanes_sums(lanes_on_the_cpu):
    """With the contact pass's 8 lanes a particle (Warp's CPU blocks, as on a GPU) which pairs a
    particle's list holds decides which lane adds which contact, and so the rounding of the sum: a
    restart goes on with the snapshot's lists, and each system of an ensemble rebuilds its lists only
    when its own particles have moved, so both move bit for bit as the run alone.  Built afresh on
    restore, or every system's lists at every build, the same runs part: the check can fail."""
    assert lanes_on_the_cpu["kept"].startswith("restart True ensemble True builds True"), lanes_on_the_cpu
    assert lanes_on_the_cpu["afresh"].startswith("restart False ensemble False"), lanes_on_the_cpu
    assert int(lanes_on_the_cpu["kept"].split()[-1]) > 8  # lists longer than the lanes: some lanes add two contacts

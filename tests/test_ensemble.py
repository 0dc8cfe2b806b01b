"""Ensembles: several independent systems laid one after another and stepped by the same launches
(Simulation(..., systems=sizes)); each must move exactly as it would alone."""

import numpy as np
import pytest
from conftest import DEVICES
from scenes import contact_cluster

import decco_warp as dw

SIZES = (37, 64, 23)

ENGINES = [
    (device, name, options)
    for device in DEVICES
    for name, options in (
        [("default", {}), ("newton", {"layout": dw.Layout(1, 3, newton=True)}), ("reference", {"force_kernel": "reference"})]
        if device == "cpu"
        else [("default", {}), ("128x4", {"layout": dw.Layout(128, 4, 4)}), ("32x3", {"layout": dw.Layout(32, 3, 2)})]
    )
]


def _systems():
    """Three clumps centred on the same point: had they felt each other, they would overlap wholesale."""
    return [contact_cluster(n, seed=seed, speed=1e3) for seed, n in enumerate(SIZES)]


def _together(states):
    def joined(name):
        return np.concatenate([getattr(s, name) for s in states])

    return dw.State.from_arrays(joined("positions"), joined("velocities"), joined("omegas"), joined("radii"), joined("masses"))


@pytest.mark.parametrize(("device", "name", "options"), ENGINES, ids=[f"{d}-{n}" for d, n, _ in ENGINES])
def test_each_system_of_an_ensemble_moves_bit_for_bit_as_it_would_alone(device, name, options):
    states = _systems()
    params = dw.Params()
    ensemble = dw.Simulation(_together(states), params, device=device, systems=SIZES, ledger=True, **options)
    alone = [dw.Simulation(s, params, device=device, ledger=True, **options) for s in states]
    cuts = np.cumsum((0, *SIZES))
    for steps in (0, 40):
        ensemble.step(steps)
        force, torque = ensemble.forces()
        positions = ensemble.state.positions
        pairs = ensemble.pair_observables()
        for k, sim in enumerate(alone):
            sim.step(steps)
            part = slice(cuts[k], cuts[k + 1])
            own_force, own_torque = sim.forces()
            assert np.array_equal(force[part], own_force) and np.array_equal(torque[part], own_torque)
            assert np.array_equal(positions[part], sim.state.positions)
            for key, values in sim.pair_observables().items():
                mine = pairs[key][part]
                if key == "overlap_partner":  # an index into the whole ensemble
                    mine = np.where(mine >= 0, mine - cuts[k], mine)
                assert np.array_equal(mine, values), key
            assert np.array_equal(ensemble.work()[part], sim.work())
    assert np.abs(force).max() > 0 and pairs["contacts"].sum() > 0  # gravity and contacts at work


#: With the Newton layout on the CPU too (the default on CUDA).
FUSED_ENGINES = ENGINES + [("cpu", "newton", {"layout": dw.Layout(1, 4, newton=True)})]


@pytest.mark.parametrize("precision", ["mixed", "float64"])
@pytest.mark.parametrize(("device", "name", "options"), FUSED_ENGINES, ids=[f"{d}-{n}" for d, n, _ in FUSED_ENGINES])
def test_an_ensemble_steps_sharing_launches_bit_for_bit_as_one_step_at_a_time(device, name, options, precision):
    """Engine.advance (a step's kicks and the packing in one launch) moves an ensemble exactly as
    Engine.step does: every array of its snapshot, bit for bit."""
    from helpers import assert_fused_steps_equal_one_step_at_a_time

    state = _together(_systems())

    def make():
        return dw.Simulation(state, dw.Params(), device=device, precision=precision, systems=SIZES, ledger=True, **options)

    assert_fused_steps_equal_one_step_at_a_time(make)


def test_ensemble_sizes_are_checked_and_the_tree_steps_one_system():
    state = _together(_systems())
    for sizes in ((37, 64), (37, 64, 23, 1), (0, 101, 23), ()):
        with pytest.raises(ValueError, match="systems must be positive sizes"):
            dw.Simulation(state, dw.Params(), device="cpu", systems=sizes)
    with pytest.raises(ValueError, match="one system at a time"):
        dw.Simulation(state, dw.Params(), device="cpu", systems=SIZES, scheme=dw.Scheme(gravity="tree"))


def test_members_of_another_layout_or_precision_are_refused():
    """A member stepped with another layout or precision would not move as it would alone."""
    from decco_warp.ensemble import Ensemble

    one, two = _systems()[:2]
    base = dw.Simulation(one, dw.Params(), device="cpu", allow_unstable=True, ledger=True)
    for options in ({"layout": dw.Layout(1, 3, newton=True)}, {"precision": "float64"}):
        other = dw.Simulation(two, dw.Params(), device="cpu", allow_unstable=True, ledger=True, **options)
        with pytest.raises(ValueError, match="share their force layout and precision"):
            Ensemble([base, other])


def _spec(out, name, **run):
    from decco_warp import spec as specs

    return specs.resolve_spec(
        {"run": {"name": name, "out": str(out), "device": "cpu", "steps": 300, "output_every": 100, "checkpoint_every": 200, **run},
         "collision": {"eta": {"a": 0.5, "b": 2.0, "c": 1.0}[name[0]]}}
    )  # fmt: skip


def test_runs_stepped_as_an_ensemble_write_what_they_would_alone_and_one_failing_stops_only_itself(tmp_path):
    """Three runs of the shipped collision at different eta stepped as one ensemble: two write run
    folders (frames, checkpoints) identical to those written alone; the third, whose [run]
    max_overlap is below its piles' resting contacts, stops at its first frame after the start
    with its own error, and the others go on."""
    from helpers import assert_same_run

    from decco_warp.io import read_checkpoint
    from decco_warp.run import BlowUp, RunResult, execute_ensemble, prepare_start, start_run

    names = ["a-slow", "b-fast", "c-strict"]
    strict = {"max_overlap": 1e-9}
    for name in names[:2]:
        start_run(_spec(tmp_path / "alone", name))
    outcomes = execute_ensemble([prepare_start(_spec(tmp_path / "together", name, **(strict if name == "c-strict" else {}))) for name in names])
    assert [type(o) for o in outcomes] == [RunResult, RunResult, BlowUp]
    assert "max_overlap" in str(outcomes[2]) and str(outcomes[2]).startswith("steps 1 to 100:")
    assert "blow-up" in (tmp_path / "together" / "c-strict" / "run.log").read_text()
    for name, outcome in zip(names[:2], outcomes):
        alone, together = tmp_path / "alone" / name, tmp_path / "together" / name
        assert outcome.steps == 300 and outcome.run_dir == together
        assert_same_run(dw.read_trajectory(alone / "trajectory.h5"), dw.read_trajectory(together / "trajectory.h5"))
        mine, theirs = read_checkpoint(together / "checkpoint.h5")[0], read_checkpoint(alone / "checkpoint.h5")[0]
        for key, values in theirs.items():
            if isinstance(values, np.ndarray):
                assert np.array_equal(mine[key], values), key
        assert "done: step 300" in (together / "run.log").read_text()
        assert "ensemble: stepped together with 2 other run(s) in one set of launches" in (together / "run.log").read_text()
        assert not (together / ".lock").exists()


def test_a_sweep_batch_steps_tree_runs_one_at_a_time(tmp_path):
    """The tree path cannot share a launch: a batch of tree runs runs them alone, each ok."""
    from decco_warp.sweep import simulate_batch

    batch = [_spec(tmp_path, name, steps=100, output_every=50) for name in ("a-tree", "b-tree")]
    for spec in batch:
        spec["params"]["gravity"] = "tree"
    rows = simulate_batch(batch)
    assert [row["status"] for row in rows] == ["ok", "ok"] and all(row["ensemble"] == 1 for row in rows)
    assert all((tmp_path / name / "checkpoint.h5").is_file() for name in ("a-tree", "b-tree"))


def test_resumed_runs_continue_as_an_ensemble_as_they_would_alone(tmp_path):
    """Two runs stopped at step 200 and continued to 300, together and alone: the same folders."""
    from helpers import assert_same_run

    from decco_warp.run import RunResult, execute, execute_ensemble, prepare_resume, start_run

    names = ("a-slow", "b-fast")
    for where in ("alone", "together"):
        for name in names:
            start_run(_spec(tmp_path / where, name, steps=200))
    for name in names:
        execute(prepare_resume(tmp_path / "alone" / name, steps=300))
    outcomes = execute_ensemble([prepare_resume(tmp_path / "together" / name, steps=300) for name in names])
    assert all(isinstance(o, RunResult) and o.steps == 300 and o.steps_this_session == 100 for o in outcomes)
    for name in names:
        alone, together = (dw.read_trajectory(tmp_path / where / name / "trajectory.h5") for where in ("alone", "together"))
        assert_same_run(alone, together)
        assert together["step"].tolist() == [0, 100, 200, 300]


def test_a_signal_stops_every_run_of_an_ensemble_at_one_step_and_each_resumes_alone(tmp_path, monkeypatch):
    """SIGINT during an ensemble: every run checkpoints at the same step and stops; resumed alone,
    each ends exactly as a run never interrupted."""
    import signal

    from helpers import assert_same_run

    from decco_warp import run as runs

    names = ("a-slow", "b-fast")
    for name in names:
        runs.start_run(_spec(tmp_path / "alone", name))
    real_pause = runs.pause_point

    def interrupt(phase, step):
        if phase == "step" and step == 100:
            signal.raise_signal(signal.SIGINT)
        real_pause(phase, step)

    monkeypatch.setattr(runs, "pause_point", interrupt)
    outcomes = runs.execute_ensemble([runs.prepare_start(_spec(tmp_path / "together", name)) for name in names])
    monkeypatch.setattr(runs, "pause_point", real_pause)
    assert all(isinstance(o, runs.RunStopped) for o in outcomes) and len({o.step for o in outcomes}) == 1
    assert 100 < outcomes[0].step < 300
    for name in names:
        runs.resume_run(tmp_path / "together" / name)
        alone, together = (dw.read_trajectory(tmp_path / where / name / "trajectory.h5") for where in ("alone", "together"))
        assert_same_run(alone, together)

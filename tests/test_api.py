"""The pinned Python API, input checking, device choice and the CLI."""


import numpy as np
import pytest
from helpers import cli
from scenes import contact_cluster

import decco_warp as dw
from decco_warp.cli import app


def _arrays(n=3):
    rng = np.random.default_rng(0)
    return (rng.normal(size=(n, 3)) * 1e7, np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, 1e6), np.full(n, 1e19))


def test_state_from_arrays_copies_and_types():
    x, v, w, r, m = _arrays()
    state = dw.State.from_arrays(x, v, w, r, m)
    x[0, 0] = 0.0
    assert state.positions[0, 0] != 0.0
    assert state.positions.dtype == np.float64 and state.n == 3
    np.testing.assert_allclose(state.inertia, 0.4 * m * r**2)
    assert state.pile_id.dtype == np.int32 and np.all(state.pile_id == 0)


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda a: a.__setitem__(3, np.array([1e6, -1.0, 1e6])), "radii must be > 0; particle 1"),
        (lambda a: a.__setitem__(4, np.array([1e19, 1e19, 0.0])), "masses must be > 0; particle 2"),
        (lambda a: a.__setitem__(0, np.zeros((3, 2))), r"positions must have shape \(3, 3\)"),
        (lambda a: a.__setitem__(1, np.full((3, 3), np.nan)), "velocities must be finite"),
        (lambda a: a.__setitem__(2, "spin"), "omegas must be numeric"),
        (lambda a: a.__setitem__(3, np.zeros(0)), "at least one particle"),
    ],
)
def test_state_rejects_bad_arrays(change, match):
    arrays = list(_arrays())
    change(arrays)
    with pytest.raises(ValueError, match=match):
        dw.State.from_arrays(*arrays)


def test_params_defaults_and_checks():
    p = dw.Params()
    assert (p.k_in, p.restitution, p.mu_k, p.mu_r, p.dt, p.G) == (1e18, 0.9, 0.3, 1e-3, 0.04, 6.67430e-8)
    assert p.k_out == pytest.approx(0.81e18)
    for bad, match in [
        (dict(k_in=0), "k_in must be > 0"),
        (dict(restitution=1.5), r"restitution must be in \(0, 1\]"),
        (dict(mu_k=-0.1), "mu_k must be >= 0"),
        (dict(dt=float("nan")), "dt must be > 0"),
        (dict(rolling_friction="spiral"), "rolling_friction must be one of couple, paper"),
        (dict(k_in="stiff"), "k_in must be a number"),
    ]:
        with pytest.raises(ValueError, match=match):
            dw.Params(**bad)
    assert dw.Params.from_dict(p.to_dict()) == p
    with pytest.raises(ValueError, match="unknown parameter"):
        dw.Params.from_dict({"k": 1.0})


def test_device_choice(monkeypatch):
    monkeypatch.delenv("DECCO_DEVICE", raising=False)
    expected = "cuda:0" if dw.device.cuda_device_count() else "cpu"
    assert dw.resolve_device(None) == expected
    monkeypatch.setenv("DECCO_DEVICE", "cpu")
    assert dw.resolve_device(None) == "cpu"
    assert dw.resolve_device("CPU") == "cpu"  # an explicit choice wins over the environment
    for bad in ["gpu", "cuda:x", "cuda:99"]:
        with pytest.raises(dw.DeviceError):
            dw.resolve_device(bad)
    monkeypatch.setenv("DECCO_DEVICE", "tpu")
    with pytest.raises(dw.DeviceError, match="DECCO_DEVICE"):
        dw.resolve_device(None)


def test_simulation_bookkeeping_and_compute_forces_agree(device):
    state = contact_cluster(20, seed=2)
    params = dw.Params()
    sim = dw.Simulation(state, params, device=device)
    force, torque = dw.compute_forces(state, params, device=device)
    np.testing.assert_array_equal(sim.forces()[0], force)
    np.testing.assert_array_equal(sim.forces()[1], torque)
    sim.step(0)
    assert sim.state.step == 0 and np.array_equal(sim.state.positions, state.positions)
    sim.step(3)
    sim.step(4)
    assert sim.step_count == 7 and sim.time == pytest.approx(7 * params.dt)
    snapshot = sim.state
    snapshot.positions[:] = 0.0  # a copy: the simulation is untouched
    assert not np.array_equal(sim.state.positions, snapshot.positions)
    with pytest.raises(ValueError, match="non-negative integer"):
        sim.step(-1)
    with pytest.raises(ValueError, match="precision"):
        dw.compute_forces(state, params, device=device, precision="half")


@pytest.mark.parametrize("gravity", ["all-pairs", "tree"])
def test_recorded_steps_equal_steps_launched_one_by_one(device, gravity):
    """Steps are steps: 3 + 110 + 7 (blocks of 50 replay a recorded graph, on the CPU too) equal 120
    steps launched one by one, bit for bit, the ledger's work included. The tree path's level loop
    keeps its condition on the device, so its steps record like the others."""
    state = contact_cluster(30, seed=4)
    params, scheme = dw.Params(), dw.Scheme(gravity=gravity)
    a = dw.Simulation(state, params, device=device, ledger=True, scheme=scheme)
    for _ in range(120):
        a.engine.step()
    b = dw.Simulation(state, params, device=device, ledger=True, scheme=scheme)
    for n in (3, 110, 7):
        b.step(n)
    assert b.step_count == 120
    np.testing.assert_array_equal(a.state.positions, b.state.positions)
    np.testing.assert_array_equal(a.state.omegas, b.state.omegas)
    np.testing.assert_array_equal(a.work(), b.work())


def test_steps_go_on_one_by_one_when_recording_fails(monkeypatch):
    """A device that cannot record a block of steps (a graph capture raising) still steps, one
    launch at a time, to the same numbers, and says so once."""
    import warp as wp

    state = contact_cluster(30, seed=4)
    a = dw.Simulation(state, dw.Params(), device="cpu")
    a.step(60)

    class Refused:
        def __init__(self, *args, **kwargs):
            pass

        def __enter__(self):
            raise RuntimeError("no graphs here")

        def __exit__(self, *exc):
            return False

    monkeypatch.setattr(wp, "ScopedCapture", Refused)
    b = dw.Simulation(state, dw.Params(), device="cpu")
    with pytest.warns(UserWarning, match="launched one by one.*no graphs here"):
        b.step(60)
    b.step(60)  # no second warning, no second try
    a.step(60)
    assert b.step_count == 120
    np.testing.assert_array_equal(a.state.positions, b.state.positions)


def test_cli_version_and_info():
    out = cli("--version")
    assert out.returncode == 0 and out.stdout.strip() == f"decco-warp {dw.__version__}"
    out = cli("info", "--device", "cpu")
    assert out.returncode == 0, out.stderr
    assert "warp-lang" in out.stdout and "would use: cpu" in out.stdout
    assert "Traceback" not in out.stderr


def test_cli_rejects_bad_device_in_one_line():
    out = cli("info", "--device", "gpu0")
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "cpu, cuda or cuda:N" in out.stderr
    assert app.info.name == "decco-warp"


def test_every_error_is_a_decco_error_with_its_exit_code_and_the_builtin_it_was(monkeypatch, capsys):
    """decco_warp/errors.py: each error derives from dw.DeccoError and from the built-in it always
    was, carries the command's exit code, and is importable where it used to live; main_entry turns
    one that no command caught into one line and that code."""
    from decco_warp import checks, cli, device, errors, forming, io, pile, plan, run, spec, stability, viz
    from decco_warp.analysis.compare import CompareError
    from decco_warp.lock import RunFolderBusy

    expected = {
        errors.InputError: (ValueError, 2), errors.SpecError: (ValueError, 2), errors.RunError: (ValueError, 2),
        errors.FileFormatError: (ValueError, 2), errors.DeviceError: (ValueError, 2), errors.StabilityError: (ValueError, 2),
        errors.RerunUnavailable: (RuntimeError, 2), errors.FormationError: (RuntimeError, 1), errors.BlowUp: (RuntimeError, 4),
        errors.OutputError: (RuntimeError, 5), errors.RunStopped: (RuntimeError, 3), errors.FormationStopped: (RuntimeError, 3),
        errors.NotSettled: (RuntimeError, 6), CompareError: (ValueError, 2), RunFolderBusy: (ValueError, 2),
    }  # fmt: skip
    for kind, (builtin, code) in expected.items():
        assert issubclass(kind, dw.DeccoError) and issubclass(kind, builtin) and kind.exit_code == code, kind
    homes = [(checks, "InputError"), (spec, "SpecError"), (plan, "RunError"), (io, "FileFormatError"), (device, "DeviceError"),
             (stability, "StabilityError"), (viz, "RerunUnavailable"), (pile, "FormationError"), (run, "BlowUp"),
             (run, "OutputError"), (run, "RunStopped"), (forming, "FormationStopped")]  # fmt: skip
    assert all(getattr(module, name) is getattr(errors, name) for module, name in homes)
    assert errors.OutputError("no space left\nsecond line").line == "no space left"

    def uncaught(**options):
        raise errors.OutputError("writing somewhere failed")

    monkeypatch.setattr(cli, "app", uncaught)
    with pytest.raises(SystemExit) as ended:
        cli.main_entry()
    assert ended.value.code == 5
    assert capsys.readouterr().err == "decco-warp: error: writing somewhere failed\n"


def test_the_library_refuses_bad_arguments_with_a_decco_error_that_is_still_a_value_error():
    """What the API refuses (a negative time step, a bad layout, mismatched arrays, an unknown test
    system, a bad cluster threshold) is one class to catch, dw.DeccoError, and still a ValueError."""
    from decco_warp.bench import bench_system

    state = dw.State.from_arrays(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 3)), np.ones(2), np.ones(2))
    refusals = [
        lambda: dw.Params(dt=-1.0),
        lambda: dw.Layout(0, 4),
        lambda: dw.State.from_arrays(np.zeros((2, 3)), np.zeros((3, 3)), np.zeros((2, 3)), np.ones(2), np.ones(2)),
        lambda: bench_system("marbles", 8),
        lambda: dw.find_clusters(state, min_members=0),
    ]
    for refuse in refusals:
        with pytest.raises(dw.DeccoError) as raised:
            refuse()
        assert isinstance(raised.value, ValueError) and raised.value.exit_code == 2 and raised.value.line


def test_run_folder_names_the_files_and_tells_how_far_a_run_kept_without_checkpoint_went(tmp_path):
    """A run folder kept as the committed results keep it (spec.toml and summary.json, no
    checkpoint): its progress comes from the summary; a folder with neither file has none."""
    import json

    from decco_warp import spec as specs

    folder = dw.RunFolder(tmp_path / "run")
    assert folder.trajectory == tmp_path / "run" / "trajectory.h5" and folder.summary.name == "summary.json"
    assert folder.progress() is None and not folder.complete()
    folder.path.mkdir()
    folder.spec.write_text(specs.dumps(specs.resolve_spec({"run": {"steps": 100, "name": "run", "out": str(tmp_path)}}), header="test"))
    folder.summary.write_text(json.dumps({"steps": 60}))
    assert folder.progress() == (60, 100) and not folder.complete()
    folder.summary.write_text(json.dumps({"steps": 100}))
    assert folder.progress() == (100, 100) and folder.complete()

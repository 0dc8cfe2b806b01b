"""Helpers shared by the tests that drive the command line and compare runs."""

import subprocess
import sys

import numpy as np


def cli(*args, env=None, cwd=None):
    """Run the ``decco-warp`` console entry in a fresh interpreter; returns the CompletedProcess."""
    return subprocess.run(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=cwd,
    )


def cli_here(*args) -> subprocess.CompletedProcess:
    """Run the ``decco-warp`` console entry in this interpreter (no second of start-up for Warp's
    import per call): the CompletedProcess that :func:`cli` would give, its exit code, stdout and stderr."""
    import contextlib
    import io

    from decco_warp.cli import main_entry

    out, err, argv = io.StringIO(), io.StringIO(), sys.argv
    sys.argv = ["decco-warp", *args]
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            main_entry()
        code = 0
    except SystemExit as done:
        code = int(done.code or 0)
    finally:
        sys.argv = argv
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def assert_same_run(a: dict, b: dict) -> None:
    """Two trajectories (read_trajectory) hold the same frames, bit for bit, with no frame lost or repeated."""
    assert a["step"].tolist() == b["step"].tolist()
    for name in a["particles"]:
        assert np.array_equal(a["particles"][name], b["particles"][name]), name
    for name in a["observables"]:
        assert np.array_equal(a["observables"][name], b["observables"][name], equal_nan=True), name
        for data in (a, b):
            assert data["observable_step"][name].tolist() == data["step"].tolist(), name


#: Step counts of one Simulation.step call after another: one step, none, then a recorded block of
#: 50 (simulation.py GRAPH_STEPS) and two steps left over.
FUSED_PIECES = (1, 0, 52)


def assert_fused_steps_equal_one_step_at_a_time(make, pieces=FUSED_PIECES):
    """``make()`` gives a fresh Simulation.  Stepped ``sum(pieces)`` times by Engine.step (a step's
    launches one after another: kick_drift, pack, forces, kick) and by Simulation.step(piece) for
    each piece (Engine.advance: the kicks of two steps and the packing in one launch), every array
    the next step depends on (positions, velocities, spins, forces, torques, the ledger's channels
    and work, the deepest-contact records) is the same, bit for bit."""
    launched, fused = make(), make()
    for _ in range(sum(pieces) // launched.step_multiple):  # with gravity on its own clock, an outer step
        launched.engine.step()
    for steps in pieces:
        fused.step(steps)
    assert fused.step_count - launched.step_count == sum(pieces)
    want, got = launched.engine.snapshot(), fused.engine.snapshot()
    for name, values in want.items():
        assert np.array_equal(got[name], values), name
    # The scene did something: contacts met and the ledger counting.
    assert want["deepest_contact"].max() > 0 and np.abs(want["work"]).max() > 0


def straight_and_resumed(state, params, steps: int, at: int, device: str = "cpu", **options):
    """Two simulations of ``state`` after ``steps`` steps: one stepped straight through, one
    stopped at ``at``, made again from that snapshot and stepped on (a resumed run); ``options``
    (precision, scheme, layout) for both. For the bit-for-bit checks of a restart."""
    import decco_warp as dw

    straight = dw.Simulation(state, params, device=device, ledger=True, allow_unstable=True, **options)
    straight.step(steps)
    first = dw.Simulation(state, params, device=device, ledger=True, allow_unstable=True, **options)
    first.step(at)
    resumed = dw.Simulation.from_snapshot(state, params, first.snapshot(), device=device, **options)
    assert resumed.step_count == at
    resumed.step(steps - at)
    return straight, resumed

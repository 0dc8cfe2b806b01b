"""Faults: kills at the risky moments, full disks, failed writes, damaged run folders and checkpoints,
and specifications of every malformed kind (hypothesis).  Damaged piles and unwritable destinations:
test_bad_input.py."""

import math
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from helpers import assert_same_run, cli
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import decco_warp as dw
from decco_warp import spec as specs
from decco_warp.io import FileFormatError, read_checkpoint
from decco_warp.run import RunError, builtin_pile, start_run

RUN = ["--steps", "2400", "--output-every", "100", "--checkpoint-every", "600", "--device", "cpu"]




@pytest.fixture(scope="module")
def straight(tmp_path_factory):
    out = tmp_path_factory.mktemp("straight")
    spec = specs.resolve_spec(
        {"run": {"name": "straight", "out": str(out), "device": "cpu", "steps": 2400, "output_every": 100, "checkpoint_every": 600}}
    )
    return dw.read_trajectory(start_run(spec).run_dir / "trajectory.h5")




@pytest.mark.parametrize("phase", ["step@1250", "trajectory-write@1300", "checkpoint-write@1200"])
def test_sigkill_at_a_risky_moment_then_resume_equals_an_uninterrupted_run(phase, straight, tmp_path):
    mark = tmp_path / "paused"
    env = dict(os.environ, DECCO_TEST_PAUSE=phase, DECCO_TEST_PAUSE_MARK=str(mark))
    process = subprocess.Popen(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "simulate", "--name", "k", "--out", str(tmp_path), *RUN],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env=env,
    )
    deadline = time.time() + 120
    while not mark.exists() and time.time() < deadline and process.poll() is None:
        time.sleep(0.02)
    assert mark.exists(), "the run never reached the pause"
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    run_dir = tmp_path / "k"
    # Right after the kill: the trajectory reads, and the checkpoint is a whole one.
    frames = dw.read_trajectory(run_dir / "trajectory.h5")
    assert frames["step"][0] == 0
    assert read_checkpoint(run_dir / "checkpoint.h5")[0]["step"] in (600, 1200)
    result = cli("resume", str(run_dir), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    assert_same_run(straight, dw.read_trajectory(run_dir / "trajectory.h5"))
    assert not list(run_dir.glob(".*.tmp"))


def test_full_disk_stops_cleanly_and_the_checkpoint_survives(straight, tmp_path):
    env = dict(os.environ, DECCO_TEST_FAIL="trajectory-write@1300")
    result = cli("simulate", "--name", "full", "--out", str(tmp_path), *RUN, env=env)
    assert result.returncode == 5, result.stderr
    assert "No space left on device" in result.stderr and "checkpoint of step 1200 is intact" in result.stderr
    assert "Traceback" not in result.stderr
    assert read_checkpoint(tmp_path / "full" / "checkpoint.h5")[0]["step"] == 1200
    assert cli("resume", str(tmp_path / "full"), "--device", "cpu").returncode == 0
    assert_same_run(straight, dw.read_trajectory(tmp_path / "full" / "trajectory.h5"))


def test_failed_checkpoint_write_keeps_the_previous_checkpoint(tmp_path):
    env = dict(os.environ, DECCO_TEST_FAIL="checkpoint-write@1200")
    result = cli("simulate", "--name", "ck", "--out", str(tmp_path), *RUN, env=env)
    assert result.returncode == 5 and "checkpoint of step 600 is intact" in result.stderr
    assert not list((tmp_path / "ck").glob(".*.tmp"))


# --- malformed input of every kind (hypothesis) ------------------------------------------------------

_values = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**12), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12), st.lists(st.integers(), max_size=3), st.dictionaries(st.text(max_size=5), st.integers(), max_size=2),
)  # fmt: skip
_known_keys = st.sampled_from(sorted({key for table in specs.SCHEMA.values() for key in table}) + ["bogus", ""])
_tables = st.dictionaries(
    st.one_of(st.sampled_from(sorted(specs.SCHEMA)), st.text(max_size=6)),
    st.one_of(st.dictionaries(_known_keys, _values, max_size=5), _values),
    max_size=4,
)


@settings(max_examples=300, deadline=None)
@given(_tables)
def test_any_spec_either_resolves_or_is_refused_with_a_spec_error(raw):
    try:
        spec = specs.resolve_spec(raw)
    except specs.SpecError as error:
        assert str(error) and "\n" not in str(error)
        return
    # Whatever resolves is complete, valid and stable.
    assert specs.resolve_spec(spec) == spec
    assert spec["run"]["steps"] >= 1 and math.isfinite(spec["params"]["dt"])


@pytest.mark.parametrize(
    "args, message",
    [
        (["simulate", "--steps", "abc"], "Invalid value for '--steps'"),
        (["simulate", "--no-such-option"], "No such option: --no-such-option"),
        (["pile"], "Missing option '--out'"),
        (["frobnicate"], "No such command 'frobnicate'"),
    ],
)
def test_command_line_mistakes_are_one_line_and_exit_2(args, message):
    result = cli(*args)
    assert result.returncode == 2 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_damaged_checkpoint_is_refused_on_resume(tmp_path):
    out = tmp_path / "runs"
    assert cli("simulate", "--steps", "200", "--output-every", "100", "--out", str(out), "--device", "cpu").returncode == 0
    checkpoint = out / "default" / "checkpoint.h5"
    checkpoint.write_bytes(checkpoint.read_bytes()[:1000])
    result = cli("resume", str(out / "default"), "--device", "cpu")
    assert result.returncode == 2 and "checkpoint" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("finished")
    spec = specs.resolve_spec({"run": {"out": str(out), "device": "cpu", "steps": 200, "output_every": 100}})
    return start_run(spec).run_dir


_run_damage = st.one_of(
    st.tuples(st.just("truncate"), st.sampled_from(["checkpoint.h5", "trajectory.h5"]), st.floats(0.0, 0.99)),
    st.tuples(st.just("delete"), st.just("checkpoint.h5"), st.sampled_from(["snapshot", "state", "run", "snapshot/positions", "state/radii"])),
    st.tuples(st.just("nan"), st.just("checkpoint.h5"), st.sampled_from(["snapshot/positions", "snapshot/velocities", "state/masses"])),
    st.tuples(st.just("negative"), st.just("checkpoint.h5"), st.sampled_from(["state/radii", "state/masses"])),
    st.tuples(st.just("missing"), st.sampled_from(["checkpoint.h5", "trajectory.h5", "spec.toml"]), st.just("")),
)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(_run_damage)
@example(("truncate", "trajectory.h5", 3e-5))  # ~16 bytes: cut inside the superblock (HDF5 2 retried for an hour)
def test_damaged_run_folders_are_refused_on_resume_with_a_reason(finished_run, tmp_path_factory, damage):
    import shutil

    from decco_warp.run import prepare_resume

    run_dir = tmp_path_factory.mktemp("damaged") / "run"
    shutil.copytree(finished_run, run_dir)
    kind, name, what = damage
    path = run_dir / name
    if kind == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[: int(what * len(data))])
    elif kind == "missing":
        path.unlink()
    else:
        with h5py.File(path, "r+") as f:
            if kind == "delete":
                del f[what]
            else:
                data = f[what][()].astype(float)
                data.flat[0] = np.nan if kind == "nan" else -1.0
                del f[what]
                f[what] = data
    before = sorted(p.name for p in run_dir.iterdir())
    with pytest.raises((RunError, FileFormatError)) as raised:
        prepare_resume(run_dir, device="cpu")
    assert str(raised.value) and "\n" not in str(raised.value)
    assert sorted(p.name for p in run_dir.iterdir()) == before  # nothing written


def test_a_run_folder_without_its_trajectory_says_how_to_go_on(finished_run, tmp_path):
    """A folder copied without trajectory.h5 (it is the large file) is refused with what to do."""
    import shutil

    from decco_warp.run import prepare_resume

    run_dir = tmp_path / "run"
    shutil.copytree(finished_run, run_dir)
    (run_dir / "trajectory.h5").unlink()
    with pytest.raises(RunError, match="trajectory.h5 is missing.*put it back to resume, or delete the folder"):
        prepare_resume(run_dir, device="cpu")


@pytest.mark.parametrize("offset", [48, 1000])
def test_a_trajectory_with_damaged_metadata_is_refused_at_once(finished_run, tmp_path, offset):
    """Bytes flipped in a finished trajectory's metadata: read at once as a FileFormatError (a SWMR
    reader under HDF5 2 retried such a file for up to an hour; checked in a subprocess with a
    time limit so that a regression fails instead of hanging)."""
    data = bytearray((finished_run / "trajectory.h5").read_bytes())
    for k in range(offset, offset + 64):
        data[k] ^= 0xFF
    damaged = tmp_path / "trajectory.h5"
    damaged.write_bytes(bytes(data))
    code = (
        "import sys\nfrom decco_warp.io import FileFormatError, read_trajectory\n"
        f"try:\n    read_trajectory({str(damaged)!r})\nexcept FileFormatError as error:\n    print('refused:', error)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "refused:" in done.stdout and "corrupted" in done.stdout, done.stdout + done.stderr


def test_background_frames_keep_order_and_return_a_write_error_at_the_next_call(tmp_path, monkeypatch):
    """Frames written on the worker thread land in order, each whole; a failed write (a full disk)
    is raised by the next append, or by close, never lost, and close still closes the file."""
    from decco_warp.io import BackgroundFrames, Trajectory

    state = dw.load_pile(builtin_pile("projectile"))
    observables = {"total_energy": 1.0, "momentum": np.zeros(3)}

    def frame(k):
        particles = {"position": state.positions + k, "velocity": state.velocities, "omega": state.omegas, "stress": state.radii * 0}
        return k, 0.5 * k, particles, {**observables, "total_energy": float(k)}

    frames = BackgroundFrames(Trajectory.create(tmp_path / "t.h5", state, observables, {}))
    for k in range(1, 6):
        frames.append(*frame(k))
    monkeypatch.setenv("DECCO_TEST_FAIL", "trajectory-write@6")
    frames.append(*frame(6))  # fails on the worker thread
    with pytest.raises(OSError, match="No space left"):
        frames.append(*frame(7))
    frames.close()
    written = dw.read_trajectory(tmp_path / "t.h5")
    # Frames 1-5 whole and in order; frame 6, cut short before its step, is not read; no 7.
    assert list(written["step"]) == [1, 2, 3, 4, 5]
    for k in range(1, 6):
        np.testing.assert_array_equal(written["particles"]["position"][k - 1], state.positions + k)
    assert list(written["observables"]["total_energy"][:5]) == [1.0, 2.0, 3.0, 4.0, 5.0]

    frames = BackgroundFrames(Trajectory.create(tmp_path / "u.h5", state, observables, {}))
    monkeypatch.setenv("DECCO_TEST_FAIL", "trajectory-write@1")
    frames.append(*frame(1))
    with pytest.raises(OSError, match="No space left"):
        frames.close()
    with h5py.File(tmp_path / "u.h5", "r+"):  # closed all the same: it opens for writing
        pass

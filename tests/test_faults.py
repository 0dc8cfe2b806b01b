"""Faults in the middle of work: every write of every writing command fails in turn.

The harness runs a command once with a journal of its writes (decco_warp.durable.write_point), then
again with its k-th write failed as a full disk (ENOSPC) or an I/O error (EIO), for a k of
every kind of write it makes (the first and the last of each kind).  Each failure must end the
command with exit 5 and one line naming the error, the file and what is kept, with every file
that is left whole; the same command (or ``resume``) then finishes with the result of an
uninterrupted run, bit for bit.  The commands run in this process (Warp loaded once), so
that the whole harness takes about a minute on two cores.
"""

import errno
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from helpers import assert_same_run, cli
from typer.testing import CliRunner

import decco_warp as dw
import decco_warp.durable as durable
import decco_warp.io as dio
from decco_warp.cli import EXIT_OUTPUT, app
from decco_warp.io import read_checkpoint

RUN = ["--steps", "200", "--output-every", "50", "--checkpoint-every", "100", "--device", "cpu"]
KINDS = {"ENOSPC": os.strerror(errno.ENOSPC), "EIO": os.strerror(errno.EIO)}


def invoke(*args, fail: str | None = None, journal: Path | None = None):
    """Run a command in this process with a fresh write count; ``fail``: "k:KIND"."""
    durable._writes = 0
    saved = {name: os.environ.pop(name, None) for name in ("DECCO_TEST_FAIL_WRITE", "DECCO_TEST_WRITES")}
    try:
        if fail:
            os.environ["DECCO_TEST_FAIL_WRITE"] = fail
        if journal:
            os.environ["DECCO_TEST_WRITES"] = str(journal)
        return CliRunner().invoke(app, [str(a) for a in args])
    finally:
        for name, value in saved.items():
            os.environ.pop(name, None)
            if value is not None:
                os.environ[name] = value


def writes_of(tmp_path, *args) -> list[str]:
    """What each write of a command is, in order (its journal), checking that it succeeds."""
    journal = tmp_path / "journal.txt"
    result = invoke(*args, journal=journal)
    assert result.exit_code == 0, result.output + result.stderr
    lines = journal.read_text().splitlines()
    journal.unlink()
    assert [int(line.split()[0]) for line in lines] == list(range(1, len(lines) + 1))
    return [line.split(" ", 1)[1] for line in lines]


def chosen(writes: list[str]) -> list[tuple[int, str, str]]:
    """(k, what, kind) for the first and last write of each kind (frames of any step are one kind,
    figures another), and the last write; the error kinds alternate."""
    first, last = {}, {}
    for k, what in enumerate(writes, 1):
        kind = re.sub(r"\d+", "N", what) if not what.endswith((".png", ".pdf")) else "figure"
        first.setdefault(kind, k)
        last[kind] = k
    ks = sorted({*first.values(), *last.values(), len(writes)})
    return [(k, writes[k - 1], ("ENOSPC", "EIO")[i % 2]) for i, k in enumerate(ks)]


def assert_one_line_failure(result, kind: str, what: str) -> str:
    """Exit 5, no traceback, and one error line naming the error and the file; returns the line."""
    assert result.exit_code == EXIT_OUTPUT, (result.exit_code, result.output, result.stderr, result.exception)
    errors = [line for line in result.stderr.splitlines() if line.startswith("decco-warp")]
    assert len(errors) == 1, result.stderr
    assert "Traceback" not in result.stderr + result.output
    line = errors[0]
    assert KINDS[kind] in line and f"writing {what.split()[0]}" in line, line
    return line


def assert_no_leftovers(folder: Path) -> None:
    """No temporary file of an atomic write is left behind."""
    assert not [p for p in folder.rglob(".*.tmp")], list(folder.rglob(".*.tmp"))


# --- simulate and resume --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted run, its trajectory, and the journal of its writes."""
    out = tmp_path_factory.mktemp("reference")
    writes = writes_of(out, "simulate", "--name", "r", "--out", out, *RUN)
    return dw.read_trajectory(out / "r" / "trajectory.h5"), writes, out / "r"


def test_simulate_fails_cleanly_at_each_kind_of_write_and_resumes_bit_for_bit(reference, tmp_path):
    straight, writes, _ = reference
    assert {"spec.toml", "run.log", "trajectory.h5", "checkpoint.h5"} <= {w.split()[0] for w in writes}
    for k, what, kind in chosen(writes):
        out = tmp_path / f"k{k}"
        args = ["simulate", "--name", "f", "--out", out, *RUN]
        line = assert_one_line_failure(invoke(*args, fail=f"{k}:{kind}"), kind, what)
        run_dir = out / "f"
        assert_no_leftovers(out)
        kept = re.search(r"the checkpoint of step (\d+) is intact", line)
        if kept:  # the checkpoint and the frames before it are whole
            assert read_checkpoint(run_dir / "checkpoint.h5")[0]["step"] == int(kept[1])
            assert dw.read_trajectory(run_dir / "trajectory.h5")["step"][0] == 0
            again = invoke("resume", run_dir, "--device", "cpu")
        else:  # before the first checkpoint: nothing kept, the same command starts again
            assert "nothing of it is kept" in line and "run the same command again" in line, line
            assert not any(run_dir.iterdir())
            again = invoke(*args)
        assert again.exit_code == 0, (k, what, again.stderr)
        assert_same_run(straight, dw.read_trajectory(run_dir / "trajectory.h5"))


@pytest.fixture(scope="module")
def stopped(reference, tmp_path_factory):
    """A run whose write of its checkpoint at step 200 failed: resumable from step 100."""
    out = tmp_path_factory.mktemp("stopped")
    _, writes, _ = reference
    k = max(k for k, what in enumerate(writes, 1) if what == "checkpoint.h5")
    result = invoke("simulate", "--name", "s", "--out", out, *RUN, fail=f"{k}:ENOSPC")
    assert "the checkpoint of step 100 is intact" in result.stderr
    return out / "s"


def test_resume_fails_cleanly_at_each_kind_of_write_and_resumes_again_bit_for_bit(reference, stopped, tmp_path):
    straight = reference[0]
    probe = tmp_path / "probe"
    shutil.copytree(stopped, probe)
    writes = writes_of(tmp_path, "resume", probe, "--device", "cpu")
    assert_same_run(straight, dw.read_trajectory(probe / "trajectory.h5"))
    for k, what, kind in chosen(writes):
        run_dir = tmp_path / f"k{k}"
        shutil.copytree(stopped, run_dir)
        line = assert_one_line_failure(invoke("resume", run_dir, "--device", "cpu", fail=f"{k}:{kind}"), kind, what)
        assert re.search(r"the checkpoint of step (100|200) is intact", line), line
        assert_no_leftovers(run_dir)
        assert dw.read_trajectory(run_dir / "trajectory.h5")["step"][0] == 0
        again = invoke("resume", run_dir, "--device", "cpu")
        assert again.exit_code == 0, (k, what, again.stderr)
        assert_same_run(straight, dw.read_trajectory(run_dir / "trajectory.h5"))


def test_a_run_folder_removed_underneath_ends_with_exit_5(tmp_path, monkeypatch):
    """The folder vanishes after the first checkpoint: the next write fails, said in one line."""
    from decco_warp import run as runs

    original = runs.write_checkpoint
    calls = []

    def vanish_after_first(path, *args):
        calls.append(path)
        if len(calls) == 2:
            shutil.rmtree(Path(path).parent)
        return original(path, *args)

    monkeypatch.setattr(runs, "write_checkpoint", vanish_after_first)
    result = invoke("simulate", "--name", "gone", "--out", tmp_path, *RUN)
    assert result.exit_code == EXIT_OUTPUT, result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("decco-warp")]
    assert len(errors) == 1 and "No such file or directory" in errors[0] and "no checkpoint is left" in errors[0], result.stderr


# --- analyze ----------------------------------------------------------------------------------------


def _analysis(run_dir: Path) -> tuple[dict, dict]:
    from decco_warp.analysis.runs import read_analysis

    analysis = read_analysis(run_dir / "analysis.h5")
    summary = json.loads((run_dir / "summary.json").read_text())
    for values in (analysis["summary"], summary):
        values.pop("analysis_seconds")
        values.pop("run")  # the folder's name
    return analysis, summary


def test_analyze_fails_cleanly_at_each_kind_of_write_and_the_same_command_finishes(reference, tmp_path):
    source = reference[2]
    clean = tmp_path / "clean"
    shutil.copytree(source, clean)
    args = ["--min-members", "20", "--every", "2", "--device", "cpu"]
    writes = writes_of(tmp_path, "analyze", clean, *args)
    assert {"analysis.h5", "summary.json", "energy.png", "energy.pdf"} <= set(writes)
    expected_analysis, expected_summary = _analysis(clean)
    for k, what, kind in chosen(writes):
        run_dir = tmp_path / f"k{k}"
        shutil.copytree(source, run_dir)
        trajectory = (run_dir / "trajectory.h5").read_bytes()
        line = assert_one_line_failure(invoke("analyze", run_dir, *args, fail=f"{k}:{kind}"), kind, what)
        assert "the runs are untouched" in line
        assert_no_leftovers(run_dir)
        assert (run_dir / "trajectory.h5").read_bytes() == trajectory
        assert not list(run_dir.rglob(what))  # the failed file was never half-written
        again = invoke("analyze", run_dir, *args)
        assert again.exit_code == 0, again.stderr
        analysis, summary = _analysis(run_dir)
        assert summary == expected_summary
        for group, values in expected_analysis.items():
            for key, value in values.items():
                floats = np.asarray(value).dtype.kind == "f"
                assert np.array_equal(analysis[group][key], value, equal_nan=floats), (group, key)


# --- pile, piles, bench --json, view --save -------------------------------------------------------

PILE = ["--particles", "12", "--seed", "9", "--dt", "0.2", "--ke-threshold", "1e-4", "--device", "cpu"]


def _same_pile(a, b) -> None:
    for name in ("positions", "velocities", "omegas", "radii", "masses", "size_class"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_pile_and_piles_fail_cleanly_and_the_same_command_finishes(tmp_path):
    reference = tmp_path / "reference.h5"
    assert writes_of(tmp_path, "pile", "--out", reference, *PILE) == ["reference.h5"]
    # Stopped at its step limit, the formation is saved first: a failed save keeps nothing.
    line = assert_one_line_failure(invoke("pile", "--out", tmp_path / "p.h5", *PILE, "--max-steps", "100", fail="1:EIO"), "EIO", "p.h5.forming")
    assert "nothing of" in line and "run the same command again" in line, line
    line = assert_one_line_failure(invoke("pile", "--out", tmp_path / "p.h5", *PILE, fail="1:ENOSPC"), "ENOSPC", "p.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["reference.h5"]
    assert invoke("pile", "--out", tmp_path / "p.h5", *PILE).exit_code == 0
    _same_pile(dw.load_pile(tmp_path / "p.h5"), dw.load_pile(reference))

    listing = tmp_path / "piles.toml"
    entry = 'particles = 12\nseed = 9\ndt = 0.2\nke_threshold = 1e-4\n'
    listing.write_text(f'[[pile]]\nout = "{tmp_path}/a.h5"\n{entry}\n[[pile]]\nout = "{tmp_path}/b.h5"\n{entry}')
    line = assert_one_line_failure(invoke("piles", listing, "--device", "cpu", fail="2:ENOSPC"), "ENOSPC", "b.h5")
    _same_pile(dw.load_pile(tmp_path / "a.h5"), dw.load_pile(reference))  # the first pile is whole
    assert not (tmp_path / "b.h5").exists()
    again = invoke("piles", listing, "--device", "cpu")
    assert again.exit_code == 0 and "a.h5: exists, skipped" in again.output
    _same_pile(dw.load_pile(tmp_path / "b.h5"), dw.load_pile(reference))
    assert_no_leftovers(tmp_path)


def test_bench_json_and_view_save_fail_cleanly_leaving_what_was_there(reference, tmp_path):
    table = tmp_path / "bench.json"
    table.write_text("earlier")
    bench = ["bench", "--n", "64", "--steps", "1", "--seconds", "0.01", "--device", "cpu", "--json", table]
    line = assert_one_line_failure(invoke(*bench, fail="1:EIO"), "EIO", "bench.json")
    assert "is not written" in line and table.read_text() == "earlier"
    pytest.importorskip("rerun")
    recording = tmp_path / "r.rrd"
    line = assert_one_line_failure(invoke("view", reference[2], "--save", recording, fail="1:ENOSPC"), "ENOSPC", "r.rrd")
    assert not recording.exists()
    assert_no_leftovers(tmp_path)
    assert invoke("view", reference[2], "--save", recording).exit_code == 0 and recording.stat().st_size > 1000


# --- a real full disk ---------------------------------------------------------------------------------


LONG = ["--steps", "600", "--output-every", "50", "--checkpoint-every", "100", "--device", "cpu"]
#: The CLI with the room check before each frame turned off: HDF5 itself then meets the full disk.
NO_ROOM_CHECK = "import decco_warp.io as io; io.check_space = lambda *args: None; from decco_warp.cli import main_entry; main_entry()"


@pytest.fixture(scope="module")
def long_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("long")
    result = cli("simulate", "--name", "r", "--out", str(out), *LONG)
    assert result.returncode == 0, result.stderr
    return out / "r"


@pytest.mark.skipif(os.geteuid() != 0 or shutil.which("mount") is None, reason="mounting a tmpfs needs root")
@pytest.mark.parametrize("room_check", [True, False], ids=["refused-before-a-frame", "inside-hdf5"])
def test_a_real_full_disk_ends_with_exit_5_and_resume_finishes_bit_for_bit(long_run, room_check, tmp_path):
    """A run on a 3 MiB tmpfs that fills half-way: a separate process meeting the kernel's ENOSPC,
    either before a frame (the room check) or inside HDF5 (the crash of exit 139 before), then
    space is freed and the run resumed."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(disk)], capture_output=True).returncode != 0:
        pytest.skip("tmpfs cannot be mounted here")
    try:
        size = sum(p.stat().st_size for p in long_run.iterdir())
        stats = os.statvfs(disk)
        filler = disk / "filler"
        # Room for about half of the run; without the room check, checkpoints (which cannot fail
        # inside HDF5: they are made in memory) are rare, so that a frame meets the full disk.
        room = 0.8 * size + durable.FRAME_HEADROOM if room_check else 0.7 * size
        filler.write_bytes(b"\0" * int(stats.f_bavail * stats.f_frsize - room))
        command = [sys.executable, "-c", NO_ROOM_CHECK if not room_check else "from decco_warp.cli import main_entry; main_entry()"]
        options = LONG if room_check else [*LONG, "--checkpoint-every", "300"]
        full = subprocess.run([*command, "simulate", "--name", "f", "--out", str(disk), *options], capture_output=True, text=True)
        assert full.returncode == EXIT_OUTPUT, full.stderr
        errors = [line for line in full.stderr.splitlines() if line.startswith("decco-warp")]
        assert len(errors) == 1 and "No space left on device writing trajectory.h5" in errors[0], full.stderr
        assert "Traceback" not in full.stderr, full.stderr
        kept = int(re.search(r"the checkpoint of step (\d+) is intact", errors[0])[1])
        assert read_checkpoint(disk / "f" / "checkpoint.h5")[0]["step"] == kept < 600
        assert dw.read_trajectory(disk / "f" / "trajectory.h5")["step"][0] == 0
        filler.unlink()
        resumed = cli("resume", str(disk / "f"), "--device", "cpu")
        assert resumed.returncode == 0, resumed.stderr
        assert_same_run(dw.read_trajectory(long_run / "trajectory.h5"), dw.read_trajectory(disk / "f" / "trajectory.h5"))
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def test_a_frame_cut_off_inside_hdf5_is_abandoned_unclosed_and_the_file_stays_readable(tmp_path, monkeypatch):
    """HDF5 failing half-way through a frame (as on a full disk, not through the write hook): the
    file is never closed again (closing such a file can crash), and what was flushed reads back."""
    state = dw.State.from_arrays(np.zeros((4, 3)), np.zeros((4, 3)), np.zeros((4, 3)), np.full(4, 1e5), np.full(4, 1e15))
    frame = {"position": np.ones((4, 3)), "velocity": np.zeros((4, 3)), "omega": np.zeros((4, 3)), "stress": np.zeros(4)}
    trajectory = dio.Trajectory.create(tmp_path / "t.h5", state, {"e": 1.0}, {"spec": {}})
    trajectory.append(0, 0.0, frame, {"e": 1.0})
    original = dio.Trajectory._append
    calls = []

    def cut_off(datasets, step, time, value):
        calls.append(step)
        if len(calls) > 1:  # as h5py reports HDF5's failed write
            raise RuntimeError("Can't write data (file write failed: errno = 28, error message = 'No space left on device')")
        original(datasets, step, time, value)

    monkeypatch.setattr(dio.Trajectory, "_append", staticmethod(cut_off))
    before = len(durable.ABANDONED)
    with pytest.raises(OSError) as raised:
        trajectory.append(10, 1.0, frame, {"e": 2.0})
    assert raised.value.errno == errno.ENOSPC and raised.value.filename == str(tmp_path / "t.h5")
    assert len(durable.ABANDONED) == before + 1 and trajectory.broken
    trajectory.close()  # never closes an abandoned file
    with pytest.raises(OSError, match="earlier write"):
        trajectory.append(20, 2.0, frame, {"e": 3.0})
    read = subprocess.run(  # another process, as a reader would be (this one still holds the file open)
        [sys.executable, "-c", f"import decco_warp as dw; print(dw.read_trajectory({str(tmp_path / 't.h5')!r})['step'].tolist())"],
        capture_output=True, text=True,
    )  # fmt: skip
    assert read.stdout.strip() == "[0]", read.stderr
    # HDF5 itself is whole here (the failure was made up): close it, and leave this process with no
    # abandoned file, which would end the in-process CLI calls of later tests with os._exit.
    durable.ABANDONED.remove(trajectory.file)
    trajectory.file.close()


# --- sweep --------------------------------------------------------------------------------------------

SWEEP = """
[sweep]
name = "grid"
out = "{out}"
min_members = 20
[sweep.grid]
"collision.eta" = [0.5]
[run]
steps = 200
output_every = 50
checkpoint_every = 100
device = "cpu"
"""


def test_a_sweep_whose_writes_fail_ends_with_exit_5_and_runs_again_to_the_end(reference, tmp_path):
    """The first write of every process of the sweep fails: the run's on its worker (its spec.toml),
    and the sweep's own (summary.csv).  Run again, the sweep finishes its run as if never stopped."""
    pytest.importorskip("distributed")
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path))
    failed = cli("sweep", str(path), "--workers", "1", "--analysis-workers", "1", env={**os.environ, "DECCO_TEST_FAIL_WRITE": "1:ENOSPC"})
    assert failed.returncode == EXIT_OUTPUT, failed.stderr
    errors = [line for line in failed.stderr.splitlines() if line.startswith("decco-warp")]
    assert len(errors) == 1 and "Traceback" not in failed.stderr, failed.stderr
    assert "No space left on device" in errors[0] and "writing summary.csv" in errors[0] and "run the sweep again" in errors[0], errors[0]
    again = cli("sweep", str(path), "--workers", "1", "--analysis-workers", "1")
    assert again.returncode == 0, again.stderr
    run_dir = next((tmp_path / "grid").glob("*/checkpoint.h5")).parent
    assert json.loads((run_dir / "summary.json").read_text())["steps"] == 200
    assert read_checkpoint(run_dir / "checkpoint.h5")[0]["step"] == 200
    assert_no_leftovers(tmp_path / "grid")


# --- analyze of a live run -------------------------------------------------------------------------


def _paused_run(tmp_path, name: str, phase: str = "step@150"):
    """A run (RUN's options) started in another process and held at ``phase`` until its mark is removed."""
    mark = tmp_path / f"{name}.paused"
    env = dict(os.environ, DECCO_TEST_PAUSE=phase, DECCO_TEST_PAUSE_MARK=str(mark))
    process = subprocess.Popen(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "simulate", "--name", name, "--out", str(tmp_path), *RUN],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    deadline = time.time() + 120
    while not mark.exists() and time.time() < deadline and process.poll() is None:
        time.sleep(0.05)
    assert mark.exists(), "the run never reached the pause"
    return process, mark, tmp_path / name


def test_analyze_of_a_live_run_reads_its_frames_so_far_and_leaves_the_writer_untouched(reference, tmp_path):
    from decco_warp.analysis.runs import read_analysis
    from decco_warp.lock import AnalysisLock

    writer, mark, run_dir = _paused_run(tmp_path, "live")
    try:
        result = invoke("analyze", run_dir, "--min-members", "20", "--device", "cpu")
        assert result.exit_code == 0, result.stderr
        assert "still running: the 3 frames written so far, to step 100" in result.output
        assert read_analysis(run_dir / "analysis.h5")["frames"]["step"].tolist() == [0, 50, 100]
        assert_no_leftovers(run_dir)
        with AnalysisLock(run_dir):  # another analysis of the run is going on: refused
            second = invoke("analyze", run_dir, "--device", "cpu")
        assert second.exit_code == 2 and "is being analysed by pid" in second.stderr, second.stderr
    finally:
        mark.unlink()
    assert writer.wait(timeout=120) == 0, writer.stderr.read()
    assert_same_run(reference[0], dw.read_trajectory(run_dir / "trajectory.h5"))
    assert read_checkpoint(run_dir / "checkpoint.h5")[0]["step"] == 200
    assert not (run_dir / ".analysis.lock").exists()


def test_analyze_follow_analyses_again_as_frames_arrive_until_the_run_ends(reference, tmp_path):
    from decco_warp.analysis.runs import read_analysis

    writer, mark, run_dir = _paused_run(tmp_path, "followed")
    follower = subprocess.Popen(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "analyze", str(run_dir), "--follow",
         "--poll", "0.2", "--min-members", "20", "--device", "cpu"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        deadline = time.time() + 120
        while not (run_dir / "analysis.h5").exists() and time.time() < deadline and follower.poll() is None:
            time.sleep(0.05)
        assert read_analysis(run_dir / "analysis.h5")["frames"]["step"].tolist() == [0, 50, 100]
    finally:
        mark.unlink()
    assert writer.wait(timeout=120) == 0
    out, err = follower.communicate(timeout=120)
    assert follower.returncode == 0, err
    assert "analysed to step 100; following the run" in err and "still running" not in out, (out, err)
    assert read_analysis(run_dir / "analysis.h5")["frames"]["step"].tolist() == [0, 50, 100, 150, 200]
    assert_same_run(reference[0], dw.read_trajectory(run_dir / "trajectory.h5"))

"""Bad input: one writer per run folder, damaged piles refused up front (physically wrong ones and
damaged files of every kind, hypothesis), destinations checked before any work, blow-ups
explained, and a property-based fuzz of the whole CLI."""

import contextlib
import dataclasses
import io
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from helpers import cli
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import decco_warp as dw
from decco_warp.forming import read_partial
from decco_warp import spec as specs
from decco_warp.io import FileFormatError, load_pile, read_checkpoint, save_pile
from decco_warp.record import RunRecord
from decco_warp.run import OverlapWatch, RunError, builtin_pile, likely_cause, prepare_start
from decco_warp.stability import StabilityReport

# --- one writer per run folder --------------------------------------------------------------------


def test_a_run_folder_in_use_refuses_every_other_writer_until_its_holder_dies(tmp_path):
    args = ["simulate", "--name", "lk", "--out", str(tmp_path), "--steps", "200000", "--output-every", "100",
            "--checkpoint-every", "200", "--device", "cpu"]  # fmt: skip
    process = subprocess.Popen(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", *args],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    run_dir = tmp_path / "lk"
    try:
        deadline = time.time() + 120
        while time.time() < deadline and "checkpoint: step 200" not in _text(run_dir / "run.log"):
            time.sleep(0.05)
        busy = f"run folder {run_dir} is in use by pid {process.pid} on {socket.gethostname()}"
        before = (run_dir / "spec.toml").read_text()
        for attempt in (
            ["resume", str(run_dir), "--device", "cpu"],
            ["simulate", "--name", "lk", "--out", str(tmp_path), "--overwrite", "--steps", "100", "--device", "cpu"],
        ):  # (analyze reads a live run: tests/test_faults.py)
            result = cli(*attempt)
            assert result.returncode == 2, (attempt, result.stderr)
            assert busy in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert process.poll() is None and (run_dir / "spec.toml").read_text() == before
    finally:
        process.kill()
        process.wait()
    # SIGKILL released the lock: nothing stale to clean, resume goes on.
    step = int(read_checkpoint(run_dir / "checkpoint.h5")[0]["step"])
    result = cli("resume", str(run_dir), "--steps", str(step + 100), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    assert not (run_dir / ".lock").exists()


def _text(path: Path) -> str:
    return path.read_text() if path.exists() else ""


def test_a_sweep_started_twice_is_refused(tmp_path):
    from decco_warp.lock import RunFolderLock

    folder = tmp_path / "grid"
    folder.mkdir()
    spec = tmp_path / "s.toml"
    spec.write_text(f'[sweep]\nname = "grid"\nout = "{tmp_path}"\n[sweep.grid]\n"collision.eta" = [0.5]\n')
    with RunFolderLock(folder):  # as a running sweep holds it
        result = cli("sweep", str(spec))
    assert result.returncode == 2 and f"sweep folder {folder} is in use by pid {os.getpid()}" in result.stderr


# --- damaged piles, refused before any folder is made -----------------------------------------------


def _pile_with(tmp_path, name, change):
    pile = dw.load_pile(builtin_pile("projectile"))
    change(pile)
    path = tmp_path / f"{name}.h5"
    save_pile(pile, path)
    return path


@pytest.mark.parametrize(
    "name, change, message",
    [
        ("same-place", lambda p: p.positions.__setitem__(7, p.positions[3]), r"particles 3 and 7 overlap by \S+ of the smaller radius \(at the same place"),
        ("nearly", lambda p: p.positions.__setitem__(7, p.positions[3] + [0.0, 0.0, 0.3 * p.radii[[3, 7]].min()]), r"particles 3 and 7 .*nearly at the same place"),
        ("tiny", lambda p: (p.radii.__imul__(1e-9), p.masses.__imul__(1e-27)), r"radius \S+ cm, outside 1 cm to 1e\+08 cm"),
        ("heavy", lambda p: p.masses.__setitem__(slice(None), 1e40), r"a density of \S+ g/cm\^3, outside 0.1 to 30"),
        ("far", lambda p: p.positions.__iadd__(1e14), r"position of \S+ cm, beyond 1e\+13"),
    ],
)
def test_damaged_piles_are_refused_up_front_with_the_reason(tmp_path, name, change, message):
    import re

    pile = _pile_with(tmp_path, name, change)
    out = tmp_path / "out"
    result = cli("simulate", "--projectile", str(pile), "--out", str(out), "--device", "cpu")
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and re.search(message, result.stderr), result.stderr
    assert not out.exists()


@pytest.fixture(scope="module")
def good_pile(tmp_path_factory):
    path = tmp_path_factory.mktemp("pile") / "good.h5"
    save_pile(load_pile(builtin_pile("projectile")), path)
    return path


_damage = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0.0, 0.999)),
    st.tuples(st.just("nan"), st.sampled_from(["positions", "velocities", "omegas", "radii", "masses"])),
    st.tuples(st.just("negative"), st.sampled_from(["radii", "masses"])),
    st.tuples(st.just("delete"), st.sampled_from(["pile/positions", "pile/radii", "pile/size_class", "pile"])),
    st.tuples(st.just("reshape"), st.sampled_from(["positions", "radii", "velocities"])),
    st.tuples(st.just("format"), st.text(st.characters(blacklist_characters="\x00"), max_size=8)),
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(_damage, st.integers(0, 149))
def test_damaged_pile_files_are_refused_with_a_reason(good_pile, tmp_path, damage, index):
    good_pile_bytes = good_pile.read_bytes()
    path = tmp_path / "damaged.h5"
    path.write_bytes(good_pile_bytes)
    kind, what = damage
    if kind == "truncate":
        path.write_bytes(good_pile_bytes[: int(what * len(good_pile_bytes))])
    else:
        with h5py.File(path, "r+") as f:
            if kind == "nan":
                data = f["pile"][what][()].astype(float)
                data[index] = np.nan
                del f["pile"][what]
                f["pile"][what] = data
            elif kind == "negative":
                f["pile"][what][index] = -1.0
            elif kind == "delete":
                del f[what]
            elif kind == "reshape":
                data = f["pile"][what][()]
                del f["pile"][what]
                f["pile"][what] = data[:-1]
            else:
                f.attrs["format"] = what
    with pytest.raises(FileFormatError) as raised:
        load_pile(path)
    assert str(raised.value) and "\n" not in str(raised.value)


def test_a_damaged_pile_through_the_cli_is_exit_2_and_writes_nothing(good_pile, tmp_path):
    good_pile_bytes = good_pile.read_bytes()
    pile = tmp_path / "bad.h5"
    pile.write_bytes(good_pile_bytes[: len(good_pile_bytes) // 2])
    out = tmp_path / "out"
    result = cli("simulate", "--projectile", str(pile), "--out", str(out), "--device", "cpu")
    assert result.returncode == 2 and len(result.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_settled_piles_pass_the_checks():
    for path in [builtin_pile("target"), builtin_pile("projectile"), *sorted(Path("runs/paper/piles").glob("*.h5"))]:
        dw.load_pile(path)  # raises if refused


# --- destinations checked before any work -----------------------------------------------------------


def test_every_writing_command_refuses_an_unwritable_destination_up_front(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    through = blocker / "sub"
    listing = tmp_path / "piles.toml"
    listing.write_text(f'[[pile]]\nout = "{tmp_path}/ok.h5"\nparticles = 10\n\n[[pile]]\nout = "{through}/p.h5"\nparticles = 10\n')
    sweep = tmp_path / "s.toml"
    sweep.write_text(f'[sweep]\nname = "g"\nout = "{through}"\n[sweep.grid]\n"collision.eta" = [0.5]\n')
    run_dir = _finished_run(tmp_path)
    for args in (
        ["pile", "--particles", "10", "--out", str(through / "p.h5"), "--device", "cpu"],
        ["piles", str(listing), "--device", "cpu"],
        ["simulate", "--out", str(through), "--steps", "10", "--device", "cpu"],
        ["view", str(run_dir), "--save", str(through / "r.rrd")],
        ["sweep", str(sweep)],
        ["bench", "--n", "8", "--json", str(through / "b.json"), "--device", "cpu"],
        ["pile", "--particles", "10", "--out", str(tmp_path), "--overwrite", "--device", "cpu"],  # a folder
    ):
        result = cli(*args)
        assert result.returncode == 2, (args, result.stderr)
        assert "cannot write the" in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
        if args[0] == "simulate":  # says which part of the path is in the way
            assert f"{blocker} is not a writable folder" in result.stderr, result.stderr
    assert blocker.read_text() == "not a folder" and not (tmp_path / "ok.h5").exists()


@pytest.mark.parametrize("kernel", ["/proc", "/sys"])
def test_a_destination_on_the_kernel_s_file_systems_is_refused_in_one_line_before_any_work(tmp_path, kernel):
    """/proc and /sys are the kernel's (proc, sysfs): os.access() lets root write there and the
    folder fails only once created (a traceback under /sys, exit 5 without a path under /proc,
    after the progress bar).  Refused by the up-front check: one line, exit 2, nothing drawn."""
    from decco_warp.checks import mount_of

    if mount_of(kernel)[1] not in ("proc", "sysfs"):
        pytest.skip(f"{kernel} is not the kernel's file system here")
    for args in (["simulate", "--out", f"{kernel}/decco", "--steps", "10", "--device", "cpu"],
                 ["pile", "--particles", "10", "--out", f"{kernel}/decco.h5", "--device", "cpu"]):  # fmt: skip
        result = cli(*args)
        assert result.returncode == 2 and result.stdout == "", (args, result.stderr)
        assert result.stderr.strip().splitlines() == [result.stderr.strip()] and "Traceback" not in result.stderr
        assert f"{kernel} is the kernel's {mount_of(kernel)[1]} file system" in result.stderr and f"{kernel}/decco" in result.stderr


def test_unwritable_output_folder_is_refused_before_any_work(tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):
            pytest.skip("running as a user who can write anywhere")
        spec = specs.resolve_spec({"run": {"out": str(locked / "runs"), "device": "cpu"}})
        with pytest.raises(RunError, match="cannot write the run folder"):
            prepare_start(spec)
    finally:
        locked.chmod(0o700)


_FINISHED: dict = {}


def _finished_run(tmp_path_factory_dir) -> Path:
    """A short finished run (built once per session, copied where asked)."""
    if "run" not in _FINISHED:
        out = Path(tmp_path_factory_dir) / "finished"
        assert cli("simulate", "--steps", "100", "--output-every", "50", "--out", str(out), "--device", "cpu").returncode == 0
        _FINISHED["run"] = out / "default"
    return _FINISHED["run"]


# --- blow-ups name their likely cause ---------------------------------------------------------------


def _report(dt_margin):
    return StabilityReport(stiffness_margin=5.0, time_step_margin=dt_margin, k_needed=2e17, dt_scale=0.04 * dt_margin,
                           v_max=1e5, k_in=1e18, dt=0.04)  # fmt: skip


def test_blow_up_causes_are_named_from_what_the_run_saw():
    def watch(depth):
        record = RunRecord()
        w = OverlapWatch(record, None, lambda line: None)
        w.see(800, {"deepest_overlap": depth, "deepest_overlap_pair": np.array([4, 9])})
        return w, record

    w, record = watch(0.1)
    coincident = dataclasses.replace(record, start_overlap=2.0, start_overlap_pair=(3, 7))
    assert "particles 3 and 7 started 2 of the smaller radius into each other" in likely_cause(_report(50.0), w, coincident)
    assert "dt = 0.04 s is too long" in likely_cause(_report(2.0), w, record)
    deep, record = watch(1.4)
    cause = likely_cause(_report(50.0), deep, record)
    assert "too soft" in cause and "1.4 of the smaller radius at step 800 (particles 4 and 9)" in cause
    assert "no cause stands out" in likely_cause(_report(50.0), w, record)


# --- a property-based fuzz of the whole command line ------------------------------------------------

def _one_fault_at_a_time(valid: dict, faults: dict, required: dict | None = None):
    """Options drawn from valid values, then at most one replaced by a faulty value: every
    refusal path gets its turn while most runs still go through."""
    flags = {flag: st.sampled_from(values) if values else st.none() for flag, values in valid.items()}
    options = st.fixed_dictionaries({k: st.sampled_from(v) for k, v in (required or {}).items()}, optional=flags)
    fault = st.sampled_from([(flag, value) for flag, values in faults.items() for value in values])
    return st.tuples(options, st.one_of(st.none(), fault)).map(lambda drawn: {**drawn[0], **dict([drawn[1]] if drawn[1] else [])})


_simulate = _one_fault_at_a_time(
    valid={
        "--steps": ["1", "20", "120"], "--dt": ["0.04", "0.02", "auto"], "--eta": ["0.5", "3"], "--speed": ["1e5"],
        "--theta": ["0", "22", "89.9"], "--k-in": ["auto", "1e18"], "--output-every": ["1", "20", "50"],
        "--checkpoint-every": ["1", "50"], "--precision": ["mixed", "float64"], "--max-overlap": ["0.5", "1e-9"],
        "--gap": ["0", "1e5"], "--name": ["run", "r-1.2", "fresh"], "--spin-target": ["0.5,+z", "0.5"],
        "--projectile": ["builtin:projectile"], "--check": [], "--overwrite": [],
    },
    faults={
        "--steps": ["-5", "0", "x"], "--dt": ["5", "0", "-1", "x"], "--eta": ["-1", "0", "nan", "inf", "1e9", ""],
        "--theta": ["90", "-5", "abc"], "--k-in": ["-3", "soft", "1e12"], "--output-every": ["0", "-1"],
        "--precision": ["half"], "--max-overlap": ["0", "-1"], "--gap": ["-1", "nan"],
        "--name": ["a b", "../up", "", ".hidden"], "--spin-target": ["2,+q", "x"], "--speed": ["1e12", "-3", "0"],
        "--projectile": ["builtin:nope", "missing.h5", "@damaged", "@coincident"],
    },
)  # fmt: skip
_pile = _one_fault_at_a_time(
    required={"--out": ["@out/p.h5"], "--particles": ["2", "8"], "--max-steps": ["1", "200", "3000"]},  # bounded
    valid={"--seed": ["1", "7"], "--radii": ["1e6", "1e6,2e6"], "--dt": ["0.2", "0.04"], "--ke-threshold": ["1e-2"],
           "--fill": ["0.3", "0.1"], "--overwrite": []},
    faults={"--out": ["@file/p.h5", "@out"], "--particles": ["-3", "0", "1", "x"], "--seed": ["x"],
            "--radii": ["0", "abc", "1e-3", ""], "--dt": ["0", "-1"], "--ke-threshold": ["0", "2"], "--fill": ["0", "1.5"]},
)  # fmt: skip
_other = st.one_of(
    st.tuples(st.just("analyze"), st.sampled_from(["@run", "@out", "@file", "missing"]), st.sampled_from([[], ["--every", "0"], ["--every", "3"], ["--min-members", "-1"], ["--device", "cpu"], ["--device", "bogus"], ["--device", "cuda:7"]])),
    st.tuples(st.just("resume"), st.sampled_from(["@run", "@out", "missing"]), st.sampled_from([[], ["--steps", "10"], ["--steps", "x"]])),
    st.tuples(st.just("view"), st.sampled_from(["@run", "missing"]), st.sampled_from([["--save", "@out/r.rrd"], ["--save", "@file/r.rrd"], ["--mode", "bogus"]])),
    st.tuples(st.just("export"), st.sampled_from(["@run", "@out", "@file", "missing"]), st.sampled_from([["--xdmf"], []])),
    st.tuples(st.just("bench"), st.just(""), st.sampled_from([["--n", "8", "--seconds", "0.01", "--steps", "2"], ["--n", "0"], ["--n", "x"], ["--seconds", "-1"], ["--layouts", "2:2"], ["--json", "@file/b.json"]])),
    st.tuples(st.just("sweep"), st.sampled_from(["@bad-sweep", "missing.toml", "@not-toml"]), st.just([])),
    st.tuples(st.just("piles"), st.sampled_from(["@bad-piles", "missing.toml", "@not-toml"]), st.just([])),
    st.tuples(st.just("info"), st.just(""), st.sampled_from([[], ["--device", "cuda:7"], ["--device", "bogus"]])),
)  # fmt: skip


def _invoke(args) -> tuple[int, str]:
    """The console entry in this process (kernels compiled once): (exit code, stderr). Any exception
    other than SystemExit propagates, and fails the test: a traceback is never an answer."""
    from decco_warp.cli import main_entry

    err = io.StringIO()
    argv = sys.argv
    sys.argv = ["decco-warp", *args]
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            main_entry()
    except SystemExit as done:
        return int(done.code or 0), err.getvalue()
    finally:
        sys.argv = argv
    return 0, err.getvalue()


@pytest.fixture(scope="module")
def arena(tmp_path_factory):
    """Files the fuzz points at: a finished run, a damaged and a coincident pile, bad TOML files."""
    root = tmp_path_factory.mktemp("arena")
    run = _finished_run(root)
    (root / "file").write_text("a file, not a folder")
    (root / "damaged.h5").write_bytes(builtin_pile("projectile").read_bytes()[:5000])
    _pile_with(root, "coincident", lambda p: p.positions.__setitem__(7, p.positions[3]))
    (root / "bad-sweep.toml").write_text('[sweep]\nname = "x y"\n[sweep.grid]\n"collision.eta" = [1]\n')
    (root / "bad-piles.toml").write_text('[[pile]]\nout = "x.h5"\nparticles = "many"\n')
    (root / "not-toml.toml").write_text("[[[")
    return root, run


def _resolve(value: str, root: Path, out: Path, run: Path) -> str:
    places = {"@out": out, "@file": root / "file", "@run": run, "@damaged": root / "damaged.h5",
              "@coincident": root / "coincident.h5", "@bad-sweep": root / "bad-sweep.toml",
              "@bad-piles": root / "bad-piles.toml", "@not-toml": root / "not-toml.toml"}  # fmt: skip
    for key, place in places.items():
        if value == key or value.startswith(key + "/"):
            return str(place) + value[len(key):]
    return value


def _args(command, options: dict, root, out, run) -> list[str]:
    args = [command]
    for flag, value in options.items():
        args += [flag] if value is None else [flag, _resolve(value, root, out, run)]
    return args


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.one_of(st.tuples(st.just("simulate"), _simulate), st.tuples(st.just("pile"), _pile), _other))
def test_fuzz_every_command_ends_with_a_documented_exit_code_and_no_half_written_folder(arena, tmp_path_factory, case):
    root, finished = arena
    out = tmp_path_factory.mktemp("out")
    run = out / "run"
    shutil.copytree(finished, run)
    if case[0] in ("simulate", "pile"):
        command, options = case
        options = dict(options)
        if command == "simulate":
            options.update({"--out": "@out", "--device": "cpu"})
            options.setdefault("--steps", "40")
        else:
            options.update({"--device": "cpu"})
        args = _args(command, options, root, out, run)
    else:
        command, target, extra = case
        args = [command] + ([_resolve(target, root, out, run)] if target else []) + [_resolve(v, root, out, run) for v in extra]
        if command == "bench":
            args += ["--device", "cpu"]
    before = {p.name for p in out.iterdir()}
    code, stderr = _invoke(args)
    assert code in (0, 1, 2, 3, 4, 5), (args, code, stderr)
    assert "Traceback" not in stderr, (args, stderr)
    if code in (1, 2):  # nothing run, nothing written, but for a pile past --max-steps: its formation, to continue
        left = {p.name for p in out.iterdir()} - before
        if code == 1 and args[0] == "pile":
            assert all(name.endswith(".forming") for name in left), (args, stderr)
            for name in left:
                read_partial(out / name)
        else:
            assert not left, (args, stderr)
        assert stderr.strip() and stderr.strip().splitlines()[-1].startswith("decco-warp"), (args, stderr)
    for folder in out.iterdir():  # every run folder left is whole
        if folder.is_dir() and (folder / "spec.toml").exists():
            assert {"trajectory.h5", "checkpoint.h5", "run.log"} <= {p.name for p in folder.iterdir()}, (args, stderr)
            read_checkpoint(folder / "checkpoint.h5")
            dw.read_trajectory(folder / "trajectory.h5")
            assert not (folder / ".lock").exists()


def test_a_checkpoint_in_the_wrong_units_is_refused_on_resume(tmp_path):
    import h5py

    run_dir = tmp_path / "run"
    shutil.copytree(_finished_run(tmp_path), run_dir)
    with h5py.File(run_dir / "checkpoint.h5", "r+") as f:
        f["state/masses"][...] = f["state/masses"][()] * 1e20  # kg read as g, and then some
    result = cli("resume", str(run_dir), "--steps", "200", "--device", "cpu")
    assert result.returncode == 2 and "a density of" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not (run_dir / ".lock").exists()


def test_files_of_a_newer_decco_warp_are_refused_and_older_checkpoints_resume(tmp_path):
    import h5py

    newer = tmp_path / "newer"
    shutil.copytree(_finished_run(tmp_path), newer)
    with h5py.File(newer / "checkpoint.h5", "r+") as f:
        f.attrs["format_version"] = 99
    result = cli("resume", str(newer), "--steps", "200", "--device", "cpu")
    assert result.returncode == 2 and "format version 99" in result.stderr and "upgrade" in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not (newer / ".lock").exists()

    older = tmp_path / "older"  # decco-warp 0.2: no format version, no stepping time, no overlap history
    shutil.copytree(_finished_run(tmp_path), older)
    with h5py.File(older / "checkpoint.h5", "r+") as f:
        del f.attrs["format_version"]
        for key in ("stepping_seconds", "last_frame_step", "deepest_overlap_since"):
            for place in (f["run"].attrs, f["run"]):
                if key in place:
                    del place[key]
        f["run"].attrs["a_key_of_the_future"] = 7
    wall = read_checkpoint(older / "checkpoint.h5")[2]["wall_seconds"]
    result = cli("resume", str(older), "--steps", "200", "--device", "cpu")
    assert result.returncode == 0, result.stderr
    record = RunRecord.from_checkpoint(read_checkpoint(older / "checkpoint.h5")[2])
    assert record.wall_seconds > wall and record.other.get("a_key_of_the_future") == 7

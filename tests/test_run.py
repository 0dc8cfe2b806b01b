"""Runs: the CLI, run folders, the H5MD trajectory, checkpoints and resume."""

import os
import re
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from helpers import assert_same_run, cli

import decco_warp as dw
from decco_warp import spec as specs
from decco_warp.io import read_checkpoint, save_pile
from decco_warp.run import resume_run, start_run

#: A short run of the shipped default collision.
SHORT = {"steps": 600, "output_every": 100, "checkpoint_every": 200}




def _spec(tmp_path, name="r", **run):
    return specs.resolve_spec({"run": {"name": name, "out": str(tmp_path), "device": "cpu", **SHORT, **run}})


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """The default collision, shortened, run through the CLI."""
    out = tmp_path_factory.mktemp("runs")
    result = cli(
        "simulate", "--steps", "600", "--output-every", "100", "--checkpoint-every", "200", "--out", str(out), "--device", "cpu"
    )
    assert result.returncode == 0, result.stderr
    return out / "default", result


def test_default_simulate_writes_a_complete_run_folder(finished):
    run_dir, result = finished
    assert {p.name for p in run_dir.iterdir()} == {"spec.toml", "trajectory.h5", "trajectory.xdmf", "checkpoint.h5", "run.log"}
    assert str(run_dir) in result.stdout and "trajectory.h5" in result.stdout
    spec = specs.resolve_spec(specs.load_spec_file(run_dir / "spec.toml"))
    assert spec["run"]["steps"] == 600 and spec["piles"]["target"] == "builtin:target"
    # The wall time, and the part of it spent stepping (the rest: frames, checkpoints, output).
    done = re.search(r"done: step 600, .*, ([\d.]+) s wall this session, ([\d.]+) s of it stepping \((\d+) % outside", (run_dir / "run.log").read_text())
    assert done, (run_dir / "run.log").read_text()
    wall, stepping, outside = float(done[1]), float(done[2]), int(done[3])
    assert 0 < stepping <= wall and 0 <= outside <= 100
    # The time outside stepping, by what took it: a part of wall - stepping (rounded to 0.1 s each).
    parts = re.search(r"% outside: observables ([\d.]+) s, trajectory ([\d.]+) s, checkpoints ([\d.]+) s\)", (run_dir / "run.log").read_text())
    assert parts, (run_dir / "run.log").read_text()
    assert sum(float(v) for v in parts.groups()) <= wall - stepping + 0.2
    extra = read_checkpoint(run_dir / "checkpoint.h5")[2]
    assert 0 < extra["stepping_seconds"] < extra["wall_seconds"]
    assert f"{extra['stepping_seconds']:.1f} s of it stepping" in result.stdout


def test_frames_made_while_the_next_steps_run_are_the_frames_made_at_their_stop(tmp_path, monkeypatch):
    """Frames and checkpoints due where no observer, stop request or end is (run.FRAMES_ALONGSIDE)
    are read from the device at their stop and made on the host after the next chunk's launch: the
    trajectory is the one whose frames are all made at their stop, bit for bit, every checkpoint
    written holds the same arrays and record (but for its wall and stepping seconds), and the log is
    the same line for line but for the times; the done line says how long the host worked beside
    the stepping."""
    from decco_warp import run as runs

    logs, trajectories, checkpoints = {}, {}, {True: [], False: []}
    real_write = runs.write_checkpoint
    for alongside in (True, False):

        def keep(path, snapshot, static, extra, mine=checkpoints[alongside]):
            named = {key: re.sub(r"alongside[01]", "RUN", value) if isinstance(value, str) else value for key, value in extra.items()}
            mine.append((snapshot, {key: value for key, value in named.items() if key not in ("wall_seconds", "stepping_seconds")}))
            real_write(path, snapshot, static, extra)

        monkeypatch.setattr(runs, "FRAMES_ALONGSIDE", alongside)
        monkeypatch.setattr(runs, "write_checkpoint", keep)
        result = start_run(_spec(tmp_path, name=f"alongside{int(alongside)}", steps=600, output_every=50, checkpoint_every=200))
        trajectories[alongside] = dw.read_trajectory(result.run_dir / "trajectory.h5")
        logs[alongside] = (result.run_dir / "run.log").read_text()
    assert_same_run(trajectories[True], trajectories[False])
    assert [snap["step"] for snap, _ in checkpoints[True]] == [snap["step"] for snap, _ in checkpoints[False]] == [0, 200, 400, 600]
    for (mine, my_record), (theirs, their_record) in zip(checkpoints[True], checkpoints[False]):
        assert my_record.keys() == their_record.keys()
        for key, value in their_record.items():
            assert np.array_equal(my_record[key], value), key
        for key, values in theirs.items():
            assert np.array_equal(mine[key], values), key
    assert trajectories[True]["step"].tolist() == list(range(0, 601, 50))

    def lines(text):
        words = [re.sub(r"alongside[01]", "RUN", line.split(" ", 1)[1]) for line in text.splitlines()]
        return [re.sub(r"[\d.]+ s\b", "T", line) for line in words if not line.startswith("done:")]

    assert lines(logs[True]) == lines(logs[False])
    assert "frames and checkpoints made on the host while the device stepped" in logs[True].splitlines()[-1]
    assert "made on the host while the device stepped" not in logs[False]


def test_trajectory_follows_h5md_and_round_trips(finished):
    run_dir, _ = finished
    spec = specs.resolve_spec(specs.load_spec_file(run_dir / "spec.toml"))
    with h5py.File(run_dir / "trajectory.h5", "r", swmr=True) as f:
        assert list(f["h5md"].attrs["version"]) == [1, 1]
        assert f["h5md/creator"].attrs["name"] == "decco-warp"
        particles = f["particles/all"]
        n = particles["radius"].shape[0]
        for element in ("position", "velocity", "omega"):
            assert particles[element]["value"].shape == (7, n, 3)
            assert particles[element]["step"][()].tolist() == list(range(0, 601, 100))
            assert particles[element]["value"].maxshape[0] is None and particles[element]["value"].chunks
        assert particles["stress/value"].shape == (7, n)
        np.testing.assert_allclose(particles["position/time"][()], np.arange(7) * 100 * spec["params"]["dt"])
        assert set(np.unique(particles["pile_id"][()])) == {0, 1}
        expected = {
            "kinetic_translational", "kinetic_rotational", "potential", "elastic", "total_energy",
            "dissipated_sliding", "dissipated_rolling", "dissipated_hysteresis", "integration_error",
            "momentum", "angular_momentum", "number_of_contacts", "max_overlap", "stress_share",
            "stress_share_per_area", "stress_share_strain", "deepest_overlap", "deepest_overlap_pair",
        }
        assert set(f["observables"]) == expected
        for name in ("stress_share", "stress_share_per_area", "stress_share_strain"):
            assert f[f"observables/{name}/value"].shape == (7, 3), name
            assert f[f"observables/{name}/value"].attrs["unit"] == "1 (100 N_top / N per size class)", name
        assert f["parameters/spec/collision"].attrs["eta"] == spec["collision"]["eta"]
        assert f["parameters/collision"].attrs["cross_potential"] < 0
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    assert data["particles"]["position"].shape == (7, n, 3)
    assert data["parameters"]["spec"]["params"]["k_in"] == spec["params"]["k_in"]


def test_observables_match_the_recorded_particles(finished):
    run_dir, _ = finished
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    masses = data["static"]["mass"]
    radii = data["static"]["radius"]
    obs = data["observables"]
    for k in (0, 3, 6):
        v = data["particles"]["velocity"][k]
        w = data["particles"]["omega"][k]
        assert obs["kinetic_translational"][k] == pytest.approx(0.5 * np.sum(masses * (v * v).sum(axis=1)), rel=1e-12)
        assert obs["kinetic_rotational"][k] == pytest.approx(0.5 * np.sum(0.4 * masses * radii**2 * (w * w).sum(axis=1)), rel=1e-12)
        np.testing.assert_allclose(obs["momentum"][k], (masses[:, None] * v).sum(axis=0), rtol=1e-12, atol=1e-9 * np.abs(masses[:, None] * v).sum())
    # The books balance at every frame, and momentum stays put.
    books = obs["total_energy"] + obs["dissipated_sliding"] + obs["dissipated_rolling"] + obs["dissipated_hysteresis"] + obs["integration_error"]
    np.testing.assert_allclose(books, obs["total_energy"][0], rtol=1e-10)
    p_scale = np.abs(masses[:, None] * data["particles"]["velocity"][0]).sum()
    assert np.abs(obs["momentum"] - obs["momentum"][0]).max() < 1e-6 * p_scale


def test_stress_shares_of_each_frame_rank_its_recorded_stress_by_each_measure(finished):
    """Each frame's three stress shares are stress_shares of that frame's recorded ``stress`` (the
    largest overlap) and the radii, by overlap, overlap / R^2 and overlap / R; by hand for one frame."""
    import math

    from decco_warp.diagnostics import stress_shares

    run_dir, _ = finished
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    radii, classes = data["static"]["radius"], data["static"]["species"]
    obs, stress = data["observables"], data["particles"]["stress"]
    assert (stress[-1] > 0).sum() > math.ceil(0.01 * len(radii))  # contacts enough to fill the top 1 %
    for name, measure in (("stress_share", "overlap"), ("stress_share_per_area", "per_area"), ("stress_share_strain", "strain")):
        assert obs[name].shape == (7, 3), name
        for k in range(7):
            np.testing.assert_array_equal(obs[name][k], stress_shares(stress[k], classes, 3, radii, measure=measure), err_msg=name)
    # The last frame by hand: the top 1 % of each measure, counted per class.
    top = math.ceil(0.01 * len(radii))
    counts = np.bincount(classes, minlength=3)
    for name, power in (("stress_share", 0), ("stress_share_per_area", 2), ("stress_share_strain", 1)):
        ranked = np.argsort(-(stress[-1] / radii**power), kind="stable")[:top]
        np.testing.assert_allclose(obs[name][-1], 100.0 * np.bincount(classes[ranked], minlength=3) / counts, err_msg=name)


def _frames(run_dir):
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    return data




def test_stopped_run_resumes_bit_identically(tmp_path):
    straight = start_run(_spec(tmp_path, "straight"))
    first = start_run(_spec(tmp_path, "parts", steps=300))
    began = time.perf_counter()
    resumed = resume_run(tmp_path / "parts", steps=600)
    took = time.perf_counter() - began
    assert resumed.steps == 600 and resumed.steps_this_session == 300
    # This session's time apart from the run's over all its sessions (the first one's, then this one's).
    assert 0 < resumed.session_stepping_seconds < resumed.session_wall_seconds < took
    assert resumed.wall_seconds == pytest.approx(first.wall_seconds + resumed.session_wall_seconds, abs=0.2)
    assert first.session_wall_seconds == first.wall_seconds
    assert_same_run(_frames(straight.run_dir), _frames(tmp_path / "parts"))
    snap_a, _, _ = read_checkpoint(tmp_path / "straight" / "checkpoint.h5")
    snap_b, _, _ = read_checkpoint(tmp_path / "parts" / "checkpoint.h5")
    for key in ("positions", "velocities", "omegas", "force", "torque", "work"):
        assert np.array_equal(snap_a[key], snap_b[key]), key


def test_a_run_in_another_force_layout_keeps_it_through_resume_and_differs_at_round_off(tmp_path):
    """[run] layout = "newton" (each pair once; the fused layout is the CPU's default): recorded in spec.toml and run.log, kept by resume (stopped and
    resumed equals straight through, bit for bit), and the motion equals the default layout's to
    round-off, amplified by the contacts (the order of float operations changes, not the physics)."""
    import tomllib

    from decco_warp.layouts import layout_for

    assert layout_for("auto", 500, "cpu") is None
    # On CUDA the default is the Newton layout; "newton" names it on the CPU too.
    assert layout_for("newton", 500, "cpu").newton and layout_for("newton", 500, "cuda:0").newton
    straight = start_run(_spec(tmp_path, "straight", layout="newton"))
    start_run(_spec(tmp_path, "parts", layout="newton", steps=300))
    resume_run(tmp_path / "parts", steps=600)
    assert_same_run(_frames(straight.run_dir), _frames(tmp_path / "parts"))
    assert tomllib.loads((tmp_path / "parts" / "spec.toml").read_text())["run"]["layout"] == "newton"
    assert "force layout newton" in (tmp_path / "parts" / "run.log").read_text()
    from decco_warp.run import prepare_resume

    resumed = prepare_resume(tmp_path / "parts", steps=700, device="cpu")
    resumed.lock.release()
    assert resumed.sim.engine.layout.newton
    default = start_run(_spec(tmp_path, "default"))
    a, b = _frames(straight.run_dir)["particles"], _frames(default.run_dir)["particles"]
    # Float32 sums in another order differ by ~1e-7 of a force; 600 steps of a crowded contact
    # network amplify that to a few cm (3.4 cm measured), far below a missed or doubled contact.
    smallest = read_checkpoint(straight.run_dir / "checkpoint.h5")[1].radii.min()
    assert np.abs(a["position"] - b["position"]).max() < 1e-4 * smallest
    with pytest.raises(specs.SpecError, match="layout"):
        _spec(tmp_path, "bad", layout="fast")


def _simulate_in_background(tmp_path, name, checkpoint_every, until):
    """The demo collision, 2400 steps, in another process; returns once ``until`` is in its log."""
    args = ["--steps", "2400", "--output-every", "100", "--checkpoint-every", str(checkpoint_every), "--out", str(tmp_path)]
    process = subprocess.Popen(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "simulate", "--name", name, *args, "--device", "cpu"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    log = tmp_path / name / "run.log"
    deadline = time.time() + 120
    while time.time() < deadline and not (log.exists() and until in log.read_text()):
        time.sleep(0.02)
    return process, log


def test_killed_run_resumes_without_lost_or_duplicated_frames(tmp_path):
    straight = start_run(_spec(tmp_path, "straight", steps=2400, checkpoint_every=600))
    process, log = _simulate_in_background(tmp_path, "killed", checkpoint_every=600, until="checkpoint: step 1200")
    os.kill(process.pid, signal.SIGKILL)
    process.wait()
    text = log.read_text()
    assert "checkpoint: step 1200" in text and "done" not in text, "the run was not killed mid-way"
    result = cli("resume", str(tmp_path / "killed"), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    assert_same_run(_frames(straight.run_dir), _frames(tmp_path / "killed"))


def test_existing_run_folder_is_not_overwritten(finished, tmp_path):
    run_dir, _ = finished
    before = (run_dir / "trajectory.h5").stat().st_mtime_ns
    result = cli("simulate", "--steps", "10", "--out", str(run_dir.parent), "--device", "cpu")
    assert result.returncode == 2 and "already exists" in result.stderr
    assert (run_dir / "trajectory.h5").stat().st_mtime_ns == before


@pytest.fixture(scope="module")
def bad_piles(tmp_path_factory):
    folder = tmp_path_factory.mktemp("piles")
    pile = dw.load_pile(dw.run.builtin_pile("projectile"))
    negative = pile.copy()
    negative.radii = negative.radii.copy()
    save_pile(negative, folder / "negative.h5")
    with h5py.File(folder / "negative.h5", "r+") as f:
        f["pile/radii"][0] = -5.0
    (folder / "corrupt.h5").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)
    return folder


@pytest.mark.parametrize(
    "args, message",
    [
        (["--eta", "0"], "[collision] eta = 0.0: must be > 0"),
        (["--theta", "95"], "[collision] theta_deg = 95.0: must be in [0, 90) degrees"),
        (["--projectile", "no/such/pile.h5"], "pile file no/such/pile.h5 does not exist"),
        (["--projectile", "{piles}/negative.h5"], "radii must be > 0; particle 0"),
        (["--projectile", "{piles}/corrupt.h5"], "not a readable HDF5 file"),
        (["--spin-target", "fast"], "--spin-target must be FRACTION[,AXIS]"),
        (["--steps", "10", "--duration", "5"], "not both"),
        (["--device", "gpu"], "must be auto, cpu, cuda or cuda:N"),
        (["--dt", "5"], "dt = 5 s is too long"),
        (["--contact-law", "pkdgrav"], "[params] contact_law = 'pkdgrav': must be paper or decco-code or ssdem"),
        (["--contact-law", "ssdem", "--mu-s", "-1"], "[params] mu_s = -1.0: must be >= 0"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(args, message, bad_piles, tmp_path):
    args = [a.replace("{piles}", str(bad_piles)) for a in args]
    result = cli("simulate", *args, "--out", str(tmp_path))
    assert result.returncode == 2, result.stderr
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
    assert not any(tmp_path.iterdir()), "nothing may be written"


@pytest.mark.parametrize(
    "text, message",
    [
        ("[collision]\netaa = 2.0\n", "unknown key [collision] etaa"),
        ("[runs]\nsteps = 2\n", "unknown table [runs]"),
        ("[run]\nsteps = 'many'\n", "[run] steps = 'many': must be int"),
        ("[params]\nrestitution = 1.5\n", "[params] restitution = 1.5: must be in (0, 1]"),
        ("[params]\ncontact_law = 'ssdem'\neps_t = 0.0\n", "[params] eps_t = 0.0: must be in (0, 1]"),
        ("[collision]\neta_potential = 'both'\n", "[collision] eta_potential = 'both': must be self (U: each pile's own pairs) or all"),
        ("[collision]\ntarget_spin_axis = [0, 0, 0]\n", "[collision] target_spin_axis = [0, 0, 0]: must be +x, -x, +y, -y, +z, -z or a vector"),
        ("[run\nsteps = 1\n", "is not valid TOML"),
    ],
)
def test_bad_spec_files_are_refused_before_any_work(text, message, tmp_path):
    config = tmp_path / "spec.toml"
    config.write_text(text)
    out = tmp_path / "out"
    result = cli("simulate", str(config), "--out", str(out))
    assert result.returncode == 2 and message in result.stderr, result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_spec_file_and_options_combine_and_resolve(tmp_path):
    config = tmp_path / "c.toml"
    config.write_text('[run]\nname = "mine"\nduration = 8.0\n[collision]\nspeed = 2e4\ntheta_deg = 10\n[params]\ndt = 0.05\n')
    result = cli("simulate", str(config), "--theta", "30", "--output-every", "40", "--out", str(tmp_path), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    spec = specs.load_spec_file(tmp_path / "mine" / "spec.toml")
    assert spec["run"]["steps"] == 160 and "duration" not in spec["run"]
    assert spec["collision"]["theta_deg"] == 30.0 and spec["collision"]["speed"] == 2e4 and "eta" not in spec["collision"]
    assert spec == specs.resolve_spec(spec)  # the written spec is complete and re-runs exactly


def test_shipped_default_spec_file_is_the_default():
    """runs/default.toml documents what `decco-warp simulate` with no arguments runs."""
    from pathlib import Path

    shipped = Path(__file__).parent.parent / "runs" / "default.toml"
    assert specs.resolve_spec(specs.load_spec_file(shipped)) == specs.resolve_spec({})


def test_blow_up_stops_with_its_exit_code_and_keeps_the_checkpoint(tmp_path):
    config = tmp_path / "unstable.toml"
    config.write_text("[run]\nallow_unstable = true\nsteps = 3000\noutput_every = 50\ncheckpoint_every = 500\n[params]\ndt = 5.0\n")
    result = cli("simulate", str(config), "--out", str(tmp_path), "--name", "boom", "--device", "cpu")
    assert result.returncode == 4, result.stderr
    assert "blew up: step 50" in result.stderr and "likely cause: dt = 5 s is too long for k_in" in result.stderr
    assert "Traceback" not in result.stderr
    snapshot, _, _ = read_checkpoint(tmp_path / "boom" / "checkpoint.h5")
    assert snapshot["step"] == 0 and np.isfinite(snapshot["positions"]).all()
    assert dw.read_trajectory(tmp_path / "boom" / "trajectory.h5")["step"].tolist() == [0]


@pytest.mark.parametrize("signal_number", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_cleanly_and_resume_equals_an_uninterrupted_run(signal_number, tmp_path):
    straight = start_run(_spec(tmp_path, "straight", steps=2400, checkpoint_every=1200))
    process, _ = _simulate_in_background(tmp_path, "stopped", checkpoint_every=1200, until="frame: step 300")
    process.send_signal(signal_number)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 3, stderr
    assert f"stopped by {signal.Signals(signal_number).name}" in stderr and "decco-warp resume" in stderr
    assert "error" not in stderr.lower()  # a stop asked for is reported as a stop, not as an error
    stopped_at = read_checkpoint(tmp_path / "stopped" / "checkpoint.h5")[0]["step"]
    assert 300 <= stopped_at < 2400
    result = cli("resume", str(tmp_path / "stopped"), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    assert_same_run(_frames(straight.run_dir), _frames(tmp_path / "stopped"))


def test_a_long_run_answers_a_signal_within_seconds_not_at_its_next_report(tmp_path, monkeypatch):
    """A 1e6-step run reports every 5 000 steps (minutes at paper scale): a signal is still answered
    after about STOP_LATENCY seconds of stepping, with a checkpoint at the step reached."""
    import signal

    from decco_warp import run as runs

    real_pause = runs.pause_point
    seen = []

    def interrupt(phase, step):
        seen.append(step)
        if phase == "step" and len(seen) == 3:
            signal.raise_signal(signal.SIGINT)
        real_pause(phase, step)

    monkeypatch.setattr(runs, "STOP_LATENCY", 0.2)
    monkeypatch.setattr(runs, "pause_point", interrupt)
    prepared = runs.prepare_start(_spec(tmp_path, "long", steps=1_000_000, output_every=100_000, checkpoint_every=100_000))
    with pytest.raises(runs.RunStopped) as stopped:
        runs.execute(prepared)
    assert stopped.value.step == seen[-1] < 5000  # stopped at the third look, long before the first report
    chunks = np.diff([0] + seen)
    assert (chunks % 50 == 0).all() and chunks[0] == 50  # whole graph blocks, the first one alone
    assert read_checkpoint(tmp_path / "long" / "checkpoint.h5")[0]["step"] == stopped.value.step


def test_a_run_written_before_the_deepest_overlap_series_resumes_and_gains_them(tmp_path):
    """Trajectories of decco-warp 0.1 lack deepest_overlap: resume adds the series, with NaN (and -1 -1)
    for the frames written before, so every series keeps one value per frame."""
    start_run(_spec(tmp_path, "old", steps=200))
    with h5py.File(tmp_path / "old" / "trajectory.h5", "r+") as f:
        del f["observables/deepest_overlap"], f["observables/deepest_overlap_pair"]
    resume_run(tmp_path / "old", steps=400)
    data = dw.read_trajectory(tmp_path / "old" / "trajectory.h5")
    depth, pairs = data["observables"]["deepest_overlap"], data["observables"]["deepest_overlap_pair"]
    assert data["observable_step"]["deepest_overlap"].tolist() == data["step"].tolist()
    written_before = data["step"] <= 200
    assert np.isnan(depth[written_before]).all() and (pairs[written_before] == -1).all()
    assert (depth[~written_before] > 0).all() and (pairs[~written_before] >= 0).all()


def test_help_prints_units_and_toml_tables_as_written():
    """Every bracketed word of an option's or argument's help ([cm], [s], [sweep.grid], [[pile]])
    appears in its command's --help: help is plain text, not markup that swallows brackets."""
    import re

    from typer.main import get_command
    from typer.testing import CliRunner

    from decco_warp.cli import app

    group = get_command(app)
    checked = 0
    for name, command in group.commands.items():
        shown = CliRunner().invoke(app, [name, "--help"], terminal_width=200).output
        for param in command.params:
            text = getattr(param, "help", None) or ""
            for token in re.findall(r"\[+[^\]\s]+\]+", text):
                assert token in shown, (name, param.name, token)
                checked += 1
    assert checked >= 5  # units of pile and simulate, the sweep's and piles' TOML tables


def test_simulate_sets_the_contact_physics_as_pile_does(tmp_path):
    """--restitution, --mu-k and --mu-r (pile's options) reach the run: its spec.toml, its checkpoint's
    Params and the plan's physics line; a value out of range is one line and exit 2, nothing written."""
    import tomllib

    import typer

    from decco_warp.cli import app

    commands = typer.main.get_command(app).commands
    physics = {"--restitution", "--mu-k", "--mu-r", "--k-in", "--dt"}
    for name in ("simulate", "pile"):
        assert physics <= {opt for param in commands[name].params for opt in param.opts}, name
    args = ("--mu-k", "0.6", "--mu-r", "0.01", "--restitution", "0.5", "--steps", "20", "--output-every", "10", "--device", "cpu")
    check = cli("simulate", *args, "--check")
    assert check.returncode == 0 and "physics: restitution 0.5, mu_k 0.6, mu_r 0.01 (couple)" in check.stdout, check.stderr
    result = cli("simulate", *args, "--out", str(tmp_path), "--name", "rough")
    assert result.returncode == 0, result.stderr
    params = tomllib.loads((tmp_path / "rough" / "spec.toml").read_text())["params"]
    assert (params["mu_k"], params["mu_r"], params["restitution"]) == (0.6, 0.01, 0.5)
    bad = cli("simulate", "--restitution", "1.5", "--out", str(tmp_path), "--name", "bad", "--device", "cpu")
    assert bad.returncode == 2 and "restitution = 1.5: must be in (0, 1]" in bad.stderr and len(bad.stderr.splitlines()) == 1
    assert not (tmp_path / "bad").exists()


def test_check_estimates_the_cost_and_a_missing_folder_does_not_exist(tmp_path):
    """simulate --check and pile --check say what the job will cost on this device before any work,
    from the measured rate a step (the estimate's own line, checked against the cost model); a path
    that is not there is said not to exist."""
    from decco_warp.costs import duration, formation_steps, step_seconds

    result = cli("simulate", "--check", "--device", "cpu", "--steps", "3000", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    step = step_seconds(450, dw.Scheme(), "cpu")
    assert f"cost: about {duration(3000 * step)} on cpu ({1e3 * step:.3g} ms a step x 3000 steps" in result.stdout
    result = cli("pile", "--out", str(tmp_path / "p.h5"), "-n", "400", "--check", "--device", "cpu")
    assert result.returncode == 0, result.stderr
    low, high = formation_steps(2.7, 0.3, 0.04)
    assert f"settling takes {low} to {high} steps" in result.stdout and not (tmp_path / "p.h5").exists()
    # 400 particles settled in ~230 000 steps (docs/benchmarks.md): inside the range.
    assert low < 230_000 < high
    for command in (["analyze"], ["resume"], ["view"], ["export", "--xdmf"]):
        result = cli(*command, str(tmp_path / "nowhere"))
        assert result.returncode == 2 and f"{tmp_path / 'nowhere'} does not exist" in result.stderr, (command, result.stderr)


def test_a_vector_spin_axis_from_the_command_line_is_recorded_and_repeats(tmp_path):
    result = cli("simulate", "--check", "--spin-target", "0.5,1,0,1", "--device", "cpu", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    import tomllib

    spec = specs.resolve_spec({"collision": {"target_spin": 0.5, "target_spin_axis": [1.0, 0.0, 1.0]}})
    assert specs.resolve_spec(tomllib.loads(specs.dumps(spec))) == spec
    result = cli("simulate", "--check", "--spin-target", "0.5,1,0,x", "--device", "cpu", "--out", str(tmp_path))
    assert result.returncode == 2 and "X,Y,Z" in result.stderr

"""Sweeps: a reduced grid on a local Dask cluster of two workers, resumed, with a failing run."""

import csv
import json
import os
from pathlib import Path

import pytest
from helpers import cli

import decco_warp as dw
from decco_warp import spec as specs
from decco_warp.analysis.runs import spin_kind
from decco_warp.collision import SPIN_AXES
from decco_warp.sweep import load_sweep, stepped_fraction

pytest.importorskip("distributed")

SWEEP = """
[sweep]
name = "grid"
out = "{out}"
min_members = 20
keep_trajectory = false
analyze_every = 2
[sweep.grid]
"collision.eta" = [0.5, 1.0]
"params.dt" = [0.04, 5.0]
[run]
steps = 200
output_every = 50
device = "cpu"
allow_unstable = true
"""


def _rows(path):
    with open(path) as f:
        return {row["run"]: row for row in csv.DictReader(f)}


def test_grid_expands_to_checked_run_specs(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path))
    settings, runs = load_sweep(path)
    assert settings["name"] == "grid" and len(runs) == 4 and settings["swept"] == ["eta", "dt"]
    assert sorted(r["run"]["name"] for r in runs) == ["eta0.5_dt0.04", "eta0.5_dt5", "eta1_dt0.04", "eta1_dt5"]
    assert {(r["collision"]["eta"], r["params"]["dt"]) for r in runs} == {(0.5, 0.04), (0.5, 5.0), (1.0, 0.04), (1.0, 5.0)}
    assert all(r["run"]["out"] == str(tmp_path / "grid") for r in runs)
    path.write_text(SWEEP.format(out=tmp_path).replace('"params.dt"', '"params.spin"'))
    with pytest.raises(specs.SpecError, match="not a sweepable"):
        load_sweep(path)
    # The key spelled as the command (analyze); sweep files of its earlier spelling are read alike.
    assert settings["analyze_every"] == 2
    path.write_text(SWEEP.format(out=tmp_path).replace("analyze_every", "analyse_every"))
    assert load_sweep(path)[0]["analyze_every"] == 2
    path.write_text(SWEEP.format(out=tmp_path).replace("analyze_every = 2", "analyze_every = 2\nanalyse_every = 3"))
    with pytest.raises(specs.SpecError, match="analyse_every is the earlier name of analyze_every"):
        load_sweep(path)


def test_a_repeated_set_up_runs_once(tmp_path):
    """Points that differ only in the axis of a zero spin are one set-up: its realization 0 runs once
    (a comparison of groups would count it twice), its other realizations differ and all run."""
    path = tmp_path / "s.toml"
    grid = '''"collision.target_spin, collision.target_spin_axis" = [[0.0, "+z"], [0.0, "+x"], [0.5, "+z"], [0.5, "+x"]]
'''
    text = SWEEP.format(out=tmp_path).replace('"collision.eta" = [0.5, 1.0]\n"params.dt" = [0.04, 5.0]\n', grid)
    text = text.replace("analyze_every = 2", "analyze_every = 2\nrealizations = 2")
    path.write_text(text)
    settings, runs = load_sweep(path)
    names = [r["run"]["name"] for r in runs]
    assert settings["same_as"] == {"target_spin0_target_spin_axispx": "target_spin0_target_spin_axispz"}
    assert len(runs) == 7 and "target_spin0_target_spin_axispx_r1" in names and "target_spin0.5_target_spin_axispx" in names
    result = cli("sweep", str(path), "--check")
    assert result.returncode == 0, result.stderr
    assert "target_spin0_target_spin_axispx is the same set-up as target_spin0_target_spin_axispz: run once" in result.stdout
    assert "7 runs" in result.stdout


def test_sweep_runs_on_two_workers_reports_failures_and_resumes(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path))
    result = cli("sweep", str(path), "--workers", "2")
    assert result.returncode == 0, result.stderr
    rows = _rows(tmp_path / "grid" / "summary.csv")
    assert len(rows) == 4
    good = [r for r in rows.values() if r["status"] == "ok"]
    failed = [r for r in rows.values() if r["status"] == "failed"]
    assert len(good) == 2 and len(failed) == 2  # dt = 5 s blows up; the others finish
    # The blow-up guard's reason, naming the step: "step N: ..."
    assert all(r["reason"].startswith("step ") and "too long" in r["reason"] for r in failed), failed
    assert {float(r["eta"]) for r in failed} == {0.5, 1.0}
    assert all(float(r["largest_mass_ratio"]) > 0 for r in good)
    # Every physics parameter is a column, each row with its run's own value (a failed run's too).
    defaults = specs.resolve_spec({})["params"]
    for row in rows.values():
        assert float(row["dt"]) == (5.0 if row["status"] == "failed" else 0.04)
        for key in ("k_in", "restitution", "mu_k", "mu_r", "G", "gravity_every"):
            assert float(row[key]) == defaults[key], key
        assert row["rolling_friction"] == defaults["rolling_friction"]
    assert (tmp_path / "grid" / "figures" / "largest_fragment.png").stat().st_size > 1000
    # Analysed, then the trajectory dropped: the analysis, the figures and the final checkpoint stay.
    for row in good:
        run_dir = tmp_path / "grid" / row["run"]
        assert not (run_dir / "trajectory.h5").exists() and not (run_dir / "trajectory.xdmf").exists()
        assert {"spec.toml", "run.log", "checkpoint.h5", "analysis.h5", "summary.json", "figures"} <= {p.name for p in run_dir.iterdir()}
        summary = json.loads((run_dir / "summary.json").read_text())
        assert summary["analyze_every"] == 2 and summary["largest_mass_ratio"] == pytest.approx(float(row["largest_mass_ratio"]))
        assert float(row["deepest_overlap"]) > 0 and float(row["ledger_closure"]) < 1e-9 and int(row["n_particles"]) == 450
        assert 0 < float(row["stepping_seconds"]) < float(row["wall_seconds"])
    record = json.loads((tmp_path / "grid" / "sweep.json").read_text())
    assert record["runs"] == {"failed": 2, "ok": 2} and record["decco_warp"] == dw.__version__
    took = {row["run"]: row["analysis_seconds"] for row in good}
    assert all(float(value) > 0 for value in took.values())
    # Again: the finished runs are skipped, the failed ones tried again (and fail the same way);
    # the skipped runs report what their analysis took when it ran, not the time to read it back.
    again = cli("sweep", str(path), "--workers", "2")
    assert again.returncode == 0, again.stderr
    rows = _rows(tmp_path / "grid" / "summary.csv")
    assert sorted(r["status"] for r in rows.values()) == ["failed", "failed", "skipped (complete)", "skipped (complete)"]
    assert {name: rows[name]["analysis_seconds"] for name in took} == took
    # A skipped run was made before: no device is claimed for it, and its line says what it took then.
    assert all(rows[name]["device"] == "" for name in took)
    skipped = [line for line in " ".join(again.stderr.split()).split(" eta") if "skipped (complete)" in line]
    assert skipped and all("made before this sweep, in" in line and "on auto" not in line for line in skipped)


def test_bad_sweep_files_are_exit_2(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text("[sweep]\nname = 'x'\n[sweep.grid]\n'collision.eta' = []\n")
    result = cli("sweep", str(path))
    assert result.returncode == 2 and "non-empty list" in result.stderr


PAPER = Path(__file__).parent.parent / "runs" / "paper"


@pytest.mark.parametrize("name", sorted(p.stem for p in PAPER.glob("*.toml") if "[sweep]" in p.read_text()))
def test_shipped_paper_sweeps_are_valid(name):
    """Every sweep file shipped in runs/paper/ loads (its piles there), with distinct runs; the
    counts of the paper's experiments and of the statistics campaigns are pinned."""
    settings, runs = load_sweep(PAPER / f"{name}.toml")
    assert runs and len({r["run"]["name"] for r in runs}) == len(runs)
    expected = {"fig3_validation": 63, "fig3_headon": 21, "fig3_oblique": 42, "fig8_stress": 3, "fig9_spin": 24, "realizations": 33, "spin_friction": 4,
                "fig9_statistics": 78, "fig6_statistics": 60, "fig6_clock": 6, "ladder_clock": 15, "contact_lanes": 3,
                "fig3_headon_r4": 45}  # fmt: skip
    if name in expected:
        assert len(runs) == expected[name]
    if name == "fig9_spin":  # two axis pairs of each kind of spin, at every eta
        kinds = [spin_kind(SPIN_AXES[r["collision"]["target_spin_axis"]], SPIN_AXES[r["collision"]["projectile_spin_axis"]]) for r in runs]
        assert sorted(set(kinds)) == ["anti-parallel", "parallel", "perpendicular"] and all(kinds.count(k) == 8 for k in set(kinds))
    if name in ("fig6_clock", "ladder_clock"):  # fig6_statistics' own set-ups, on another clock
        stats = {r["run"]["name"]: r for r in load_sweep(PAPER / "fig6_statistics.toml")[1]}
        for run in runs:
            twin = stats[run["run"]["name"]]
            assert run["collision"] == twin["collision"] and run["piles"] == twin["piles"]
            assert {k: v for k, v in run["params"].items() if k != "gravity_every"} == {k: v for k, v in twin["params"].items() if k != "gravity_every"}
            assert (run["params"]["gravity_every"], twin["params"]["gravity_every"]) == ({"fig6_clock": 1, "ladder_clock": 50}[name], 10)
    if name == "throughput_r4_k40":  # throughput_r4_k16's eight set-ups, gravity every 1.0 s instead of 0.4 s
        k16 = {r["run"]["name"]: r for r in load_sweep(PAPER / "throughput_r4_k16.toml")[1]}
        assert sorted(k16) == sorted(r["run"]["name"] for r in runs) and len(runs) == 8
        for run in runs:
            twin = k16[run["run"]["name"]]
            assert run["collision"] == twin["collision"] and run["piles"] == twin["piles"]
            assert {k: v for k, v in run["params"].items() if k != "gravity_every"} == {k: v for k, v in twin["params"].items() if k != "gravity_every"}
            assert (run["params"]["gravity_every"], twin["params"]["gravity_every"]) == (40, 16)
            assert run["params"]["gravity_every"] * run["params"]["dt"] == pytest.approx(1.0, rel=0.01)
            assert run["run"]["steps"] % 40 == 0 and abs(run["run"]["steps"] - twin["run"]["steps"]) < 40
    if name in ("fig3_oblique", "realizations"):  # the same folder and names as the head-on runs they join
        headon = {r["run"]["name"]: r for r in load_sweep(Path(__file__).parent.parent / "runs" / "paper" / "fig3_headon.toml")[1]}
        assert {r["run"]["out"] for r in runs} == {r["run"]["out"] for r in headon.values()}
        assert all(headon[r["run"]["name"]] == r for r in runs if r["run"]["name"] in headon)
    for run in runs:  # the paper's piles are shipped
        for which in ("target", "projectile"):
            reference = run["piles"][which]
            assert reference.startswith("builtin:") or (Path(__file__).parent.parent / reference).is_file(), reference


def test_piles_from_a_toml_list_are_built_once(tmp_path):
    listing = tmp_path / "piles.toml"
    listing.write_text(
        f'[[pile]]\nout = "{tmp_path}/a.h5"\nparticles = 12\nseed = 1\ndt = 0.2\nke_threshold = 1e-4\n\n'
        f'[[pile]]\nout = "{tmp_path}/b.h5"\nparticles = 10\nseed = 2\ndt = 0.2\nke_threshold = 1e-4\n'
    )
    result = cli("piles", str(listing), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    import decco_warp as dw

    assert dw.load_pile(tmp_path / "a.h5").n == 12 and dw.load_pile(tmp_path / "b.h5").n == 10
    again = cli("piles", str(listing), "--device", "cpu")
    assert again.returncode == 0 and again.stdout.count("exists, skipped") == 2
    listing.write_text('[[pile]]\nout = "x.h5"\nparticles = 10\ncolour = "red"\n')
    bad = cli("piles", str(listing))
    assert bad.returncode == 2 and "unknown key colour" in bad.stderr


def test_shipped_pile_list_is_valid():
    from pathlib import Path

    from decco_warp.spec import load_spec_file

    entries = load_spec_file(Path(__file__).parent.parent / "runs" / "paper" / "piles.toml")["pile"]
    assert [e["particles"] for e in entries] == [5000, 5000, 1250, 500]


def test_a_stopped_sweep_keeps_its_table_and_continues(tmp_path):
    """SIGTERM (a batch scheduler's stop) after the first run: exit 3 with that run in summary.csv;
    run again, the sweep skips it and finishes the others."""
    import signal
    import subprocess
    import sys
    import time

    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path).replace('"params.dt" = [0.04, 5.0]', '"collision.theta_deg" = [0.0, 22.0, 44.0]'))
    process = subprocess.Popen(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "sweep", str(path), "--workers", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    table = tmp_path / "grid" / "summary.csv"
    deadline = time.time() + 120
    while time.time() < deadline and not (table.exists() and len(_rows(table)) >= 1):
        time.sleep(0.1)
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 3, stderr
    assert "sweep stopped after" in stderr and "run it again" in stderr
    done = _rows(table)
    assert 1 <= len(done) < 6 and all(r["status"] == "ok" for r in done.values())
    again = cli("sweep", str(path), "--workers", "1")
    assert again.returncode == 0, again.stderr
    rows = _rows(table)
    assert len(rows) == 6 and all(rows[name]["status"] == "skipped (complete)" for name in done)


def test_a_worker_leaves_out_only_the_heartbeat_that_found_the_scheduler_gone(caplog):
    """A local worker's log (sweep.dask_setup, quiet_heartbeats): the traceback of Dask's heartbeat
    that found the scheduler closed, which a cluster's closing can print, is left out; the worker's
    other errors stay, and installing it twice leaves one filter."""
    import logging

    from decco_warp.sweep import quiet_heartbeats

    quiet_heartbeats()
    quiet_heartbeats()
    logger = logging.getLogger("distributed.worker")
    assert sum(type(f).__name__ == "_Heartbeats" for f in logger.filters) == 1
    with caplog.at_level(logging.ERROR, logger="distributed.worker"):
        logger.error("Failed to communicate with scheduler during heartbeat.")
        logger.error("Unexpected exception during heartbeat. Closing worker.")
        logger.error("Compute Failed")
    assert [r.getMessage() for r in caplog.records] == ["Unexpected exception during heartbeat. Closing worker.", "Compute Failed"]


def test_ctrl_c_on_a_sweep_checkpoints_its_running_runs_and_says_what_it_kept(tmp_path):
    """Ctrl-C at a terminal signals every process of the sweep at once (its Dask workers and analysis
    processes too): the running runs write a checkpoint at the step they reached (their last periodic
    one is step 0 here) with a "stopped" line in run.log, the sweep ends with exit 3 and a line that
    says so (and that no summary.csv exists yet: no run had finished), without Dask's "still alive,
    killing" warnings; run again, the runs resume from those steps."""
    import signal
    import subprocess
    import sys
    import time

    from decco_warp.io import read_checkpoint

    path = tmp_path / "s.toml"
    text = SWEEP.format(out=tmp_path).replace('"params.dt" = [0.04, 5.0]', "").replace('"collision.eta" = [0.5, 1.0]', '"params.mu_k" = [0.0, 0.6]')
    text = text.replace("steps = 200\noutput_every = 50", "steps = 2000000\noutput_every = 1000\ncheckpoint_every = 1000000")
    path.write_text(text + "[params]\ngravity_every = 10\n")
    process = subprocess.Popen(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "sweep", str(path), "--workers", "2"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    logs = [tmp_path / "grid" / name / "run.log" for name in ("mu_k0", "mu_k0.6")]
    deadline = time.time() + 180
    while time.time() < deadline and not all(log.is_file() and "frame: step 3000," in log.read_text() for log in logs):
        time.sleep(0.2)
    os.killpg(process.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 3, stderr
    assert "still alive" not in stderr and "Traceback" not in stderr, stderr
    line = " ".join(stderr.split("decco-warp: ")[-1].split())
    assert "after 0 of 2 runs (no run had finished, so there is no summary.csv yet)" in line and "summary.csv holds" not in line
    assert not (tmp_path / "grid" / "summary.csv").exists()
    steps = {}
    for log in logs:
        last = log.read_text().splitlines()[-1]
        assert "stopped by SIGINT at step" in last, last
        steps[log.parent.name] = int(last.split("at step ")[1].split(";")[0])
        assert int(read_checkpoint(log.parent / "checkpoint.h5")[0]["step"]) == steps[log.parent.name] >= 3000
        assert f"{log.parent.name} at step {steps[log.parent.name]}" in line
    result = cli("sweep", str(path), "--check")
    states = {line.split()[0]: line.split(None, 1)[1] for line in result.stdout.splitlines()[1:] if line.startswith("  ") and not line.startswith("   ")}
    assert states == {name: f"resumes at step {step}" for name, step in steps.items()}


def test_a_stopped_sweep_s_line_says_what_each_kind_of_stop_kept(tmp_path):
    """Stopped in order: the runs checkpointed with their steps and those left unanalysed; by a second
    signal: none waited for; before the workers were up: none started; summary.csv named only where
    finished runs fill it."""
    from decco_warp.errors import SweepStopped
    from decco_warp.sweep import SweepJob

    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path))
    job = SweepJob(*load_sweep(path))
    job.stopped, job.finished = True, [{"run": "eta0.5_dt0.04", "status": "ok"}]
    job.stop = SweepStopped("SIGTERM", [{"run": "eta1_dt0.04", "step": 120}, {"run": "eta1_dt5", "step": None}], ["eta0.5_dt5"])
    line = job.stopped_line()
    assert "after 1 of 4 runs (summary.csv holds the 1 finished)" in line and "1 stepping run(s) wrote a checkpoint" in line
    assert "eta1_dt0.04 at step 120" in line and "eta1_dt5" not in line and "not analysed yet (eta0.5_dt5)" in line
    job.finished, job.stop = [], SweepStopped("SIGINT", [], [], at_once=True)
    assert "no summary.csv yet" in job.stopped_line() and "without waiting for the runs stepping" in job.stopped_line()
    job.stop = None
    assert "before its workers were up, so no run had started" in job.stopped_line()


def test_a_sweep_packs_runs_into_ensembles_with_the_results_of_runs_alone(tmp_path):
    """[sweep] ensemble = 4 hands the whole grid to one worker: the two runs of each dt are stepped
    together, the dt = 5 s pair blows up on its own (each with its own reason), and the others
    end exactly as they do alone."""
    import numpy as np

    from decco_warp.io import read_checkpoint
    from decco_warp.run import start_run

    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path).replace("analyze_every = 2", "analyze_every = 2\nensemble = 4"))
    settings, runs = load_sweep(path)
    assert settings["ensemble"] == 4
    result = cli("sweep", str(path), "--workers", "1")
    assert result.returncode == 0, result.stderr
    assert " ".join((result.stdout + result.stderr).split()).count("2 runs together") == 4
    rows = _rows(tmp_path / "grid" / "summary.csv")
    assert {name: row["status"] for name, row in rows.items()} == {
        "eta0.5_dt0.04": "ok", "eta1_dt0.04": "ok", "eta0.5_dt5": "failed", "eta1_dt5": "failed"
    }  # fmt: skip
    assert all(rows[name]["reason"].startswith("step ") and "too long" in rows[name]["reason"] for name in ("eta0.5_dt5", "eta1_dt5"))
    assert {row["ensemble"] for row in rows.values()} == {"2"}
    for spec in (r for r in runs if r["params"]["dt"] == 0.04):
        alone = start_run({**spec, "run": {**spec["run"], "out": str(tmp_path / "alone")}})
        mine = read_checkpoint(tmp_path / "grid" / spec["run"]["name"] / "checkpoint.h5")[0]
        theirs = read_checkpoint(alone.run_dir / "checkpoint.h5")[0]
        assert all(np.array_equal(mine[key], theirs[key]) for key in ("positions", "velocities", "omegas", "work"))
    with pytest.raises(specs.SpecError, match="ensemble"):
        path.write_text(SWEEP.format(out=tmp_path).replace("analyze_every = 2", "ensemble = 0"))
        load_sweep(path)


def test_ensemble_auto_packs_small_runs_on_a_gpu_only_and_alike_in_size(tmp_path):
    """[sweep] ensemble defaults to "auto": one run at a time on a CPU; on a GPU up to 8 to a worker
    (fewer when that would leave a worker without runs), stepped together only when they have the
    same particle count, up to 20 000."""
    from decco_warp.sweep import ENSEMBLE_MAX_PARTICLES, ensemble_plan, simulate_batch

    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path))
    settings, runs = load_sweep(path)
    assert settings["ensemble"] == "auto"
    assert ensemble_plan("auto", 0) == (1, None)
    assert ENSEMBLE_MAX_PARTICLES == 20_000  # the largest count measured to gain on an H100 (docs/benchmarks.md)
    assert ensemble_plan("auto", 1, runs=42) == (8, 20_000)
    assert ensemble_plan("auto", 8, runs=42, workers=8) == (6, ENSEMBLE_MAX_PARTICLES)  # every GPU gets runs
    assert ensemble_plan("auto", 2, runs=3, workers=2) == (2, ENSEMBLE_MAX_PARTICLES)
    assert ensemble_plan("auto", 2, runs=0, workers=2) == (1, ENSEMBLE_MAX_PARTICLES)
    assert ensemble_plan(3, 0) == (3, None)
    for bad in ("many", 0, 2.5, True):
        path.write_text(SWEEP.format(out=tmp_path).replace("analyze_every = 2", f"ensemble = {json.dumps(bad)}"))
        with pytest.raises(specs.SpecError, match='ensemble = .*"auto"'):
            load_sweep(path)
    # Two runs alike in all but eta: together when small enough, each alone past the limit.
    pair = [r for r in runs if r["params"]["dt"] == 0.04]
    together = simulate_batch([{**r, "run": {**r["run"], "out": str(tmp_path / "a")}} for r in pair], max_particles=10**6)
    alone = simulate_batch([{**r, "run": {**r["run"], "out": str(tmp_path / "b")}} for r in pair], max_particles=10)
    assert [row["ensemble"] for row in together] == [2, 2] and [row["ensemble"] for row in alone] == [1, 1]
    # Runs of another force layout or precision never go together.
    mixed = [{**r, "run": {**r["run"], "out": str(tmp_path / "c"), **extra}} for r, extra in zip(pair, ({"layout": "newton"}, {}))]
    assert [row["ensemble"] for row in simulate_batch(mixed)] == [1, 1]
    assert all(row["status"] == "ok" for row in together + alone)
    # Stopped part-way (a stop requested before its first step: it checkpoints at its first stop), then
    # resumed, a run's row gives this session's time beside the run's over all its sessions.
    from decco_warp.errors import RunStopped
    from decco_warp.run import execute, prepare_start
    from decco_warp.sweep import finished_line

    first = {**pair[0], "run": {**pair[0]["run"], "out": str(tmp_path / "d")}}
    (tmp_path / "stop").write_text("SIGINT")
    with pytest.raises(RunStopped):
        execute(prepare_start(first), stop_file=tmp_path / "stop")
    [row] = simulate_batch([first])
    assert row["status"] == "ok" and row["resumed"] and 0 < row["session_seconds"] < row["wall_seconds"], row.get("reason")
    assert f"{row['session_seconds']:.1f} s on cpu; {row['wall_seconds']:.1f} s over all its sessions" in finished_line(row)


def test_auto_ensembles_group_runs_of_10000_particles_and_keep_larger_ones_alone():
    """simulate_batch's groups under ensemble = "auto" (ensemble_groups on stand-ins for prepared
    runs, nothing stepped): the paper's 10 000-particle runs go together, one count per group; with
    gravity on its own clock, the R = 4 runs' 25 000 too."""
    from types import SimpleNamespace

    from decco_warp.params import Params
    from decco_warp.scheme import Scheme
    from decco_warp.sweep import ensemble_groups, ensemble_plan

    def run(n, gravity="all-pairs", every=1):
        plan = SimpleNamespace(params=Params(), scheme=Scheme(gravity=gravity, gravity_every=every), state=SimpleNamespace(n=n))
        return SimpleNamespace(plan=plan, sim=SimpleNamespace(step_count=0))

    cap = ensemble_plan("auto", 1, runs=8)[1]
    batch = [run(10_000), run(6_250), run(10_000), None, run(20_000), run(20_001), run(20_000), run(20_001), run(10_000, "tree")]
    assert ensemble_groups(batch, cap) == [[0, 2], [1], [4, 6], [5], [7], [8]]
    assert ensemble_groups(batch, None) == [[0, 1, 2, 4, 5, 6, 7], [8]]
    # With gravity on its own clock a step fills less of the GPU: 25 000-particle runs go together too.
    clocked = [run(25_000, every=10), run(25_000), run(25_000, every=10), run(25_001, every=10), run(25_000)]
    assert ensemble_groups(clocked, cap) == [[0, 2], [1], [3], [4]]


def test_shipped_large_pile_list_and_collision_are_valid():
    """runs/large/: the 1e5-particle piles and their collision (built and run on a GPU, not here)."""
    from decco_warp.spec import load_spec_file, resolve_spec

    root = Path(__file__).parent.parent / "runs" / "large"
    entries = load_spec_file(root / "piles.toml")["pile"]
    assert sum(e["particles"] for e in entries) == 100_000
    spec = resolve_spec(load_spec_file(root / "collision.toml"))
    assert spec["params"]["gravity"] == "auto" and spec["collision"]["eta"] == 3.0
    assert {spec["piles"]["target"], spec["piles"]["projectile"]} == {e["out"] for e in entries}


@pytest.mark.parametrize(
    "folder, sweeps, overrides",
    [("fig3", ["fig3_validation", "realizations"], None), ("fig8", ["fig8_stress"], None), ("fig9", ["fig9_spin"], None), ("causes", ["size_change_causes"], None),
     ("spin_friction", ["spin_friction"], None), ("fig9_statistics", ["fig9_statistics"], None), ("fig9_zero_slip", ["fig9_statistics"], None),
     ("fig9_decco_code", ["fig9_decco_code"], None), ("fig6_statistics", ["fig6_statistics"], None), ("fig6_zero_slip", ["fig6_statistics"], None),
     ("fig6_decco_code", ["fig6_decco_code"], None), ("fig6_decco_code_cor", ["fig6_decco_code_cor"], None),
     ("fig6_clock", ["fig6_clock"], None), ("resolution", ["resolution"], {"resolution": 0.25}),
     ("resolution/x4", ["resolution_auto"], {"resolution": 4.0}),
     ("resolution_paper_contacts", ["resolution_paper_contacts"], {"resolution": 0.25}),
     ("resolution_paper_contacts/x4", ["resolution_paper_contacts"], {"resolution": 4.0}),
     ("fig3_auto", ["fig3_headon_auto"], None), ("resolution/x16", ["resolution_fine"], {"resolution": 16.0}),
     ("qstar_rd/x4", ["qstar_rd"], {"resolution": 4.0}), ("throughput_r4", ["throughput_r4"], {"resolution": 4.0}), ("qstar_rd_frictionless", ["qstar_rd_frictionless"], None),
     ("qstar_rd_frictionless/x4", ["qstar_rd_frictionless"], {"resolution": 4.0}), ("qstar_rd_paper_contacts", ["qstar_rd_paper_contacts"], {"resolution": 4.0}),
     ("throughput_r4_k16", ["throughput_r4_k16"], {"resolution": 4.0}), ("throughput_r4_k40", ["throughput_r4_k40"], {"resolution": 4.0}),
     ("ladder_clock", ["ladder_clock"], None),
     ("fig9_energy_matched", ["fig9_energy_matched"], None), ("fig3_headon_r4", ["fig3_headon_r4"], {"resolution": 4.0})],
)  # fmt: skip
def test_committed_results_are_runs_of_the_shipped_sweeps(folder, sweeps, overrides):
    """Every run kept under runs/results/ is, name and set-up (piles, collision with its orientation
    seed, Params, steps), a run of the shipped sweep files: so `decco-warp sweep` over that folder
    skips it, and the same files repeat it."""
    import tomllib

    from decco_warp.spec import resolve_spec

    root = Path(__file__).parent.parent
    if overrides and overrides.get("resolution", 1) != 1:
        factor = f"{overrides['resolution']:g}"
        missing = [f"{name}_x{factor}.h5" for name in ("target5000", "proj1250", "proj500", "equal5000")
                   if f"{name}.h5" in "".join((root / "runs" / "paper" / f"{sweep}.toml").read_text() for sweep in sweeps)
                   and not (root / "runs" / "paper" / "piles" / f"{name}_x{factor}.h5").is_file()]  # fmt: skip
        if missing:
            pytest.skip(f"piles not shipped ({', '.join(missing)}): decco-warp piles runs/paper/piles.toml --resolution {factor} builds them")
    planned = {}
    for name in sweeps:
        for run in load_sweep(root / "runs" / "paper" / f"{name}.toml", overrides)[1]:
            planned[run["run"]["name"]] = run
    kept = sorted((root / "runs" / "results" / folder).glob("*/spec.toml"))
    assert kept
    for path in kept:
        spec = tomllib.loads(path.read_text())
        run = planned.get(spec["run"]["name"])
        assert run is not None, f"{path.parent.name} is no run of {sweeps}"
        for table in ("piles", "collision"):  # keys added since (eta_potential) take their defaults
            assert resolve_spec(spec)[table] == run[table], (path.parent.name, table)
        shared = set(spec["params"]) & set(run["params"])  # early runs' spec.toml name fewer keys
        assert shared >= {"k_in", "restitution", "mu_k", "mu_r", "dt"}
        assert {key: spec["params"][key] for key in shared} == {key: run["params"][key] for key in shared}, path.parent.name
        assert spec["run"]["steps"] == run["run"]["steps"]


def test_sweep_check_costs_runs_at_their_own_gravity_clock_with_a_total_and_one_note(tmp_path):
    """gravity_every = 10 on a CPU: each run's cost is that of a step at K = 10 (the K = 1 step's
    gravity over 10 plus the contacts), which stands to the K = 1 step as whole runs measured it (the
    default collision, 450 particles: 48.8 s against 6.2 s of stepping on a 2-core CPU, 7.9x; here
    within 15 %); a total for the sweep sums them; the note on how K > 1 is estimated is said once."""
    import re

    from decco_warp.costs import GRAVITY_EVERY_NOTE, step_seconds

    path = tmp_path / "s.toml"
    text = SWEEP.format(out=tmp_path).replace('"params.dt" = [0.04, 5.0]', "").replace('"collision.eta" = [0.5, 1.0]', '"params.mu_k" = [0.0, 0.6]')
    path.write_text(text.replace("steps = 200", "steps = 50000").replace("analyze_every = 2", "analyze_every = 2\nrealizations = 3")
                    + "[params]\ngravity_every = 10\n")  # fmt: skip
    result = cli("sweep", str(path), "--check")
    assert result.returncode == 0, result.stderr
    k10, k1 = step_seconds(450, dw.Scheme(gravity_every=10), "cpu"), step_seconds(450, dw.Scheme(), "cpu")
    assert k1 / k10 == pytest.approx(48.8 / 6.2, rel=0.15)
    costs = re.findall(r"; about ([\d.]+) s on cpu \(([\d.]+) ms a step x 50000 steps at gravity every 10 steps", result.stdout)
    assert len(costs) == 6 and all(float(ms) == pytest.approx(1e3 * k10, rel=0.01) for _, ms in costs)
    total = re.search(r"^cost: about ([\d.]+) (s|min) of stepping for the 6 run\(s\) to make or resume on cpu", result.stdout, re.M)
    assert total and float(total[1]) * (60 if total[2] == "min" else 1) == pytest.approx(6 * 50000 * k10, rel=0.05)
    assert result.stdout.count(GRAVITY_EVERY_NOTE) == 1 and result.stdout.count("note:") == 1


def test_sweep_check_lists_where_runs_stand_and_only_runs_a_part(tmp_path):
    """`--check` lists the runs and their state without starting anything; `--only` steps the runs
    whose names match, while complete runs stay in summary.csv; a pattern matching nothing is refused."""
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path))
    result = cli("sweep", str(path), "--only", "*dt9", "--check")
    assert result.returncode == 2 and "matches none" in result.stderr
    result = cli("sweep", str(path), "--check")
    assert result.returncode == 0, result.stderr
    assert "4 runs" in result.stdout and "0 complete, 0 to resume, 4 to run" in result.stdout
    assert not (tmp_path / "grid").exists()  # nothing started
    result = cli("sweep", str(path), "--only", "eta0.5_dt0.04", "--workers", "1")
    assert result.returncode == 0, result.stderr
    assert list(_rows(tmp_path / "grid" / "summary.csv")) == ["eta0.5_dt0.04"]
    result = cli("sweep", str(path), "--check")
    listed = [line for line in result.stdout.splitlines()[1:] if line.startswith("  ") and not line.startswith("   ")]
    lines = {line.split()[0]: line.split(None, 1)[1] for line in listed}
    assert lines == {"eta0.5_dt0.04": "complete", "eta0.5_dt5": "to run", "eta1_dt0.04": "to run", "eta1_dt5": "to run"}
    # Each run still to make: its margins, predicted overlap and cost (dt = 5 s: eq. 17's margin far below 10,
    # run all the same under allow_unstable).
    details = [line.strip() for line in result.stdout.splitlines()[1:] if line.startswith("   ")]
    assert len(details) == 3 and sum("time step 0.437 (>= 10)" in d for d in details) == 2
    assert all(d.startswith("eta ") and "predicted deepest overlap" in d and "on cpu" in d and "REFUSED" not in d for d in details)
    result = cli("sweep", str(path), "--only", "eta1_dt0*", "--workers", "1", env={**os.environ, "DECCO_LOG_EVERY": "0"})
    assert result.returncode == 0, result.stderr
    made = [int(line.split("runs, ")[1].split(" %")[0]) for line in result.stderr.splitlines() if "% of the steps made" in line]
    assert made[0] == 50 and made[-1] == 100 and made == sorted(made)  # the complete run counts from the start
    rows = _rows(tmp_path / "grid" / "summary.csv")
    assert set(rows) == {"eta0.5_dt0.04", "eta1_dt0.04"}
    assert rows["eta0.5_dt0.04"]["status"] == "skipped (complete)" and rows["eta1_dt0.04"]["status"] == "ok"
    # A run whose checkpoint is short of its steps (here: asked for more) resumes from it.
    spec_file = tmp_path / "grid" / "eta1_dt0.04" / "spec.toml"
    spec_file.write_text(spec_file.read_text().replace("steps = 200", "steps = 400"))
    result = cli("sweep", str(path), "--check", "--only", "eta1_dt0.04")
    assert result.returncode == 0, result.stderr
    lines = {line.split()[0]: line.split(None, 1)[1] for line in result.stdout.splitlines()[1:] if line.startswith("  ") and not line.startswith("   ")}
    assert lines == {"eta0.5_dt0.04": "complete", "eta1_dt0.04": "resumes at step 200"}
    assert "1 complete, 1 to resume, 0 to run" in result.stdout
    # The progress a sweep reports while its runs step: each run by its last checkpoint.
    fractions = {run["run"]["name"]: stepped_fraction(run) for run in load_sweep(path)[1]}
    assert fractions == {"eta0.5_dt0.04": 1.0, "eta0.5_dt5": 0.0, "eta1_dt0.04": 0.5, "eta1_dt5": 0.0}

"""Campaigns past one process: a sweep's faults (a worker killed mid-run, a worker's device gone, the
scheduler stopped, the disk full mid-sweep) and Slurm job arrays run as a local loop.

Every test makes the same grid of two small runs (the shipped piles, 100 and 200 steps on the CPU)
and holds what it ends with to one uninterrupted sweep of it: no finished run lost, summary.csv
whole, every outcome the same to the last digit (a resumed run on the CPU is bit-identical). The
200-step run is held at step 150 (DECCO_TEST_PAUSE) while the fault is made; the 100-step run has
finished by then. The runs take the CPU; `DECCO_TEST_CAMPAIGN_DEVICE=cuda pytest tests/test_campaigns.py`
makes the same faults with the runs on a GPU machine's GPUs (a resumed run there is bit-identical too)."""

import csv
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from helpers import cli_here

pytest.importorskip("distributed")

#: The device the grid's runs take (cpu; cuda to make the faults on a GPU machine).
DEVICE = os.environ.get("DECCO_TEST_CAMPAIGN_DEVICE", "cpu")
GRID = """
[sweep]
name = "campaign"
out = "{out}"
min_members = 20
analyze_every = 4
ensemble = 1
[sweep.grid]
"run.steps" = [100, 200]
[run]
output_every = 50
checkpoint_every = 50
device = "{device}"
"""
#: What a run came to: held equal to the uninterrupted sweep's, digit for digit.
OUTCOME = ("steps", "largest_mass_ratio", "clusters", "settled", "particle_size_change", "deepest_overlap", "ledger_closure", "n_particles")
#: The step at which the 200-step run is held while a test makes its fault.
HOLD = "step@150"


def _grid(tmp_path) -> Path:
    path = tmp_path / "campaign.toml"
    path.write_text(GRID.format(out=tmp_path / "out", device=DEVICE))
    return path


def _rows(sweep_dir: Path) -> dict:
    with open(sweep_dir / "summary.csv") as f:
        return {row["run"]: row for row in csv.DictReader(f)}


def _outcomes(rows: dict) -> dict:
    return {name: {key: row[key] for key in OUTCOME} for name, row in rows.items()}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The grid swept without a fault: its rows."""
    tmp_path = tmp_path_factory.mktemp("reference")
    result = cli_here("sweep", str(_grid(tmp_path)), "--workers", "2", "--analysis-workers", "1")
    assert result.returncode == 0, result.stderr
    rows = _rows(tmp_path / "out" / "campaign")
    assert {name: row["status"] for name, row in rows.items()} == {"steps100": "ok", "steps200": "ok"}
    return _outcomes(rows)


def _assert_whole(sweep_dir: Path, reference: dict, statuses: dict) -> dict:
    """summary.csv holds every run, with the statuses given and the uninterrupted sweep's outcomes."""
    rows = _rows(sweep_dir)
    assert {name: row["status"] for name, row in rows.items()} == statuses
    assert _outcomes(rows) == reference
    return rows


class Hold:
    """The 200-step run held at HOLD in whichever process steps it: ``env`` for that process; ``at(what)``
    calls ``what()`` once the run is held and the 100-step run's row is in summary.csv, then lets the
    run go on, and lets it go again each time it comes back to HOLD (a retried run passes it again)."""

    def __init__(self, tmp_path, release: bool = True):
        self.release = release  # False: the run stays held once the fault is made (its process dies so)
        self.mark = tmp_path / "held"
        self.table = tmp_path / "out" / "campaign" / "summary.csv"
        self.run_dir = tmp_path / "out" / "campaign" / "steps200"
        self.env = {"DECCO_TEST_PAUSE": HOLD, "DECCO_TEST_PAUSE_MARK": str(self.mark)}
        self.done = threading.Event()
        self.made = threading.Event()

    def at(self, what) -> "Hold":
        def watch():
            deadline = time.time() + 180
            while not self.done.is_set() and time.time() < deadline:
                if self.mark.exists() and (self.made.is_set() or (self.table.exists() and "steps100" in self.table.read_text())):
                    if not self.made.is_set():
                        what()
                        self.made.set()
                    if self.release:
                        self.mark.unlink(missing_ok=True)
                time.sleep(0.05)

        threading.Thread(target=watch, daemon=True).start()
        return self

    def holder(self) -> int:
        """The pid of the process stepping the held run (its folder's lock says)."""
        return int((self.run_dir / ".lock").read_text().split()[0])


def test_a_worker_killed_mid_run_is_replaced_and_its_run_resumes_from_its_checkpoint(reference, tmp_path, monkeypatch):
    """SIGKILL of the worker process stepping a run: its nanny starts another, Dask hands it the run,
    which resumes from its checkpoint of step 100; the sweep ends whole by itself and says so."""
    hold = Hold(tmp_path)
    for name, value in hold.env.items():
        monkeypatch.setenv(name, value)  # the local workers' environment
    killed = []
    hold.at(lambda: killed.append(os.kill(hold.holder(), signal.SIGKILL) or hold.holder()))
    try:
        result = cli_here("sweep", str(_grid(tmp_path)), "--workers", "1", "--analysis-workers", "1")
    finally:
        hold.done.set()
    assert killed and result.returncode == 0, result.stderr
    _assert_whole(tmp_path / "out" / "campaign", reference, {"steps100": "ok", "steps200": "ok"})
    said = " ".join(result.stderr.split())
    assert "steps200: ok" in said and "its worker was lost: Dask handed it to another, which resumed it from its checkpoint of step 100" in said, said
    log = (hold.run_dir / "run.log").read_text()
    assert "resume: from step 100 of 200" in log and "stopped" not in log


def test_a_worker_whose_device_is_gone_hands_its_runs_to_the_other_workers(reference, tmp_path):
    """One of a scheduler's two workers loses its device (here its $DECCO_DEVICE names a GPU this
    machine has not): the batch it is handed comes back, goes to the other worker, and the sweep says so."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, Client(cluster) as client:
        gone = sorted(client.scheduler_info()["workers"])[1]
        client.run(lambda: os.environ.__setitem__("DECCO_DEVICE", "cuda:99"), workers=[gone])
        result = cli_here("sweep", str(_grid(tmp_path)), "--scheduler", cluster.scheduler_address, "--analysis-workers", "1")
    assert result.returncode == 0, result.stderr
    said = " ".join(result.stderr.split())
    # No CUDA here, or not 100 GPUs: either way the device is gone, and the message says which.
    gone_why = r"( asks for CUDA, but Warp finds no CUDA device here|: there are only \d+ CUDA device\(s\))"
    assert re.search(rf"worker {re.escape(gone)} cannot use its device \(device 'cuda:99'{gone_why}", said), said
    assert "go to the other workers" in said
    rows = _assert_whole(tmp_path / "out" / "campaign", reference, {"steps100": "ok", "steps200": "ok"})
    assert all(row["device"].startswith(DEVICE) and row["device"] != "cuda:99" for row in rows.values()), rows


def test_a_stopped_scheduler_ends_the_sweep_keeping_its_finished_runs_and_the_same_command_finishes(reference, tmp_path):
    """The scheduler stops while the 200-step run steps: the sweep ends (exit 3) with the 100-step
    run in summary.csv and a line that says to start a scheduler and run the same command; with a
    scheduler at the same address again, it skips the finished run and resumes the other."""
    import dask
    from distributed import Client, LocalCluster

    hold = Hold(tmp_path, release=False)  # its worker goes with the cluster, as on a node that is lost
    path = _grid(tmp_path)
    options = dict(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None)
    # Closing a cluster whose scheduler is gone tries to reach it for the connect timeout (30 s by default).
    with dask.config.set({"distributed.comm.timeouts.connect": "2s"}), LocalCluster(**options, env=hold.env) as cluster:
        address, port = cluster.scheduler_address, cluster.scheduler.port
        sweep = subprocess.Popen(
            [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", "sweep", str(path), "--scheduler", address,
             "--analysis-workers", "1"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        hold.at(lambda: (cluster.sync(cluster.scheduler.close), os.kill(hold.holder(), signal.SIGKILL)))  # its node, say
        try:
            _, stderr = sweep.communicate(timeout=180)
        finally:
            hold.done.set()
    assert sweep.returncode == 3, stderr
    line = " ".join(stderr.split("decco-warp: ")[-1].split())
    assert f"it lost its Dask scheduler at {address}" in line and "summary.csv holds the 1 finished" in line, line
    assert "run the same command" in line and "Traceback" not in stderr, stderr
    assert {name: row["status"] for name, row in _rows(tmp_path / "out" / "campaign").items()} == {"steps100": "ok"}
    with LocalCluster(**options, scheduler_port=port) as cluster, Client(cluster):
        assert cluster.scheduler_address == address
        again = cli_here("sweep", str(path), "--scheduler", address, "--analysis-workers", "1")
    assert again.returncode == 0, again.stderr
    _assert_whole(tmp_path / "out" / "campaign", reference, {"steps100": "skipped (complete)", "steps200": "ok"})


def test_a_disk_that_fills_mid_sweep_ends_it_with_exit_5_and_the_same_command_finishes(reference, tmp_path, monkeypatch):
    """The disk fills (DECCO_TEST_FULL: every write of every process fails) while the 200-step run is
    at step 150, after the 100-step run finished: the run fails at its next frame keeping its
    checkpoint of step 100, the sweep cannot add it to summary.csv and ends with exit 5 and one line;
    summary.csv holds the finished run, whole. Space freed, the same command finishes."""
    hold = Hold(tmp_path)
    full = tmp_path / "full"
    for name, value in {**hold.env, "DECCO_TEST_FULL": str(full)}.items():
        monkeypatch.setenv(name, value)
    hold.at(lambda: full.write_text(""))
    path = _grid(tmp_path)
    try:
        result = cli_here("sweep", str(path), "--workers", "1", "--analysis-workers", "1")
    finally:
        hold.done.set()
    assert result.returncode == 5, result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("decco-warp")]
    assert len(errors) == 1 and "Traceback" not in result.stderr, result.stderr
    assert "No space left on device" in errors[0] and "run the sweep again" in errors[0], errors[0]
    sweep_dir = tmp_path / "out" / "campaign"
    assert {name: row["status"] for name, row in _rows(sweep_dir).items()} == {"steps100": "ok"}
    assert not list(sweep_dir.rglob(".*.tmp"))
    full.unlink()
    monkeypatch.delenv("DECCO_TEST_PAUSE")
    again = cli_here("sweep", str(path), "--workers", "1", "--analysis-workers", "1")
    assert again.returncode == 0, again.stderr
    _assert_whole(sweep_dir, reference, {"steps100": "skipped (complete)", "steps200": "ok"})
    assert "resume: from step 100 of 200" in (sweep_dir / "steps200" / "run.log").read_text()


# --- Slurm job arrays ---------------------------------------------------------------------------------


def test_a_job_array_run_as_a_local_loop_then_collected_gives_the_sweep_s_summary(reference, tmp_path, monkeypatch):
    """`--array` writes the script; its tasks, run one by one as Slurm would run them (bash, with
    SLURM_ARRAY_TASK_ID), step and analyse their runs; a task run again skips its run; `--collect`
    writes the summary.csv that a sweep on Dask workers writes, rows and outcomes."""
    monkeypatch.chdir(tmp_path)
    path = _grid(tmp_path)
    made = cli_here("sweep", str(path), "--array")
    assert made.returncode == 0, made.stderr
    script = tmp_path / "out" / "campaign" / "array" / "array.sh"
    assert f"submit: sbatch {script}" in made.stdout
    text = script.read_text()
    if DEVICE == "cpu":  # 0.2 s of stepping on the CPU, no GPU asked for
        assert "#SBATCH --array=0-1\n#SBATCH --time=00:11:00\n" in text and "--gres" not in text
    else:
        assert "#SBATCH --array=0-1\n" in text and "#SBATCH --gres=gpu:1\n" in text
    commands = dict(re.findall(r"^  (\d+)\) exec (decco-warp sweep .*) ;;$", text, re.M))
    assert {k: shlex.split(c)[3:] for k, c in commands.items()} == {"0": ["--task", "steps100"], "1": ["--task", "steps200"]}
    for k in commands:
        task = subprocess.run(["bash", str(script)], env={**os.environ, "SLURM_ARRAY_TASK_ID": k}, capture_output=True, text=True)
        assert task.returncode == 0, task.stderr
        assert task.stdout.startswith(f"steps{100 * (int(k) + 1)}: ok"), task.stdout
    again = cli_here(*shlex.split(commands["0"])[1:])  # a task submitted again
    assert again.returncode == 0 and again.stdout.startswith("steps100: skipped (complete)"), again.stdout + again.stderr
    collected = cli_here("sweep", str(path), "--collect")
    assert collected.returncode == 0, collected.stderr
    sweep_dir = tmp_path / "out" / "campaign"
    _assert_whole(sweep_dir, reference, {"steps100": "ok", "steps200": "ok"})
    assert (sweep_dir / "figures" / "largest_fragment.png").stat().st_size > 1000
    assert cli_here("sweep", str(path), "--array").returncode == 2  # nothing left to make: one line, exit 2


def test_a_gpu_sweep_s_array_asks_each_task_for_a_gpu_for_its_estimated_time(tmp_path, monkeypatch):
    """Runs on "auto" ask each task for a GPU, and for the time --check's cost gives at an H100's rates
    (this machine needs none: the runs are planned on its CPU); a task of runs still to make only."""
    from decco_warp import jobarray
    from decco_warp.costs import step_seconds
    from decco_warp.scheme import Scheme

    monkeypatch.chdir(tmp_path)
    path = tmp_path / "gpu.toml"
    path.write_text(GRID.format(out=tmp_path / "out", device="auto").replace("ensemble = 1\n", "").replace("[100, 200]", "[40000000, 80000000]"))
    made = cli_here("sweep", str(path), "--array")
    assert made.returncode == 0, made.stderr
    text = (tmp_path / "out" / "campaign" / "array" / "array.sh").read_text()
    both = step_seconds(450, Scheme(), "cuda:0") * 120_000_000  # one task: "auto" packs runs on a GPU, up to 8 to a worker
    assert "#SBATCH --array=0-0\n" in text and "--task steps40000000 --task steps80000000 ;;" in text
    assert "#SBATCH --gres=gpu:1" in text and f"#SBATCH --time={jobarray.time_limit(both)}\n" in text
    assert jobarray.time_limit(0) == "00:10:00" and jobarray.time_limit(3600) == "01:40:00" and jobarray.time_limit(2 * 86400) == "3-00:10:00"


def test_the_documented_dask_jobqueue_configuration_asks_slurm_for_a_single_threaded_worker_a_gpu(monkeypatch):
    """docs/sweeps.md's SLURMCluster, made as written (its scheduler on this machine, no job
    submitted): each job one worker of one thread, with a GPU and the walltime asked for."""
    pytest.importorskip("dask_jobqueue")
    import dask
    import dask_jobqueue

    text = (Path(__file__).parents[1] / "docs" / "sweeps.md").read_text()
    (block,) = re.findall(r"^```python\n(from dask_jobqueue import SLURMCluster\n.*?)^```$", text, re.S | re.M)
    scaled = []
    monkeypatch.setattr(dask_jobqueue.SLURMCluster, "scale", lambda self, *args, **kwargs: scaled.append((args, kwargs)))
    names: dict = {}
    with dask.config.set({"jobqueue.slurm.scheduler-options": {"host": "127.0.0.1", "dashboard_address": None}}):
        exec(compile(block, "docs/sweeps.md", "exec"), names)
    cluster = names["cluster"]
    try:
        script = cluster.job_script()
    finally:
        cluster.close()
    assert ((), {"jobs": 4}) in scaled  # the block's own call (closing scales to 0)
    assert "#SBATCH --gres=gpu:1" in script and "#SBATCH -t 04:00:00" in script and "source .venv/bin/activate" in script
    worker = next(line for line in script.splitlines() if "dask_worker" in line)
    assert "--nthreads 1 " in worker and "--nworkers" not in worker and cluster.scheduler_address in worker

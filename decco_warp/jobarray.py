"""A sweep as a Slurm job array: the script (``sweep --array``), a task (``sweep --task RUN ...``) and
the gathering of what the tasks made (``sweep --collect``).

Each task steps its runs in its own process on the GPU Slurm gives it (one run, or the runs a
worker would be handed at a time and step together as an ensemble), then analyses them there, and
records each run's row in the sweep folder's ``array/rows/``.  A task is idempotent: a run complete
is skipped, a stopped or killed one resumes from its checkpoint, and a run folder that another task
is writing is refused by its lock; so the same script may be submitted again after a time limit, a
failed node or a change of the grid.  ``--collect`` then analyses what the tasks left unanalysed
and writes the sweep's summary.csv and figures, in grid order, as a sweep on Dask workers would.
"""

from __future__ import annotations

import json
import math
import shlex
import shutil
import sys
from pathlib import Path

from . import sweep as sweeps
from .durable import json_text, write_atomic

#: The folder of a sweep's folder that holds its array's script, task logs and rows.
ARRAY = "array"
#: A task's time limit: its estimate (costs.step_seconds) times this, plus TASK_EXTRA_SECONDS for
#: Warp's start and kernel compiles on a fresh node, the frames' writes and the analysis.
TASK_TIME_FACTOR = 1.5
TASK_EXTRA_SECONDS = 600
#: CPU cores a task asks for: the run steps on one, the analysis's NumPy and the writes use the rest.
TASK_CPUS = {"gpu": 4, "cpu": 2}


def array_folder(settings: dict) -> Path:
    return Path(settings["out"]) / settings["name"] / ARRAY


def on_gpu(runs: list[dict]) -> bool:
    """Whether the tasks ask for a GPU: unless every run names the CPU ([run] device = "cpu")."""
    return any(run["run"]["device"] != "cpu" for run in runs)


def tasks(settings: dict, runs: list[dict]) -> list[list[dict]]:
    """The runs still to make, in grid order, cut into tasks as a sweep hands them to one worker:
    ``[sweep] ensemble`` at a time ("auto": up to AUTO_ENSEMBLE on a GPU, one on the CPU)."""
    todo = [run for run in runs if sweeps._complete_row(run) is None]
    size, _ = sweeps.ensemble_plan(settings.get("ensemble", 1), 1 if on_gpu(runs) else 0, len(todo), workers=1)
    return [todo[k : k + size] for k in range(0, len(todo), size)]


def stepping_seconds(spec: dict, device: str) -> float:
    """About how long a run still to make steps on ``device`` (``cuda``: an H100's rates), planned here
    on the CPU so that a login node without a GPU can make the script."""
    from dataclasses import replace

    from .costs import step_seconds
    from .plan import plan_start
    from .scheme import choose_gravity

    plan = plan_start(spec, "cpu")
    gravity = spec["params"]["gravity"]
    gravity = choose_gravity(plan.state.n, device) if gravity == "auto" else gravity
    done = sweeps._standing(spec)[1]
    return step_seconds(plan.state.n, replace(plan.scheme, gravity=gravity), device) * max(0, plan.steps - done)


def time_limit(seconds: float) -> str:
    """Slurm's --time for a task estimated at ``seconds`` of stepping: D-HH:MM:SS, whole minutes."""
    minutes = math.ceil((seconds * TASK_TIME_FACTOR + TASK_EXTRA_SECONDS) / 60 - 1e-9)  # a sum's last bits never add a minute
    days, minutes = divmod(minutes, 24 * 60)
    return f"{days}-{minutes // 60:02d}:{minutes % 60:02d}:00" if days else f"{minutes // 60:02d}:{minutes % 60:02d}:00"


def task_command(sweep_file: Path, batch: list[dict], resolution: float | None) -> str:
    """The command line of one task: this sweep file, its runs by name."""
    words = ["decco-warp", "sweep", str(sweep_file.resolve())]
    if resolution is not None:
        words += ["--resolution", f"{resolution:g}"]
    for run in batch:
        words += ["--task", run["run"]["name"]]
    return shlex.join(words)


def write_script(settings: dict, runs: list[dict], sweep_file: Path, resolution: float | None = None) -> tuple[Path, list[str]]:
    """The job-array script of a sweep's runs still to make, in ``array/array.sh`` of its folder, and
    what it holds in lines to print.  InputError for a folder that cannot be written; SpecError when
    every run is complete (there is no task to make: ``--collect`` gathers them)."""
    from .checks import check_destination
    from .costs import duration
    from .spec import SpecError

    batches = tasks(settings, runs)
    if not batches:
        raise SpecError(f"every run of sweep {settings['name']} is complete: no task to make; decco-warp sweep {sweep_file} --collect gathers them")
    kind = "gpu" if on_gpu(runs) else "cpu"
    device = "cuda:0" if kind == "gpu" else "cpu"
    seconds = [sum(stepping_seconds(run, device) for run in batch) for batch in batches]
    folder = array_folder(settings).resolve()
    check_destination(folder, "array folder", folder=True)
    folder.mkdir(parents=True, exist_ok=True)
    rates = "an H100's rates" if kind == "gpu" else "this machine's CPU"
    where = Path(shutil.which("decco-warp") or Path(sys.executable).with_name("decco-warp")).parent
    lines = [
        "#!/bin/bash",
        f"# Sweep {settings['name']} as a Slurm job array: {len(batches)} task(s) of {sum(map(len, batches))} run(s) still to make,",
        "# each `decco-warp sweep FILE --task RUN ...`: its runs stepped in one process (together where they share",
        "# their Params), analysed, and their rows kept in array/rows/. A task is idempotent (a run complete is",
        "# skipped, a stopped one resumes from its checkpoint, a run folder in use is refused), so submit the",
        "# script again after a time limit or a failure. When the tasks are done:",
        f"#   decco-warp sweep {sweep_file.resolve()} --collect",
        f"# Time limit: the longest task's stepping, {duration(max(seconds))} at {rates} (docs/benchmarks.md),",
        f"# x {TASK_TIME_FACTOR:g} + {TASK_EXTRA_SECONDS // 60} min; raise --time for a slower device.",
        f"#SBATCH --job-name=decco-{settings['name']}",
        f"#SBATCH --array=0-{len(batches) - 1}",
        f"#SBATCH --time={time_limit(max(seconds))}",
        *(["#SBATCH --gres=gpu:1"] if kind == "gpu" else []),
        f"#SBATCH --cpus-per-task={TASK_CPUS[kind]}",
        f"#SBATCH --output={folder}/task-%A_%a.log",
        f"#SBATCH --chdir={Path.cwd()}",
        "set -euo pipefail",
        f'export PATH="{where}:$PATH"',
        'case "${SLURM_ARRAY_TASK_ID:?submit with sbatch, or set SLURM_ARRAY_TASK_ID}" in',
        *(f"  {k}) exec {task_command(sweep_file, batch, resolution)} ;;" for k, batch in enumerate(batches)),  # Slurm's SIGTERM to decco-warp
        '  *) echo "no task ${SLURM_ARRAY_TASK_ID} in this array" >&2; exit 2 ;;',
        "esac",
    ]
    path = write_atomic(folder / "array.sh", "\n".join(lines) + "\n")
    path.chmod(0o755)
    said = [f"array of {len(batches)} task(s) for the {sum(map(len, batches))} run(s) to make ({len(runs) - sum(map(len, batches))} complete): {path}",
            f"each task: {'a GPU' if kind == 'gpu' else 'CPUs'}, --time {time_limit(max(seconds))} (the longest task, {duration(max(seconds))} of stepping at {rates}, x {TASK_TIME_FACTOR:g} + {TASK_EXTRA_SECONDS // 60} min)",
            f"submit: sbatch {path}", f"then: decco-warp sweep {sweep_file} --collect"]  # fmt: skip
    return path, said


def run_task(settings: dict, runs: list[dict], names: list[str]) -> list[dict]:
    """One task of the array: the runs named, stepped here as a worker steps a batch (simulate_batch,
    on $DECCO_DEVICE or the first GPU), each one finished analysed here; every run's row recorded in
    ``array/rows/NAME.json``.  Returns the rows (analysed where they were).  SpecError for a name the
    sweep has not."""
    from .device import local_gpus
    from .spec import SpecError

    by_name = {run["run"]["name"]: run for run in runs}
    unknown = [name for name in names if name not in by_name]
    if unknown:
        raise SpecError(f"--task {unknown[0]}: sweep {settings['name']} has no such run (the first is {runs[0]['run']['name']})")
    batch = [run for run in runs if run["run"]["name"] in set(names)]  # grid order
    _, max_particles = sweeps.ensemble_plan(settings.get("ensemble", 1), 1 if on_gpu(batch) else 0, len(batch))
    rows = [sweeps.with_set_up(row, spec, settings) for row, spec in zip(sweeps.simulate_batch(batch, max_particles), batch)]
    folder = array_folder(settings) / "rows"
    folder.mkdir(parents=True, exist_ok=True)
    gpus = local_gpus()
    for k, row in enumerate(rows):
        recorded = folder / f"{row['run']}.json"
        if not (row["status"] == "skipped (complete)" and recorded.is_file()):  # a task submitted again keeps the row that made it
            write_atomic(recorded, json_text(row))  # before the analysis: a stopped task's runs are known
        if row["status"] in ("ok", "skipped (complete)"):
            try:
                device = sweeps.analysis_device(row, gpus, k)
                rows[k] = sweeps.analysed(row, sweeps.analyse_one(*sweeps.analysis_args(row, settings, device)))
            except (OSError, ValueError, RuntimeError) as error:  # --collect tries again
                rows[k] = sweeps.analysis_failed(row, error)
    return rows


def collect(settings: dict, runs: list[dict], analysis_workers: int | None = None, on_row=None) -> tuple[list[dict], list[str]]:
    """What the tasks made, gathered in grid order: each run's row as its task recorded it (a run
    complete without one was made before: "skipped (complete)"), analysed here where it is not yet
    (in processes, each on the device :func:`~decco_warp.sweep.analysis_device` picks), each told to
    ``on_row``.  Returns the rows of the runs finished (made, failed or skipped) and, for each run
    not finished (no task made it, or its task stopped), a line saying where it stands."""
    from .device import local_gpus
    from .processes import usable_cores

    recorded = array_folder(settings) / "rows"
    analyses = sweeps.Analyses(analysis_workers or usable_cores(), local_gpus())
    rows: list[dict | None] = [None] * len(runs)
    pending, missing = {}, []
    try:
        for k, spec in enumerate(runs):
            path = recorded / f"{spec['run']['name']}.json"
            row = json.loads(path.read_text()) if path.is_file() else sweeps._complete_row(spec)
            if row is not None and row["status"] == "ok" and sweeps._complete_row(spec) is None:
                row = None  # recorded by a task, then its folder changed (a run asked for more steps)
            if row is None or row["status"] == "stopped":
                missing.append(f"{spec['run']['name']}: {sweeps.run_state(spec)}")
            elif row["status"] == "failed":
                rows[k] = sweeps.with_set_up(row, spec, settings)
            else:
                row = sweeps.with_set_up(row, spec, settings)
                pending[k] = analyses.submit(row, settings), row
        for k, (future, row) in pending.items():
            try:
                rows[k] = sweeps.analysed(row, future.result())
            except Exception as error:  # a damaged trajectory, a full disk: this run only
                rows[k] = sweeps.analysis_failed(row, error)
    finally:
        analyses.shutdown(wait=True)
    finished = [row for row in rows if row is not None]
    for row in finished:
        if on_row is not None:
            on_row(row)
    return finished, missing


def collect_job(job, analysis_workers: int | None = None, on_row=None) -> list[str]:
    """:func:`collect` into a claimed SweepJob: its rows once every run is finished (``job.finish()``
    then writes summary.csv and the figures), else summary.csv of those finished, as a stopped
    sweep keeps it; returns the lines of the runs not finished."""
    rows, missing = collect(job.settings, job.runs, analysis_workers, on_row)
    job.finished = rows
    if missing:
        sweeps.write_summary(job.folder, rows, job.swept)
    else:
        job.rows = rows
    return missing

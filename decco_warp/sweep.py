"""Parameter sweeps: a grid of runs executed with Dask, then analysed together.

A sweep specification is a run specification plus a ``[sweep]`` table:

    [sweep]
    name = "fig3-reduced"          # the sweep folder under out
    out = "runs/out"
    min_members = 50               # for the analysis of each run
    analyse_every = 1              # analyse every Nth frame of a run (the last one always)
    keep_trajectory = true         # false: delete trajectory.h5 once the run is analysed
    ensemble = "auto"              # runs handed to a worker at a time; those sharing Params step together
                                   # (auto: 4 at a time on a GPU, runs of the same particle count up to
                                   # 8 000 particles stepped together, larger ones alone; 1 on a CPU)
    [sweep.grid]                   # the cartesian product of these lists
    "collision.eta" = [0.5, 1.0, 2.0]
    "collision.theta_deg" = [0.0, 22.0]

Every combination is checked as a run specification before anything runs.  The
runs go to Dask workers (one per GPU); each finished run is analysed on this
machine's cores while the workers go on with the next runs.  A run already
complete and analysed is skipped (so an interrupted sweep resumes), a run
stopped part-way is resumed, and a run that fails is recorded with its reason
without stopping the others.
"""

from __future__ import annotations

import csv
import itertools
import json
import multiprocessing
import os
import platform
import time
from concurrent.futures import Future, ProcessPoolExecutor
from datetime import datetime, timezone
from pathlib import Path

from . import spec as specs
from ._version import __version__

#: ``ensemble = "auto"`` on a GPU: runs go to a worker 4 at a time, and those of the same particle
#: count up to 8 000 are stepped together (on an H100, 4 systems of 5 500 to 6 250 particles step
#: 1.35 to 1.47 times as fast as one at a time; at 10 000 one run nearly fills the GPU: 1.07x for 2).
AUTO_ENSEMBLE = 4
ENSEMBLE_MAX_PARTICLES = 8_000
SWEEP_KEYS = {"name", "out", "min_members", "analyse_every", "keep_trajectory", "ensemble", "grid"}
SUMMARY_FIELDS = [
    "run", "status", "reason", "n_particles", "mass_ratio", "theta_deg", "eta", "speed", "k_in", "dt", "steps",
    "largest_mass_ratio", "ls12_largest_mass_ratio", "particle_size_change", "clusters", "deepest_overlap", "predicted_overlap",
    "momentum_drift", "angular_momentum_drift", "ledger_closure", "wall_seconds", "stepping_seconds", "analysis_seconds",
    "device", "device_name", "ensemble",
]  # fmt: skip
SUMMARY_FILE = "summary.json"
TRAJECTORY_FILE = "trajectory.h5"
CHECKPOINT_FILE = "checkpoint.h5"


def load_sweep(path) -> tuple[dict, list[dict]]:
    """(sweep settings, resolved run specifications) of a sweep file; SpecError names what is wrong."""
    raw = specs.load_spec_file(path)
    sweep = raw.pop("sweep", None)
    if not isinstance(sweep, dict):
        raise specs.SpecError(f"{path} has no [sweep] table")
    unknown = sorted(set(sweep) - SWEEP_KEYS)
    if unknown:
        raise specs.SpecError(f"unknown key [sweep] {unknown[0]}; allowed: {', '.join(sorted(SWEEP_KEYS))}")
    name = sweep.get("name", Path(path).stem)
    if not isinstance(name, str) or not specs._NAME.fullmatch(name):
        raise specs.SpecError(f"[sweep] name = {name!r}: must be letters, digits, '.', '_' and '-'")
    settings = {
        "name": name,
        "out": str(sweep.get("out", "runs/out")),
        "min_members": sweep.get("min_members", 50),
        "analyse_every": sweep.get("analyse_every", 1),
        "keep_trajectory": sweep.get("keep_trajectory", True),
        "ensemble": sweep.get("ensemble", "auto"),
    }
    for key in ("min_members", "analyse_every", "ensemble"):
        value = settings[key]
        if key == "ensemble" and value == "auto":
            continue
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            also = ' or "auto"' if key == "ensemble" else ""
            raise specs.SpecError(f"[sweep] {key} = {value!r}: must be an integer >= 1{also}")
    if not isinstance(settings["keep_trajectory"], bool):
        raise specs.SpecError(f"[sweep] keep_trajectory = {settings['keep_trajectory']!r}: must be true or false")
    grid = sweep.get("grid", {})
    if not isinstance(grid, dict) or not grid:
        raise specs.SpecError("[sweep.grid] must list at least one \"table.key\" = [values]")
    axes = []
    for dotted, values in grid.items():
        table, _, key = dotted.partition(".")
        if table not in specs.SCHEMA or key not in specs.SCHEMA[table] or table == "run" and key in ("name", "out"):
            raise specs.SpecError(f"[sweep.grid] {dotted!r} is not a sweepable \"table.key\"")
        if not isinstance(values, list) or not values:
            raise specs.SpecError(f"[sweep.grid] {dotted} must be a non-empty list")
        axes.append((table, key, values))
    runs = []
    for combination in itertools.product(*(values for _, _, values in axes)):
        run = {table: dict(values) for table, values in raw.items() if isinstance(values, dict)}
        labels = []
        for (table, key, _), value in zip(axes, combination):
            run.setdefault(table, {})[key] = value
            if table == "collision" and key in ("eta", "speed"):
                run[table].pop("speed" if key == "eta" else "eta", None)
            labels.append(f"{key}{_slug(value)}")
        run.setdefault("run", {})
        run["run"]["name"] = "_".join(labels)
        run["run"]["out"] = str(Path(settings["out"]) / name)
        runs.append(specs.resolve_spec(run))
    names = [r["run"]["name"] for r in runs]
    if len(set(names)) != len(names):
        raise specs.SpecError("[sweep.grid] gives two runs the same name; use values that differ in their text")
    return settings, runs


def _slug(value) -> str:
    """A value as a piece of a run name: a pile file by its stem, "+z" as "pz", "-z" as "mz"."""
    text = Path(str(value)).stem if isinstance(value, str) else f"{value:g}" if isinstance(value, float) else str(value)
    text = text.replace("+", "p").replace("-", "m") if isinstance(value, str) else text
    return "".join(c if c.isalnum() or c in ".-" else "_" for c in text)


# --- one run: simulated on a worker, analysed here ----------------------------------------


def simulate_one(spec: dict) -> dict:
    """Run (or resume, or skip) one run of a sweep on a Dask worker; never raises.

    Returns a row with ``status`` (ok, skipped (complete) or failed, with ``reason``),
    the run folder, the device, and the run's own wall time over all its sessions.
    """
    return simulate_batch([spec])[0]


def ensemble_plan(setting, gpus: int) -> tuple[int, int | None]:
    """``[sweep] ensemble`` as (runs handed to a worker at a time, the largest particle count
    stepped with others, None for any): ``"auto"`` packs the small runs on a GPU only."""
    if setting != "auto":
        return int(setting), None
    return (AUTO_ENSEMBLE, ENSEMBLE_MAX_PARTICLES) if gpus > 0 else (1, None)


def simulate_batch(batch: list[dict], max_particles: int | None = None) -> list[dict]:
    """Run (or resume, or skip) several runs of a sweep on one Dask worker, those that share their
    Params and step advanced together as one ensemble (decco_warp/ensemble.py: each writes what it
    would alone); never raises.  One row per run, as :func:`simulate_one` gives.  With
    ``max_particles`` only runs of the same particle count, up to that many, go together."""
    from .run import RUN_FAILURES, execute, execute_ensemble

    device = _worker_device()
    rows, prepared = zip(*(_prepare(spec, device) for spec in batch))
    rows = list(rows)
    groups: dict[tuple, list[int]] = {}
    for k, run in enumerate(prepared):
        if run is not None:
            params = specs.params_of(run.spec)
            # The tree steps one system at a time: its runs go alone.
            # Only runs that would be stepped alone with the same kernels go together.
            engine = run.sim.engine
            key = (params, engine.precision, engine.layout, run.sim.step_count) if params.gravity == "all-pairs" else (k,)
            if max_particles is not None:
                count = run.sim.engine.count
                key = (*key, count) if count <= max_particles else (k,)
            groups.setdefault(key, []).append(k)
    for members in groups.values():
        try:
            if len(members) == 1:
                outcomes = [execute(prepared[members[0]])]
            else:
                outcomes = execute_ensemble([prepared[k] for k in members])
        except RUN_FAILURES as error:  # the run, or the ensemble as a whole (its device memory, ...)
            outcomes = [error] * len(members)
        for k, outcome in zip(members, outcomes):
            rows[k]["ensemble"] = len(members)
            if isinstance(outcome, BaseException):
                rows[k].update(status="failed", reason=" ".join(str(outcome).split()))
            else:
                rows[k]["status"] = "ok"
    return [_timed(row) for row in rows]


def _prepare(spec: dict, device: str | None) -> tuple[dict, object]:
    """A sweep run's row so far, and the run prepared to start or resume (None if complete or failed)."""
    from .run import RUN_FAILURES, prepare_resume, prepare_start, run_dir_of

    run_dir = run_dir_of(spec)
    row = {"run": spec["run"]["name"], "run_dir": str(run_dir), "device": device or "auto"}
    try:
        checkpoint = run_dir / CHECKPOINT_FILE
        if checkpoint.is_file() and _run_complete(run_dir):
            row["status"] = "skipped (complete)"
            return row, None
        prepared = prepare_resume(run_dir, device=device) if checkpoint.is_file() else prepare_start(spec, overwrite=True, device=device)
        row["device"] = prepared.sim.device
        return row, prepared
    except RUN_FAILURES as error:
        row.update(status="failed", reason=" ".join(str(error).split()))
        return row, None


def _timed(row: dict) -> dict:
    """A row with the run's wall and stepping time over all its sessions (from its checkpoint)."""
    from .io import read_checkpoint
    from .run import RUN_FAILURES

    checkpoint = Path(row["run_dir"]) / CHECKPOINT_FILE
    try:
        if checkpoint.is_file():
            extra = read_checkpoint(checkpoint)[2]
            row["wall_seconds"] = round(float(extra["wall_seconds"]), 3)
            row["stepping_seconds"] = round(float(extra["stepping_seconds"]), 3) if "stepping_seconds" in extra else None
    except RUN_FAILURES as error:
        row.update(status="failed", reason=" ".join(str(error).split()))
    row["device_name"] = _device_name(row["device"])
    return row


def _run_complete(run_dir: Path) -> bool:
    """True when the run folder's checkpoint has reached the steps of its own spec.toml."""
    from .io import read_checkpoint

    spec = specs.resolve_spec(specs.load_spec_file(run_dir / "spec.toml"))
    return int(read_checkpoint(run_dir / CHECKPOINT_FILE)[0]["step"]) >= spec["run"]["steps"]


def _device_name(device: str) -> str:
    try:
        import warp as wp

        return str(wp.get_device(device).name) if device != "auto" else ""
    except Exception:  # the name is a label for the table, never a reason to fail
        return ""


def analyse_one(run_dir: str, min_members: int, analyse_every: int, keep_trajectory: bool, device: str | None = None) -> dict:
    """Analyse a finished run (unless its summary.json is current), draw its figures, and
    drop its trajectory if asked; returns its summary (``analysis_seconds``: what the analysis
    took when it ran, also for a run found analysed).  Runs in a process of this machine; the
    cluster finder's O(N^2) density is summed on ``device`` (default as for runs: this machine's
    GPU when it has one, where a 6 250-particle frame takes milliseconds, else NumPy)."""
    from .lock import RunFolderLock

    with RunFolderLock(run_dir):  # the run has finished: no one else should be writing there
        return _analyse(Path(run_dir), min_members, analyse_every, keep_trajectory, device)


def _analyse(run_dir: Path, min_members: int, analyse_every: int, keep_trajectory: bool, device: str | None = None) -> dict:
    from .analysis.figures import draw_run
    from .analysis.runs import analyse_run
    from .device import resolve_device

    summary_path = run_dir / SUMMARY_FILE
    trajectory = run_dir / TRAJECTORY_FILE
    settings = {"min_members": min_members, "analyse_every": analyse_every}
    previous = json.loads(summary_path.read_text()) if summary_path.is_file() else None
    current = previous is not None and all(previous.get(k) == v for k, v in settings.items())
    if trajectory.is_file() and not (current and summary_path.stat().st_mtime >= trajectory.stat().st_mtime):
        analysis = analyse_run(run_dir, min_members=min_members, every=analyse_every, device=resolve_device(device))
        draw_run(analysis, run_dir)
        summary = analysis["summary"]
    elif previous is not None:
        summary = previous  # analysed before (its trajectory may be gone)
    else:
        raise FileNotFoundError(f"{run_dir} has neither a trajectory nor a summary to report")
    if not keep_trajectory and trajectory.is_file():
        trajectory.unlink()  # analysis.h5, summary.json, figures/ and the checkpoint stay
        trajectory.with_name("trajectory.xdmf").unlink(missing_ok=True)  # it describes the trajectory only
    return summary


def _worker_device() -> str | None:
    """One GPU per Dask worker (by worker number, among the GPUs of the worker's own machine),
    each worker with its own Warp kernel cache."""
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return None
    from .device import cuda_device_count

    gpus = cuda_device_count()
    digits = "".join(c for c in str(worker.name) if c.isdigit())
    index = int(digits) if digits else 0
    import warp as wp

    cache = Path(os.environ.get("DECCO_CACHE", Path.home() / ".cache" / "decco-warp")) / f"warp-worker-{index}"
    if wp.config.kernel_cache_dir is None or "warp-worker-" not in str(wp.config.kernel_cache_dir):
        wp.config.kernel_cache_dir = str(cache)
    return f"cuda:{index % gpus}" if gpus > 0 else "cpu"


# --- the whole grid ------------------------------------------------------------------------


def run_sweep(
    settings: dict,
    runs: list[dict],
    scheduler: str | None = None,
    workers: int | None = None,
    on_result=None,
    analysis_workers: int | None = None,
) -> list[dict]:
    """Simulate every run with Dask and analyse each here as it finishes; one row per run, in grid order."""
    from distributed import Client, LocalCluster, as_completed

    from .device import cuda_device_count

    gpus = cuda_device_count()
    if scheduler:
        client = Client(scheduler)
        cluster = None
        simulating = 1
    else:
        simulating = workers or (gpus if gpus > 0 else min(2, os.cpu_count() or 1))
        cluster = LocalCluster(n_workers=simulating, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    # Analysis runs here, beside the workers, in fresh processes (its density on this machine's GPU if any).
    analysers = analysis_workers or max(1, (os.cpu_count() or 1) - (0 if gpus > 0 else simulating))
    pool = ProcessPoolExecutor(max_workers=analysers, mp_context=multiprocessing.get_context("spawn"))
    rows: list[dict | None] = [None] * len(runs)
    pending: dict[Future, tuple[int, dict]] = {}

    def finish(k: int, row: dict) -> None:
        rows[k] = row
        if on_result is not None:
            on_result(row)

    def collect() -> None:
        for future in [f for f in list(pending) if f.done()]:
            k, row = pending.pop(future)
            try:
                summary = future.result()
                finish(k, {**row, **{key: summary.get(key) for key in SUMMARY_FIELDS if key in summary}, "run": row["run"]})
            except Exception as error:  # a damaged trajectory, a full disk: this run only
                finish(k, {**row, "status": "failed", "reason": f"analysis: {' '.join(str(error).split())}"})

    try:
        # Runs in grid order, `ensemble` at a time to a worker (neighbours in a grid mostly share
        # their piles and Params, and those are stepped together).
        size, max_particles = ensemble_plan(settings.get("ensemble", 1), gpus)
        batches = [list(range(k, min(k + size, len(runs)))) for k in range(0, len(runs), size)]
        futures = {client.submit(simulate_batch, [runs[k] for k in batch], max_particles, pure=False): batch for batch in batches}
        simulations = as_completed(futures)
        while not simulations.is_empty() or pending:
            # Poll both kinds of work, so that each run is reported as soon as its analysis ends.
            for future in simulations.next_batch(block=False):
                batch = futures[future]
                try:
                    results = future.result()
                except Exception as error:  # a worker that died: record it, go on
                    results = [{"run": runs[k]["run"]["name"], "status": "failed", "reason": f"worker lost: {error}"} for k in batch]
                for k, row in zip(batch, results):
                    collision = runs[k]["collision"]
                    row.update(eta=collision.get("eta"), speed=collision.get("speed"), theta_deg=collision["theta_deg"])
                    if row["status"] == "failed":
                        finish(k, row)
                    else:
                        args = (row["run_dir"], settings["min_members"], settings["analyse_every"], settings["keep_trajectory"])
                        pending[pool.submit(analyse_one, *args)] = (k, row)
            collect()
            time.sleep(POLL_SECONDS)
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        client.close()
        if cluster is not None:
            cluster.close()
    return rows


#: How often the sweep looks for finished simulations and analyses [s].
POLL_SECONDS = 0.2


def write_summary(folder: Path, rows: list[dict]) -> Path:
    path = folder / "summary.csv"
    folder.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=SUMMARY_FIELDS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path


def write_record(folder: Path, settings: dict, rows: list[dict], wall_seconds: float) -> Path:
    """sweep.json: what ran where, with which versions, and how long it took."""
    import warp as wp

    devices = sorted({(r.get("device"), r.get("device_name")) for r in rows if r.get("device")})
    record = {
        "sweep": settings["name"],
        "finished": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "wall_seconds": round(wall_seconds, 1),
        "run_seconds": round(sum(float(r.get("wall_seconds") or 0) for r in rows if r.get("status") == "ok"), 1),
        "runs": {status: sum(1 for r in rows if r.get("status") == status) for status in sorted({r.get("status") for r in rows})},
        "devices": [{"device": d, "name": n} for d, n in devices],
        "host": platform.node(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "decco_warp": __version__,
        "warp": wp.config.version,
        "settings": settings,
    }
    path = folder / "sweep.json"
    path.write_text(json.dumps(record, indent=2) + "\n")
    return path

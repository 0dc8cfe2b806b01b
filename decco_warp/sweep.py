"""Parameter sweeps: a grid of runs executed with Dask, then analysed together.

A sweep specification is a run specification plus a ``[sweep]`` table:

    [sweep]
    name = "fig3-reduced"          # the sweep folder under out
    out = "runs/out"
    min_members = 50               # for the analysis of each run
    [sweep.grid]                   # the cartesian product of these lists
    "collision.eta" = [0.5, 1.0, 2.0]
    "collision.theta_deg" = [0.0, 22.0]

Every combination is checked as a run specification before anything runs.  A
run already complete is skipped (so an interrupted sweep resumes), a run
stopped part-way is resumed, and a run that fails is recorded with its reason
without stopping the others.
"""

from __future__ import annotations

import csv
import itertools
import os
import time
from pathlib import Path

from . import spec as specs

SWEEP_KEYS = {"name", "out", "min_members", "grid"}
SUMMARY_FIELDS = [
    "run", "status", "reason", "eta", "speed", "theta_deg", "mass_ratio", "largest_mass_ratio",
    "particle_size_change", "clusters", "momentum_drift", "angular_momentum_drift", "wall_seconds", "device",
]  # fmt: skip


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
    }
    if isinstance(settings["min_members"], bool) or not isinstance(settings["min_members"], int) or settings["min_members"] < 1:
        raise specs.SpecError(f"[sweep] min_members = {settings['min_members']!r}: must be an integer >= 1")
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


def run_one(spec: dict, min_members: int) -> dict:
    """Run (or resume, or skip) one run of a sweep and analyse it; never raises."""
    from .analysis.runs import analyse_run
    from .io import read_checkpoint
    from .run import RUN_FAILURES, prepare_resume, prepare_start, run_dir_of, execute

    started = time.perf_counter()
    run_dir = run_dir_of(spec)
    device = _worker_device()
    row = {"run": spec["run"]["name"], "device": device or "auto"}
    try:
        checkpoint = run_dir / "checkpoint.h5"
        done = checkpoint.is_file() and read_checkpoint(checkpoint)[0]["step"] >= spec["run"]["steps"]
        if not done:
            prepared = prepare_resume(run_dir, device=device) if checkpoint.is_file() else prepare_start(spec, overwrite=True, device=device)
            execute(prepared)
            row["status"] = "ok"
        else:
            row["status"] = "skipped (complete)"
        summary = analyse_run(run_dir, min_members=min_members)
        row.update({key: summary["summary"].get(key) for key in SUMMARY_FIELDS if key in summary["summary"]})
    except RUN_FAILURES as error:
        row.update(status="failed", reason=" ".join(str(error).split()))
    row["run"] = spec["run"]["name"]
    row["wall_seconds"] = round(time.perf_counter() - started, 3)
    row["eta"] = row.get("eta", spec["collision"].get("eta"))
    row["speed"] = spec["collision"].get("speed")
    row["theta_deg"] = spec["collision"]["theta_deg"]
    return row


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


def run_sweep(settings: dict, runs: list[dict], scheduler: str | None = None, workers: int | None = None, on_result=None) -> list[dict]:
    """Execute every run with Dask; returns one summary row per run (in grid order)."""
    from distributed import Client, LocalCluster, as_completed

    from .device import cuda_device_count

    gpus = cuda_device_count()
    if scheduler:
        client = Client(scheduler)
        cluster = None
    else:
        n = workers or (gpus if gpus > 0 else min(2, os.cpu_count() or 1))
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    try:
        futures = {client.submit(run_one, spec, settings["min_members"], pure=False): k for k, spec in enumerate(runs)}
        rows: list[dict | None] = [None] * len(runs)
        for future in as_completed(futures):
            k = futures[future]
            try:
                rows[k] = future.result()
            except Exception as error:  # a worker that died: record it, go on
                rows[k] = {"run": runs[k]["run"]["name"], "status": "failed", "reason": f"worker lost: {error}"}
            if on_result is not None:
                on_result(rows[k])
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return rows


def write_summary(folder: Path, rows: list[dict]) -> Path:
    path = folder / "summary.csv"
    folder.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=SUMMARY_FIELDS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path

"""Parameter sweeps: a grid of runs executed with Dask, then analysed together.

A sweep specification is a run specification plus a ``[sweep]`` table:

    [sweep]
    name = "fig3-reduced"          # the sweep folder under out
    out = "runs/out"
    min_members = 50               # for the analysis of each run
    analyze_every = 1              # analyze every Nth frame of a run (the last one always)
    keep_trajectory = true         # false: delete trajectory.h5 once the run is analysed
    ensemble = "auto"              # runs handed to a worker at a time; those sharing Params step together
                                   # (auto: up to 8 at a time on a GPU, runs of the same particle count up to
                                   # 20 000 particles stepped together, larger ones alone; 1 on a CPU)
    realizations = 1               # runs of each grid point: the piles as their files hold them, then
                                   # turned by random rotations (orientation_seed derived from the point)
    resolution = 1                 # R x the particles of the same bodies: the piles NAME_xR.h5, and unless
    scale_contacts = true          # false, k_in and dt x R^(-1/3) (the same contact physics; docs/model.md)
    [sweep.pile_alternatives]      # piles that may stand in for a pile in realizations 1, 2, ...: the same
                                   # recipe formed from other seeds; each realization draws its pair from its seed
    "runs/paper/piles/target5000.h5" = ["runs/paper/piles/target5000_s11.h5", "runs/paper/piles/target5000_s12.h5"]
    [sweep.grid]                   # the cartesian product of these lists
    "collision.eta" = [0.5, 1.0, 2.0]
    "collision.theta_deg" = [0.0, 22.0]
    # several keys that go together: one entry, a list of values for each
    "collision.target_spin_axis, collision.projectile_spin_axis" = [["+z", "+z"], ["+z", "-z"]]

Every combination is checked as a run specification before anything runs.  The
runs go to Dask workers (one per GPU); each finished run is analysed on this
machine's cores while the workers go on with the next runs.  A run already
complete and analysed is skipped (so an interrupted sweep resumes), a run
stopped part-way is resumed, and a run that fails is recorded with its reason
without stopping the others.
"""

from __future__ import annotations

import fnmatch
import hashlib
import itertools
import math
import json
import logging
import multiprocessing
import os
import platform
import time
from concurrent.futures import CancelledError, Future, ProcessPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import partial
from pathlib import Path

import numpy as np

from . import resolution as resolutions
from . import spec as specs
from ._version import __version__
from .folder import SWEEP_RECORD, RunFolder
from .processes import usable_cores, use_cores
from .stops import clear_request

#: ``ensemble = "auto"`` on a GPU: runs go to a worker up to 8 at a time (fewer where that leaves a
#: worker idle), and those of the same particle count up to ENSEMBLE_MAX_PARTICLES are stepped
#: together.  On an H100 (docs/benchmarks.md, "Ensembles"), systems of 5 500 to 6 250 particles step
#: 1.39 to 1.50 times as fast as one at a time 4 together, 1.47 to 1.60 times 8 together (bench,
#: piles), and whole sweeps 1.45 to 1.55x with 4, 1.68 to 1.86x with 6.
AUTO_ENSEMBLE = 8
#: The largest particle count measured to gain from stepping together (H100, piles): 4 together gain
#: 1.25x at 10 000 (a sweep: 4 runs of 10 000 in 505 s against ~668 s one at a time), 1.14x at
#: 16 384 and 1.09x at 20 000, as one system fills more of the GPU.  Larger runs go alone.
ENSEMBLE_MAX_PARTICLES = 20_000
#: The same with gravity on its own clock (K > 1), where a step leaves less work to fill the GPU:
#: 25 000-particle piles at K = 10 step 1.16x as fast 2 together and 1.22x 4 together (bench,
#: one H200, 2026-11-27), where at K = 1 they gain 1.05x and 1.07x.
ENSEMBLE_MAX_PARTICLES_CLOCKED = 25_000
SUMMARY_FIELDS = [
    "run", "status", "reason", "n_particles", "mass_ratio", "target_mass", "theta_deg", "eta", "speed", "spin_kind", "realization",
    "orientation_seed", "target_pile", "projectile_pile",
    "k_in", "dt", "restitution", "mu_k", "mu_r", "G", "rolling_friction", "contact_law", "gravity_every", "steps",
    "largest_mass_ratio", "settled", "settled_note", "largest_mass_ratio_late_low", "largest_mass_ratio_late_high",
    "ls12_largest_mass_ratio", "ls12_band_low", "ls12_band_high", "ls12_planets_largest_mass_ratio",
    "speed_over_escape", "q_r", "q_rd_star", "q_r_over_q_rd_star",
    "eta_potential", "eta_self", "eta_all", "cross_potential", "contact_surface_speed", "contact_twist_rate",
    "particle_size_change", "particle_size_change_mass_weighted", "size_change_late", "size_change_late_std",
    "size_change_mass_weighted_late", "size_change_mass_weighted_late_std", "late_frames",
    "clusters", "deepest_overlap", "predicted_overlap",
    "momentum_drift", "angular_momentum_drift", "ledger_closure", "wall_seconds", "stepping_seconds", "analysis_seconds",
    "device", "device_name", "ensemble",
]  # fmt: skip


def summary_fields(swept=()) -> list[str]:
    """summary.csv's columns: SUMMARY_FIELDS, then every other key of [params] (a law added to the
    specification is a column without a word here), then the columns of the keys a sweep varies
    (``swept``, :func:`swept_columns`) that are not among them."""
    fields = list(SUMMARY_FIELDS)
    for column in (*specs.SCHEMA["params"], *swept):
        if column not in fields:
            fields.append(column)
    return fields


def swept_columns(grid_keys) -> list[str]:
    """The summary columns of a grid's ``(table, key)`` pairs, in grid order (a run's summary.json
    holds each: analysis.runs.spec_columns)."""
    from .analysis.runs import spec_column

    return list(dict.fromkeys(spec_column(table, key) for table, key in grid_keys))


def set_up_values(spec: dict, swept: list[str]) -> dict:
    """The [params] and the ``swept`` columns of a run as its own specification gives them, so that a
    run that fails has them too (a run's analysis replaces them by those it was resolved to)."""
    from .analysis.runs import spec_columns

    return {column: value for column, value in spec_columns(spec).items() if column in swept or column in spec["params"]}


def load_sweep(path, overrides: dict | None = None) -> tuple[dict, list[dict]]:
    """(sweep settings, resolved run specifications) of a sweep file, its ``[sweep]`` keys replaced by
    ``overrides`` (the command line's); SpecError names what is wrong."""
    raw = specs.load_spec_file(path)
    sweep = raw.pop("sweep", None)
    if isinstance(sweep, dict) and overrides:
        sweep = {**sweep, **{key: value for key, value in overrides.items() if value is not None}}
    if not isinstance(sweep, dict):
        raise specs.SpecError(f"{path} has no [sweep] table")
    settings = specs.sweep_settings(sweep, Path(path).stem)
    name = settings["name"]
    try:
        resolutions.length_factor(settings["resolution"])
    except ValueError as error:
        raise specs.SpecError(f"[sweep] {error}") from None
    grid = sweep.get("grid", {})
    if not isinstance(grid, dict) or not grid:
        raise specs.SpecError("[sweep.grid] must list at least one \"table.key\" = [values]")
    axes = []  # per grid entry: its (table, key) pairs and, per value, one value for each
    for dotted, values in grid.items():
        keys = [part.strip().partition(".")[::2] for part in dotted.split(",")]
        for table, key in keys:
            if table not in specs.SCHEMA or key not in specs.SCHEMA[table] or table == "run" and key in ("name", "out"):
                raise specs.SpecError(f"[sweep.grid] {dotted!r} is not a sweepable \"table.key\"")
        if not isinstance(values, list) or not values:
            raise specs.SpecError(f"[sweep.grid] {dotted} must be a non-empty list")
        if len(keys) > 1 and not all(isinstance(v, list) and len(v) == len(keys) for v in values):
            raise specs.SpecError(f"[sweep.grid] {dotted} names {len(keys)} keys: each value must be a list of {len(keys)}")
        axes.append((keys, [v if len(keys) > 1 else [v] for v in values]))
    seeded = "orientation_seed" in raw.get("collision", {}) or any(("collision", "orientation_seed") in keys for keys, _ in axes)
    if settings["realizations"] > 1 and seeded:
        raise specs.SpecError("[sweep] realizations choose each run's orientation_seed: leave [collision] orientation_seed out")
    alternatives = _pile_alternatives(sweep.get("pile_alternatives", {}), settings["realizations"])
    runs = []
    for combination in itertools.product(*(values for _, values in axes)):
        run = {table: dict(values) for table, values in raw.items() if isinstance(values, dict)}
        labels = []
        for (keys, _), values in zip(axes, combination):
            for (table, key), value in zip(keys, values):
                run.setdefault(table, {})[key] = value
                if table == "collision" and key in ("eta", "speed"):
                    run[table].pop("speed" if key == "eta" else "eta", None)
                labels.append(f"{key}{_slug(value)}")
        run.setdefault("run", {})
        run["run"]["out"] = str(Path(settings["out"]) / name)
        if settings["resolution"] != 1:
            run = _at_resolution(run, settings)
            labels.append(f"x{settings['resolution']:g}")
        for k in range(settings["realizations"]):
            runs.append(specs.resolve_spec(realization(run, "_".join(labels), k, alternatives)))
    names = [r["run"]["name"] for r in runs]
    if len(set(names)) != len(names):
        raise specs.SpecError("[sweep.grid] gives two runs the same name; use values that differ in their text")
    runs, settings["same_as"] = _distinct(runs)
    settings["swept"] = swept_columns(key for keys, _ in axes for key in keys)
    return settings, runs


def set_up_of(spec: dict) -> str:
    """What makes a resolved run what it is (its tables but its name), with the axis of a body that
    does not spin left out: two runs with the same set-up step the same motion."""
    tables = {table: dict(values) for table, values in spec.items() if isinstance(values, dict)}
    tables["run"].pop("name", None)
    collision = tables.get("collision", {})
    for body in ("target", "projectile"):
        if not collision.get(f"{body}_spin"):
            collision.pop(f"{body}_spin_axis", None)
    return json.dumps(tables, sort_keys=True, default=str)


def _distinct(runs: list[dict]) -> tuple[list[dict], dict[str, str]]:
    """The runs whose set-up no earlier run has, and for each one left out the run it repeats (a
    grid whose points differ only in the axis of a zero spin, say): a repeat would count one outcome
    twice in a comparison of groups."""
    kept, same_as, first = [], {}, {}
    for run in runs:
        key = set_up_of(run)
        if key in first:
            same_as[run["run"]["name"]] = first[key]
        else:
            first[key] = run["run"]["name"]
            kept.append(run)
    return kept, same_as


def realization(point: dict, name: str, k: int, alternatives: dict[str, list[str]] | None = None) -> dict:
    """The ``k``-th realization of a grid point (raw tables): k = 0 is the point as written (its piles
    as their files hold them: the runs a sweep without realizations makes, under the same name); k >= 1
    is named NAME_rK and turns the piles by random rotations whose seed is drawn from the point's
    piles and collision and from k alone, so that adding points, realizations or other [params]
    never changes a run already made, and runs that differ only in their [params] share orientations.
    With ``alternatives`` (a pile file -> the files that may stand in for it), realization k >= 1
    also draws each pile from the file and its alternatives with that seed."""
    run = {table: dict(values) for table, values in point.items()}
    run["run"]["name"] = name
    if k > 0:
        run["run"]["name"] = f"{name}_r{k}"
        resolved = specs.resolve_spec(point)
        seed = orientation_seed_of(resolved, k)
        run.setdefault("collision", {})["orientation_seed"] = seed
        if alternatives:
            draw = np.random.default_rng(seed)
            for which in ("target", "projectile"):
                original = resolved["piles"][which]
                choices = [original, *alternatives.get(original, [])]
                run.setdefault("piles", {})[which] = choices[int(draw.integers(len(choices)))]
    return run


def _at_resolution(run: dict, settings: dict) -> dict:
    """A grid point at the sweep's resolution (decco_warp/resolution.py); its piles must exist."""
    defaults = specs.resolve_spec({})
    try:
        run = resolutions.scaled_run(run, settings["resolution"], settings["scale_contacts"], defaults)
    except ValueError as error:
        raise specs.SpecError(f"[sweep] resolution: {error}") from None
    for which in ("target", "projectile"):
        _require_pile(run["piles"][which], f"[sweep] resolution = {settings['resolution']:g}:",
                      f"build the piles at that resolution first (decco-warp piles PILES.toml --resolution {settings['resolution']:g})")  # fmt: skip
    return run


def _require_pile(path: str, where: str, remedy: str) -> None:
    """Refuse (SpecError, naming ``where`` and the ``remedy``) a pile file that is not there yet."""
    if not path.startswith("builtin:") and not Path(path).expanduser().is_file():
        raise specs.SpecError(f"{where} pile file {path} does not exist; {remedy}")


def _pile_alternatives(table, realizations: int) -> dict[str, list[str]]:
    """``[sweep.pile_alternatives]`` checked: each key a pile file, each value a non-empty list of other
    pile files, all of them existing; only with realizations > 1."""
    if not isinstance(table, dict):
        raise specs.SpecError("[sweep.pile_alternatives] must be a table: a pile file = [files that may stand in for it]")
    if table and realizations < 2:
        raise specs.SpecError("[sweep.pile_alternatives] serve realizations 1, 2, ...: set [sweep] realizations >= 2")
    checked = {}
    for pile, others in table.items():
        if not isinstance(others, list) or not others or not all(isinstance(o, str) and o.strip() for o in others):
            raise specs.SpecError(f"[sweep.pile_alternatives] {pile!r} must be a non-empty list of pile files")
        for path in (pile, *others):
            _require_pile(path, "[sweep.pile_alternatives]", "build it first (decco-warp piles)")
        checked[pile] = list(others)
    return checked


def orientation_seed_of(spec: dict, k: int) -> int:
    """A seed in [0, 2^31) from a resolved point's piles and collision and the realization number."""
    collision = dict(spec["collision"])
    if collision.get("eta_potential") == "self":  # the default, older than the key: seeds stay as they were
        del collision["eta_potential"]
    identity = json.dumps({"piles": spec["piles"], "collision": collision, "realization": k}, sort_keys=True)
    return int(hashlib.sha256(identity.encode()).hexdigest()[:8], 16) & 0x7FFFFFFF


def realization_of(spec: dict) -> int:
    """Which realization of its point a sweep's run is (0: the piles as their files hold them)."""
    if "orientation_seed" not in spec["collision"]:
        return 0
    suffix = spec["run"]["name"].rpartition("_r")[2]
    return int(suffix) if suffix.isdigit() else 0


def _slug(value) -> str:
    """A value as a piece of a run name: a pile file by its stem, "+z" as "pz", "-z" as "mz"."""
    if isinstance(value, (list, tuple)):  # a vector (a spin axis): its components
        return "_".join(_slug(v) for v in value)
    text = Path(str(value)).stem if isinstance(value, str) else f"{value:g}" if isinstance(value, float) else str(value)
    text = text.replace("+", "p").replace("-", "m") if isinstance(value, str) else text
    return "".join(c if c.isalnum() or c in ".-" else "_" for c in text)


# --- one run: simulated on a worker, analysed here ----------------------------------------


def ensemble_plan(setting, gpus: int, runs: int = AUTO_ENSEMBLE, workers: int = 1) -> tuple[int, int | None]:
    """``[sweep] ensemble`` as (runs handed to a worker at a time, the largest particle count
    stepped with others, None for any): ``"auto"`` packs the small runs on a GPU only, up to
    AUTO_ENSEMBLE at a time but no more than shares ``runs`` out among all ``workers``."""
    if setting != "auto":
        return int(setting), None
    if gpus == 0:
        return 1, None
    return max(1, min(AUTO_ENSEMBLE, math.ceil(runs / max(1, workers)))), ENSEMBLE_MAX_PARTICLES


def ensemble_groups(prepared, max_particles: int | None = None) -> list[list[int]]:
    """The indices of ``prepared`` runs (PreparedRun, or None for one not to step) as the groups
    :func:`simulate_batch` steps together, in order of first member: runs that would be stepped
    alone with the same kernels (Params, precision, layout, step), all-pairs only (the tree steps
    one system at a time), and with ``max_particles`` of the same particle count, up to that many
    (up to ENSEMBLE_MAX_PARTICLES_CLOCKED where gravity has its own clock)."""
    groups: dict[tuple, list[int]] = {}
    for k, run in enumerate(prepared):
        if run is not None:
            plan = run.plan
            key = (plan.params, plan.scheme, run.sim.step_count) if plan.scheme.gravity == "all-pairs" else (k,)
            if max_particles is not None:
                count = plan.state.n
                cap = max_particles if plan.scheme.clocks == 1 else max(max_particles, ENSEMBLE_MAX_PARTICLES_CLOCKED)
                key = (*key, count) if count <= cap else (k,)
            groups.setdefault(key, []).append(k)
    return list(groups.values())


def simulate_batch(batch: list[dict], max_particles: int | None = None, stop_file: str | None = None) -> list[dict]:
    """Run (or resume, or skip) several runs of a sweep on one Dask worker, those that share their
    Params and step advanced together as one ensemble (decco_warp/ensemble.py: each writes what it
    would alone); never raises.  One row per run: ``status`` (ok, skipped (complete), failed with
    ``reason``, or stopped), the run folder, the device, the run's own wall time over all its
    sessions and this session's (``session_seconds``).  With ``max_particles`` only runs of the
    same particle count, up to that many, go together.  Once ``stop_file`` exists (the sweep was
    stopped) a stepping run checkpoints and ends as "stopped" (``step``: where), and a run not
    started is left as "stopped" with ``step`` None."""
    from .device import device_problem
    from .run import RUN_FAILURES, RunStopped, execute, execute_ensemble, run_dir_of
    from .stops import StopRequests

    device = _worker_device()
    stop = StopRequests(stop_file)
    untouched = [{"run": spec["run"]["name"], "run_dir": str(run_dir_of(spec)), "device": device} for spec in batch]
    if stop.signal is not None:  # asked to stop before this batch began: leave it whole
        return [{**row, "status": "stopped", "step": None} for row in untouched]
    problem = device_problem(device)
    if problem is not None:  # a GPU gone from this worker: the sweep hands the batch to another
        worker = _worker()
        return [{**row, "status": UNAVAILABLE, "reason": problem, "worker": worker and worker.address} for row in untouched]
    rows, prepared = zip(*(_prepare(spec, device) for spec in batch))
    rows, prepared = list(rows), list(prepared)
    groups = [group for members in ensemble_groups(prepared, max_particles) for group in fit_in_memory(members, prepared)]
    for members in groups:
        if stop.signal is not None:
            outcomes = [None] * len(members)  # not started
        else:
            try:
                if len(members) == 1:
                    outcomes = [execute(prepared[members[0]], stop_file=stop_file)]
                else:
                    outcomes = execute_ensemble([prepared[k] for k in members], stop_file=stop_file)
            except RunStopped as stopped:
                outcomes = [stopped]
            except RUN_FAILURES as error:  # the run, or the ensemble as a whole (its device memory, ...)
                outcomes = [error] * len(members)
        for k, outcome in zip(members, outcomes):
            rows[k]["ensemble"] = len(members)
            rows[k]["resumed"] = prepared[k].resume
            if outcome is None or isinstance(outcome, RunStopped):
                rows[k].update(status="stopped", step=getattr(outcome, "step", None))
                if outcome is None and prepared[k].lock is not None:  # prepared, never started: its folder is free
                    prepared[k].lock.release()
            elif isinstance(outcome, BaseException):
                rows[k].update(status="failed", reason=" ".join(str(outcome).split()))
            else:
                rows[k].update(status="ok", session_seconds=round(outcome.session_wall_seconds, 3))
            prepared[k].sim = None  # its device arrays (an ensemble's too) freed before the next group is built
    return [_timed(row) for row in rows]


#: A batch's rows when its worker's device cannot take work: the sweep hands the runs to another worker.
UNAVAILABLE = "device unavailable"


def fit_in_memory(members: list[int], prepared: list) -> list[list[int]]:
    """The ``members`` of an ensemble (indices into ``prepared``) cut, in order, into ensembles that
    their device's free memory holds beside the members' own arrays (allocated as each was prepared,
    and each checked then): eight runs that fit one at a time need not fit joined."""
    from .costs import FIXED_BYTES
    from .device import free_memory
    from .run import plan_memory

    if len(members) < 2:
        return [members]
    free = free_memory(prepared[members[0]].plan.device)
    groups, need = [[]], 0
    for k in members:
        own = plan_memory(prepared[k].plan)
        if groups[-1] and need + own - FIXED_BYTES > free:
            groups.append([])
            need = 0
        need += own - (FIXED_BYTES if groups[-1] else 0)  # Warp's modules and the like once an ensemble
        groups[-1].append(k)
    return groups



def _complete_row(spec: dict) -> dict | None:
    """A sweep run's row if its folder holds it complete, else None (also when that cannot be told
    here: the worker then finds out, and reports a damaged folder)."""
    from .run import RUN_FAILURES, run_dir_of

    run_dir = run_dir_of(spec)
    try:
        if not RunFolder(run_dir).complete():
            return None
    except (*RUN_FAILURES, specs.SpecError):
        return None
    # Made before this sweep: where is not known here (its run.log says), so no device is claimed.
    return _timed({"run": spec["run"]["name"], "run_dir": str(run_dir), "device": None, "status": "skipped (complete)"})


def run_state(spec: dict) -> str:
    """Where a sweep's run stands: "complete", "resumes at step K" (its checkpoint is short of its
    steps) or "to run"."""
    return _standing(spec)[0]


def _standing(spec: dict) -> tuple[str, int]:
    """:func:`run_state` and the steps its folder holds already (0 where it has none)."""
    from .run import RUN_FAILURES, run_dir_of

    run_dir = run_dir_of(spec)
    try:
        folder = RunFolder(run_dir)
        progress = folder.progress()
    except (*RUN_FAILURES, specs.SpecError):  # the worker will report what is wrong with the folder
        return "to run (its folder cannot be read)", 0
    if progress is not None and progress[0] >= progress[1]:
        return "complete", progress[0]
    if progress is not None and folder.checkpoint.is_file():
        return f"resumes at step {progress[0]}", progress[0]
    return "to run", 0


def check_lines(settings: dict, runs: list[dict]) -> list[str]:
    """``sweep --check``: the sweep's runs and where each stands (:func:`run_state`), with, for each
    one still to make, :func:`run_check`'s line; then the cost of them all, and once each note on
    what the estimates rest on."""
    from .costs import duration

    standing = [_standing(run) for run in runs]
    states = [state for state, _ in standing]
    counts = {kind: sum(s.startswith(kind) for s in states) for kind in ("complete", "resumes", "to run")}
    lines = [f"sweep {settings['name']}: {len(runs)} runs into {Path(settings['out']) / settings['name']} "
             f"({counts['complete']} complete, {counts['resumes']} to resume, {counts['to run']} to run)"]  # fmt: skip
    width = max(len(run["run"]["name"]) for run in runs)
    total, devices, notes = 0.0, set(), []
    for run, (state, done) in zip(runs, standing):
        lines.append(f"  {run['run']['name']:<{width}}  {state}")
        if not state.startswith("complete"):
            line, cost = run_check(run, done)
            lines.append(f"  {'':<{width}}  {line}")
            if cost is not None:
                total += cost.seconds
                devices.add(cost.device)
                notes += [cost.note] if cost.note and cost.note not in notes else []
    left = len(runs) - counts["complete"]
    if left:
        lines.append(f"cost: about {duration(total)} of stepping for the {left} run(s) to make or resume on {', '.join(sorted(devices)) or 'no device'} "
                     "(the sum of the runs' lines; workers that share a device share its time; analysis not included)")  # fmt: skip
    return lines + notes


@dataclass
class RunCost:
    """What :func:`run_check` estimates a run still to make will take: ``seconds`` on ``device``."""

    seconds: float
    device: str
    note: str | None
    """What the estimate rests on, where a line should say so (costs.cost_note)."""


def run_check(spec: dict, done: int = 0) -> tuple[str, RunCost | None]:
    """A line on a run still to make (``done`` steps made already): its set-up's margins, its
    predicted deepest overlap and its cost on this machine's device by its scheme, or why it
    would be refused; and that cost (None for a run refused)."""
    from .costs import cost_note, run_cost, step_seconds
    from .plan import plan_start
    from .run import plan_fits

    try:
        plan = plan_start(spec)
        plan_fits(plan, plan.state.n, plan.steps)  # refused where its device has not the memory
    except ValueError as error:  # bad input: each input error of errors.py is a ValueError, as are Params' checks
        return f"REFUSED: {error}", None
    stability = plan.stability
    refused = "" if stability.stable or plan.allow_unstable else f"; REFUSED: {'; '.join(stability.problems())}"
    steps = max(0, plan.steps - done)
    line = (f"eta {plan.state.metadata['eta']:.3g}, margins: stiffness {stability.stiffness_margin:.3g} (>= 1), time step "
            f"{stability.time_step_margin:.3g} (>= 10); predicted deepest overlap {plan.forecast.fraction:.2g}; "
            f"{run_cost(plan.state.n, plan.scheme, plan.device, steps)}{refused}")  # fmt: skip
    cost = None if refused else RunCost(step_seconds(plan.state.n, plan.scheme, plan.device) * steps, plan.device, cost_note(plan.scheme))
    return line, cost


def select_runs(runs: list[dict], patterns: list[str]) -> list[dict]:
    """The runs whose names match any of the glob ``patterns``, and every run already complete (only
    reported, so that the sweep's table and figures stay whole).  A pattern that matches no run is
    an error: it is most likely a typing slip."""
    names = [r["run"]["name"] for r in runs]
    for pattern in patterns:
        if not fnmatch.filter(names, pattern):
            raise specs.SpecError(f"--only {pattern!r} matches none of the sweep's {len(runs)} runs (the first is {names[0]})")
    chosen = {name for pattern in patterns for name in fnmatch.filter(names, pattern)}
    return [r for r in runs if r["run"]["name"] in chosen or _complete_row(r) is not None]


def _prepare(spec: dict, device: str | None) -> tuple[dict, object]:
    """A sweep run's row so far, and the run prepared to start or resume (None if complete or failed):
    the row names its GPU by UUID too (``device_uuid``), which the sweep's analysis finds its own name
    for, and a resumed run the step it resumed from."""
    from .device import gpu_uuid
    from .run import RUN_FAILURES, prepare_resume, prepare_start, run_dir_of

    run_dir = run_dir_of(spec)
    row = {"run": spec["run"]["name"], "run_dir": str(run_dir), "device": device or "auto"}
    try:
        folder = RunFolder(run_dir)
        if folder.complete():
            row["status"] = "skipped (complete)"
            return row, None
        prepared = prepare_resume(run_dir, device=device) if folder.checkpoint.is_file() else prepare_start(spec, overwrite=True, device=device)
        row.update(device=prepared.sim.device, device_uuid=gpu_uuid(prepared.sim.device), n_particles=prepared.plan.state.n)
        if prepared.resume:
            row["resumed_from"] = prepared.sim.step_count
        return row, prepared
    except RUN_FAILURES as error:
        row.update(status="failed", reason=" ".join(str(error).split()))
        return row, None


def _timed(row: dict) -> dict:
    """A row with the run's wall and stepping time over all its sessions (from its checkpoint)."""
    from .io import read_checkpoint
    from .record import RunRecord
    from .run import RUN_FAILURES

    checkpoint = RunFolder(row["run_dir"]).checkpoint
    try:
        if checkpoint.is_file():
            kept = RunRecord.from_checkpoint(read_checkpoint(checkpoint)[2])
            row["wall_seconds"] = round(kept.wall_seconds, 3)
            row["stepping_seconds"] = None if kept.stepping_seconds is None else round(kept.stepping_seconds, 3)
    except RUN_FAILURES as error:
        row.update(status="failed", reason=" ".join(str(error).split()))
    row["device_name"] = _device_name(row["device"])
    return row


def stepped_fraction(spec: dict) -> float:
    """How far a sweep's run has stepped, 0 to 1, by its folder's last checkpoint (0 while it has
    none, or its folder cannot be read just now)."""
    from .run import RUN_FAILURES, run_dir_of

    try:
        progress = RunFolder(run_dir_of(spec)).progress()
    except (*RUN_FAILURES, specs.SpecError, OSError):
        return 0.0
    return 0.0 if progress is None else min(1.0, progress[0] / max(1, progress[1]))


def _device_name(device: str | None) -> str:
    try:
        import warp as wp

        return str(wp.get_device(device).name) if device not in (None, "auto") else ""
    except Exception:  # the name is a label for the table, never a reason to fail
        return ""


def analyse_one(run_dir: str, min_members: int, analyze_every: int, keep_trajectory: bool, device: str | None = None) -> dict:
    """Analyse a finished run (unless its summary.json is current), draw its figures, and
    drop its trajectory if asked; returns its summary (``analysis_seconds``: what the analysis
    took when it ran, also for a run found analysed).  Runs in a process of this machine; the
    cluster finder's O(N^2) density is summed on ``device`` (default as for runs: this machine's
    GPU when it has one, where a 6 250-particle frame takes milliseconds, else NumPy), its frames
    in as many processes as this one's share of the cores allows (:class:`Analyses`)."""
    from .lock import AnalysisLock

    # The run has finished: no one else should be writing there, nor analysing it (decco-warp analyze).
    with RunFolder(run_dir).lock(), AnalysisLock(run_dir):
        return _analyse(Path(run_dir), min_members, analyze_every, keep_trajectory, device)


def _analyse(run_dir: Path, min_members: int, analyze_every: int, keep_trajectory: bool, device: str | None = None) -> dict:
    from .analysis.figures import draw_run
    from .analysis.runs import analyse_run
    from .device import resolve_device

    folder = RunFolder(run_dir)
    summary_path, trajectory = folder.summary, folder.trajectory
    settings = {"min_members": min_members, "analyze_every": analyze_every}
    previous = json.loads(summary_path.read_text()) if summary_path.is_file() else None
    if previous is not None and "analyse_every" in previous:  # a summary of the key's earlier spelling
        previous.setdefault("analyze_every", previous["analyse_every"])
    # A summary older than the settled verdict is analysed again (its finder stopped too early).
    current = previous is not None and "settled" in previous and all(previous.get(k) == v for k, v in settings.items())
    if trajectory.is_file() and not (current and summary_path.stat().st_mtime >= trajectory.stat().st_mtime):
        analysis = analyse_run(run_dir, min_members=min_members, every=analyze_every, device=resolve_device(device))
        draw_run(analysis, run_dir)
        summary = analysis["summary"]
    elif previous is not None:
        summary = previous  # analysed before (its trajectory may be gone)
    else:
        raise FileNotFoundError(f"{run_dir} has neither a trajectory nor a summary to report")
    if not keep_trajectory and trajectory.is_file():
        trajectory.unlink()  # analysis.h5, summary.json, figures/ and the checkpoint stay
        folder.xdmf.unlink(missing_ok=True)  # it describes the trajectory only
    return summary


def _worker():
    """The Dask worker this task runs on, else None (not on a worker: a job array's task)."""
    try:
        from distributed import get_worker

        return get_worker()
    except (ImportError, ValueError):
        return None


def _worker_device(worker=None) -> str | None:
    """The device of this Dask worker (``worker``, else the one running this task): the one it was
    pinned to (its own $DECCO_DEVICE, set by :func:`local_cluster`, or by whoever started a remote
    worker), else None (the run's own choice); each worker with its own Warp kernel cache."""
    worker = worker or _worker()
    if worker is None:
        return None
    import warp as wp

    from .device import ENV_VARIABLE

    label = "".join(c if c.isalnum() or c in "-_" else "_" for c in str(worker.name))
    cache = Path(os.environ.get("DECCO_CACHE", Path.home() / ".cache" / "decco-warp")) / f"warp-worker-{label}"
    if wp.config.kernel_cache_dir is None or "warp-worker-" not in str(wp.config.kernel_cache_dir):
        wp.config.kernel_cache_dir = str(cache)
    return os.environ.get(ENV_VARIABLE) or None


def worker_device(dask_worker=None) -> dict:
    """What a Dask worker steps on (``client.run`` calls this on each): its device as its runs
    resolve it, that GPU's UUID (None on a CPU), and why the device cannot take work (None if it can)."""
    from .device import device_problem, gpu_uuid, resolve_device

    device = _worker_device(dask_worker)
    problem = device_problem(device)
    if problem is not None:
        return {"device": device, "uuid": None, "problem": problem}
    device = resolve_device(device)
    return {"device": device, "uuid": gpu_uuid(device), "problem": None}


def worker_devices(client, on_note=None) -> dict[str, dict]:
    """:func:`worker_device` of each worker of ``client``'s scheduler (waiting for the first to join),
    by address: so that a sweep handed to a scheduler packs its ensembles for the workers' devices,
    not for this machine's."""
    if not client.scheduler_info()["workers"]:
        if on_note is not None:
            on_note(f"waiting for a worker to join the scheduler at {client.scheduler.address}")
        client.wait_for_workers(1)
    return client.run(worker_device)


#: Runs of fewer particles are analysed on the CPU: there the O(N^2) density of a frame takes 7 ms at
#: 1 000 particles (0.65 s at 5 000; 2-core CPU), while a GPU costs each analysis process Warp's
#: start and a CUDA context (hundreds of MB of the GPU's memory) before its first frame.
ANALYSIS_GPU_MIN_PARTICLES = 1000


def analysis_device(row: dict, gpus: dict[str, str], turn: int = 0) -> str:
    """Where a finished run (its row) is analysed on this machine, whose GPUs are ``gpus`` (UUID ->
    name): a small run on the CPU (ANALYSIS_GPU_MIN_PARTICLES); else on the GPU that stepped it, so that
    the analyses spread over the GPUs as the runs do, beside one stepping worker each, instead of all
    landing on cuda:0; a run stepped elsewhere (another host, a CPU) on this machine's GPUs in
    ``turn``; the CPU where this machine has none."""
    n = row.get("n_particles")
    if not gpus or (n is not None and n < ANALYSIS_GPU_MIN_PARTICLES):
        return "cpu"
    return gpus.get(row.get("device_uuid") or "") or list(gpus.values())[turn % len(gpus)]


def analysis_args(row: dict, settings: dict, device: str) -> tuple:
    """:func:`analyse_one`'s arguments for a finished run's row, analysed on ``device``."""
    return row["run_dir"], settings["min_members"], settings["analyze_every"], settings["keep_trajectory"], device


def analysis_failed(row: dict, error: BaseException) -> dict:
    """A finished run's row once its analysis failed (a damaged trajectory, a full disk: this run only)."""
    return {**row, "status": "failed", "reason": f"analysis: {' '.join(str(error).split())}"}


def analysis_process(cores: int) -> None:
    """The start of an analysis process of :class:`Analyses`: SIGINT and SIGTERM left to the sweep,
    ``cores`` cores its own (decco_warp/processes.py)."""
    from .stops import ignore_stops

    ignore_stops()
    use_cores(cores)


class Analyses:
    """The analyses of finished runs, in processes of this machine: a pool of processes per device,
    so that each process opens one CUDA context (a process that took runs of every GPU would hold a
    context on each), ``processes`` on the CPU and a share of them on each GPU.  Each process has
    its share of the cores ($DECCO_CORES): a run's frames are analysed in as many processes as that
    allows (one, where the processes are one a core), never processes^2 of them."""

    def __init__(self, processes: int, gpus: dict[str, str]):
        self.processes, self.gpus = processes, gpus
        self.pools: dict[str, ProcessPoolExecutor] = {}
        self.turn = 0

    def submit(self, row: dict, settings: dict) -> Future:
        """:func:`analyse_one` of a finished run's row, on :func:`analysis_device`."""
        device = analysis_device(row, self.gpus, self.turn)
        self.turn += 1
        if device not in self.pools:
            share = self.processes if device == "cpu" else max(1, -(-self.processes // len(self.gpus)))
            context = multiprocessing.get_context("spawn")
            cores = max(1, usable_cores() // self.processes)
            self.pools[device] = ProcessPoolExecutor(max_workers=share, mp_context=context, initializer=partial(analysis_process, cores))
        return self.pools[device].submit(analyse_one, *analysis_args(row, settings, device))

    def shutdown(self, wait: bool) -> None:
        for pool in self.pools.values():
            pool.shutdown(wait=wait, cancel_futures=True)


#: The module each local worker loads as it starts (Dask's preload: its ``dask_setup``).
WORKER_SETUP = "decco_warp.sweep"


def dask_setup(worker) -> None:
    """Dask's preload hook, in each local worker process as it starts: SIGINT and SIGTERM are left to
    the sweep (decco_warp/stops.py, ``ignore_stops``), which asks the worker's runs to checkpoint
    and end; a worker killed by the terminal's Ctrl-C would lose their work since the last one."""
    from .stops import ignore_stops

    ignore_stops()
    quiet_heartbeats()


class _Heartbeats(logging.Filter):
    """Drops Dask's traceback for a worker heartbeat that found the scheduler gone (quiet_heartbeats)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "with scheduler during heartbeat" not in record.getMessage()


def quiet_heartbeats() -> None:
    """Leave out of a worker's log the traceback Dask prints for a heartbeat that found the scheduler
    gone: as a sweep closes its cluster (at its end, or stopped by Ctrl-C) the scheduler can close
    before a worker's last heartbeat, and a scheduler lost mid-sweep is said in words by the sweep."""
    logger = logging.getLogger("distributed.worker")
    if not any(isinstance(f, _Heartbeats) for f in logger.filters):
        logger.addFilter(_Heartbeats())


def local_cluster(workers: int, gpus: int):
    """A Dask LocalCluster of ``workers`` single-threaded processes, worker k pinned to cuda:(k mod
    gpus) (to the CPU without GPUs) through its own $DECCO_DEVICE, which it keeps if restarted."""
    from distributed import LocalCluster

    from .device import ENV_VARIABLE

    cluster = LocalCluster(n_workers=0, threads_per_worker=1, processes=True, dashboard_address=None, memory_limit=1 / workers)
    spec = cluster.new_spec
    for k in range(workers):
        env = {ENV_VARIABLE: f"cuda:{k % gpus}" if gpus > 0 else "cpu"}
        # WORKER_SETUP leaves Ctrl-C to the sweep, which stops the runs at checkpoints (run_sweep).
        cluster.worker_spec[k] = {"cls": spec["cls"], "options": {**spec["options"], "env": env, "preload": [WORKER_SETUP]}}
    cluster.scale(workers)
    try:
        cluster.wait_for_workers(workers, timeout=WORKER_START_SECONDS)
    except BaseException:  # a worker that cannot start, or Ctrl-C: leave no processes behind
        cluster.close()
        raise
    return cluster


# --- the whole grid ------------------------------------------------------------------------


def run_sweep(
    settings: dict,
    runs: list[dict],
    scheduler: str | None = None,
    workers: int | None = None,
    on_result=None,
    analysis_workers: int | None = None,
    gpus: int | None = None,
    on_progress=None,
    stop_file=None,
    on_stopping=None,
    on_note=None,
) -> list[dict]:
    """Simulate every run with Dask and analyse each here as it finishes; one row per run, in grid order.
    Local workers: one per GPU (the first ``gpus``, default all, see :func:`local_cluster`), else
    ``workers`` (default 2) on the CPU; a ``scheduler``'s workers each use their own device, and the
    ensembles are packed for their devices (:func:`worker_devices`).
    ``on_progress(runs_stepped)`` hears, every PROGRESS_SECONDS and as runs finish, how many runs'
    worth of steps are made (complete runs count whole, stepping ones by their last checkpoint);
    ``on_note(line)`` what the sweep does about a fault (a worker whose device is gone).

    Faults: a worker that dies has its runs handed to another by Dask, where they resume from their
    last checkpoints (the row says ``retried``); a worker whose device cannot take work has its batch
    handed to the others (the rows fail, saying so, when no other is left); a scheduler lost ends
    the sweep with SchedulerLost once the analyses under way have finished.

    SIGINT or SIGTERM once the workers are up stops the sweep in order: the signal's name is written
    to ``stop_file`` (a path every worker sees: the sweep folder), where each stepping run reads it,
    writes a checkpoint and ends, and runs not started are left (``on_stopping()`` hears that this
    began); the analyses under way finish, those not begun are left; then SweepStopped.  A second
    signal stops at once, the work of the runs since their last checkpoints lost (SweepStopped with
    ``at_once``).  A signal before the workers are up is a KeyboardInterrupt (nothing had started)."""
    from distributed import as_completed

    from .device import local_gpus
    from .errors import SchedulerLost, SweepStopped
    from .stops import StopRequests, request_stop

    note = on_note or (lambda line: None)
    client, cluster, gpus, simulating = _workers_for(scheduler, workers, gpus, note)
    # Analysis runs here, beside the workers, in fresh processes (its density on the GPU that stepped the run).
    analyses = Analyses(analysis_workers or max(1, usable_cores() - (0 if gpus > 0 else simulating)), local_gpus())
    rows: list[dict | None] = [None] * len(runs)
    pending: dict[Future, tuple[int, dict]] = {}
    stopped: list[dict] = []  # the rows of runs that a stop left part-way (or not started)
    unanalysed: list[str] = []  # runs that finished stepping but whose analysis a stop left

    def finish(k: int, row: dict) -> None:
        rows[k] = row
        if on_result is not None:
            on_result(row)

    def collect() -> None:
        for future in [f for f in list(pending) if f.done()]:
            k, row = pending.pop(future)
            if future.cancelled():
                unanalysed.append(row["run"])
                continue
            try:
                finish(k, analysed(row, future.result()))
            except Exception as error:  # a damaged trajectory, a full disk: this run only
                finish(k, analysis_failed(row, error))

    abandoned = False
    lost = None  # why the scheduler was lost, once it was
    signals = StopRequests()  # from here on, through the workers' closing, a signal stops in order
    signals.__enter__()
    try:
        # Runs in grid order, `ensemble` at a time to a worker (neighbours in a grid mostly share
        # their piles and Params, and those are stepped together).
        # Runs already complete (made by an earlier sweep) are reported here, so that the batches
        # hold only runs to step and pack into full ensembles.
        done = {k: _complete_row(spec) for k, spec in enumerate(runs)}
        todo = [k for k, row in done.items() if row is None]
        begun = {k: _standing(runs[k])[1] for k in todo}  # the steps each had: more resumed from means a worker was lost
        size, max_particles = ensemble_plan(settings.get("ensemble", 1), gpus, len(todo), simulating)
        request = None if stop_file is None else str(stop_file)
        futures: dict = {}
        unusable: dict[str, str] = {}  # workers whose device cannot take work -> why

        def submit(batch: list[int]) -> None:
            # Away from workers whose device failed; loosely, so that the batch is not stranded if those left die too.
            usable = {"workers": [w for w in client.scheduler_info()["workers"] if w not in unusable], "allow_other_workers": True}
            future = client.submit(simulate_batch, [runs[k] for k in batch], max_particles, request, pure=False, **(usable if unusable else {}))
            futures[future] = batch
            simulations.add(future)

        simulations = as_completed()
        for start in range(0, len(todo), size):
            submit(todo[start : start + size])
        arrived = [([k for k, row in done.items() if row is not None], [row for row in done.values() if row is not None])]
        stepped = {k: 0.0 for k in todo}  # never lowered: a checkpoint being replaced reads as none
        looked = -math.inf
        stopping = None  # the signal that stops the sweep, once one came
        while not simulations.is_empty() or pending or arrived:
            if signals.count > 1:  # asked twice: go at once
                abandoned = True
                raise SweepStopped(stopping or signals.signal, stopped, unanalysed, at_once=True)
            if signals.signal is not None and stopping is None:
                stopping = signals.signal
                if stop_file is not None:
                    request_stop(stop_file, stopping)
                for future in pending:
                    future.cancel()  # the analyses not begun; those under way finish
                if on_stopping is not None:
                    on_stopping()
            if on_progress is not None and time.monotonic() - looked >= PROGRESS_SECONDS:
                looked = time.monotonic()
                for k in todo:
                    if stepped[k] < 1.0:
                        stepped[k] = max(stepped[k], stepped_fraction(runs[k]))
                on_progress(len(runs) - len(todo) + sum(stepped.values()))
            # Poll both kinds of work, so that each run is reported as soon as its analysis ends.
            for future in simulations.next_batch(block=False):
                batch = futures.pop(future)
                try:
                    arrived.append((batch, future.result()))
                except CancelledError as error:  # the client lost its scheduler: every future is cancelled
                    lost = lost or getattr(error, "reason", None) or "cancelled"
                    stopped += [{"run": runs[k]["run"]["name"], "step": None} for k in batch]
                except Exception as error:  # a worker that died too often (KilledWorker): record it, go on
                    reason = f"its worker was lost while stepping it ({' '.join(str(error).split())}); {RETRY}"
                    arrived.append((batch, [{"run": runs[k]["run"]["name"], "status": "failed", "reason": reason} for k in batch]))
            while arrived:
                batch, results = arrived.pop(0)
                again = []
                for k, row in zip(batch, results):
                    if row["status"] == UNAVAILABLE:
                        unusable[row.get("worker") or "?"] = row["reason"]
                        again.append(k)
                        continue
                    if k in stepped and row["status"] != "stopped":
                        stepped[k] = 1.0
                        looked = -math.inf  # reported at the next poll
                    if k in begun and (row["status"] == "skipped (complete)" or row.get("resumed_from", 0) > begun[k]):
                        row.update(status="ok", retried=True)  # made in this sweep, on a worker lost since
                    row.update(with_set_up(row, runs[k], settings))
                    if row["status"] == "stopped":
                        stopped.append(row)
                    elif row["status"] == "failed":
                        finish(k, row)
                    elif stopping is not None or lost is not None:
                        unanalysed.append(row["run"])  # complete: the sweep run again analyses it
                    else:
                        pending[analyses.submit(row, settings)] = (k, row)
                if again:
                    names = ", ".join(runs[k]["run"]["name"] for k in again)
                    usable = set(client.scheduler_info()["workers"]) - set(unusable)
                    worker, why = next(iter(unusable.items()))
                    if usable:
                        note(f"worker {worker} cannot use its device ({why}): its runs ({names}) go to the other workers")
                        submit(again)
                    else:
                        reason = f"no worker can use its device (worker {worker}: {why}); {RETRY}"
                        for k in again:
                            finish(k, with_set_up({"run": runs[k]["run"]["name"], "status": "failed", "reason": reason}, runs[k], settings))
            collect()
            time.sleep(POLL_SECONDS)
        if lost is not None:
            raise SchedulerLost(scheduler or "local", lost, stopped, unanalysed)
        if stopping is not None:
            raise SweepStopped(stopping, stopped, unanalysed)
    finally:
        try:
            analyses.shutdown(wait=not abandoned)
            _close(client, quietly=lost is not None)
            if cluster is not None:
                close_cluster(cluster, 0 if abandoned or signals.count > 1 else WORKER_CLOSE_SECONDS)
        finally:
            signals.__exit__(None, None, None)
    return rows


def _close(client, quietly: bool) -> None:
    """Close ``client``; ``quietly`` where it lost its scheduler: Dask then logs a traceback as its
    attempts to reconnect are ended, which the sweep's own line says in words."""
    logger = logging.getLogger("distributed.client")
    level = logger.level
    if quietly:
        logger.setLevel(logging.CRITICAL)
    try:
        client.close(timeout=CLIENT_CLOSE_SECONDS)
    finally:
        logger.setLevel(level)


#: How long a client that lost its scheduler may take to close [s].
CLIENT_CLOSE_SECONDS = 5


#: What a run whose worker failed it is to do.
RETRY = "run the sweep again: it resumes from its last checkpoint"


def _workers_for(scheduler: str | None, workers: int | None, gpus: int | None, note) -> tuple:
    """(client, local cluster or None, GPUs among the workers, workers): a ``scheduler``'s workers as
    they report their devices, else a local cluster of ``workers`` (one per GPU of the first
    ``gpus``, else 2 on the CPU)."""
    from distributed import Client

    from .device import gpus_to_use

    if scheduler:
        client = connect(scheduler)
        devices = worker_devices(client, note)
        return client, None, sum(1 for d in devices.values() if d["uuid"]), max(1, len(devices))
    gpus = gpus_to_use(gpus)
    simulating = workers or (gpus if gpus > 0 else min(2, os.cpu_count() or 1))
    cluster = local_cluster(simulating, gpus)
    return Client(cluster), cluster, gpus, simulating


def connect(scheduler: str):
    """A Dask client of the scheduler at ``scheduler``; InputError where none answers there."""
    from distributed import Client

    from .errors import InputError

    try:
        return Client(scheduler, timeout=SCHEDULER_CONNECT_SECONDS)
    except (OSError, TimeoutError) as error:
        raise InputError(f"no Dask scheduler answers at {scheduler} ({' '.join(str(error).split())}); "
                         "start one (dask scheduler), or leave --scheduler out to run on workers of this machine") from None  # fmt: skip


#: How long a sweep tries to reach the scheduler it is given before it says none answers [s].
SCHEDULER_CONNECT_SECONDS = 30


def analysed(row: dict, summary: dict) -> dict:
    """A finished run's row with its analysis (its summary.json's columns, but the sweep's own)."""
    return {**row, **{key: value for key, value in summary.items() if key not in SWEEP_OWN}, "run": row["run"]}


def with_set_up(row: dict, spec: dict, settings: dict) -> dict:
    """``row`` with the set-up columns its spec gives (so that a run that failed has them too)."""
    collision = spec["collision"]
    return {
        **row, **set_up_values(spec, settings.get("swept", [])),
        "eta": collision.get("eta"), "speed": collision.get("speed"), "theta_deg": collision["theta_deg"],
        "realization": realization_of(spec), "orientation_seed": collision.get("orientation_seed"),
    }  # fmt: skip


#: How long a local worker may take to exit once idle (its interpreter and Warp shutting down on a
#: loaded machine) before it is killed [s]; Dask's own 4 s ended sweeps with "still alive, killing".
WORKER_CLOSE_SECONDS = 60.0


def close_cluster(cluster, seconds: float) -> None:
    """Close a local cluster, each worker given ``seconds`` to exit before it is killed (0: Dask's own
    wait, as when the sweep stops at once)."""
    if seconds > 0:
        for nanny in list(cluster.workers.values()):
            try:
                cluster.sync(nanny.close, timeout=seconds, reason="sweep-done")
            except Exception:  # one that cannot close in order is killed below
                pass
    cluster.close()


#: How long local workers may take to start (a loaded machine) before the sweep gives up [s].
WORKER_START_SECONDS = 300

#: How often the sweep looks for finished simulations and analyses [s].
POLL_SECONDS = 0.2

#: How often the sweep reads its stepping runs' checkpoints to report their progress [s].
PROGRESS_SECONDS = 10.0


#: The columns of a sweep's row that are the sweep's own (where and how the run went), which a
#: run's summary.json does not replace.
SWEEP_OWN = ("status", "reason", "realization", "wall_seconds", "stepping_seconds", "device", "device_name", "ensemble", "run_dir")


def write_summary(folder: Path, rows: list[dict], swept=()) -> Path:
    """summary.csv of ``rows``: :func:`summary_fields` (``swept``: the columns of the grid's keys)."""
    from .durable import write_table
    from .folder import TABLE

    folder.mkdir(parents=True, exist_ok=True)
    return write_table(folder / TABLE, rows, summary_fields(swept), ignore_extra=True)  # a full disk leaves the previous table whole


def write_record(folder: Path, settings: dict, rows: list[dict], wall_seconds: float) -> Path:
    """sweep.json: what ran where, with which versions, and how long it took."""
    import warp as wp

    from .durable import json_text, write_atomic

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
    path = folder / SWEEP_RECORD
    return write_atomic(path, json_text(record))


# --- a sweep into its folder: progress, stops, the end ----------------------------------------

#: What a sweep stopped by a failed write says to do.
AGAIN = "free space, then run the sweep again: finished runs are skipped, a stopped one resumes from its checkpoint"


def finished_line(row: dict) -> str:
    """A run's line as the sweep reports it finished: its status (or why it failed), outcome and
    deepest overlap, and its time: this session's on its device (and over all its sessions, for a
    resumed run), or, for a run complete before this sweep, what it took then."""
    from .analysis.runs import outcome_text

    outcome = row["status"] if row["status"] != "failed" else f"FAILED: {row.get('reason', '')}"
    detail = f", {outcome_text(row)}" if isinstance(row.get("largest_mass_ratio"), float) else ""
    depth = row.get("deepest_overlap")
    detail += f", deepest overlap {depth:.2f}" if isinstance(depth, float) else ""
    together = f", {row['ensemble']} runs together" if (row.get("ensemble") or 1) > 1 else ""
    total = row.get("wall_seconds") or 0.0
    if row["status"].startswith("skipped"):
        spent = f"made before this sweep, in {total:.1f} s"
    else:
        session = row.get("session_seconds")
        spent = f"{total if session is None else session:.1f} s on {row.get('device')}{together}"
        if row.get("resumed") and session is not None:
            spent += f"; {total:.1f} s over all its sessions"
        if row.get("retried"):
            spent += ("; its worker was lost: Dask handed it to another, which resumed it from its checkpoint of step "
                      f"{row['resumed_from']}" if "resumed_from" in row else "; its worker was lost after it finished")  # fmt: skip
    return f"{row['run']}: {outcome}{detail} ({spent})"


#: The file in a sweep's folder through which a stopped sweep asks its workers' runs to stop
#: (decco_warp/stops.py): every worker writes into that folder, so every worker sees it.
STOP_REQUEST = ".stop-request"


class SweepJob:
    """A sweep made into its folder: the folder claimed (one sweep at a time), the runs made and
    analysed (:func:`run_sweep`; summary.csv rewritten as each finishes, so that a stopped sweep
    keeps its table), sweep.json, then the whole table and the cross-run figures.

        job = SweepJob(settings, runs).claim()
        job.run(on_row=print, on_progress=redraw)   # False: stopped (Ctrl-C, SIGTERM)
        job.save_record(); job.release()
        if not job.stopped:
            job.finish()
    """

    def __init__(self, settings: dict, runs: list[dict]):
        self.settings, self.runs = settings, runs
        self.folder = Path(settings["out"]) / settings["name"]
        self.started = time.perf_counter()
        self.finished: list[dict] = []  # the runs' rows as they finish
        self.stepped = 0.0  # runs' worth of steps made (run_sweep's on_progress)
        self.rows: list[dict] | None = None  # every run's row, in grid order, once the sweep has run whole
        self.stopped = False
        self.stop = None  # what the stop left (SweepStopped), once stopped with its workers up
        self.lock = None

    def claim(self) -> "SweepJob":
        """Create the folder and take its lock: InputError for one that cannot be written or that
        another sweep holds."""
        from .checks import InputError, check_destination
        from .lock import RunFolderLock

        try:
            check_destination(self.folder, "sweep folder", folder=True)
            self.folder.mkdir(parents=True, exist_ok=True)
            self.lock = RunFolderLock(self.folder).acquire()
        except InputError as error:
            raise InputError(str(error).replace("run folder", "sweep folder")) from None
        clear_request(self.stop_file)  # a request left by a sweep that was killed while it stopped
        return self

    @property
    def stop_file(self) -> Path:
        return self.folder / STOP_REQUEST

    def release(self) -> None:
        self.lock.release()

    @property
    def completed(self) -> float:
        """Runs' worth of work done, for a progress bar to len(runs): the steps made, or the runs finished if more."""
        return max(self.stepped, len(self.finished))

    def progress_text(self) -> str:
        return f"{len(self.finished)}/{len(self.runs)} runs, {100 * self.stepped / len(self.runs):.0f} % of the steps made"

    def run(self, scheduler=None, workers=None, analysis_workers=None, gpus=None, on_row=None, on_progress=None, on_stopping=None,
            on_note=None) -> bool:  # fmt: skip
        """:func:`run_sweep` (its arguments), with SIGTERM (a batch scheduler's stop) taken as Ctrl-C.
        Each finished run's row is added to summary.csv, then told to ``on_row(row)``; ``on_progress()``
        hears of each change of :attr:`completed`; ``on_stopping()`` that a stop began (the running
        runs checkpoint); ``on_note(line)`` what the sweep did about a fault.  Returns False when
        stopped or its scheduler was lost (the rows so far in :attr:`finished`, what the stop left in
        :attr:`stop`); OSError when summary.csv could not be written."""
        import signal

        from .errors import SweepStopped

        on_row, on_progress = on_row or (lambda row: None), on_progress or (lambda: None)

        def report(row: dict) -> None:
            self.finished.append(row)
            write_summary(self.folder, self.finished, self.swept)  # as runs finish, so that a stopped sweep keeps its table
            on_row(row)
            on_progress()

        def progress(made: float) -> None:
            self.stepped = made
            on_progress()

        previous = signal.signal(signal.SIGTERM, signal.default_int_handler)  # a batch scheduler's stop, as Ctrl-C
        try:
            self.rows = run_sweep(
                self.settings, self.runs, scheduler, workers, report, analysis_workers=analysis_workers, gpus=gpus,
                on_progress=progress, stop_file=self.stop_file, on_stopping=on_stopping, on_note=on_note,
            )  # fmt: skip
        except SweepStopped as stop:
            self.stopped, self.stop = True, stop
        except KeyboardInterrupt:  # before the workers were up: no run had started
            self.stopped = True
        finally:
            signal.signal(signal.SIGTERM, previous)
            clear_request(self.stop_file)
        return not self.stopped

    def save_record(self) -> Path:
        """sweep.json (:func:`write_record`) of the rows so far."""
        return write_record(self.folder, self.settings, self.rows or self.finished, time.perf_counter() - self.started)

    def stopped_line(self) -> str:
        """What a stopped sweep kept, and how to go on: the runs finished (in summary.csv, if any),
        each run the stop ended with its checkpoint's step, the runs left to analyse; for a sweep
        that lost its scheduler, that it did."""
        from .errors import SchedulerLost
        finished = len(self.finished)
        table = f"summary.csv holds the {finished} finished" if finished else "no run had finished, so there is no summary.csv yet"
        if finished == len(self.runs):  # stopped while its workers shut down: nothing to continue
            return (f"sweep stopped after its {len(self.runs)} runs had finished ({table}), before its figures: "
                    "run it again to draw them (every run is skipped)")  # fmt: skip
        parts = [f"sweep stopped after {finished} of {len(self.runs)} runs ({table})"]
        stop = self.stop
        if isinstance(stop, SchedulerLost):
            parts[0] = parts[0].replace("sweep stopped", f"sweep ended: it lost its Dask scheduler at {stop.scheduler} ({stop.why})")
            parts.append("runs that were stepping keep their last periodic checkpoints")
            parts.append("start a scheduler there with its workers and run the same command: finished runs are skipped, "
                         "the others resume from their checkpoints")  # fmt: skip
            return "; ".join(parts)
        if stop is None:
            parts.append("it stopped before its workers were up, so no run had started")
        elif stop.at_once:
            parts.append("a second signal stopped it without waiting for the runs stepping: each keeps its last checkpoint")
        else:
            ended = [r for r in stop.stopped if r.get("step") is not None]
            if ended:
                parts.append(f"{len(ended)} stepping run(s) wrote a checkpoint where they stopped: "
                             + ", ".join(f"{r['run']} at step {r['step']}" for r in ended))  # fmt: skip
            if stop.unanalysed:
                parts.append(f"{len(stop.unanalysed)} run(s) finished stepping but are not analysed yet ({', '.join(stop.unanalysed)})")
        parts.append("run it again to continue: finished runs are skipped, stopped ones resume from their checkpoints")
        return "; ".join(parts)

    def finish(self) -> Path:
        """Every run's summary.csv, in grid order, and the cross-run figures of those that did not fail."""
        from .analysis.figures import write_cross_run

        summary = write_summary(self.folder, self.rows, self.swept)
        done = [r for r in self.rows if r.get("status") != "failed"]
        from .analysis.runs import histories_of

        write_cross_run(self.folder, done, self.swept, histories=histories_of({r["run"]: r.get("run_dir") for r in done}))
        return summary

    @property
    def swept(self) -> list[str]:
        """The columns of the keys the grid varies."""
        return self.settings.get("swept", [])

    @property
    def failed(self) -> list[dict]:
        """The rows of the runs that failed (once the sweep has run whole)."""
        return [r for r in self.rows if r.get("status") == "failed"]

    def summary_lines(self, summary: Path) -> list[str]:
        """The sweep's end: where its table and figures are, the runs that failed, and those not settled."""
        lines = [f"summary: {summary}, sweep.json; figures in {self.folder / 'figures'}; {len(self.failed)} failed"]
        unsettled = [r for r in self.rows if r.get("status") != "failed" and r.get("settled") is False]
        if unsettled:
            lines.append(f"{len(unsettled)} run(s) NOT SETTLED (their m_lf/m_t is not final; decco-warp resume RUN --steps N runs them on):")
            lines += [f"  {row['run']}: {row.get('settled_note', '')}" for row in unsettled]
        return lines

    def unwritten_line(self) -> str | None:
        """For runs that could not write their folder (a full disk), the line that says so, else None."""
        from .run import OUTPUT_FAILURE

        unwritten = [r for r in self.failed if OUTPUT_FAILURE in r.get("reason", "") or "No space left" in r.get("reason", "")]
        if not unwritten:
            return None
        return f"{len(unwritten)} run(s) could not write their folder ({unwritten[0]['run']}: {unwritten[0]['reason']}); {AGAIN}"

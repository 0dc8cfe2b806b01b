"""A collision run from a specification: set-up, stepping, trajectory, checkpoints, resume.

A run folder holds ``spec.toml`` (the resolved specification), ``trajectory.h5``
(H5MD, one frame every ``output_every`` steps), ``checkpoint.h5`` (replaced
atomically every ``checkpoint_every`` steps and at the end) and ``run.log``.
"""

from __future__ import annotations

import contextlib
import time as _time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

import numpy as np

from . import spec as specs
from .checks import MAX_REST_OVERLAP, InputError, check_destination
from .diagnostics import energy_ledger, energy_scale, ledger_closure, state_diagnostics, stress_share_observables
from .durable import describe_write_error, pause_point, write_atomic, write_point
from .folder import RunFolder, missing
from .io import BackgroundFrames, FileFormatError, Trajectory, read_checkpoint, read_frame, write_checkpoint
from .lock import RunFolderLock
from .record import RunRecord
from .plan import Plan, RunError, builtin_pile, pile_path, plan_resume, plan_start, run_dir_of  # noqa: F401 (run's names)
from .simulation import Simulation, graph_steps
from .stops import StopRequests, drive
from .stability import MIN_TIME_STEP_MARGIN, StabilityReport
from .xdmf import write_xdmf
from .errors import BlowUp, NotSettled, OutputError, RunStopped  # noqa: F401 (re-exported: the error lives in errors.py)

#: Seconds of stepping between two looks at the stop requests (Ctrl-C, SIGTERM), whatever the pace.
STOP_LATENCY = 2.0


@dataclass
class RunProgress:
    """What a progress display gets during a run."""

    step: int
    total_steps: int
    time: float
    first_step: int
    elapsed: float
    deepest_overlap: float = 0.0
    """The deepest contact so far, as a fraction of the smaller radius of its pair."""
    warning: str | None = None
    """A warning raised at this step (shown once), else None."""


@dataclass
class RunResult:
    run_dir: Path
    steps: int
    time: float
    wall_seconds: float
    steps_this_session: int
    stepping_seconds: float = 0.0
    """Of the wall time over all sessions, the part spent stepping (the rest: frames, checkpoints, set-up)."""
    session_wall_seconds: float = 0.0
    """The wall time of this session alone (after a resume, the sessions before are not counted)."""
    session_stepping_seconds: float = 0.0
    """Of it, the part spent stepping."""


# --- folders ----------------------------------------------------------------------------


def check_writable(run_dir: Path) -> None:
    """Refuse early an output folder that cannot be created or written (nothing is left behind)."""
    try:
        check_destination(run_dir, "run folder", folder=True)
    except InputError as error:
        raise RunError(str(error)) from None


class RunLog:
    """Timestamped lines appended to run.log (and flushed at once)."""

    def __init__(self, path: Path):
        write_point(path.name)
        self.file = open(path, "a", encoding="utf-8")

    def __call__(self, message: str) -> None:
        if self.file.closed:
            return
        write_point(self.file.name.rsplit("/", 1)[-1])
        stamp = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
        try:
            self.file.write(f"{stamp} {message}\n")
            self.file.flush()
        except OSError as error:
            raise OSError(error.errno, error.strerror, self.file.name) from None

    def close(self) -> None:
        with contextlib.suppress(OSError):  # a line that could not be flushed is already reported
            self.file.close()


# --- one frame of output -------------------------------------------------------------

#: A frame or checkpoint due at a stop that needs nothing of it there (no observer, stop request or
#: end) is made on the host while the device steps the next chunk (RunDriver.advance): its reads
#: from the device are taken at the stop; the frame's observables, checks and write, then the
#: checkpoint's write, after the next launch.  False: everything at its stop (the same frames,
#: checkpoints and log; the tests compare the two).
FRAMES_ALONGSIDE = True


def take_reading(sim: Simulation) -> dict:
    """What a frame reads of the device (each a copy to the host, the device idle between two
    chunks): the state, the pair observables, the work, and the deepest contact since the previous
    frame (whose record starts afresh), with the step and time; :func:`frame_of` makes the frame."""
    return {"step": sim.step_count, "time": sim.time, "state": sim.state, "pairs": sim.pair_observables(),
            "work": sim.work(), "deepest": sim.take_deepest_contact()}  # fmt: skip


def frame_of(reading: dict, sim: Simulation, size_classes: int) -> tuple[dict, dict]:
    """Particle arrays and observables of a :func:`take_reading`, as written to the trajectory: host
    work only (``sim`` gives its constants: the ledger's start, whether the law keeps springs), so
    that it may run while the device steps on."""
    state, pairs = reading["state"], reading["pairs"]
    d = state_diagnostics(state, pairs)
    ledger = energy_ledger(d, sim.energy_start, reading["work"])
    particles = {
        "position": state.positions,
        "velocity": state.velocities,
        "omega": state.omegas,
        "stress": pairs["max_overlap"],
    }
    observables = {
        "kinetic_translational": d["kinetic_translational"],
        "kinetic_rotational": d["kinetic_rotational"],
        "potential": d["potential"],
        "elastic": d["elastic"],
        # The energy held in the contacts' springs (a law with springs per pair: "ssdem").
        **({key: d[key] for key in ("elastic_tangential", "elastic_rolling")} if sim.params.keeps_springs else {}),
        "total_energy": d["total_energy"],
        **ledger,
        "momentum": d["momentum"],
        "angular_momentum": d["angular_momentum"],
        "number_of_contacts": np.int64(d["number_of_contacts"]),
        "max_overlap": d["max_overlap"],
        "deepest_overlap": d["deepest_overlap"],
        "deepest_overlap_pair": d["deepest_overlap_pair"],
        # The top 1 % by largest overlap (the paper's Fig. 8), by overlap / R^2 and by overlap / R.
        **stress_share_observables(pairs["max_overlap"], state.radii, state.size_class, size_classes),
    }
    return particles, observables


def record(sim: Simulation, size_classes: int) -> tuple[dict, dict]:
    """Particle arrays and observables of the current state, as written to the trajectory (the
    deepest contact of the state itself: a run's frame adds the deepest since the previous frame)."""
    return frame_of({"state": sim.state, "pairs": sim.pair_observables(), "work": sim.work()}, sim, size_classes)


# --- start, resume ----------------------------------------------------------------------


@dataclass
class PreparedRun:
    """A run's plan with its simulation built, nothing written yet: what :func:`execute` needs."""

    sim: Simulation
    plan: Plan
    record: RunRecord
    """The run's record (record.py), as its checkpoints keep it."""
    resume: bool
    lock: RunFolderLock | None = None
    """The run folder's lock, once taken (execute takes it for a new folder and releases it at the end)."""
    note: str | None = None
    """A line to show before the run starts (a run that will take hours on the CPU), else None."""

    @property
    def spec(self) -> dict:
        """The plan's resolved specification (spec.toml, /parameters)."""
        return self.plan.spec

    @property
    def run_dir(self) -> Path:
        return self.plan.run_dir


def prepare_start(spec: dict, overwrite: bool = False, device: str | None = None) -> PreparedRun:
    """Check a resolved ``spec``, plan it (:func:`plan_start`) and build its simulation, writing nothing."""
    run_dir = run_dir_of(spec)
    if run_dir.exists() and (not run_dir.is_dir() or any(run_dir.iterdir())) and not overwrite:
        raise RunError(f"run folder {run_dir} already exists; use --overwrite to replace it or resume to continue it")
    check_writable(run_dir)
    # An existing folder (to be overwritten) is locked before anything else: no one else may write there.
    lock = RunFolder(run_dir).lock().acquire() if run_dir.is_dir() else None
    try:
        plan = plan_start(spec, device)
        note = plan_fits(plan, plan.state.n, plan.steps)
        sim = Simulation(
            plan.state,
            plan.params,
            device=plan.device,
            scheme=plan.scheme,
            allow_unstable=plan.allow_unstable,
            ledger=True,
            stability=plan.stability,
        )
    except BaseException:
        if lock is not None:
            lock.release()
        raise
    depth, i, j = plan.rest_overlap
    run_record = RunRecord(size_classes=plan.size_classes, start_overlap=depth, start_overlap_pair=(int(i), int(j)))
    return PreparedRun(sim, plan, run_record, resume=False, lock=lock, note=note)


def plan_fits(plan: Plan, n: int, steps: int) -> str | None:
    """Refuse (RunError) a run of ``n`` particles that its device has no memory for, its force path
    counted (the Newton sweep's rows, O(N^2 / tile)); a line for one that takes hours on the CPU."""
    from .costs import check_fits

    try:
        return check_fits(
            n, plan.scheme, plan.device, steps, "a run", candidate_width=_candidate_width(plan), contact_history=plan.params.keeps_springs
        )  # fmt: skip
    except InputError as error:
        raise RunError(str(error)) from None


def plan_memory(plan: Plan) -> int:
    """Bytes a run's plan needs on its device (costs.memory_estimate of its force path)."""
    from .costs import memory_estimate

    return memory_estimate(plan.state.n, plan.scheme, plan.device, candidate_width=_candidate_width(plan), contact_history=plan.params.keeps_springs)


def _candidate_width(plan: Plan) -> int:
    """The contact lists' width of a plan's particles (arrays.candidate_width)."""
    from .arrays import candidate_width

    return candidate_width(float(plan.state.radii.min()), float(plan.state.radii.max()))


def prepare_resume(run_dir, steps: int | None = None, device: str | None = None) -> PreparedRun:
    """Check a run folder and load its checkpoint; ``steps`` raises the total to run."""
    run_dir = Path(run_dir)
    folder = RunFolder(run_dir)
    spec_path, checkpoint_path, trajectory_path = folder.spec, folder.checkpoint, folder.trajectory
    for path in (spec_path, checkpoint_path):
        if not path.is_file():
            raise RunError(f"{run_dir} does not exist" if not Path(run_dir).exists() else f"{run_dir} is not a run folder: {path.name} is missing")
    if not trajectory_path.is_file():
        # A resumed run appends to its own trajectory; starting a new one would leave a run whose
        # frames begin mid-collision, which analysis would take for the whole run.
        raise RunError(
            f"{run_dir}: {trajectory_path.name} is missing, and a run continues its own trajectory; "
            "put it back to resume, or delete the folder to run it again from the start"
        )
    check_writable(run_dir)
    lock = folder.lock().acquire()
    try:
        return _prepare_resume(run_dir, spec_path, checkpoint_path, trajectory_path, steps, device, lock)
    except BaseException:
        lock.release()
        raise


def _prepare_resume(run_dir, spec_path, checkpoint_path, trajectory_path, steps, device, lock) -> PreparedRun:
    spec = specs.resolve_spec(specs.load_spec_file(spec_path))
    try:
        snapshot, static, kept = read_checkpoint(checkpoint_path)
        run_record = RunRecord.from_checkpoint(kept)
        first_frame = read_frame(trajectory_path, 0)[0]
    except FileFormatError as error:
        raise RunError(str(error)) from None
    except (IndexError, ValueError) as error:
        raise RunError(f"trajectory {trajectory_path} has no readable first frame ({error})") from None
    if first_frame["position"].shape != snapshot["positions"].shape:
        raise RunError(f"{trajectory_path} and {checkpoint_path} are of different runs (particle counts differ)")
    if specs.resolve_spec(_parse_toml(run_record.spec_toml)) != spec:
        raise RunError(f"{spec_path} changed since the run started; restore it to resume")
    if steps is not None and steps < int(snapshot["step"]):
        raise RunError(f"steps {steps} is below the {int(snapshot['step'])} already taken")
    plan = plan_resume(spec, static, run_dir, device, steps)
    note = plan_fits(plan, static.n, max(0, plan.steps - int(snapshot["step"])))
    sim = Simulation.from_snapshot(static, plan.params, snapshot, device=plan.device, scheme=plan.scheme)
    return PreparedRun(sim, plan, run_record, resume=True, lock=lock, note=note)


#: Something that watches frames as a run makes them: (every how many steps, callback(step, time, particles, observables)).
Observer = tuple[int, Callable[[int, float, dict, dict], None]]


def execute(
    run: PreparedRun, progress: Callable[[RunProgress], None] | None = None, observers: list[Observer] | None = None,
    stop_file=None,
) -> RunResult:  # fmt: skip
    """Write the run folder (or continue it) and step the run to its end, holding its lock.  It stops
    at a checkpoint (RunStopped) on SIGINT or SIGTERM, or once ``stop_file`` exists (a sweep's
    request to its workers: decco_warp/stops.py)."""
    if not run.resume:
        run.run_dir.mkdir(parents=True, exist_ok=True)
    run.lock = run.lock or RunFolder(run.run_dir).lock()
    try:
        run.lock.acquire()  # a new folder: before anything in it is touched
        return _advance(_open_or_clean(run, progress, observers), stop_file)
    finally:
        run.lock.release()


def _open_or_clean(run: PreparedRun, progress, observers) -> RunDriver:
    """:func:`_open`, with a failed write as an OutputError saying what is kept: a resumed run keeps
    its checkpoint; a new run whose first checkpoint was never written is removed, so that the same
    command starts it again."""
    opened: list = []
    try:
        return _open(run, progress, observers, opened)
    except OSError as error:
        for thing in reversed(opened):  # the log and the trajectory, unless a driver owns them
            with contextlib.suppress(OSError):
                thing.close()
        if run.resume:
            raise OutputError(_failed_write(run.run_dir, run.sim.step_count, error)) from None
        for name in RunFolder.RUN_FILES:
            with contextlib.suppress(OSError):
                (run.run_dir / name).unlink(missing_ok=True)
        raise OutputError(
            f"writing the run folder {run.run_dir} failed before its first checkpoint ({describe_write_error(error)}); "
            "nothing of it is kept: free space or fix the folder, then run the same command again"
        ) from None


#: How the one line of a run whose write failed begins (a sweep tells them by it).
OUTPUT_FAILURE = "writing the run folder"


def _failed_write(run_dir: Path, step: int, error: OSError) -> str:
    """The one line of a run whose write failed at ``step``: what failed and what is kept."""
    try:
        kept = int(read_checkpoint(RunFolder(run_dir).checkpoint)[0]["step"])
    except (FileFormatError, OSError):
        return (
            f"writing the run folder failed at step {step} ({describe_write_error(error)}); no checkpoint is left in "
            f"{run_dir}: fix the folder, then run the run again with --overwrite"
        )
    return (
        f"writing the run folder failed at step {step} ({describe_write_error(error)}); "
        f"the checkpoint of step {kept} is intact: free space or fix the folder, then decco-warp resume {run_dir}"
    )


def _open(run: PreparedRun, progress, observers, opened: list) -> RunDriver:
    """Write a new run folder's first frame and checkpoint, or reopen a resumed one: its driver.
    What it opens (the log, the trajectory) is added to ``opened`` as it goes."""
    observers = observers or []
    sim, plan, spec, run_dir, run_record = run.sim, run.plan, run.spec, run.run_dir, run.record
    folder = RunFolder(run_dir)
    spec_text = specs.dumps(spec, header=f"decco-warp run specification, resolved {datetime.now(timezone.utc):%Y-%m-%d %H:%M UTC}")
    if run.resume:
        if spec_text.split("\n", 1)[1] != run_record.spec_toml.split("\n", 1)[1]:  # the total steps changed
            run_record.spec_toml = spec_text
            write_atomic(folder.spec, spec_text)
        log = RunLog(folder.log)
        opened.append(log)
        for stale in run_dir.glob(".*.tmp"):  # a checkpoint being written when the run was killed
            stale.unlink()
            log(f"resume: removed the unfinished {stale.name}")
        log(f"resume: from step {sim.step_count} of {plan.steps} on {sim.device}")
        sample = record(sim, run_record.size_classes)[1]
        trajectory = Trajectory.reopen(folder.trajectory, keep_through_step=sim.step_count, observables=sample)
        opened.append(trajectory)
        return RunDriver(sim, trajectory, plan, run_dir, log, run_record, progress, observers)

    for path in (folder.trajectory, folder.checkpoint, folder.log):
        path.unlink(missing_ok=True)
    write_atomic(folder.spec, spec_text)
    run_record.spec_toml = spec_text
    log = RunLog(folder.log)
    opened.append(log)
    state = plan.state
    log(f"start: {state.n} particles on {sim.device}, precision {plan.precision}, {plan.steps} steps")
    for line in plan.lines():
        log(line)
    particles, observables = record(sim, run_record.size_classes)
    observables.update(deepest_since(observables, sim.take_deepest_contact()))
    parameters = {
        "spec": spec,
        "collision": state.metadata,
        "piles": plan.pile_info,
        "size_classes": run_record.size_classes,
        "stability": {
            "stiffness_margin": plan.stability.stiffness_margin,
            "time_step_margin": plan.stability.time_step_margin,
            "impact_speed": plan.forecast.impact_speed,
            "predicted_overlap": plan.forecast.fraction,
        },
    }
    trajectory = Trajectory.create(folder.trajectory, state, observables, parameters)
    opened.append(trajectory)
    trajectory.append(sim.step_count, sim.time, particles, observables)
    for _, observe in observers:
        observe(sim.step_count, sim.time, particles, observables)
    write_checkpoint(folder.checkpoint, sim.snapshot(), state, run_record.as_checkpoint())
    return RunDriver(sim, trajectory, plan, run_dir, log, run_record, progress, observers)


def execute_ensemble(runs: list[PreparedRun], stop_file=None) -> list[RunResult | BaseException]:
    """Step prepared runs together as one ensemble (decco_warp/ensemble.py): the same Params and
    step, any sizes.  Each run writes its own folder as if stepped alone (bit for bit), under its
    own lock; one that fails (a blow-up, its output, a signal or ``stop_file``, as for
    :func:`execute`) ends with its error in the list while the others go on.  Returns, per run,
    its RunResult or the error that ended it."""
    from .ensemble import Ensemble

    outcomes: list[RunResult | BaseException | None] = [None] * len(runs)
    ensemble = Ensemble([run.sim for run in runs])
    drivers: dict[int, RunDriver] = {}
    locks = []
    try:
        for k, run in enumerate(runs):
            run.sim = ensemble.views[k]
            try:
                if not run.resume:
                    run.run_dir.mkdir(parents=True, exist_ok=True)
                run.lock = run.lock or RunFolder(run.run_dir).lock()
                run.lock.acquire()
                locks.append(run.lock)
                drivers[k] = _open_or_clean(run, None, None)
                others = [other.run_dir.name for other in runs if other is not run]
                drivers[k].log(f"ensemble: stepped together with {len(others)} other run(s) in one set of launches: {', '.join(others)}")
            except (RunError, OSError, FileFormatError, OutputError) as error:
                outcomes[k] = error
        drive(_Together(ensemble, drivers, outcomes), stop_file)
    finally:
        for k, driver in drivers.items():
            closing = driver.close()
            if outcomes[k] is None and closing is not None:
                outcomes[k] = driver.failure(closing, log=False)
            if outcomes[k] is None and driver.done:
                outcomes[k] = driver.result()
        for lock in locks:
            lock.release()
    return outcomes


class _Together:
    """Runs stepped as one ensemble, for :func:`~decco_warp.stops.drive`: each chunk ends at the
    nearest stop of any run still going; a run that fails or stops ends with its outcome, the
    others go on."""

    def __init__(self, ensemble, drivers: dict[int, RunDriver], outcomes: list):
        self.ensemble, self.drivers, self.outcomes = ensemble, drivers, outcomes
        self.stepped: list[int] = []

    @property
    def active(self) -> list[int]:
        return [k for k, driver in self.drivers.items() if not driver.done and self.outcomes[k] is None]

    @property
    def done(self) -> bool:
        return not self.active

    def advance(self) -> None:
        self.stepped = self.active  # the runs of this chunk (the last chunk of a run makes it done)
        self.ensemble.step(min(self.drivers[k].steps_to_next_stop() for k in self.stepped))
        for k in self.stepped:  # the frames read at the last stop, made on the host while the device steps
            try:
                self.drivers[k].finish_stop()
            except (BlowUp, OSError) as error:
                self.outcomes[k] = self.drivers[k].failure(error)
        self.ensemble.finish()

    def after(self, seconds: float, stop: StopRequests) -> None:
        requested = stop.signal  # read once, so that every run stops at the same step
        for k in self.stepped:
            if self.outcomes[k] is not None:  # its last frame failed while this chunk stepped
                continue
            try:
                self.drivers[k].after_steps(seconds, requested)
            except (BlowUp, OSError) as error:
                self.outcomes[k] = self.drivers[k].failure(error)
            except RunStopped as stopped:
                self.outcomes[k] = stopped


def start_run(spec: dict, overwrite: bool = False, device: str | None = None, progress=None) -> RunResult:
    """Set up the collision of a resolved ``spec`` and run it in a new run folder."""
    return execute(prepare_start(spec, overwrite, device), progress)


def resume_run(run_dir, steps: int | None = None, device: str | None = None, progress=None) -> RunResult:
    """Continue a stopped or killed run from its checkpoint."""
    return execute(prepare_resume(run_dir, steps, device), progress)


#: :func:`resume_until_settled` extends a run by this fraction of its steps at a time.
SETTLE_EXTENSION = 0.25


def resume_until_settled(
    run_dir,
    advance: Callable[[int | None], object] | None = None,
    max_steps: int | None = None,
    min_members: int = 50,
    device: str | None = None,
    say: Callable[[str], None] | None = None,
) -> dict:
    """Finish a run, then judge its late window (``analysis.runs.late_verdict``); while it is not
    settled, extend it by SETTLE_EXTENSION of its steps, at most to ``max_steps`` (default: 4 times
    its steps once finished), and judge again.  Returns the settled verdict.

    ``advance(steps)`` runs the run on to ``steps`` in all (None: to those it asks for already);
    default :func:`resume_run` (``decco-warp resume --until-settled`` passes its own, with a
    progress bar).  ``say`` hears a line per verdict and per extension.  Raises RunError for a
    folder without a trajectory, FileFormatError for a run that cannot be judged and NotSettled at
    the limit (the run is whole)."""
    from .analysis.runs import late_verdict  # SciPy and the cluster finder, only when a run is judged

    run_dir = Path(run_dir)
    advance = advance or (lambda steps: resume_run(run_dir, steps, device))
    say = say or (lambda line: None)

    def verdict() -> dict:
        try:
            return late_verdict(run_dir, min_members=min_members, device=device)
        except (FileFormatError, OSError) as error:
            raise FileFormatError(f"{run_dir}: cannot judge whether the run is settled: {error}") from None

    if not RunFolder(run_dir).trajectory.is_file():
        raise RunError(f"{run_dir} holds no {RunFolder.TRAJECTORY}" if run_dir.is_dir() else missing(run_dir))
    advance(None)  # its own steps first
    judged = verdict()
    limit = max_steps if max_steps is not None else 4 * judged["steps"]
    while not judged["settled"]:
        say(f"{run_dir}: not settled at step {judged['steps']} (t {judged['time']:.6g} s): {judged['settled_note']}")
        if judged["steps"] >= limit:
            raise NotSettled(f"{run_dir} is not settled at step {judged['steps']}, the limit; raise --max-steps to run it on")
        target = min(limit, judged["steps"] + max(1, int(SETTLE_EXTENSION * judged["steps"])))
        say(f"{run_dir}: extending to step {target}")
        advance(target)
        judged = verdict()
    say(f"{run_dir}: settled at step {judged['steps']} (t {judged['time']:.6g} s): {judged['settled_note']}; "
        f"decco-warp analyze {run_dir} analyses it whole")  # fmt: skip
    return judged


def _parse_toml(text: str) -> dict:
    return specs.tomllib.loads(text)


def _advance(driver: RunDriver, stop_file=None) -> RunResult:
    try:
        drive(driver, stop_file)
    except (BlowUp, OSError) as error:
        failure = driver.failure(error)
        driver.close()
        raise failure from None
    except BaseException:
        driver.close()
        raise
    closing = driver.close()
    if closing is not None:
        raise driver.failure(closing, log=False)
    return driver.result()


class RunDriver:
    """One run's side of the stepping loop: when it must stop, and what it does there (frames,
    checkpoints, progress, the overlap and blow-up watches).  The loop that steps the simulation
    (one run's, or an ensemble's shared by several drivers) belongs to the caller."""

    def __init__(self, sim, trajectory, plan: Plan, run_dir: Path, log: RunLog, run_record: RunRecord, progress, observers=()):
        self.sim, self.run_dir, self.log, self.record = sim, run_dir, log, run_record
        self.trajectory = BackgroundFrames(trajectory)
        self.progress, self.observers = progress, list(observers)
        self.total = plan.steps
        self.output_every = plan.outputs.output_every
        self.checkpoint_every = plan.outputs.checkpoint_every
        self.size_classes = run_record.size_classes
        self.first_step = sim.step_count
        self.wall_before = run_record.wall_seconds
        self.stepping_before = run_record.stepping_seconds or 0.0  # runs of decco-warp 0.2 did not count it
        self.stepping = 0.0
        # Where the time outside stepping goes (this session): frames' observables, trajectory writes, checkpoints.
        self.outside = {"observables": 0.0, "trajectory": 0.0, "checkpoints": 0.0}
        # What was read of the device at the last stop for a frame and a checkpoint whose host work
        # (the frame's observables, checks, log line and hand-over to the writer; the checkpoint's
        # write) waits for the next chunk's launch, so that the device steps meanwhile (FRAMES_ALONGSIDE);
        # that work's seconds, spent while the steps ran; a warning its frame raised, for the progress line.
        self.pending: dict | None = None
        self.pending_checkpoint: tuple | None = None
        self.alongside = 0.0
        self.pending_warning: str | None = None
        self.started = _time.perf_counter()
        # Progress is reported about 200 times per run, never between graph blocks (nor outer steps).
        outer = sim.step_multiple  # steps of an outer step: every stop is a whole number of them
        self.graph_steps = graph_steps(outer)
        self.report_every = outer * max(-(-50 // outer), self.total // 200 // outer)
        self.start_energy = sim.energy_start["total_energy"]
        # Dissipation only lowers the total energy; a gain of a fraction of this means the integration broke down.
        self.scale = energy_scale(sim.energy_start)
        self.overlaps = OverlapWatch(run_record, plan.max_overlap, log)
        # A frame's deepest overlap is the deepest since the previous frame, which a resumed run may
        # have written before it stopped (checkpoints of decco-warp 0.2 do not say: then its start).
        self.last_frame = self.first_step if run_record.last_frame_step is None else run_record.last_frame_step
        self.overflows_noted: set[str] = set()
        """The overflows said in the log already ("history", "candidates"): each is said once."""

    @property
    def done(self) -> bool:
        return self.sim.step_count >= self.total

    def advance(self) -> None:
        """Step this run alone up to its next stop (an ensemble's runs are stepped together: _Together),
        the last stop's frame made on the host while the device steps."""
        self.sim.step(self.steps_to_next_stop())
        self.finish_stop()
        self.sim.finish()  # so that the steps' time is counted here, not in the frame that reads them

    def finish_stop(self) -> None:
        """The host's part of the last stop, if it waits (:meth:`after_steps`): its frame, then its
        checkpoint, from what was read of the device there.  Raises BlowUp as the frame would have at
        its stop; nothing of it is written then, nor its checkpoint."""
        reading, self.pending = self.pending, None
        checkpoint, self.pending_checkpoint = self.pending_checkpoint, None
        if reading is None and checkpoint is None:
            return
        began = _time.perf_counter()
        try:
            if reading is not None:
                _, self.pending_warning = self.make_frame(reading, alongside=True)
            if checkpoint is not None:
                self.save_checkpoint(*checkpoint)
        finally:
            self.alongside += _time.perf_counter() - began

    def after(self, seconds: float, stop: StopRequests) -> None:
        """:meth:`after_steps`, the stop asked for read first."""
        self.after_steps(seconds, stop.signal)

    def steps_to_next_stop(self) -> int:
        step = self.sim.step_count
        stops = [self.total, _next_multiple(step, self.output_every), _next_multiple(step, self.checkpoint_every)]
        stops += [_next_multiple(step, every) for every, _ in self.observers]
        due = min(min(stops) - step, self.report_every - step % self.report_every)
        return min(due, self._steps_within(STOP_LATENCY))

    def _steps_within(self, seconds: float) -> int:
        """Whole graph blocks of steps that take about ``seconds`` at this session's pace: a stop
        asked for (Ctrl-C, SIGTERM) is answered that soon, however far apart the run's reports are."""
        done = self.sim.step_count - self.first_step
        if done == 0 or self.stepping <= 0.0:
            return self.graph_steps
        return max(self.graph_steps, int(seconds * done / self.stepping) // self.graph_steps * self.graph_steps)

    def checkpoint(self, step: int) -> None:
        began = _time.perf_counter()
        self.save_checkpoint(step, self.sim.snapshot(), began)
        self.outside["checkpoints"] += _time.perf_counter() - began

    def save_checkpoint(self, step: int, snapshot: dict, at: float) -> None:
        """Write the checkpoint of ``step`` from its ``snapshot``, read at the stop (``at``:
        perf_counter then), once the trajectory's frames up to it are on disk."""
        self.trajectory.flush()  # the frames up to this step are on disk before the checkpoint says so
        self.record.wall_seconds = self.wall_before + at - self.started
        self.record.stepping_seconds = self.stepping_before + self.stepping
        write_checkpoint(RunFolder(self.run_dir).checkpoint, snapshot, self.sim.static, self.record.as_checkpoint())
        self.log(f"checkpoint: step {step}")

    def after_steps(self, seconds: float, stop_signal: str | None = None) -> None:
        """Count ``seconds`` of stepping, then do what is due at the step reached (nothing between
        this run's stops); raises BlowUp, OSError, or RunStopped after a checkpoint when ``stop_signal``."""
        sim, total = self.sim, self.total
        self.stepping += seconds
        step = sim.step_count
        pause_point("step", step)
        frame = None
        warning, self.pending_warning = self.pending_warning, None  # a frame made while the device stepped
        # Made here: what an observer or the end needs, or a stop asked for; else on the host while
        # the device steps the next chunk (advance), from what is read of the device now.
        now = not FRAMES_ALONGSIDE or step == total or stop_signal is not None or any(step % every == 0 for every, _ in self.observers)
        if step % self.output_every == 0 or step == total:
            began = _time.perf_counter()
            reading = take_reading(sim)
            self.note_candidate_overflows(step)
            self.outside["observables"] += _time.perf_counter() - began
            if now:
                frame, made = self.make_frame(reading)
                warning = made or warning
            else:
                self.pending = reading
        for every, observe in self.observers:
            if step % every == 0 or step == total:
                frame = frame or record(sim, self.size_classes)  # copied to the host only when due
                observe(step, sim.time, *frame)
        if step % self.checkpoint_every == 0 or step == total:
            if now:
                self.checkpoint(step)
            else:  # written after the frame of this step, if any (finish_stop)
                began = _time.perf_counter()
                self.pending_checkpoint = (step, sim.snapshot(), began)
                self.outside["checkpoints"] += _time.perf_counter() - began
        if self.progress is not None:
            elapsed = _time.perf_counter() - self.started
            self.progress(RunProgress(step, total, sim.time, self.first_step, elapsed, self.overlaps.deepest, warning))
        if stop_signal is not None and step < total:
            self.checkpoint(step)
            self.log(f"stopped by {stop_signal} at step {step}; decco-warp resume {self.run_dir} continues")
            raise RunStopped(stop_signal, step, self.run_dir)

    def make_frame(self, reading: dict, alongside: bool = False) -> tuple[tuple[dict, dict], str | None]:
        """A frame from its reading (:func:`take_reading`): checked (BlowUp: nothing of it is written),
        its deepest contact watched, handed to the trajectory's writer and logged; the frame and any
        warning it raised.  ``alongside``: while the device steps (its time is counted there)."""
        step, time, sim = reading["step"], reading["time"], self.sim
        began = _time.perf_counter()
        frame = particles, observables = frame_of(reading, sim, self.size_classes)
        observables.update(deepest_since(observables, reading["deepest"]))
        try:
            check_sanity(step, particles)
            check_energy(step, observables["total_energy"], self.start_energy, self.scale)
        except BlowUp as error:
            raise BlowUp(f"{error}; likely cause: {likely_cause(sim.stability, self.overlaps, self.record)}") from None
        warning = self.overlaps.see(step, observables, since=self.last_frame)
        self.last_frame = self.record.last_frame_step = step
        written = _time.perf_counter()
        self.trajectory.append(step, time, particles, observables)
        if not alongside:
            self.outside["observables"] += written - began
            self.outside["trajectory"] += _time.perf_counter() - written
        self.log(
            f"frame: step {step}, t {time:.6g} s, E {observables['total_energy']:.9g} erg, "
            f"ledger closed to {ledger_closure(observables, self.start_energy, self.scale):.2g}, "
            f"contacts {int(observables['number_of_contacts'])}, "
            f"deepest overlap {float(observables['deepest_overlap']):.3g}"
        )
        return frame, warning

    def note_candidate_overflows(self, step: int) -> None:
        """Say once, at a frame, that some particles met more contact candidates than their list
        holds: right, but each walks its whole system every step, so a run slows down; and once
        that some touched more particles than their contact history holds (a law with springs per
        pair): the springs of those contacts were not kept."""
        for kind, count, said in (
            ("history", self.sim.history_overflows,
             "warning: at step {step}, {overflows} of the particles touched more particles than their contact history holds; the "
             "springs of the contacts past it start afresh at every step (static friction and the rolling and twisting springs are lost there)"),
            ("candidates", self.sim.candidate_overflows,
             "note: at step {step}, {overflows} of the particles met more contact candidates than a list holds; their contacts are "
             "right, but each of them walks its whole system every step, which slows the run (docs/benchmarks.md)"),
        ):  # fmt: skip
            if kind in self.overflows_noted:
                continue  # said once: no more copies of the counts from the device
            overflows = count()
            if overflows:
                self.overflows_noted.add(kind)
                self.log(said.format(step=step, overflows=overflows))

    def failure(self, error: BaseException, log: bool = True) -> BaseException:
        """What a BlowUp or OSError raised by :meth:`after_steps` means for the user, logged."""
        if isinstance(error, BlowUp):
            with contextlib.suppress(OSError):
                self.log(f"blow-up: {error}; the last checkpoint is kept")
            return error
        message = _failed_write(self.run_dir, self.sim.step_count, error)
        if log:
            with contextlib.suppress(OSError):
                self.log(f"output error: {message}")
        return OutputError(message)

    def close(self) -> OSError | None:
        """Close the trajectory and the log (saying so when the run is done); returns the error of a
        write that failed on the way (the trajectory's last frame, the log's last line), else None."""
        failed = None
        try:  # a finished or stopped run's frames were flushed by its last checkpoint
            self.trajectory.close()
        except OSError as error:
            failed = error
            with contextlib.suppress(OSError):
                self.log(f"output error: the last frame may be missing from the trajectory ({error})")
        try:  # the sidecar through which ParaView and VisIt read the trajectory (decco_warp/xdmf.py)
            write_xdmf(RunFolder(self.run_dir).trajectory)
        except (OSError, FileFormatError) as error:
            if isinstance(error, OSError):
                failed = failed or error
            with contextlib.suppress(OSError):
                self.log(f"output error: trajectory.xdmf not written ({error}); decco-warp export {self.run_dir} --xdmf writes it")
        try:
            self._log_done()
        except OSError as error:
            failed = failed or error
        self.log.close()
        return failed

    def _log_done(self) -> None:
        self.wall = _time.perf_counter() - self.started
        if self.done:
            outside = 100.0 * (self.wall - self.stepping) / self.wall if self.wall > 0 else 0.0
            self.log(
                f"done: step {self.sim.step_count}, t {self.sim.time:.6g} s, {self.wall:.1f} s wall this session, "
                f"{self.stepping:.1f} s of it stepping ({outside:.0f} % outside: "
                + ", ".join(f"{what} {seconds:.1f} s" for what, seconds in self.outside.items())
                + "); "
                + (f"frames and checkpoints made on the host while the device stepped: {self.alongside:.1f} s of the stepping; " if self.alongside > 0 else "")
                + f"{self.overlaps.summary()}"
                + self._list_builds()
            )

    def _list_builds(self) -> str:
        """How often the contacts' neighbour list was built this session (gravity on its own clock), or nothing."""
        builds = self.sim.neighbour_list_builds()
        if builds is None:
            return ""
        steps = self.sim.step_count - self.first_step
        return f"; neighbour list built {builds} times in {steps} steps" + (f" (every {steps / builds:.3g} steps)" if builds else "")

    def result(self) -> RunResult:
        sim = self.sim
        return RunResult(
            self.run_dir, sim.step_count, sim.time, self.wall_before + self.wall, sim.step_count - self.first_step,
            self.stepping_before + self.stepping, self.wall, self.stepping,
        )  # fmt: skip


def check_sanity(step: int, particles: dict) -> None:
    """Raise BlowUp naming the step, the particle and the quantity that is not finite."""
    for name in ("position", "velocity", "omega"):
        bad = np.flatnonzero(~np.isfinite(particles[name]).all(axis=1))
        if bad.size:
            raise BlowUp(f"step {step}: particle {bad[0]} has a non-finite {name}")


def likely_cause(stability: StabilityReport, overlaps: "OverlapWatch", run_record: RunRecord) -> str:
    """What most probably broke a run, from what it saw: coincident particles at the start, a time
    step too long for the spring (eq. 17), or contacts deeper than a centre (a spring too soft)."""
    depth = run_record.start_overlap
    if depth > MAX_REST_OVERLAP:
        i, j = run_record.start_overlap_pair
        return (
            f"particles {i} and {j} started {depth:.3g} of the smaller radius into each other: coincident or "
            "nearly coincident particles in the input"
        )
    if stability.time_step_margin < MIN_TIME_STEP_MARGIN:
        return (
            f"dt = {stability.dt:.3g} s is too long for k_in = {stability.k_in:.3g} dyne/cm (eq. 17 margin "
            f"{stability.time_step_margin:.3g}, need >= {MIN_TIME_STEP_MARGIN:g}); use dt <= {stability.safe_dt:.3g} s"
        )
    if overlaps.deepest > 1.0:
        return (
            f"contacts went past a sphere's centre ({overlaps.summary()}): k_in = {stability.k_in:.3g} dyne/cm is "
            'too soft for the impact speed; k_in = "auto" chooses one stiff enough'
        )
    return (
        f"no cause stands out: dt = {stability.dt:.3g} s may still be too long for k_in (eq. 17 margin "
        f"{stability.time_step_margin:.3g}); halving dt tells"
    )


#: Depths (fractions of the smaller radius of a pair) past which a run warns, once each, and why.
OVERLAP_WARNINGS = {
    0.5: "deeper than half the smaller radius",
    1.0: "a centre inside the other sphere, outside the model's validity",
}


def deepest_since(observables: dict, since_last: dict) -> dict:
    """A frame's deepest overlap: the deepest contact of any step since the previous frame
    (Simulation.take_deepest_contact), or of the frame's own state if that is deeper (the same
    contact, seen without the record's 6e-8 quantisation)."""
    if since_last["deepest_overlap"] > observables["deepest_overlap"]:
        return since_last
    return {key: observables[key] for key in since_last}


class OverlapWatch:
    """The deepest contact of a run, frame by frame: warned about past each of OVERLAP_WARNINGS
    (once, in run.log and on the progress line), and a stop past ``[run] max_overlap`` if set.

    Its record lives in the run's record (record.py), written into each checkpoint, so that a resumed
    run neither forgets its deepest contact nor warns twice.
    """

    def __init__(self, run_record: RunRecord, limit: float | None, log: Callable[[str], None]):
        self.record, self.limit, self.log = run_record, limit, log

    @property
    def deepest(self) -> float:
        return self.record.deepest_overlap

    def see(self, step: int, observables: dict, since: int | None = None) -> str | None:
        """Note a frame's deepest contact, met at a step after ``since`` (the previous frame) and up
        to ``step``; returns a warning when it first passes a level."""
        depth = float(observables["deepest_overlap"])
        i, j = (int(k) for k in observables["deepest_overlap_pair"])
        since = step - 1 if since is None else since
        if depth > self.deepest:
            r = self.record
            r.deepest_overlap, r.deepest_overlap_step, r.deepest_overlap_since, r.deepest_overlap_pair = depth, step, since, (i, j)
        when = _steps(since, step)
        if self.limit is not None and depth > self.limit:
            raise BlowUp(
                f"{when}: particles {i} and {j} overlap by {depth:.3g} of the smaller radius, past "
                f"[run] max_overlap = {self.limit:g}; k_in is too soft for the impact speed (see the predicted "
                "deepest overlap in run.log, or set k_in = \"auto\")"
            )
        warning = None
        for level, meaning in OVERLAP_WARNINGS.items():
            if depth > level > self.record.overlap_warned:
                self.record.overlap_warned = level
                warning = (
                    f"warning: {when}: particles {i} and {j} overlap by {depth:.3g} of the smaller radius "
                    f"({meaning}); the run goes on"
                )
        if warning:
            self.log(warning)
        return warning

    def summary(self) -> str:
        r = self.record
        if r.deepest_overlap_step < 0:
            return "no contacts seen at the frames"
        i, j = r.deepest_overlap_pair
        step, since = r.deepest_overlap_step, r.deepest_overlap_since
        when = _steps(since if since >= 0 else step - 1, step)  # runs of decco-warp 0.2 kept no `since`
        return f"deepest overlap {self.deepest:.3g} of the smaller radius at {when} (particles {i} and {j})"


def _steps(since: int, step: int) -> str:
    """The steps after ``since`` up to ``step``, in words."""
    return f"step {step}" if since >= step - 1 else f"steps {since + 1} to {step}"


#: What can go wrong with one run (its input, its numerics, its output), as a sweep records it.
RUN_FAILURES = (RunError, BlowUp, OutputError, FileFormatError, ValueError, RuntimeError, OSError)

#: A frame stops the run if the total energy has grown by this fraction of |U| + KE at the start.
BLOW_UP_ENERGY_GAIN = 0.1


def check_energy(step: int, total_energy: float, start_energy: float, scale: float) -> None:
    gain = total_energy - start_energy
    if not np.isfinite(total_energy) or gain > BLOW_UP_ENERGY_GAIN * scale:
        raise BlowUp(
            f"step {step}: the total energy grew by {gain:.3g} erg ({gain / scale:.2g} of |U| + KE at the start), "
            "which friction and restitution cannot do"
        )


def _next_multiple(step: int, every: int) -> int:
    return (step // every + 1) * every

"""The ``decco-warp`` command line: a thin layer over the Python API."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from ._version import __version__
from .folder import RunFolder, missing
from .params import PHYSICS_RANGES
from .scheme import GRAVITY_INTERVAL_AUTO, auto_gravity_every
from .spec import pile_defaults
from .errors import EXIT_BLOW_UP, EXIT_INPUT, EXIT_NOT_SETTLED, EXIT_OUTPUT, EXIT_STOPPED, DeccoError  # noqa: F401
# (The exit codes, README "When things go wrong", live in errors.py beside the errors that carry them.)

app = typer.Typer(
    name="decco-warp",
    help="Soft-sphere DEM collisions of self-gravitating rubble piles on NVIDIA Warp.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts are plain: units like [cm] and TOML tables like [sweep] print as written
)

DeviceOption = typer.Option(
    None, "--device", help="cpu, cuda or cuda:N (default: $DECCO_DEVICE, else CUDA if present, else cpu)."
)


def fail(message: str, code: int = EXIT_INPUT) -> None:
    """Print a one-line error and exit: bad input is exit code 2, never a traceback.  A requested
    stop (exit 3: SIGINT or SIGTERM, a checkpoint written) is no error, and its line says so."""
    typer.echo(f"decco-warp: {'' if code == EXIT_STOPPED else 'error: '}{message}", err=True)
    raise typer.Exit(code)


def fail_on(error: Exception) -> None:
    """The one map from an error to how a command ends: decco-warp's errors (errors.py) with their own
    exit code (a blow-up saying the last checkpoint is kept), any other bad input (a ValueError:
    parsing, Params' checks) with exit code 2; always one line."""
    from .errors import BlowUp

    message = " ".join(str(error).split())
    if isinstance(error, BlowUp):
        message = f"the run blew up: {message}; the last checkpoint is kept"
    fail(message, error.exit_code if isinstance(error, DeccoError) else EXIT_INPUT)


def write_failed(error: OSError, kept: str) -> None:
    """Exit 5 with one line: the write that failed (``error``), and what is kept."""
    from .durable import describe_write_error

    fail(f"{describe_write_error(error)}; {kept}", EXIT_OUTPUT)


def _end(code: int, abandoned_before: int = 0) -> None:
    """Exit with ``code``; at once (os._exit) when HDF5 was cut off inside a write (since
    ``abandoned_before`` files were), since closing such a file (as Python's exit would) can crash:
    what it wrote before stays readable."""
    import sys

    durable = sys.modules.get("decco_warp.durable")
    if durable is not None and len(durable.ABANDONED) > abandoned_before:
        import os

        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    raise SystemExit(code)


def main_entry() -> None:
    """The console script: typer's app, with usage errors as one line (exit code 2) instead of a panel."""
    import sys

    durable = sys.modules.get("decco_warp.durable")
    before = len(durable.ABANDONED) if durable is not None else 0
    try:
        code = app(standalone_mode=False)
    except typer.Exit as done:
        _end(done.exit_code, before)
    except OSError as error:  # a write that no command caught (each names what it keeps): still one line
        from .durable import WRITE_ERRNOS, describe_write_error

        if error.errno not in WRITE_ERRNOS:
            raise
        typer.echo(f"decco-warp: error: {describe_write_error(error)}; the files written before it are whole", err=True)
        _end(EXIT_OUTPUT, before)
    except DeccoError as error:  # one that no command caught (each adds what it keeps): still one line, its exit code
        try:
            fail_on(error)
        except typer.Exit as done:
            _end(done.exit_code, before)
    except Exception as error:  # typer's (or click's) usage errors carry a message and an exit code
        if type(error).__name__ == "Abort":
            typer.echo("decco-warp: aborted", err=True)
            raise SystemExit(130) from None
        if not (hasattr(error, "format_message") and hasattr(error, "exit_code")):
            raise
        ctx = getattr(error, "ctx", None)
        command = f" {ctx.info_name}" if ctx is not None and ctx.parent is not None else ""
        message = " ".join(error.format_message().split())
        typer.echo(f"decco-warp{command}: error: {message} (see --help)", err=True)
        raise SystemExit(error.exit_code) from None
    _end(code if isinstance(code, int) else 0, before)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"decco-warp {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """Soft-sphere DEM collisions of self-gravitating rubble piles on NVIDIA Warp."""


@app.command()
def info(device: Optional[str] = DeviceOption) -> None:
    """Show the Warp version, the devices found (each GPU with its memory) and the one a run would use."""
    import warp as wp

    from .device import DeviceError, describe_devices, resolve_device
    from .layouts import choose_layout

    try:
        chosen = resolve_device(device)
    except DeviceError as error:
        fail(str(error))
    typer.echo(f"decco-warp {__version__}")
    typer.echo(f"warp-lang  {wp.config.version}")
    typer.echo("devices (* the one a run would use):")
    devices = describe_devices()
    for entry in devices:
        marker = "*" if entry["name"] == chosen else " "
        memory = f", {entry['memory'] / 2**30:.1f} GiB" if entry["memory"] else ""
        typer.echo(f"  {marker} {entry['name']:<8} {entry['description']}{memory}")
    gpus = sum(1 for entry in devices if entry["is_cuda"])
    layout = choose_layout(10_240, chosen)
    typer.echo(f"would use: {chosen}")
    if gpus:
        typer.echo(f"a sweep here: {gpus} worker(s), one per GPU, cuda:0 to cuda:{gpus - 1} (--gpus N: the first N)")
    typer.echo(f"force kernel layout at N = 10 240: {layout.describe()}")


# --- progress displays -----------------------------------------------------------------


#: Seconds between progress lines when stderr is a file or pipe (a batch job's log), where rich
#: draws its bar only once, at the end: $DECCO_LOG_EVERY, default 30.
LOG_EVERY_DEFAULT = 30.0


def _progress_bar(description: str, *fields: str):
    """A rich progress bar with elapsed and estimated remaining time, on stderr; a line every
    $DECCO_LOG_EVERY seconds instead when stderr is not a terminal."""
    import os
    import time

    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    class LoggedProgress(Progress):
        """The bar's line printed whole at most every ``every`` seconds (and at the end by rich)."""

        every = float(os.environ.get("DECCO_LOG_EVERY") or LOG_EVERY_DEFAULT)
        _last_line = time.monotonic()

        def update(self, task_id, **changes):
            super().update(task_id, **changes)
            if time.monotonic() - self._last_line >= self.every:
                self._last_line = time.monotonic()
                with self._lock:
                    task = self._tasks[task_id]
                self.console.print(self.make_tasks_table([task]), soft_wrap=True)

    console = Console(stderr=True)
    columns = [TextColumn("[bold]{task.description}")] + ([BarColumn()] if console.is_terminal else [])
    columns += [TextColumn(f"{{task.fields[{name}]}}") for name in fields]
    columns += [TimeElapsedColumn(), TextColumn("eta"), TimeRemainingColumn()]
    kind = Progress if console.is_terminal else LoggedProgress
    return kind(*columns, console=console, transient=False)


# --- pile ------------------------------------------------------------------------------


def _floats(text: str, what: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        fail(f"{what} must be comma-separated numbers; got {text!r}")
    if not values:
        fail(f"{what} must list at least one number")
    return values


PILE_DEFAULTS = pile_defaults()


@app.command()
def pile(
    context: typer.Context,
    out: Path = typer.Option(..., "--out", "-o", help="Pile file to write (HDF5)."),
    particles: int = typer.Option(PILE_DEFAULTS["particles"], "--particles", "-n", help="Number of particles."),
    seed: int = typer.Option(PILE_DEFAULTS["seed"], "--seed", help="Random seed: the same seed gives the same pile."),
    radii: str = typer.Option(PILE_DEFAULTS["radii"], "--radii", help="Particle radii of the size classes [cm], equal mass per size."),
    size_distribution: Optional[str] = typer.Option(
        PILE_DEFAULTS["size_distribution"], "--size-distribution",
        help="Radii drawn from a power law instead of --radii: power:q=Q:r_min=R_MIN:r_max=R_MAX[:classes=K] (dN/dR ~ R^q, radii in cm; K size classes of equal width in log R, default 3), e.g. power:q=-3.5:r_min=5e5:r_max=2.5e6.",
    ),
    density: float = typer.Option(PILE_DEFAULTS["density"], "--density", help="Particle density [g/cm^3]."),
    ke_threshold: float = typer.Option(PILE_DEFAULTS["ke_threshold"], "--ke-threshold", help="Stop when kinetic energy < this x |U|."),
    fill: float = typer.Option(PILE_DEFAULTS["fill"], "--fill", help="Volume fraction of the seeding sphere."),
    max_steps: int = typer.Option(PILE_DEFAULTS["max_steps"], "--max-steps", help="Give up after this many steps."),
    k_in: float = typer.Option(PILE_DEFAULTS["k_in"], "--k-in", help="Spring constant while approaching [dyne/cm]."),
    restitution: float = typer.Option(PILE_DEFAULTS["restitution"], "--restitution", help="Coefficient of restitution."),
    mu_k: float = typer.Option(PILE_DEFAULTS["mu_k"], "--mu-k", help="Sliding friction coefficient."),
    mu_r: float = typer.Option(PILE_DEFAULTS["mu_r"], "--mu-r", help="Rolling friction coefficient."),
    dt: float = typer.Option(PILE_DEFAULTS["dt"], "--dt", help="Time step [s]."),
    precision: str = typer.Option(PILE_DEFAULTS["precision"], "--precision", help="mixed or float64."),
    gravity: str = typer.Option(PILE_DEFAULTS["gravity"], "--gravity", help="all-pairs, tree, or auto: the tree from the size where it is the faster on this device (scheme.TREE_FROM)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing pile file."),
    check: bool = typer.Option(False, "--check", help="Check the inputs and estimate the steps and wall time of the formation, form nothing."),
    from_ss: Optional[Path] = typer.Option(
        None, "--from", help="Make the pile from a pkdgrav .ss file (standard or reduced, pkdgrav's units) instead of forming one: centred, its bulk motion and spin removed, checked as every pile file."
    ),
    device: Optional[str] = DeviceOption,
) -> None:
    """Build a rubble pile: seed spheres without overlaps, collapse under gravity until settled (or take one from a pkdgrav .ss file)."""
    if from_ss is not None:
        given = {name: context.get_parameter_source(name) for name in PILE_DEFAULTS}
        forming = [f"--{name.replace('_', '-')}" for name, source in given.items() if source is not None and source.name == "COMMANDLINE"]
        if forming:
            fail(f"--from takes the pile as the file holds it: {', '.join(forming)} {'does' if len(forming) == 1 else 'do'} not apply")
        _pile_from_ss(from_ss, out, overwrite, check)
        return
    radii_given = context.get_parameter_source("radii")
    if size_distribution is not None and radii_given is not None and radii_given.name == "COMMANDLINE":
        fail("give --radii or --size-distribution, not both")
    _form_pile(
        out, overwrite, check, device, particles=particles, seed=seed, radii=radii, density=density, ke_threshold=ke_threshold,
        fill=fill, max_steps=max_steps, k_in=k_in, restitution=restitution, mu_k=mu_k, mu_r=mu_r, dt=dt, precision=precision, gravity=gravity,
        size_distribution=size_distribution,
    )  # fmt: skip


def _form_pile(
    out: Path, overwrite: bool, check: bool, device: Optional[str], *, particles: int, seed: int, radii: str, density: float,
    ke_threshold: float, fill: float, max_steps: int, k_in: float, restitution: float, mu_k: float, mu_r: float, dt: float,
    precision: str, gravity: str, size_distribution: Optional[str] = None,
) -> None:  # fmt: skip
    """``decco-warp pile``'s work, also that of each pile of ``decco-warp piles``: exits as the command would."""
    from .checks import check_destination
    from .forming import TYPICAL_FORMATION_STEPS, FormationStopped, form_pile_file, partial_path, plan_pile
    from .pile import FormationError

    if out.exists() and not overwrite and not check:
        fail(f"{out} already exists; use --overwrite to replace it")
    try:
        if not check:
            check_destination(out, "pile file")
        plan = plan_pile(
            out, particles=particles, seed=seed, radii=_floats(radii, "--radii"), density=density, ke_threshold=ke_threshold, fill=fill,
            max_steps=max_steps, k_in=k_in, restitution=restitution, mu_k=mu_k, mu_r=mu_r, dt=dt, precision=precision, gravity=gravity,
            device=device, size_distribution=size_distribution,
        )  # fmt: skip
    except ValueError as error:  # bad input: each input error of errors.py is a ValueError, as are Params' checks
        fail(str(error))
    gravity, chosen = plan.gravity, plan.device
    if check:
        from .costs import formation_cost

        typer.echo(f"pile: {particles} particles, density {density:g} g/cm^3, seed {seed}, {gravity} gravity on {chosen}")
        for line in plan.grain_lines():
            typer.echo(line)
        typer.echo(f"cost: {formation_cost(particles, density, fill, dt, gravity, chosen)}; gives up at {max_steps} steps")
    refusal = plan.refusal()
    if refusal:
        fail(refusal)
    if check:
        typer.echo(f"verdict: would form {out}" + (" (replacing it)" if out.exists() else ""))
        return
    if plan.note:
        typer.echo(f"{plan.note} (a pile takes ~{TYPICAL_FORMATION_STEPS:.0e} steps to settle)", err=True)
    typer.echo(f"forming a {particles}-particle pile on {chosen} (seed {seed}, {gravity} gravity)", err=True)
    bar = _progress_bar("forming", "step", "ratio")
    with bar:
        task = bar.add_task("collapse", total=1.0, step="", ratio="")

        def show(p):
            bar.update(
                task,
                completed=p.fraction_done,
                step=f"step {p.step}",
                ratio=f"KE/|U| {p.ke_over_u:.2e} (stop < {p.threshold:.0e})",
                description="settling" if p.peak_ke_over_u >= 1e-3 else "collapsing",
            )

        def resumed(step):
            bar.console.print(f"continuing the formation saved in {partial_path(out)} at step {step}", soft_wrap=True, highlight=False)

        failed = None  # reported after the bar's last line
        timing = []
        try:
            formed = form_pile_file(out, progress=show, on_resume=resumed, on_done=timing.append, **plan.options())
        except ValueError as error:
            failed = (str(error), EXIT_INPUT)
        except FormationError as error:
            failed = (f"{error}; saved in {partial_path(out)}: the same command with a larger --max-steps continues", error.exit_code)
        except FormationStopped as error:
            failed = (str(error), EXIT_STOPPED)
        except OSError as error:  # a full disk, say: the last checkpoint (if any) is intact
            failed = error
    if isinstance(failed, OSError):
        partial = partial_path(out)
        kept = (
            f"the formation saved in {partial} is kept: free space, then the same command continues it"
            if partial.is_file()
            else f"nothing of {out} is kept: free space, then run the same command again"
        )
        write_failed(failed, kept)
    if failed:
        fail(*failed)
    from .collision import pile_radius

    meta = formed.metadata
    typer.echo(
        f"wrote {out}: {formed.n} particles ({_size_classes(formed)}), "
        f"mass {formed.total_mass:.4g} g, radius {pile_radius(formed) / 1e5:.4g} km, U {meta['potential']:.4g} erg; "
        f"{meta['formation_steps']} steps ({meta['formation_time']:.4g} s simulated) in "
        f"{meta['formation_wall_seconds']:.1f} s (this session: {timing[0]})"
    )


def _pile_from_ss(source: Path, out: Path, overwrite: bool, check: bool) -> None:
    """``decco-warp pile --from FILE.ss``: the pile of a pkdgrav file, checked, written as a pile file."""
    import numpy as np

    from .checks import check_destination
    from .collision import pile_radius
    from .interchange import pile_from_ss
    from .io import save_pile

    if out.exists() and not overwrite and not check:
        fail(f"{out} already exists; use --overwrite to replace it")
    try:
        if not check:
            check_destination(out, "pile file")
        pile = pile_from_ss(source)
    except DeccoError as error:
        fail_on(error)
    meta = pile.metadata
    what = (f"{pile.n} particles ({_size_classes(pile)}), mass {pile.total_mass:.4g} g, radius {pile_radius(pile) / 1e5:.4g} km, from {source} "
            f"(pkdgrav {meta['ss_format']} .ss, t = {meta['ss_time']:.6g} s); its bulk velocity {np.linalg.norm(meta['removed_velocity']):.3g} cm/s "
            f"and spin {np.linalg.norm(meta['removed_spin']):.3g} rad/s removed")  # fmt: skip
    if check:
        typer.echo(f"pile: {what}")
        typer.echo(f"verdict: would write {out}" + (" (replacing it)" if out.exists() else ""))
        return
    try:
        save_pile(pile, out)
    except OSError as error:
        write_failed(error, f"{out} is not written (any earlier one is as it was)")
    typer.echo(f"wrote {out}: {what}")


def _size_classes(pile) -> str:
    """A pile's size classes in words, smallest first: '385 of radius 7.5 km, 48 of radius 15 km, ...';
    continuous radii by class: '120 of 5 to 8.55 km, 40 of 8.56 to 14.6 km, ...'."""
    from .sizes import MAX_DISCRETE_SIZES, class_ranges, distinct_sizes

    if distinct_sizes(pile.radii).size <= MAX_DISCRETE_SIZES:
        import numpy as np

        radii, counts = np.unique(pile.radii, return_counts=True)
        return ", ".join(f"{int(c)} of radius {r / 1e5:g} km" for c, r in zip(counts, radii))
    ranges = class_ranges(pile.radii, pile.size_class)
    return ", ".join(f"{int(c)} of {low / 1e5:.3g} to {high / 1e5:.3g} km" for c, low, high in zip(ranges["count"], ranges["radius_min"], ranges["radius_max"]))


# --- simulate, resume ----------------------------------------------------------------------


def _spin_option(text: Optional[str], which: str) -> dict:
    if text is None:
        return {}
    fraction, _, axis = text.partition(",")
    try:
        values = {f"{which}_spin": float(fraction)}
    except ValueError:
        fail(f"--spin-{which} must be FRACTION[,AXIS], e.g. 0.5,+z; got {text!r}")
    if axis:
        axis = axis.strip()
        if "," in axis:  # a vector: FRACTION,X,Y,Z
            try:
                axis = [float(c) for c in axis.split(",")]
            except ValueError:
                fail(f"--spin-{which} must be FRACTION[,AXIS] with AXIS one of +-x, +-y, +-z or X,Y,Z; got {text!r}")
        values[f"{which}_spin_axis"] = axis
    return values


RerunOption = typer.Option(
    None, "--rerun", help="Stream to rerun: spawn (local viewer), save (recording.rrd), connect[=ADDR], serve (web viewer)."
)
RerunEveryOption = typer.Option(None, "--rerun-every", help="Steps between rerun frames (default: --output-every).")


def _rerun_observer(prepared, mode_text: str | None, every: int | None):
    """A RerunLogger watching the run, or None; exits with code 2 on a bad mode or a missing rerun."""
    if mode_text is None:
        return None, []
    from .io import read_frame
    from .viz import RerunLogger, RerunUnavailable, parse_mode

    try:
        mode, address = parse_mode(mode_text)
        every = every or prepared.plan.outputs.output_every
        outer = prepared.plan.scheme.step_multiple
        if every < 1 or every % outer:
            raise ValueError(f"--rerun-every must be a multiple of [params] gravity_every = {outer} (>= 1); got {every}")
        if prepared.resume:
            first_particles, first_observables, static = read_frame(RunFolder(prepared.run_dir).trajectory, 0)
        else:
            state = prepared.plan.state
            static = {"radius": state.radii, "mass": state.masses, "species": state.size_class, "pile_id": state.pile_id}
        logger = RerunLogger(mode, address, prepared.run_dir, static, name=prepared.run_dir.name)
        if prepared.resume:  # drifts are measured from the run's first frame, not from the restart
            logger.set_reference(first_particles, first_observables)
    except (ValueError, RerunUnavailable) as error:
        fail_on(error)
    if logger.url:
        typer.echo(f"rerun: serving {logger.url}; open the printed web viewer address, or: rerun --connect {logger.url}")
    return logger, [(every, logger.log_frame)]


def _run_with_progress(prepare, *args, rerun: str | None = None, rerun_every: int | None = None, **kwargs):
    """Prepare a run (every input problem exits with code 2, nothing written), then run it with a
    progress bar; (its RunResult, the rerun recording it wrote or None)."""
    from .run import execute
    from .stability import StabilityError

    try:
        prepared = prepare(*args, **kwargs)
    except StabilityError as error:
        fail(f"{error}; set allow_unstable = true in [run] to run it anyway")
    except ValueError as error:  # bad input: each input error of errors.py is a ValueError, as are Params' checks
        fail(str(error))
    if prepared.note:
        typer.echo(prepared.note, err=True)
    logger, observers = _rerun_observer(prepared, rerun, rerun_every)
    finished = False
    bar = _progress_bar("simulating", "step", "time", "overlap")
    try:
        with bar:
            task = bar.add_task("run", total=None, step="", time="", overlap="")

            def show(p):
                if p.warning:
                    bar.console.print(f"[yellow]{p.warning}[/yellow]")
                style = "yellow" if p.deepest_overlap > 0.5 else "default"
                bar.update(
                    task,
                    total=p.total_steps - p.first_step,
                    completed=p.step - p.first_step,
                    step=f"step {p.step}/{p.total_steps}",
                    time=f"t {p.time:.0f} s",
                    overlap=f"[{style}]deepest overlap {p.deepest_overlap:.2f}[/{style}]",
                )

            # The run's outcome is reported after the bar's last line, so that it ends the output.
            try:
                result = execute(prepared, progress=show, observers=observers)
                finished, stopped_by = True, None
            except DeccoError as error:  # a stop, a blow-up, a failed write, a lock taken: each its own end
                stopped_by = error
        if stopped_by is not None:
            fail_on(stopped_by)
    finally:
        recording = None
        if logger is not None:
            try:
                logger.close()
            except OSError as error:
                write_failed(error, f"the run folder is as the run left it; {logger.path} is not written")
            recording = getattr(logger, "path", None)
            if recording and not finished:  # a finished run lists it with its outputs
                typer.echo(f"rerun recording: {recording} (view it with: rerun {recording})")
    return result, recording


def _report(outcome) -> None:
    """The end of simulate and resume: the run's totals and this session's, and what it wrote
    (``outcome``: :func:`_run_with_progress`'s)."""
    result, recording = outcome
    run_dir = result.run_dir
    # The run's totals and this session's costs apart: after a resume they are not the same steps.
    typer.echo(
        f"done: the run is at step {result.steps} ({result.time:.6g} s simulated); this session stepped "
        f"{result.steps_this_session} steps in {result.session_wall_seconds:.1f} s wall, {result.session_stepping_seconds:.1f} s of it stepping"
        + (f" ({result.wall_seconds:.1f} s wall over all the run's sessions)" if result.steps_this_session < result.steps else "")
    )
    recorded = ""
    if recording is not None:
        inside = Path(recording).parent.resolve() == Path(run_dir).resolve()
        recorded = f", {Path(recording).name if inside else recording} (rerun's recording: rerun {recording})"
    typer.echo(f"outputs in {run_dir}/: spec.toml, trajectory.h5 (H5MD), trajectory.xdmf (for ParaView, VisIt), checkpoint.h5, run.log{recorded}")
    typer.echo(f"inspect: h5ls -r {run_dir}/trajectory.h5   |   python: decco_warp.io.read_trajectory('{run_dir}/trajectory.h5')")


@app.command()
def simulate(
    config: Optional[Path] = typer.Argument(None, help="Run specification (TOML); default: the shipped demo collision."),
    name: Optional[str] = typer.Option(None, "--name", help="Run name: the folder under --out."),
    target: Optional[str] = typer.Option(None, "--target", help="Target pile file (or builtin:target)."),
    projectile: Optional[str] = typer.Option(None, "--projectile", help="Projectile pile file (or builtin:projectile)."),
    eta: Optional[float] = typer.Option(None, "--eta", help="KE / |U| of the collision (paper eq. 18)."),
    speed: Optional[float] = typer.Option(None, "--speed", help="Relative speed [cm/s] instead of --eta."),
    eta_potential: Optional[str] = typer.Option(
        None, "--eta-potential", help="U of eta: self (each pile's own pairs, the default) or all (every pair of both piles, the cross term included)."
    ),
    theta: Optional[float] = typer.Option(None, "--theta", help="Impact angle [degrees]."),
    gap: Optional[float] = typer.Option(None, "--gap", help="Initial surface gap along x [cm]."),
    spin_target: Optional[str] = typer.Option(None, "--spin-target", help="FRACTION[,AXIS] of breakup spin, e.g. 0.5,+z or 0.5,1,0,1 (a vector)."),
    spin_projectile: Optional[str] = typer.Option(None, "--spin-projectile", help="FRACTION[,AXIS] of breakup spin."),
    orientation_seed: Optional[int] = typer.Option(
        None, "--orientation-seed", help="Turn each pile by a random rotation drawn from this seed (a realization of the collision)."
    ),
    steps: Optional[int] = typer.Option(None, "--steps", help="Steps to run."),
    duration: Optional[float] = typer.Option(None, "--duration", help="Simulated time to run [s], instead of --steps."),
    dt: Optional[str] = typer.Option(None, "--dt", help='Time step [s], or "auto" (eq. 17 for k_in).'),
    k_in: Optional[str] = typer.Option(
        None, "--k-in", help='Spring constant while approaching [dyne/cm], or "auto" (from the impact speed, eq. 12).'
    ),
    restitution: Optional[float] = typer.Option(None, "--restitution", help=f"Coefficient of restitution, {PHYSICS_RANGES['restitution'].words}."),
    mu_k: Optional[float] = typer.Option(None, "--mu-k", help=f"Sliding friction coefficient, {PHYSICS_RANGES['mu_k'].words}."),
    mu_r: Optional[float] = typer.Option(None, "--mu-r", help=f"Rolling friction coefficient, {PHYSICS_RANGES['mu_r'].words}."),
    max_overlap: Optional[float] = typer.Option(
        None, "--max-overlap", help="Stop the run when a contact is deeper than this fraction of the smaller radius."
    ),
    gravity: Optional[str] = typer.Option(
        None, "--gravity", help="all-pairs (exact), tree (O(N log N), for large piles) or auto (by size and device)."
    ),
    gravity_every: Optional[str] = typer.Option(
        None, "--gravity-every", help=f"K: gravity evaluated every K steps, the contacts every step (docs/model.md, \"Gravity on its own clock\"); 1 is the paper's scheme; auto is gravity every {GRAVITY_INTERVAL_AUTO:g} s, the K nearest {GRAVITY_INTERVAL_AUTO:g} s / dt ({auto_gravity_every(0.04)} at the paper's dt of 0.04 s; with --dt auto, chosen with that dt). Step counts must then be multiples of K."
    ),
    contact_law: Optional[str] = typer.Option(
        None, "--contact-law", help="paper (the paper's law as docs/model.md states it), decco-code (DECCO's pair forces as its code computes them) or ssdem (pkdgrav's soft-sphere law: a tangential spring per contact, static friction, rolling and twisting springs)."
    ),
    mu_s: Optional[float] = typer.Option(None, "--mu-s", help=f"ssdem: static friction coefficient (the tangential spring's cap), {PHYSICS_RANGES['mu_s'].words}."),
    mu_t: Optional[float] = typer.Option(None, "--mu-t", help=f"ssdem: twisting friction coefficient, {PHYSICS_RANGES['mu_t'].words}."),
    beta: Optional[float] = typer.Option(None, "--beta", help=f"ssdem: shape parameter, the rolling and twisting radius over R*, {PHYSICS_RANGES['beta'].words}."),
    eps_t: Optional[float] = typer.Option(None, "--eps-t", help=f"ssdem: tangential damping as a restitution, {PHYSICS_RANGES['eps_t'].words} (1: none)."),
    k_t_ratio: Optional[float] = typer.Option(None, "--k-t-ratio", help=f"ssdem: k_t / k_n, {PHYSICS_RANGES['k_t_ratio'].words} (default 2/7)."),
    cohesion: Optional[float] = typer.Option(None, "--cohesion", help=f"ssdem: cohesive strength, a tensile stress [dyne/cm^2], {PHYSICS_RANGES['cohesion'].words} (0: none)."),
    check: bool = typer.Option(False, "--check", help="Set up the collision, print its margins and predicted deepest overlap, run nothing."),
    output_every: Optional[int] = typer.Option(None, "--output-every", help="Steps between trajectory frames."),
    checkpoint_every: Optional[int] = typer.Option(None, "--checkpoint-every", help="Steps between checkpoints."),
    precision: Optional[str] = typer.Option(None, "--precision", help="mixed or float64."),
    layout: Optional[str] = typer.Option(
        None, "--layout", help="Force kernel layout: auto (the device's default) or newton (each pair once, the CUDA default, on any device)."
    ),
    out: Optional[str] = typer.Option(None, "--out", help="Parent folder of run folders (default runs/out)."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing run folder."),
    rerun: Optional[str] = RerunOption,
    rerun_every: Optional[int] = RerunEveryOption,
    device: Optional[str] = DeviceOption,
) -> None:
    """Run a collision: the shipped demo, a TOML specification, and/or options (options win)."""
    from . import spec as specs
    from .run import prepare_start

    try:
        raw = specs.load_spec_file(config) if config is not None else {}
        if steps is not None and duration is not None:
            raise specs.SpecError("give --steps or --duration, not both")
        run_overrides = {"name": name, "output_every": output_every, "checkpoint_every": checkpoint_every}
        run_overrides.update(precision=precision, layout=layout, out=out, device=device, max_overlap=max_overlap)
        if steps is not None or duration is not None:  # a command-line length replaces the file's
            raw.get("run", {}).pop("steps", None)
            raw.get("run", {}).pop("duration", None)
            run_overrides.update(steps=steps, duration=duration)
        collision = {"theta_deg": theta, "gap": gap, "orientation_seed": orientation_seed, "eta_potential": eta_potential}
        collision.update(**_spin_option(spin_target, "target"), **_spin_option(spin_projectile, "projectile"))
        if eta is not None or speed is not None:
            raw.get("collision", {}).pop("eta", None)
            raw.get("collision", {}).pop("speed", None)
            collision.update(eta=eta, speed=speed)
        overrides = {
            "run": run_overrides,
            "piles": {"target": target, "projectile": projectile},
            "collision": collision,
            "params": {"dt": _number_or_auto(dt, "--dt"), "k_in": _number_or_auto(k_in, "--k-in"), "gravity": gravity,
                       "gravity_every": _integer_or_auto(gravity_every, "--gravity-every"), "contact_law": contact_law,
                       "restitution": restitution, "mu_k": mu_k, "mu_r": mu_r, "mu_s": mu_s, "mu_t": mu_t, "beta": beta,
                       "eps_t": eps_t, "k_t_ratio": k_t_ratio, "cohesion": cohesion},
        }
        spec = specs.resolve_spec(raw, overrides)
    except specs.SpecError as error:
        fail(str(error))
    if check:
        _check(spec)
        return
    result = _run_with_progress(prepare_start, spec, overwrite=overwrite, rerun=rerun, rerun_every=rerun_every)
    _report(result)


def _number_or_auto(text: Optional[str], option: str):
    """An option that takes a number or "auto"; None when not given."""
    if text is None:
        return None
    if text.strip() == "auto":
        return "auto"
    try:
        return float(text)
    except ValueError:
        fail(f'{option} must be a number or "auto"; got {text!r}')


def _integer_or_auto(text: Optional[str], option: str):
    """An option that takes an integer or "auto"; None when not given (the specification checks its range)."""
    if text is None or text.strip() == "auto":
        return None if text is None else "auto"
    try:
        return int(text)
    except ValueError:
        fail(f'{option} must be an integer or "auto"; got {text!r}')


def _check(spec: dict) -> None:
    """``simulate --check``: the run's plan (its set-up, margins, predicted deepest overlap and resolved choices); exit 2 if it would be refused."""
    from .costs import cost_note, run_cost
    from .plan import plan_start

    try:
        plan = plan_start(spec)
    except ValueError as error:  # bad input: each input error of errors.py is a ValueError, as are Params' checks
        fail(str(error))
    for line in [*plan.lines(), *plan.choices()]:
        typer.echo(line)
    typer.echo(f"cost: {run_cost(plan.state.n, plan.scheme, plan.device, plan.steps)}")
    note = cost_note(plan.scheme)
    if note:
        typer.echo(note)
    if plan.run_dir.exists():
        typer.echo(f"note: run folder {plan.run_dir} exists (resume continues it, --overwrite replaces it)")
    if not plan.stability.stable and not plan.allow_unstable:
        fail(f"unstable set-up: {'; '.join(plan.stability.problems())}; set allow_unstable = true in [run] to run it anyway")
    depth = plan.forecast.fraction
    verdict = "would run"
    if depth > 1:
        verdict += "; contacts may pass a centre into the other sphere, outside the model's validity (k_in = \"auto\" keeps them shallow)"
    elif depth > 0.5:
        verdict += "; contacts deeper than half the smaller radius are possible (the prediction is an upper estimate) and would be warned about"
    typer.echo(f"verdict: {verdict}")


@app.command()
def resume(
    run_dir: Path = typer.Argument(..., help="Run folder to continue."),
    steps: Optional[int] = typer.Option(None, "--steps", help="New total number of steps (to extend a run)."),
    until_settled: bool = typer.Option(
        False, "--until-settled", help="Extend the run until its outcome is settled (docs/model.md), at most to --max-steps."
    ),
    max_steps: Optional[int] = typer.Option(
        None, "--max-steps", help="With --until-settled: the most steps the run may reach (default: 4 times its steps now)."
    ),
    min_members: Optional[int] = typer.Option(
        None, "--min-members", help="With --until-settled: smallest cluster, as for analyze (default: the run's own, else 50)."
    ),
    rerun: Optional[str] = RerunOption,
    rerun_every: Optional[int] = RerunEveryOption,
    device: Optional[str] = DeviceOption,
) -> None:
    """Continue a stopped or killed run from its last checkpoint (or extend it, with --steps or --until-settled)."""
    from .run import prepare_resume, resume_until_settled

    if not until_settled:
        if max_steps is not None:
            fail("--max-steps goes with --until-settled")
        result = _run_with_progress(prepare_resume, run_dir, steps=steps, device=device, rerun=rerun, rerun_every=rerun_every)
        _report(result)
        return
    if steps is not None:
        fail("give --steps or --until-settled, not both")
    if min_members is not None and min_members < 1 or (max_steps is not None and max_steps < 1):
        fail("--min-members and --max-steps must be >= 1")
    if min_members is None:  # the run's own: what it was analysed or swept with
        min_members = RunFolder(run_dir).min_members()

    def advance(total: int | None) -> None:
        _report(_run_with_progress(prepare_resume, run_dir, steps=total, device=device, rerun=rerun, rerun_every=rerun_every))

    try:
        resume_until_settled(run_dir, advance, max_steps, min_members, device, say=typer.echo)
    except DeccoError as error:
        fail_on(error)


# --- bench -------------------------------------------------------------------------------


def _integer_list(text: str) -> list[int]:
    """A comma-separated list of integers (empty: none); [0] for one that is not, which every caller refuses."""
    try:
        return [int(v) for v in filter(None, (part.strip() for part in text.split(",")))]
    except ValueError:
        return [0]


@app.command()
def bench(
    n: str = typer.Option("", "--n", help="Comma-separated particle counts (default: 2048,10240,65536,131072 on CUDA; 256,1024 on CPU)."),
    steps: int = typer.Option(100, "--steps", help="Steps per timed call of the full step (one CUDA graph replay per 50)."),
    budget: float = typer.Option(1.0, "--seconds", help="Seconds of timing per measurement."),
    precision: str = typer.Option("mixed", "--precision", help="mixed or float64."),
    layouts: str = typer.Option(
        "", "--layouts", help="Also time these layouts, BLOCK_DIM:PER_BLOCK[:SLOTS[:MAX_REGISTERS]][:newton][:unfused],... (e.g. 128:1,128:4:4:96,32:128:newton,32:64:newton:unfused; newton: each pair once, a warp meeting two tiles of PER_BLOCK; unfused: each step's kicks and packing in launches of their own, as before they were fused)."
    ),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the table as JSON here."),
    gravity: str = typer.Option("all-pairs", "--gravity", help="Gravity solvers to time, side by side: all-pairs, tree or all-pairs,tree."),
    ensemble: str = typer.Option(
        "", "--ensemble", help="Also time ensembles of this many systems of N stepped together, e.g. 2,4,8 (aggregate pairs/s, against one at a time)."
    ),
    system: str = typer.Option(
        "lattice", "--system", help="Test systems, side by side: lattice (equal spheres, 6 contacts each), piles (copies of the shipped pile: the paper's radii, up to ~27 contacts) or lattice,piles."
    ),
    gravity_every: str = typer.Option(
        "", "--gravity-every", help="Also time gravity on its own clock at these K, e.g. 5,10,20 (gravity every K steps, contacts from a neighbour list), against the K = 1 step of the same call; 1 in the list is the default row."
    ),
    particle_blocks: str = typer.Option(
        "", "--particle-blocks", help="Also time the step with these threads a block for the kernels of one thread a particle (kicks, drift, gather, list build), e.g. 32,64, at K = 1 and each --gravity-every K, against the default (decco_warp.layouts.PARTICLE_BLOCK); the motion is the same at any."
    ),
    contact_law: str = typer.Option(
        "paper", "--contact-law", help="Contact laws to time, each with its default constants, e.g. paper,ssdem: every row of each law after the first against the first's."
    ),
    device: Optional[str] = DeviceOption,
) -> None:
    """Pairs/s of the force kernel and of the full step, beside a one-thread-per-particle baseline."""
    import math

    import warp as wp

    from . import bench as benchmarks
    from .checks import check_destination
    from .device import resolve_device
    from .scheme import PRECISIONS
    from .layouts import parse_layout
    from .params import CONTACT_LAWS
    from .scheme import GRAVITY_SOLVERS

    try:
        chosen = resolve_device(device)
        if json_out is not None:
            check_destination(json_out, "benchmark table")
    except DeccoError as error:
        fail_on(error)
    if precision not in PRECISIONS:
        fail(f"--precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
    solvers = [g.strip() for g in gravity.split(",") if g.strip()]
    if not solvers or any(g not in GRAVITY_SOLVERS for g in solvers):
        fail(f"--gravity must list {' and/or '.join(GRAVITY_SOLVERS)}; got {gravity!r}")
    ensembles = _integer_list(ensemble)
    if any(k < 2 for k in ensembles):
        fail(f"--ensemble must list system counts >= 2, e.g. 2,4,8; got {ensemble!r}")
    clocks = _integer_list(gravity_every)
    if any(k < 1 for k in clocks):
        fail(f"--gravity-every must list integers >= 1, e.g. 5,10,20; got {gravity_every!r}")
    clocks = [k for k in dict.fromkeys(clocks) if k > 1]
    blocks = _integer_list(particle_blocks)
    if any(b < 1 or b > 1024 for b in blocks):
        fail(f"--particle-blocks must list threads a block from 1 to 1024, e.g. 32,64; got {particle_blocks!r}")
    laws = list(dict.fromkeys(law.strip() for law in contact_law.split(",") if law.strip()))
    if not laws or any(law not in CONTACT_LAWS for law in laws):
        fail(f"--contact-law must list {', '.join(CONTACT_LAWS)}; got {contact_law!r}")
    kinds = [k.strip() for k in system.split(",") if k.strip()]
    if not kinds or any(k not in benchmarks.TEST_SYSTEMS for k in kinds):
        fail(f"--system must list {' and/or '.join(benchmarks.TEST_SYSTEMS)}; got {system!r}")
    default_sizes = "2048,10240,65536,131072" if chosen.startswith("cuda") else "256,1024"
    sizes = [int(v) for v in _floats(n or default_sizes, "--n")]
    if any(v < 2 for v in sizes) or steps < 1 or budget <= 0:
        fail("--n values must be >= 2, --steps >= 1 and --seconds > 0")
    try:
        extra_layouts = [parse_layout(item, chosen) for item in filter(None, (part.strip() for part in layouts.split(",")))]
    except ValueError as error:
        fail(str(error))
    limit, how = benchmarks.device_limit_pairs_per_s(chosen)
    d = wp.get_device(chosen)
    typer.echo(f"device: {chosen} ({d.name}), warp-lang {wp.config.version}, precision {precision}")
    typer.echo(f"limit: {how}" + (f" -> {limit:.3g} pairs/s" if limit else ""))
    typer.echo("pairs/s: N^2 a step (what an every-step all-pairs code needs); of limit: the gravity pairs evaluated, N^2 / K a step at gravity every K")
    header = f"{'N':>8} {'force pairs/s':>14} {'step pairs/s':>13} {'step ms':>9} {'particles/s':>12} {'of limit':>9} {'baseline pairs/s':>17} {'speed-up':>9}  layout"
    typer.echo(header)
    rows = []
    for row in benchmarks.bench_rows(sizes, kinds, chosen, precision, budget, steps, solvers, extra_layouts, ensembles, clocks, blocks, laws):
        rows.append(row)
        baseline = not math.isnan(row.baseline_seconds)
        fraction = f"{100 * row.fraction_of_limit:8.1f}%" if row.fraction_of_limit is not None else f"{'n/a':>9}"
        baseline_text = f"{row.baseline_pairs_per_s:17.3g} {row.speedup:8.1f}x" if baseline else f"{'':>17} {'':>9}"
        rates = f"{row.force_pairs_per_s:14.3g} {row.step_pairs_per_s:13.3g}" if row.gravity == "all-pairs" else f"{'-':>14} {'-':>13}"
        typer.echo(
            f"{row.n:>8} {rates} {1e3 * row.step_seconds:9.3f} {row.particles_per_s:12.3g} "
            f"{fraction} {baseline_text}  {row.layout}"
        )
    if json_out is not None:
        from .durable import json_text, write_atomic

        table = {"device": chosen, "device_name": d.name, "warp": wp.config.version, "precision": precision,
                 "limit_pairs_per_s": limit, "limit": how, "rows": [benchmarks.as_dict(r) for r in rows]}  # fmt: skip
        try:
            write_atomic(json_out, json_text(table))
        except OSError as error:
            write_failed(error, f"{json_out} is not written (any earlier one is as it was); the table above is the result")
        typer.echo(f"wrote {json_out}")


# --- analyze -------------------------------------------------------------------------------


@app.command()
def analyze(
    path: Path = typer.Argument(..., help="A run folder (finished or still running), or a folder of run folders (a sweep)."),
    min_members: Optional[int] = typer.Option(
        None, "--min-members", help="Smallest cluster counted (default: what each run was analysed or swept with, else 50 as the paper's Fig. 2)."
    ),
    every: int = typer.Option(1, "--every", help="Analyse every Nth frame (the last one always)."),
    follow: bool = typer.Option(False, "--follow", help="Of a running run: analyse again as new frames arrive, until the run ends."),
    poll: float = typer.Option(10.0, "--poll", help="With --follow: seconds between looks for new frames."),
    device: Optional[str] = typer.Option(
        None, "--device", help="Where the cluster finder's O(N^2) smoothed density is summed: cpu (NumPy, all cores) or cuda[:N] (default: $DECCO_DEVICE, else CUDA if present, else cpu)."
    ),
    workers: Optional[int] = typer.Option(
        None, "--workers", help="Processes that analyse a run's frames side by side, each reading its share of the frames (on a GPU, each with a CUDA context); "
        "the results are the same. Default: one a CPU core ($DECCO_CORES, else every core; at most 16 on a GPU), 1 for a small run. 1: frame by frame in this process."
    ),
) -> None:
    """Fragments, the paper's metrics, conservation and energy of runs: analysis.h5, summary.json, figures.

    A run still being written is analysed as far as its frames go (its writer is never touched)."""
    from .analysis.runs import outcome_text
    from .checks import InputError
    from .device import DeviceError, resolve_device
    from .watch import analyse_runs, check_analysable, find_runs, write_cross_run_results

    if min_members is not None and min_members < 1 or every < 1 or workers is not None and workers < 1 or not poll > 0:
        fail("--min-members, --every and --workers must be >= 1, --poll > 0")
    try:
        device = resolve_device(device)
    except DeviceError as error:
        fail(str(error))
    try:
        runs = find_runs(path)
    except InputError as error:
        fail(str(error))
    if follow and len(runs) > 1:
        fail("--follow follows one run folder")
    try:  # every destination, and no other analysis of these runs, before the first analysis
        check_analysable(path, runs)
    except InputError as error:
        fail(str(error))
    results = []
    failed = None
    bar = _progress_bar("analysing", "frames")
    with bar:

        def frames_of(run_dir: Path):
            task = bar.add_task(run_dir.name, total=None, frames="")
            return lambda done, total: bar.update(task, total=total, completed=done, frames=f"{done}/{total} frames")

        def following(run_dir: Path, step: int) -> None:
            bar.console.print(f"{run_dir}: analysed to step {step}; following the run", soft_wrap=True, highlight=False)

        try:
            runs_analysed = analyse_runs(runs, min_members, every, device, follow=follow, poll=poll, on_run=frames_of, on_follow=following, workers=workers)
            for result in runs_analysed:  # each kept as it comes, so that a failed write can say how many are whole
                results.append(result)
        except DeccoError as error:
            fail_on(error)
        except OSError as error:
            failed = error
    if failed is not None:
        done = f"the analyses of {len(results)} run(s) before it are whole, " if results else ""
        write_failed(failed, f"{done}each output file is whole or absent and the runs are untouched: free space, then decco-warp analyze {path} again")
    for result in results:
        state = f" (still running: the {result.frames} frames written so far, to step {result.summary['steps']})" if result.live else ""
        typer.echo(f"{result.run_dir}: {outcome_text(result.summary)}{state}; analysis.h5, summary.json and figures/ written")
    if len(runs) > 1:
        try:
            write_cross_run_results(path, [result.summary for result in results])
        except OSError as error:
            write_failed(error, f"every run's own analysis is whole; the cross-run files are whole or absent: free space, then decco-warp analyze {path} again")
        typer.echo(f"{path}: summary.csv and cross-run figures in {path / 'figures'}")


# --- extract -------------------------------------------------------------------------------


@app.command()
def extract(
    run_dir: Path = typer.Argument(..., help="An analysed run folder (analysis.h5 and trajectory.h5)."),
    out: Path = typer.Option(..., "--out", "-o", help="Pile file to write (HDF5), for simulate's --target or --projectile."),
    fragment: int = typer.Option(0, "--fragment", help="Which cluster of the last analysed frame: 0 the largest, 1 the next, ..."),
    spin: str = typer.Option("keep", "--spin", help="keep the fragment's rigid spin about its centre, or remove it."),
    settle: bool = typer.Option(True, "--settle/--no-settle", help="Step the fragment alone until its internal motion dies down."),
    ke_threshold: float = typer.Option(1e-5, "--ke-threshold", help="Settled when the kinetic energy about the rigid motion is below this x |U|."),
    max_steps: int = typer.Option(1_000_000, "--max-steps", help="Give up settling after this many steps."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing pile file."),
    device: Optional[str] = DeviceOption,
) -> None:
    """Write a fragment of a finished collision as a pile (centred, settled, its spin kept or removed)
    that simulate takes as a target or a projectile: the next collision of a hierarchy."""
    from .checks import check_destination
    from .device import resolve_device
    from .io import save_pile
    from .remnant import check_options, fragment_of, loose_note, settle_fragment

    if out.exists() and not overwrite:
        fail(f"{out} already exists; use --overwrite to replace it")
    if not run_dir.is_dir():
        fail(missing(run_dir))
    try:  # every input, before the progress bar draws a line
        check_destination(out, "pile file")
        chosen = resolve_device(device)
        check_options(spin, ke_threshold, max_steps)
        state, source = fragment_of(run_dir, fragment)
    except ValueError as error:  # bad input: each input error of errors.py is a ValueError, as are Params' checks
        fail(str(error))
    note = loose_note(state, fragment, settle)
    if note:
        typer.echo(note, err=True)
    bar = _progress_bar("settling", "step", "ratio")
    try:
        with bar:
            task = bar.add_task("fragment", total=None, step="", ratio="")

            def show(step: int, ratio: float) -> None:
                bar.update(task, step=f"step {step}", ratio=f"internal KE/|U| {ratio:.3g} (settled < {ke_threshold:g})")

            remnant = settle_fragment(state, source, spin=spin, settle=settle, ke_threshold=ke_threshold,
                                      max_steps=max_steps, device=chosen, progress=show)  # fmt: skip
    except ValueError as error:  # a fragment that did not settle within --max-steps
        fail(str(error))
    try:
        save_pile(remnant, out)
    except OSError as error:
        write_failed(error, f"{out} is not written (any earlier one is as it was); the run is untouched")
    import numpy as np

    from .collision import pile_radius

    meta = remnant.metadata
    rate = float(np.linalg.norm(meta["spin_vector"]))
    turning = "its spin removed" if spin == "remove" else f"spinning at {rate:.3g} rad/s (a turn in {2 * np.pi / rate / 3600:.3g} h)" if rate > 0 else "not spinning"
    settled = f"settled in {meta['settle_steps']} steps" if settle else "not settled (--no-settle)"
    typer.echo(f"wrote {out}: fragment {fragment} of {run_dir} ({remnant.n} particles: {_size_classes(remnant)}), mass {remnant.total_mass:.4g} g, "
               f"radius {pile_radius(remnant) / 1e5:.4g} km, {turning}, {settled}")  # fmt: skip


# --- compare -------------------------------------------------------------------------------


@app.command()
def compare(
    paths: List[Path] = typer.Argument(..., help="Run folders, folders of run folders (their summary.json), or sweeps' summary.csv files."),
    by: str = typer.Option(..., "--by", help="The column whose groups are compared, e.g. spin_kind; folder: the sweep folder each run was read from."),
    metric: str = typer.Option(..., "--metric", help="The numeric column compared, e.g. largest_mass_ratio [its own units]."),
    at: Optional[str] = typer.Option(None, "--at", help="Compare at each value of this column too, e.g. eta (numbers equal to 6 significant digits are one point)."),
    reference: Optional[str] = typer.Option(
        None, "--reference", help="The group the others are compared with (default: none for spin_kind where present, else the first group in sorted order)."
    ),
    against: Optional[float] = typer.Option(
        None, "--against", metavar="VALUE", help="Compare each group's mean with this value instead of with a group (its interval by Student's t, "
        "or the bootstrap from 30 runs), e.g. --against 0: does the size change differ from none?"
    ),
    confidence: float = typer.Option(
        0.95, "--confidence", metavar="LEVEL", help="Level of every interval and verdict (two-sided). Where several groups meet the reference "
        "at a point, their intervals hold at this level together (Dunnett's test)."
    ),
    per_comparison: bool = typer.Option(
        False, "--per-comparison", help="Give each group's difference to the reference its own interval (Welch's t, or the bootstrap from 30 runs) "
        "instead of Dunnett's simultaneous ones where several groups meet the reference at a point; --confidence 0.983 (1 - 0.05/3) keeps "
        "three of them at 95 % together (Bonferroni)."
    ),
    resolve: Optional[float] = typer.Option(
        None, "--resolve", metavar="DELTA", help="Difference to resolve [the metric's units] (default: each difference seen): the runs per group it needs are "
        "n = 2 (z_0.975 + z_0.8)^2 s^2 / DELTA^2 rounded up (two-sided 5 %, power 0.8; s^2 the mean of the two groups' variances)."
    ),
    where: Optional[List[str]] = typer.Option(
        None, "--where", metavar="COLUMN=VALUE[,VALUE...]",
        help="Keep only the runs with one of these values in COLUMN (repeatable, every column must match; numbers within 1 %), e.g. --where mass_ratio=1 --where eta=3,6."
    ),
    paired: bool = typer.Option(
        False, "--paired", help="Pair each run with its twin in the reference group (the run that agrees in the set-up, eta, the spins, realization, "
        "orientation_seed and the piles, where both record them: all but --by; by folder, its name too, and not a column that each folder holds "
        "one value of, another than the reference's: the law a campaign was rerun under) and give the mean of the twins' differences with Student's t interval on them (pairs - 1 dof), "
        "their count and correlation r; runs without a twin are named and left out, a group of fewer than 2 pairs is refused. One group against "
        "the reference per point, or --per-comparison."
    ),
    allow_mixed: bool = typer.Option(
        False, "--allow-mixed", help="Compare runs at one point that differ in a set-up column (mass_ratio, theta_deg, k_in, dt, gravity_every, eta_potential, n_particles, restitution, mu_k, mu_r, G, rolling_friction, contact_law, k_t_ratio, eps_t, mu_s, mu_t, beta, cohesion) other than --by and --at (by folder, one that each folder holds one value of is what the folders compare, no mix)."
    ),
    allow_single: bool = typer.Option(
        False, "--allow-single", help="Accept groups of one run: shown without spread or interval (without it, the table is printed and the command exits 2 naming them)."
    ),
    json_out: Optional[Path] = typer.Option(None, "--json", help="Write the table as JSON here."),
) -> None:
    """Compare groups of runs: per group (and point), the mean and spread of a metric, and the
    difference to a reference group (or to a value, --against) with its 95 % interval (Welch's t for
    groups under 30 runs, else a seeded bootstrap; Dunnett's simultaneous intervals where several
    groups meet the reference at a point; with --paired, the mean of twin runs' differences), a
    verdict, the smallest difference the runs at hand resolve (detectable, power 0.8) and the runs
    per group a difference needs.  Rows of failed runs are left out."""
    from .analysis.compare import SingleRunGroup, compare as compare_runs, parse_where, read_rows
    from .checks import InputError, check_destination

    try:
        if json_out is not None:
            check_destination(json_out, "comparison table")
        result = compare_runs(read_rows(paths), by, metric, at, reference=reference, resolve=resolve, where=parse_where(where or []),
                              allow_mixed=allow_mixed, allow_single=allow_single, against=against, confidence=confidence,
                              per_comparison=per_comparison, paired=paired)  # fmt: skip
    except SingleRunGroup as error:  # the rest is shown, so that one sees what the runs there give
        for line in error.comparison.lines():
            typer.echo(line)
        fail(str(error))
    except InputError as error:  # CompareError is one
        fail(str(error))
    for line in result.lines():
        typer.echo(line)
    if json_out is not None:
        from .durable import json_text, write_atomic

        try:
            write_atomic(json_out, json_text(result.as_dict()))
        except OSError as error:
            write_failed(error, f"{json_out} is not written (any earlier one is as it was); the table above is the result")
        typer.echo(f"wrote {json_out}")


# --- view --------------------------------------------------------------------------------


@app.command()
def threshold(
    paths: List[Path] = typer.Argument(..., help="Run folders or folders of run folders (their summary.json) of head-on runs at one angle."),
    where: Optional[List[str]] = typer.Option(
        None, "--where", metavar="COLUMN=VALUE[,VALUE...]", help="Keep only the runs with one of these values in COLUMN (repeatable), e.g. --where theta_deg=0."
    ),
    confidence: float = typer.Option(0.95, "--confidence", metavar="LEVEL", help="Level of the intervals (two-sided)."),
    against: Optional[List[Path]] = typer.Option(
        None, "--against", metavar="PATH", help="Also each Q*_RD over that of these runs (folders as PATHS; repeatable), with its interval."
    ),
) -> None:
    """The catastrophic disruption threshold Q*_RD per mass ratio (the Q_R at which the largest
    remnant holds half the total mass, from a line through the runs in LS12's linear regime) with
    its interval, and LS12's c* and mu_bar fitted to the thresholds of two or more mass ratios;
    with --against, each threshold over another set's (friction off over on, R = 4 over R = 1)."""
    from .analysis.compare import parse_where, read_rows, select
    from .analysis.threshold import report, report_ratios, thresholds
    from .checks import InputError

    def found_in(folders):
        rows, _ = select(read_rows(folders), parse_where(where or []))
        rows = [row for row in rows if row.get("status", "ok") in (None, "ok") or str(row.get("status")).startswith("skipped")]
        return thresholds(rows, confidence)

    try:
        if not 0 < confidence < 1:
            raise InputError(f"--confidence must be in (0, 1); got {confidence}")
        found = found_in(paths)
        lines = report(found)
        if against:
            lines += report_ratios(found, found_in(against), " ".join(map(str, against)))
    except InputError as error:  # CompareError is one
        fail(str(error))
    for line in lines:
        typer.echo(line)


@app.command()
def view(
    path: Path = typer.Argument(..., help="A run folder or its trajectory.h5 (finished or still running)."),
    save_to: Optional[Path] = typer.Option(None, "--save", help="Write a .rrd recording here instead of opening a viewer."),
    mode: str = typer.Option("spawn", "--mode", help="Without --save: spawn, connect[=ADDR] or serve."),
) -> None:
    """Replay a run into rerun: a local viewer, a recording (.rrd), or a viewer elsewhere."""
    from .checks import check_destination
    from .durable import WRITE_ERRNOS
    from .viz import RerunUnavailable, parse_mode, replay

    trajectory = RunFolder(path).trajectory if path.is_dir() else path
    if not trajectory.is_file():
        fail(f"{path} does not exist" if not path.exists() else f"{path} is neither a run folder nor a trajectory file")
    try:
        chosen, address = ("save", None) if save_to is not None else parse_mode(mode)
        if chosen == "save" and save_to is None:
            save_to = trajectory.parent / "recording.rrd"
        if save_to is not None:
            check_destination(save_to, "recording")
        bar = _progress_bar("replaying", "frames")
        with bar:
            task = bar.add_task(trajectory.parent.name, total=None, frames="")
            logger = replay(
                trajectory, chosen, address, save_to=save_to,
                progress=lambda done, total: bar.update(task, total=total, completed=done, frames=f"{done}/{total}"),
            )  # fmt: skip
    except OSError as error:
        if error.errno not in WRITE_ERRNOS:
            fail(" ".join(str(error).split()))
        write_failed(error, f"{save_to} is not written (a recording is renamed into place only when whole; any earlier one is as it was)")
    except (ValueError, RerunUnavailable) as error:
        fail_on(error)
    if save_to is not None:
        typer.echo(f"wrote {save_to} (view it with: rerun {save_to})")
    elif logger.url:
        typer.echo(f"rerun: serving {logger.url}")


# --- movie -------------------------------------------------------------------------------


@app.command()
def movie(
    path: Path = typer.Argument(..., help="A run folder (finished, stopped or still running)."),
    out: Optional[Path] = typer.Option(
        None, "--out", "-o", help="The movie: .mp4 (needs ffmpeg; without it a .gif beside it) or .gif (default: RUN/figures/movie.mp4)."
    ),
    every: int = typer.Option(1, "--every", help="Use every Nth frame of the trajectory (the last one always)."),
    fps: int = typer.Option(10, "--fps", help="Frames a second of the movie."),
) -> None:
    """Write a movie of a run without a display: its frames on the impact plane, spheres at true size,
    coloured by cluster where analysed (else by pile)."""
    from .analysis.movie import movie_path, write_movie
    from .checks import check_destination
    from .durable import WRITE_ERRNOS
    from .io import FileFormatError

    if not RunFolder(path).trajectory.is_file():
        fail(missing(path) if not path.exists() else f"{path} is not a run folder with a {RunFolder.TRAJECTORY}")
    if every < 1 or fps < 1:
        fail("--every and --fps must be >= 1")
    out = out if out is not None else RunFolder(path).path / "figures" / "movie.mp4"
    try:
        destination, note = movie_path(out)
        check_destination(destination, "movie")
    except ValueError as error:  # InputError is one
        fail(str(error))
    if note:
        typer.echo(f"note: {note}", err=True)
    bar = _progress_bar("drawing", "frames")
    try:
        with bar:
            task = bar.add_task(path.name, total=None, frames="")
            written, _ = write_movie(path, destination, every=every, fps=fps,
                                     progress=lambda done, total: bar.update(task, total=total, completed=done, frames=f"{done}/{total}"))  # fmt: skip
    except FileFormatError as error:
        fail(str(error))
    except OSError as error:
        if error.errno not in WRITE_ERRNOS:
            fail(" ".join(str(error).split()))
        write_failed(error, f"{destination} is not written (a movie is renamed into place only when whole); the run is untouched")
    typer.echo(f"wrote {written}")


# --- export ------------------------------------------------------------------------------


@app.command()
def export(
    path: Path = typer.Argument(..., help="A run folder or its trajectory.h5 (finished, stopped or still running); with --ss, a pile file too."),
    xdmf: bool = typer.Option(False, "--xdmf", help="Write trajectory.xdmf beside trajectory.h5, for ParaView and VisIt."),
    ss: Optional[Path] = typer.Option(
        None, "--ss", help="Write pkdgrav's .ss here (its units: G = 1, M_sun, AU, yr/2pi): a frame of the run (--frame), every frame into this folder (--frame all), or the pile."
    ),
    reduced: bool = typer.Option(False, "--reduced", help="With --ss: pkdgrav's reduced format (float mass, radius and position; no velocities or spins)."),
    rebound: Optional[Path] = typer.Option(
        None, "--rebound", help="Write an analysed frame's fragments (and the grains of none) as a REBOUND simulation file here, in cgs with sim.G in cgs (needs rebound)."
    ),
    frame: Optional[str] = typer.Option(
        None, "--frame", help="The frame: its index (negative: from the end; default the last, for --rebound the last analysed), or all (--ss only)."
    ),
) -> None:
    """Write a run (or a pile) for other programs: an XDMF description for ParaView and VisIt, pkdgrav
    .ss files, or its fragments as a REBOUND simulation."""
    if not (xdmf or ss or rebound):
        fail("say what to export: --xdmf, --ss FILE or --rebound FILE")
    if frame not in (None, "all"):
        try:
            frame = int(frame)
        except ValueError:
            fail(f"--frame must be a frame's index (negative: from the end) or all; got {frame!r}")
    if frame == "all" and rebound:
        fail("--frame all goes with --ss alone: --rebound writes one frame")
    if reduced and not ss:
        fail("--reduced goes with --ss")
    if not path.exists():
        fail(f"{path} does not exist")
    if xdmf:
        _export_xdmf(path)
    if ss:
        _export_ss(path, ss, frame, reduced)
    if rebound:
        _export_rebound(path, rebound, frame)


def _export_xdmf(path: Path) -> None:
    """``export --xdmf``: trajectory.xdmf beside the run's trajectory."""
    from .checks import check_destination
    from .repair import clear_write_flags
    from .lock import RunFolderBusy
    from .xdmf import write_xdmf

    trajectory = RunFolder(path).trajectory if path.is_dir() else path
    if not trajectory.is_file():
        fail(f"{path} is neither a run folder with a {RunFolder.TRAJECTORY} nor a trajectory file")
    destination = trajectory.with_name(RunFolder.XDMF)
    running = False
    try:
        check_destination(destination, "XDMF file")
        try:  # no run writes it: clear the flags a killed one left (as h5clear -s), which other readers refuse
            with RunFolder(trajectory.parent).lock():
                clear_write_flags(trajectory)
        except RunFolderBusy:
            running = True
        frames = write_xdmf(trajectory, destination)
    except (DeccoError, OSError) as error:  # an unreadable trajectory is bad input here, as a missing one
        fail(" ".join(str(error).split()))
    typer.echo(f"wrote {destination}: {frames} frame(s) of {trajectory.name}, read in place; open it in ParaView or VisIt")
    if running:
        typer.echo(
            "the run is still going: ParaView and VisIt open its trajectory once it ends (while a file is written, HDF5 "
            "admits only SWMR readers), and it then rewrites trajectory.xdmf with every frame"
        )


def _export_ss(path: Path, destination: Path, frame, reduced: bool) -> None:
    """``export --ss``: a frame, every frame or a pile as pkdgrav .ss."""
    from .checks import check_destination
    from .interchange import export_ss, is_pile_file

    try:
        check_destination(destination, "folder of .ss files" if frame == "all" else ".ss file", folder=frame == "all")
        pile = is_pile_file(path)
        written = export_ss(path, destination, frame, reduced)
    except DeccoError as error:
        fail_on(error)
    except OSError as error:
        write_failed(error, "each .ss file written before it is whole")
    kind = "reduced" if reduced else "standard"
    if len(written) > 1:
        typer.echo(f"wrote {len(written)} pkdgrav {kind} .ss files into {destination}, {written[0].path.name} to {written[-1].path.name}")
        return
    one = written[0]
    what = f"the pile {path}" if pile else f"step {one.step} (t = {one.time:.6g} s) of {path}"
    typer.echo(f"wrote {one.path}: {what}, {one.n} particles, pkdgrav {kind} .ss in pkdgrav's units (G = 1; M_sun, AU, yr/2pi: docs/data.md)")


def _export_rebound(path: Path, destination: Path, frame) -> None:
    """``export --rebound``: an analysed frame's fragments as a REBOUND simulation file."""
    from .checks import check_destination
    from .interchange import handoff_bodies, write_rebound

    if not path.is_dir():
        fail(f"--rebound takes a run folder (analysed: its analysis.h5 holds the fragments); {path} is not one")
    try:
        check_destination(destination, "REBOUND file")
        bodies = handoff_bodies(path, frame)
        write_rebound(destination, bodies)
    except DeccoError as error:
        fail_on(error)
    except OSError as error:
        write_failed(error, f"{destination} is not written (any earlier one is as it was)")
    typer.echo(
        f"wrote {destination}: frame {bodies.frame} (step {bodies.step}, t = {bodies.time:.6g} s) of {path}, {bodies.fragments} fragment(s) "
        f"and {bodies.grains} grain(s) of none as REBOUND particles in cgs (sim.G = {bodies.G:g}); open it with rebound.Simulation('{destination}')"
    )


# --- sweep ---------------------------------------------------------------------------------


@app.command()
def sweep(
    spec_file: Path = typer.Argument(..., help="Sweep specification (TOML): a run spec plus [sweep] and [sweep.grid]."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", help="Address of a running Dask scheduler."),
    gpus: Optional[int] = typer.Option(
        None, "--gpus", help="GPUs to use, cuda:0 to cuda:N-1, each with its own worker (default: all visible)."
    ),
    workers: Optional[int] = typer.Option(
        None, "--workers", help="Local workers (default: one per GPU, else 2); more than GPUs share them in turn."
    ),
    analysis_workers: Optional[int] = typer.Option(
        None, "--analysis-workers", help="Processes analysing finished runs here (default: the cores this process may use: $DECCO_CORES, else its CPU affinity)."
    ),
    only: Optional[List[str]] = typer.Option(
        None, "--only", help="Run only the runs whose names match this glob, e.g. '*eta6' (repeatable); complete runs stay in the table."
    ),
    check: bool = typer.Option(
        False, "--check", help="List the runs and where each stands (complete, resumes, to run), each one's margins and cost and the sweep's, then stop."
    ),
    resolution: Optional[float] = typer.Option(
        None, "--resolution", help="Replace [sweep] resolution: R x the particles (piles NAME_xR.h5), k_in and dt x R^(-1/3) unless scale_contacts = false."
    ),
    array: bool = typer.Option(
        False, "--array", help="Write a Slurm job-array script (SWEEP/array/array.sh) of the runs to make, one task per run or ensemble, then stop."
    ),
    task: Optional[List[str]] = typer.Option(
        None, "--task", help="A job array's task: step these runs (by name, repeatable) here without Dask, analyse them, record their rows."
    ),
    collect: bool = typer.Option(
        False, "--collect", help="Gather what a job array's tasks made: analyse what is left, write summary.csv and the figures."
    ),
) -> None:
    """Run a grid of collisions with Dask (skipping finished runs), analysing each as it finishes."""
    from .checks import InputError
    from .device import DeviceError, gpus_to_use
    from .spec import SpecError
    from .sweep import SweepJob, check_lines, load_sweep, select_runs

    modes = [name for name, on in (("--check", check), ("--array", array), ("--task", task), ("--collect", collect)) if on]
    if len(modes) > 1:
        fail(f"{' and '.join(modes)} do different things: give one")
    if modes and modes[0] != "--check" and (scheduler or gpus is not None or workers is not None):
        fail(f"{modes[0]} runs without Dask workers: leave --scheduler, --gpus and --workers out")
    try:
        settings, runs = load_sweep(spec_file, {"resolution": resolution})
        if only:
            runs = select_runs(runs, only)
    except SpecError as error:
        fail(str(error))
    for repeat, original in settings["same_as"].items():
        typer.echo(f"  {repeat} is the same set-up as {original}: run once")
    if check:
        for line in check_lines(settings, runs):
            typer.echo(line)
        return
    if array or task:
        _sweep_array(settings, runs, spec_file, resolution, task)
        return
    if workers is not None and workers < 1 or analysis_workers is not None and analysis_workers < 1:
        fail("--workers and --analysis-workers must be >= 1")
    if gpus is not None and scheduler:
        fail("--gpus pins local workers; with --scheduler each worker uses its own device (its $DECCO_DEVICE)")
    try:
        gpus_to_use(gpus)
    except DeviceError as error:
        fail(str(error))
    job = SweepJob(settings, runs)
    try:
        job.claim()  # one sweep per folder: a second one started is refused
    except InputError as error:
        fail(str(error))
    typer.echo(f"sweep {settings['name']}: {len(runs)} runs {'gathered from its job array in' if collect else 'into'} {job.folder}")
    try:
        if collect:
            _sweep_collected(job, analysis_workers)
        else:
            _sweep_claimed(job, scheduler, workers, analysis_workers, gpus)
    finally:
        job.release()  # however it ends (a Python caller may go on in this process)


def _sweep_array(settings: dict, runs: list, spec_file: Path, resolution: Optional[float], names: Optional[List[str]]) -> None:
    """``sweep --array`` (the job-array script) or ``sweep --task RUN ...`` (one of its tasks)."""
    from .checks import InputError
    from .jobarray import run_task, write_script
    from .run import OUTPUT_FAILURE
    from .spec import SpecError
    from .sweep import AGAIN, finished_line

    try:
        if not names:
            for line in write_script(settings, runs, spec_file, resolution)[1]:
                typer.echo(line)
            return
        rows = run_task(settings, runs, names)
    except (SpecError, InputError) as error:
        fail(str(error))
    except OSError as error:  # a row could not be recorded: the runs' folders are whole
        write_failed(error, f"the runs' folders are whole; {AGAIN}")
    for row in rows:
        typer.echo(finished_line(row))
    stopped = [row["run"] for row in rows if row["status"] == "stopped"]
    if stopped:
        fail(f"task stopped: {', '.join(stopped)} wrote a checkpoint where it stopped; the same task (or the script submitted again) resumes it",
             code=EXIT_STOPPED)  # fmt: skip
    unwritten = [row for row in rows if OUTPUT_FAILURE in row.get("reason", "")]
    if unwritten:
        fail(f"{unwritten[0]['run']}: {unwritten[0]['reason']}; {AGAIN}", EXIT_OUTPUT)


def _sweep_collected(job, analysis_workers) -> None:
    """``sweep --collect`` once its folder is claimed: the tasks' rows gathered and analysed, the record,
    then the table and figures (or, with runs not finished, the table of those that are)."""
    from .jobarray import collect_job
    from .sweep import AGAIN, finished_line

    try:
        missing = collect_job(job, analysis_workers, on_row=lambda row: typer.echo(finished_line(row)))
        job.save_record()
    except OSError as error:
        write_failed(error, f"the runs' folders are whole, and summary.csv whole or absent; {AGAIN}")
    if missing:
        fail(f"{len(missing)} run(s) not finished ({'; '.join(missing)}); summary.csv holds the {len(job.finished)} finished: "
             "submit the array again (decco-warp sweep FILE --array writes it for the runs left), then --collect", code=EXIT_STOPPED)  # fmt: skip
    _sweep_end(job)


def _sweep_claimed(job, scheduler, workers, analysis_workers, gpus) -> None:
    """``sweep`` once its folder is claimed: the runs, the record, the table and figures, the end."""
    from .sweep import AGAIN, finished_line

    bar = _progress_bar("sweep", "runs")
    with bar:
        task = bar.add_task(job.settings["name"], total=len(job.runs), runs="")

        def show() -> None:
            bar.update(task, completed=job.completed, runs=job.progress_text())

        def report(row: dict) -> None:
            bar.console.print(finished_line(row))

        def stopping() -> None:
            note("stopping: each run stepping writes a checkpoint and ends (a second Ctrl-C stops at once, "
                 "losing their work since their last checkpoints)")  # fmt: skip

        def note(line: str) -> None:
            bar.console.print(line, soft_wrap=True, highlight=False)

        try:
            job.run(scheduler, workers, analysis_workers, gpus, on_row=report, on_progress=show, on_stopping=stopping, on_note=note)
        except OSError as error:  # summary.csv could not be written: the runs' own folders are whole
            write_failed(error, f"the finished runs' folders and the last summary.csv are whole; {AGAIN}")
    try:
        job.save_record()
    except OSError as error:
        write_failed(error, f"the runs' folders and summary.csv are whole; {AGAIN}")
    if job.stopped:
        fail(job.stopped_line(), code=EXIT_STOPPED)
    _sweep_end(job)


def _sweep_end(job) -> None:
    """A sweep whose runs are all finished: summary.csv in grid order and the figures, its last lines,
    and exit 5 when runs could not write their folders."""
    from .sweep import AGAIN

    try:
        summary = job.finish()
    except OSError as error:
        write_failed(error, f"the runs' folders are whole, and summary.csv and each figure whole or absent; {AGAIN}")
    for line in job.summary_lines(summary):
        typer.echo(line)
    unwritten = job.unwritten_line()
    if unwritten:
        fail(unwritten, EXIT_OUTPUT)


# --- piles (a list of piles from a TOML file) ------------------------------------------------

@app.command()
def piles(
    spec_file: Path = typer.Argument(..., help="TOML with [[pile]] tables: out, particles, seed, and any pile option."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Rebuild piles whose file exists."),
    resolution: float = typer.Option(
        1.0, "--resolution", help="Build each pile with R times its particles, radii x R^(-1/3), into NAME_xR.h5 (docs/model.md)."
    ),
    device: Optional[str] = DeviceOption,
) -> None:
    """Build every pile a TOML file lists (the paper's: runs/paper/piles.toml), skipping those already built."""
    from .checks import check_destination
    from .spec import SpecError, check_pile_list, load_spec_file, pile_options

    try:
        entries = check_pile_list(load_spec_file(spec_file), spec_file)
        if resolution != 1:
            from .resolution import pile_entry

            try:
                entries = [pile_entry(entry, resolution, PILE_DEFAULTS["radii"]) for entry in entries]
            except ValueError as error:
                raise SpecError(f"--resolution: {error}") from None
        outs = [Path(entry["out"]) if Path(entry["out"]).is_absolute() else Path.cwd() / entry["out"] for entry in entries]
        for out in outs:  # every destination, before the first pile is built
            if overwrite or not out.exists():
                check_destination(out, "pile file")
    except DeccoError as error:
        fail_on(error)
    for entry, out in zip(entries, outs):
        if out.exists() and not overwrite:
            typer.echo(f"{out}: exists, skipped")
            continue
        _form_pile(out, True, False, device, **pile_options(entry))  # its errors exit as `decco-warp pile`'s would

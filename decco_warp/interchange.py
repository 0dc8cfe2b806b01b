"""Piles and runs to and from other codes: pkdgrav's .ss files (the format in ss.py) and a run's
fragments handed on to REBOUND.

    pile = pile_from_ss("rubble.ss")                         # a pile (State) at rest, checked
    export_ss("runs/out/default", "last.ss")                 # a run's last frame (or a pile file) as .ss
    bodies = handoff_bodies("runs/out/default")              # the last analysed frame's fragments and loose grains
    write_rebound("fragments.bin", bodies)                   # as a REBOUND simulation file (cgs, sim.G in cgs)

Units: cgs here, pkdgrav's system units inside .ss files (ss.py), cgs in the REBOUND file.  Reads
pile files, trajectories and analysis.h5; no Warp.  rebound is imported only to write its file.
"""

from __future__ import annotations

import hashlib
import tempfile
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from .checks import check_pile
from .durable import write_atomic
from .errors import FileFormatError, InputError
from .folder import RunFolder
from .io import PILE_FORMAT, frame_clock, load_pile, open_h5, open_trajectory, read_dict, read_frame
from .params import G_CGS
from .sizes import size_classes
from .ss import DEFAULT_UNITS, PROJECTILE_COLOR, TARGET_COLOR, SSParticles, SSUnits, read_ss, write_ss
from .state import State, remove_net_motion

#: The name of a run's frame exported as .ss: its step, ten digits (pkdgrav numbers its outputs so).
FRAME_NAME = "frame_{step:010d}.ss"


# --- pkdgrav .ss: piles in ------------------------------------------------------------------------


def pile_from_ss(path, units: SSUnits = DEFAULT_UNITS) -> State:
    """A pile from a .ss file: its particles in cgs, centred, their bulk motion and rigid spin removed
    (a pile file is at rest), size classes from their radii (sizes.size_classes), and the checks
    made on every pile file (radii from 1 cm to 1000 km, densities, no two spheres pressed deeper
    than a quarter of the smaller radius).  InputError or FileFormatError: one line."""
    path = Path(path)
    particles = read_ss(path, units)
    size_class, sizes = size_classes(particles.radius)
    state = State.from_arrays(particles.position, particles.velocity, particles.spin, particles.radius, particles.mass, size_class=size_class)
    centre, bulk, spin = state.centre_of_mass, state.bulk_velocity, state.spin()
    pile = remove_net_motion(state)
    check_pile(pile, f"{path}")
    pile.metadata = {
        "source": "pkdgrav .ss",
        "ss_file": str(path.resolve()),
        "ss_sha256": hashlib.sha256(path.read_bytes()).hexdigest(),
        "ss_format": "reduced" if particles.reduced else "standard",
        "ss_units": units.name,
        "ss_time": particles.time,
        "ss_color": particles.color,
        "ss_org_idx": particles.org_idx,
        "removed_centre": centre,
        "removed_velocity": bulk,
        "removed_spin": spin,
        "n_particles": pile.n,
        "size_counts": np.bincount(size_class),
        **sizes,
    }
    return pile


# --- pkdgrav .ss: piles and frames out --------------------------------------------------------------


@dataclass(frozen=True)
class Exported:
    """One file written by :func:`export_ss`."""

    path: Path
    step: int
    time: float
    """[s]"""
    n: int


def is_pile_file(path) -> bool:
    """Whether ``path`` is a decco-warp pile file (its format mark), not a trajectory."""
    path = Path(path)
    if not path.is_file():
        return False
    with open_h5(path, "file") as f:
        return f.attrs.get("format") == PILE_FORMAT


def export_ss(source, destination, frame: int | str | None = None, reduced: bool = False, units: SSUnits = DEFAULT_UNITS) -> list[Exported]:
    """Write ``source`` as .ss: a pile file (colours and original indices as its .ss held them, if it
    came from one), or a run folder's (or trajectory file's) frame ``frame`` (an index, negative from
    the end; default the last; "all": every frame, into the folder ``destination`` as FRAME_NAME),
    its target's grains in pkdgrav colour TARGET_COLOR, the projectile's PROJECTILE_COLOR, original
    indices the particles' indices."""
    source, destination = Path(source), Path(destination)
    if is_pile_file(source):
        if frame is not None:
            raise InputError(f"{source} is a pile file: it has no frames (--frame is for runs)")
        pile = load_pile(source)
        meta = pile.metadata
        color = _kept(meta.get("ss_color"), pile.n, np.full(pile.n, TARGET_COLOR))
        org_idx = _kept(meta.get("ss_org_idx"), pile.n, np.arange(pile.n))
        particles = SSParticles(0.0, pile.masses, pile.radii, pile.positions, pile.velocities, pile.omegas, color, org_idx, reduced)
        write_ss(destination, particles, units)
        return [Exported(destination, 0, 0.0, pile.n)]
    trajectory = RunFolder(source).trajectory if source.is_dir() else source
    if not trajectory.is_file():
        raise InputError(f"{source} does not exist" if not source.exists() else f"{source} is neither a pile file, a run folder nor a trajectory")
    steps, times = frame_clock(trajectory)
    if len(steps) == 0:
        raise InputError(f"{source} has no whole frame yet")
    if frame == "all":
        destination.mkdir(parents=True, exist_ok=True)
        chosen = [(index, destination / FRAME_NAME.format(step=int(step))) for index, step in enumerate(steps)]
    else:
        chosen = [(_frame_index(frame, len(steps), source), destination)]
    written = []
    for index, path in chosen:
        particles_of, _, static = read_frame(trajectory, index)
        color = np.where(static["pile_id"] == 0, TARGET_COLOR, PROJECTILE_COLOR)
        particles = SSParticles(float(times[index]), static["mass"], static["radius"], particles_of["position"], particles_of["velocity"],
                                particles_of["omega"], color, np.arange(static["mass"].shape[0]), reduced)  # fmt: skip
        write_ss(path, particles, units)
        written.append(Exported(path, int(steps[index]), float(times[index]), particles.n))
    return written


def _kept(values, n: int, otherwise: np.ndarray) -> np.ndarray:
    """A pile's recorded per-particle values if there are ``n`` of them, else ``otherwise``."""
    values = None if values is None else np.asarray(values)
    return values.astype(np.int32) if values is not None and values.shape == (n,) else otherwise.astype(np.int32)


def _frame_index(frame, frames: int, source) -> int:
    """A frame's index among a trajectory's ``frames`` (None: the last; negative: from the end)."""
    if frame is None:
        return frames - 1
    try:
        index = int(frame)
    except (TypeError, ValueError):
        raise InputError(f"--frame must be a frame's index (negative: from the end) or all; got {frame!r}") from None
    if not -frames <= index < frames:
        raise InputError(f"--frame {index}: {source} has {frames} frame(s), 0 to {frames - 1} (or -1 to -{frames})")
    return index % frames


# --- REBOUND ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class HandoffBodies:
    """A frame's bodies for an N-body code, in cgs: each fragment of the analysis as one body (its
    mass, centre of mass, velocity, and radius of the sphere of its bulk volume: the volume of the
    uniform ellipsoid with its mass and inertia, as the catalogue's bulk density), each grain in no
    fragment as a body of its own."""

    names: list[str]
    mass: np.ndarray
    """(K,) [g]"""
    position: np.ndarray
    """(K, 3) [cm], the run's frame (the collision's centre of mass at rest)"""
    velocity: np.ndarray
    """(K, 3) [cm s-1]"""
    radius: np.ndarray
    """(K,) [cm]"""
    time: float
    """[s]"""
    step: int
    frame: int
    G: float
    """The run's gravitational constant [cm3 g-1 s-2]."""
    fragments: int
    grains: int


def handoff_bodies(run_dir, frame: int | None = None) -> HandoffBodies:
    """The bodies of an analysed frame of a run (``frame``: a trajectory frame index, negative from the
    end; default the last analysed frame): its catalogue's fragments and the grains of no fragment."""
    folder = RunFolder(run_dir)
    if not folder.analysis.is_file():
        raise InputError(f"{run_dir} has no {RunFolder.ANALYSIS}: decco-warp analyze {run_dir} first (it finds the fragments)")
    steps, times = frame_clock(folder.trajectory)
    try:
        with h5py.File(folder.analysis, "r") as f:
            analysed = f["frames/step"][()]
            if frame is None:
                done = np.flatnonzero(np.isin(steps, analysed))
                if done.size == 0:
                    raise InputError(f"none of the analysed frames of {run_dir} is in its trajectory: analyse it again")
                index = int(done[-1])
            else:
                index = _frame_index(frame, len(steps), run_dir)
            step = int(steps[index])
            row = np.flatnonzero(analysed == step)
            if row.size == 0:
                raise InputError(f"frame {index} (step {step}) of {run_dir} was not analysed: decco-warp analyze {run_dir} (--every 1 analyses every frame)")
            label = f["frames/label"][row[0]]
            mine = f["catalogue/step"][()] == step
            catalogue = {name: f["catalogue"][name][()][mine] for name in ("mass", "com", "velocity", "semi_axes")}
    except (OSError, KeyError) as error:
        raise FileFormatError(f"{folder.analysis} is not a whole analysis of this version ({error}): analyse the run again") from None
    particles, _, static = read_frame(folder.trajectory, index)
    with open_trajectory(folder.trajectory) as f:
        spec = read_dict(f["parameters/spec"]) if "parameters/spec" in f else {}
    loose = np.flatnonzero(label < 0)
    fragments = int(mine.sum())
    return HandoffBodies(
        names=[f"fragment_{k}" for k in range(fragments)] + [f"grain_{i}" for i in loose],
        mass=np.concatenate([catalogue["mass"], static["mass"][loose]]),
        position=np.concatenate([catalogue["com"].reshape(-1, 3), particles["position"][loose]]),
        velocity=np.concatenate([catalogue["velocity"].reshape(-1, 3), particles["velocity"][loose]]),
        radius=np.concatenate([np.cbrt(catalogue["semi_axes"].reshape(-1, 3).prod(axis=1)), static["radius"][loose]]),
        time=float(times[index]),
        step=step,
        frame=index,
        G=float(spec.get("params", {}).get("G", G_CGS)),
        fragments=fragments,
        grains=int(loose.size),
    )


def write_rebound(path, bodies: HandoffBodies) -> Path:
    """``bodies`` as a REBOUND simulation file that ``rebound.Simulation(path)`` opens: one particle a
    body (mass, position, velocity, radius; named fragment_K or grain_I), in cgs, with ``sim.units``
    recorded as (s, cm, g), ``sim.G`` the run's G and ``sim.t`` the frame's time [s].  Written whole
    or not at all; InputError without rebound."""
    try:
        import rebound
    except ImportError:
        raise InputError("--rebound needs REBOUND: pip install rebound (or: pip install -e \".[rebound]\")") from None
    sim = rebound.Simulation()
    sim.units = ("s", "cm", "g")
    sim.G = bodies.G  # REBOUND's cgs G is CODATA 2014's; the run's is the one its fragments moved under
    sim.t = bodies.time
    for name, m, x, v, r in zip(bodies.names, bodies.mass, bodies.position, bodies.velocity, bodies.radius):
        sim.add(m=float(m), x=float(x[0]), y=float(x[1]), z=float(x[2]), vx=float(v[0]), vy=float(v[1]), vz=float(v[2]), r=float(r), name=name)
    with tempfile.TemporaryDirectory() as folder:
        scratch = Path(folder) / "simulation.bin"
        sim.save_to_file(str(scratch), delete_file=True)
        return write_atomic(path, scratch.read_bytes())

"""HDF5 files: piles, run trajectories (H5MD layout) and checkpoints.

Nothing here imports Warp: these functions read and write NumPy snapshots.

* A pile file holds one formed rubble pile and how it was made.
* A trajectory follows H5MD 1.1: ``/h5md`` metadata, ``/particles/all`` with the
  time-dependent elements ``position``, ``velocity``, ``omega``, ``stress``
  (each ``step``, ``time``, ``value``) and the static ``radius``, ``mass``,
  ``species`` (size class) and ``pile_id``; ``/observables`` time series; and
  ``/parameters`` with the resolved run specification.  It is written in SWMR
  mode and flushed after every frame, so it can be read while the run goes on
  (open it with ``swmr=True``) and stays readable if the run is killed.
  ``BackgroundFrames`` writes a run's frames on a worker thread while it steps on.
* A checkpoint is replaced atomically (temporary file, fsync, rename).

Every write goes through decco_warp/durable.py (atomic replacement, the write hook, the room
check); a trajectory whose writer was killed has its flags reset by decco_warp/repair.py.

Piles and checkpoints are checked as they are read (decco_warp.checks): values that make
sense in cgs and, for a pile at rest, no two spheres pressed deep into each other.
"""

from __future__ import annotations

import contextlib
import errno
import gc
import os
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from ._version import __version__
from .checks import InputError, check_particles, check_pile
from .durable import WRITE_ERRNOS, abandon, as_os_error, atomic_h5, check_space, complaints_held, first_line, pause_point, write_point
from .diagnostics import STRESS_SHARE_OBSERVABLES
from .kernels.channels import HELD_ENERGIES, LEDGER_ENTRIES
from .repair import HDF5_SIGNATURE, clear_write_flags
from .state import State
from .errors import FileFormatError  # noqa: F401 (re-exported: the error lives in errors.py)

PILE_FORMAT = "decco-warp pile"
CHECKPOINT_FORMAT = "decco-warp checkpoint"
#: The layout of the files this decco-warp writes (trajectories, checkpoints), in their
#: ``format_version`` attribute; it reads every version up to this one (files of decco-warp 0.2 have
#: none: version 0, their missing parts default, run.py and record.py say how) and refuses newer ones.
FORMAT_VERSION = 1


def check_format_version(f, what: str, path) -> int:
    """The format version of an open file (0 where it records none); FileFormatError for one newer
    than this decco-warp reads."""
    version = int(f.attrs.get("format_version", 0))
    if version > FORMAT_VERSION:
        creator = f.attrs.get("creator", "a newer decco-warp")
        raise FileFormatError(
            f"{what} {path} has format version {version} ({creator}); this decco-warp {__version__} reads up to "
            f"{FORMAT_VERSION}: upgrade decco-warp to read it"
        )
    return version

_STATE_ARRAYS = ("positions", "velocities", "omegas", "radii", "masses", "size_class")


# --- plain dictionaries <-> HDF5 groups ------------------------------------------


def write_dict(group: h5py.Group, values: dict) -> None:
    """Scalars and strings as attributes, arrays as datasets, dicts as subgroups."""
    for key, value in values.items():
        if isinstance(value, dict):
            write_dict(group.require_group(key), value)
        elif isinstance(value, np.ndarray) and value.ndim > 0:
            group.create_dataset(key, data=value)
        elif isinstance(value, (list, tuple)):
            group.attrs[key] = np.asarray(value)
        elif value is None:
            continue
        else:
            group.attrs[key] = value


def read_dict(group: h5py.Group) -> dict:
    values: dict = {}
    for key, value in group.attrs.items():
        values[key] = _plain(value)
    for key, item in group.items():
        values[key] = read_dict(item) if isinstance(item, h5py.Group) else item[()]
    return values


def _plain(value):
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


@contextlib.contextmanager
def open_h5(path, what: str, mode: str = "r", **options):
    """Open an HDF5 file, turning every way it can fail into a one-line FileFormatError."""
    path = Path(path)
    if mode == "r" and not path.is_file():
        raise FileFormatError(f"{what} {path} does not exist")
    try:
        f = h5py.File(path, mode, **options)
    except (OSError, RuntimeError) as error:
        raise FileFormatError(f"{what} {path} is not a readable HDF5 file ({first_line(error)})") from None
    with f:
        try:
            yield f
        except (KeyError, OSError, RuntimeError, TypeError) as error:
            raise FileFormatError(f"{what} {path} is incomplete or corrupted ({first_line(error)})") from None


@contextlib.contextmanager
def open_trajectory(path):
    """A trajectory opened for reading: plainly when no writer holds it (a damaged one then fails at
    once), else as a SWMR reader (a running or killed writer leaves its flags set), which HDF5 2
    would have retried on damaged metadata for up to an hour."""
    check_complete(path, "trajectory")
    try:
        with open_h5(path, "trajectory", locking=False) as f:
            check_format_version(f, "trajectory", path)
            yield f
            return
    except FileFormatError as error:
        if "already open for write" not in str(error):
            raise
    with open_h5(path, "trajectory", swmr=True, locking=False) as f:
        yield f


# --- piles ----------------------------------------------------------------------


def save_pile(pile: State, path) -> None:
    """Write a formed pile (State with size_class and formation metadata) to ``path`` atomically."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    with atomic_h5(Path(path)) as f:
        f.attrs["format"] = PILE_FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["creator"] = f"decco-warp {__version__}"
        group = f.create_group("pile")
        for name in _STATE_ARRAYS:
            group.create_dataset(name, data=getattr(pile, name))
        from .collision import pile_radius

        summary = {"n_particles": pile.n, "mass": pile.total_mass, "radius": pile_radius(pile)}
        if "potential" in pile.metadata:
            summary["potential"] = pile.metadata["potential"]
        write_dict(group.create_group("summary"), summary)
        write_dict(group.create_group("formation"), pile.metadata)


def load_pile(path) -> State:
    """Read a pile file written by :func:`save_pile`; raises FileFormatError naming what is wrong."""
    with open_h5(path, "pile file") as f:
        if f.attrs.get("format") != PILE_FORMAT or "pile" not in f:
            raise FileFormatError(f"pile file {path} is not a decco-warp pile (no 'pile' group or format mark)")
        group = f["pile"]
        missing = [name for name in _STATE_ARRAYS if name not in group]
        if missing:
            raise FileFormatError(f"pile file {path} lacks {', '.join(missing)}")
        arrays = {name: group[name][()] for name in _STATE_ARRAYS}
        metadata = read_dict(group["formation"]) if "formation" in group else {}
    try:
        pile = State.from_arrays(
            arrays["positions"],
            arrays["velocities"],
            arrays["omegas"],
            arrays["radii"],
            arrays["masses"],
            size_class=arrays["size_class"],
            metadata=metadata,
        )
    except ValueError as error:
        raise FileFormatError(f"pile file {path}: {error}") from None
    try:
        check_pile(pile, f"pile file {path}")
    except InputError as error:
        raise FileFormatError(str(error)) from None
    return pile


# --- trajectories (H5MD) -----------------------------------------------------------


#: Units of the trajectory's /observables (the attribute "unit" of each value; docs/data.md).
OBSERVABLE_UNITS = {
    # The energies: kinetic, those the channels hold, the total, the ledger's entries (kernels/channels.py).
    **{name: "erg" for name in ("kinetic_translational", "kinetic_rotational", *HELD_ENERGIES, "total_energy", *LEDGER_ENTRIES)},
    "momentum": "g cm s-1",
    "angular_momentum": "g cm2 s-1",
    "number_of_contacts": "1",
    "max_overlap": "cm",
    "deepest_overlap": "1 (of the smaller radius of the pair)",
    "deepest_overlap_pair": "particle index",
    **{name: "1 (100 N_top / N per size class)" for name in STRESS_SHARE_OBSERVABLES},
}


def _time_series(group: h5py.Group, name: str, shape: tuple, dtype) -> None:
    element = group.create_group(name)
    element.create_dataset("step", shape=(0,), maxshape=(None,), dtype=np.int64, chunks=(1024,))
    element.create_dataset("time", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(1024,))
    element["time"].attrs["unit"] = "s"
    chunk = (1, *shape) if shape and int(np.prod(shape)) > 64 else (256, *shape)
    element.create_dataset("value", shape=(0, *shape), maxshape=(None, *shape), dtype=dtype, chunks=chunk)
    if name in OBSERVABLE_UNITS and group.name == "/observables":
        element["value"].attrs["unit"] = OBSERVABLE_UNITS[name]


class Trajectory:
    """An H5MD trajectory being written: create or reopen, append frames, flush each time."""

    PARTICLE_ELEMENTS = {"position": ("cm", 3), "velocity": ("cm s-1", 3), "omega": ("rad s-1", 3), "stress": ("cm", None)}

    def __init__(self, file: h5py.File, path: Path):
        self.file = file
        self.path = path
        self.broken = False  # a write failed: no more frames
        self.abandoned = False  # ... inside HDF5: never closed either
        # (step, time, value) datasets of each element, looked up once: h5py's lookups by
        # name cost more than the writes themselves.
        self._datasets: dict[tuple[str, str], tuple] = {}

    @classmethod
    def create(cls, path, state: State, observables: dict, parameters: dict) -> "Trajectory":
        """A new file for ``state``'s particles; ``observables`` gives each series' shape from a sample frame."""
        path = Path(path)
        write_point(path.name)
        try:
            f = h5py.File(path, "w", libver="latest")
        except (OSError, RuntimeError) as error:
            raise as_os_error(error, path) from None
        try:
            cls._layout(f, state, observables, parameters)
        except BaseException as error:
            abandon(f)  # HDF5 may have been cut off half-way: closing could crash
            with contextlib.suppress(OSError):
                path.unlink()
            raise as_os_error(error, path) if isinstance(error, (OSError, RuntimeError)) else error from None
        return cls(f, path)

    @classmethod
    def _layout(cls, f: h5py.File, state: State, observables: dict, parameters: dict) -> None:
        h5md = f.create_group("h5md")
        h5md.attrs["version"] = np.array([1, 1])
        h5md.create_group("author").attrs["name"] = os.environ.get("USER", "decco-warp user")
        creator = h5md.create_group("creator")
        creator.attrs["name"] = "decco-warp"
        creator.attrs["version"] = __version__
        particles = f.create_group("particles/all")
        box = particles.create_group("box")
        box.attrs["dimension"] = 3
        box.attrs["boundary"] = np.array([b"none"] * 3)
        n = state.n
        for name, (unit, width) in cls.PARTICLE_ELEMENTS.items():
            _time_series(particles, name, (n, width) if width else (n,), np.float64)
            particles[name]["value"].attrs["unit"] = unit
        for name, values, unit in [
            ("radius", state.radii, "cm"),
            ("mass", state.masses, "g"),
            ("species", state.size_class, None),
            ("pile_id", state.pile_id, None),
        ]:
            dataset = particles.create_dataset(name, data=values)
            if unit:
                dataset.attrs["unit"] = unit
        observables_group = f.create_group("observables")
        for name, value in observables.items():
            value = np.asarray(value)
            dtype = np.int64 if np.issubdtype(value.dtype, np.integer) else np.float64
            _time_series(observables_group, name, value.shape, dtype)
        write_dict(f.create_group("parameters"), parameters)
        f.swmr_mode = True

    @classmethod
    def reopen(cls, path, keep_through_step: int, observables: dict | None = None) -> "Trajectory":
        """Open an existing trajectory to continue it, dropping frames after ``keep_through_step``;
        ``observables`` (a sample frame) adds the series an older version did not write."""
        path = Path(path)
        write_point(path.name)
        clear_write_flags(path)  # left set by a writer that was killed
        try:
            f = h5py.File(path, "r+", libver="latest")
        except OSError as error:
            if error.errno in WRITE_ERRNOS:
                raise as_os_error(error, path) from None
            raise FileFormatError(f"trajectory {path} cannot be reopened ({first_line(error)})") from None
        trajectory = cls(f, path)
        try:
            for element in trajectory._elements():
                keep = _complete_frames(element, keep_through_step)
                for name in ("step", "time", "value"):
                    element[name].resize(keep, axis=0)
            if observables:
                trajectory._add_missing(observables)  # before SWMR mode, which allows no new datasets
            f.swmr_mode = True
        except (OSError, RuntimeError) as error:
            abandon(f)  # the frames dropped are dropped again by the next resume
            raise as_os_error(error, path) from None
        return trajectory

    def _elements(self):
        for name in self.PARTICLE_ELEMENTS:
            yield self.file["particles/all"][name]
        yield from self.file["observables"].values()

    def append(self, step: int, time: float, particles: dict, observables: dict) -> None:
        """One frame: particle arrays (position, velocity, omega, stress) and observable values."""
        write_point(f"{self.path.name} (frame of step {step})")
        self.write(step, time, particles, observables)

    def write(self, step: int, time: float, particles: dict, observables: dict) -> None:
        """:meth:`append` without its write point (counted by the caller).  A failed write raises
        OSError and ends the file's frames; one that failed inside HDF5 leaves the file abandoned,
        never closed: the frames flushed before it stay readable, and a resume drops whatever of
        the failed frame reached the disk."""
        if self.broken:
            raise OSError(errno.EIO, "an earlier write of this file failed", str(self.path))
        check_space(self.path.parent, sum(np.asarray(v).nbytes for v in (*particles.values(), *observables.values())), self.path)
        failure = None
        with complaints_held() as held:
            try:
                for group, values in (("particles/all", particles), ("observables", observables)):
                    for name, value in values.items():
                        self._append(self._element(group, name), step, time, value)
                self.file.flush()
            except (OSError, RuntimeError) as error:
                failure, outside = as_os_error(error, self.path), getattr(error, "outside_hdf5", False)
            if failure is not None:  # (the error and its frames are freed here, inside the hold)
                held.drop = True
                gc.collect()
        if failure is None:
            return
        self.broken = True
        if not outside:
            self.abandoned = True
            abandon(self.file)
        raise failure

    def _element(self, group: str, name: str) -> tuple:
        key = (group, name)
        if key not in self._datasets:
            element = self.file[group][name]
            self._datasets[key] = (element["step"], element["time"], element["value"])
        return self._datasets[key]

    def _add_missing(self, observables: dict) -> None:
        """Series of ``observables`` that a trajectory written by an older version lacks, with its
        earlier frames filled with NaN (-1 for integers), so that every series keeps a value per frame."""
        frames = self.file["particles/all/position"]
        for name, value in observables.items():
            if name in self.file["observables"]:
                continue
            value = np.asarray(value)
            dtype = np.int64 if np.issubdtype(value.dtype, np.integer) else np.float64
            _time_series(self.file["observables"], name, value.shape, dtype)
            element = self.file["observables"][name]
            count = frames["step"].shape[0]
            for dataset in ("step", "time", "value"):
                element[dataset].resize(count, axis=0)
            element["value"][...] = -1 if dtype == np.int64 else np.nan
            element["time"][...] = frames["time"][()]
            element["step"][...] = frames["step"][()]

    @staticmethod
    def _append(datasets: tuple, step: int, time: float, value) -> None:
        # The step is written last: a frame whose step is missing was cut short (see _complete_frames).
        steps, times, values = datasets
        k = steps.shape[0]
        for dataset in datasets:
            dataset.resize(k + 1, axis=0)
        values[k] = value
        times[k] = time
        pause_point("trajectory-write", step)
        steps[k] = step

    def close(self) -> None:
        if self.abandoned:
            return  # see write
        try:
            self.file.close()
        except (OSError, RuntimeError) as error:
            self.broken = self.abandoned = True
            abandon(self.file)
            raise as_os_error(error, self.path) from None


class BackgroundFrames:
    """A trajectory whose frames are written by one worker thread, in order and one at a time, so
    that writing a frame (~6 ms, mostly HDF5's cost per dataset) overlaps the next steps: the
    stepping loop waits on the device or in Warp's kernels with the GIL released.  A frame's write
    error comes back at the next ``append``, ``flush`` or ``close``; flush before anything that must
    not be on disk before the frames (a checkpoint), so that a kill never leaves a checkpoint ahead
    of its trajectory."""

    def __init__(self, trajectory: Trajectory):
        self.trajectory = trajectory
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="decco-frames")
        self._pending: Future | None = None

    def append(self, step: int, time: float, particles: dict, observables: dict) -> None:
        """Queue one frame (its arrays must not change afterwards) once the previous one is written."""
        self.flush()
        write_point(f"{self.trajectory.path.name} (frame of step {step})")  # counted here, in order with the caller's writes
        self._pending = self._worker.submit(self.trajectory.write, step, time, particles, observables)

    def flush(self) -> None:
        """Wait until every queued frame is written and flushed; raises a write's error."""
        pending, self._pending = self._pending, None
        if pending is not None:
            pending.result()

    def close(self) -> None:
        """Flush, then close the file (also when the flush fails, whose error is then raised)."""
        try:
            self.flush()
        finally:
            self._worker.shutdown(wait=True)
            self.trajectory.close()


def _complete_frames(element: h5py.Group, keep_through_step: int) -> int:
    """How many leading frames of an element are whole and at or before ``keep_through_step``.

    A frame cut short by a kill has its step still at the fill value 0 (or lacks
    its value), so only the strictly increasing prefix of steps counts.
    """
    steps = element["step"][()]
    n = min(len(steps), element["time"].shape[0], element["value"].shape[0])
    keep = 0
    while keep < n and steps[keep] <= keep_through_step and (keep == 0 or steps[keep] > steps[keep - 1]):
        keep += 1
    return keep




def check_complete(path, what: str) -> None:
    """Raise FileFormatError if an HDF5 file (superblock v2/3) is shorter than its recorded end of file.

    A SWMR reader retries metadata reads on such a file for a long time instead of failing,
    so a truncated trajectory is caught here first.
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"{what} {path} does not exist")
    with open(path, "rb") as f:
        head = f.read(48)
    if head[:8] == HDF5_SIGNATURE and len(head) < 48:  # cut inside the superblock: a SWMR open would retry for an hour
        raise FileFormatError(f"{what} {path} is truncated ({len(head)} bytes, inside its superblock)")
    if len(head) < 48 or head[:8] != HDF5_SIGNATURE or head[8] not in (2, 3) or head[9] != 8:
        return
    end = int.from_bytes(head[28:36], "little")
    size = path.stat().st_size
    if size < end:
        raise FileFormatError(f"{what} {path} is truncated ({size} of {end} bytes)")


@dataclass(frozen=True)
class TrajectoryData:
    """A trajectory read into memory (:func:`read_trajectory`): F frames of N particles.

    Fields are read as attributes (``data.time``) or, as a dict's, by name (``data["time"]``).
    docs/data.md lists every dataset of the file these come from.

    >>> data = read_trajectory("runs/out/default/trajectory.h5")
    >>> data.time[-1], data.particles["position"].shape     # [s], (F, N, 3) [cm]
    """

    step: np.ndarray
    """(F,) int64: the step of each frame."""
    time: np.ndarray
    """(F,) float64 [s]: simulated time of each frame."""
    particles: dict
    """Per frame and particle: ``position`` (F, N, 3) [cm], ``velocity`` (F, N, 3) [cm s-1],
    ``omega`` (F, N, 3) [rad s-1] (each sphere's angular velocity), ``stress`` (F, N) [cm] (a
    particle's largest overlap over its contacts)."""
    static: dict
    """Per particle, constant: ``radius`` (N,) [cm], ``mass`` (N,) [g], ``species`` (N,) (size
    class, 0 the smallest radius), ``pile_id`` (N,) (0 target, 1 projectile)."""
    observables: dict
    """Per frame, the system's series (units: OBSERVABLE_UNITS): energies [erg] and the ledger's
    dissipated channels, momentum [g cm s-1], angular momentum [g cm2 s-1], contacts, overlaps,
    stress shares by size class."""
    observable_step: dict
    """The step of each observable's frames (the same as ``step`` for a run of this version)."""
    parameters: dict
    """The run's set-up: ``spec`` (the resolved specification), ``collision`` (eta in both
    readings, speed [cm s-1], radii [cm], masses [g], energies [erg], spins [rad s-1], ...),
    ``stability`` (the margins and predicted overlap), the pile files and their SHA-256."""

    def __getitem__(self, name: str):
        if name not in self.__dataclass_fields__:
            raise KeyError(name)
        return getattr(self, name)

    def keys(self):
        return self.__dataclass_fields__.keys()


def read_trajectory(path, particle_frames=None) -> TrajectoryData:
    """A finished or running trajectory as NumPy arrays (:class:`TrajectoryData`): steps, times,
    particle frames, observables, parameters.

    Of a run still being written, the frames whole in every element so far (a frame being
    written is left out).  ``particle_frames``: the particles of these frames only (indices of the
    whole frames, -1 the last, in the order given), the others left on disk (an analysis reads the
    rest a share at a time: a long run of many particles is gigabytes)."""
    with open_trajectory(path) as f:
        particles = f["particles/all"]
        elements = [particles[name] for name in Trajectory.PARTICLE_ELEMENTS] + list(f["observables"].values())
        n = min(_complete_frames(element, np.iinfo(np.int64).max) for element in elements)
        if particle_frames is None:
            chosen = {name: particles[name]["value"][:n] for name in Trajectory.PARTICLE_ELEMENTS}
        else:
            wanted = [int(k) + n if int(k) < 0 else int(k) for k in particle_frames]
            if any(not 0 <= k < n for k in wanted):
                raise InputError(f"{path}: frames {list(particle_frames)} asked of a trajectory of {n} whole frame(s)")
            read = sorted(set(wanted))  # HDF5 reads a selection in increasing order, once each
            chosen = {name: particles[name]["value"][read][[read.index(k) for k in wanted]] if read
                      else particles[name]["value"][:0] for name in Trajectory.PARTICLE_ELEMENTS}  # fmt: skip
        return TrajectoryData(
            step=particles["position/step"][:n],
            time=particles["position/time"][:n],
            particles=chosen,
            static={name: particles[name][()] for name in ("radius", "mass", "species", "pile_id")},
            observables={name: group["value"][:n] for name, group in f["observables"].items()},
            observable_step={name: group["step"][:n] for name, group in f["observables"].items()},
            parameters=read_dict(f["parameters"]),
        )


def last_frame_step(path) -> int:
    """The step of a trajectory's last whole frame (of its positions; -1 before the first)."""
    with open_trajectory(path) as f:
        element = f["particles/all/position"]
        n = _complete_frames(element, np.iinfo(np.int64).max)
        return int(element["step"][n - 1]) if n else -1


def frame_clock(path) -> tuple[np.ndarray, np.ndarray]:
    """The step and time [s] of each whole frame of a trajectory (every particle element written),
    without reading the frames: what picks one frame of a long run to read with :func:`read_frame`."""
    with open_trajectory(path) as f:
        particles = f["particles/all"]
        n = min(_complete_frames(particles[name], np.iinfo(np.int64).max) for name in Trajectory.PARTICLE_ELEMENTS)
        return particles["position/step"][:n], particles["position/time"][:n]


def read_frame(path, index: int = 0) -> tuple[dict, dict, dict]:
    """(particles, observables, static) of one frame of a trajectory, without reading the rest."""
    with open_trajectory(path) as f:
        particles = f["particles/all"]
        frame = {name: particles[name]["value"][index] for name in Trajectory.PARTICLE_ELEMENTS}
        observables = {name: group["value"][index] for name, group in f["observables"].items()}
        static = {name: particles[name][()] for name in ("radius", "mass", "species", "pile_id")}
    return frame, observables, static


def read_frames(path, indices, elements=("position", "velocity", "omega")) -> tuple[dict, dict]:
    """(particles, static) of the frames ``indices`` (increasing) of a trajectory: each of
    ``elements`` as (len(indices), N, ...), as :func:`read_trajectory` has them, without reading the
    other frames (what an analysis worker reads of its share)."""
    indices = [int(k) for k in indices]
    with open_trajectory(path) as f:
        particles = f["particles/all"]
        frames = {name: particles[name]["value"][indices] for name in elements}
        static = {name: particles[name][()] for name in ("radius", "mass", "species", "pile_id")}
    return frames, static


# --- checkpoints ---------------------------------------------------------------------


def write_checkpoint(path, snapshot: dict, static: State, extra: dict) -> None:
    """Everything a run needs to continue bit for bit, replacing ``path`` atomically."""
    with atomic_h5(Path(path)) as f:
        f.attrs["format"] = CHECKPOINT_FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["creator"] = f"decco-warp {__version__}"
        state = f.create_group("state")
        for name in ("radii", "masses", "pile_id", "size_class"):
            state.create_dataset(name, data=getattr(static, name))
        write_dict(f.create_group("snapshot"), snapshot)
        f.flush()
        pause_point("checkpoint-write", int(snapshot["step"]))
        write_dict(f.create_group("run"), extra)


def read_checkpoint(path) -> tuple[dict, State, dict]:
    """(snapshot, static State, extra) from :func:`write_checkpoint`."""
    with open_h5(path, "checkpoint") as f:
        if f.attrs.get("format") != CHECKPOINT_FORMAT:
            raise FileFormatError(f"checkpoint {path} is not a decco-warp checkpoint")
        check_format_version(f, "checkpoint", path)
        snapshot = read_dict(f["snapshot"])
        static = {name: f["state"][name][()] for name in ("radii", "masses", "pile_id", "size_class")}
        extra = read_dict(f["run"])
    try:
        state = State.from_arrays(
            snapshot["positions"],
            snapshot["velocities"],
            snapshot["omegas"],
            static["radii"],
            static["masses"],
            pile_id=static["pile_id"],
            size_class=static["size_class"],
        )
        check_particles(state, f"checkpoint {path}")
    except (KeyError, ValueError) as error:
        raise FileFormatError(f"checkpoint {path}: {error}" if not isinstance(error, InputError) else str(error)) from None
    return snapshot, state, extra

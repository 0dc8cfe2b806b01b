"""Input checks made before any work: particle data that make sense in cgs, piles at rest
without deep overlaps, and destinations that can be written.

Every check raises :class:`InputError` with one line naming what is wrong; the CLI turns it
into exit code 2.  Nothing here imports Warp.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .errors import InputError  # noqa: F401 (re-exported: the error lives in errors.py)

#: A particle radius must lie in this range [cm]: 1 cm to 1000 km.
RADIUS_RANGE = (1.0, 1.0e8)
#: A particle's density m / (4/3 pi R^3) must lie in this range [g/cm^3] (ices to metals, with room).
DENSITY_RANGE = (0.1, 30.0)
#: Positions beyond this are not a pile or a collision [cm] (about 0.7 AU).
MAX_POSITION = 1.0e13
#: A speed or a surface spin speed beyond this is not the subsonic regime of the model [cm/s].
MAX_SPEED = 1.0e8
#: A pile at rest may press two spheres together by at most this fraction of the smaller radius.
#: Settled piles reach ~0.01; coincident particles give 1 to 2.
MAX_REST_OVERLAP = 0.25


def check_particles(state, source: str) -> None:
    """Radii, densities, positions, speeds and spins that make sense in cgs (State is finite already)."""
    radii, masses = state.radii, state.masses
    k = _first_outside(radii, *RADIUS_RANGE)
    if k is not None:
        raise InputError(
            f"{source}: particle {k} has radius {radii[k]:.3g} cm, outside {RADIUS_RANGE[0]:g} cm to "
            f"{RADIUS_RANGE[1]:g} cm (radii are in cm, as every length)"
        )
    density = masses / (4.0 / 3.0 * math.pi * radii**3)
    k = _first_outside(density, *DENSITY_RANGE)
    if k is not None:
        raise InputError(
            f"{source}: particle {k} has mass {masses[k]:.3g} g for radius {radii[k]:.3g} cm, a density of "
            f"{density[k]:.3g} g/cm^3, outside {DENSITY_RANGE[0]:g} to {DENSITY_RANGE[1]:g} (masses are in g, radii in cm)"
        )
    for name, values, limit, unit in (
        ("position", np.abs(state.positions).max(axis=1), MAX_POSITION, "cm"),
        ("speed", np.linalg.norm(state.velocities, axis=1), MAX_SPEED, "cm/s"),  # 1000 km/s
        ("spin surface speed", np.linalg.norm(state.omegas, axis=1) * radii, MAX_SPEED, "cm/s"),
    ):
        k = _first_outside(values, -math.inf, limit)
        if k is not None:
            raise InputError(f"{source}: particle {k} has a {name} of {values[k]:.3g} {unit}, beyond {limit:.0e} {unit}")


def _first_outside(values: np.ndarray, low: float, high: float) -> int | None:
    """Index of the first value outside [low, high], or None."""
    bad = np.flatnonzero((values < low) | (values > high))
    return int(bad[0]) if bad.size else None


def deepest_rest_overlap(state) -> tuple[float, int, int]:
    """(depth as a fraction of the smaller radius, i, j) of the deepest contact; (0, -1, -1) without any."""
    from scipy.spatial import cKDTree

    pairs = cKDTree(state.positions).query_pairs(2.0 * float(state.radii.max()), output_type="ndarray")
    if pairs.size == 0:
        return 0.0, -1, -1
    i, j = pairs[:, 0], pairs[:, 1]
    gap = np.linalg.norm(state.positions[i] - state.positions[j], axis=1)
    depth = (state.radii[i] + state.radii[j] - gap) / np.minimum(state.radii[i], state.radii[j])
    k = int(np.argmax(depth))
    return float(depth[k]), int(min(i[k], j[k])), int(max(i[k], j[k]))


def check_pile(state, source: str) -> None:
    """A pile at rest: sane particles, and no two spheres pressed deeper than MAX_REST_OVERLAP."""
    check_particles(state, source)
    depth, i, j = deepest_rest_overlap(state)
    if depth > MAX_REST_OVERLAP:
        where = "at the same place" if depth >= 2.0 - 1e-9 else "nearly at the same place" if depth > 1.0 else "pressed together"
        raise InputError(
            f"{source}: particles {i} and {j} overlap by {depth:.3g} of the smaller radius ({where}; a settled "
            f"pile stays below {MAX_REST_OVERLAP:g}, typically ~0.01): the file is damaged or not a settled pile"
        )


def check_destination(path, what: str, folder: bool = False) -> Path:
    """Refuse, before any work, a file (or folder) that cannot be created or replaced at ``path``."""
    path = Path(path).expanduser()
    if path.exists():
        if folder and not path.is_dir():
            raise InputError(f"cannot write the {what} {path}: it is a file, not a folder")
        if not folder and path.is_dir():
            raise InputError(f"cannot write the {what} {path}: it is a folder")
        target = path if folder else path.parent
        if not os.access(target, os.W_OK | os.X_OK):
            raise InputError(f"cannot write the {what} {path}: {target} is not writable")
        _check_file_system(target, path, what)
        return path
    existing = path.parent
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir() or not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"cannot write the {what} {path}: {existing} is not a writable folder")
    _check_file_system(existing, path, what)
    return path


#: File systems that are the kernel's interfaces, where nothing can be stored: os.access() grants root
#: writing there, and creating a folder fails only once the work has begun.
KERNEL_FILE_SYSTEMS = {"proc", "sysfs", "devtmpfs", "devpts", "cgroup", "cgroup2", "debugfs", "tracefs", "securityfs", "configfs",
                       "pstore", "bpf", "efivarfs", "fusectl", "mqueue", "binfmt_misc", "autofs", "rpc_pipefs", "nsfs"}  # fmt: skip


def _check_file_system(folder: Path, path: Path, what: str) -> None:
    """Refuse a destination whose ``folder`` is on a read-only file system or on one of the kernel's
    (KERNEL_FILE_SYSTEMS: /proc, /sys, ...)."""
    mount, kind = mount_of(folder)
    if kind in KERNEL_FILE_SYSTEMS:
        raise InputError(f"cannot write the {what} {path}: {mount} is the kernel's {kind} file system, not a place for files")
    try:
        read_only = bool(os.statvfs(folder).f_flag & os.ST_RDONLY)
    except OSError:
        read_only = False  # cannot be told here: the write says
    if read_only:
        raise InputError(f"cannot write the {what} {path}: {mount} is a read-only file system")


def mount_of(folder) -> tuple[str, str | None]:
    """(mount point, file-system type) of the mount holding ``folder``, from /proc/self/mounts (the
    longest mount point that contains it); (its path, None) where that cannot be read."""
    real = os.path.realpath(folder)
    best, kind = "/", None
    try:
        with open("/proc/self/mounts", encoding="utf-8", errors="replace") as mounts:
            for line in mounts:
                fields = line.split()
                if len(fields) < 3:
                    continue
                point = fields[1].replace("\\040", " ")
                inside = real == point or real.startswith(point.rstrip("/") + "/")
                if inside and len(point) >= len(best):
                    best, kind = point, fields[2]
    except OSError:
        return str(folder), None
    return best, kind

"""pkdgrav's .ss particle files, read and written with NumPy, in pkdgrav's units and in cgs.

The layout is pkdgrav's ``ssio.h`` / ``ssio.c`` (docs/data.md cites them), written with XDR: big-endian,
4-byte ints, 8-byte doubles, 4-byte floats, no padding.

* header, 16 bytes: ``double time; int n_data; int iMagicNumber`` (-1 standard, -10101 reduced);
* a standard record, 96 bytes: ``double mass, radius, pos[3], vel[3], spin[3]; int color, org_idx``;
* a reduced record, 28 bytes: ``float mass, radius, pos[3]; int color, org_idx`` (no velocities, no spins).

Values are in pkdgrav's system units, where G = 1: mass in solar masses, length in AU, time in
years / 2 pi (:class:`SSUnits`; velocities in AU per that time, spins in radians per it).  Readers
and writers here take and give cgs (:class:`SSParticles`).  Every way a file can be wrong is one
:class:`FileFormatError` line.  No Warp, and no ``xdrlib`` (gone from Python 3.13).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .durable import write_atomic
from .errors import FileFormatError, InputError

MAGIC_STANDARD = -1
MAGIC_REDUCED = -10101

HEADER = np.dtype([("time", ">f8"), ("n_data", ">i4"), ("magic", ">i4")])
STANDARD = np.dtype(
    [("mass", ">f8"), ("radius", ">f8"), ("pos", ">f8", 3), ("vel", ">f8", 3), ("spin", ">f8", 3), ("color", ">i4"), ("org_idx", ">i4")]
)
REDUCED = np.dtype([("mass", ">f4"), ("radius", ">f4"), ("pos", ">f4", 3), ("color", ">i4"), ("org_idx", ">i4")])
RECORDS = {MAGIC_STANDARD: STANDARD, MAGIC_REDUCED: REDUCED}
FORMATS = {MAGIC_STANDARD: "standard", MAGIC_REDUCED: "reduced"}

#: pkdgrav's colours for a collision's two piles (ssdefs.h: 3 PLANETESIMAL, green; 12 FRAGMENT, violet).
TARGET_COLOR, PROJECTILE_COLOR = 3, 12


@dataclass(frozen=True)
class SSUnits:
    """pkdgrav's system units in cgs (G = 1 in them)."""

    name: str
    mass: float
    """One solar mass [g]."""
    length: float
    """One AU [cm]."""
    time: float
    """One year / 2 pi [s]."""

    @property
    def velocity(self) -> float:
        """One AU per (year / 2 pi) [cm s-1]."""
        return self.length / self.time


#: pkdgrav's conversions to cgs (src/ss/companion.c, "Fundamental constants from 1998 Astronomical
#: Almanac": AU 1.49597870e11 m, M_SUN 1.9891e30 kg, SID_YR 3.15581497632e7 s, time unit SID_YR / 2 pi;
#: src/pkdgrav/rubble.h the same AU and M_SUN).  G M T^2 / L^3 = 1.00034 with G = 6.6743e-8.
ALMANAC_1998 = SSUnits("almanac-1998", 1.9891e33, 1.49597870e13, 3.15581497632e7 / (2.0 * math.pi))
#: The constants of pkdgrav's ss utilities as they stand now (src/ss/ss.h: AU 1.495978707e11 m, M_SUN
#: 1.9884e30 kg, T_SCALE SID_YR / 2 pi with SID_YR 3.15581497635e7 s): 3.5e-4 less mass a solar mass.
#: G M T^2 / L^3 = 0.99999 with G = 6.6743e-8.
SS_H = SSUnits("ss.h", 1.9884e33, 1.495978707e13, 3.15581497635e7 / (2.0 * math.pi))
UNITS = {units.name: units for units in (ALMANAC_1998, SS_H)}
DEFAULT_UNITS = ALMANAC_1998


@dataclass
class SSParticles:
    """The particles of a .ss file in cgs: ``mass`` (N,) [g], ``radius`` (N,) [cm], ``position``
    (N, 3) [cm], ``velocity`` (N, 3) [cm s-1], ``spin`` (N, 3) [rad s-1], pkdgrav's ``color`` and
    ``org_idx`` (N,) (its original index; negative: a member of an aggregate); ``time`` [s];
    ``reduced``: from (or for) a reduced file, which holds no velocities or spins (zeros here)."""

    time: float
    mass: np.ndarray
    radius: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    spin: np.ndarray
    color: np.ndarray
    org_idx: np.ndarray
    reduced: bool = False

    @property
    def n(self) -> int:
        return int(self.mass.shape[0])


def read_ss(path, units: SSUnits = DEFAULT_UNITS) -> SSParticles:
    """A standard or reduced .ss file in cgs; FileFormatError (one line) for a file that is not one
    whole: too short, a wrong magic number, records cut short or followed by bytes, values that are
    not finite, masses or radii <= 0."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise FileFormatError(f"{path} does not exist") from None
    except OSError as error:
        raise FileFormatError(f"{path} cannot be read: {error.strerror}") from None
    if len(data) < HEADER.itemsize:
        raise FileFormatError(f"{path} is not a pkdgrav .ss file: {len(data)} bytes, fewer than its {HEADER.itemsize}-byte header")
    header = np.frombuffer(data, HEADER, count=1)[0]
    magic, n, time = int(header["magic"]), int(header["n_data"]), float(header["time"])
    if magic not in RECORDS:
        raise FileFormatError(f"{path} is not a pkdgrav .ss file: magic number {magic} (standard {MAGIC_STANDARD}, reduced {MAGIC_REDUCED})")
    record = RECORDS[magic]
    if n < 1:
        raise FileFormatError(f"{path}: its header declares {n} particles")
    need = HEADER.itemsize + n * record.itemsize
    if len(data) != need:
        whole = (len(data) - HEADER.itemsize) // record.itemsize
        swapped = int(np.frombuffer(data, "<i4", count=1, offset=8)[0])
        hint = " (it reads whole as little-endian: pkdgrav writes XDR, big-endian)" if HEADER.itemsize + swapped * record.itemsize == len(data) else ""
        if len(data) < need:
            raise FileFormatError(f"{path} is truncated: its header declares {n} {FORMATS[magic]} particles ({need} bytes), "
                                  f"the file has {len(data)} bytes ({whole} whole records){hint}")  # fmt: skip
        raise FileFormatError(f"{path} has {len(data) - need} bytes after its {n} {FORMATS[magic]} particles: not a .ss file of ssio.h's layout{hint}")
    if not math.isfinite(time):
        raise FileFormatError(f"{path}: the header's time is {time}")
    records = np.frombuffer(data, record, count=n, offset=HEADER.itemsize)
    for name in (name for name in record.names if record[name].base.kind == "f"):
        values = records[name].astype(float).reshape(n, -1)
        bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
        if bad.size:
            raise FileFormatError(f"{path}: particle {bad[0]} has a non-finite {name} ({values[bad[0]].tolist()})")
    for name in ("mass", "radius"):
        bad = np.flatnonzero(records[name] <= 0)
        if bad.size:
            raise FileFormatError(f"{path}: particle {bad[0]} has {name} {float(records[name][bad[0]]):g} (must be > 0)")
    reduced = magic == MAGIC_REDUCED
    zeros = np.zeros((n, 3))
    return SSParticles(
        time=time * units.time,
        mass=records["mass"].astype(float) * units.mass,
        radius=records["radius"].astype(float) * units.length,
        position=records["pos"].astype(float) * units.length,
        velocity=zeros if reduced else records["vel"].astype(float) * units.velocity,
        spin=zeros.copy() if reduced else records["spin"].astype(float) / units.time,
        color=records["color"].astype(np.int32),
        org_idx=records["org_idx"].astype(np.int32),
        reduced=reduced,
    )


def ss_bytes(particles: SSParticles, units: SSUnits = DEFAULT_UNITS) -> bytes:
    """``particles`` (cgs) as the bytes of a .ss file, reduced if ``particles.reduced`` (floats:
    24 bits, so that a pile far from the origin loses its grains' places); InputError for a value
    that is not finite in pkdgrav's units (or too large for a float)."""
    n = particles.n
    record = REDUCED if particles.reduced else STANDARD
    values = {
        "mass": particles.mass / units.mass,
        "radius": particles.radius / units.length,
        "pos": particles.position / units.length,
        "vel": particles.velocity / units.velocity,
        "spin": particles.spin * units.time,
    }
    records = np.zeros(n, dtype=record)
    with np.errstate(over="ignore"):  # a double too large for a float becomes inf, refused below
        for name in record.names:
            records[name] = particles.color if name == "color" else particles.org_idx if name == "org_idx" else values[name]
    for name in (name for name in record.names if record[name].base.kind == "f"):
        bad = np.flatnonzero(~np.isfinite(records[name].astype(float).reshape(n, -1)).all(axis=1))
        if bad.size:
            raise InputError(f"particle {bad[0]} has a {name} that is not finite in pkdgrav's units as a {record[name].base.name}")
    magic = MAGIC_REDUCED if particles.reduced else MAGIC_STANDARD
    header = np.array([(particles.time / units.time, n, magic)], dtype=HEADER)
    return header.tobytes() + records.tobytes()


def write_ss(path, particles: SSParticles, units: SSUnits = DEFAULT_UNITS) -> Path:
    """Write ``particles`` (cgs) to ``path`` as a .ss file (:func:`ss_bytes`), atomically."""
    return write_atomic(path, ss_bytes(particles, units))

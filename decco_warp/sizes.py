"""Particle sizes: a power law of radii beside the paper's three discrete sizes, the size classes that
the analysis counts particles by, and how many grains a large one can touch.

A pile's particles fall into size classes (``State.size_class``, 0 the smallest): one class per size
for discrete radii (the paper's three; a pile file from another code with a few distinct radii), and
for continuous radii (a power law; a pile file with many distinct radii) CONTINUOUS_CLASSES bins of
equal width in log R from the smallest radius to the largest, whose edges the pile file records.

No Warp: pile formation, pile files from other codes and the analysis all use it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .errors import InputError

#: Size classes of continuous radii: bins of equal width in log R between the smallest and the
#: largest radius, three as the paper's three sizes.
CONTINUOUS_CLASSES = 3
#: Radii with at most this many distinct values keep a class per value (discrete sizes).
MAX_DISCRETE_SIZES = 8
#: Radii closer than this (relative) are one size: a size stored in float32 (pkdgrav's reduced .ss
#: files) or converted from other units differs from itself by ~1e-7.
SAME_SIZE = 1e-5
#: The form of ``--size-distribution``.
POWER_LAW_FORM = "power:q=Q:r_min=R_MIN:r_max=R_MAX[:classes=K] (radii in cm; dN/dR ~ R^q)"


@dataclass(frozen=True)
class PowerLaw:
    """Radii R drawn from dN/dR proportional to R^q on [r_min, r_max] [cm]; q = -3.5 is a collisional
    cascade's (Dohnanyi 1969).  ``classes``: the size classes the analysis counts by (log-R bins)."""

    q: float
    r_min: float
    r_max: float
    classes: int = CONTINUOUS_CLASSES

    def sample(self, n: int, seed: int) -> np.ndarray:
        """``n`` radii [cm], smallest first, drawn by inverting the cumulative distribution with a
        generator of its own seeded from ``seed`` (the seeding of positions draws from another)."""
        u = np.random.default_rng((int(seed), 56)).random(n)
        a, b, p = self.r_min, self.r_max, self.q + 1.0
        if abs(p) < 1e-12:  # dN/dR ~ 1/R: uniform in log R
            radii = a * (b / a) ** u
        else:
            radii = (a**p + u * (b**p - a**p)) ** (1.0 / p)
        return np.sort(np.clip(radii, a, b))

    def edges(self) -> np.ndarray:
        """The size classes' edges [cm]: ``classes`` + 1 values, equal steps in log R."""
        return np.geomspace(self.r_min, self.r_max, self.classes + 1)

    def text(self) -> str:
        """The form ``--size-distribution`` reads, e.g. power:q=-3.5:r_min=500000:r_max=2500000:classes=3."""
        return f"power:q={self.q:g}:r_min={self.r_min:.10g}:r_max={self.r_max:.10g}:classes={self.classes}"

    def scaled(self, factor: float) -> "PowerLaw":
        """The same law with every radius times ``factor`` (a pile at another resolution)."""
        return replace(self, r_min=self.r_min * factor, r_max=self.r_max * factor)


def parse_size_distribution(text: str) -> PowerLaw:
    """``power:q=-3.5:r_min=5e5:r_max=2.5e6[:classes=3]`` as a :class:`PowerLaw` (InputError, one line, otherwise)."""
    kind, _, rest = str(text).strip().partition(":")
    if kind != "power":
        raise InputError(f"--size-distribution must be {POWER_LAW_FORM}; got {text!r}")
    values: dict[str, str] = {}
    for part in filter(None, rest.split(":")):
        key, equals, value = part.partition("=")
        if not equals or key.strip() not in ("q", "r_min", "r_max", "classes") or key.strip() in values:
            raise InputError(f"--size-distribution: {part!r} is not one of q=, r_min=, r_max=, classes= (once each): {POWER_LAW_FORM}")
        values[key.strip()] = value.strip()
    missing = [key for key in ("q", "r_min", "r_max") if key not in values]
    if missing:
        raise InputError(f"--size-distribution lacks {', '.join(missing)}: {POWER_LAW_FORM}")
    try:
        q, r_min, r_max = (float(values[key]) for key in ("q", "r_min", "r_max"))
        classes = int(values.get("classes", CONTINUOUS_CLASSES))
    except ValueError:
        raise InputError(f"--size-distribution takes numbers (classes an integer): {POWER_LAW_FORM}; got {text!r}") from None
    if not (math.isfinite(q) and math.isfinite(r_min) and math.isfinite(r_max) and 0 < r_min < r_max):
        raise InputError(f"--size-distribution needs a finite q and 0 < r_min < r_max [cm]; got q={q:g}, r_min={r_min:g}, r_max={r_max:g}")
    if not 1 <= classes <= 64:
        raise InputError(f"--size-distribution: classes must be from 1 to 64; got {classes}")
    return PowerLaw(q, r_min, r_max, classes)


def classify(radii: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Each radius's class among the bins [edges[k], edges[k + 1]) (the last bin closed), as int32."""
    inner = np.asarray(edges, dtype=float)[1:-1]
    return np.searchsorted(inner, np.asarray(radii, dtype=float), side="right").astype(np.int32)


def distinct_sizes(radii: np.ndarray) -> np.ndarray:
    """The distinct radii [cm], smallest first, radii within SAME_SIZE of the one before taken as one."""
    values = np.unique(np.asarray(radii, dtype=float))
    starts = np.concatenate([[True], np.diff(values) > SAME_SIZE * values[1:]])
    return values[starts]


def size_classes(radii: np.ndarray) -> tuple[np.ndarray, dict]:
    """Size classes of radii that came without any (a pile file from another code): a class per
    distinct size when there are at most MAX_DISCRETE_SIZES, else CONTINUOUS_CLASSES log-R bins
    from the smallest radius to the largest.  Returns (size_class, what a pile file records of them:
    ``size_radii`` [cm] for discrete sizes, else ``size_class_edges`` [cm])."""
    radii = np.asarray(radii, dtype=float)
    sizes = distinct_sizes(radii)
    if sizes.size <= MAX_DISCRETE_SIZES:
        size_class = (np.searchsorted(sizes, radii * (1.0 + SAME_SIZE), side="right") - 1).astype(np.int32)
        return size_class, {"size_radii": sizes}
    edges = np.geomspace(radii.min(), radii.max(), CONTINUOUS_CLASSES + 1)
    return classify(radii, edges), {"size_class_edges": edges}


def class_ranges(radii: np.ndarray, size_class: np.ndarray) -> dict[str, np.ndarray]:
    """Per size class: the smallest and largest radius of its particles [cm] and their count (the
    bins a run's composition and stress shares are counted in, as the particles fill them)."""
    radii = np.asarray(radii, dtype=float)
    size_class = np.asarray(size_class)
    classes = int(size_class.max()) + 1
    count = np.bincount(size_class, minlength=classes)
    low = np.full(classes, np.nan)
    high = np.full(classes, np.nan)
    np.fmin.at(low, size_class, radii)
    np.fmax.at(high, size_class, radii)
    return {"radius_min": low, "radius_max": high, "count": count}


def touching_limit(r_large: float, r_small: float) -> int:
    """The most spheres of radius ``r_small`` that can touch one of ``r_large``: each covers a cap of
    half-angle asin(r_small / (r_large + r_small)) of the large one's sphere of centres, and the caps
    cannot overlap, so at most 2 / (1 - cos) of them (14 for equal spheres, whose true limit is 12;
    62 for the paper's radius ratio of 3)."""
    sine = r_small / (r_large + r_small)
    return int(2.0 / (1.0 - math.sqrt(1.0 - sine * sine)))


def contact_list_rule(radius_ratio: float) -> int:
    """8 + 4 (R_max / R_min)^2, rounded up: contacts a particle's list is sized for in a pile of that
    radius ratio, close to the densest covering of the largest grain by the smallest (hexagonal, about
    0.9 of :func:`touching_limit`), which a settled pile does not reach (its large grains touch large
    ones too)."""
    return int(math.ceil(8.0 + 4.0 * radius_ratio * radius_ratio))

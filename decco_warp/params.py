"""Material and run constants of the DECCO model (paper Table 1, docs/model.md)."""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass, fields

from .errors import InputError

#: Gravitational constant [cm^3 g^-1 s^-2] (CODATA 2018).
G_CGS = 6.67430e-8

#: Rolling-friction forms (docs/model.md): "couple" opposes relative rolling and is
#: the default; "paper" is the force printed as the paper's eq. 9, for comparison.
ROLLING_FRICTION_FORMS = ("couple", "paper")

#: Contact laws (docs/model.md, "Contact laws"): "paper", the paper's law as docs/model.md states it
#: (rolling friction by ``rolling_friction``); "decco-code", DECCO's pair forces as its code computes
#: them (LucasKolanz/DECCO at fae89d3).
CONTACT_LAWS = ("paper", "decco-code")

#: Gravity solvers: "all-pairs" sums every pair (exact, O(N^2)); "tree" walks a radix tree with
#: monopole + quadrupole nodes (O(N log N), error set by theta_open; contacts from a hash grid).
GRAVITY_SOLVERS = ("all-pairs", "tree")
#: What a specification or the CLI may ask for: a solver, or "auto" (:func:`choose_gravity`).
GRAVITY_CHOICES = (*GRAVITY_SOLVERS, "auto")

#: From this many particles ``gravity = "auto"`` takes the tree, per device kind. CPU: measured
#: (docs/benchmarks.md: on copies of a settled pile the tree's step is the faster from ~1 150
#: particles, since its hash grid notes only touching neighbours). CUDA: measured on an H100 on
#: real piles (the innermost 32 768, 49 152 and 65 536 particles of a settled 80 000-particle pile):
#: a step takes 1.15, 2.42 and 4.19 ms with all-pairs in the Newton layout, 1.72, 2.20 and 2.74 ms
#: with the tree, so the two meet near 45 000 (docs/benchmarks.md, "The tree path").
TREE_FROM = {"cpu": 1200, "cuda": 45_000}


def choose_gravity(n: int, device: str) -> str:
    """The gravity solver ``gravity = "auto"`` takes for ``n`` particles on ``device`` ("cpu", "cuda:0")."""
    return "tree" if n >= TREE_FROM["cuda" if device.startswith("cuda") else "cpu"] else "all-pairs"


#: The K that ``gravity_every = "auto"`` stands for: on the paper's runs (the Fig. 8 collision and the
#: equal-mass head-on ones at eta 3, 9 and 12) every K from 5 to 50 lands inside the spread of K = 1's
#: realizations or within 0.015 of it (eta 9: K = 5 and 10 above it; docs/benchmarks.md, "Equivalence
#: before speed"), no difference resolved or growing with K; 10 takes most of the speed (whole
#: runs ~2x at 6 250 particles, ~3x at 10 000) at a fifth of the largest K measured.
GRAVITY_EVERY_AUTO = 10


def auto_gravity_every() -> int:
    """The K of ``gravity_every = "auto"``."""
    return GRAVITY_EVERY_AUTO


@dataclass(frozen=True)
class Params:
    """Constants of a run, in cgs.  Defaults are the paper's (Table 1, sect. 3.1).

    >>> p = Params(k_in=1e18, restitution=0.9, mu_k=0.3, mu_r=1e-3, dt=0.04)
    >>> p.k_out
    8.1e+17
    """

    k_in: float = 1e18
    """Spring constant while two spheres approach [dyne/cm]."""
    restitution: float = 0.9
    """Coefficient of restitution eps; the receding spring is k_out = eps^2 k_in (paper eq. 4)."""
    mu_k: float = 0.3
    """Sliding (kinetic) friction coefficient."""
    mu_r: float = 1e-3
    """Rolling friction coefficient."""
    dt: float = 0.04
    """Time step [s]."""
    G: float = G_CGS
    """Gravitational constant [cm^3 g^-1 s^-2]; 0 switches gravity off."""
    rolling_friction: str = "couple"
    """Form of rolling friction of the paper's law, one of ROLLING_FRICTION_FORMS."""
    contact_law: str = "paper"
    """The contact law, one of CONTACT_LAWS."""
    gravity: str = "all-pairs"
    """Gravity solver, one of GRAVITY_SOLVERS."""
    theta_open: float = 0.4
    """Tree opening angle: a node is used whole beyond size / theta_open (plus its centre's offset);
    0.4 keeps the rms relative gravity error on settled piles below 1e-3 (tests/test_tree.py)."""
    gravity_every: int = 1
    """K: steps of dt per evaluation of gravity.  1 is the paper's scheme (gravity and contacts every
    step); K > 1 kicks gravity every K dt around K steps of contacts alone (impulse multiple time
    stepping, docs/model.md "Gravity on its own clock"), and step counts are multiples of K."""

    def __post_init__(self):
        _require(self, "k_in", lambda v: v > 0, "> 0 [dyne/cm]")
        _require(self, "restitution", lambda v: 0 < v <= 1, "in (0, 1]")
        _require(self, "mu_k", lambda v: v >= 0, ">= 0")
        _require(self, "mu_r", lambda v: v >= 0, ">= 0")
        _require(self, "dt", lambda v: v > 0, "> 0 [s]")
        _require(self, "G", lambda v: v >= 0, ">= 0 [cm^3 g^-1 s^-2]")
        _require(self, "theta_open", lambda v: 0 < v < 2, "in (0, 2)")
        every = self.gravity_every
        if isinstance(every, bool) or not isinstance(every, numbers.Integral) or every < 1:
            raise InputError(f"gravity_every must be an integer >= 1 (steps of dt per gravity evaluation); got {every!r}")
        object.__setattr__(self, "gravity_every", int(every))
        if self.gravity not in GRAVITY_SOLVERS:
            raise InputError(f"gravity must be one of {', '.join(GRAVITY_SOLVERS)}; got {self.gravity!r}")
        if self.rolling_friction not in ROLLING_FRICTION_FORMS:
            raise InputError(
                f"rolling_friction must be one of {', '.join(ROLLING_FRICTION_FORMS)}; got {self.rolling_friction!r}"
            )
        if self.contact_law not in CONTACT_LAWS:
            raise InputError(f"contact_law must be one of {', '.join(CONTACT_LAWS)}; got {self.contact_law!r}")
        if self.contact_law != "paper" and self.rolling_friction != "couple":
            raise InputError(f"rolling_friction chooses the paper law's rolling friction; contact_law {self.contact_law!r} has its own")

    @property
    def law(self) -> str:
        """The contact law's name among the kernels' (kernels/pair.py CONTACT_LAWS): the paper's law
        with rolling friction as a couple ("paper") or as the paper's printed force, or another law."""
        if self.contact_law == "paper":
            return "paper" if self.rolling_friction == "couple" else "paper-printed-rolling"
        return self.contact_law

    @property
    def k_out(self) -> float:
        """Spring constant while receding or at rest, eps^2 k_in [dyne/cm]."""
        return self.restitution**2 * self.k_in

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict) -> "Params":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise InputError(f"unknown parameter(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
        return cls(**values)


def _require(params: Params, name: str, ok, allowed: str) -> None:
    value = getattr(params, name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{name} must be a number {allowed}; got {value!r}")
    value = float(value)
    if not math.isfinite(value) or not ok(value):
        raise InputError(f"{name} must be {allowed}; got {value!r}")
    object.__setattr__(params, name, value)

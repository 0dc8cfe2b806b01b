"""The physical constants of the DECCO model (paper Table 1, docs/model.md): the contact law and its
constants, G and the time step.  How they are evaluated (the gravity solver, its clock, precision,
layouts) is a :class:`~decco_warp.scheme.Scheme`."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields

from .errors import InputError
from .kernels.pair import CONTACT_LAWS as KERNEL_LAWS, LAW_VARIANTS, LAWS_WITH_SPRINGS

#: Gravitational constant [cm^3 g^-1 s^-2] (CODATA 2018).
G_CGS = 6.67430e-8

#: Rolling-friction forms (docs/model.md): "couple" opposes relative rolling and is
#: the default; "paper" is the force printed as the paper's eq. 9, for comparison.
ROLLING_FRICTION_FORMS = ("couple", "paper")

#: Contact laws (docs/model.md, "Contact laws"): "paper", the paper's law as docs/model.md states it
#: (rolling friction by ``rolling_friction``); "decco-code", DECCO's pair forces as its code computes
#: them (LucasKolanz/DECCO at fae89d3); "ssdem", pkdgrav's soft-sphere law (Schwartz, Richardson &
#: Michel 2012), with a tangential spring per pair (static friction) and rolling and twisting springs.
CONTACT_LAWS = tuple(name for name in KERNEL_LAWS if name not in LAW_VARIANTS)

#: The constants of the soft-sphere law alone (contact_law = "ssdem"): the other laws read none of them.
SSDEM_CONSTANTS = ("k_t_ratio", "eps_t", "mu_s", "mu_t", "beta", "cohesion")


@dataclass(frozen=True)
class Range:
    """The values a number may take: a test, and its words as messages print them (with a note: a
    unit, or what the number is)."""

    test: Callable[[float], bool]
    words: str
    note: str = ""

    def text(self, brackets: str = "[]") -> str:
        """The words and the note, e.g. "> 0 [dyne/cm]" (``brackets`` "()": "> 0 (dyne/cm)")."""
        return self.words + (f" {brackets[0]}{self.note}{brackets[1]}" if self.note else "")


#: The physical constants' ranges: Params checks them, and the run specification's schema (spec.py)
#: reads the same, so that they live once.
PHYSICS_RANGES = {
    "k_in": Range(lambda v: v > 0, "> 0", "dyne/cm"),
    "restitution": Range(lambda v: 0 < v <= 1, "in (0, 1]"),
    "mu_k": Range(lambda v: v >= 0, ">= 0"),
    "mu_r": Range(lambda v: v >= 0, ">= 0"),
    "k_t_ratio": Range(lambda v: v >= 0, ">= 0", "k_t / k_n"),
    "eps_t": Range(lambda v: 0 < v <= 1, "in (0, 1]"),
    "mu_s": Range(lambda v: v >= 0, ">= 0"),
    "mu_t": Range(lambda v: v >= 0, ">= 0"),
    "beta": Range(lambda v: v >= 0, ">= 0", "R_r / R*"),
    "cohesion": Range(lambda v: v >= 0, ">= 0", "dyne/cm^2"),
    "dt": Range(lambda v: v > 0, "> 0", "s"),
    "G": Range(lambda v: v >= 0, ">= 0", "cm^3 g^-1 s^-2"),
}


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
    # The soft-sphere law ("ssdem", docs/model.md): its normal spring is k_n = k_in / 2 (the pair of
    # the paper's springs in series), its normal restitution eps_n = restitution, and:
    k_t_ratio: float = 2.0 / 7.0
    """ssdem: k_t / k_n, the tangential spring's stiffness over the normal's (pkdgrav's default 2/7:
    the tangential contact frequency equals the normal one)."""
    eps_t: float = 1.0
    """ssdem: sets the tangential dashpot C_t as restitution sets C_n (pkdgrav's dEpsT; 1: none). Not
    the tangential restitution that results (docs/model.md)."""
    mu_s: float = 0.3
    """ssdem: static friction coefficient, the cap of the tangential spring: |F_T| <= mu_s |F_N|."""
    mu_t: float = 0.0
    """ssdem: twisting friction coefficient: the twisting couple slides at mu_t mu_s R_r |F_N|."""
    beta: float = 0.5
    """ssdem: shape parameter: rolling and twisting act at R_r = beta R_i R_j / (R_i + R_j); the
    rolling couple slides at mu_r R_r |F_N|."""
    cohesion: float = 0.0
    """ssdem: cohesive strength c, a tensile stress [dyne/cm^2] (pkdgrav's dCohesiveCoeff, model 0): a
    touching pair attracts with c 4 R_r^2, outside the friction caps."""

    def __post_init__(self):
        for name, allowed in PHYSICS_RANGES.items():
            require_number(self, name, allowed)
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
    def keeps_springs(self) -> bool:
        """Whether the contact law keeps springs per pair (a contact history, saved in snapshots)."""
        return self.law in LAWS_WITH_SPRINGS

    @property
    def k_n(self) -> float:
        """ssdem's normal spring, k_in / 2 [dyne/cm]: the paper's two springs in series (F = k_n x)."""
        return 0.5 * self.k_in

    @property
    def k_t(self) -> float:
        """ssdem's tangential spring, k_t_ratio k_n [dyne/cm]."""
        return self.k_t_ratio * self.k_n

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


def require_number(holder, name: str, allowed: Range) -> None:
    """Check the number ``name`` of a frozen dataclass against its range (InputError naming both), and
    keep it as a float."""
    value = getattr(holder, name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(f"{name} must be a number {allowed.text()}; got {value!r}")
    value = float(value)
    if not math.isfinite(value) or not allowed.test(value):
        raise InputError(f"{name} must be {allowed.text()}; got {value!r}")
    object.__setattr__(holder, name, value)

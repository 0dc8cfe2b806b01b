"""Stability of a set-up: paper sect. 2.5, eqs. 12-17 (docs/model.md, "Stability").

Eq. 15 asks the spring to be stiff enough that the fastest particle cannot
penetrate deeply: k >> (4 pi / 3) rho r_max v_max^2.  Eq. 17 asks the step to
resolve the stiffest oscillation: dt << sqrt(m_min / k).

Eq. 15 is printed with r_max^2, which has units of a force (dyne), not of a
spring constant (dyne/cm).  It comes from eq. 14, which reduces to
(4 pi / 3) rho r v^2 = m v^2 / r^2 for the lighter sphere of a pair; that is the
dimensionally consistent form used here, taken over the particles as
max(m / R^2) v_max^2.  (With r_max^2 the paper's own k_in = 1e18 would fail
its 1 km/s collisions by six orders of magnitude; with r_max it passes with a
margin of about 4, as the paper says it does.)

A margin is bound / need: how many times over the inequality holds.

Eq. 12 assumes the lighter sphere of a pair moves.  In a collision of piles the
deepest contacts come from a heavy sphere driven into a light one that its own
pile holds in place; :func:`predict_compression` takes eq. 12 with i the
heaviest sphere and j the lightest in that limit, and :func:`choose_stiffness`
inverts it for ``k_in = "auto"``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .params import Params
from .state import State
from .errors import InputError, StabilityError  # noqa: F401 (re-exported: the error lives in errors.py)

#: Smallest accepted eq. 15 margin: below 1 the deepest compression exceeds the
#: particle radius (Delta ~ R / sqrt(margin)), and spheres can pass through each other.
MIN_STIFFNESS_MARGIN = 1.0
#: Smallest accepted eq. 17 margin: with 10, a contact between the lightest
#: particles lasts ~30 steps (half period pi sqrt(m/k) of the paired springs).
MIN_TIME_STEP_MARGIN = 10.0


@dataclass(frozen=True)
class StabilityReport:
    """Both margins of paper sect. 2.5 for one state and one set of parameters."""

    stiffness_margin: float
    """k_in / k_needed (eq. 15); inf when nothing moves."""
    time_step_margin: float
    """sqrt(m_min / k_in) / dt (eq. 17)."""
    k_needed: float
    """(4 pi / 3) rho r v_max^2 = max(m / R^2) v_max^2 [dyne/cm]."""
    dt_scale: float
    """sqrt(m_min / k_in) [s]."""
    v_max: float
    """Fastest particle speed in the centre-of-mass frame [cm/s]."""
    k_in: float
    dt: float

    @property
    def stable(self) -> bool:
        return self.stiffness_margin >= MIN_STIFFNESS_MARGIN and self.time_step_margin >= MIN_TIME_STEP_MARGIN

    @property
    def safe_k_in(self) -> float:
        """Smallest k_in that meets eq. 15 with the required margin [dyne/cm]."""
        return MIN_STIFFNESS_MARGIN * self.k_needed

    @property
    def safe_dt(self) -> float:
        """Largest dt that meets eq. 17 with the required margin [s]."""
        return self.dt_scale / MIN_TIME_STEP_MARGIN

    def problems(self) -> list[str]:
        """One sentence per violated condition, naming the quantity and a safe value."""
        found = []
        if self.stiffness_margin < MIN_STIFFNESS_MARGIN:
            found.append(
                f"k_in = {self.k_in:.3g} dyne/cm is too soft for v_max = {self.v_max:.3g} cm/s "
                f"(eq. 15 margin {self.stiffness_margin:.3g}, need >= {MIN_STIFFNESS_MARGIN:g}); "
                f"use k_in >= {self.safe_k_in:.3g} dyne/cm"
            )
        if self.time_step_margin < MIN_TIME_STEP_MARGIN:
            found.append(
                f"dt = {self.dt:.3g} s is too long for sqrt(m_min/k_in) = {self.dt_scale:.3g} s "
                f"(eq. 17 margin {self.time_step_margin:.3g}, need >= {MIN_TIME_STEP_MARGIN:g}); "
                f"use dt <= {self.safe_dt:.3g} s"
            )
        return found

    def summary(self) -> str:
        return (
            f"eq. 15 stiffness margin {self.stiffness_margin:.3g} (need >= {MIN_STIFFNESS_MARGIN:g}), "
            f"eq. 17 time-step margin {self.time_step_margin:.3g} (need >= {MIN_TIME_STEP_MARGIN:g})"
        )


def check_stability(state: State, params: Params) -> StabilityReport:
    """Margins of eqs. 15 and 17 for ``state`` and ``params``; never raises."""
    masses = state.masses
    centre_velocity = (masses[:, None] * state.velocities).sum(axis=0) / masses.sum()
    v_max = float(np.sqrt(((state.velocities - centre_velocity) ** 2).sum(axis=1)).max())
    k_needed = float((masses / state.radii**2).max()) * v_max**2
    dt_scale = math.sqrt(float(masses.min()) / params.k_in)
    return StabilityReport(
        stiffness_margin=params.k_in / k_needed if k_needed > 0 else math.inf,
        time_step_margin=dt_scale / params.dt,
        k_needed=k_needed,
        dt_scale=dt_scale,
        v_max=v_max,
        k_in=params.k_in,
        dt=params.dt,
    )


# --- the deepest compression of a collision (eq. 12 with i the heavier sphere) ---------

#: Default of ``[params] max_compression``: the deepest overlap ``k_in = "auto"`` allows,
#: as a fraction of the smallest radius.
DEFAULT_MAX_COMPRESSION = 0.1


@dataclass(frozen=True)
class CompressionForecast:
    """The deepest overlap a set-up should reach, from its impact speed (paper eq. 12).

    The heaviest sphere, arriving at the impact speed, drives into the lightest one,
    which its pile holds in place: eq. 12 with i the heavier sphere and m_j -> infinity,
    so that its whole kinetic energy 1/2 m_H v^2 goes into the contact spring,
    (k_in / 4) delta^2 (two springs in series).  Hence delta = v sqrt(2 m_H / k_in).
    It is an upper estimate: the collisions measured so far reach 0.24 to 0.43 of it
    (docs/model.md); a free light sphere (eq. 12 as printed, in the pair's frame)
    would give v sqrt(2 mu / k_in), about 5 times less at the paper's sizes.
    """

    impact_speed: float
    """Largest approach speed of a particle of one pile to one of the other [cm/s]."""
    heavy_mass: float
    """Mass of the heaviest sphere [g]."""
    light_mass: float
    """Mass of the lightest sphere [g]."""
    light_radius: float
    """Radius of the lightest sphere [cm]."""
    k_in: float
    overlap: float
    """Predicted deepest overlap delta [cm]."""

    @property
    def fraction(self) -> float:
        """The predicted deepest overlap as a fraction of the lightest sphere's radius."""
        return self.overlap / self.light_radius

    def summary(self) -> str:
        return (
            f"predicted deepest overlap {self.fraction:.3g} of the smallest radius ({self.overlap:.3g} cm: "
            f"a {self.heavy_mass:.3g} g sphere at the impact speed {self.impact_speed:.4g} cm/s into a "
            f"{self.light_mass:.3g} g one held by its pile, eq. 12)"
        )


def impact_speed(state: State) -> float:
    """The largest speed at which a particle of one pile can approach one of the other [cm/s].

    With two piles (``pile_id`` 0 and 1): max |v_p - V_t| over the projectile's particles
    plus max |v_t - V_t| over the target's (V_t the target's bulk velocity), which bounds
    every cross-pile approach speed, spins included.  With one pile: twice the fastest
    particle's speed in its centre-of-mass frame.
    """
    masses, velocities = state.masses, state.velocities
    pile_id = state.pile_id if state.pile_id is not None else np.zeros(state.n, dtype=np.int32)
    target = pile_id == 0
    if target.all() or not target.any():
        bulk = (masses[:, None] * velocities).sum(axis=0) / masses.sum()
        return 2.0 * float(np.linalg.norm(velocities - bulk, axis=1).max())
    bulk_t = (masses[target, None] * velocities[target]).sum(axis=0) / masses[target].sum()
    relative = np.linalg.norm(velocities - bulk_t, axis=1)
    return float(relative[~target].max() + relative[target].max())


def predict_compression(state: State, k_in: float) -> CompressionForecast:
    """The deepest overlap ``state``'s collision should reach with spring constant ``k_in``."""
    heavy, light = int(np.argmax(state.masses)), int(np.argmin(state.masses))
    speed = impact_speed(state)
    return CompressionForecast(
        impact_speed=speed,
        heavy_mass=float(state.masses[heavy]),
        light_mass=float(state.masses[light]),
        light_radius=float(state.radii[light]),
        k_in=float(k_in),
        overlap=speed * math.sqrt(2.0 * float(state.masses[heavy]) / k_in),
    )


def choose_stiffness(state: State, max_compression: float = DEFAULT_MAX_COMPRESSION) -> float:
    """k_in for ``k_in = "auto"``: the softest spring whose predicted deepest overlap (eq. 12,
    :func:`predict_compression`) stays within ``max_compression`` of the smallest radius,
    rounded up to three significant digits [dyne/cm]."""
    if not 0 < max_compression <= 1:
        raise InputError(f"max_compression must be in (0, 1] (fraction of the smallest radius); got {max_compression!r}")
    probe = predict_compression(state, 1.0)  # the overlap scales as 1/sqrt(k_in)
    if not probe.overlap > 0:
        raise InputError("the particles do not move (impact speed 0), so no spring constant follows from eq. 12")
    return _round_sig((probe.overlap / (max_compression * probe.light_radius)) ** 2, up=True)


def choose_time_step(state: State, k_in: float) -> float:
    """dt for ``dt = "auto"``: eq. 17 with the required margin, sqrt(m_min / k_in) / 10,
    rounded down to three significant digits [s]."""
    return _round_sig(math.sqrt(float(state.masses.min()) / k_in) / MIN_TIME_STEP_MARGIN, up=False)


def _round_sig(value: float, up: bool, digits: int = 3) -> float:
    scale = 10.0 ** (math.floor(math.log10(value)) - digits + 1)
    rounded = (math.ceil if up else math.floor)(value / scale * (1 - 1e-12 if up else 1 + 1e-12)) * scale
    return float(f"{rounded:.{digits}g}")

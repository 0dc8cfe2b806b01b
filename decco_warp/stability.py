"""Stability of a set-up: paper sect. 2.5, eqs. 15 and 17.

Eq. 15 asks the spring to be stiff enough that the fastest particle cannot
penetrate deeply: k >> (4 pi / 3) rho r_max v_max^2.  Eq. 17 asks the step to
resolve the stiffest oscillation: dt << sqrt(m_min / k).

Eq. 15 is printed (and copied in physics.md) with r_max^2, which has units of a
force (dyne), not of a spring constant (dyne/cm).  It comes from eq. 14, which
reduces to (4 pi / 3) rho r v^2 = m v^2 / r^2 for the lighter sphere of a pair;
that is the dimensionally consistent form used here, taken over the particles as
max(m / R^2) v_max^2.  (With r_max^2 the paper's own k_in = 1e18 would fail
its 1 km/s collisions by six orders of magnitude; with r_max it passes with a
margin of about 4, as the paper says it does.)

A margin is bound / need: how many times over the inequality holds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .params import Params
from .state import State

#: Smallest accepted eq. 15 margin: below 1 the deepest compression exceeds the
#: particle radius (Delta ~ R / sqrt(margin)), and spheres can pass through each other.
MIN_STIFFNESS_MARGIN = 1.0
#: Smallest accepted eq. 17 margin: with 10, a contact between the lightest
#: particles lasts ~30 steps (half period pi sqrt(m/k) of the paired springs).
MIN_TIME_STEP_MARGIN = 10.0


class StabilityError(ValueError):
    """A set-up that violates eq. 15 or 17; ``.report`` holds the numbers."""

    def __init__(self, report: "StabilityReport"):
        self.report = report
        super().__init__("unstable set-up: " + "; ".join(report.problems()))


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

"""The user's world: a State, its Params, and a device that advances it."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import warp as wp

from .engine import Engine, Layout
from .params import Params
from .stability import StabilityError, StabilityReport, check_stability
from .state import State

#: Steps recorded into one CUDA graph and replayed as a unit.
GRAPH_STEPS = 50


class Simulation:
    """A particle system being integrated on one device.

    >>> sim = Simulation(state, Params(), device="cpu")
    >>> sim.step(100)               # 100 steps of params.dt
    >>> later = sim.state           # a host copy, State
    >>> diagnostics(later, sim.params)

    The set-up is checked against paper eqs. 15 and 17 first; an unstable one
    raises :class:`StabilityError` unless ``allow_unstable=True``.
    """

    def __init__(
        self,
        state: State,
        params: Params,
        device: str | None = None,
        precision: str = "mixed",
        allow_unstable: bool = False,
        force_kernel: str = "tiled",
        layout: Layout | None = None,
    ):
        self.params = params
        self.stability: StabilityReport = check_stability(state, params)
        if not self.stability.stable and not allow_unstable:
            raise StabilityError(self.stability)
        self._static = state.copy()
        self.engine = Engine(state, params, device, precision, force_kernel, layout)
        self._time0 = state.time
        self._step0 = state.step
        self._steps = 0
        self._graph = None
        # Forces at x(0) with v(0): the first half kick needs them.
        self.engine.eval_forces()

    @property
    def device(self) -> str:
        return self.engine.device

    @property
    def step_count(self) -> int:
        """Steps taken since the run began (including those before a restart)."""
        return self._step0 + self._steps

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self._time0 + self._steps * self.params.dt

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps of ``params.dt``.  On CUDA, whole blocks of steps replay a graph."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f"step count must be a non-negative integer; got {n!r}")
        n = int(n)
        if self.engine.device.startswith("cuda"):
            while n >= GRAPH_STEPS:
                wp.capture_launch(self._step_graph())
                n -= GRAPH_STEPS
                self._steps += GRAPH_STEPS
        for _ in range(n):
            self.engine.step()
            self._steps += 1

    def _step_graph(self):
        if self._graph is None:
            with wp.ScopedCapture(device=self.engine.device) as capture:
                for _ in range(GRAPH_STEPS):
                    self.engine.step()
            self._graph = capture.graph
        return self._graph

    @property
    def state(self) -> State:
        """A host copy of the current state."""
        positions, velocities, omegas = self.engine.read()
        return replace(
            self._static.copy(),
            positions=positions,
            velocities=velocities,
            omegas=omegas,
            time=self.time,
            step=self.step_count,
        )

    def forces(self) -> tuple[np.ndarray, np.ndarray]:
        """Force [dyne] and torque [dyne cm] of the last evaluation, (N, 3) float64 each."""
        return self.engine.read_forces()


def compute_forces(
    state: State,
    params: Params,
    device: str | None = None,
    precision: str = "mixed",
    force_kernel: str = "tiled",
    layout: Layout | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Force [dyne] and torque [dyne cm] on every particle, with the kernels that Simulation steps with.

    >>> force, torque = compute_forces(state, Params(), device="cpu")
    """
    engine = Engine(state, params, device, precision, force_kernel, layout)
    engine.eval_forces()
    return engine.read_forces()

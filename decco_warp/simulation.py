"""The user's world: a State, its Params, and a device that advances it."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import warp as wp

from .diagnostics import ENERGY_START_KEYS, state_diagnostics
from .engine import Engine
from .layouts import Layout
from .params import Params
from .scheme import Scheme
from .stability import StabilityError, StabilityReport, check_stability
from .state import State
from .errors import InputError

#: Steps recorded into one graph and replayed as a unit (CUDA graphs; on the CPU, Warp's recorded
#: graphs replay the kernels without Python between them).
GRAPH_STEPS = 50


def graph_steps(step_multiple: int) -> int:
    """The steps of one recorded graph: GRAPH_STEPS, or whole outer steps of ``step_multiple`` steps
    (as many as fit in GRAPH_STEPS, at least one)."""
    return step_multiple * max(1, GRAPH_STEPS // step_multiple)


class Simulation:
    """A particle system being integrated on one device.

    >>> sim = Simulation(state, Params(), device="cpu")
    >>> sim.step(100)               # 100 steps of params.dt
    >>> clocked = Simulation(state, Params(), scheme=Scheme(gravity_every=10))   # gravity every 10 steps
    >>> later = sim.state           # a host copy, State
    >>> diagnostics(later, sim.params)

    The set-up is checked against paper eqs. 15 and 17 first (or ``stability``, that check made
    already); an unstable one raises :class:`StabilityError` unless ``allow_unstable=True``.  With
    ``ledger=True`` the work of each force channel is tracked, so that
    :meth:`energy_ledger` accounts for every erg.
    """

    def __init__(
        self,
        state: State,
        params: Params,
        device: str | None = None,
        precision: str | None = None,
        allow_unstable: bool = False,
        force_kernel: str | None = None,
        layout: Layout | None = None,
        ledger: bool = False,
        systems: Sequence[int] | None = None,
        stability: StabilityReport | None = None,
        scheme: Scheme | None = None,
    ):
        self.params = params
        # A run's plan has made the report for this state and params already.
        self.stability: StabilityReport = stability or check_stability(state, params)
        if not self.stability.stable and not allow_unstable:
            raise StabilityError(self.stability)
        self._static = state.copy()
        self.engine = Engine(state, params, device, precision, force_kernel, layout, ledger, systems, scheme)
        # Time is origin + step * dt, never a running sum, so that a restarted run keeps the same clock.
        self._time_origin = state.time - state.step * params.dt
        self._step = state.step
        self._graph = None
        self._graph_flipped = False  # the contact history's roles the graph was recorded with
        self._graph_steps = graph_steps(self.step_multiple)
        # A loop or branch decided on the device (the tree's levels) is a conditional graph node on
        # CUDA (driver and toolkit 12.4+); without them steps are launched one by one, which gives
        # the same numbers.
        conditional_nodes = not self.engine.device.startswith("cuda") or wp.is_conditional_graph_supported()
        self._record = not self.engine.path.graph_conditionals or conditional_nodes
        # Forces at x(0) with v(0): the first half kick needs them.
        self.engine.eval_forces()
        self.energy_start: dict | None = self.diagnostics() if ledger else None
        """Diagnostics when the ledger started: its reference point."""

    @classmethod
    def from_snapshot(
        cls, state: State, params: Params, snapshot: dict, device: str | None = None, **options
    ) -> "Simulation":
        """Continue exactly where :meth:`snapshot` left off (``state`` gives the static arrays).

        The stability check is not repeated: the run was accepted when it began.
        """
        options.setdefault("allow_unstable", True)
        start = replace(
            state,
            positions=snapshot["positions"],
            velocities=snapshot["velocities"],
            omegas=snapshot["omegas"],
            time=float(snapshot["time_origin"]) + int(snapshot["step"]) * params.dt,
            step=int(snapshot["step"]),
        )
        sim = cls(start, params, device=device, ledger=bool(snapshot["ledger"]), **options)
        sim.engine.restore(snapshot)
        sim._time_origin = float(snapshot["time_origin"])
        if sim.engine.ledger:
            sim.energy_start = {key: float(value) for key, value in snapshot["energy_start"].items()}
        return sim

    def snapshot(self) -> dict:
        """Every array and number the next step depends on (host copies): a bit-exact restart point."""
        snap = self.engine.snapshot()
        snap.update(step=self._step, time_origin=self._time_origin, ledger=self.engine.ledger)
        if self.energy_start is not None:
            snap["energy_start"] = {key: self.energy_start.get(key, 0.0) for key in ENERGY_START_KEYS}
        return snap

    @property
    def step_multiple(self) -> int:
        """Steps of an outer step (with gravity on its own clock, its K; else 1): every step count is a
        multiple of it."""
        return self.engine.step_multiple

    @property
    def scheme(self) -> Scheme:
        """How the model is evaluated (scheme.py)."""
        return self.engine.scheme

    @property
    def device(self) -> str:
        return self.engine.device

    @property
    def step_count(self) -> int:
        """Steps taken since the run began (including those before a restart)."""
        return self._step

    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return self._time_origin + self._step * self.params.dt

    def step(self, n: int = 1) -> None:
        """Advance ``n`` steps of ``params.dt`` (with gravity on its own clock, a multiple of
        ``scheme.step_multiple``: whole outer steps): whole blocks of steps replay a recorded graph
        (the steps of a block, and those left over, share launches: :meth:`Engine.advance`)."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise InputError(f"step count must be a non-negative integer; got {n!r}")
        n = int(n)
        every = self.step_multiple
        if n % every:
            raise InputError(f"with gravity_every = {every} the step count must be a multiple of {every} (whole outer steps); got {n}")
        while self._record and n >= self._graph_steps:
            graph = self._step_graph()
            if graph is None:
                break
            # The graph reads the contact history's buffers in the roles they had when it was recorded
            # (after an odd count of steps launched one by one they are the other way round: one copy).
            self.engine.state.history.settle(self._graph_flipped)
            wp.capture_launch(graph)
            n -= self._graph_steps
            self._step += self._graph_steps
        self.engine.advance(n)
        self._step += n

    def finish(self) -> None:
        """Wait until the device has done every step asked of it (steps on CUDA return at once)."""
        wp.synchronize_device(self.engine.device)

    def _step_graph(self):
        """The recorded block of steps, recorded at the first call; None if recording failed (a
        recording only records: nothing was stepped, and steps go on one launch at a time)."""
        if self._graph is None:
            # Each contact evaluation swaps the contact history's buffers in Python (arrays.ContactHistory),
            # so the recorded launches alternate them as stepping does; the graph, replayed with no
            # Python between, must leave the roles as it found them: after an odd count of evaluations
            # (e.g. K = 7, 49 steps) it ends with one copy that turns them back.
            history = self.engine.state.history
            flipped = history.flipped
            try:
                with wp.ScopedCapture(device=self.engine.device) as capture:
                    self.engine.advance(self._graph_steps)
                    history.settle(flipped)
            except Exception as error:  # e.g. a driver without conditional graph nodes for the tree
                history.flipped = flipped  # nothing ran: the roles are those before the recording
                warnings.warn(f"steps are launched one by one: recording them in a graph failed ({error})", stacklevel=3)
                self._record = False
                return None
            self._graph, self._graph_flipped = capture.graph, flipped
        return self._graph

    @property
    def static(self) -> State:
        """The state this simulation began from, for its per-particle constants (radii, masses, ...)."""
        return self._static

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

    def pair_observables(self) -> dict[str, np.ndarray]:
        """Per particle: half its pair potential and elastic energy, its contacts and largest overlap."""
        return self.engine.pair_observables()

    def diagnostics(self, state: State | None = None, pairs: dict | None = None) -> dict:
        """:func:`decco_warp.diagnostics` of the current state, computed on this simulation's device."""
        state = self.state if state is None else state
        pairs = self.pair_observables() if pairs is None else pairs
        return state_diagnostics(state, pairs)

    def neighbour_list_builds(self, system: int | None = None) -> int | None:
        """Builds of the contacts' neighbour lists since this simulation was made or restored
        (gravity_every > 1; None otherwise: no list is kept), of one ``system`` of an ensemble or
        the most of any."""
        return self.engine.path.list_builds(system)

    def candidate_overflows(self) -> int:
        """Particles whose contact candidates overflowed their list at the last force evaluation."""
        return self.engine.candidate_overflows()

    def history_overflows(self) -> int:
        """Particles that touched more particles than their contact history holds at the last force
        evaluation (a law with springs per pair; 0 otherwise): the springs of the others were not kept."""
        return self.engine.history_overflows()

    def take_deepest_contact(self) -> dict:
        """The deepest contact any step met since the last call (or since this simulation was made or
        restored): ``deepest_overlap`` (fraction of the smaller radius) and ``deepest_overlap_pair``."""
        return self.engine.take_deepest_contact()

    def work(self) -> np.ndarray:
        """Work of (gravity, spring, sliding, rolling) on each particle since the ledger began [erg], (N, 4)."""
        return self.engine.read_work()


def compute_forces(
    state: State,
    params: Params,
    device: str | None = None,
    precision: str | None = None,
    force_kernel: str | None = None,
    layout: Layout | None = None,
    scheme: Scheme | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Force [dyne] and torque [dyne cm] on every particle, with the kernels that Simulation steps with.

    >>> force, torque = compute_forces(state, Params(), device="cpu")
    """
    engine = Engine(state, params, device, precision, force_kernel, layout, scheme=scheme)
    engine.eval_forces()
    return engine.read_forces()

"""Integrators: kick-drift-kick on one clock, and on two (gravity every K steps), each owning its kick
launches and its clock (kernels/integrate.py).

    integrator = integrator_for(scheme)(model, state, path, scheme)   # as Engine does
    integrator.step()            # one step (K > 1: one outer step of K), a launch a stage
    integrator.advance(steps)    # ``steps`` steps, a step's closing kick and the next's opening kick
                                 # and drift in one launch: the same numbers, bit for bit

The force path (decco_warp/forces.py) gives the forces; the integrator decides when they are
evaluated and how the velocities take them; the path packs its sweep's bodies (``path.pack``) for
the stages that pack them in a launch of their own.
"""

from __future__ import annotations

import warp as wp

from .arrays import ModelArrays, StateArrays
from .errors import InputError
from .forces import ForcePath
from .kernels import integrate
from .kernels.bodies import BODY_TYPES
from .layouts import particle_block
from .scheme import Scheme


class OneClock:
    """Kick-drift-kick (paper eq. 1): gravity and contacts every step."""

    clocks = 1

    def __init__(self, model: ModelArrays, state: StateArrays, path: ForcePath, scheme: Scheme):
        self.model, self.state, self.path, self.scheme = model, state, path, scheme
        self.every = 1
        self._no_body = wp.zeros(0, dtype=BODY_TYPES[scheme.precision], device=model.device)  # a kick_drift that packs none

    def evaluate(self) -> None:
        """The forces at the current state (the bodies packed first)."""
        self.path.pack()
        self.path.evaluate()

    def kick_drift(self, close_step: bool = False, pack: bool = False) -> None:
        """Half kick with the current forces, then a full drift; with ``close_step`` first the last
        half kick of the step before (:meth:`kick`), with ``pack`` then the packing of the bodies
        for the sweep, in the same launch."""
        m, s = self.model, self.state
        wp.launch(
            integrate.KICK_DRIFT[self.scheme.precision],
            dim=m.count,
            inputs=[wp.float64(m.params.dt), wp.float64(m.params.G), m.radius, m.mass, m.inertia, s.force, s.torque, s.channels, close_step],
            outputs=[s.position, s.velocity, s.omega, s.work, self.path.body if pack else self._no_body],
            device=m.device,
            block_dim=particle_block(),
        )  # fmt: skip

    def kick(self) -> None:
        """Second half kick with the forces at the new positions."""
        m, s = self.model, self.state
        wp.launch(
            integrate.kick,
            dim=m.count,
            inputs=[wp.float64(m.params.dt), m.mass, m.inertia, s.force, s.torque, s.channels],
            outputs=[s.velocity, s.omega, s.work],
            device=m.device,
            block_dim=particle_block(),
        )

    def step(self) -> None:
        """One step, each stage a launch of its own: kick-drift, the forces at x(n+1) with the
        half-step velocities, kick."""
        self.kick_drift()
        self.evaluate()
        self.kick()

    def advance(self, steps: int) -> None:
        """``steps`` steps: a step's last half kick, the next one's first half kick and drift and the
        packing of its bodies are one launch (kernels/integrate.py ``kick_drift``)."""
        for k in range(steps):
            self.kick_drift(close_step=k > 0, pack=True)
            self.path.evaluate()
        if steps > 0:
            self.kick()


class TwoClocks(OneClock):
    """Gravity on its own clock (impulse multiple time stepping, docs/model.md): one outer step of K
    steps is a gravity half kick of K dt / 2, K kick-drift-kick steps of the contacts alone, gravity
    at the new positions and the second gravity half kick.  The path is forces.ClockedForces."""

    clocks = 2

    def __init__(self, model: ModelArrays, state: StateArrays, path: ForcePath, scheme: Scheme):
        super().__init__(model, state, path, scheme)
        self.every = scheme.step_multiple

    def kick_outer(self, close_step: bool = False) -> None:
        """A gravity half kick of K dt / 2; with ``close_step`` first the last contact half kick (:meth:`kick`)."""
        m, s = self.model, self.state
        wp.launch(
            integrate.kick_outer,
            dim=m.count,
            inputs=[wp.float64(m.params.dt), wp.float64(self.every * m.params.dt), m.mass, m.inertia, s.force, s.torque,
                    s.channels, self.path.gravity_force, close_step],
            outputs=[s.velocity, s.omega, s.work],
            device=m.device,
            block_dim=particle_block(),
        )  # fmt: skip

    def kick_drift_inner(self, close_step: bool = False, gravity_kicks: int = 0, pack: bool = False) -> None:
        """A contact half kick and a full drift, then the neighbour list's displacement check; with
        ``close_step`` first the last contact half kick of the step before, then ``gravity_kicks``
        gravity half kicks (closing and opening outer steps); with ``pack`` the packing of the bodies
        for the gravity sweep after the drift."""
        m, s = self.model, self.state
        neighbours = self.path.finder
        wp.launch(
            integrate.KICK_DRIFT_INNER[self.scheme.precision],
            dim=m.count,
            inputs=[wp.float64(m.params.dt), wp.float64(self.every * m.params.dt), wp.float64(m.params.G),
                    m.radius, m.mass, m.inertia, neighbours.system, wp.float64(0.5 * neighbours.skin),
                    s.force, s.torque, s.channels, self.path.gravity_force, close_step, gravity_kicks, neighbours.reference],
            outputs=[s.position, s.velocity, s.omega, s.work, neighbours.stale, neighbours.stale_system,
                     self.path.body if pack else self._no_body],
            device=m.device,
            block_dim=particle_block(),
        )  # fmt: skip

    def step(self) -> None:
        """One outer step of K steps, each stage a launch of its own."""
        self.kick_outer()
        for k in range(self.every):
            self.kick_drift_inner(pack=k == self.every - 1)
            self.path.contacts()
            self.kick()
        self.path.gravity_step()
        self.kick_outer()

    def advance(self, steps: int) -> None:
        """``steps`` steps (a multiple of K), the kicks that meet between them in one launch
        (kernels/integrate.py ``kick_drift_inner``)."""
        outer_steps = steps // self.every
        last = self.every - 1
        for s in range(outer_steps):
            for k in range(self.every):
                # The first inner step opens the outer step's gravity kick (after closing the one before).
                self.kick_drift_inner(close_step=s > 0 or k > 0, gravity_kicks=(2 if s > 0 else 1) if k == 0 else 0, pack=k == last)
                self.path.contacts()
            self.path.gravity_step()
        if outer_steps > 0:
            self.kick_outer(close_step=True)


#: The integrators, by their number of clocks.
INTEGRATORS = {integrator.clocks: integrator for integrator in (OneClock, TwoClocks)}


def integrator_for(scheme: Scheme) -> type:
    """The integrator of a scheme: one clock at K = 1 (the paper's), two where gravity has its own."""
    return INTEGRATORS[scheme.clocks]


def check_steps(steps: int, every: int) -> None:
    """Refuse a step count that is not whole outer steps of ``every``."""
    if steps % every:
        raise InputError(f"steps must be a multiple of gravity_every = {every}; got {steps}")

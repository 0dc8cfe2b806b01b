"""Force paths: how the parts that compute a step's forces are composed for a scheme.

A path is either one kernel that sums gravity and contacts together (the plain "reference" kernel,
the "fused" layout), or a gravity solver (decco_warp/gravity_solvers.py), a contact finder
(decco_warp/contact_finders.py) and the :class:`ContactPass`, which applies the contact law to the
finder's candidates in float64:

    path = force_path(scheme)(model, state, scheme)   # as Engine does
    path.evaluate()        # state.force, torque, channels, deepest_contact (bodies packed first)
    path.contacts()        # gravity on its own clock: the contacts of an inner step
    path.gravity_step()    # and gravity, into path.gravity_force
    path.observables(outputs)

Each path says which schemes it serves (``serves``), and :func:`force_path` takes the first in
:data:`FORCE_PATHS` that does.  "solver" (gravity and contacts on one clock) composes the scheme's
gravity solver, whatever its name, with the finder its class names: "all-pairs" with its own
"sweep-bits" (the Newton layout), "tree" with its "hash-grid"; "clocked" (gravity every K steps)
composes it, listing nothing, with a "neighbour-list".  So a new solver or finder is a class and its
registration there, and no path here changes; a new composition is one class here and its place in
:data:`FORCE_PATHS`.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .arrays import ModelArrays, StateArrays
from .contact_finders import CONTACT_FINDERS, ContactFinder, NeighbourList
from .errors import InputError
from .gravity_solvers import GRAVITY_SOLVERS, GravitySolver, packed_bodies
from .kernels import observables as observable_kernels
from .kernels.bodies import PACK_KERNELS
from .kernels.contacts import contact_pass
from .kernels.fused import pair_forces_tiled
from .kernels.reference import pair_forces_reference
from .layouts import particle_block
from .scheme import Scheme

#: Threads per particle of the observables kernel on a GPU.
OBSERVABLES_BLOCK = 128
#: The contact pass's lanes per particle and particles per block on a GPU (one and one on the
#: CPU): ~8 listed candidates a particle, one a lane (kernels/contacts.py ``contact_pass``).
CONTACT_LANES = 8
CONTACT_PARTICLES = 4


def tiled_blocks(starts: np.ndarray, ends: np.ndarray, per_block: int) -> np.ndarray:
    """Per block of a tiled launch: (first row, end of its rows, first and end of its system)."""
    rows = [
        (first, min(first + per_block, end), start, end)
        for start, end in zip(starts, ends)
        for first in range(int(start), int(end), per_block)
    ]
    return np.array(rows, dtype=np.int32).reshape(-1, 4)


def _on_cuda(device: str) -> bool:
    return device.startswith("cuda")


class ContactPass:
    """The contact law applied to listed candidates (lists in increasing j), CONTACT_PARTICLES
    particles a block of CONTACT_LANES lanes each on a GPU (kernels/contacts.py ``contact_pass``: one
    thread per particle would leave most of the GPU idle, a few warps per SM at paper sizes); one
    lane on the CPU, or the GPU's blocks with Warp's CPU blocks on (tests check the lanes' reduction
    so).  A law with springs takes the same lanes: each contact's row is its rank in the list, so the
    rows are those of one lane.  With ``accumulate`` the contact force is added to gravity's in
    state.force, else written there alone."""

    def __init__(self, model: ModelArrays, accumulate: bool):
        self.model, self.accumulate = model, accumulate
        blocks = _on_cuda(model.device) or wp.config.enable_cpu_blocks
        self.lanes, self.particles = (CONTACT_LANES, CONTACT_PARTICLES) if blocks else (1, 1)
        self.kernel = contact_pass(model.params.law, self.lanes, self.particles, accumulate)

    def launch(self, state: StateArrays, finder: ContactFinder) -> None:
        m = self.model
        wp.launch_tiled(
            self.kernel,
            dim=[-(-m.count // self.particles)],
            block_dim=self.lanes * self.particles,
            inputs=[m.contact, m.ranges, m.radius, m.mass, *state.contact_inputs(), finder.candidate_count, finder.candidates],
            outputs=state.contact_outputs(),
            device=m.device,
        )
        state.history.commit()


class ForcePath:
    """What every force path gives the engine.  ``body``: the packed bodies its sweep reads (empty
    where none: :meth:`pack` packs them before :meth:`evaluate`); ``finder``: its contact finder (None
    where one kernel finds and evaluates the contacts)."""

    name = ""
    finder: ContactFinder | None = None
    gravity: GravitySolver | None = None

    @staticmethod
    def serves(scheme: Scheme) -> bool:
        """Whether this path computes the forces of ``scheme`` (:func:`force_path` asks the paths in order)."""
        raise NotImplementedError

    def __init__(self, model: ModelArrays, state: StateArrays, scheme: Scheme):
        self.model, self.state, self.scheme = model, state, scheme
        self.body = packed_bodies(model, scheme, 0)

    def _solver(self, listing: bool) -> GravitySolver:
        """The scheme's gravity solver (its packed bodies become the path's)."""
        solver = GRAVITY_SOLVERS[self.scheme.gravity](self.model, self.scheme, listing)
        if solver.body is not None:
            self.body = solver.body
        return solver

    @property
    def graph_conditionals(self) -> bool:
        """Whether its launches hold a loop or branch decided on the device (wp.capture_while,
        wp.capture_if): a CUDA graph of them needs conditional nodes (driver and toolkit 12.4+)."""
        return any(part is not None and part.graph_conditionals for part in (self.gravity, self.finder))

    def evaluate(self) -> None:
        """state.force, torque, channels (with the ledger) and deepest_contact at the current state."""
        raise NotImplementedError

    def total_force(self) -> np.ndarray:
        """The force on every particle at the last evaluation [dyne], a host copy."""
        return self.state.force.numpy().copy()

    def observables(self, outputs: dict) -> None:
        """Per particle, into ``outputs`` (engine.PAIR_OBSERVABLES): over every pair of its system, a
        block of threads per particle on a GPU (N threads alone would leave most of it idle); where the
        gravity solver has its own potential, that and the contacts of the finder's candidates (O(N log N))."""
        m, s = self.model, self.state
        potential, *contacts = outputs.values()
        if self.gravity is not None and self.finder is not None and self.gravity.potential(s, potential):
            if not self.finder.current:
                self.finder.find(s)
            wp.launch(
                observable_kernels.candidate_observables,
                dim=m.count,
                inputs=[m.contact, m.ranges, m.radius, s.position, s.velocity, self.finder.candidate_count, self.finder.candidates],
                outputs=contacts,
                device=m.device,
            )
            return
        block_dim = OBSERVABLES_BLOCK if _on_cuda(m.device) else 1
        wp.launch_tiled(
            observable_kernels.pair_observables_tiled(block_dim),
            dim=[m.count],
            inputs=[m.contact, m.ranges, m.radius, m.mass, s.position, s.velocity],
            outputs=list(outputs.values()),
            block_dim=block_dim,
            device=m.device,
        )

    def candidate_overflows(self, first: int = 0, end: int | None = None) -> int:
        """Particles (of rows [first, end)) whose contact candidates overflowed their list at the last
        evaluation (0 where no list is kept): each costs a walk over its whole system."""
        return 0 if self.finder is None else self.finder.overflows(first, end)

    def list_builds(self, system: int | None = None) -> int | None:
        """Builds of a system's neighbour lists since the engine began or was restored (``system``
        None: the most of any system; None: the path keeps none)."""
        return None if self.finder is None else self.finder.builds(system)

    def arrays(self) -> dict[str, np.ndarray]:
        """Per-particle arrays beside the state's that a snapshot must hold for the path to go on bit for bit
        (its finder's lists; the contacts' springs are the state's own, arrays.ContactHistory)."""
        return {} if self.finder is None else self.finder.arrays()

    def pack(self) -> None:
        """The sweep's packed bodies (``body``) from the current positions (none unless the path reads them)."""
        if self.body.shape[0] > 0:
            m = self.model
            wp.launch(
                PACK_KERNELS[self.scheme.precision],
                dim=m.count,
                inputs=[wp.float64(m.params.G), m.radius, m.mass, self.state.position],
                outputs=[self.body],
                device=m.device,
                block_dim=particle_block(),
            )

    def restored(self, snapshot: dict) -> None:
        """Called after the state's arrays were loaded from ``snapshot``."""


class ReferenceForces(ForcePath):
    """One thread per particle, a plain loop over every j of its system (kernels/reference.py): the
    tests' yardstick, the bench's baseline and diagnostics' all-pairs engine (it never builds a tree)."""

    name = "reference"

    @staticmethod
    def serves(scheme: Scheme) -> bool:
        return scheme.force_kernel == "reference"

    def __init__(self, model: ModelArrays, state: StateArrays, scheme: Scheme):
        if scheme.clocks > 1:
            raise InputError("the reference kernel evaluates gravity with every force: it steps with gravity_every = 1 only")
        super().__init__(model, state, scheme)
        self.kernel = pair_forces_reference(scheme.precision, model.params.law)

    def evaluate(self) -> None:
        m, s = self.model, self.state
        wp.launch(self.kernel, dim=m.count, inputs=[m.contact, m.ranges, m.radius, m.mass, *s.contact_inputs()],
                  outputs=s.contact_outputs(), device=m.device)  # fmt: skip
        s.history.commit()


class FusedForces(ForcePath):
    """The fused layout (kernels/fused.py): gravity of every ordered pair and the contacts in one
    tiled kernel; blocks of ``layout.particles_per_block`` rows, never straddling two systems."""

    name = "fused"

    @staticmethod
    def serves(scheme: Scheme) -> bool:
        return scheme.clocks == 1 and scheme.gravity == "all-pairs" and not scheme.layout.newton

    def __init__(self, model: ModelArrays, state: StateArrays, scheme: Scheme):
        super().__init__(model, state, scheme)
        # (Warp's CPU blocks, wp.config.enable_cpu_blocks, run every lane: tests use them to check the
        # GPU layouts' reductions on a CPU.)
        if not _on_cuda(model.device) and scheme.layout.block_dim != 1 and not wp.config.enable_cpu_blocks:
            raise InputError("on the CPU a layout's block_dim must be 1 (Warp runs one thread per block)")
        self.body = packed_bodies(model, scheme, model.count)
        layout = scheme.layout
        self.blocks = wp.array(tiled_blocks(model.starts, model.ends, layout.particles_per_block), dtype=wp.vec4i, device=model.device)
        self.kernel = pair_forces_tiled(
            layout.block_dim, layout.particles_per_block, layout.contact_slots, scheme.precision, model.params.law,
            state.ledger, layout.max_registers,
        )  # fmt: skip

    def evaluate(self) -> None:
        m, s = self.model, self.state
        wp.launch_tiled(
            self.kernel,
            dim=[self.blocks.shape[0]],
            block_dim=self.scheme.layout.block_dim,
            inputs=[m.contact, self.blocks, m.radius, m.mass, m.sweep_max_radius, s.position, s.velocity, s.omega, self.body,
                    s.history.current],
            outputs=s.contact_outputs(),
            device=m.device,
        )  # fmt: skip
        s.history.commit()


class SolverForces(ForcePath):
    """Gravity and contacts on one clock, from parts: the scheme's gravity solver, the contact finder
    its class names listing the candidates ("all-pairs": its own "sweep-bits", in the Newton layout;
    "tree": its "hash-grid"), then the contact pass over them, added to gravity's force.  Where the
    solver has its own potential (the tree), frames too cost O(N log N): the potential from it, the
    contact observables from the finder's candidates."""

    name = "solver"

    @staticmethod
    def serves(scheme: Scheme) -> bool:
        return scheme.clocks == 1

    def __init__(self, model: ModelArrays, state: StateArrays, scheme: Scheme):
        super().__init__(model, state, scheme)
        self.gravity = self._solver(listing=True)
        self.finder = CONTACT_FINDERS[self.gravity.finder](model, model.candidate_width, self.gravity)
        self.contact_pass = ContactPass(model, accumulate=True)

    def evaluate(self) -> None:
        self.gravity.evaluate(self.state, self.state.force)
        self.finder.find(self.state)
        self.contact_pass.launch(self.state, self.finder)


class ClockedForces(ForcePath):
    """Gravity on its own clock (``Scheme.gravity_every`` K > 1; docs/model.md): gravity every K steps into its
    own array (the scheme's solver, listing nothing: "all-pairs" in the Newton sweep, or "tree"), the
    contacts every step from a "neighbour-list", whatever the solver (the integrator checks its skin
    at every drift).  The integrator (decco_warp/integrators.py ``TwoClocks``) kicks each on its clock."""

    name = "clocked"

    @staticmethod
    def serves(scheme: Scheme) -> bool:
        return scheme.clocks > 1

    def __init__(self, model: ModelArrays, state: StateArrays, scheme: Scheme):
        super().__init__(model, state, scheme)
        self.gravity = self._solver(listing=False)
        self.gravity_force = wp.zeros(model.count, dtype=wp.vec3d, device=model.device)
        """Gravity at the positions of the last outer step [dyne]."""
        self.finder = NeighbourList(model, model.candidate_width)
        self.contact_pass = ContactPass(model, accumulate=False)

    def evaluate(self) -> None:
        """Gravity and the contacts at the current state, the neighbour lists built afresh."""
        self.gravity.evaluate(self.state, self.gravity_force)
        self.finder.find(self.state)
        self.contact_pass.launch(self.state, self.finder)

    def gravity_step(self) -> None:
        """Gravity at the current positions (the bodies packed by the last inner drift)."""
        self.gravity.evaluate(self.state, self.gravity_force)

    def contacts(self) -> None:
        """The contacts of an inner step, at the positions after its drift: the lists first rebuilt if stale."""
        self.finder.refresh(self.state)
        self.contact_pass.launch(self.state, self.finder)

    def restored(self, snapshot: dict) -> None:
        """Gravity at the restored positions (what the uninterrupted run holds, bit for bit: the same
        kernels on the same positions) and the snapshot's neighbour lists (a snapshot without them,
        of decco-warp 0.2, has them built afresh: the run goes on as another realization would); the
        contact force is the snapshot's."""
        self.pack()
        self.gravity.evaluate(self.state, self.gravity_force)
        if not self.finder.load(snapshot):
            self.finder.find(self.state)

    def total_force(self) -> np.ndarray:
        """Gravity plus the contact force [dyne], both at the current positions."""
        return self.state.force.numpy() + self.gravity_force.numpy()


#: Every force path, in the order :func:`force_path` asks them: the first that serves a scheme computes it.
FORCE_PATHS = (ReferenceForces, FusedForces, SolverForces, ClockedForces)


def force_path(scheme: Scheme) -> type[ForcePath]:
    """The one switch from a scheme to the composition of parts that computes its forces: the first
    path of :data:`FORCE_PATHS` that serves it ("reference" or "fused": one kernel, gravity and
    contacts; "solver": the scheme's gravity solver and its finder; "clocked": gravity every K steps,
    contacts every step from a neighbour list)."""
    return next(path for path in FORCE_PATHS if path.serves(scheme))

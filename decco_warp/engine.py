"""One particle system on a device: its arrays, composed with the parts that step it.

The engine holds the arrays (decco_warp/arrays.py: the model's constants and the state), and
composes, from its :class:`~decco_warp.scheme.Scheme`, a force path (decco_warp/forces.py: a gravity
solver, a contact finder and the contact pass, or one kernel doing both) and an integrator
(decco_warp/integrators.py: one clock, or two).  It chooses them in one place
(``forces.force_path``), then only delegates: the public objects
(:class:`~decco_warp.simulation.Simulation`, :func:`~decco_warp.simulation.compute_forces`,
:func:`~decco_warp.diagnostics.diagnostics`) are built on it.  Beside its parts, this module is the
only one that launches kernels (the packing of the bodies, and the cluster finder's smoothed density
on a GPU, :func:`smoothed_density`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import warp as wp

from .arrays import PAIR_OBSERVABLES, ModelArrays, StateArrays, system_sizes
from .device import resolve_device
from .forces import force_path
from .gravity_solvers import empty_candidates
from .integrators import check_steps, integrator_for
from .kernels import observables
from .kernels.channels import WORK_CHANNELS
from .kernels.contacts import CANDIDATES, unpack_depth
from .layouts import Layout
from .params import Params
from .scheme import Scheme, choose_scheme
from .state import State
from .errors import InputError

class Engine:
    """A particle system on one device, and the parts that step it.

    >>> engine = Engine(state, params, device="cpu")
    >>> engine.eval_forces()      # the forces at the current state (the first half kick needs them)
    >>> engine.advance(100)       # 100 steps
    >>> positions, velocities, omegas = engine.read()
    """

    def __init__(
        self,
        state: State,
        params: Params,
        device: str | None = None,
        precision: str | None = None,
        force_kernel: str | None = None,
        layout: Layout | None = None,
        ledger: bool = False,
        systems: Sequence[int] | None = None,
        scheme: Scheme | None = None,
    ):
        """``scheme``: how the model is evaluated (scheme.py; default Scheme()), ``precision``,
        ``force_kernel`` and ``layout`` replacing its own where given.  ``systems``: the sizes of
        independent systems laid one after another in ``state`` (an ensemble: each particle feels only
        its own system; default, one system)."""
        self.device = resolve_device(device)
        self.params = params
        largest = int(system_sizes(systems, state.n).max())
        self.scheme = choose_scheme(largest, self.device, scheme, precision=precision, force_kernel=force_kernel, layout=layout)
        self.model = ModelArrays(state, params, self.device, self.scheme.precision, systems)
        # A law with springs per pair keeps each particle's contacts: as many rows as its candidate
        # lists hold, or as it has others in its system.
        rows = max(1, min(self.model.candidate_width, largest - 1)) if params.keeps_springs else 0
        self.state = StateArrays(state, self.device, ledger, rows)
        # The parts, chosen in one place (forces.force_path; the integrator by the clocks).
        self.path = force_path(self.scheme)(self.model, self.state, self.scheme)
        self.integrator = integrator_for(self.scheme)(self.model, self.state, self.path, self.scheme)

    # -- what others read of it ----------------------------------------------------

    precision = property(lambda self: self.scheme.precision)
    layout = property(lambda self: self.scheme.layout)
    step_multiple = property(lambda self: self.integrator.every, doc="steps of an outer step: every step count is a multiple of it")
    ledger = property(lambda self: self.state.ledger)
    count = property(lambda self: self.model.count)
    candidate_width = property(lambda self: self.model.candidate_width)
    contact = property(lambda self: self.model.contact, doc="the pair laws' constants (kernels/pair.py ContactModel)")
    radius = property(lambda self: self.model.radius)
    mass = property(lambda self: self.model.mass)
    ranges = property(lambda self: self.model.ranges)
    position = property(lambda self: self.state.position)
    velocity = property(lambda self: self.state.velocity)
    force = property(lambda self: self.state.force)
    channels = property(lambda self: self.state.channels)

    @property
    def candidate_count(self) -> wp.array:
        """Per particle, the contact candidates its force path met at the last evaluation (empty if it lists none)."""
        return self.path.finder.candidate_count if self.path.finder is not None else empty_candidates(0, self.device, CANDIDATES)[0]

    @property
    def candidates(self) -> wp.array:
        """Per particle, the first of them (as many as its list holds)."""
        return self.path.finder.candidates if self.path.finder is not None else empty_candidates(0, self.device, CANDIDATES)[1]

    # -- stepping --------------------------------------------------------------------

    def eval_forces(self) -> None:
        """Force and torque on every particle at the current positions and velocities."""
        self.integrator.evaluate()

    def candidate_overflows(self, first: int = 0, end: int | None = None) -> int:
        """Particles (of rows [first, end)) whose contact candidates overflowed the list at the last
        force evaluation (the paths that list candidates; 0 otherwise): each costs a walk over
        its whole system."""
        return self.path.candidate_overflows(first, end)

    def step(self) -> None:
        """One step (docs/model.md), each stage a launch of its own (with gravity on its own clock, one
        outer step of K steps): the integrator's :meth:`~decco_warp.integrators.OneClock.step`."""
        self.integrator.step()

    def advance(self, steps: int) -> None:
        """``steps`` steps (a multiple of K), ending at a whole step as :meth:`step` does, bit for bit
        the same: with ``layout.fuse_kicks``, a step's last half kick, the next one's first half
        kick and drift and the packing of its bodies are one launch."""
        check_steps(steps, self.step_multiple)
        if not self.scheme.layout.fuse_kicks:
            for _ in range(steps // self.step_multiple):
                self.integrator.step()
        else:
            self.integrator.advance(steps)

    # -- host side ----------------------------------------------------------------

    def pair_observables(self) -> dict[str, np.ndarray]:
        """Per particle: half its pair potential and elastic energy, its contacts, its largest
        overlap [cm], and its deepest contact as a fraction of the pair's smaller radius with that partner."""
        outputs = {name: wp.zeros(self.count, dtype=dtype, device=self.device) for name, dtype in PAIR_OBSERVABLES.items()}
        self.path.observables(outputs)
        pairs = {name: array.numpy() for name, array in outputs.items()}
        if self.state.history.kept:  # the contacts' springs (a law with springs per pair)
            pairs["elastic_tangential"], pairs["elastic_rolling"] = self.state.history.spring_energies(self.model.radius.numpy(), self.params)
        return pairs

    def history_overflows(self, first: int = 0, end: int | None = None) -> int:
        """Particles (of rows [first, end)) that touched more particles than their contact history holds at
        the last evaluation (a law with springs per pair): the springs of the others were not kept."""
        return self.state.history.overflows(first, end)

    def take_deepest_contact(self, first: int = 0, end: int | None = None) -> dict:
        """The deepest contact any force evaluation met since the last call (or the start), as
        ``deepest_overlap`` (a fraction of the smaller radius of the pair, to 6e-8) and
        ``deepest_overlap_pair`` (lower index first, counted from ``first``; -1 -1 when nothing
        touched), among particles [first, end) (one system of an ensemble); starts their new record."""
        end = self.count if end is None else end
        records = self.deepest_contact_records(first, end)  # a copy: on the CPU numpy() is a view of the array zeroed next
        self.state.deepest_contact[first:end].zero_()
        i = int(np.argmax(records))
        depth, j = unpack_depth(int(records[i]))
        pair = np.array(sorted((i, j - first)) if records[i] > 0 else (-1, -1), dtype=np.int64)
        return {"deepest_overlap": depth, "deepest_overlap_pair": pair}

    def deepest_contact_records(self, first: int = 0, end: int | None = None) -> np.ndarray:
        """The deepest-contact records of particles [first, end) as they stand (kept, unlike :meth:`take_deepest_contact`)."""
        return self.state.deepest_contact[first : self.count if end is None else end].numpy().copy()

    def read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and angular velocities copied to the host."""
        s = self.state
        return s.position.numpy().copy(), s.velocity.numpy().copy(), s.omega.numpy().copy()

    def read_forces(self) -> tuple[np.ndarray, np.ndarray]:
        """The last evaluated force [dyne] (gravity included) and torque [dyne cm], copied to the host."""
        return self.path.total_force(), self.state.torque.numpy().copy()

    def read_work(self) -> np.ndarray:
        """Work of each energy channel (WORK_CHANNELS: gravity, spring, sliding, rolling) on each particle
        since the start [erg], (N, 4)."""
        return self.state.work.numpy().copy() if self.ledger else np.zeros((self.count, len(WORK_CHANNELS)))

    #: The state's arrays a snapshot holds and restores, by snapshot key.
    SNAPSHOT_ARRAYS = {"positions": "position", "velocities": "velocity", "omegas": "omega", "force": "force",
                       "torque": "torque", "channels": "channels", "work": "work"}  # fmt: skip

    def snapshot(self) -> dict[str, np.ndarray]:
        """Every array the next step depends on: enough to continue bit for bit (with a law that keeps
        springs per pair, its contact history, arrays.ContactHistory.arrays).  With gravity on its
        own clock ``force`` is the contact force; gravity, a function of the positions alone, is
        evaluated anew on :meth:`restore`, and the neighbour lists are kept (contact_finders.py
        ``NeighbourList.arrays``)."""
        s = self.state
        arrays = {key: getattr(s, name).numpy().copy() for key, name in self.SNAPSHOT_ARRAYS.items()}
        return {**arrays, "deepest_contact": s.deepest_contact.numpy().copy(), **s.history.arrays(), **self.path.arrays()}

    def restore(self, snapshot: dict[str, np.ndarray]) -> None:
        """Load a :meth:`snapshot` back (same particle count and ledger setting)."""
        for key, name in self.SNAPSHOT_ARRAYS.items():
            target = getattr(self.state, name)
            values = np.asarray(snapshot[key], dtype=np.float64)
            if values.shape != target.numpy().shape:
                raise InputError(f"snapshot {key} has shape {values.shape}; expected {target.numpy().shape}")
            target.assign(wp.array(values, dtype=target.dtype, device=self.device))
        # The record since the last frame (checkpoints of decco-warp 0.2 have none: it starts afresh).
        records = np.asarray(snapshot.get("deepest_contact", np.zeros(self.count)), dtype=np.int64)
        if records.shape != (self.count,):
            raise InputError(f"snapshot deepest_contact has shape {records.shape}; expected {(self.count,)}")
        self.state.deepest_contact.assign(wp.array(records, dtype=wp.int64, device=self.device))
        self.state.history.load(snapshot)
        self.path.restored(snapshot)


def smoothed_density(sources: np.ndarray, norm: np.ndarray, inv_two_var: np.ndarray, targets: np.ndarray, device: str) -> np.ndarray:
    """sum_j norm_j exp(-|y - x_j|^2 inv_two_var_j) at each target y, on ``device`` in float64
    (kernels/observables.py; analysis/clusters.py gives the factors)."""
    device = resolve_device(device)
    if len(targets) == 0 or len(sources) == 0:
        return np.zeros(len(targets))

    def array(values, dtype):
        return wp.array(np.ascontiguousarray(values, dtype=np.float64), dtype=dtype, device=device)

    density = wp.zeros(len(targets), dtype=wp.float64, device=device)
    inputs = [array(sources, wp.vec3d), array(norm, wp.float64), array(inv_two_var, wp.float64), array(targets, wp.vec3d)]
    wp.launch(observables.smoothed_density, dim=len(targets), inputs=inputs, outputs=[density], device=device)
    return density.numpy()

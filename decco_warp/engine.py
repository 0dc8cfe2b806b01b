"""Device arrays of one particle system and the kernel launches that act on them.

This module (with the force paths of forces.py and gravity_tree.py) is the only one that touches
Warp arrays and launches kernels; the public objects (:class:`~decco_warp.simulation.Simulation`,
:func:`~decco_warp.simulation.compute_forces`, :func:`~decco_warp.diagnostics.diagnostics`)
are built on it, and the cluster finder's smoothed density on a GPU (:func:`smoothed_density`).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
import warp as wp

from .device import resolve_device
from .forces import FORCE_PATHS, particle_block, path_name
from .layouts import Layout, choose_layout, newton_scratch_bytes, newton_sweep_layout
from .gravity_tree import walk_parts
from .kernels import integrate, observables
from .kernels.bodies import BODY_TYPES, PACK_KERNELS, PRECISIONS
from .kernels.contacts import CANDIDATES, LEDGER_CHANNELS, unpack_depth
from .kernels.pair import ContactModel
from .params import Params
from .sizes import contact_list_rule
from .state import State
from .errors import InputError

FORCE_KERNELS = ("tiled", "reference")

#: Per-particle outputs of kernels/observables.py, in the kernel's order.
PAIR_OBSERVABLES = {
    "potential": wp.float64,
    "elastic": wp.float64,
    "contacts": wp.int32,
    "max_overlap": wp.float64,
    "overlap_depth": wp.float64,
    "overlap_partner": wp.int32,
}


def system_sizes(systems: Sequence[int] | None, count: int) -> np.ndarray:
    """The sizes of an ensemble's systems, checked against the particle count (None: one system)."""
    sizes = np.array([count] if systems is None else list(systems), dtype=np.int64)
    if sizes.ndim != 1 or len(sizes) == 0 or (sizes <= 0).any() or sizes.sum() != count:
        raise InputError(f"systems must be positive sizes adding up to the {count} particles; got {list(sizes)}")
    return sizes


def candidate_width(min_radius: float, max_radius: float) -> int:
    """Contact candidates a particle's list holds on the paths that list them (the Newton layout, the
    tree): CANDIDATES, or more for a wide size range (sizes.contact_list_rule of the radius ratio), so
    that a large grain among many small ones does not overflow into a walk over its whole system.
    Gravity on its own clock keeps CANDIDATES: its build holds a row in a fixed vector
    (kernels/neighbours.py NeighbourRow)."""
    return max(CANDIDATES, contact_list_rule(max_radius / min_radius))


def contact_model(params: Params) -> ContactModel:
    model = ContactModel()
    model.G = wp.float64(params.G)
    model.k_in = wp.float64(params.k_in)
    model.k_out = wp.float64(params.k_out)
    model.mu_k = wp.float64(params.mu_k)
    model.mu_r = wp.float64(params.mu_r)
    return model


class Engine:
    """Particle arrays on one device and launch wrappers for each stage of a step."""

    def __init__(
        self,
        state: State,
        params: Params,
        device: str | None = None,
        precision: str = "mixed",
        force_kernel: str = "tiled",
        layout: Layout | None = None,
        ledger: bool = False,
        systems: Sequence[int] | None = None,
    ):
        """``systems``: the sizes of independent systems laid one after another in ``state``
        (an ensemble: each particle feels only its own system; default, one system)."""
        if precision not in PRECISIONS:
            raise InputError(f"precision must be one of {', '.join(PRECISIONS)}; got {precision!r}")
        if force_kernel not in FORCE_KERNELS:
            raise InputError(f"force_kernel must be one of {', '.join(FORCE_KERNELS)}; got {force_kernel!r}")
        self.device = resolve_device(device)
        self.params = params
        self.precision = precision
        self.force_kernel = force_kernel
        self.ledger = ledger
        self.count = state.n
        self.systems = system_sizes(systems, self.count)
        self.layout = layout or choose_layout(int(self.systems.max()), self.device)
        self.model = contact_model(params)

        def vectors(values):
            return wp.array(values, dtype=wp.vec3d, device=self.device)

        def scalars(values):
            return wp.array(values, dtype=wp.float64, device=self.device)

        # Model: constant per particle.
        self.radius = scalars(state.radii)
        self.mass = scalars(state.masses)
        self.inertia = scalars(state.inertia)
        # State: changes every step.
        self.position = vectors(state.positions)
        self.velocity = vectors(state.velocities)
        self.omega = vectors(state.omegas)
        self.force = wp.zeros(self.count, dtype=wp.vec3d, device=self.device)
        self.torque = wp.zeros(self.count, dtype=wp.vec3d, device=self.device)
        # Energy ledger (kernels/integrate.py): contact channels of the last force
        # evaluation, and the work of each channel since the start, per particle.
        ledger_rows = self.count if ledger else 0
        channel_count = len(LEDGER_CHANNELS)
        self.channels = wp.zeros((ledger_rows, channel_count), dtype=wp.vec3d, device=self.device)
        self.work = wp.zeros(ledger_rows, dtype=wp.vec4d, device=self.device)
        # Each particle's deepest contact met by any force evaluation since the host last took it
        # (kernels/contacts.py note_depth): frames report the peak between them, not a sample.
        self.deepest_contact = wp.zeros(self.count, dtype=wp.int64, device=self.device)

        # Each particle's own system, [first, end).
        self.ends = np.cumsum(self.systems)
        self.starts = self.ends - self.systems
        ranges = np.repeat(np.stack([self.starts, self.ends], axis=1), self.systems, axis=0).astype(np.int32)
        self.ranges = wp.array(ranges, dtype=wp.vec2i, device=self.device)
        self.max_radius = float(state.radii.max())
        self.min_radius = float(state.radii.min())
        self.candidate_width = candidate_width(self.min_radius, self.max_radius)
        # The sweeps' per-i contact bound, in their arithmetic (float32 rounding of the largest
        # radius is no smaller than that of any other radius, so the bound holds).
        self.sweep_max_radius = (wp.float32 if precision == "mixed" else wp.float64)(self.max_radius)

        self._no_body = wp.zeros(0, dtype=BODY_TYPES[precision], device=self.device)  # a kick_drift that packs none
        # The force path (decco_warp/forces.py), chosen by name in one place.
        self.path = FORCE_PATHS[path_name(force_kernel, params, self.layout)](self)
        self.gravity_every = params.gravity_every
        """K: steps of dt per gravity evaluation (K > 1: the force path is RespaForces)."""

    def pair_state(self) -> list:
        """What a pair kernel reads of the particles: radius, mass, position, velocity, omega."""
        return [self.radius, self.mass, self.position, self.velocity, self.omega]

    def contact_state(self) -> list:
        """What a contact pass reads of the particles beside their radii: position, velocity, omega."""
        return [self.position, self.velocity, self.omega]

    @property
    def candidate_count(self) -> wp.array:
        """Per particle, the contact candidates its force path met at the last evaluation (empty if it lists none)."""
        return self.path.candidate_count

    @property
    def candidates(self) -> wp.array:
        """Per particle, the first of them (as many as its list holds: candidate_width)."""
        return self.path.candidates

    # -- stages of a step -----------------------------------------------------------

    def pack_bodies(self) -> None:
        """The sweep's packed bodies (``path.body``) from the current positions (none unless the path reads them)."""
        if self.path.body.shape[0] > 0:
            wp.launch(
                PACK_KERNELS[self.precision],
                dim=self.count,
                inputs=[wp.float64(self.params.G), self.radius, self.mass, self.position],
                outputs=[self.path.body],
                device=self.device,
                block_dim=particle_block(),
            )

    def eval_forces(self) -> None:
        """Force and torque on every particle at the current positions and velocities."""
        self.pack_bodies()
        self.path.evaluate()

    def candidate_overflows(self, first: int = 0, end: int | None = None) -> int:
        """Particles (of rows [first, end)) whose contact candidates overflowed the list at the last
        force evaluation (the paths that list candidates; 0 otherwise): each costs a walk over
        its whole system."""
        return self.path.candidate_overflows(first, end)

    def kick_drift(self, close_step: bool = False, pack: bool = False) -> None:
        """Half kick with the current forces, then a full drift; with ``close_step`` first the last
        half kick of the step before (:meth:`kick`), with ``pack`` then the packing of the bodies
        for the sweep (the first stage of :meth:`eval_forces`), in the same launch."""
        wp.launch(
            integrate.KICK_DRIFT[self.precision],
            dim=self.count,
            inputs=[wp.float64(self.params.dt), wp.float64(self.params.G), self.radius, self.mass, self.inertia,
                    self.force, self.torque, self.channels, close_step],
            outputs=[self.position, self.velocity, self.omega, self.work, self.path.body if pack else self._no_body],
            device=self.device,
            block_dim=particle_block(),
        )  # fmt: skip

    def kick(self) -> None:
        """Second half kick with the forces at the new positions."""
        wp.launch(
            integrate.kick,
            dim=self.count,
            inputs=[wp.float64(self.params.dt), self.mass, self.inertia, self.force, self.torque, self.channels],
            outputs=[self.velocity, self.omega, self.work],
            device=self.device,
            block_dim=particle_block(),
        )

    # Gravity on its own clock (K = gravity_every > 1, docs/model.md): the path is RespaForces.

    def kick_outer(self, close_step: bool = False) -> None:
        """A gravity half kick of K dt / 2; with ``close_step`` first the last contact half kick (:meth:`kick`)."""
        wp.launch(
            integrate.kick_outer,
            dim=self.count,
            inputs=[wp.float64(self.params.dt), wp.float64(self.gravity_every * self.params.dt), self.mass, self.inertia,
                    self.force, self.torque, self.channels, self.path.gravity_force, close_step],
            outputs=[self.velocity, self.omega, self.work],
            device=self.device,
            block_dim=particle_block(),
        )  # fmt: skip

    def kick_drift_inner(self, close_step: bool = False, gravity_kicks: int = 0, pack: bool = False) -> None:
        """A contact half kick and a full drift, then the neighbour list's displacement check; with
        ``close_step`` first the last contact half kick of the step before, then ``gravity_kicks``
        gravity half kicks (closing and opening outer steps); with ``pack`` the packing of the bodies
        for the gravity sweep after the drift."""
        neighbours = self.path.neighbours
        wp.launch(
            integrate.KICK_DRIFT_INNER[self.precision],
            dim=self.count,
            inputs=[wp.float64(self.params.dt), wp.float64(self.gravity_every * self.params.dt), wp.float64(self.params.G),
                    self.radius, self.mass, self.inertia, self.force, self.torque, self.channels, self.path.gravity_force,
                    close_step, gravity_kicks, neighbours.reference, wp.float64(0.5 * neighbours.skin), neighbours.system],
            outputs=[self.position, self.velocity, self.omega, self.work, neighbours.stale, neighbours.stale_system,
                     self.path.body if pack else self._no_body],
            device=self.device,
            block_dim=particle_block(),
        )  # fmt: skip

    def step(self) -> None:
        """One step (docs/model.md), each stage a launch of its own: kick-drift, the forces at x(n+1)
        with the half-step velocities, kick.  With gravity on its own clock, one outer step of K
        steps: a gravity half kick, K steps of the contacts alone, gravity at the new positions and
        the second gravity half kick."""
        if self.gravity_every == 1:
            self.kick_drift()
            self.eval_forces()
            self.kick()
            return
        self.kick_outer()
        for k in range(self.gravity_every):
            self.kick_drift_inner(pack=k == self.gravity_every - 1)
            self.path.contacts()
            self.kick()
        self.path.gravity_step()
        self.kick_outer()

    def advance(self, steps: int) -> None:
        """``steps`` steps (a multiple of K), ending at a whole step as :meth:`step` does, bit for bit
        the same: with ``layout.fuse_kicks``, a step's last half kick, the next one's first half
        kick and drift and the packing of its bodies are one launch (kernels/integrate.py
        ``kick_drift``, ``kick_drift_inner``)."""
        if steps % self.gravity_every:
            raise InputError(f"steps must be a multiple of gravity_every = {self.gravity_every}; got {steps}")
        if not self.layout.fuse_kicks:
            for _ in range(steps // self.gravity_every):
                self.step()
        elif self.gravity_every == 1:
            self._advance_one_clock(steps)
        else:
            self._advance_two_clocks(steps // self.gravity_every)

    def _advance_one_clock(self, steps: int) -> None:
        for k in range(steps):
            self.kick_drift(close_step=k > 0, pack=True)
            self.path.evaluate()
        if steps > 0:
            self.kick()

    def _advance_two_clocks(self, outer_steps: int) -> None:
        last = self.gravity_every - 1
        for s in range(outer_steps):
            for k in range(self.gravity_every):
                # The first inner step opens the outer step's gravity kick (after closing the one before).
                self.kick_drift_inner(close_step=s > 0 or k > 0, gravity_kicks=(2 if s > 0 else 1) if k == 0 else 0, pack=k == last)
                self.path.contacts()
            self.path.gravity_step()
        if outer_steps > 0:
            self.kick_outer(close_step=True)

    # -- host side ----------------------------------------------------------------

    def pair_observables(self) -> dict[str, np.ndarray]:
        """Per particle: half its pair potential and elastic energy, its contacts, its largest
        overlap [cm], and its deepest contact as a fraction of the pair's smaller radius with that partner."""
        outputs = {name: wp.zeros(self.count, dtype=dtype, device=self.device) for name, dtype in PAIR_OBSERVABLES.items()}
        self.path.observables(outputs)
        return {name: array.numpy() for name, array in outputs.items()}

    def take_deepest_contact(self, first: int = 0, end: int | None = None) -> dict:
        """The deepest contact any force evaluation met since the last call (or the start), as
        ``deepest_overlap`` (a fraction of the smaller radius of the pair, to 6e-8) and
        ``deepest_overlap_pair`` (lower index first, counted from ``first``; -1 -1 when nothing
        touched), among particles [first, end) (one system of an ensemble); starts their new record."""
        end = self.count if end is None else end
        part = self.deepest_contact[first:end]
        records = part.numpy().copy()  # on the CPU numpy() is a view of the array zeroed next
        part.zero_()
        i = int(np.argmax(records))
        depth, j = unpack_depth(int(records[i]))
        pair = np.array(sorted((i, j - first)) if records[i] > 0 else (-1, -1), dtype=np.int64)
        return {"deepest_overlap": depth, "deepest_overlap_pair": pair}

    def read(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and angular velocities copied to the host."""
        return self.position.numpy().copy(), self.velocity.numpy().copy(), self.omega.numpy().copy()

    def read_forces(self) -> tuple[np.ndarray, np.ndarray]:
        """The last evaluated force [dyne] (gravity included) and torque [dyne cm], copied to the host."""
        return self.path.total_force(), self.torque.numpy().copy()

    def read_work(self) -> np.ndarray:
        """Work of (gravity, spring, sliding, rolling) on each particle since the start [erg], (N, 4)."""
        return self.work.numpy().copy() if self.ledger else np.zeros((self.count, 4))

    def snapshot(self) -> dict[str, np.ndarray]:
        """Every array the next step depends on: enough to continue bit for bit.  With gravity on its
        own clock ``force`` is the contact force; gravity, a function of the positions alone, is
        evaluated anew on :meth:`restore`, and the neighbour lists are kept (forces.py ``NeighbourList.arrays``)."""
        positions, velocities, omegas = self.read()
        return {
            "positions": positions,
            "velocities": velocities,
            "omegas": omegas,
            "force": self.force.numpy().copy(),
            "torque": self.torque.numpy().copy(),
            "channels": self.channels.numpy().copy(),
            "work": self.work.numpy().copy(),
            "deepest_contact": self.deepest_contact.numpy().copy(),
            **self.path.arrays(),
        }

    def restore(self, snapshot: dict[str, np.ndarray]) -> None:
        """Load a :meth:`snapshot` back (same particle count and ledger setting)."""
        for name, target in [
            ("positions", self.position),
            ("velocities", self.velocity),
            ("omegas", self.omega),
            ("force", self.force),
            ("torque", self.torque),
            ("channels", self.channels),
            ("work", self.work),
        ]:
            values = np.asarray(snapshot[name], dtype=np.float64)
            if values.shape != target.numpy().shape:
                raise InputError(f"snapshot {name} has shape {values.shape}; expected {target.numpy().shape}")
            target.assign(wp.array(values, dtype=target.dtype, device=self.device))
        # The record since the last frame (checkpoints of decco-warp 0.2 have none: it starts afresh).
        records = np.asarray(snapshot.get("deepest_contact", np.zeros(self.count)), dtype=np.int64)
        if records.shape != (self.count,):
            raise InputError(f"snapshot deepest_contact has shape {records.shape}; expected {(self.count,)}")
        self.deepest_contact.assign(wp.array(records, dtype=wp.int64, device=self.device))
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


# --- what a job needs, before it starts ---------------------------------------------------------

#: Bytes a particle takes on the host beside the engine's arrays: the State, a frame's record, a
#: snapshot, the checks (NumPy copies of a few vectors each), with room.
HOST_BYTES_PER_PARTICLE = 600
#: Bytes of a job whatever its size: Warp's modules, the hash grid's cells, launch bookkeeping.
FIXED_BYTES = 256 << 20
#: CPU step time of this project's 2-core CI-class machine (docs/benchmarks.md, the tree section):
#: all-pairs ~5 ns a pair (8 000 particles: 0.31 s a step); the tree ~7.5 us a particle at 8 000,
#: growing as log N.  Scaled by the cores here.
CPU_SECONDS_PER_PAIR = 5e-9
CPU_TREE_SECONDS_PER_PARTICLE = 7.5e-6


def memory_estimate(
    n: int, gravity: str, device: str = "cpu", ledger: bool = True, *, gravity_every: int = 1, layout: Layout | None = None,
    precision: str = "mixed", candidate_width: int = CANDIDATES,
) -> int:
    """Bytes a job of ``n`` particles needs on its device (and on the host), an upper estimate:
    the arrays Engine and GravityTree allocate, taken as for the largest layout, and the Newton
    sweep's rows where all-pairs gravity takes it (``layout`` Newton, as CUDA's default is up to
    NEWTON_MAX particles, or gravity on its own clock, ``gravity_every`` > 1, on any device)."""
    vec3d, f64, i32 = 24, 8, 4
    per = 3 * f64 + 5 * vec3d  # radius, mass, inertia; position, velocity, omega, force, torque
    per += (len(LEDGER_CHANNELS) * vec3d + 32) if ledger else 0  # channels, work
    per += 8 + 32 + 8  # deepest contact, packed body, system range
    per += i32 * (1 + candidate_width)  # the contact candidates of the Newton layout, the tree or the neighbour list
    per += 3 * vec3d + f64 + 5 * i32  # gravity on its own clock: gravity, the list's build positions, the build's sorted
    # positions and radii; system, cell keys and order (2 N)
    per += len(PAIR_OBSERVABLES) * f64  # a frame's pair observables
    if gravity == "tree":  # nodes (2n): mass, centre, quadrupole, box, size, offset, links (16), child, first,
        # last, parent, escape; keys, order (2n); leaf positions, grid points; each walk part's field and potential
        per += 2 * (f64 + vec3d + 72 + 2 * vec3d + 2 * f64 + 16 + 5 * i32) + 4 * i32 + vec3d + 12
        per += walk_parts(n, device) * (vec3d + f64)
    newton = newton_sweep_layout(gravity, gravity_every, layout or choose_layout(n, device), device)
    scratch = newton_scratch_bytes(n, newton, 12 if precision == "mixed" else 24, listing=gravity_every == 1) if newton else 0
    return int(n * (per + HOST_BYTES_PER_PARTICLE) + scratch + FIXED_BYTES)


def cpu_step_seconds(n: int, gravity: str) -> float:
    """About how long one step of ``n`` particles takes on this machine's CPU."""
    cores = max(1, os.cpu_count() or 1) / 2.0
    if gravity == "tree":
        return CPU_TREE_SECONDS_PER_PARTICLE * n * max(1.0, np.log2(max(n, 2)) / np.log2(8000)) / cores
    return CPU_SECONDS_PER_PAIR * float(n) * float(n) / cores


#: A CPU job expected to take longer than this says so before it starts [s].
LONG_ON_CPU = 3600.0


def check_fits(n: int, gravity: str, device: str, steps: int, what: str, **forces) -> str | None:
    """Refuse (InputError) a job whose memory estimate passes the device's free memory; for one that
    fits but would take hours on the CPU, the line that says so (else None).  ``forces``: the
    keywords of :func:`memory_estimate` that say how its forces are summed."""
    from .checks import InputError
    from .device import free_memory

    need = memory_estimate(n, gravity, device, **forces)
    free = free_memory(device)
    if need > free:
        tree = "" if gravity == "tree" else ", gravity = \"tree\" (its memory grows as N, all-pairs' as N^2 here)"
        raise InputError(
            f"{what} of {n} particles needs about {need / 2**30:.3g} GiB on {device}, which has {free / 2**30:.3g} GiB free; "
            f"use fewer particles{tree} or a device with more memory"
        )
    if device.startswith("cuda"):
        return None
    seconds = steps * cpu_step_seconds(n, gravity)
    if seconds < LONG_ON_CPU:
        return None
    return (
        f"note: {what} of {n} particles ({gravity} gravity) will take about {_duration(seconds)} on the CPU "
        f"({cpu_step_seconds(n, gravity):.3g} s a step, {steps} steps); a GPU (--device cuda) is far faster"
    )


def _duration(seconds: float) -> str:
    hours = seconds / 3600.0
    if hours < 48:
        return f"{hours:.3g} hours"
    days = hours / 24.0
    return f"{days:.3g} days" if days < 730 else f"{days / 365.25:.3g} years"

"""Force paths: each way of computing the forces of a step is one object that owns its scratch
arrays and its launches, and :func:`path_name` chooses one by name, in one place.

    path = FORCE_PATHS[path_name(force_kernel, params, layout)](engine)   # as Engine does:
                                   # "reference", "fused", "newton", "tree" or "respa"
    engine.pack_bodies()           # first (into path.body, empty where the path reads none)
    path.evaluate()                # engine.force, torque, channels, deepest_contact at the current state
    path.observables(outputs)      # a frame's per-particle observables
    path.candidate_overflows()     # particles whose candidate list overflowed at the last evaluation

The engine (engine.py) holds the particles' arrays and the integrator; a path reads and writes
them and keeps only what its own kernels need.  With gravity_tree.py's GravityTree, these are
the only objects beside the engine that launch kernels.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .gravity_tree import GravityTree
from .layouts import NEWTON_MAX, newton_sweep_layout
from .kernels import observables as observable_kernels
from .kernels.bodies import BODY_TYPES
from .kernels.contacts import CANDIDATES, contact_pass
from .kernels.fused import pair_forces_tiled
from .kernels.neighbours import GRID_CELLS, REACH_MARGIN, build_neighbour_list, cell_keys, cell_ranges, lists_built
from .kernels import newton
from .kernels.newton import GatherRows, TilePair, gather_newton, pair_gravity_newton
from .kernels.reference import pair_forces_reference
from .errors import InputError

#: Threads per particle of the observables kernel on a GPU.
OBSERVABLES_BLOCK = 128
#: The contact pass's lanes per particle and particles per block on a GPU (one and one on the
#: CPU): ~8 listed candidates a particle, one a lane (kernels/contacts.py ``contact_pass``).
CONTACT_LANES = 8
CONTACT_PARTICLES = 4
#: Threads a block for the kernels of one thread a particle (the packing, the kicks and drifts, the
#: Newton sweep's gather, the neighbour list's build).  A thread's arithmetic is the same at any
#: block size, and so is the motion; Warp's default, 256, puts 6 250 particles in 25 blocks, on 25 of
#: a GPU's 132 SMs (docs/benchmarks.md, "The device limit").
PARTICLE_BLOCK = 256


def particle_block() -> int:
    """``block_dim`` of a launch of one thread a particle: :data:`PARTICLE_BLOCK`, read at launch."""
    return PARTICLE_BLOCK


def tiled_blocks(starts: np.ndarray, ends: np.ndarray, per_block: int) -> np.ndarray:
    """Per block of a tiled launch: (first row, end of its rows, first and end of its system)."""
    rows = [
        (first, min(first + per_block, end), start, end)
        for start, end in zip(starts, ends)
        for first in range(int(start), int(end), per_block)
    ]
    return np.array(rows, dtype=np.int32).reshape(-1, 4)


def newton_tiles(starts: np.ndarray, ends: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray, int]:
    """The Newton layout's tile pairs (kernels/newton.py ``TilePair``), each particle's rows
    (``GatherRows``) and the number of rows.  A system's particles are cut into tiles of ``size``;
    its tile pairs (a, b), a <= b, each meet once; row a * n + b (after the rows of the systems
    before) holds what tile a gets from tile b."""
    tiles, gather, rows = [], [], 0
    for start, end in zip(starts.tolist(), ends.tolist()):
        firsts = np.arange(start, end, size)
        n = len(firsts)
        a, b = np.triu_indices(n)
        tile_ends = np.minimum(firsts + size, end)
        tiles.append(np.stack([firsts[a], tile_ends[a], firsts[b], tile_ends[b], rows + a * n + b, np.where(a < b, rows + b * n + a, -1)], axis=1))
        index = np.arange(start, end)
        tile = (index - start) // size
        gather.append(np.stack([rows + tile * n, np.full_like(index, n), index - firsts[tile], np.full_like(index, start)], axis=1))
        rows += n * n
    return np.concatenate(tiles).astype(np.int32), np.concatenate(gather).astype(np.int32), rows


def _on_cuda(device: str) -> bool:
    return device.startswith("cuda")


def _candidate_arrays(count: int, device: str, width: int = CANDIDATES) -> tuple[wp.array, wp.array]:
    """Per particle: how many contact candidates it met, and the first ``width`` of them (the kernels
    read the width from the array)."""
    return wp.zeros(count, dtype=wp.int32, device=device), wp.zeros((count, width), dtype=wp.int32, device=device)


def _bodies(engine, count: int) -> wp.array:
    """Packed bodies (kernels/bodies.py) for an all-pairs sweep, refreshed before each (count 0: none)."""
    return wp.zeros(count, dtype=BODY_TYPES[engine.precision], device=engine.device)


class ContactPass:
    """The contacts of listed candidates (lists in increasing j), CONTACT_PARTICLES particles a
    block of CONTACT_LANES lanes each on a GPU (kernels/contacts.py ``contact_pass``: one thread
    per particle would leave most of the GPU idle, a few warps per SM at paper sizes); one lane on
    the CPU, or the GPU's blocks with Warp's CPU blocks on (tests check the lanes' reduction so).
    With ``accumulate`` the contact force is added to gravity's in engine.force, else written
    there alone."""

    def __init__(self, engine, accumulate: bool):
        self.engine = engine
        blocks = _on_cuda(engine.device) or wp.config.enable_cpu_blocks
        self.lanes, self.particles = (CONTACT_LANES, CONTACT_PARTICLES) if blocks else (1, 1)
        self.kernel = contact_pass(engine.params.rolling_friction, self.lanes, self.particles, accumulate)

    def launch(self, candidate_count: wp.array, candidates: wp.array, outputs: list) -> None:
        e = self.engine
        wp.launch_tiled(
            self.kernel,
            dim=[-(-e.count // self.particles)],
            block_dim=self.lanes * self.particles,
            inputs=[e.model, e.ranges, e.radius, *e.contact_state(), candidate_count, candidates],
            outputs=outputs,
            device=e.device,
        )


def _contact_pass(path) -> None:
    """A path's contact pass (:class:`ContactPass`) over its candidate lists."""
    path.contact_pass.launch(path.candidate_count, path.candidates, path.outputs())


class ForcePath:
    """What every force path gives the engine; a path that lists contact candidates fills
    ``candidate_count`` and ``candidates``, one that sweeps all pairs reads ``body`` (else they
    are empty)."""

    name = ""
    graph_conditionals = False
    """Whether its launches hold a loop or branch decided on the device (wp.capture_while,
    wp.capture_if): a CUDA graph of them needs conditional nodes (driver and toolkit 12.4+)."""

    def __init__(self, engine):
        self.engine = engine
        self.candidate_count, self.candidates = _candidate_arrays(0, engine.device)
        self.body = _bodies(engine, 0)

    def evaluate(self) -> None:
        """engine.force, torque, channels (with the ledger) and deepest_contact at the current state."""
        raise NotImplementedError

    def outputs(self) -> list:
        e = self.engine
        return [e.force, e.torque, e.channels, e.deepest_contact]

    def total_force(self) -> np.ndarray:
        """The force on every particle at the last evaluation [dyne], a host copy."""
        return self.engine.force.numpy().copy()

    def list_builds(self, system: int | None = None) -> int | None:
        """Builds of a system's neighbour lists since the engine began or was restored (``system``
        None: the most of any system; None: the path keeps none)."""
        return None

    def arrays(self) -> dict[str, np.ndarray]:
        """Per-particle arrays beside the engine's that a snapshot must hold for the path to go on bit for bit."""
        return {}

    def observables(self, outputs: dict) -> None:
        """Per particle, into ``outputs`` (engine.PAIR_OBSERVABLES): over every pair of its system,
        a block of threads per particle on a GPU (N threads alone would leave most of it idle)."""
        e = self.engine
        block_dim = OBSERVABLES_BLOCK if _on_cuda(e.device) else 1
        wp.launch_tiled(
            observable_kernels.pair_observables_tiled(block_dim),
            dim=[e.count],
            inputs=[e.model, e.ranges, e.radius, e.mass, e.position, e.velocity],
            outputs=list(outputs.values()),
            block_dim=block_dim,
            device=e.device,
        )

    def candidate_overflows(self, first: int = 0, end: int | None = None) -> int:
        """Particles (of rows [first, end)) whose contact candidates overflowed their list at the last
        evaluation: each costs a walk over its whole system."""
        if self.candidates.shape[0] == 0:
            return 0
        return int((self.candidate_count.numpy()[first:end] > self.candidates.shape[1]).sum())

    def restored(self, snapshot: dict) -> None:
        """Called after the engine's arrays were loaded from ``snapshot``."""


class ReferenceForces(ForcePath):
    """One thread per particle, a plain loop over every j of its system (kernels/reference.py): the
    tests' yardstick, the bench's baseline and diagnostics' all-pairs engine (it never builds a tree)."""

    name = "reference"

    def __init__(self, engine):
        super().__init__(engine)
        self.kernel = pair_forces_reference(engine.precision, engine.params.rolling_friction)

    def evaluate(self) -> None:
        e = self.engine
        wp.launch(self.kernel, dim=e.count, inputs=[e.model, e.ranges, *e.pair_state()], outputs=self.outputs(), device=e.device)


def _check_cpu_blocks(engine, newton: bool) -> None:
    # (Warp's CPU blocks, wp.config.enable_cpu_blocks, run every lane: tests use them to check the
    # GPU layouts' reductions on a CPU; the Newton layout's lane shuffles exist on a GPU only.)
    if not _on_cuda(engine.device) and engine.layout.block_dim != 1 and (newton or not wp.config.enable_cpu_blocks):
        raise InputError("on the CPU a layout's block_dim must be 1 (Warp runs one thread per block)")


class FusedForces(ForcePath):
    """The fused layout (kernels/fused.py): gravity of every ordered pair and the contacts in one
    tiled kernel; blocks of ``layout.particles_per_block`` rows, never straddling two systems."""

    name = "fused"

    def __init__(self, engine):
        super().__init__(engine)
        _check_cpu_blocks(engine, newton=False)
        self.body = _bodies(engine, engine.count)
        layout = engine.layout
        self.blocks = wp.array(tiled_blocks(engine.starts, engine.ends, layout.particles_per_block), dtype=wp.vec4i, device=engine.device)
        self.kernel = pair_forces_tiled(
            layout.block_dim,
            layout.particles_per_block,
            layout.contact_slots,
            engine.precision,
            engine.params.rolling_friction,
            engine.ledger,
            layout.max_registers,
        )

    def evaluate(self) -> None:
        e = self.engine
        wp.launch_tiled(
            self.kernel,
            dim=[self.blocks.shape[0]],
            block_dim=e.layout.block_dim,
            inputs=[e.model, self.blocks, *e.pair_state(), self.body, e.sweep_max_radius],
            outputs=self.outputs(),
            device=e.device,
        )


class NewtonGravity:
    """Each pair's gravity once (kernels/newton.py): the sweep over a system's tile pairs of the packed
    ``body``, then the gather of each particle's rows; given candidate arrays, with its contact
    candidates listed in increasing j."""

    def __init__(self, engine, layout, body: wp.array, candidate_count: wp.array | None = None, candidates: wp.array | None = None):
        if _on_cuda(engine.device) and layout.block_dim != 32:
            raise InputError(f"a Newton layout's block is one warp: block_dim must be 32 on CUDA; got {layout.block_dim}")
        self.engine, self.layout, self.body = engine, layout, body
        listing = candidates is not None
        if not listing:  # nothing listed, nothing noted: empty arrays in the kernels' signatures
            candidate_count, candidates = _candidate_arrays(0, engine.device)
        self.candidate_count, self.candidates = candidate_count, candidates
        # Per tile pair and side, per particle of the tile: the sweep's field sum and candidate bits.
        tiles, gather, rows = newton_tiles(engine.starts, engine.ends, layout.particles_per_block)
        device = engine.device
        self.tiles = wp.array(tiles, dtype=TilePair, device=device)
        self.gather = wp.array(gather, dtype=GatherRows, device=device)
        vector = wp.vec3f if engine.precision == "mixed" else wp.vec3d
        self.tile_field = wp.zeros((rows, layout.particles_per_block), dtype=vector, device=device)
        self.tile_near = wp.zeros((rows if listing else 0, layout.particles_per_block), dtype=wp.uint64, device=device)
        self.sweep = pair_gravity_newton(layout.particles_per_block // layout.block_dim, engine.precision, layout.max_registers, listing)
        self.gather_kernel = gather_newton(engine.precision, listing, newton.GATHER_AHEAD)

    def evaluate(self, force_out: wp.array) -> None:
        """``force_out`` = gravity on every particle (the bodies packed), and its candidates listed."""
        e = self.engine
        wp.launch_tiled(
            self.sweep,
            dim=[self.tiles.shape[0]],
            block_dim=self.layout.block_dim,
            inputs=[self.tiles, self.body, e.sweep_max_radius],
            outputs=[self.tile_field, self.tile_near],
            device=e.device,
        )
        wp.launch(
            self.gather_kernel,
            dim=e.count,
            inputs=[self.gather, e.mass, self.tile_field, self.tile_near],
            outputs=[force_out, self.candidate_count, self.candidates],
            device=e.device,
            block_dim=particle_block(),
        )


class NewtonForces(ForcePath):
    """The Newton layout: :class:`NewtonGravity`, then the contacts of the listed candidates
    (:class:`ContactPass`)."""

    name = "newton"

    def __init__(self, engine):
        super().__init__(engine)
        _check_cpu_blocks(engine, newton=True)
        self.candidate_count, self.candidates = _candidate_arrays(engine.count, engine.device, engine.candidate_width)
        self.body = _bodies(engine, engine.count)
        self.gravity = NewtonGravity(engine, engine.layout, self.body, self.candidate_count, self.candidates)
        # The gather lists each particle's candidates in increasing j: lanes can share them out.
        self.contact_pass = ContactPass(engine, accumulate=True)

    def evaluate(self) -> None:
        self.gravity.evaluate(self.engine.force)
        _contact_pass(self)


class TreeGravity:
    """Gravity from a radix tree (gravity_tree.py), built from the positions at every evaluation; one
    system at a time."""

    def __init__(self, engine):
        if len(engine.systems) > 1:
            raise InputError('the tree path steps one system at a time; an ensemble needs gravity = "all-pairs"')
        self.engine = engine
        self.tree = GravityTree(engine.count, engine.device, engine.precision)

    def evaluate(self, force_out: wp.array) -> None:
        """``force_out`` = gravity on every particle."""
        e = self.engine
        self.tree.build(e.position, e.mass)
        self.tree.gravity(e.params.G, e.params.theta_open, e.mass, force_out)

    def potential(self, potential_out: wp.array) -> None:
        """``potential_out`` = half of each particle's gravitational energy, from the same walk."""
        e = self.engine
        self.tree.build(e.position, e.mass)
        self.tree.potential(e.params.G, e.params.theta_open, e.mass, potential_out)


def _candidate_observables(engine, contacts: list, candidate_count: wp.array, candidates: wp.array) -> None:
    """The contact observables of a frame from each particle's candidate list (a superset of its contacts)."""
    e = engine
    wp.launch(
        observable_kernels.candidate_observables,
        dim=e.count,
        inputs=[e.model, e.ranges, e.radius, e.position, e.velocity, candidate_count, candidates],
        outputs=contacts,
        device=e.device,
    )


class TreeForces(ForcePath):
    """The tree path: :class:`TreeGravity`, contacts from a hash grid's candidates in increasing j
    (kernels/tree.py, :class:`ContactPass`).  Frames too
    cost O(N log N): the potential from the tree, the contact observables from the grid's candidates."""

    name = "tree"
    graph_conditionals = True  # the moments' levels: wp.capture_while

    def __init__(self, engine):
        super().__init__(engine)
        self.gravity = TreeGravity(engine)
        self.candidate_count, self.candidates = _candidate_arrays(engine.count, engine.device, engine.candidate_width)
        self.contact_pass = ContactPass(engine, accumulate=True)  # added to gravity's force

    def _candidates(self) -> None:
        """Each particle's contact candidates from the hash grid (the tree built)."""
        e = self.engine
        self.gravity.tree.contact_candidates(e.position, e.radius, e.max_radius, self.candidate_count, self.candidates)

    def evaluate(self) -> None:
        self.gravity.evaluate(self.engine.force)
        self._candidates()
        _contact_pass(self)

    def observables(self, outputs: dict) -> None:
        potential, *contacts = outputs.values()
        self.gravity.potential(potential)
        self._candidates()
        _candidate_observables(self.engine, contacts, self.candidate_count, self.candidates)


#: The neighbour list's skin, as a fraction of the smallest radius: 0.5 (3.75 km at the paper's
#: 7.5 km spheres).  A wider skin rebuilds the list less often but lists more pairs that do not
#: touch, each evaluated every step (the contact pass's lanes take them side by side).  Measured on
#: an H100 in the Fig. 8 collision at K = 10 (docs/benchmarks.md): skins of 0.2, 0.5 and 1.0 rebuilt
#: the list every 24, 60 and 118 steps, listed 5.6, 7.6 and 10.2 neighbours a particle at impact
#: (at most 31, 34 and 42 of the list's 64 slots), and stepped in 52, 41 and 39 us.
SKIN_FRACTION = 0.5


class NeighbourList:
    """Each particle's neighbours within R_i + R_j + skin, in increasing j (kernels/neighbours.py),
    in the candidate arrays; a system's lists are rebuilt on the device once any of its particles has
    moved skin / 2 since their last build (``stale_system``, with ``stale`` [0] for any system: set by
    the inner drift, kernels/integrate.py ``kick_drift_inner``).  Which superset of the touching pairs
    a list holds sets how the contact pass's lanes share a particle's contacts (and so the rounding of
    their sum): each system of an ensemble keeps the lists it would keep alone, and a snapshot holds
    them (:meth:`arrays`), so that a restart goes on with the same lists.  The grid's cell tables take
    8 bytes per cell, GRID_CELLS^3 cells per system (2 MiB)."""

    def __init__(self, engine, min_radius: float):
        device, count = engine.device, engine.count
        systems = len(engine.systems)
        self.engine = engine
        self.skin = SKIN_FRACTION * min_radius
        """[cm]"""
        # CANDIDATES wide, not engine.candidate_width: the build keeps a row in a vector of that length.
        self.candidate_count, self.candidates = _candidate_arrays(count, device)
        self.reference = wp.zeros(count, dtype=wp.vec3d, device=device)
        """The positions of the last build."""
        self.stale = wp.zeros(1, dtype=wp.int32, device=device)
        """[0] = 1 once a particle has moved past skin / 2 since its list was built."""
        self.stale_system = wp.zeros(systems, dtype=wp.int32, device=device)
        """[s] = 1 once one of system s's particles has."""
        self.builds = wp.zeros(systems, dtype=wp.int64, device=device)
        """[s]: builds of system s's lists since the engine began or was restored."""
        # The grid: a cell as wide as the farthest reach, 2 R_max + skin; its keys hold each particle's
        # system, so that the systems of an ensemble never meet.
        self.system = wp.array(np.repeat(np.arange(systems), engine.systems).astype(np.int32), device=device)
        self.cell_width = (2.0 * engine.max_radius + self.skin) * REACH_MARGIN
        self.keys = wp.zeros(2 * count, dtype=wp.int32, device=device)  # radix_sort_pairs needs room for 2 N
        # The keys' bits (kernels/neighbours.py cell_key): the sort passes over these alone (3 of
        # CUB's 8-bit passes for one system, not 4).
        self.key_bits = 3 * (GRID_CELLS - 1).bit_length() + max(0, (systems - 1).bit_length())
        self.order = wp.zeros(2 * count, dtype=wp.int32, device=device)
        cells = systems * GRID_CELLS**3
        self.cell_start = wp.zeros(cells, dtype=wp.int32, device=device)
        self.cell_end = wp.zeros(cells, dtype=wp.int32, device=device)
        # Radii and positions in key order: a cell's particles side by side for the build's scans.
        self.sorted_radius = wp.zeros(count, dtype=wp.float64, device=device)
        self.sorted_position = wp.zeros(count, dtype=wp.vec3d, device=device)

    def build(self, everything: bool = False) -> None:
        """List the neighbours of every particle of a stale system (``everything``: of every system) at
        the current positions."""
        e = self.engine
        width = wp.float64(self.cell_width)
        wp.launch(cell_keys, dim=e.count, inputs=[self.system, width, e.position], outputs=[self.keys, self.order], device=e.device,
                  block_dim=particle_block())  # fmt: skip
        wp.utils.radix_sort_pairs(self.keys, self.order, e.count, end_bit=self.key_bits)
        self.cell_start.zero_()
        self.cell_end.zero_()
        wp.launch(
            cell_ranges,
            dim=e.count,
            inputs=[self.keys, e.count, self.order, e.radius, e.position],
            outputs=[self.cell_start, self.cell_end, self.sorted_radius, self.sorted_position],
            device=e.device,
            block_dim=particle_block(),
        )
        wp.launch(
            build_neighbour_list,
            dim=e.count,
            inputs=[self.system, wp.float64(self.skin), width, self.order, self.cell_start, self.cell_end, self.sorted_radius,
                    self.sorted_position, self.stale_system, everything],
            outputs=[self.reference, self.candidate_count, self.candidates],
            device=e.device,
            block_dim=particle_block(),
        )
        wp.launch(lists_built, dim=len(e.systems), inputs=[everything], outputs=[self.stale, self.stale_system, self.builds], device=e.device)

    def refresh(self) -> None:
        """Rebuild the stale systems' lists if there are any, decided on the device (a conditional graph node on CUDA)."""
        wp.capture_if(self.stale, self.build)

    def arrays(self) -> dict[str, np.ndarray]:
        """The lists as a snapshot holds them (:func:`neighbour_arrays`)."""
        return neighbour_arrays(self.reference.numpy(), self.candidate_count.numpy(), self.candidates.numpy())

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """Lists from :meth:`arrays` (the stale flags clear: a snapshot is taken between steps, after
        the last contact evaluation rebuilt whatever was stale)."""
        count = np.asarray(arrays["neighbour_count"], dtype=np.int32)
        listed = np.asarray(arrays["neighbour_list"], dtype=np.int32)
        reference = np.asarray(arrays["neighbour_reference"], dtype=np.float64)
        if count.shape != (self.engine.count,) or reference.shape != (self.engine.count, 3) or listed.ndim != 2 \
                or listed.shape[0] != self.engine.count or listed.shape[1] > self.candidates.shape[1]:  # fmt: skip
            raise InputError(f"snapshot neighbour lists have shapes {count.shape}, {listed.shape}, {reference.shape}; "
                             f"expected ({self.engine.count},), ({self.engine.count}, <= {self.candidates.shape[1]}), ({self.engine.count}, 3)")  # fmt: skip
        rows = np.zeros(self.candidates.shape, dtype=np.int32)
        rows[:, : listed.shape[1]] = listed
        device = self.engine.device
        self.candidates.assign(wp.array(rows, dtype=wp.int32, device=device))
        self.candidate_count.assign(wp.array(count, dtype=wp.int32, device=device))
        self.reference.assign(wp.array(reference, dtype=wp.vec3d, device=device))
        self.stale.zero_()
        self.stale_system.zero_()


#: The snapshot keys of the neighbour lists (NeighbourList.arrays), per particle.
NEIGHBOUR_ARRAYS = ("neighbour_reference", "neighbour_count", "neighbour_list")


def neighbour_arrays(reference: np.ndarray, count: np.ndarray, listed: np.ndarray) -> dict[str, np.ndarray]:
    """Neighbour lists as a snapshot holds them, per particle (host copies): the positions of their
    build, the count of neighbours and the neighbours, as many columns as the longest list uses."""
    width = int(min(count.max(initial=0), listed.shape[1]))
    return {"neighbour_reference": reference.copy(), "neighbour_count": count.copy(), "neighbour_list": listed[:, :width].copy()}


class RespaForces(ForcePath):
    """Gravity on its own clock (``Params.gravity_every`` K > 1; docs/model.md): gravity every K steps
    into its own array (the Newton sweep of every pair once, or with ``gravity = "tree"`` the tree),
    the contacts every step from a neighbour list.  The engine kicks each on its clock
    (kernels/integrate.py ``kick_outer``, ``kick_drift_inner``)."""

    name = "respa"
    graph_conditionals = True  # the neighbour list's rebuild: wp.capture_if

    def __init__(self, engine):
        super().__init__(engine)
        if engine.params.gravity == "tree":
            self.gravity = TreeGravity(engine)
        else:
            largest = int(engine.systems.max())
            if _on_cuda(engine.device) and largest > NEWTON_MAX:
                raise InputError(
                    f"gravity_every > 1 sums all-pairs gravity with the Newton sweep, which holds systems of up to "
                    f"{NEWTON_MAX} particles; this one has {largest}: use gravity = \"tree\""
                )
            params = engine.params
            layout = newton_sweep_layout(params.gravity, params.gravity_every, engine.layout, engine.device)
            self.body = _bodies(engine, engine.count)
            self.gravity = NewtonGravity(engine, layout, self.body)
        self.gravity_force = wp.zeros(engine.count, dtype=wp.vec3d, device=engine.device)
        """Gravity at the positions of the last outer step [dyne]."""
        self.neighbours = NeighbourList(engine, engine.min_radius)
        self.candidate_count, self.candidates = self.neighbours.candidate_count, self.neighbours.candidates
        self.contact_pass = ContactPass(engine, accumulate=False)

    def evaluate(self) -> None:
        """Gravity and the contacts at the current state, the neighbour lists built afresh."""
        self.gravity.evaluate(self.gravity_force)
        self.neighbours.build(everything=True)
        _contact_pass(self)

    def gravity_step(self) -> None:
        """Gravity at the current positions (the bodies packed by the last inner drift)."""
        self.gravity.evaluate(self.gravity_force)

    def contacts(self) -> None:
        """The contacts of an inner step, at the positions after its drift: the list first rebuilt if stale."""
        self.neighbours.refresh()
        _contact_pass(self)

    def restored(self, snapshot: dict) -> None:
        """Gravity at the restored positions (what the uninterrupted run holds, bit for bit: the same
        kernels on the same positions) and the snapshot's neighbour lists (a snapshot without them,
        of decco-warp 0.2, has them built afresh: the run goes on as another realization would); the
        contact force is the snapshot's."""
        self.engine.pack_bodies()
        self.gravity.evaluate(self.gravity_force)
        if all(key in snapshot for key in NEIGHBOUR_ARRAYS):
            self.neighbours.load(snapshot)
        else:
            self.neighbours.build(everything=True)

    def arrays(self) -> dict[str, np.ndarray]:
        return self.neighbours.arrays()

    def total_force(self) -> np.ndarray:
        """Gravity plus the contact force [dyne], both at the current positions."""
        return self.engine.force.numpy() + self.gravity_force.numpy()

    def list_builds(self, system: int | None = None) -> int:
        builds = self.neighbours.builds.numpy()
        return int(builds.max() if system is None else builds[system])

    def observables(self, outputs: dict) -> None:
        if not isinstance(self.gravity, TreeGravity):
            super().observables(outputs)
            return
        # O(N log N) as the tree path: the potential from the tree, the contacts from the list (which
        # holds every touching pair: its last check was at the current positions).
        potential, *contacts = outputs.values()
        self.gravity.potential(potential)
        _candidate_observables(self.engine, contacts, self.candidate_count, self.candidates)


#: Every force path, by name.
FORCE_PATHS = {path.name: path for path in (ReferenceForces, FusedForces, NewtonForces, TreeForces, RespaForces)}


def path_name(force_kernel: str, params, layout) -> str:
    """The one switch: the force path of an engine with ``force_kernel`` ("tiled" or "reference"),
    ``params`` and ``layout``."""
    if force_kernel == "reference":
        if params.gravity_every > 1:
            raise InputError("the reference kernel evaluates gravity with every force: it steps with gravity_every = 1 only")
        return "reference"
    if params.gravity_every > 1:
        return "respa"
    if params.gravity == "tree":
        return "tree"
    return "newton" if layout.newton else "fused"

"""Force paths: each way of computing the forces of a step is one object that owns its scratch
arrays and its launches, and :func:`path_name` chooses one by name, in one place.

    path = FORCE_PATHS[path_name(force_kernel, params, layout)](engine)   # as Engine does
    engine.pack_bodies()           # first, where path.packs_bodies
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
from .kernels import observables as observable_kernels
from .kernels.contacts import CANDIDATES, contact_pass
from .kernels.fused import pair_forces_tiled
from .kernels.newton import GatherRows, TilePair, contact_pass_ordered, gather_newton, pair_gravity_newton
from .kernels.reference import pair_forces_reference

#: Threads per particle of the observables kernel on a GPU.
OBSERVABLES_BLOCK = 128
#: Lanes per particle of the Newton layout's contact pass on a GPU (one on the CPU): its
#: candidates, at most kernels/contacts.py CANDIDATES, two a lane.
CONTACT_BLOCK = 32


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


def _candidate_arrays(count: int, device: str) -> tuple[wp.array, wp.array]:
    """Per particle: how many contact candidates it met, and the first CANDIDATES of them."""
    return wp.zeros(count, dtype=wp.int32, device=device), wp.zeros((count, CANDIDATES), dtype=wp.int32, device=device)


class ForcePath:
    """What every force path gives the engine; a path that lists contact candidates fills
    ``candidate_count`` and ``candidates`` (else they are empty)."""

    name = ""
    packs_bodies = False
    """Whether :meth:`evaluate` reads the packed bodies (kernels/bodies.py), refreshed before it."""
    graph_conditionals = False
    """Whether its launches hold a loop or branch decided on the device (wp.capture_while,
    wp.capture_if): a CUDA graph of them needs conditional nodes (driver and toolkit 12.4+)."""

    def __init__(self, engine):
        self.engine = engine
        self.candidate_count, self.candidates = _candidate_arrays(0, engine.device)

    def evaluate(self) -> None:
        """engine.force, torque, channels (with the ledger) and deepest_contact at the current state."""
        raise NotImplementedError

    def outputs(self) -> list:
        e = self.engine
        return [e.force, e.torque, e.channels, e.deepest_contact]

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

    def restored(self) -> None:
        """Called after the engine's arrays were loaded from a snapshot."""


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
        raise ValueError("on the CPU a layout's block_dim must be 1 (Warp runs one thread per block)")


class FusedForces(ForcePath):
    """The fused layout (kernels/fused.py): gravity of every ordered pair and the contacts in one
    tiled kernel; blocks of ``layout.particles_per_block`` rows, never straddling two systems."""

    name = "fused"
    packs_bodies = True

    def __init__(self, engine):
        super().__init__(engine)
        _check_cpu_blocks(engine, newton=False)
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
            inputs=[e.model, self.blocks, *e.pair_state(), e.body, e.sweep_max_radius],
            outputs=self.outputs(),
            device=e.device,
        )


class NewtonGravity:
    """Each pair's gravity once (kernels/newton.py): the sweep over a system's tile pairs, then the
    gather of each particle's rows, with its contact candidates listed in increasing j."""

    def __init__(self, engine, layout, candidate_count: wp.array, candidates: wp.array):
        if _on_cuda(engine.device) and layout.block_dim != 32:
            raise ValueError(f"a Newton layout's block is one warp: block_dim must be 32 on CUDA; got {layout.block_dim}")
        self.engine, self.layout = engine, layout
        self.candidate_count, self.candidates = candidate_count, candidates
        # Per tile pair and side, per particle of the tile: the sweep's field sum and candidate bits.
        tiles, gather, rows = newton_tiles(engine.starts, engine.ends, layout.particles_per_block)
        device = engine.device
        self.tiles = wp.array(tiles, dtype=TilePair, device=device)
        self.gather = wp.array(gather, dtype=GatherRows, device=device)
        vector = wp.vec3f if engine.precision == "mixed" else wp.vec3d
        self.tile_field = wp.zeros((rows, layout.particles_per_block), dtype=vector, device=device)
        self.tile_near = wp.zeros((rows, layout.particles_per_block), dtype=wp.uint64, device=device)
        self.sweep = pair_gravity_newton(layout.particles_per_block // layout.block_dim, engine.precision, layout.max_registers)
        self.gather_kernel = gather_newton(engine.precision)

    def evaluate(self, force_out: wp.array) -> None:
        """``force_out`` = gravity on every particle (the bodies packed), and its candidates listed."""
        e = self.engine
        wp.launch_tiled(
            self.sweep,
            dim=[self.tiles.shape[0]],
            block_dim=self.layout.block_dim,
            inputs=[self.tiles, e.body, e.sweep_max_radius],
            outputs=[self.tile_field, self.tile_near],
            device=e.device,
        )
        wp.launch(
            self.gather_kernel,
            dim=e.count,
            inputs=[self.gather, e.mass, self.tile_field, self.tile_near],
            outputs=[force_out, self.candidate_count, self.candidates],
            device=e.device,
        )


class NewtonForces(ForcePath):
    """The Newton layout: :class:`NewtonGravity`, then the contacts of the listed candidates, a
    warp per particle (kernels/newton.py ``contact_pass_ordered``; with Warp's CPU blocks on, the
    CPU runs those lanes too: tests check the lanes' reduction so)."""

    name = "newton"
    packs_bodies = True

    def __init__(self, engine):
        super().__init__(engine)
        _check_cpu_blocks(engine, newton=True)
        self.candidate_count, self.candidates = _candidate_arrays(engine.count, engine.device)
        self.gravity = NewtonGravity(engine, engine.layout, self.candidate_count, self.candidates)
        self.contact_block = CONTACT_BLOCK if _on_cuda(engine.device) or wp.config.enable_cpu_blocks else 1
        # The gather lists each particle's candidates in increasing j: lanes can share them out.
        self.contact_kernel = contact_pass_ordered(engine.params.rolling_friction, self.contact_block)

    def evaluate(self) -> None:
        e = self.engine
        self.gravity.evaluate(e.force)
        wp.launch_tiled(
            self.contact_kernel,
            dim=[e.count],
            block_dim=self.contact_block,
            inputs=[e.model, e.ranges, e.radius, *e.contact_state(), self.candidate_count, self.candidates],
            outputs=self.outputs(),
            device=e.device,
        )


class TreeForces(ForcePath):
    """The tree path: gravity from a radix tree, contacts from a hash grid's candidates, one thread
    per particle in increasing j (kernels/tree.py, kernels/contacts.py ``contact_pass``); one
    system at a time.  Frames too cost O(N log N): the potential from the tree, the contact
    observables from the grid's candidates."""

    name = "tree"
    graph_conditionals = True  # the moments' levels: wp.capture_while

    def __init__(self, engine):
        super().__init__(engine)
        if len(engine.systems) > 1:
            raise ValueError('the tree path steps one system at a time; an ensemble needs gravity = "all-pairs"')
        self.tree = GravityTree(engine.count, engine.device, engine.precision)
        self.candidate_count, self.candidates = _candidate_arrays(engine.count, engine.device)
        self.contact_kernel = contact_pass(engine.params.rolling_friction)

    def _candidates(self) -> None:
        """Each particle's contact candidates from the hash grid (the tree built)."""
        e = self.engine
        self.tree.contact_candidates(e.position, e.radius, e.max_radius, self.candidate_count, self.candidates)

    def evaluate(self) -> None:
        e = self.engine
        self.tree.build(e.position, e.mass)
        self.tree.gravity(e.params.G, e.params.theta_open, e.mass, e.force)
        self._candidates()
        wp.launch(
            self.contact_kernel,
            dim=e.count,
            inputs=[e.model, e.ranges, e.radius, *e.contact_state(), self.candidate_count, self.candidates],
            outputs=self.outputs(),
            device=e.device,
        )

    def observables(self, outputs: dict) -> None:
        e = self.engine
        potential, *contacts = outputs.values()
        self.tree.build(e.position, e.mass)
        self.tree.potential(e.params.G, e.params.theta_open, e.mass, potential)
        self._candidates()
        wp.launch(
            observable_kernels.candidate_observables,
            dim=e.count,
            inputs=[e.model, e.ranges, e.radius, e.position, e.velocity, self.candidate_count, self.candidates],
            outputs=contacts,
            device=e.device,
        )


#: Every force path, by name.
FORCE_PATHS = {path.name: path for path in (ReferenceForces, FusedForces, NewtonForces, TreeForces)}


def path_name(force_kernel: str, params, layout) -> str:
    """The one switch: the force path of an engine with ``force_kernel`` ("tiled" or "reference"),
    ``params`` and ``layout``."""
    if force_kernel == "reference":
        return "reference"
    if params.gravity == "tree":
        return "tree"
    return "newton" if layout.newton else "fused"

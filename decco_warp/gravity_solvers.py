"""Gravity solvers: each way of summing the particles' gravity is one class with one interface, and
:data:`GRAVITY_SOLVERS` names them.

    solver = GRAVITY_SOLVERS["pairs-once"](model, scheme, body)   # as decco_warp/forces.py does
    solver.evaluate(state, force_out)     # gravity at the state's positions (bodies packed first)
    solver.potential(state, potential_out)  # half each particle's potential energy; False: not this solver's

"pairs-once" sums each pair once (the Newton sweep, kernels/newton.py; given candidate arrays it also
lists each particle's contact candidates, in increasing j), "tree" walks a radix tree (gravity_tree.py).
The all-pairs kernels that sum gravity and contacts in one launch (the fused layout, the reference
kernel) are force paths of their own (decco_warp/forces.py).  A new solver is one class here and its
line in :data:`GRAVITY_SOLVERS`.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .arrays import ModelArrays, StateArrays
from .errors import InputError
from .gravity_tree import GravityTree
from .kernels import newton
from .kernels.newton import GatherRows, TilePair, gather_newton, pair_gravity_newton
from .layouts import Layout, particle_block
from .scheme import Scheme


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


def empty_candidates(count: int, device: str, width: int) -> tuple[wp.array, wp.array]:
    """Per particle: how many contact candidates it met, and the first ``width`` of them (the kernels
    read the width from the array; ``count`` 0: none listed)."""
    return wp.zeros(count, dtype=wp.int32, device=device), wp.zeros((count, width), dtype=wp.int32, device=device)


class GravitySolver:
    """What every gravity solver gives: gravity into an array, and where it has its own, the potential."""

    name = ""
    graph_conditionals = False
    """Whether its launches hold a loop decided on the device (wp.capture_while): a CUDA graph of them
    needs conditional nodes (driver and toolkit 12.4+)."""

    def evaluate(self, state: StateArrays, force_out: wp.array) -> None:
        """``force_out`` = gravity on every particle at the state's positions."""
        raise NotImplementedError

    def potential(self, state: StateArrays, potential_out: wp.array) -> bool:
        """``potential_out`` = half of each particle's gravitational energy, from this solver (True);
        False where frames sum it over all pairs instead (decco_warp/forces.py)."""
        return False


class PairsOnce(GravitySolver):
    """Each pair's gravity once (kernels/newton.py): the sweep over a system's tile pairs of the packed
    ``body``, then the gather of each particle's rows; given candidate arrays, with its contact
    candidates listed in increasing j (the contact finder of the Newton layout)."""

    name = "pairs-once"

    def __init__(self, model: ModelArrays, scheme: Scheme, layout: Layout, body: wp.array,
                 candidate_count: wp.array | None = None, candidates: wp.array | None = None):  # fmt: skip
        if model.device.startswith("cuda") and layout.block_dim != 32:
            raise InputError(f"a Newton layout's block is one warp: block_dim must be 32 on CUDA; got {layout.block_dim}")
        self.model, self.layout, self.body = model, layout, body
        listing = candidates is not None
        if not listing:  # nothing listed, nothing noted: empty arrays in the kernels' signatures
            candidate_count, candidates = empty_candidates(0, model.device, 1)
        self.candidate_count, self.candidates = candidate_count, candidates
        # Per tile pair and side, per particle of the tile: the sweep's field sum and candidate bits.
        tiles, gather, rows = newton_tiles(model.starts, model.ends, layout.particles_per_block)
        device = model.device
        self.tiles = wp.array(tiles, dtype=TilePair, device=device)
        self.gather = wp.array(gather, dtype=GatherRows, device=device)
        vector = wp.vec3f if scheme.precision == "mixed" else wp.vec3d
        self.tile_field = wp.zeros((rows, layout.particles_per_block), dtype=vector, device=device)
        self.tile_near = wp.zeros((rows if listing else 0, layout.particles_per_block), dtype=wp.uint64, device=device)
        self.sweep = pair_gravity_newton(layout.particles_per_block // layout.block_dim, scheme.precision, layout.max_registers, listing)
        self.gather_kernel = gather_newton(scheme.precision, listing, newton.GATHER_AHEAD)

    def evaluate(self, state: StateArrays, force_out: wp.array) -> None:
        m = self.model
        wp.launch_tiled(
            self.sweep,
            dim=[self.tiles.shape[0]],
            block_dim=self.layout.block_dim,
            inputs=[self.tiles, m.sweep_max_radius, self.body],
            outputs=[self.tile_field, self.tile_near],
            device=m.device,
        )
        wp.launch(
            self.gather_kernel,
            dim=m.count,
            inputs=[self.gather, m.mass, self.tile_field, self.tile_near],
            outputs=[force_out, self.candidate_count, self.candidates],
            device=m.device,
            block_dim=particle_block(),
        )


class Tree(GravitySolver):
    """Gravity from a radix tree (gravity_tree.py), built from the positions at every evaluation; one
    system at a time.  Its hash grid lists contact candidates too (decco_warp/contact_finders.py)."""

    name = "tree"
    graph_conditionals = True  # the moments' levels: wp.capture_while

    def __init__(self, model: ModelArrays, scheme: Scheme):
        if len(model.systems) > 1:
            raise InputError('the tree path steps one system at a time; an ensemble needs gravity = "all-pairs"')
        self.model, self.theta_open = model, scheme.theta_open
        self.tree = GravityTree(model.count, model.device, scheme.precision)

    def evaluate(self, state: StateArrays, force_out: wp.array) -> None:
        m = self.model
        self.tree.build(state.position, m.mass)
        self.tree.gravity(m.params.G, self.theta_open, m.mass, force_out)

    def potential(self, state: StateArrays, potential_out: wp.array) -> bool:
        m = self.model
        self.tree.build(state.position, m.mass)
        self.tree.potential(m.params.G, self.theta_open, m.mass, potential_out)
        return True


#: Every gravity solver, by name.
GRAVITY_SOLVERS = {solver.name: solver for solver in (PairsOnce, Tree)}

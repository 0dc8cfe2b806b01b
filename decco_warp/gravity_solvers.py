"""Gravity solvers: each way of summing the particles' gravity is one class with one interface,
registered under the name a scheme gives it (``Scheme.gravity``) in :data:`GRAVITY_SOLVERS`.

    solver = GRAVITY_SOLVERS[scheme.gravity](model, scheme, listing)   # as decco_warp/forces.py does
    solver.evaluate(state, force_out)     # gravity at the state's positions (``solver.body`` packed first)
    solver.potential(state, potential_out)  # half each particle's potential energy; False: not this solver's

"all-pairs" sums each pair once (the Newton sweep, kernels/newton.py; ``listing``, it also lists each
particle's contact candidates, in increasing j, for its finder "sweep-bits"), "tree" walks a radix
tree (gravity_tree.py; its finder "hash-grid" reads the tree's box).  The all-pairs kernels that sum
gravity and contacts in one launch (the fused layout, the reference kernel) are force paths of their
own (decco_warp/forces.py).  A new solver is one class here (or anywhere) with the decorator
:func:`gravity_solver`: a scheme may then name it, and the force paths compose it with the contact
finder its class names (:attr:`GravitySolver.finder`).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .arrays import ModelArrays, StateArrays
from .errors import InputError
from .gravity_tree import GravityTree
from .kernels import newton
from .kernels.bodies import BODY_TYPES
from .kernels.newton import GatherRows, TilePair, gather_newton, pair_gravity_newton
from .layouts import NEWTON_MAX, newton_layout, particle_block


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


def packed_bodies(model: ModelArrays, scheme, count: int) -> wp.array:
    """Packed bodies (kernels/bodies.py) for an all-pairs sweep, refreshed before each (count 0: none)."""
    return wp.zeros(count, dtype=BODY_TYPES[scheme.precision], device=model.device)


#: Every gravity solver, by the name a scheme gives it (:func:`gravity_solver` registers them).
GRAVITY_SOLVERS: dict[str, type[GravitySolver]] = {}


def registrar(table: dict, what: str):
    """A class decorator that registers a class in ``table`` under its ``name``, once."""

    def register(cls):
        if cls.name in table:
            raise ValueError(f"a {what} named {cls.name!r} is registered already")
        table[cls.name] = cls
        return cls

    return register


#: Register a solver under its ``name``: a :class:`~decco_warp.scheme.Scheme` may then name it.
gravity_solver = registrar(GRAVITY_SOLVERS, "gravity solver")


class GravitySolver:
    """What every gravity solver gives: gravity into an array, and where it has its own, the potential.
    Made as ``Solver(model, scheme, listing)``: ``scheme`` a scheme.Scheme (which names the solvers
    registered here, so that this module does not import it), ``listing`` where its :attr:`finder`
    lists the step's contact candidates from it (gravity and contacts on one clock)."""

    name = ""
    """The name a scheme gives it (``Scheme.gravity``)."""
    finder = "neighbour-list"
    """The contact finder (contact_finders.py ``CONTACT_FINDERS``) that lists the candidates beside it
    when gravity and contacts share the step: one that reads its work (its sort, its sweep), else a
    cell list of its own.  Gravity on its own clock takes the neighbour list whatever the solver."""
    graph_conditionals = False
    """Whether its launches hold a loop decided on the device (wp.capture_while): a CUDA graph of them
    needs conditional nodes (driver and toolkit 12.4+)."""
    body: wp.array | None = None
    """The packed bodies its sweep reads, packed by the force path before each evaluation (None: it
    reads the state's positions)."""

    def evaluate(self, state: StateArrays, force_out: wp.array) -> None:
        """``force_out`` = gravity on every particle at the state's positions."""
        raise NotImplementedError

    def potential(self, state: StateArrays, potential_out: wp.array) -> bool:
        """``potential_out`` = half of each particle's gravitational energy, from this solver (True);
        False where frames sum it over all pairs instead (decco_warp/forces.py)."""
        return False


@gravity_solver
class PairsOnce(GravitySolver):
    """All-pairs gravity, each pair once (kernels/newton.py): the sweep over a system's tile pairs of
    the packed ``body``, then the gather of each particle's rows; ``listing``, with its contact
    candidates listed in increasing j (``candidate_count``, ``candidates``: what "sweep-bits" reads).
    The scheme's layout where that is a Newton layout, else the device's (gravity on its own clock)."""

    name = "all-pairs"
    finder = "sweep-bits"

    def __init__(self, model: ModelArrays, scheme, listing: bool = False):
        cuda = model.device.startswith("cuda")
        largest = int(model.systems.max())
        if scheme.clocks > 1 and cuda and largest > NEWTON_MAX:
            raise InputError(
                f"gravity_every > 1 sums all-pairs gravity with the Newton sweep, which holds systems of up to "
                f"{NEWTON_MAX} particles; this one has {largest}: use gravity = \"tree\""
            )
        layout = scheme.layout if scheme.layout.newton else newton_layout(model.device)
        if not cuda and layout.block_dim != 1:  # its lane shuffles exist on a GPU only
            raise InputError("on the CPU a layout's block_dim must be 1 (Warp runs one thread per block)")
        if cuda and layout.block_dim != 32:
            raise InputError(f"a Newton layout's block is one warp: block_dim must be 32 on CUDA; got {layout.block_dim}")
        self.model, self.layout = model, layout
        listed, width = (model.count, model.candidate_width) if listing else (0, 1)  # nothing listed: empty arrays in the signatures
        self.candidate_count, self.candidates = empty_candidates(listed, model.device, width)
        self.body = packed_bodies(model, scheme, model.count)
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


@gravity_solver
class Tree(GravitySolver):
    """Gravity from a radix tree (gravity_tree.py), built from the positions at every evaluation; one
    system at a time.  Its hash grid lists contact candidates too (decco_warp/contact_finders.py)."""

    name = "tree"
    finder = "hash-grid"  # the grid is placed in the tree's box, found at its build
    graph_conditionals = True  # the moments' levels: wp.capture_while

    def __init__(self, model: ModelArrays, scheme, listing: bool = False):
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

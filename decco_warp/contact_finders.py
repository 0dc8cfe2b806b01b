"""Contact finders: each way of listing the pairs that may touch is one class with one interface,
registered by name in :data:`CONTACT_FINDERS`.  A finder fills ``candidate_count`` and
``candidates`` (per particle, its candidates in increasing j, a superset of its contacts); the
contact pass (decco_warp/forces.py) applies the contact law to them in float64.

    finder = CONTACT_FINDERS[solver.finder](model, width, solver)   # beside a gravity solver, as forces.py does
    finder.find(state)        # lists at the current positions
    finder.refresh(state)     # (a list with a skin) rebuilt only where stale, decided on the device
    finder.arrays(), finder.load(arrays)   # what a snapshot keeps of it

"sweep-bits": the Newton sweep's own candidate bits, listed by its gather (the gravity solver
"all-pairs" fills them: finding costs nothing more); "hash-grid": the tree's hash grid of the
touching pairs at each evaluation; "neighbour-list": a cell list of the pairs within a skin, rebuilt
when a particle has moved half the skin (gravity on its own clock, and any solver that names no
finder of its own).  A new finder is one class here (or anywhere) with the decorator
:func:`contact_finder`; a gravity solver takes it by naming it (``GravitySolver.finder``).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .arrays import ModelArrays, StateArrays
from .errors import InputError
from .gravity_solvers import GravitySolver, empty_candidates, registrar
from .kernels.contacts import CANDIDATES
from .kernels.neighbours import (GRID_CELLS, STENCIL, build_neighbour_list, cell_keys, cell_neighbours, cell_ranges, lists_built,
                                 sort_neighbours)
from .kernels.pair import NEIGHBOUR_LIST_MARGIN, host_reach
from .layouts import particle_block


#: Every contact finder, by name (:func:`contact_finder` registers them).
CONTACT_FINDERS: dict[str, type[ContactFinder]] = {}


#: Register a finder under its ``name``: a gravity solver may then name it (``GravitySolver.finder``).
contact_finder = registrar(CONTACT_FINDERS, "contact finder")


class ContactFinder:
    """What every contact finder gives: each particle's candidates, and what a snapshot keeps of them.
    Made as ``Finder(model, width, gravity)``: lists ``width`` wide, beside the gravity solver
    ``gravity`` (for a finder that lists from its work; the others ignore it)."""

    name = ""
    graph_conditionals = False
    """Whether its launches hold a branch decided on the device (wp.capture_if)."""
    current = False
    """Whether its lists hold every touching pair at the current positions without a new search
    (a list with a skin, checked at every drift): a frame's observables then read them as they are."""

    def __init__(self, model: ModelArrays, width: int, gravity: GravitySolver | None = None):
        self.model = model
        self.candidate_count, self.candidates = empty_candidates(model.count, model.device, width)

    def find(self, state: StateArrays) -> None:
        """List every particle's candidates at the state's positions."""

    def refresh(self, state: StateArrays) -> None:
        """Bring the lists up to date before a contact evaluation (by default: :meth:`find`)."""
        self.find(state)

    def overflows(self, first: int = 0, end: int | None = None) -> int:
        """Particles (of rows [first, end)) whose candidates overflowed their list at the last search:
        each costs a walk over its whole system."""
        return int((self.candidate_count.numpy()[first:end] > self.candidates.shape[1]).sum())

    def builds(self, system: int | None = None) -> int | None:
        """Builds of a system's lists since the engine began or was restored (None: not kept)."""
        return None

    def arrays(self) -> dict[str, np.ndarray]:
        """Per-particle arrays a snapshot must hold for the lists to go on bit for bit (none by default:
        they are found afresh from the positions)."""
        return {}

    def load(self, arrays: dict[str, np.ndarray]) -> bool:
        """Lists from a snapshot's :meth:`arrays`; False where it holds none (they are then found afresh)."""
        return False


@contact_finder
class SweepBits(ContactFinder):
    """The Newton sweep's candidate bits, listed by its gather in increasing j: the gravity solver
    ("all-pairs", made ``listing``) fills its arrays as it sums gravity, so finding costs nothing more."""

    name = "sweep-bits"

    def __init__(self, model: ModelArrays, width: int, gravity: GravitySolver):
        self.model = model
        self.candidate_count, self.candidates = gravity.candidate_count, gravity.candidates


@contact_finder
class HashGrid(ContactFinder):
    """Each particle's neighbours within (R_i + R_j)(1 + 1e-4), from the tree's hash grid (built with
    the tree at each evaluation, placed in its box): kernels/tree.py ``grid_candidates``.  Beside a
    solver that holds a gravity_tree.GravityTree as ``tree`` ("tree")."""

    name = "hash-grid"

    def __init__(self, model: ModelArrays, width: int, gravity: GravitySolver):
        super().__init__(model, width)
        self.tree = gravity.tree

    def find(self, state: StateArrays) -> None:
        m = self.model
        self.tree.contact_candidates(state.position, m.radius, m.max_radius, self.candidate_count, self.candidates)


#: The neighbour list's skin, as a fraction of the smallest radius: 0.5 (3.75 km at the paper's
#: 7.5 km spheres).  A wider skin rebuilds the list less often but lists more pairs that do not
#: touch, each evaluated every step (the contact pass's lanes take them side by side).  Measured on
#: an H100 at the Fig. 8 impact at K = 10 (docs/benchmarks.md, "Tried and dropped"): skins of 0.2,
#: 0.35, 0.5 and 0.75 rebuilt the list every 23, 40, 58 and 86 steps, listed 4.9, 6.2, 7.1 and 8.5
#: neighbours a particle, and stepped in 35.0, 32.3, 32.3 and 31.8 us.
SKIN_FRACTION = 0.5

#: The snapshot keys of the neighbour lists (NeighbourList.arrays), per particle.
NEIGHBOUR_ARRAYS = ("neighbour_reference", "neighbour_count", "neighbour_list")


def neighbour_arrays(reference: np.ndarray, count: np.ndarray, listed: np.ndarray) -> dict[str, np.ndarray]:
    """Neighbour lists as a snapshot holds them, per particle (host copies): the positions of their
    build, the count of neighbours and the neighbours, as many columns as the longest list uses."""
    width = int(min(count.max(initial=0), listed.shape[1]))
    return {"neighbour_reference": reference.copy(), "neighbour_count": count.copy(), "neighbour_list": listed[:, :width].copy()}


@contact_finder
class NeighbourList(ContactFinder):
    """Each particle's neighbours within R_i + R_j + skin, in increasing j (kernels/neighbours.py); a
    system's lists are rebuilt on the device once any of its particles has moved skin / 2 since their
    last build (``stale_system``, with ``stale`` [0] for any system: set by the inner drift,
    kernels/integrate.py ``kick_drift_inner``).  Which superset of the touching pairs a list holds
    sets how the contact pass's lanes share a particle's contacts (and so the rounding of their sum):
    each system of an ensemble keeps the lists it would keep alone, and a snapshot holds them
    (:meth:`arrays`), so that a restart goes on with the same lists.  The grid's cell tables take
    8 bytes per cell, GRID_CELLS^3 cells per system (2 MiB).  Its lists are ``width`` wide (the
    model's candidate_width: wider for a wide size range, so that a large grain among many small
    ones keeps its list; the build sorts each row in place).

    ``scan``: how a build looks in the cells, "by cell" (a thread per particle and cell of its 27,
    then a thread per list entry putting each row in order: kernels/neighbours.py ``cell_neighbours``,
    ``sort_neighbours``) or "by particle" (a thread per particle walking its 27 cells in turn:
    ``build_neighbour_list``, the tests' yardstick); the same lists bit for bit.  None (the default)
    takes "by cell" on a GPU, where one thread a particle is a fraction of a wave, each thread
    waiting on ~300 loads in a row (the paper's collision), and "by particle" on the CPU, which runs
    threads one after another (there "by cell", testing every pair twice, built the paper's
    collision in 17 ms against 5.5 on 2 cores).  "by cell" keeps (27 + width) int32 a particle
    more: each cell's count and the neighbours as met."""

    name = "neighbour-list"
    scan: str | None = None
    graph_conditionals = True  # the rebuild: wp.capture_if
    current = True  # every drift checks the lists against the positions

    def __init__(self, model: ModelArrays, width: int = CANDIDATES, gravity: GravitySolver | None = None):
        super().__init__(model, width)
        device, count = model.device, model.count
        systems = len(model.systems)
        self.skin = SKIN_FRACTION * model.min_radius
        """[cm]"""
        self.reference = wp.zeros(count, dtype=wp.vec3d, device=device)
        """The positions of the last build."""
        self.stale = wp.zeros(1, dtype=wp.int32, device=device)
        """[0] = 1 once a particle has moved past skin / 2 since its list was built."""
        self.stale_system = wp.zeros(systems, dtype=wp.int32, device=device)
        """[s] = 1 once one of system s's particles has."""
        self.build_count = wp.zeros(systems, dtype=wp.int64, device=device)
        """[s]: builds of system s's lists since the engine began or was restored."""
        # The grid: a cell as wide as the farthest reach, 2 R_max + skin; its keys hold each particle's
        # system, so that the systems of an ensemble never meet.
        self.system = wp.array(np.repeat(np.arange(systems), model.systems).astype(np.int32), device=device)
        self.cell_width = host_reach(model.max_radius, model.max_radius, self.skin, NEIGHBOUR_LIST_MARGIN)
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
        # A build by cell: per cell of the stencil and particle (in key order) its neighbours there, and
        # per particle (in key order) its neighbours as met (a row of the lists' width).
        self.scan = type(self).scan or ("by cell" if device.startswith("cuda") else "by particle")
        if self.scan not in ("by cell", "by particle"):
            raise InputError(f"a neighbour list's scan is \"by cell\" or \"by particle\"; got {self.scan!r}")
        by_cell = self.scan == "by cell"
        self.cell_counts = wp.zeros((STENCIL, count) if by_cell else (0, 0), dtype=wp.int32, device=device)
        self.found = wp.zeros((count, width) if by_cell else (0, 0), dtype=wp.int32, device=device)

    def build(self, state: StateArrays, everything: bool = False) -> None:
        """List the neighbours of every particle of a stale system (``everything``: of every system) at
        the current positions."""
        m = self.model
        width = wp.float64(self.cell_width)
        wp.launch(cell_keys, dim=m.count, inputs=[self.system, width, state.position], outputs=[self.keys, self.order], device=m.device,
                  block_dim=particle_block())  # fmt: skip
        wp.utils.radix_sort_pairs(self.keys, self.order, m.count, end_bit=self.key_bits)
        self.cell_start.zero_()
        self.cell_end.zero_()
        wp.launch(
            cell_ranges,
            dim=m.count,
            inputs=[m.count, m.radius, self.keys, self.order, state.position],
            outputs=[self.cell_start, self.cell_end, self.sorted_radius, self.sorted_position],
            device=m.device,
            block_dim=particle_block(),
        )
        cells = [self.system, wp.float64(self.skin), width, self.order, self.cell_start, self.cell_end, self.sorted_radius,
                 self.sorted_position, self.stale_system, everything]  # fmt: skip
        if self.scan == "by particle":
            wp.launch(build_neighbour_list, dim=m.count, inputs=cells, outputs=[self.reference, self.candidate_count, self.candidates],
                      device=m.device, block_dim=particle_block())  # fmt: skip
        else:
            # Count each cell's neighbours, write them after the cells before, then each row in increasing j.
            for write in (False, True):
                wp.launch(cell_neighbours, dim=(STENCIL, m.count), inputs=[*cells, write],
                          outputs=[self.cell_counts, self.found, self.reference, self.candidate_count], device=m.device,
                          block_dim=particle_block())  # fmt: skip
            wp.launch(sort_neighbours, dim=(m.count, self.found.shape[1]),
                      inputs=[self.system, self.order, self.stale_system, everything, self.found, self.candidate_count],
                      outputs=[self.candidates], device=m.device, block_dim=particle_block())  # fmt: skip
        wp.launch(lists_built, dim=len(m.systems), inputs=[everything], outputs=[self.stale, self.stale_system, self.build_count], device=m.device)

    def find(self, state: StateArrays) -> None:
        self.build(state, everything=True)

    def refresh(self, state: StateArrays) -> None:
        """Rebuild the stale systems' lists if there are any, decided on the device (a conditional graph node on CUDA)."""
        wp.capture_if(self.stale, lambda: self.build(state))

    def builds(self, system: int | None = None) -> int:
        counts = self.build_count.numpy()
        return int(counts.max() if system is None else counts[system])

    def arrays(self) -> dict[str, np.ndarray]:
        """The lists as a snapshot holds them (:func:`neighbour_arrays`)."""
        return neighbour_arrays(self.reference.numpy(), self.candidate_count.numpy(), self.candidates.numpy())

    def load(self, arrays: dict[str, np.ndarray]) -> bool:
        """Lists from :meth:`arrays` (the stale flags clear: a snapshot is taken between steps, after
        the last contact evaluation rebuilt whatever was stale); False for a snapshot without them
        (decco-warp 0.2's checkpoints)."""
        if not all(key in arrays for key in NEIGHBOUR_ARRAYS):
            return False
        count = np.asarray(arrays["neighbour_count"], dtype=np.int32)
        listed = np.asarray(arrays["neighbour_list"], dtype=np.int32)
        reference = np.asarray(arrays["neighbour_reference"], dtype=np.float64)
        n = self.model.count
        if count.shape != (n,) or reference.shape != (n, 3) or listed.ndim != 2 or listed.shape[0] != n \
                or listed.shape[1] > self.candidates.shape[1]:  # fmt: skip
            raise InputError(f"snapshot neighbour lists have shapes {count.shape}, {listed.shape}, {reference.shape}; "
                             f"expected ({n},), ({n}, <= {self.candidates.shape[1]}), ({n}, 3)")  # fmt: skip
        rows = np.zeros(self.candidates.shape, dtype=np.int32)
        rows[:, : listed.shape[1]] = listed
        device = self.model.device
        self.candidates.assign(wp.array(rows, dtype=wp.int32, device=device))
        self.candidate_count.assign(wp.array(count, dtype=wp.int32, device=device))
        self.reference.assign(wp.array(reference, dtype=wp.vec3d, device=device))
        self.stale.zero_()
        self.stale_system.zero_()
        return True

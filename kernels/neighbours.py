"""The Verlet neighbour list of gravity on its own clock (docs/model.md "Gravity on its own clock").

``build_neighbour_list`` lists, for each particle in increasing j, the particles of its own system
closer than R_i + R_j + skin, and keeps the positions of the build.  They are found in a grid of
cells at least as wide as the largest reach, so that a neighbour lies in one of the 27 cells around
a particle's own: ``cell_keys`` gives each particle its cell's key (the cell, wrapped into
GRID_CELLS per axis, and its system: no system sees another), ``wp.utils.radix_sort_pairs`` sorts
the particles by key and ``cell_ranges`` marks where each key's run begins and ends.  Only kernels,
a sort and memsets: the whole build can be a branch of a CUDA graph (``wp.HashGrid`` cannot: its
build copies its descriptor from host memory, which a conditional node's body may not).  A drift that
takes any particle more than skin / 2 from its position at the build flags its system's lists stale
(kernels/integrate.py ``kick_drift_inner``), and the next contact evaluation rebuilds them first, a
branch taken on the device (``wp.capture_if``): between two builds no pair that touches can be
missing from a list.

The contacts are then :mod:`.contacts` ``contact_pass`` over the list (increasing j, an exact zero
for a listed pair that does not touch).  With its lanes, which superset of the touching pairs a list
holds sets the rounding of the sums: the lists are part of the state (snapshots keep them), and a
build lists only the particles of the systems whose particles moved (``stale_system``), so that each
system of an ensemble keeps the lists it would keep alone.

Two builds give the same lists, bit for bit (tests/test_respa.py): ``build_neighbour_list``, a thread
a particle walking its 27 cells one after another (~320 distance tests in a row a particle of the
paper's piles: at 6 250 particles a fraction of a wave of threads, each waiting on memory in turn),
and, a GPU's default, a thread per particle and cell: ``cell_neighbours`` counts each cell's neighbours,
then, given the counts of the cells before, writes them in the order the walk of one thread meets
them, and ``sort_neighbours`` puts each row in increasing j (each entry's rank among its row's).  A
list that overflows keeps, as the walk does, the first ``width`` met, in increasing j.
"""

import warp as wp

from .contacts import note_candidate
from .pair import NEIGHBOUR_LIST_MARGIN, reach, within_reach

wp.set_module_options({"enable_backward": False})

#: Cells per axis of the list's grid.  It wraps: particles far apart may share a cell, which costs
#: distance checks, never a missed neighbour (the 27 cells around any cell are distinct).
GRID_CELLS = 64


@wp.func
def cell_key(cell: wp.vec3i, system: int) -> int:
    """The key of a cell (wrapped into GRID_CELLS per axis) of a system."""
    d = wp.static(GRID_CELLS)
    x = ((cell[0] % d) + d) % d
    y = ((cell[1] % d) + d) % d
    z = ((cell[2] % d) + d) % d
    return x + d * (y + d * (z + d * system))


@wp.func
def cell_of(x: wp.vec3d, cell_width: wp.float64) -> wp.vec3i:
    return wp.vec3i(int(wp.floor(x[0] / cell_width)), int(wp.floor(x[1] / cell_width)), int(wp.floor(x[2] / cell_width)))


#: The cells a build looks in around a particle's own: 3 x 3 x 3.
STENCIL = 27


@wp.func
def stencil_cell(own: wp.vec3i, neighbour: int) -> wp.vec3i:
    """The ``neighbour``-th of the STENCIL cells around ``own``, in the order a list's build walks them."""
    return own + wp.vec3i(neighbour % 3 - 1, (neighbour // 3) % 3 - 1, neighbour // 9 - 1)


@wp.kernel
def cell_keys(
    # Model:
    system_in: wp.array(dtype=wp.int32),
    cell_width: wp.float64,
    # In:
    position_in: wp.array(dtype=wp.vec3d),
    # Out:
    keys_out: wp.array(dtype=wp.int32),  # (2 N: radix_sort_pairs' room) each particle's cell key
    order_out: wp.array(dtype=wp.int32),  # (2 N) the particles, to be sorted by key
):
    i = wp.tid()
    keys_out[i] = wp.int32(cell_key(cell_of(position_in[i], cell_width), int(system_in[i])))
    order_out[i] = wp.int32(i)


@wp.kernel
def cell_ranges(
    # Model:
    count: int,  # particles
    radius_in: wp.array(dtype=wp.float64),
    # In:
    keys_in: wp.array(dtype=wp.int32),  # sorted
    order_in: wp.array(dtype=wp.int32),  # the particles in key order
    position_in: wp.array(dtype=wp.vec3d),
    # Out:
    start_out: wp.array(dtype=wp.int32),  # zeroed first: per key, where its run of sorted particles begins
    end_out: wp.array(dtype=wp.int32),  # zeroed first: and ends (empty cells: 0, 0)
    sorted_radius_out: wp.array(dtype=wp.float64),  # radius and position of the k-th particle in key order
    sorted_position_out: wp.array(dtype=wp.vec3d),
):
    k = wp.tid()
    key = keys_in[k]
    if k == 0 or keys_in[k - 1] != key:
        start_out[key] = wp.int32(k)
    if k == count - 1 or keys_in[k + 1] != key:
        end_out[key] = wp.int32(k + 1)
    i = int(order_in[k])
    sorted_radius_out[k] = radius_in[i]
    sorted_position_out[k] = position_in[i]


@wp.func
def to_build(system: int, stale_system: wp.array(dtype=wp.int32), everything: bool) -> bool:
    """Whether a build lists ``system``'s particles: every system's (``everything``), else a stale one's."""
    return everything or stale_system[system] != 0


@wp.func
def listed(
    k: int,  # the particle, in key order
    m: int,  # another, in key order
    x: wp.vec3d,  # k's position
    radius: wp.float64,  # k's radius
    skin: wp.float64,
    sorted_radius_in: wp.array(dtype=wp.float64),
    sorted_position_in: wp.array(dtype=wp.vec3d),
) -> bool:
    """Whether m belongs in k's neighbour list: another particle within reach (both builds' test)."""
    if m == k:
        return False
    r = sorted_position_in[m] - x
    return within_reach(wp.dot(r, r), reach(radius, sorted_radius_in[m], skin, wp.float64(NEIGHBOUR_LIST_MARGIN)), wp.float64(1.0))


@wp.kernel
def build_neighbour_list(
    # Model:
    system_in: wp.array(dtype=wp.int32),  # per particle: its system
    skin: wp.float64,
    cell_width: wp.float64,
    # In:
    order_in: wp.array(dtype=wp.int32),  # the particles sorted by cell key (cell_keys, then the sort)
    start_in: wp.array(dtype=wp.int32),  # per key, its run in order_in (cell_ranges)
    end_in: wp.array(dtype=wp.int32),
    sorted_radius_in: wp.array(dtype=wp.float64),  # radii and positions in key order (cell_ranges)
    sorted_position_in: wp.array(dtype=wp.vec3d),
    stale_system_in: wp.array(dtype=wp.int32),  # per system: whether its list is to be built
    everything: bool,  # build every system's list, stale or not
    # Out:
    reference_out: wp.array(dtype=wp.vec3d),  # the positions of this build
    candidate_count_out: wp.array(dtype=wp.int32),  # neighbours met (past the list's width: an overflow)
    candidates_out: wp.array2d(dtype=wp.int32),  # the first of them (as many as its columns: arrays.candidate_width), in increasing j
):
    """Thread k lists the k-th particle in key order: the threads of a warp share cells, and a cell's
    particles are read from the sorted copies one after another, not gathered from all over memory.
    Only the systems whose list is stale are built: each system of an ensemble keeps the list it
    would keep alone (which pairs it holds sets the order of a particle's contact sums)."""
    k = wp.tid()
    i = int(order_in[k])
    system = int(system_in[i])
    if not to_build(system, stale_system_in, everything):
        return
    x = sorted_position_in[k]
    radius = sorted_radius_in[k]
    own = cell_of(x, cell_width)
    noted = int(0)
    for neighbour in range(wp.static(STENCIL)):  # the 3 x 3 x 3 cells around its own
        key = cell_key(stencil_cell(own, neighbour), system)
        for m in range(int(start_in[key]), int(end_in[key])):
            # In order in i's row; past its width only counted (an overflow).
            if listed(k, m, x, radius, skin, sorted_radius_in, sorted_position_in):
                noted = note_candidate(candidates_out, i, noted, int(order_in[m]))
    candidate_count_out[i] = wp.int32(noted)
    reference_out[i] = x


@wp.kernel
def lists_built(
    # In:
    everything: bool,  # every system's list was built, stale or not
    # Out:
    stale_out: wp.array(dtype=wp.int32),  # [0] cleared: every list is fresh
    stale_system_inout: wp.array(dtype=wp.int32),  # per system: cleared
    builds_inout: wp.array(dtype=wp.int64),  # per system: its builds so far, one more where built
):
    """After a build (a launch of its own: the build reads the flags that this clears)."""
    system = wp.tid()
    if to_build(system, stale_system_inout, everything):
        builds_inout[system] = builds_inout[system] + wp.int64(1)
    stale_system_inout[system] = 0
    if system == 0:
        stale_out[0] = 0


# --- The build a thread per particle and cell (NeighbourList's default) ----------------------------


@wp.func
def neighbours_in_cell(
    k: int,  # the particle, in key order
    x: wp.vec3d,
    radius: wp.float64,
    skin: wp.float64,
    key: int,  # the cell's key
    order_in: wp.array(dtype=wp.int32),
    start_in: wp.array(dtype=wp.int32),
    end_in: wp.array(dtype=wp.int32),
    sorted_radius_in: wp.array(dtype=wp.float64),
    sorted_position_in: wp.array(dtype=wp.vec3d),
    write: bool,
    slot: int,  # with ``write``: where in k's row of ``found_out`` the first goes
    found_out: wp.array2d(dtype=wp.int32),
) -> int:
    """The particles of a cell within reach of k (``listed``, the walk's test), in key order: their
    count; with ``write`` each written into k's row from ``slot`` on (past its width only counted)."""
    hits = int(0)
    for m in range(int(start_in[key]), int(end_in[key])):
        if listed(k, m, x, radius, skin, sorted_radius_in, sorted_position_in):
            if write and slot + hits < found_out.shape[1]:
                found_out[k, slot + hits] = order_in[m]
            hits += 1
    return hits


@wp.kernel
def cell_neighbours(
    # Model:
    system_in: wp.array(dtype=wp.int32),  # per particle: its system
    skin: wp.float64,
    cell_width: wp.float64,
    # In:
    order_in: wp.array(dtype=wp.int32),  # the particles sorted by cell key (cell_keys, then the sort)
    start_in: wp.array(dtype=wp.int32),  # per key, its run in order_in (cell_ranges)
    end_in: wp.array(dtype=wp.int32),
    sorted_radius_in: wp.array(dtype=wp.float64),  # radii and positions in key order (cell_ranges)
    sorted_position_in: wp.array(dtype=wp.vec3d),
    stale_system_in: wp.array(dtype=wp.int32),  # per system: whether its list is to be built
    everything: bool,  # build every system's list, stale or not
    write: bool,  # False: count each cell's neighbours; True (after): write them
    # Out:
    counts_inout: wp.array2d(dtype=wp.int32),  # (STENCIL, N): per cell of the stencil and particle in key order, its neighbours there
    found_out: wp.array2d(dtype=wp.int32),  # (N, width) per particle in key order: its neighbours as a walk of its cells meets them
    reference_out: wp.array(dtype=wp.vec3d),  # the positions of this build
    candidate_count_out: wp.array(dtype=wp.int32),  # neighbours met (past the list's width: an overflow)
):
    """Launched over (STENCIL, N), twice: thread (c, k) looks in the c-th cell around the k-th
    particle in key order (threads side by side look in the same cell for neighbouring particles).
    The first launch counts; the second writes them after those of the cells before, so that a row
    holds what ``build_neighbour_list``'s walk notes, in the order it meets them."""
    neighbour, k = wp.tid()
    i = int(order_in[k])
    system = int(system_in[i])
    if not to_build(system, stale_system_in, everything):
        return
    x = sorted_position_in[k]
    key = cell_key(stencil_cell(cell_of(x, cell_width), neighbour), system)
    slot = int(0)
    if write:
        for before in range(neighbour):
            slot += int(counts_inout[before, k])
    hits = neighbours_in_cell(k, x, sorted_radius_in[k], skin, key, order_in, start_in, end_in, sorted_radius_in, sorted_position_in,
                              write, slot, found_out)  # fmt: skip
    if not write:
        counts_inout[neighbour, k] = wp.int32(hits)
    elif neighbour == wp.static(STENCIL - 1):
        candidate_count_out[i] = wp.int32(slot + hits)
        reference_out[i] = x


@wp.kernel
def sort_neighbours(
    # Model:
    system_in: wp.array(dtype=wp.int32),  # per particle: its system
    # In:
    order_in: wp.array(dtype=wp.int32),  # the particles sorted by cell key
    stale_system_in: wp.array(dtype=wp.int32),
    everything: bool,
    found_in: wp.array2d(dtype=wp.int32),  # (cell_neighbours) per particle in key order: its neighbours as met
    candidate_count_in: wp.array(dtype=wp.int32),  # (cell_neighbours) per particle: its neighbours met
    # Out:
    candidates_out: wp.array2d(dtype=wp.int32),  # the first of them (as many as its columns), in increasing j
):
    """Launched over (N, width): thread (k, s) puts the s-th neighbour met of the k-th particle in key
    order at its rank among the row's (a particle is met once, so the ranks are distinct).  Only the
    columns below the count are written, as ``note_candidate`` writes them."""
    k, s = wp.tid()
    i = int(order_in[k])
    if not to_build(int(system_in[i]), stale_system_in, everything):
        return
    noted = wp.min(int(candidate_count_in[i]), found_in.shape[1])
    if s >= noted:
        return
    j = found_in[k, s]
    rank = int(0)
    for t in range(noted):
        if found_in[k, t] < j:
            rank += 1
    candidates_out[i, rank] = j

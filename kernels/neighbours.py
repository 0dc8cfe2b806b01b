"""The Verlet neighbour list of gravity on its own clock (docs/model.md "Gravity on its own clock").

``build_neighbour_list`` lists, for each particle in increasing j, the particles of its own system
closer than R_i + R_j + skin, and keeps the positions of the build.  They are found in a grid of
cells at least as wide as the largest reach, so that a neighbour lies in one of the 27 cells around
a particle's own: ``cell_keys`` gives each particle its cell's key (the cell, wrapped into
GRID_CELLS per axis, and its system: no system sees another), ``wp.utils.radix_sort_pairs`` sorts
the particles by key and ``cell_ranges`` marks where each key's run begins and ends.  Only kernels,
a sort and memsets: the whole build can be a branch of a CUDA graph (``wp.HashGrid`` cannot: its
build copies its descriptor from host memory, which a conditional node's body may not).  A drift that
takes any particle more than skin / 2 from its position at the build flags the list stale
(kernels/integrate.py ``kick_drift_inner``), and the next contact evaluation rebuilds it first, a
branch taken on the device (``wp.capture_if``): between two builds no pair that touches can be
missing from the list.

The contacts are then :mod:`.contacts` ``contact_pass`` over the list (increasing j, an exact zero
for a listed pair that does not touch): their sums do not depend on which superset of the touching
pairs the list holds, so a list built at another step (as after a restart) gives the same bits.
"""

import warp as wp

from .contacts import note_candidate

wp.set_module_options({"enable_backward": False})

#: Relative margin on a list's reach R_i + R_j + skin: it covers the rounding of the float64
#: distances of the build and of the displacement check (a pair at the reach exactly stays listed).
REACH_MARGIN = 1.0 + 1e-9
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


@wp.kernel
def cell_keys(
    # Model:
    system_in: wp.array(dtype=wp.int32),
    cell_width: wp.float64,
    # State in:
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
    keys_in: wp.array(dtype=wp.int32),  # sorted
    count: int,
    start_out: wp.array(dtype=wp.int32),  # zeroed first: per key, where its run of sorted particles begins
    end_out: wp.array(dtype=wp.int32),  # zeroed first: and ends (empty cells: 0, 0)
):
    k = wp.tid()
    key = keys_in[k]
    if k == 0 or keys_in[k - 1] != key:
        start_out[key] = wp.int32(k)
    if k == count - 1 or keys_in[k + 1] != key:
        end_out[key] = wp.int32(k + 1)


@wp.kernel
def build_neighbour_list(
    # Model:
    system_in: wp.array(dtype=wp.int32),  # per particle: its system
    radius_in: wp.array(dtype=wp.float64),
    skin: wp.float64,
    cell_width: wp.float64,
    # In:
    order_in: wp.array(dtype=wp.int32),  # the particles sorted by cell key (cell_keys, then the sort)
    start_in: wp.array(dtype=wp.int32),  # per key, its run in order_in (cell_ranges)
    end_in: wp.array(dtype=wp.int32),
    # State in:
    position_in: wp.array(dtype=wp.vec3d),
    # Out:
    reference_out: wp.array(dtype=wp.vec3d),  # the positions of this build
    candidate_count: wp.array(dtype=wp.int32),  # neighbours met (past the list's width: an overflow)
    candidates: wp.array2d(dtype=wp.int32),  # the first of them, in increasing j
    # In/out:
    stale_inout: wp.array(dtype=wp.int32),  # [0] cleared: the list is fresh
    builds_inout: wp.array(dtype=wp.int64),  # [0]: builds so far, one more
):
    i = wp.tid()
    x = position_in[i]
    margin = wp.float64(REACH_MARGIN)
    own = cell_of(x, cell_width)
    noted = int(0)
    for neighbour in range(27):  # the 3 x 3 x 3 cells around its own
        cell = own + wp.vec3i(neighbour % 3 - 1, (neighbour // 3) % 3 - 1, neighbour // 9 - 1)
        key = cell_key(cell, int(system_in[i]))
        for k in range(int(start_in[key]), int(end_in[key])):
            j = int(order_in[k])
            if j != i:
                reach = (radius_in[i] + radius_in[j] + skin) * margin
                r = position_in[j] - x
                if wp.dot(r, r) < reach * reach:
                    noted = note_candidate(candidates, i, noted, j)
    candidate_count[i] = wp.int32(noted)
    reference_out[i] = x
    if i == 0:  # no thread of this launch reads either
        stale_inout[0] = 0
        builds_inout[0] = builds_inout[0] + wp.int64(1)


"""The Verlet neighbour list of gravity on its own clock (docs/model.md "Gravity on its own clock").

``build_neighbour_list`` lists, for each particle in increasing j, the particles of its own system
closer than R_i + R_j + skin (found in a float64 ``wp.HashGrid`` whose groups are the systems of an
ensemble, so that no system sees another), and keeps the positions of the build.  A drift that
takes any particle more than skin / 2 from its position at the build flags the list stale
(kernels/integrate.py ``kick_drift_inner``), and the next contact evaluation rebuilds it first, a
branch taken on the device (``wp.capture_if``): between two builds no pair that touches can be
missing from the list.

``listed_contacts`` walks a particle's list in increasing j (every j of its system after an
overflow of the list, also in increasing j) and adds, for a listed pair that does not touch, an
exact zero: its sums do not depend on which superset of the touching pairs the list holds, so a
list built at another step (as after a restart) gives the same bits.
"""

import functools

import warp as wp

from .contacts import ContactSum, candidates_walk, contact_sum_function, write_contacts
from .pair import ContactModel

wp.set_module_options({"enable_backward": False})

#: Relative margin on a list's reach R_i + R_j + skin: it covers the rounding of the float64
#: distances of the build and of the displacement check (a pair at the reach exactly stays listed).
REACH_MARGIN = 1.0 + 1e-9


@wp.func
def insert_sorted(candidates: wp.array2d(dtype=wp.int32), i: int, count: int, j: int):
    """Insert j into i's first ``count`` candidates, kept in increasing order (a list is short)."""
    s = count
    while s > 0:
        if candidates[i, s - 1] < j:
            break
        candidates[i, s] = candidates[i, s - 1]
        s -= 1
    candidates[i, s] = wp.int32(j)


@wp.kernel
def build_neighbour_list(
    # Model:
    grid: wp.uint64,
    system_in: wp.array(dtype=wp.int32),  # per particle: its system, the grid's group
    radius_in: wp.array(dtype=wp.float64),
    max_radius: wp.float64,
    skin: wp.float64,
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
    query = wp.hash_grid_query(grid, x, (radius_in[i] + max_radius + skin) * margin, system_in[i])
    j = int(0)
    noted = int(0)
    while wp.hash_grid_query_next(query, j):
        if j != i:
            reach = (radius_in[i] + radius_in[j] + skin) * margin
            r = position_in[j] - x
            if wp.dot(r, r) < reach * reach:
                if noted < candidates.shape[1]:
                    insert_sorted(candidates, i, noted, j)
                noted += 1
    candidate_count[i] = wp.int32(noted)
    reference_out[i] = x
    if i == 0:  # no thread of this launch reads either
        stale_inout[0] = 0
        builds_inout[0] = builds_inout[0] + wp.int64(1)


@functools.cache
def listed_contacts(rolling: str = "couple"):
    """Build the contact pass over a neighbour list, one thread per particle: its listed pairs in
    increasing j, each evaluated in float64 (zero unless they touch); writes ``force_out`` (the
    contact force alone: gravity is kicked on its own clock), ``torque_out`` and the ledger's
    ``channels_out`` (when it has rows) whole."""
    add_contact = contact_sum_function(rolling)

    @wp.kernel(module="unique", enable_backward=False)
    def listed_contacts_kernel(
        # Model:
        model: ContactModel,
        ranges: wp.array(dtype=wp.vec2i),  # per particle: its system's particles, [first, end)
        radius_in: wp.array(dtype=wp.float64),
        # State in:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        candidate_count: wp.array(dtype=wp.int32),
        candidates: wp.array2d(dtype=wp.int32),
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),
        deepest_out: wp.array(dtype=wp.int64),
    ):
        i = wp.tid()
        listed, walk = candidates_walk(i, ranges, candidate_count, candidates)
        total = ContactSum()
        for s in range(walk):  # the list, or every j of the system after an overflow: increasing j either way
            j = int(ranges[i][0]) + s
            if listed:
                j = int(candidates[i, s])
            total = add_contact(model, i, j, radius_in, position_in, velocity_in, omega_in, deepest_out, total)
        force_out[i] = write_contacts(total, i, torque_out, channels_out)

    return listed_contacts_kernel

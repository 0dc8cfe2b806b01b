"""Contacts in float64, shared by every layout: the contact channels of a pair, their sums per
particle, the record of the deepest contact, and the contact pass over a list of candidates.

The sweeps find contacts cheaply (:mod:`.bodies` ``is_candidate``, in the sweep's precision); every
contact is then evaluated here, in float64 from the state arrays, with the pair laws of
:mod:`.pair`: positions are ~1e7 cm and overlaps ~1e2 cm.  Contacts are few, so this code is kept
out of the hot loops.

Candidate lists are kept in increasing j: the tree path's hash grid notes them so
(``note_candidate``, :mod:`.tree` ``grid_candidates``), the neighbour list of gravity on its own
clock in each thread's own row before writing it out (:mod:`.neighbours`), and the Newton layout's
gather tile after tile (:mod:`.newton`).  ``contact_pass`` (8 lanes a
particle on a GPU, one on the CPU) walks a list in order and reduces its lanes in a fixed
order, so its sums (and the ledger's channels) do not depend on scheduling.  A listed pair that does
not touch adds an exact zero, but its slot decides which lane adds the contacts after it: with
lanes, the rounding of a sum depends on which superset of the touching pairs the list holds (a
neighbour list is part of the state: decco_warp/contact_finders.py ``NeighbourList``).  The observables walk
the lists the same way (``candidates_walk``, ``candidate_at``).
"""

import functools

import warp as wp

from .pair import CONTACT_LAWS, ContactModel, in_contact, overlap

wp.set_module_options({"enable_backward": False})

#: Per-particle contact channels written by the ledger variants, in this order
#: (float64, summed over contacts); gravity is the rest of the force.
LEDGER_CHANNELS = ("spring_force", "sliding_force", "sliding_torque", "rolling_force")


# The deepest contact of each particle since the host last read it, as one int64 so that a
# single atomic max keeps depth and partner together: the depth (a fraction of the smaller
# radius) in units of 2^-DEPTH_BITS above PARTNER_BITS bits of the partner's index.
DEPTH_BITS = 24
PARTNER_BITS = 31
MAX_DEPTH = 63.0  # keeps the packed value below 2^62 (depths past 2 cannot occur: 4 with radii 1:3)
DEPTH_UNIT = float(2**DEPTH_BITS)


@wp.func
def note_depth(deepest_out: wp.array(dtype=wp.int64), i: int, j: int, d2: wp.float64, radius_i: wp.float64, radius_j: wp.float64):
    """Raise i's record of its deepest contact to this one (with j) if deeper; no-op without a record."""
    if deepest_out.shape[0] > 0:
        depth = overlap(wp.sqrt(d2), radius_i, radius_j) / wp.min(radius_i, radius_j)
        units = wp.int64(wp.min(depth, wp.float64(MAX_DEPTH)) * wp.float64(DEPTH_UNIT))
        wp.atomic_max(deepest_out, i, (units << wp.int64(PARTNER_BITS)) | wp.int64(j))


def unpack_depth(record: int) -> tuple[float, int]:
    """A record written by :func:`note_depth`: (depth as a fraction of the smaller radius, partner)."""
    return (record >> PARTNER_BITS) / DEPTH_UNIT, record & ((1 << PARTNER_BITS) - 1)


@functools.cache
def contact_function(law: str):
    """The Warp function giving the contact channels on i from j if they touch, by ``law``
    (kernels/pair.py CONTACT_LAWS), in float64 from the state arrays.

    Returns (spring force, sliding force, sliding torque, rolling force, rolling
    torque), all zero for a pair that does not touch; notes the contact's depth in
    ``deepest_out`` (see :func:`note_depth`).
    """
    contact = CONTACT_LAWS[law]

    @wp.func
    def contact_channels(
        model: ContactModel,
        i: int,
        j: int,
        radius_in: wp.array(dtype=wp.float64),
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        deepest_out: wp.array(dtype=wp.int64),
    ):
        # The separation is taken in float64: positions are ~1e7 cm, overlaps ~1e2 cm.
        r_ij = position_in[i] - position_in[j]
        d2 = wp.dot(r_ij, r_ij)
        # d2 == 0: the particle itself, or a coincident one, which has no direction.
        if d2 > wp.float64(0.0) and in_contact(d2, radius_in[i], radius_in[j]):
            note_depth(deepest_out, i, j, d2, radius_in[i], radius_in[j])
            return wp.static(contact)(
                model,
                r_ij,
                d2,
                radius_in[i],
                velocity_in[i],
                omega_in[i],
                radius_in[j],
                velocity_in[j],
                omega_in[j],
                i < j,
            )
        return wp.vec3d(), wp.vec3d(), wp.vec3d(), wp.vec3d(), wp.vec3d()

    return contact_channels


@wp.struct
class ContactSum:
    """The contact channels on one particle, summed over its contacts."""

    spring: wp.vec3d
    sliding: wp.vec3d
    sliding_torque: wp.vec3d
    rolling: wp.vec3d
    rolling_torque: wp.vec3d


@functools.cache
def contact_sum_function(law: str):
    """The Warp function adding the contact channels on i from j (zero unless they touch) to a ContactSum."""
    contact_channels = contact_function(law)

    @wp.func
    def add_contact(
        model: ContactModel,
        i: int,
        j: int,
        radius_in: wp.array(dtype=wp.float64),
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        deepest_out: wp.array(dtype=wp.int64),
        total: ContactSum,
    ) -> ContactSum:
        spring, sliding, sliding_torque, rolling_force, rolling_torque = contact_channels(
            model, i, j, radius_in, position_in, velocity_in, omega_in, deepest_out
        )
        out = ContactSum()
        out.spring = total.spring + spring
        out.sliding = total.sliding + sliding
        out.sliding_torque = total.sliding_torque + sliding_torque
        out.rolling = total.rolling + rolling_force
        out.rolling_torque = total.rolling_torque + rolling_torque
        return out

    return add_contact


@wp.func
def write_contacts(total: ContactSum, i: int, torque_out: wp.array(dtype=wp.vec3d), channels_out: wp.array2d(dtype=wp.vec3d)) -> wp.vec3d:
    """Write i's contact torque and (when the ledger has rows) its channels; return its contact force."""
    torque_out[i] = total.sliding_torque + total.rolling_torque
    if channels_out.shape[0] > 0:
        channels_out[i, 0] = total.spring
        channels_out[i, 1] = total.sliding
        channels_out[i, 2] = total.sliding_torque
        channels_out[i, 3] = total.rolling
    return total.spring + total.sliding + total.rolling


#: A contact's channels on i, one per row: spring force, sliding force, sliding torque, rolling
#: force, rolling torque (the order of :func:`contact_function`'s results).
ContactRows = wp.types.matrix(shape=(5, 3), dtype=wp.float64)

#: The ledger's channels on i, one per row (the order of LEDGER_CHANNELS): one value, so that the
#: lanes of a block can sum them with one reduction (kernels/fused.py).
LedgerRows = wp.types.matrix(shape=(len(LEDGER_CHANNELS), 3), dtype=wp.float64)


@wp.func
def write_channels(rows: LedgerRows, i: int, channels_out: wp.array2d(dtype=wp.vec3d)):
    """Write i's ledger channels whole."""
    for k in range(wp.static(len(LEDGER_CHANNELS))):
        channels_out[i, k] = rows[k]


@wp.func
def contact_sum_of(rows: ContactRows) -> ContactSum:
    total = ContactSum()
    total.spring = rows[0]
    total.sliding = rows[1]
    total.sliding_torque = rows[2]
    total.rolling = rows[3]
    total.rolling_torque = rows[4]
    return total


# --- Candidate lists and the contact pass -------------------------------------------

#: Contact candidates a particle may note for the contact pass (the list's width; kernels read it
#: from the array).  A large grain of a settled pile touches up to ~27 small ones, ~33 when the
#: pile is squeezed to overlaps of 0.25 of a radius; the geometric limit for the paper's radius
#: ratio of 3 is ~60.  A particle with more has every j of its system looked at again, which is
#: right but costs a whole-system walk per step (24 slots made a merged pile 10x slower).
CANDIDATES = 64


@wp.func
def note_candidate(candidates: wp.array2d(dtype=wp.int32), i: int, noted: int, j: int) -> int:
    """Note j among i's ``noted`` candidates, kept in increasing j (a list is short: an insertion),
    once; returns the count noted.  Past the list's width it only counts (an overflow: the list
    is walked no more)."""
    if noted >= candidates.shape[1]:
        return noted + 1
    s = noted
    while s > 0:  # where j goes
        if candidates[i, s - 1] <= j:
            break
        s -= 1
    if s > 0:
        if candidates[i, s - 1] == j:  # met again
            return noted
    for k in range(noted, s, -1):
        candidates[i, k] = candidates[i, k - 1]
    candidates[i, s] = wp.int32(j)
    return noted + 1


@wp.func
def candidates_walk(i: int, ranges: wp.array(dtype=wp.vec2i), candidate_count: wp.array(dtype=wp.int32), candidates: wp.array2d(dtype=wp.int32)):
    """How i's candidates are walked: (listed, how many steps).  Listed: its noted candidates, in
    increasing j; after an overflow of the list, every j of its system, also in increasing j."""
    noted = candidate_count[i]
    if noted <= candidates.shape[1]:
        return True, noted
    return False, ranges[i][1] - ranges[i][0]


@wp.func
def candidate_at(i: int, listed: bool, ranges: wp.array(dtype=wp.vec2i), candidates: wp.array2d(dtype=wp.int32), s: int) -> int:
    """The candidate of step s of i's walk (:func:`candidates_walk`)."""
    if listed:
        return int(candidates[i, s])
    return int(ranges[i][0]) + s


@functools.cache
def contact_pass(law: str = "paper", lanes: int = 1, particles: int = 1, accumulate: bool = True):
    """Build the contact pass over candidate lists kept in increasing j: a block of ``particles``
    particles with ``lanes`` lanes each (8 x 4 on a GPU, 1 x 1 on the CPU; launch with
    ``wp.launch_tiled(dim=[ceil(N / particles)], block_dim=lanes * particles)``), each lane
    evaluating every ``lanes``-th candidate of its particle in float64 and adding them in list
    order, a particle's lanes then added in lane order (a tile sum along the lanes), so that the
    sum does not depend on scheduling (one lane: in increasing j).  After an overflow of the list,
    lane 0 looks at every j of the system in turn.  Writes ``torque_out`` and the ledger's
    ``channels_out`` (when it has rows) whole; with ``accumulate`` adds the contact force to
    ``force_inout`` (gravity's), without (gravity on its own clock) writes it there alone.

    Why groups of lanes: a particle lists ~8 candidates (~30 in a squeezed pile), so a warp of 32
    lanes a particle leaves most lanes idle and spends its time in a 32-lane reduction of 15
    float64 values; 8 lanes keep each lane busy and a warp serves four particles."""
    contact_channels = contact_function(law)
    add_contact = contact_sum_function(law)

    @wp.kernel(module="unique", enable_backward=False)
    def contact_pass_kernel(
        # Model:
        model: ContactModel,
        ranges_in: wp.array(dtype=wp.vec2i),  # per particle: its system's particles, [first, end)
        radius_in: wp.array(dtype=wp.float64),
        # In:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        candidate_count_in: wp.array(dtype=wp.int32),  # per particle: candidates noted (past the list's width: an overflow)
        candidates_in: wp.array2d(dtype=wp.int32),  # per particle: its candidates, in increasing j
        # Out:
        force_inout: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),
        deepest_inout: wp.array(dtype=wp.int64),  # raised to each contact's depth (note_depth), or empty
    ):
        block, thread = wp.tid()
        group = thread // wp.static(lanes)
        lane = thread - group * wp.static(lanes)
        i = block * wp.static(particles) + group
        # Past the last particle a lane still takes part in the block's reduction, with nothing.
        noted = int(0)
        listed = True
        if i < candidate_count_in.shape[0]:
            noted = int(candidate_count_in[i])
            listed = noted <= candidates_in.shape[1]
        mine = ContactRows()
        for slot in range(lane, wp.where(listed, noted, 0), wp.static(lanes)):
            spring, sliding, sliding_torque, rolling_force, rolling_torque = contact_channels(
                model, i, candidates_in[i, slot], radius_in, position_in, velocity_in, omega_in, deepest_inout
            )
            mine += wp.matrix_from_rows(spring, sliding, sliding_torque, rolling_force, rolling_torque)
        per_lane = wp.tile_reshape(wp.tile(mine, preserve_type=True), shape=(wp.static(particles), wp.static(lanes)))
        sums = wp.tile_sum(per_lane, axis=1)
        if lane == 0 and i < candidate_count_in.shape[0]:
            total = contact_sum_of(sums[group])
            if not listed:  # every j of the system, each checked in float64
                for j in range(ranges_in[i][0], ranges_in[i][1]):
                    total = add_contact(model, i, j, radius_in, position_in, velocity_in, omega_in, deepest_inout, total)
            contacts = write_contacts(total, i, torque_out, channels_out)
            if wp.static(accumulate):
                force_inout[i] = force_inout[i] + contacts
            else:
                force_inout[i] = contacts

    return contact_pass_kernel

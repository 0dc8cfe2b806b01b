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

from .channels import CONTACT_CHANNELS, LEDGER_CHANNELS
from .pair import CONTACT_LAWS, LAWS_WITH_SPRINGS, ContactModel, PairSprings, in_contact, overlap

wp.set_module_options({"enable_backward": False})

#: Where a contact's rows (ContactRows) hold each channel (kernels/channels.py CONTACT_CHANNELS).
SPRING_FORCE, SLIDING_FORCE, SLIDING_TORQUE, ROLLING_FORCE, ROLLING_TORQUE = (
    CONTACT_CHANNELS.index(name) for name in ("spring_force", "sliding_force", "sliding_torque", "rolling_force", "rolling_torque")
)


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


# --- A contact history: each particle's contacts by partner, with the pair's springs --------------
#
# A law with springs per pair (kernels/pair.py LAWS_WITH_SPRINGS) reads, for each pair it meets, the
# springs of the step before from the particle's own rows (found by the partner's index: carried
# whatever the candidate lists were rebuilt to, as long as the pair touched then), and writes the
# springs now into the next rows, in an order fixed whatever the scheduling: the contact pass (one
# lane a particle or several) and the reference kernel as the row of the contact's rank among the
# particle's, in increasing partner; the fused layout's lanes one lane's after another's (a scan of
# their counts).  A pair that no longer touches is not written, so that its springs are dropped.
# Both particles of a pair keep a copy: each evaluates the pair from its lower index with the same
# arguments (kernels/pair.py ssdem_contact), so the two copies stay the same bits, and no thread
# writes another particle's rows.  The two sets of rows then swap roles (decco_warp/arrays.py
# ContactHistory.commit, no launch); ``copy_springs`` copies one into the other only where a
# recorded graph needs the rows back in the buffer it was recorded with (ContactHistory.settle).


@wp.struct
class PairHistory:
    """Each particle's contacts at a contact evaluation, one row each, and their springs (the frame of
    the pair's lower index, kernels/pair.py PairSprings); arrays without rows for a law without springs."""

    count: wp.array(dtype=wp.int32)  # per particle: its contacts (past the rows' width: an overflow, the rest not kept)
    partner: wp.array2d(dtype=wp.int32)  # per particle and row: the other particle
    spring: wp.array2d(dtype=wp.vec3d)  # S [cm]
    normal: wp.array2d(dtype=wp.vec3d)  # n from the lower index to the higher
    rolling: wp.array2d(dtype=wp.vec3d)  # theta_r [rad]
    twist: wp.array2d(dtype=wp.float64)  # theta_t [rad]


@wp.func
def springs_at(history: PairHistory, i: int, row: int) -> PairSprings:
    """The springs of i's row ``row``."""
    springs = PairSprings()
    springs.spring = history.spring[i, row]
    springs.normal = history.normal[i, row]
    springs.rolling = history.rolling[i, row]
    springs.twist = history.twist[i, row]
    return springs


@wp.func
def springs_before(history: PairHistory, i: int, j: int, hint: int):
    """(found, springs) of the pair (i, j) in i's rows: found when they touched at the evaluation before.

    ``hint``: the row the pair is written to now, looked at first, then every row.  Rows are written
    in a fixed order (by the contact pass, one lane a particle or several, and the reference kernel in
    increasing partner: a pair's row is its rank among i's contacts; by the fused layout's lanes one
    lane's after another's), so the hint is the pair's row of the evaluation before unless a contact
    that comes before it in that order formed or broke since: one look in place of a scan of half the
    rows on average (99 % of the lookups in the shipped pile sheared, its lists rebuilt every few
    steps).  A particle holds a partner once, so the springs found do not depend on the hint, only the
    cost of finding them."""
    rows = wp.min(int(history.count[i]), history.partner.shape[1])
    if hint < rows:
        if int(history.partner[i, hint]) == j:
            return True, springs_at(history, i, hint)
    for row in range(rows):
        if int(history.partner[i, row]) == j:
            return True, springs_at(history, i, row)
    return False, PairSprings()


@wp.func
def keep_springs(history: PairHistory, i: int, row: int, j: int, springs: PairSprings):
    """Write the pair (i, j)'s springs as i's row ``row`` (past the rows' width: not kept, counted)."""
    if row < history.partner.shape[1]:
        history.partner[i, row] = wp.int32(j)
        history.spring[i, row] = springs.spring
        history.normal[i, row] = springs.normal
        history.rolling[i, row] = springs.rolling
        history.twist[i, row] = springs.twist


@wp.func
def close_rows(history: PairHistory, i: int, rows: int):
    """Note i's count of contacts (no-op for a law without springs)."""
    if history.count.shape[0] > 0:
        history.count[i] = wp.int32(rows)


@wp.func
def touches(i: int, j: int, radius_in: wp.array(dtype=wp.float64), position_in: wp.array(dtype=wp.vec3d)) -> bool:
    """Whether i and j (not the same) touch, in float64: the test every contact evaluation makes."""
    r_ij = position_in[i] - position_in[j]
    d2 = wp.dot(r_ij, r_ij)
    return d2 > wp.float64(0.0) and in_contact(d2, radius_in[i], radius_in[j])


@wp.kernel
def copy_springs(
    # In:
    history_in: PairHistory,
    # Out:
    history_out: PairHistory,
):
    """Copy one contact history's rows into another (ContactHistory.settle): a thread a row (launch over
    (particles, rows)), so that neighbouring threads copy neighbouring rows of one particle (one
    thread a particle walking its rows read and wrote memory a row's width apart: 8x the time)."""
    i, row = wp.tid()
    count = history_in.count[i]
    if row == 0:
        history_out.count[i] = count
    if row < int(count):
        history_out.partner[i, row] = history_in.partner[i, row]
        history_out.spring[i, row] = history_in.spring[i, row]
        history_out.normal[i, row] = history_in.normal[i, row]
        history_out.rolling[i, row] = history_in.rolling[i, row]
        history_out.twist[i, row] = history_in.twist[i, row]


@functools.cache
def contact_function(law: str):
    """The Warp function giving the contact channels on i from j if they touch, by ``law``
    (kernels/pair.py CONTACT_LAWS), in float64 from the state arrays.

    Returns (spring force, sliding force, sliding torque, rolling force, rolling torque, touching:
    1 or 0), the channels all zero for a pair that does not touch; notes the contact's depth in
    ``deepest_out`` (see :func:`note_depth`).  A law with springs reads the pair's springs of the
    step before in ``history_in`` and writes them now as i's row ``row`` of ``history_out``; its
    spring channel is the normal force (spring and dashpot), its sliding channel the tangential force,
    its rolling channel the rolling and twisting couple (no force).
    """
    contact = CONTACT_LAWS[law]
    springs = law in LAWS_WITH_SPRINGS

    @wp.func
    def contact_channels(
        model: ContactModel,
        i: int,
        j: int,
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        history_in: PairHistory,
        row: int,
        history_out: PairHistory,
        deepest_out: wp.array(dtype=wp.int64),
    ):
        # The separation is taken in float64: positions are ~1e7 cm, overlaps ~1e2 cm.
        r_ij = position_in[i] - position_in[j]
        d2 = wp.dot(r_ij, r_ij)
        # d2 == 0: the particle itself, or a coincident one, which has no direction.
        if d2 > wp.float64(0.0) and in_contact(d2, radius_in[i], radius_in[j]):
            note_depth(deepest_out, i, j, d2, radius_in[i], radius_in[j])
            if wp.static(springs):
                found, before = springs_before(history_in, i, j, row)
                # The pair from its lower index p, one call with the same arguments on either side.
                p = wp.min(i, j)
                q = wp.max(i, j)
                normal, tangential, torque_p, torque_q, couple, now = wp.static(contact)(
                    model, position_in[p], velocity_in[p], omega_in[p], radius_in[p], mass_in[p],
                    position_in[q], velocity_in[q], omega_in[q], radius_in[q], mass_in[q], before, found,
                )  # fmt: skip
                keep_springs(history_out, i, row, j, now)
                if i == p:
                    return normal, tangential, torque_p, wp.vec3d(), couple, 1
                return -normal, -tangential, torque_q, wp.vec3d(), -couple, 1
            else:
                spring, sliding, sliding_torque, rolling_force, rolling_torque = wp.static(contact)(
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
                return spring, sliding, sliding_torque, rolling_force, rolling_torque, 1
        return wp.vec3d(), wp.vec3d(), wp.vec3d(), wp.vec3d(), wp.vec3d(), 0

    return contact_channels


#: A contact's channels on i, one per row (kernels/channels.py CONTACT_CHANNELS: spring force,
#: sliding force, sliding torque, rolling force, rolling torque, the order of
#: :func:`contact_function`'s results), or their sum over i's contacts.
ContactRows = wp.types.matrix(shape=(len(CONTACT_CHANNELS), 3), dtype=wp.float64)

#: The ledger's channels on i, one per row (the order of LEDGER_CHANNELS, the first rows of a
#: ContactRows): one value, so that the lanes of a block can sum them with one reduction (kernels/fused.py).
LedgerRows = wp.types.matrix(shape=(len(LEDGER_CHANNELS), 3), dtype=wp.float64)


@functools.cache
def contact_sum_function(law: str):
    """The Warp function adding the contact channels on i from j (zero unless they touch) to a
    ContactRows sum; returns it and the count of i's contacts met (``rows`` before: the row j's springs
    are kept in, for a law with springs)."""
    contact_channels = contact_function(law)

    @wp.func
    def add_contact(
        model: ContactModel,
        i: int,
        j: int,
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        history_in: PairHistory,
        rows: int,
        history_out: PairHistory,
        deepest_out: wp.array(dtype=wp.int64),
        total: ContactRows,
    ):
        spring, sliding, sliding_torque, rolling_force, rolling_torque, touching = contact_channels(
            model, i, j, radius_in, mass_in, position_in, velocity_in, omega_in, history_in, rows, history_out, deepest_out
        )
        return total + wp.matrix_from_rows(spring, sliding, sliding_torque, rolling_force, rolling_torque), rows + touching

    return add_contact


@wp.func
def write_contacts(total: ContactRows, i: int, torque_out: wp.array(dtype=wp.vec3d), channels_out: wp.array2d(dtype=wp.vec3d)) -> wp.vec3d:
    """Write i's contact torque and (when the ledger has rows) its channels; return its contact force."""
    torque_out[i] = total[SLIDING_TORQUE] + total[ROLLING_TORQUE]
    if channels_out.shape[0] > 0:
        for k in range(wp.static(len(LEDGER_CHANNELS))):
            channels_out[i, k] = total[k]
    return total[SPRING_FORCE] + total[SLIDING_FORCE] + total[ROLLING_FORCE]


@wp.func
def write_channels(rows: LedgerRows, i: int, channels_out: wp.array2d(dtype=wp.vec3d)):
    """Write i's ledger channels whole."""
    for k in range(wp.static(len(LEDGER_CHANNELS))):
        channels_out[i, k] = rows[k]


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

    A law with springs (``history_out``) takes the same lanes.  Its lanes walk the list in rounds,
    slot ``round * lanes + lane`` in each; each lane first tests its slot (``touches``, the contact
    evaluation's own test), and a scan of those tests over the block gives each contact its rank
    among i's contacts in list order, which is its row: the rows a particle writes are then those
    of one lane, in the same order (increasing partner), whatever the lanes and the scheduling.
    The rank also points the springs' lookup at the pair's row of the evaluation before
    (:func:`springs_before`).  Past the list's width lane 0 goes on in increasing j, as one lane does,
    so that which contacts overflow the rows is the same too.

    Why groups of lanes: a particle lists ~8 candidates (~30 in a squeezed pile), so a warp of 32
    lanes a particle leaves most lanes idle and spends its time in a 32-lane reduction of 15
    float64 values; 8 lanes keep each lane busy and a warp serves four particles."""
    contact_channels = contact_function(law)
    add_contact = contact_sum_function(law)
    springs = law in LAWS_WITH_SPRINGS

    @wp.kernel(module="unique", enable_backward=False)
    def contact_pass_kernel(
        # Model:
        model: ContactModel,
        ranges_in: wp.array(dtype=wp.vec2i),  # per particle: its system's particles, [first, end)
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        # In:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        history_in: PairHistory,  # the contacts' springs at the evaluation before (a law with springs)
        candidate_count_in: wp.array(dtype=wp.int32),  # per particle: candidates noted (past the list's width: an overflow)
        candidates_in: wp.array2d(dtype=wp.int32),  # per particle: its candidates, in increasing j
        # Out:
        force_inout: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),
        deepest_inout: wp.array(dtype=wp.int64),  # raised to each contact's depth (note_depth), or empty
        history_out: PairHistory,  # the contacts' springs now, in increasing partner (a law with springs)
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
        rows = int(0)  # i's contacts met (where rows are kept: every lane of i's group holds their count)
        if wp.static(springs):
            walk = wp.where(listed, noted, 0)
            # Rounds of a slot a lane, as many as the block's longest list needs: the scans below are
            # the block's, so that every lane of the block takes part in each (a particle with fewer,
            # or none, with nothing).
            rounds = (int(wp.tile_max(wp.tile(walk))[0]) + wp.static(lanes) - 1) // wp.static(lanes)
            for r in range(rounds):
                slot = r * wp.static(lanes) + lane
                j = int(0)
                touching = int(0)
                if slot < walk:
                    j = int(candidates_in[i, slot])
                    if touches(i, j, radius_in, position_in):
                        touching = 1
                # This contact's rank among i's: i's contacts of the rounds before, and of this round
                # those of the lanes before this one (the block's scan less the groups before i's).
                tests = wp.tile(touching)
                before = int(wp.untile(wp.tile_scan_exclusive(tests)))
                per_group = wp.tile_sum(wp.tile_reshape(tests, shape=(wp.static(particles), wp.static(lanes))), axis=1)
                for g in range(group):
                    before -= int(per_group[g])
                if slot < walk:
                    spring, sliding, sliding_torque, rolling_force, rolling_torque, met = contact_channels(
                        model, i, j, radius_in, mass_in, position_in, velocity_in, omega_in, history_in, rows + before,
                        history_out, deepest_inout,
                    )  # fmt: skip
                    mine += wp.matrix_from_rows(spring, sliding, sliding_torque, rolling_force, rolling_torque)
                rows += int(per_group[group])
        else:
            for slot in range(lane, wp.where(listed, noted, 0), wp.static(lanes)):
                spring, sliding, sliding_torque, rolling_force, rolling_torque, touching = contact_channels(
                    model, i, candidates_in[i, slot], radius_in, mass_in, position_in, velocity_in, omega_in, history_in, rows,
                    history_out, deepest_inout,
                )  # fmt: skip
                mine += wp.matrix_from_rows(spring, sliding, sliding_torque, rolling_force, rolling_torque)
                rows += touching
        per_lane = wp.tile_reshape(wp.tile(mine, preserve_type=True), shape=(wp.static(particles), wp.static(lanes)))
        sums = wp.tile_sum(per_lane, axis=1)
        if lane == 0 and i < candidate_count_in.shape[0]:
            total = sums[group]
            if not listed:  # every j of the system, each checked in float64
                for j in range(ranges_in[i][0], ranges_in[i][1]):
                    total, rows = add_contact(
                        model, i, j, radius_in, mass_in, position_in, velocity_in, omega_in, history_in, rows, history_out, deepest_inout, total
                    )
            close_rows(history_out, i, rows)
            contacts = write_contacts(total, i, torque_out, channels_out)
            if wp.static(accumulate):
                force_inout[i] = force_inout[i] + contacts
            else:
                force_inout[i] = contacts

    return contact_pass_kernel

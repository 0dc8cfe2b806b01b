"""All-pairs force and torque kernels: gravity between every pair, contact between overlapping ones.

* ``pair_gravity_newton`` + ``gather_newton`` + ``contact_pass_ordered`` -- the CUDA default (the
  Newton layout): each pair's gravity computed once and given to both particles, a warp meeting two
  tiles of particles, the j side moving lane to lane by register shuffles; per tile pair a row of
  field sums and contact-candidate words, which the gather adds up per particle in a fixed order,
  listing its candidates in increasing j; then the contacts in float64, a warp per particle.  No
  atomics: the motion does not depend on scheduling.
* ``pair_forces_tiled`` -- the fused kernel (the CPU default).  A block of ``block_dim``
  threads owns ``particles_per_block`` particles i and sweeps all j in tiles of
  ``block_dim``, loaded cooperatively with ``wp.tile_load`` (one j per thread;
  one thread per block on CPU, so the same source serves both).  Each j load
  serves every particle of the block.  The sweep itself is gravity only, plus a
  cheap test that notes contact candidates in a few slots; the contacts, which
  are few, are evaluated in float64 after the sweep, so that the hot loop stays
  small.  Per-thread sums are reduced with ``wp.tile_sum`` and lane 0 writes
  each particle's force and torque: no atomics, and the motion does not depend
  on scheduling.  (The energy ledger's contact channels are added with atomics;
  on a GPU their last bits may vary from run to run, the motion's never.)
* ``pair_gravity_tiled`` + ``contact_pass`` -- the same work split in two launches
  (``Layout(contact_pass=True)``, opt-in until measured on a GPU): the tiled sweep keeps only
  gravity and notes each particle's contact candidates in a global list (atomics, any order);
  then one thread per particle walks its list in increasing j and evaluates the contacts in float64.  The
  sweep carries no contact code, so it needs fewer registers; the fixed order keeps the motion (and
  here the ledger too) independent of scheduling.
* ``pair_forces_reference`` -- one thread per particle, a plain loop over j.  It
  is the yardstick for tests and the baseline of ``decco-warp bench``.

Kernels are built by cached factories, specialised on layout, precision,
rolling-friction form and ledger, each in its own Warp module so that a variant
compiles once and never forces another to recompile.

Precision:
    ``"mixed"`` (default): the sweep reads packed float32 bodies (position split
    into float32 hi + lo, so that a separation keeps float32 *relative*
    precision however far from the origin; radius; G m), gravity is float32
    with fast math, and contact candidates are confirmed in float64.  Every
    contact quantity is float64; sums are float32.
    ``"float64"``: everything in double.
"""

import functools
from typing import Any

import warp as wp

from .pair import CONTACT_FUNCTIONS, ContactModel, gravity, in_contact, inverse_sqrt_exact, inverse_sqrt_fast, overlap

wp.set_module_options({"enable_backward": False})

PRECISIONS = ("mixed", "float64")

#: Packed particles for the sweep.  mixed: hi xyz, lo xyz, radius, G m (float32);
#: float64: x y z, radius, G m.
BodyMixed = wp.types.vector(length=8, dtype=wp.float32)
BodyDouble = wp.types.vector(length=5, dtype=wp.float64)
BODY_TYPES = {"mixed": BodyMixed, "float64": BodyDouble}

#: A float32 separation is good to ~1e-7 relative; pairs this close (in d^2) are
#: contact candidates, confirmed or rejected in float64.
CONTACT_CANDIDATE = 1.0 + 1e-5

#: Per-particle contact channels written by the ledger variants, in this order
#: (float64, summed over contacts); gravity is the rest of the force.
LEDGER_CHANNELS = ("spring_force", "sliding_force", "sliding_torque", "rolling_force")


@wp.kernel
def pack_bodies_mixed(
    # Model:
    G: wp.float64,
    radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64),
    # State in:
    position_in: wp.array(dtype=wp.vec3d),
    # Out:
    body_out: wp.array(dtype=BodyMixed),
):
    """Split each float64 position into float32 hi + lo: (hi_i - hi_j) + (lo_i - lo_j) is then
    accurate to float32 relative precision of the separation itself."""
    i = wp.tid()
    x = position_in[i]
    hi = wp.vec3f(x)
    lo = wp.vec3f(x - wp.vec3d(hi))
    body_out[i] = BodyMixed(
        hi[0], hi[1], hi[2], lo[0], lo[1], lo[2], wp.float32(radius_in[i]), wp.float32(G * mass_in[i])
    )


@wp.kernel
def pack_bodies_double(
    # Model:
    G: wp.float64,
    radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64),
    # State in:
    position_in: wp.array(dtype=wp.vec3d),
    # Out:
    body_out: wp.array(dtype=BodyDouble),
):
    i = wp.tid()
    x = position_in[i]
    body_out[i] = BodyDouble(x[0], x[1], x[2], radius_in[i], G * mass_in[i])


PACK_KERNELS = {"mixed": pack_bodies_mixed, "float64": pack_bodies_double}


@wp.func
def separation(body_i: BodyMixed, body_j: BodyMixed) -> wp.vec3f:
    """r_ij from packed float32 bodies: hi and lo differences summed."""
    hi = wp.vec3f(body_i[0], body_i[1], body_i[2]) - wp.vec3f(body_j[0], body_j[1], body_j[2])
    lo = wp.vec3f(body_i[3], body_i[4], body_i[5]) - wp.vec3f(body_j[3], body_j[4], body_j[5])
    return hi + lo


@wp.func
def separation(body_i: BodyDouble, body_j: BodyDouble) -> wp.vec3d:
    """r_ij from packed float64 bodies."""
    return wp.vec3d(body_i[0], body_i[1], body_i[2]) - wp.vec3d(body_j[0], body_j[1], body_j[2])


def _real_types(precision: str):
    if precision not in BODY_TYPES:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    return (wp.float32, wp.vec3f) if precision == "mixed" else (wp.float64, wp.vec3d)


def _inverse_sqrt(precision: str):
    """The sweep's 1/d: one rsqrt instruction on a GPU in the default precision, exact in float64."""
    return inverse_sqrt_fast if precision == "mixed" else inverse_sqrt_exact


@wp.func
def is_candidate(d2: Any, radius_i: Any, radius_j: Any, candidate: Any) -> bool:
    """The sweep's contact test: d^2 < (R_i + R_j)^2 (1 + margin), confirmed later in float64."""
    reach = radius_i + radius_j
    return d2 < reach * reach * candidate


@wp.func
def near_bound(radius_i: Any, max_radius: Any, candidate: Any) -> Any:
    """The same bound with R_max for R_j: computed once per i, it holds every candidate of i
    (rounding is monotone, so R_j <= R_max gives a bound no smaller), and one comparison
    per pair clears the others."""
    reach = radius_i + max_radius
    return reach * reach * candidate


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


@wp.func
def unpack_block(block: wp.vec4i):
    """A tiled block's rows [first, end) and its system's particles [j_first, j_end) (Engine.blocks)."""
    return block[0], block[1], block[2], block[3]


@functools.cache
def contact_function(rolling: str):
    """The Warp function giving the contact channels on i from j if they touch, in float64 from the state arrays.

    Returns (spring force, sliding force, sliding torque, rolling force, rolling
    torque), all zero for a pair that does not touch; notes the contact's depth in
    ``deepest_out`` (see :func:`note_depth`).
    """
    contact = CONTACT_FUNCTIONS[rolling]

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
def contact_sum_function(rolling: str):
    """The Warp function adding the contact channels on i from j (zero unless they touch) to a ContactSum."""
    contact_channels = contact_function(rolling)

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


@functools.cache
def pair_forces_tiled(
    block_dim: int,
    particles_per_block: int,
    contact_slots: int,
    precision: str = "mixed",
    rolling: str = "couple",
    ledger: bool = False,
    max_registers: int = 0,
    prefetch: bool = False,
):
    """Build the tiled all-pairs kernel for a layout; launch with ``wp.launch_tiled``.

    Launch: ``ceil(N / particles_per_block)`` blocks of ``block_dim`` threads
    (``block_dim`` must be 1 on CPU, where Warp runs one thread per block), with
    ``body_in`` packed by ``PACK_KERNELS[precision]``.  Each thread notes up to
    ``contact_slots`` contact candidates per particle; past that it finds them
    again after the sweep, so any number of contacts is handled.  ``max_registers``
    (CUDA, 0 = the compiler's choice) caps registers per thread: the float64
    contact code, which runs rarely, then spills instead of the sweep losing occupancy.
    ``prefetch`` loads each tile of j one tile ahead.
    """
    real, _ = _real_types(precision)
    inverse_sqrt = _inverse_sqrt(precision)
    Body = BODY_TYPES[precision]
    contact_channels = contact_function(rolling)
    T, P, K = block_dim, particles_per_block, contact_slots
    radius_at, g_mass_at = (6, 7) if precision == "mixed" else (3, 4)
    candidate = real(CONTACT_CANDIDATE if precision == "mixed" else 1.0)
    Bodies = wp.types.matrix(shape=(P, Body._length_), dtype=real)
    Near = wp.types.vector(length=P, dtype=real)
    Fields = wp.types.matrix(shape=(P, 3), dtype=real)
    Slots = wp.types.matrix(shape=(P, K), dtype=wp.int32)
    Counts = wp.types.vector(length=P, dtype=wp.int32)
    # Per particle: the field sum G m_j r_ij / d^3 (gravity is -m_i times it), contact force, torque.
    Sums = wp.types.matrix(shape=(P, 9), dtype=real)
    Sum = wp.types.vector(length=9, dtype=real)
    Contacts = wp.types.matrix(shape=(P, 6), dtype=real)

    @wp.kernel(
        module="unique",
        enable_backward=False,
        module_options={"fast_math": precision == "mixed"},
        cuda_max_registers=max_registers or None,
    )
    def pair_forces_tiled_kernel(
        # Model:
        model: ContactModel,
        blocks: wp.array(dtype=wp.vec4i),  # per block: first particle, end of its rows, its system's j range
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        # State in:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        body_in: wp.array(dtype=Body),
        max_radius: real,  # the largest radius: a per-i bound that spares most pairs the contact test
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),  # (N, 4) with the ledger, else empty; zeroed by the caller
        deepest_out: wp.array(dtype=wp.int64),  # raised to each contact's depth (note_depth), or empty
    ):
        block, lane = wp.tid()
        first, end, j_first, j_end = unpack_block(blocks[block])

        # The block's own particles stay in registers; rows past the end repeat the
        # last particle and are never written.
        bodies_i = Bodies()
        near = Near()
        for p in range(wp.static(P)):
            bodies_i[p] = body_in[wp.min(first + p, end - 1)]
            near[p] = near_bound(bodies_i[p][radius_at], max_radius, candidate)

        fields = Fields()
        slots = Slots()
        candidates = Counts()
        # With prefetch each tile of j is loaded one tile ahead, so that the load is in flight
        # while the tile before is swept (latency hidden at low occupancy); past the array a
        # tile holds zeros, never used.
        if wp.static(prefetch):
            body_next = wp.untile(wp.tile_load(body_in, shape=wp.static(T), offset=j_first, storage="register"))
        for start in range(j_first, j_end, wp.static(T)):
            # One j per thread (counted from the system's first, so that a system's sums do not
            # depend on where it sits among others); elements past its end are skipped.
            if wp.static(prefetch):
                body_j = body_next
                body_next = wp.untile(wp.tile_load(body_in, shape=wp.static(T), offset=start + wp.static(T), storage="register"))
            else:
                body_j = wp.untile(wp.tile_load(body_in, shape=wp.static(T), offset=start, storage="register"))
            j = start + lane
            if j < j_end:
                for p in range(wp.static(P)):
                    r = separation(bodies_i[p], body_j)
                    d2 = wp.dot(r, r)
                    if d2 > real(0.0):  # not the particle itself
                        inv_d = inverse_sqrt(d2)
                        fields[p] = fields[p] + (body_j[g_mass_at] * inv_d * inv_d * inv_d) * r
                        if d2 < near[p]:  # within R_i + R_max: rare, so the exact test costs little
                            if is_candidate(d2, bodies_i[p][radius_at], body_j[radius_at], candidate):
                                noted = candidates[p]
                                if noted < wp.static(K):
                                    slots[p, noted] = j
                                candidates[p] = noted + 1

        # Contacts, in float64: the noted candidates, or after an overflow of the slots,
        # this thread's share of j looked at again; either way in increasing j.  The
        # loop over the block's particles is deliberately not unrolled: one copy of the
        # contact code keeps the kernel's register count (and so the sweep's occupancy) low.
        contacts = Contacts()
        for p in range(wp.min(wp.static(P), end - first)):  # a run-time bound: not unrolled
            i = first + p
            noted = candidates[p]
            overflow = noted > wp.static(K)
            walk = noted
            body_i = body_in[i]
            if overflow:
                walk = (j_end - j_first - lane + wp.static(T) - 1) // wp.static(T)
            for s in range(walk):
                j = 0
                if overflow:
                    j = j_first + lane + s * wp.static(T)
                    body_j = body_in[j]
                    r = separation(body_i, body_j)
                    reach = body_i[radius_at] + body_j[radius_at]
                    if wp.dot(r, r) >= reach * reach * candidate:
                        continue
                else:
                    j = slots[p, s]
                spring, sliding, sliding_torque, rolling, rolling_torque = contact_channels(
                    model, i, j, radius_in, position_in, velocity_in, omega_in, deepest_out
                )
                force = spring + sliding + rolling
                torque = sliding_torque + rolling_torque
                for k in range(3):
                    contacts[p, k] += real(force[k])
                    contacts[p, 3 + k] += real(torque[k])
                if wp.static(ledger):
                    # Atomics: the channel sums feed only the energy ledger, never the motion,
                    # and keeping them out of the reduction keeps the kernel lean.
                    wp.atomic_add(channels_out, i, 0, spring)
                    wp.atomic_add(channels_out, i, 1, sliding)
                    wp.atomic_add(channels_out, i, 2, sliding_torque)
                    wp.atomic_add(channels_out, i, 3, rolling)

        sums = Sums()
        for p in range(wp.static(P)):
            field = fields[p]
            row = Sum()
            for k in range(3):
                row[k] = field[k]
            for k in range(6):
                row[3 + k] = contacts[p, k]
            sums[p] = row

        total = wp.tile_sum(wp.tile(sums, preserve_type=True))[0]
        if lane == 0:
            for p in range(wp.static(P)):
                i = first + p
                if i < end:
                    row = total[p]
                    field_sum = wp.vec3d(wp.float64(row[0]), wp.float64(row[1]), wp.float64(row[2]))
                    contact_sum = wp.vec3d(wp.float64(row[3]), wp.float64(row[4]), wp.float64(row[5]))
                    force_out[i] = contact_sum - mass_in[i] * field_sum
                    torque_out[i] = wp.vec3d(wp.float64(row[6]), wp.float64(row[7]), wp.float64(row[8]))

    return pair_forces_tiled_kernel


#: Contact candidates a particle may note for the contact pass (the list's width; kernels read it
#: from the array).  A large grain of a settled pile touches up to ~27 small ones, ~33 when the
#: pile is squeezed to overlaps of 0.25 of a radius; the geometric limit for the paper's radius
#: ratio of 3 is ~60.  A particle with more has every j of its system looked at again, which is
#: right but costs a whole-system walk per step (24 slots made a merged pile 10x slower).
CANDIDATES = 64


@wp.func
def candidates_walk(i: int, ranges: wp.array(dtype=wp.vec2i), candidate_count: wp.array(dtype=wp.int32), candidates: wp.array2d(dtype=wp.int32)):
    """How i's candidates are walked: (listed, how many steps).  Listed: its noted candidates in
    increasing j (see :func:`next_candidate`), so that sums over them do not depend on the order
    they were noted in; after an overflow of the list, every j of its system."""
    noted = candidate_count[i]
    if noted <= candidates.shape[1]:
        return True, noted
    return False, ranges[i][1] - ranges[i][0]


@wp.func
def next_candidate(i: int, listed: bool, candidates: wp.array2d(dtype=wp.int32), walk: int, previous: int) -> int:
    """The candidate after ``previous`` (start from the system's first particle - 1): the smallest
    noted j above it (a selection pass over the row: no per-thread copy of the list), or simply
    the next j of the system after an overflow."""
    if not listed:
        return previous + 1
    best = int(2147483647)
    for s in range(walk):
        j = candidates[i, s]
        if j > previous and j < best:
            best = j
    return best


@functools.cache
def pair_gravity_tiled(block_dim: int, particles_per_block: int, precision: str = "mixed", max_registers: int = 0, prefetch: bool = False):
    """Build the sweep of the split layout: gravity between every pair, and each particle's contact
    candidates appended to ``candidates`` (counted in ``candidate_count``, zeroed by the caller).

    Launch like :func:`pair_forces_tiled`; ``force_out`` receives gravity only, and
    :func:`contact_pass` adds the contacts.
    """
    real, _ = _real_types(precision)
    inverse_sqrt = _inverse_sqrt(precision)
    Body = BODY_TYPES[precision]
    T, P = block_dim, particles_per_block
    radius_at, g_mass_at = (6, 7) if precision == "mixed" else (3, 4)
    candidate = real(CONTACT_CANDIDATE if precision == "mixed" else 1.0)
    Bodies = wp.types.matrix(shape=(P, Body._length_), dtype=real)
    Near = wp.types.vector(length=P, dtype=real)
    Fields = wp.types.matrix(shape=(P, 3), dtype=real)

    @wp.kernel(
        module="unique",
        enable_backward=False,
        module_options={"fast_math": precision == "mixed"},
        cuda_max_registers=max_registers or None,
    )
    def pair_gravity_tiled_kernel(
        # Model:
        blocks: wp.array(dtype=wp.vec4i),  # per block: first particle, end of its rows, its system's j range
        mass_in: wp.array(dtype=wp.float64),
        # State in:
        body_in: wp.array(dtype=Body),
        max_radius: real,  # the largest radius: a per-i bound that spares most pairs the contact test
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        candidate_count: wp.array(dtype=wp.int32),
        candidates: wp.array2d(dtype=wp.int32),
    ):
        block, lane = wp.tid()
        first, end, j_first, j_end = unpack_block(blocks[block])
        bodies_i = Bodies()
        near = Near()
        for p in range(wp.static(P)):
            bodies_i[p] = body_in[wp.min(first + p, end - 1)]
            near[p] = near_bound(bodies_i[p][radius_at], max_radius, candidate)

        fields = Fields()
        if wp.static(prefetch):  # as in pair_forces_tiled
            body_next = wp.untile(wp.tile_load(body_in, shape=wp.static(T), offset=j_first, storage="register"))
        for start in range(j_first, j_end, wp.static(T)):
            if wp.static(prefetch):
                body_j = body_next
                body_next = wp.untile(wp.tile_load(body_in, shape=wp.static(T), offset=start + wp.static(T), storage="register"))
            else:
                body_j = wp.untile(wp.tile_load(body_in, shape=wp.static(T), offset=start, storage="register"))
            j = start + lane
            if j < j_end:
                for p in range(wp.static(P)):
                    r = separation(bodies_i[p], body_j)
                    d2 = wp.dot(r, r)
                    if d2 > real(0.0):  # not the particle itself
                        inv_d = inverse_sqrt(d2)
                        fields[p] = fields[p] + (body_j[g_mass_at] * inv_d * inv_d * inv_d) * r
                        # Rows past the end repeat the last particle: they note nothing.
                        if d2 < near[p] and first + p < end:  # within R_i + R_max: rare
                            if is_candidate(d2, bodies_i[p][radius_at], body_j[radius_at], candidate):
                                slot = wp.atomic_add(candidate_count, first + p, 1)
                                if slot < candidates.shape[1]:
                                    candidates[first + p, slot] = j

        total = wp.tile_sum(wp.tile(fields, preserve_type=True))[0]
        if lane == 0:
            for p in range(wp.static(P)):
                i = first + p
                if i < end:
                    row = total[p]
                    field_sum = wp.vec3d(wp.float64(row[0]), wp.float64(row[1]), wp.float64(row[2]))
                    force_out[i] = -mass_in[i] * field_sum

    return pair_gravity_tiled_kernel


#: A contact's channels on i, one per row: spring force, sliding force, sliding torque, rolling
#: force, rolling torque (the order of :func:`contact_function`'s results).
ContactRows = wp.types.matrix(shape=(5, 3), dtype=wp.float64)


@wp.func
def contact_sum_of(rows: ContactRows) -> ContactSum:
    total = ContactSum()
    total.spring = rows[0]
    total.sliding = rows[1]
    total.sliding_torque = rows[2]
    total.rolling = rows[3]
    total.rolling_torque = rows[4]
    return total


@functools.cache
def contact_pass(rolling: str = "couple"):
    """Build the second launch of the split layout, one thread per particle: its noted candidates
    sorted by j, each evaluated in float64 and added to ``force_inout``; ``torque_out`` and the
    ledger's ``channels_out`` (when it has rows) are written whole."""
    add_contact = contact_sum_function(rolling)

    @wp.kernel(module="unique", enable_backward=False)
    def contact_pass_kernel(
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
        force_inout: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),
        deepest_out: wp.array(dtype=wp.int64),
    ):
        i = wp.tid()
        listed, walk = candidates_walk(i, ranges, candidate_count, candidates)
        total = ContactSum()
        j = ranges[i][0] - 1
        for _ in range(walk):  # the list, or every j after an overflow (each pair checked in float64)
            j = next_candidate(i, listed, candidates, walk, j)
            total = add_contact(model, i, j, radius_in, position_in, velocity_in, omega_in, deepest_out, total)
        force_inout[i] = force_inout[i] + write_contacts(total, i, torque_out, channels_out)

    return contact_pass_kernel


@functools.cache
def contact_pass_ordered(rolling: str = "couple", block_dim: int = 1):
    """Build the contact pass for candidate lists that come in increasing j (the Newton layout's):
    a block of ``block_dim`` lanes per particle (32 on a GPU, 1 on the CPU; launch with
    ``wp.launch_tiled(dim=[N])``), each lane evaluating every ``block_dim``-th candidate in float64
    and adding them in list order, the lanes then reduced in a fixed order, so that the sum does not
    depend on scheduling (on the CPU: in increasing j, as :func:`contact_pass`).  After an overflow of
    the list, lane 0 looks at every j of the system in turn.  Writes ``torque_out`` and the ledger's
    ``channels_out`` (when it has rows) whole and adds the contact force to ``force_inout``."""
    contact_channels = contact_function(rolling)
    add_contact = contact_sum_function(rolling)

    @wp.kernel(module="unique", enable_backward=False)
    def contact_pass_ordered_kernel(
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
        force_inout: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),
        deepest_out: wp.array(dtype=wp.int64),
    ):
        i, lane = wp.tid()
        noted = candidate_count[i]
        listed = noted <= candidates.shape[1]
        mine = ContactRows()
        for slot in range(lane, wp.where(listed, noted, 0), wp.block_dim()):
            spring, sliding, sliding_torque, rolling_force, rolling_torque = contact_channels(
                model, i, candidates[i, slot], radius_in, position_in, velocity_in, omega_in, deepest_out
            )
            mine += wp.matrix_from_rows(spring, sliding, sliding_torque, rolling_force, rolling_torque)
        total = contact_sum_of(wp.tile_sum(wp.tile(mine, preserve_type=True))[0])
        if lane == 0:
            if not listed:  # every j of the system, each checked in float64
                for j in range(ranges[i][0], ranges[i][1]):
                    total = add_contact(model, i, j, radius_in, position_in, velocity_in, omega_in, deepest_out, total)
            force_inout[i] = force_inout[i] + write_contacts(total, i, torque_out, channels_out)

    return contact_pass_ordered_kernel


# --- Newton's third law: each pair once ------------------------------------------------------

#: A tile-pair block of the Newton layout: its i tile [i_first, i_end), its j tile [j_first, j_end),
#: the row of the sweep's outputs its i tile's sums go to and the row its j tile's go to (-1 on the
#: diagonal, where i and j are the same tile and every pair is met from both sides).
TilePair = wp.types.vector(length=6, dtype=wp.int32)

#: What the gather needs of a particle: its first row of the sweep's outputs (one per tile of its
#: system, in order), how many, its column (its place in its tile) and its system's first particle.
GatherRows = wp.types.vector(length=4, dtype=wp.int32)

#: The Newton layout's tiles hold at most this many particles: a particle's contact candidates in
#: another tile are the bits of one 64-bit word.
NEWTON_TILE_MAX = 64

# One lane's value from lane ``source`` of its warp (a warp is one block of the Newton layout).
# On the CPU a block has one lane, which holds every value itself.
_LANE_VALUE = """
#if defined(__CUDA_ARCH__)
return __shfl_sync(0xffffffffu, value, source);
#else
return value;
#endif
"""


@wp.func_native(_LANE_VALUE)
def lane_value_f32(value: wp.float32, source: int) -> wp.float32: ...


@wp.func_native(_LANE_VALUE)
def lane_value_f64(value: wp.float64, source: int) -> wp.float64: ...


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
return __shfl_sync(0xffffffffu, (unsigned long long)value, source);
#else
return value;
#endif
"""
)
def lane_value_u64(value: wp.uint64, source: int) -> wp.uint64: ...


@wp.func_native(
    """
#if defined(__CUDA_ARCH__)
return __ffsll((long long)bits) - 1;
#else
return __builtin_ctzll(bits);
#endif
"""
)
def lowest_bit(bits: wp.uint64) -> wp.int32: ...


#: Where an absent particle of a tile (past its system's end) sits: far from everything (d^2 ~ 1e36
#: stays finite in float32), massless and of no size, so that it adds nothing and is near nothing.
ABSENT = 1.0e18


@wp.func
def absent_body(like: BodyMixed) -> BodyMixed:
    a = wp.float32(ABSENT)
    return BodyMixed(a, a, a, wp.float32(0.0), wp.float32(0.0), wp.float32(0.0), wp.float32(0.0), wp.float32(0.0))


@wp.func
def absent_body(like: BodyDouble) -> BodyDouble:
    a = wp.float64(ABSENT)
    return BodyDouble(a, a, a, wp.float64(0.0), wp.float64(0.0))


@wp.func
def body_from_lane(body: BodyMixed, source: int) -> BodyMixed:
    """The body held by lane ``source``."""
    return BodyMixed(
        lane_value_f32(body[0], source), lane_value_f32(body[1], source), lane_value_f32(body[2], source),
        lane_value_f32(body[3], source), lane_value_f32(body[4], source), lane_value_f32(body[5], source),
        lane_value_f32(body[6], source), lane_value_f32(body[7], source),
    )  # fmt: skip


@wp.func
def body_from_lane(body: BodyDouble, source: int) -> BodyDouble:
    return BodyDouble(
        lane_value_f64(body[0], source), lane_value_f64(body[1], source), lane_value_f64(body[2], source),
        lane_value_f64(body[3], source), lane_value_f64(body[4], source),
    )  # fmt: skip


@wp.func
def field_from_lane(field: wp.vec3f, source: int) -> wp.vec3f:
    return wp.vec3f(lane_value_f32(field[0], source), lane_value_f32(field[1], source), lane_value_f32(field[2], source))


@wp.func
def field_from_lane(field: wp.vec3d, source: int) -> wp.vec3d:
    return wp.vec3d(lane_value_f64(field[0], source), lane_value_f64(field[1], source), lane_value_f64(field[2], source))


@functools.cache
def pair_gravity_newton(particles_per_lane: int, precision: str = "mixed", max_registers: int = 0):
    """Build the Newton-layout sweep: gravity of each pair computed once and given to both sides,
    and each pair's contact candidacy noted for both.

    One block is one warp (``wp.block_dim()`` lanes: 32 on a GPU, 1 on the CPU) and meets two tiles
    of ``lanes * particles_per_lane`` particles (at most NEWTON_TILE_MAX), i and j (``TilePair``).
    Each lane keeps its particles of the i tile and, in turn, every lane's particles of the j tile:
    after each round the j particles and their sums move one lane on (a register shuffle), so that
    a lane only ever adds to what it holds and every sum has a fixed order (the motion does not
    depend on scheduling).  Per particle and per tile of the other side, the sweep writes its field
    sum and its contact candidates in that tile (as the bits of a word) to its column of the tile
    pair's row of ``field_out`` and ``near_out``: no atomics, no waits in the hot loop, each row
    written whole by one warp.  :func:`gather_newton` adds them up.
    """
    real, vec_real = _real_types(precision)
    inverse_sqrt = _inverse_sqrt(precision)
    Body = BODY_TYPES[precision]
    K = particles_per_lane
    radius_at, g_mass_at = (6, 7) if precision == "mixed" else (3, 4)
    candidate = real(CONTACT_CANDIDATE if precision == "mixed" else 1.0)
    Bodies = wp.types.matrix(shape=(K, Body._length_), dtype=real)
    Near = wp.types.vector(length=K, dtype=real)
    Fields = wp.types.matrix(shape=(K, 3), dtype=real)
    Bits = wp.types.vector(length=K, dtype=wp.uint64)

    @wp.func
    def tile_body(body_in: wp.array(dtype=Body), index: int, end: int) -> Body:
        """A particle of a tile, or past its system's end an absent one."""
        if index < end:
            return body_in[index]
        return absent_body(Body())

    @wp.kernel(
        module="unique",
        enable_backward=False,
        module_options={"fast_math": precision == "mixed"},
        cuda_max_registers=max_registers or None,
    )
    def pair_gravity_newton_kernel(
        # Model:
        tiles: wp.array(dtype=TilePair),
        # State in:
        body_in: wp.array(dtype=Body),
        max_radius: real,  # the largest radius: a per-i bound that spares most pairs the contact test
        # Out:
        field_out: wp.array2d(dtype=vec_real),  # [row, column]: G m_j r_ij / d^3 summed over the other tile
        near_out: wp.array2d(dtype=wp.uint64),  # [row, column]: bit k, the other tile's k-th particle is a candidate
    ):
        block, lane = wp.tid()
        lanes = wp.block_dim()
        tile = tiles[block]
        i_first, i_end, j_first, j_end, row_i, row_j = tile[0], tile[1], tile[2], tile[3], tile[4], tile[5]
        source = (lane + 1) % lanes  # each round a lane takes its neighbour's j particles

        bodies_i = Bodies()
        bodies_j = Bodies()
        near = Near()
        for k in range(wp.static(K)):
            bodies_i[k] = tile_body(body_in, i_first + k * lanes + lane, i_end)
            bodies_j[k] = tile_body(body_in, j_first + k * lanes + lane, j_end)
            near[k] = near_bound(bodies_i[k][radius_at], max_radius, candidate)
        fields_i = Fields()
        fields_j = Fields()  # the sums of the j particles this lane holds, moving with them
        near_i = Bits()
        near_j = Bits()  # likewise
        # The bit of each of this lane's i particles in a j particle's word (lanes is 1 or 32).
        i_bits = Bits()
        for k in range(wp.static(K)):
            i_bits[k] = wp.uint64(1) << wp.uint64(k * lanes + lane)

        for held in range(lanes):  # a round: this lane holds the j particles of lane (lane + held) % lanes
            j_bits = Bits()  # the bit of each held j particle in an i particle's word
            for k in range(wp.static(K)):
                j_bits[k] = wp.uint64(1) << wp.uint64(k * lanes + ((lane + held) & (lanes - 1)))
            for a in range(wp.static(K)):
                for b in range(wp.static(K)):
                    r = separation(bodies_i[a], bodies_j[b])
                    d2 = wp.dot(r, r)
                    if d2 > real(0.0):  # not the particle itself (on the diagonal), nor two absent ones
                        inv_d = inverse_sqrt(d2)
                        inv_d3 = inv_d * inv_d * inv_d
                        fields_i[a] = fields_i[a] + (bodies_j[b][g_mass_at] * inv_d3) * r
                        fields_j[b] = fields_j[b] - (bodies_i[a][g_mass_at] * inv_d3) * r
                        if d2 < near[a]:  # within R_i + R_max: rare
                            if is_candidate(d2, bodies_i[a][radius_at], bodies_j[b][radius_at], candidate):
                                near_i[a] = near_i[a] | j_bits[b]
                                near_j[b] = near_j[b] | i_bits[a]
            for b in range(wp.static(K)):
                bodies_j[b] = body_from_lane(bodies_j[b], source)
                fields_j[b] = field_from_lane(fields_j[b], source)
                near_j[b] = lane_value_u64(near_j[b], source)

        # After a full turn every lane holds its own j particles again.  On the diagonal the i side
        # has met every pair from both ends.
        for k in range(wp.static(K)):
            field_out[row_i, k * lanes + lane] = fields_i[k]
            near_out[row_i, k * lanes + lane] = near_i[k]
            if row_j >= 0:
                field_out[row_j, k * lanes + lane] = fields_j[k]
                near_out[row_j, k * lanes + lane] = near_j[k]

    return pair_gravity_newton_kernel


#: Tiles whose rows the gather loads at once.
GATHER_AHEAD = 8


@functools.cache
def gather_newton(precision: str = "mixed"):
    """Build the kernel that gives each particle what the Newton sweep found for it, one thread per
    particle (launch with ``dim=N``): its gravity (its field sums from every tile of its system, added
    in float64 in the tiles' order) and its contact candidates, listed in increasing j (the bits of
    each tile's word, tile after tile), with their count.  The threads of a warp read neighbouring
    columns of each row: whole lines of memory."""
    real, vec_real = _real_types(precision)
    Fields = wp.types.matrix(shape=(GATHER_AHEAD, 3), dtype=real)
    Words = wp.types.vector(length=GATHER_AHEAD, dtype=wp.uint64)

    @wp.kernel(module="unique", enable_backward=False)
    def gather_newton_kernel(
        # Model:
        gather: wp.array(dtype=GatherRows),
        mass_in: wp.array(dtype=wp.float64),
        # In:
        field_in: wp.array2d(dtype=vec_real),
        near_in: wp.array2d(dtype=wp.uint64),
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        candidate_count: wp.array(dtype=wp.int32),
        candidates: wp.array2d(dtype=wp.int32),
    ):
        i = wp.tid()
        rows = gather[i]
        row, tiles, column, first = rows[0], rows[1], rows[2], rows[3]
        size = field_in.shape[1]
        field = wp.vec3d()
        noted = int(0)
        for start in range(0, tiles, wp.static(GATHER_AHEAD)):
            # The loads of several tiles first, so that their waits overlap (tiles past the end add zeros).
            fields = Fields()
            words = Words()
            for k in range(wp.static(GATHER_AHEAD)):
                if start + k < tiles:
                    fields[k] = field_in[row + start + k, column]
                    words[k] = near_in[row + start + k, column]
            for k in range(wp.static(GATHER_AHEAD)):
                field += wp.vec3d(fields[k])
                bits = words[k]
                while bits != wp.uint64(0):
                    if noted < candidates.shape[1]:
                        candidates[i, noted] = first + (start + k) * size + lowest_bit(bits)
                    bits = bits & (bits - wp.uint64(1))
                    noted += 1
        force_out[i] = -mass_in[i] * field
        candidate_count[i] = noted

    return gather_newton_kernel


@functools.cache
def pair_forces_reference(precision: str = "mixed", rolling: str = "couple"):
    """Build the one-thread-per-particle kernel of the same physics; launch with ``dim=N``.

    Gravity pair by pair in the precision's arithmetic on the float64 separation,
    contacts with the same function as the tiled kernel; the ledger's channels are written
    when ``channels_out`` has rows.
    """
    real, vec_real = _real_types(precision)
    add_contact = contact_sum_function(rolling)

    @wp.kernel(module="unique", enable_backward=False)
    def pair_forces_reference_kernel(
        # Model:
        model: ContactModel,
        ranges: wp.array(dtype=wp.vec2i),  # per particle: its system's particles, [first, end)
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        # State in:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),
        deepest_out: wp.array(dtype=wp.int64),
    ):
        i = wp.tid()
        position_i = position_in[i]
        g_mass_i = model.G * mass_in[i]
        gravity_sum = vec_real()
        total = ContactSum()
        for j in range(ranges[i][0], ranges[i][1]):
            r_ij = position_i - position_in[j]
            d2 = wp.dot(r_ij, r_ij)
            if d2 > wp.float64(0.0):
                gravity_sum += gravity(vec_real(r_ij), real(g_mass_i * mass_in[j]))
                if in_contact(d2, radius_in[i], radius_in[j]):
                    total = add_contact(model, i, j, radius_in, position_in, velocity_in, omega_in, deepest_out, total)
        contact_force = write_contacts(total, i, torque_out, channels_out)
        force_out[i] = wp.vec3d(gravity_sum) + contact_force

    return pair_forces_reference_kernel

"""The fused layout: gravity and contacts in one tiled kernel (the CPU default; on CUDA the
default past the Newton layout's memory reach, engine.NEWTON_MAX particles).

A block of ``block_dim`` threads owns ``particles_per_block`` particles i and sweeps all j in tiles
of ``block_dim``, loaded cooperatively with ``wp.tile_load`` (one j per thread; one thread per block
on the CPU, so the same source serves both).  Each j load serves every particle of the block.  The
sweep itself is gravity only, plus a cheap test that notes contact candidates in a few slots; the
contacts, which are few, are evaluated in float64 after the sweep (:mod:`.contacts`), so that the
hot loop stays small.  Per-thread sums are reduced with ``wp.tile_sum`` and lane 0 writes each
particle's force and torque: no atomics, and the motion does not depend on scheduling.  The energy
ledger's contact channels, float64, get a reduction of their own per particle, so the ledger does
not either.

``max_registers`` tunes it to a GPU: it caps the registers per thread, so that the rarely run
float64 contact code spills rather than the sweep losing occupancy.
"""

import functools

import warp as wp

from .bodies import is_candidate, near_bound, separation, sweep_of, unpack_block
from .contacts import LedgerRows, PairHistory, close_rows, contact_function, touches, write_channels
from .pair import LAWS_WITH_SPRINGS, ContactModel

wp.set_module_options({"enable_backward": False})


@functools.cache
def pair_forces_tiled(
    block_dim: int,
    particles_per_block: int,
    contact_slots: int,
    precision: str = "mixed",
    law: str = "paper",
    ledger: bool = False,
    max_registers: int = 0,
):
    """Build the tiled all-pairs kernel for a layout; launch with ``wp.launch_tiled``.

    Launch: ``ceil(N / particles_per_block)`` blocks of ``block_dim`` threads
    (``block_dim`` must be 1 on CPU, where Warp runs one thread per block), with
    ``body_in`` packed by ``PACK_KERNELS[precision]``.  Each thread notes up to
    ``contact_slots`` contact candidates per particle; past that it finds them
    again after the sweep, so any number of contacts is handled.  ``max_registers``
    (CUDA, 0 = the compiler's choice) caps registers per thread: the float64
    contact code, which runs rarely, then spills instead of the sweep losing occupancy.
    """
    real, _, Body, inverse_sqrt, radius_at, g_mass_at, candidate = sweep_of(precision)
    contact_channels = contact_function(law)
    springs = law in LAWS_WITH_SPRINGS
    T, P, K = block_dim, particles_per_block, contact_slots
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
        blocks_in: wp.array(dtype=wp.vec4i),  # per block: first particle, end of its rows, its system's j range
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        max_radius: real,  # the largest radius: a per-i bound that spares most pairs the contact test
        # In:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        body_in: wp.array(dtype=Body),
        history_in: PairHistory,  # the contacts' springs at the evaluation before (a law with springs)
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),  # (N, 4) with the ledger (written whole), else empty
        deepest_inout: wp.array(dtype=wp.int64),  # raised to each contact's depth (note_depth), or empty
        history_out: PairHistory,  # the contacts' springs now (a law with springs)
    ):
        block, lane = wp.tid()
        first, end, j_first, j_end = unpack_block(blocks_in[block])

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
        for start in range(j_first, j_end, wp.static(T)):
            # One j per thread (counted from the system's first, so that a system's sums do not
            # depend on where it sits among others); elements past its end are skipped.
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
        # this thread's share of j looked at again; either way in increasing j.  The loop over
        # the block's particles is unrolled, as nvcc unrolled it anyway with a run-time bound:
        # a run-time loop holding the ledger's block reduction (a barrier) stays rolled, and its
        # counts and sums indexed at run time then spill the sweep's sums (sm_90 SASS).
        contacts = Contacts()
        for p in range(wp.static(P)):
            if p >= end - first:  # rows past the end
                continue
            i = first + p
            noted = candidates[p]
            overflow = noted > wp.static(K)
            walk = noted
            body_i = body_in[i]
            if overflow:
                walk = (j_end - j_first - lane + wp.static(T) - 1) // wp.static(T)
            if wp.static(ledger):
                channels = LedgerRows()
            rows = int(0)
            if wp.static(springs):
                # Where this lane's rows of i's contacts begin: after the lanes before it (a scan of
                # their counts), so that the lanes write them side by side in a fixed order.
                mine = int(0)
                for s in range(walk):
                    j = 0
                    if overflow:  # (the walk's own test first, as below)
                        j = j_first + lane + s * wp.static(T)
                        body_j = body_in[j]
                        r = separation(body_i, body_j)
                        if not is_candidate(wp.dot(r, r), body_i[radius_at], body_j[radius_at], candidate):
                            continue
                    else:
                        j = slots[p, s]
                    if touches(i, j, radius_in, position_in):
                        mine += 1
                rows = wp.untile(wp.tile_scan_exclusive(wp.tile(mine)))
                contacts_of_i = wp.tile_sum(wp.tile(mine))
                if lane == 0:
                    close_rows(history_out, i, contacts_of_i[0])
            for s in range(walk):
                j = 0
                if overflow:
                    j = j_first + lane + s * wp.static(T)
                    body_j = body_in[j]
                    r = separation(body_i, body_j)
                    if not is_candidate(wp.dot(r, r), body_i[radius_at], body_j[radius_at], candidate):
                        continue
                else:
                    j = slots[p, s]
                spring, sliding, sliding_torque, rolling, rolling_torque, touching = contact_channels(
                    model, i, j, radius_in, mass_in, position_in, velocity_in, omega_in, history_in, rows, history_out, deepest_inout
                )
                rows += touching
                force = spring + sliding + rolling
                torque = sliding_torque + rolling_torque
                for k in range(3):
                    contacts[p, k] += real(force[k])
                    contacts[p, 3 + k] += real(torque[k])
                if wp.static(ledger):
                    channels += wp.matrix_from_rows(spring, sliding, sliding_torque, rolling)
            if wp.static(ledger):
                # The lanes' channels summed in a fixed order, not with atomics: i's contacts
                # are met by several lanes, in a block of more than 32 by several warps, whose
                # float64 atomics landed in whatever order the warps ran (the ledger's last
                # bits varied from run to run).  A reduction of its own: the sweep's is float32
                # in mixed precision.
                total_channels = wp.tile_sum(wp.tile(channels, preserve_type=True))[0]
                if lane == 0:
                    write_channels(total_channels, i, channels_out)

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

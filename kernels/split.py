"""The split layout: the fused layout's work in two launches (``Layout(contact_pass=True)``, opt-in).

``pair_gravity_tiled`` is the fused sweep (:mod:`.fused`) with gravity only: it notes each
particle's contact candidates in a global list (``candidate_count``, ``candidates``; atomics, in any
order) and carries no contact code, so it needs fewer registers and runs at a higher occupancy.
Then :func:`.contacts.contact_pass`, one thread per particle, walks its list in increasing j and
evaluates the contacts in float64: the fixed order keeps the motion (and here the ledger too)
independent of scheduling.  That contact pass is in :mod:`.contacts`, not here, because the tree
path feeds it too, with the hash grid's lists.
"""

import functools

import warp as wp

from .bodies import is_candidate, near_bound, separation, sweep_of, unpack_block

wp.set_module_options({"enable_backward": False})


@functools.cache
def pair_gravity_tiled(block_dim: int, particles_per_block: int, precision: str = "mixed", max_registers: int = 0, prefetch: bool = False):
    """Build the sweep of the split layout: gravity between every pair, and each particle's contact
    candidates appended to ``candidates`` (counted in ``candidate_count``, zeroed by the caller).

    Launch like :func:`.fused.pair_forces_tiled`; ``force_out`` receives gravity only, and
    :func:`.contacts.contact_pass` adds the contacts.
    """
    real, _, Body, inverse_sqrt, radius_at, g_mass_at, candidate = sweep_of(precision)
    T, P = block_dim, particles_per_block
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
        if wp.static(prefetch):  # as in the fused layout's pair_forces_tiled
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

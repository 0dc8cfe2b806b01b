"""The Newton layout (the CUDA default up to engine.NEWTON_MAX particles): each pair's gravity
computed once and given to both particles, in three launches with no atomics.

1. ``pair_gravity_newton``: a block is one warp; it meets two tiles of up to 64 particles, i and j
   (each tile pair a <= b of a system once, ``TilePair``).  Each lane keeps its particles of the i
   tile and holds some of the j tile; per round it computes its pairs, adds the field to its i sums
   and the opposite field to the j sums it holds, and sets a bit per contact candidate on both
   sides.  Then the j particles, their sums and their candidate bits move one lane on (a register
   shuffle, ``__shfl_sync``: the native snippets below, the identity on the CPU's one-lane blocks).
   After a full turn every lane holds its own j particles again, and the warp writes, per tile pair
   and side, a row of field sums and 64-bit candidate words.
2. ``gather_newton``, one thread per particle: adds its rows in float64 in tile order and lists its
   candidates in increasing j from the words.
3. the contacts of the listed candidates in float64 (:mod:`.contacts` ``contact_pass``, 8 lanes a
   particle, as every path that lists candidates).

Every sum has a fixed order, so the motion is bit-reproducible on a GPU, and the same source runs on
the CPU (tiles of 4, one lane), where it equals the plain loop.  Half the pairs and no atomics give
1.7x to 2.4x the fused layout's full step on an H100 from 5 500 to 131 072 particles
(docs/benchmarks.md).  The price is memory: a row of field sums and words per tile pair, N^2 / 64
x 20 bytes (5.4 GB at 131 072 particles), hence the fused layout past that.
"""

import functools

import warp as wp

from .bodies import BodyDouble, BodyMixed, is_candidate, near_bound, real_types, separation, sweep_of

wp.set_module_options({"enable_backward": False})

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
def pair_gravity_newton(particles_per_lane: int, precision: str = "mixed", max_registers: int = 0, listing: bool = True):
    """Build the Newton-layout sweep: gravity of each pair computed once and given to both sides,
    and (with ``listing``) each pair's contact candidacy noted for both.

    One block is one warp (``wp.block_dim()`` lanes: 32 on a GPU, 1 on the CPU) and meets two tiles
    of ``lanes * particles_per_lane`` particles (at most NEWTON_TILE_MAX), i and j (``TilePair``).
    Each lane keeps its particles of the i tile and, in turn, every lane's particles of the j tile:
    after each round the j particles and their sums move one lane on (a register shuffle), so that
    a lane only ever adds to what it holds and every sum has a fixed order (the motion does not
    depend on scheduling).  Per particle and per tile of the other side, the sweep writes its field
    sum and its contact candidates in that tile (as the bits of a word) to its column of the tile
    pair's row of ``field_out`` and ``near_out``: no atomics, no waits in the hot loop, each row
    written whole by one warp.  :func:`gather_newton` adds them up.  Without ``listing`` (gravity on
    its own clock, whose contacts come from a neighbour list) no bit is noted nor ``near_out`` written.
    """
    real, vec_real, Body, inverse_sqrt, radius_at, g_mass_at, candidate = sweep_of(precision)
    K = particles_per_lane
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
        tiles_in: wp.array(dtype=TilePair),
        max_radius: real,  # the largest radius: a per-i bound that spares most pairs the contact test
        # In:
        body_in: wp.array(dtype=Body),
        # Out:
        field_out: wp.array2d(dtype=vec_real),  # [row, column]: G m_j r_ij / d^3 summed over the other tile
        near_out: wp.array2d(dtype=wp.uint64),  # [row, column]: bit k, the other tile's k-th particle is a candidate
    ):
        block, lane = wp.tid()
        lanes = wp.block_dim()
        tile = tiles_in[block]
        i_first, i_end, j_first, j_end, row_i, row_j = tile[0], tile[1], tile[2], tile[3], tile[4], tile[5]
        source = (lane + 1) % lanes  # each round a lane takes its neighbour's j particles

        bodies_i = Bodies()
        bodies_j = Bodies()
        near = Near()
        for k in range(wp.static(K)):
            bodies_i[k] = tile_body(body_in, i_first + k * lanes + lane, i_end)
            bodies_j[k] = tile_body(body_in, j_first + k * lanes + lane, j_end)
            if wp.static(listing):
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
                        if wp.static(listing):
                            if d2 < near[a]:  # within R_i + R_max: rare
                                if is_candidate(d2, bodies_i[a][radius_at], bodies_j[b][radius_at], candidate):
                                    near_i[a] = near_i[a] | j_bits[b]
                                    near_j[b] = near_j[b] | i_bits[a]
            for b in range(wp.static(K)):
                bodies_j[b] = body_from_lane(bodies_j[b], source)
                fields_j[b] = field_from_lane(fields_j[b], source)
                if wp.static(listing):
                    near_j[b] = lane_value_u64(near_j[b], source)

        # After a full turn every lane holds its own j particles again.  On the diagonal the i side
        # has met every pair from both ends.
        for k in range(wp.static(K)):
            field_out[row_i, k * lanes + lane] = fields_i[k]
            if wp.static(listing):
                near_out[row_i, k * lanes + lane] = near_i[k]
            if row_j >= 0:
                field_out[row_j, k * lanes + lane] = fields_j[k]
                if wp.static(listing):
                    near_out[row_j, k * lanes + lane] = near_j[k]

    return pair_gravity_newton_kernel


#: Tiles whose rows the gather loads at once (their waits overlap; the adds keep the tiles' order,
#: so the sums are the same at any number).  At the Fig. 8 impact on an H100, 8, 16 and 32 stepped
#: in 78.1, 77.0 and 80.1 us at K = 1 and 32.1, 31.3 and 31.1 us at K = 10 (docs/benchmarks.md).
GATHER_AHEAD = 16


@functools.cache
def gather_newton(precision: str = "mixed", listing: bool = True, ahead: int = GATHER_AHEAD):
    """Build the kernel that gives each particle what the Newton sweep found for it, one thread per
    particle (launch with ``dim=N``): its gravity (its field sums from every tile of its system, added
    in float64 in the tiles' order) and, with ``listing``, its contact candidates, listed in
    increasing j (the bits of each tile's word, tile after tile), with their count.  The threads of
    a warp read neighbouring columns of each row: whole lines of memory."""
    real, vec_real = real_types(precision)
    Fields = wp.types.matrix(shape=(ahead, 3), dtype=real)
    Words = wp.types.vector(length=ahead, dtype=wp.uint64)

    @wp.kernel(module="unique", enable_backward=False)
    def gather_newton_kernel(
        # Model:
        gather_in: wp.array(dtype=GatherRows),
        mass_in: wp.array(dtype=wp.float64),
        # In:
        field_in: wp.array2d(dtype=vec_real),
        near_in: wp.array2d(dtype=wp.uint64),
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        candidate_count_out: wp.array(dtype=wp.int32),  # candidates met (past the list's width: an overflow), or empty
        candidates_out: wp.array2d(dtype=wp.int32),  # the first of them, in increasing j, or empty
    ):
        i = wp.tid()
        rows = gather_in[i]
        row, tiles, column, first = rows[0], rows[1], rows[2], rows[3]
        size = field_in.shape[1]
        field = wp.vec3d()
        noted = int(0)
        for start in range(0, tiles, wp.static(ahead)):
            # The loads of several tiles first, so that their waits overlap (tiles past the end add zeros).
            fields = Fields()
            words = Words()
            for k in range(wp.static(ahead)):
                if start + k < tiles:
                    fields[k] = field_in[row + start + k, column]
                    if wp.static(listing):
                        words[k] = near_in[row + start + k, column]
            for k in range(wp.static(ahead)):
                field += wp.vec3d(fields[k])
                if wp.static(listing):
                    bits = words[k]
                    while bits != wp.uint64(0):
                        if noted < candidates_out.shape[1]:
                            candidates_out[i, noted] = first + (start + k) * size + lowest_bit(bits)
                        bits = bits & (bits - wp.uint64(1))
                        noted += 1
        force_out[i] = -mass_in[i] * field
        if wp.static(listing):
            candidate_count_out[i] = noted

    return gather_newton_kernel

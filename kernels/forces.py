"""All-pairs force and torque kernels: gravity between every pair, contact between overlapping ones.

Two kernels share one pair function:

* ``pair_forces_tiled`` -- the production kernel.  A block of threads owns
  ``particles_per_block`` particles i; tiles of ``tile`` particles j are loaded
  cooperatively into shared memory with ``wp.tile_load``, each thread takes the
  j's of the tile at stride ``wp.block_dim()`` (one thread per block on CPU, so
  the same source serves both), and the per-thread partial sums are reduced
  with ``wp.tile_sum``.  Each particle's force and torque is written once, by
  lane 0: no atomics, and the result does not depend on scheduling.
* ``pair_forces_reference`` -- one thread per particle, a plain loop over j.  It
  is the yardstick for tests on CPU and the baseline of ``decco-warp bench``.

Kernels are built by cached factories, specialised on precision, rolling-friction
form and layout, each in its own Warp module so that a variant compiles once and
never forces another to recompile.

Precision:
    ``"mixed"`` (default): the sweep runs on packed float32 "bodies" (each
    position split into a float32 pair hi + lo, so that separations keep float32
    *relative* precision however far from the origin; radius; G m).  Gravity is
    float32; a pair that may touch is re-examined from the float64 arrays, and
    every contact quantity is float64.  Sums are float32.
    ``"float64"``: everything in double.
"""

import functools

import warp as wp

from .pair import CONTACT_FUNCTIONS, ContactModel, gravity, in_contact

wp.set_module_options({"enable_backward": False})

PRECISIONS = ("mixed", "float64")

#: A packed particle for the mixed-precision sweep: position as float32 hi + lo, radius, G m.
Body = wp.types.vector(length=8, dtype=wp.float32)

#: A float32 separation is good to ~1e-7 relative; pairs this close (in d^2) are
#: candidates, confirmed or rejected in float64.
CONTACT_CANDIDATE = 1.0 + 1e-5


@wp.kernel
def pack_bodies(
    # Model:
    G: wp.float64,
    radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64),
    # State in:
    position_in: wp.array(dtype=wp.vec3d),
    # Out:
    body_out: wp.array(dtype=Body),
):
    """Split each float64 position into float32 hi + lo; (hi_i - hi_j) + (lo_i - lo_j) is then
    accurate to float32 relative precision of the separation itself."""
    i = wp.tid()
    x = position_in[i]
    hi = wp.vec3f(x)
    lo = wp.vec3f(x - wp.vec3d(hi))
    body_out[i] = Body(hi[0], hi[1], hi[2], lo[0], lo[1], lo[2], wp.float32(radius_in[i]), wp.float32(G * mass_in[i]))

_REAL = {"mixed": (wp.float32, wp.vec3f), "float64": (wp.float64, wp.vec3d)}


def _real_types(precision: str):
    if precision not in _REAL:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    return _REAL[precision]


#: Per-particle contact channels written by the ledger variants, in this order
#: (float64, summed over contacts); gravity is the rest of the force.
LEDGER_CHANNELS = ("spring_force", "sliding_force", "sliding_torque", "rolling_force")


@functools.cache
def pair_interaction(precision: str, rolling: str, ledger: bool):
    """The Warp function giving (force, torque) on i from j for one precision and rolling form.

    With ``ledger``, it also adds each contact's channels (LEDGER_CHANNELS) to row
    i of ``channels_out`` with atomics: contacts are few, and these sums feed only
    the energy ledger, never the motion.
    """
    real, vec_real = _real_types(precision)
    contact = CONTACT_FUNCTIONS[rolling]

    @wp.func
    def interaction(
        model: ContactModel,
        i: int,
        j: int,
        g_mass_i: wp.float64,
        position_i: wp.vec3d,
        velocity_i: wp.vec3d,
        omega_i: wp.vec3d,
        radius_i: wp.float64,
        position_j: wp.vec3d,
        velocity_j: wp.vec3d,
        omega_j: wp.vec3d,
        radius_j: wp.float64,
        mass_j: wp.float64,
        channels_out: wp.array2d(dtype=wp.vec3d),
    ):
        # The separation is taken in float64: positions are ~1e7 cm, overlaps ~1e2 cm.
        r_ij = position_i - position_j
        d2 = wp.dot(r_ij, r_ij)
        force = vec_real()
        torque = vec_real()
        # d2 == 0 is the particle itself (or a coincident one, which has no direction).
        if d2 > wp.float64(0.0):
            force = gravity(vec_real(r_ij), real(g_mass_i * mass_j))
            if in_contact(d2, radius_i, radius_j):
                spring, sliding, sliding_torque, rolling, rolling_torque = wp.static(contact)(
                    model, r_ij, d2, radius_i, velocity_i, omega_i, radius_j, velocity_j, omega_j, i < j
                )
                force += vec_real(spring + sliding + rolling)
                torque = vec_real(sliding_torque + rolling_torque)
                if wp.static(ledger):
                    wp.atomic_add(channels_out, i, 0, spring)
                    wp.atomic_add(channels_out, i, 1, sliding)
                    wp.atomic_add(channels_out, i, 2, sliding_torque)
                    wp.atomic_add(channels_out, i, 3, rolling)
        return force, torque

    return interaction


@functools.cache
def pair_forces_tiled(
    tile: int, particles_per_block: int, precision: str = "mixed", rolling: str = "couple", ledger: bool = False
):
    """Build the tiled all-pairs kernel for a layout; launch with ``wp.launch_tiled``.

    Launch dimension: ``ceil(N / particles_per_block)`` blocks.  On CUDA use
    ``block_dim = tile`` (one j per thread per tile); on CPU Warp runs one thread
    per block, which then walks the whole tile.
    """
    real, _ = _real_types(precision)
    interaction = pair_interaction(precision, rolling, ledger)
    P = particles_per_block
    # Registers for the block's own particles and its partial sums: rows are particles.
    Rows3 = wp.types.matrix(shape=(P, 3), dtype=wp.float64)
    Rows = wp.types.vector(length=P, dtype=wp.float64)
    Sums = wp.types.matrix(shape=(P, 6), dtype=real)  # force xyz, torque xyz
    Sum = wp.types.vector(length=6, dtype=real)

    @wp.kernel(module="unique", enable_backward=False)
    def pair_forces_tiled_kernel(
        # Model:
        model: ContactModel,
        count: int,
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        # State in:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),  # (N, 4) with ledger, else empty; zeroed by the caller
    ):
        block, lane = wp.tid()
        first = block * wp.static(P)

        position_i = Rows3()
        velocity_i = Rows3()
        omega_i = Rows3()
        radius_i = Rows()
        g_mass_i = Rows()
        for p in range(wp.static(P)):
            # Rows past the end repeat the last particle; their sums are never written.
            i = wp.min(first + p, count - 1)
            position_i[p] = position_in[i]
            velocity_i[p] = velocity_in[i]
            omega_i[p] = omega_in[i]
            radius_i[p] = radius_in[i]
            g_mass_i[p] = model.G * mass_in[i]

        sums = Sums()
        for start in range(0, count, wp.static(tile)):
            # Out-of-range elements of the last tile load as zero and are skipped below.
            position_t = wp.tile_load(position_in, shape=wp.static(tile), offset=start, storage="shared")
            velocity_t = wp.tile_load(velocity_in, shape=wp.static(tile), offset=start, storage="shared")
            omega_t = wp.tile_load(omega_in, shape=wp.static(tile), offset=start, storage="shared")
            radius_t = wp.tile_load(radius_in, shape=wp.static(tile), offset=start, storage="shared")
            mass_t = wp.tile_load(mass_in, shape=wp.static(tile), offset=start, storage="shared")
            for k in range(lane, wp.static(tile), wp.block_dim()):
                j = start + k
                if j < count:
                    position_j = position_t[k]
                    velocity_j = velocity_t[k]
                    omega_j = omega_t[k]
                    radius_j = radius_t[k]
                    mass_j = mass_t[k]
                    for p in range(wp.static(P)):
                        if first + p >= count:
                            continue  # a padding row of the last block
                        f, t = wp.static(interaction)(
                            model,
                            first + p,
                            j,
                            g_mass_i[p],
                            position_i[p],
                            velocity_i[p],
                            omega_i[p],
                            radius_i[p],
                            position_j,
                            velocity_j,
                            omega_j,
                            radius_j,
                            mass_j,
                            channels_out,
                        )
                        sums[p] = sums[p] + Sum(f[0], f[1], f[2], t[0], t[1], t[2])

        total = wp.tile_sum(wp.tile(sums, preserve_type=True))[0]
        if lane == 0:
            for p in range(wp.static(P)):
                i = first + p
                if i < count:
                    row = total[p]
                    force_out[i] = wp.vec3d(wp.float64(row[0]), wp.float64(row[1]), wp.float64(row[2]))
                    torque_out[i] = wp.vec3d(wp.float64(row[3]), wp.float64(row[4]), wp.float64(row[5]))

    return pair_forces_tiled_kernel


@functools.cache
def pair_forces_tiled_mixed(tile: int, particles_per_block: int, rolling: str = "couple", ledger: bool = False):
    """The tiled kernel of the default precision: the sweep touches only packed float32 bodies.

    Same launch as :func:`pair_forces_tiled`, with ``body_in`` from :data:`pack_bodies`.
    """
    contact = CONTACT_FUNCTIONS[rolling]
    P = particles_per_block
    Rows3 = wp.types.matrix(shape=(P, 3), dtype=wp.float32)
    Rows = wp.types.vector(length=P, dtype=wp.float32)
    # Per particle: the gravitational field sum G m_j r_ij / d^3 (force is -m_i times it),
    # then contact force and torque.
    Sums = wp.types.matrix(shape=(P, 9), dtype=wp.float32)
    Sum = wp.types.vector(length=9, dtype=wp.float32)
    candidate = wp.float32(CONTACT_CANDIDATE)

    @wp.kernel(module="unique", enable_backward=False, module_options={"fast_math": True})
    def pair_forces_tiled_mixed_kernel(
        # Model:
        model: ContactModel,
        count: int,
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        # State in:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        body_in: wp.array(dtype=Body),
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),
    ):
        block, lane = wp.tid()
        first = block * wp.static(P)

        hi_i = Rows3()
        lo_i = Rows3()
        radius_i = Rows()
        for p in range(wp.static(P)):
            b = body_in[wp.min(first + p, count - 1)]
            hi_i[p] = wp.vec3f(b[0], b[1], b[2])
            lo_i[p] = wp.vec3f(b[3], b[4], b[5])
            radius_i[p] = b[6]

        sums = Sums()
        for start in range(0, count, wp.static(tile)):
            body_t = wp.tile_load(body_in, shape=wp.static(tile), offset=start, storage="shared")
            for k in range(lane, wp.static(tile), wp.block_dim()):
                j = start + k
                if j < count:
                    b = body_t[k]
                    hi_j = wp.vec3f(b[0], b[1], b[2])
                    lo_j = wp.vec3f(b[3], b[4], b[5])
                    radius_j = b[6]
                    g_mass_j = b[7]
                    for p in range(wp.static(P)):
                        i = first + p
                        r = (hi_i[p] - hi_j) + (lo_i[p] - lo_j)
                        d2 = wp.dot(r, r)
                        # d2 == 0: the particle itself (or a coincident one, which has no direction).
                        if i < count and d2 > wp.float32(0.0):
                            inv_d = wp.float32(1.0) / wp.sqrt(d2)
                            field = (g_mass_j * inv_d * inv_d * inv_d) * r
                            force = wp.vec3f()
                            torque = wp.vec3f()
                            reach = radius_i[p] + radius_j
                            if d2 < reach * reach * candidate:
                                r64 = position_in[i] - position_in[j]
                                d2_64 = wp.dot(r64, r64)
                                if in_contact(d2_64, radius_in[i], radius_in[j]):
                                    spring, sliding, sliding_torque, rolling, rolling_torque = wp.static(contact)(
                                        model,
                                        r64,
                                        d2_64,
                                        radius_in[i],
                                        velocity_in[i],
                                        omega_in[i],
                                        radius_in[j],
                                        velocity_in[j],
                                        omega_in[j],
                                        i < j,
                                    )
                                    force = wp.vec3f(spring + sliding + rolling)
                                    torque = wp.vec3f(sliding_torque + rolling_torque)
                                    if wp.static(ledger):
                                        wp.atomic_add(channels_out, i, 0, spring)
                                        wp.atomic_add(channels_out, i, 1, sliding)
                                        wp.atomic_add(channels_out, i, 2, sliding_torque)
                                        wp.atomic_add(channels_out, i, 3, rolling)
                            sums[p] = sums[p] + Sum(
                                field[0], field[1], field[2], force[0], force[1], force[2], torque[0], torque[1], torque[2]
                            )

        total = wp.tile_sum(wp.tile(sums, preserve_type=True))[0]
        if lane == 0:
            for p in range(wp.static(P)):
                i = first + p
                if i < count:
                    row = total[p]
                    field_sum = wp.vec3d(wp.float64(row[0]), wp.float64(row[1]), wp.float64(row[2]))
                    contact_force = wp.vec3d(wp.float64(row[3]), wp.float64(row[4]), wp.float64(row[5]))
                    force_out[i] = contact_force - mass_in[i] * field_sum
                    torque_out[i] = wp.vec3d(wp.float64(row[6]), wp.float64(row[7]), wp.float64(row[8]))

    return pair_forces_tiled_mixed_kernel


@functools.cache
def pair_forces_reference(precision: str = "mixed", rolling: str = "couple", ledger: bool = False):
    """Build the one-thread-per-particle kernel of the same physics; launch with ``dim=N``."""
    _, vec_real = _real_types(precision)
    interaction = pair_interaction(precision, rolling, ledger)

    @wp.kernel(module="unique", enable_backward=False)
    def pair_forces_reference_kernel(
        # Model:
        model: ContactModel,
        count: int,
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        # State in:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        omega_in: wp.array(dtype=wp.vec3d),
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),  # (N, 4) with ledger, else empty; zeroed by the caller
    ):
        i = wp.tid()
        position_i = position_in[i]
        velocity_i = velocity_in[i]
        omega_i = omega_in[i]
        radius_i = radius_in[i]
        g_mass_i = model.G * mass_in[i]
        force = vec_real()
        torque = vec_real()
        for j in range(count):
            f, t = wp.static(interaction)(
                model,
                i,
                j,
                g_mass_i,
                position_i,
                velocity_i,
                omega_i,
                radius_i,
                position_in[j],
                velocity_in[j],
                omega_in[j],
                radius_in[j],
                mass_in[j],
                channels_out,
            )
            force += f
            torque += t
        force_out[i] = wp.vec3d(force)
        torque_out[i] = wp.vec3d(torque)

    return pair_forces_reference_kernel

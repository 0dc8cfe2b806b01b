"""Packed bodies: what the tiled sweeps of every layout read, and the pieces they share.

The sweeps of the fused (:mod:`.fused`) and Newton (:mod:`.newton`) layouts
spend their time on gravity between every pair, so they read each particle as one packed vector,
refreshed before each sweep by ``PACK_KERNELS[precision]``, and do the arithmetic of a pair in the
run's precision:

``"mixed"`` (default): the packed body is float32 (position split into float32 hi + lo, so that a
separation keeps float32 *relative* precision however far from the origin; radius; G m), gravity is
float32 with fast math, and pairs within a margin of touching (``is_candidate``) are noted as contact
candidates, to be confirmed in float64 by :mod:`.contacts`.  Every contact quantity is float64; the
sweep's sums are float32.
``"float64"``: everything in double.

Also here: each sweep's per-i bound (``near_bound``) that spares most pairs the candidate test, and
the tiled blocks of the fused layout (``unpack_block``).  The pack kernels are the only
kernels of this module, so a CPU run compiles it once, whatever the layout.
"""

from typing import Any, NamedTuple

import warp as wp

from .pair import CONTACT_CANDIDATE, inverse_sqrt_exact, inverse_sqrt_fast, reach, squared_reach, within_reach

wp.set_module_options({"enable_backward": False})

PRECISIONS = ("mixed", "float64")

#: Packed particles for the sweep.  mixed: hi xyz, lo xyz, radius, G m (float32);
#: float64: x y z, radius, G m.
BodyMixed = wp.types.vector(length=8, dtype=wp.float32)
BodyDouble = wp.types.vector(length=5, dtype=wp.float64)
BODY_TYPES = {"mixed": BodyMixed, "float64": BodyDouble}



@wp.func
def pack_body(G: wp.float64, radius: wp.float64, mass: wp.float64, x: wp.vec3d, body_out: wp.array(dtype=BodyMixed), i: int):
    """Write particle i's packed body: its float64 position split into float32 hi + lo, so that
    (hi_i - hi_j) + (lo_i - lo_j) is accurate to float32 relative precision of the separation itself."""
    hi = wp.vec3f(x)
    lo = wp.vec3f(x - wp.vec3d(hi))
    body_out[i] = BodyMixed(hi[0], hi[1], hi[2], lo[0], lo[1], lo[2], wp.float32(radius), wp.float32(G * mass))


@wp.func
def pack_body(G: wp.float64, radius: wp.float64, mass: wp.float64, x: wp.vec3d, body_out: wp.array(dtype=BodyDouble), i: int):
    """Write particle i's packed body in float64."""
    body_out[i] = BodyDouble(x[0], x[1], x[2], radius, G * mass)


@wp.kernel
def pack_bodies(
    # Model:
    G: wp.float64,
    radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64),
    # In:
    position_in: wp.array(dtype=wp.vec3d),
    # Out:
    body_out: wp.array(dtype=Any),  # BodyMixed or BodyDouble: the overload of the run's precision
):
    i = wp.tid()
    pack_body(G, radius_in[i], mass_in[i], position_in[i], body_out, i)


def body_overloads(kernel) -> dict:
    """A kernel generic in its ``body_out`` (an array of BodyMixed or BodyDouble), overloaded for each
    precision: precision -> overload (a launch of the generic kernel picks it by the array's type)."""
    return {precision: wp.overload(kernel, {"body_out": wp.array(dtype=Body)}) for precision, Body in BODY_TYPES.items()}


#: The kernel that packs the bodies before a sweep, per precision (kernels/integrate.py also packs
#: them, after the drift, when a step's kicks share launches).
PACK_KERNELS = body_overloads(pack_bodies)


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


def real_types(precision: str):
    """The scalar and 3-vector of a kernel's arithmetic in ``precision``."""
    if precision not in BODY_TYPES:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    return (wp.float32, wp.vec3f) if precision == "mixed" else (wp.float64, wp.vec3d)


class Sweep(NamedTuple):
    """What a tiled sweep in one precision works with (unpack it in a kernel factory: a Warp kernel
    takes the values as constants)."""

    real: type  # the scalar of its arithmetic
    vector: type  # and its 3-vector
    Body: type  # a packed body
    inverse_sqrt: Any  # 1/d: one rsqrt instruction on a GPU in the default precision, exact in float64
    radius_at: int  # where a Body holds its radius
    g_mass_at: int  # and its G m
    candidate: Any  # the contact test's margin (is_candidate), in the sweep's scalar


def sweep_of(precision: str) -> Sweep:
    """The :class:`Sweep` of ``precision``."""
    real, vector = real_types(precision)
    mixed = precision == "mixed"
    return Sweep(
        real,
        vector,
        BODY_TYPES[precision],
        inverse_sqrt_fast if mixed else inverse_sqrt_exact,
        6 if mixed else 3,
        7 if mixed else 4,
        real(CONTACT_CANDIDATE if mixed else 1.0),
    )


@wp.func
def is_candidate(d2: Any, radius_i: Any, radius_j: Any, candidate: Any) -> bool:
    """The sweep's contact test: d^2 < (R_i + R_j)^2 candidate (pair.CONTACT_CANDIDATE in mixed
    precision), confirmed later in float64."""
    return within_reach(d2, reach(radius_i, radius_j, type(radius_i)(0.0), type(radius_i)(1.0)), candidate)


@wp.func
def near_bound(radius_i: Any, max_radius: Any, candidate: Any) -> Any:
    """The same bound with R_max for R_j: computed once per i, it holds every candidate of i
    (rounding is monotone, so R_j <= R_max gives a bound no smaller), and one comparison
    per pair clears the others."""
    return squared_reach(reach(radius_i, max_radius, type(radius_i)(0.0), type(radius_i)(1.0)), candidate)


@wp.func
def unpack_block(block: wp.vec4i):
    """A tiled block's rows [first, end) and its system's particles [j_first, j_end) (Engine.blocks)."""
    return block[0], block[1], block[2], block[3]

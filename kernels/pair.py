"""The physics of one pair of spheres, as small Warp functions (docs/model.md).

Every function here is pure: it takes the state of spheres i and j and returns
what i receives from j.  The force kernels (one module per layout, :mod:`.contacts` for the
contacts) only gather pairs and sum.  Everything in contact is float64: the overlap of two
~1e6 cm spheres is ~1e2 cm, and its velocity-dependent terms (the k_in/k_out
switch, the slip) need the same resolution.

Sign conventions (docs/model.md, "Pair geometry"):
    r_ij = x_i - x_j,  d = |r_ij|,  n = r_ij / d  (unit vector from j to i)
    overlap delta = R_i + R_j - d   (in contact when > 0)
    lever arms to the contact point c = (R_j x_i + R_i x_j) / (R_i + R_j):
        a_i = -(R_i / (R_i + R_j)) r_ij,   a_j = +(R_j / (R_i + R_j)) r_ij

Each result is exactly antisymmetric under i <-> j in floating point (the same
operations on negated operands), so computing every pair twice, once from each
side, still conserves momentum to round-off.
"""

from typing import Any

import warp as wp

wp.set_module_options({"enable_backward": False})

vec3d = wp.vec3d
f64 = wp.float64


@wp.struct
class ContactModel:
    """Constants of the contact and gravity model (cgs, float64), passed to every force kernel."""

    G: wp.float64  # gravitational constant [cm^3 g^-1 s^-2]
    k_in: wp.float64  # spring constant while approaching [dyne/cm]
    k_out: wp.float64  # spring constant while receding, restitution^2 * k_in [dyne/cm]
    mu_k: wp.float64  # sliding (kinetic) friction coefficient
    mu_r: wp.float64  # rolling friction coefficient
    # The soft-sphere law of pkdgrav ("ssdem", docs/model.md), zero for the other laws:
    k_n: wp.float64  # normal spring [dyne/cm]
    k_t: wp.float64  # tangential spring [dyne/cm]
    damping_n: wp.float64  # C_n / sqrt(reduced mass) [g^1/2 s^-1]: -2 ln(eps_n) sqrt(k_n / (pi^2 + ln^2 eps_n))
    damping_t: wp.float64  # C_t / sqrt(reduced mass), the same of k_t and eps_t
    mu_s: wp.float64  # static friction coefficient: |F_T| <= mu_s |F_N|
    mu_t: wp.float64  # twisting friction coefficient: |M_t| <= mu_t mu_s R_r |F_N|
    beta: wp.float64  # shape parameter: the rolling and twisting radius R_r = beta R_i R_j / (R_i + R_j)
    cohesion: wp.float64  # c, the cohesive tensile strength [dyne/cm^2]: a touching pair attracts with 4 c R_r^2
    dt: wp.float64  # the step over which a contact's springs are carried and stretched [s]


# --- gravity (paper eq. 2) ---------------------------------------------------


# 1/sqrt(d^2) in one instruction on a GPU: written as 1 / sqrt, fast math still issues two
# special-function instructions (sqrt.approx, then div.approx), and these units, 16 per SM
# against 128 float32 lanes, bound the all-pairs sweep.  rsqrt.approx is within 2^-22 relative;
# the CPU keeps the correctly rounded 1 / sqrt.
_INVERSE_SQRT = """
#if defined(__CUDA_ARCH__)
return rsqrtf(d2);
#else
return 1.0f / wp::sqrt(d2);
#endif
"""


@wp.func_native(_INVERSE_SQRT)
def inverse_sqrt_fast(d2: wp.float32) -> wp.float32: ...


@wp.func
def inverse_sqrt_exact(d2: wp.float64) -> wp.float64:
    """1/sqrt(d^2) correctly rounded, for float64 sweeps."""
    return f64(1.0) / wp.sqrt(d2)


@wp.func
def gravity(r_ij: wp.vec3f, g_mass_mass: wp.float32) -> wp.vec3f:
    """Gravity on i from j, -G m_i m_j / d^2 n, in float32 (the fast default)."""
    d2 = wp.dot(r_ij, r_ij)
    inv_d = inverse_sqrt_fast(d2)
    return (-g_mass_mass * inv_d * inv_d * inv_d) * r_ij


@wp.func
def gravity(r_ij: wp.vec3d, g_mass_mass: wp.float64) -> wp.vec3d:
    """Gravity on i from j, -G m_i m_j / d^2 n, in float64."""
    d2 = wp.dot(r_ij, r_ij)
    inv_d = f64(1.0) / wp.sqrt(d2)
    return (-g_mass_mass * inv_d * inv_d * inv_d) * r_ij


# --- contact geometry ----------------------------------------------------------


@wp.func
def overlap(distance: wp.float64, radius_i: wp.float64, radius_j: wp.float64) -> wp.float64:
    """delta = R_i + R_j - d; positive when the spheres touch."""
    return radius_i + radius_j - distance


# --- who interacts ---------------------------------------------------------------
# Every test of who may touch whom is reach() and within_reach(); a path's margin is its own
# argument (the margins differ, and the motion keeps each path's bits).

#: The all-pairs sweep's float32 candidates: on d^2, as a float32 separation is good to ~1e-7
#: relative (the candidates are confirmed in float64).
CONTACT_CANDIDATE = 1.0 + 1e-5
#: The tree's hash grid, on the reach: it covers float32 positions to |x| ~ 1e9 cm.
TREE_GRID_MARGIN = 1.0001
#: The neighbour list, on R_i + R_j + skin: it covers the rounding of the float64 distances of the
#: build and of the displacement check (a pair at the reach exactly stays listed).
NEIGHBOUR_LIST_MARGIN = 1.0 + 1e-9


@wp.func
def reach(radius_i: Any, radius_j: Any, skin: Any, margin: Any) -> Any:
    """How far i and j interact: (R_i + R_j + skin) margin.  A contact is skin 0 and margin 1
    (delta > 0); a contact finder adds its skin or its rounding margin (above)."""
    return (radius_i + radius_j + skin) * margin


@wp.func
def squared_reach(reach: Any, square_margin: Any) -> Any:
    """reach^2 square_margin: the bound on d^2 (``square_margin``: CONTACT_CANDIDATE in the float32
    sweep, else 1)."""
    return reach * reach * square_margin


@wp.func
def within_reach(d2: Any, reach: Any, square_margin: Any) -> bool:
    """Whether d^2 < reach^2 square_margin: tested on d^2, no square root for distant pairs."""
    return d2 < squared_reach(reach, square_margin)


def host_reach(radius_i, radius_j, skin=0.0, margin=1.0):
    """:func:`reach` on the host (floats or NumPy arrays): the same operations in the same order,
    for the cells the finders' grids are built with."""
    return (radius_i + radius_j + skin) * margin


@wp.func
def in_contact(d2: wp.float64, radius_i: wp.float64, radius_j: wp.float64) -> bool:
    """True when delta > 0."""
    return within_reach(d2, reach(radius_i, radius_j, f64(0.0), f64(1.0)), f64(1.0))


@wp.func
def lever_arm(r_ij: wp.vec3d, radius_i: wp.float64, radius_j: wp.float64) -> wp.vec3d:
    """a_i = -(R_i / (R_i + R_j)) r_ij: from the centre of i to the shared contact point."""
    return (-radius_i / (radius_i + radius_j)) * r_ij


# --- normal spring (paper eqs. 4-5) --------------------------------------------


@wp.func
def spring_constant(normal_speed: wp.float64, k_in: wp.float64, k_out: wp.float64) -> wp.float64:
    """k_in while approaching ((v_i - v_j).n < 0), k_out = eps^2 k_in while receding or at rest."""
    if normal_speed < f64(0.0):
        return k_in
    return k_out


@wp.func
def normal_force_magnitude(delta: wp.float64, k: wp.float64) -> wp.float64:
    """|F_N| = (k/2) delta: two springs in series, one per sphere."""
    return f64(0.5) * k * delta


# --- sliding friction (paper eqs. 6-8, signs of docs/model.md) --------------------


@wp.func
def surface_slip(
    n: wp.vec3d,
    velocity_i: wp.vec3d,
    omega_i: wp.vec3d,
    arm_i: wp.vec3d,
    velocity_j: wp.vec3d,
    omega_j: wp.vec3d,
    arm_j: wp.vec3d,
) -> wp.vec3d:
    """Tangential velocity of i's surface relative to j's at the contact point."""
    g = (velocity_i + wp.cross(omega_i, arm_i)) - (velocity_j + wp.cross(omega_j, arm_j))
    return g - wp.dot(g, n) * n


#: Slip below this fraction of the pair's velocity scale (:func:`velocity_scale`) is none: the slip
#: of a rigidly moving pair is round-off of its velocities, and friction then would act in a
#: direction set by round-off (docs/model.md, "Sliding friction").
SLIP_THRESHOLD = 1e-10


@wp.func
def velocity_scale(
    velocity_i: wp.vec3d, omega_i: wp.vec3d, radius_i: wp.float64, velocity_j: wp.vec3d, omega_j: wp.vec3d, radius_j: wp.float64
) -> wp.float64:
    """V = |v_i| + |v_j| + |w_i| R_i + |w_j| R_j, summed so that i <-> j gives the same bits."""
    return (wp.length(velocity_i) + wp.length(velocity_j)) + (wp.length(omega_i) * radius_i + wp.length(omega_j) * radius_j)


@wp.func
def sliding_friction(slip: wp.vec3d, n: wp.vec3d, normal_magnitude: wp.float64, mu_k: wp.float64, scale: wp.float64) -> wp.vec3d:
    """F_S = -mu_k |F_N| s_t/|s_t| on i: opposes the slip s, along s_t = s - (s.n) n (s projected
    once more, so that round-off cannot tilt the force off the tangent plane); zero where
    |s| <= SLIP_THRESHOLD x the pair's velocity scale (``scale``)."""
    if wp.length(slip) > f64(SLIP_THRESHOLD) * scale:
        tangent = slip - wp.dot(slip, n) * n
        size = wp.length(tangent)
        if size > f64(0.0):
            return (-mu_k * normal_magnitude / size) * tangent
    return vec3d()


# --- rolling friction (paper eq. 9) ---------------------------------------------


@wp.func
def rolling_couple(
    n: wp.vec3d,
    omega_i: wp.vec3d,
    omega_j: wp.vec3d,
    normal_magnitude: wp.float64,
    mu_r: wp.float64,
    reduced_radius: wp.float64,
) -> wp.vec3d:
    """Torque on i, -mu_r |F_N| R* W/|W| with W the relative rotation without twist.

    A pure couple (docs/model.md default): it opposes relative rolling and moves no
    momentum or angular momentum between the spheres.
    """
    relative = omega_i - omega_j
    rolling = relative - wp.dot(relative, n) * n
    rate = wp.length(rolling)
    if rate > f64(0.0):
        return (-mu_r * normal_magnitude * reduced_radius / rate) * rolling
    return vec3d()


@wp.func
def rolling_force_printed(
    r_ij: wp.vec3d,
    omega_i: wp.vec3d,
    omega_j: wp.vec3d,
    normal_magnitude: wp.float64,
    mu_r: wp.float64,
    i_is_first: bool,
) -> wp.vec3d:
    """The paper's printed eq. 9, -mu_r |F_N| (w_i - w_j) x r_ij / |...|, as a force on i.

    The printed expression is symmetric in i <-> j, so taken literally both spheres
    would get the same force.  The paper says j gets the opposite one; we apply it
    to the lower-index sphere of the pair and its negative to the other, so that
    momentum is conserved.  Kept for comparison only (docs/model.md).
    """
    direction = wp.cross(omega_i - omega_j, r_ij)
    size = wp.length(direction)
    if size > f64(0.0):
        force = (-mu_r * normal_magnitude / size) * direction
        if i_is_first:
            return force
        return -force
    return vec3d()


# --- one contact, composed ------------------------------------------------------


@wp.func
def normal_spring(
    model: ContactModel,
    r_ij: wp.vec3d,
    d2: wp.float64,
    radius_i: wp.float64,
    velocity_i: wp.vec3d,
    radius_j: wp.float64,
    velocity_j: wp.vec3d,
):
    """The paper's spring of a pair in contact, seen from i: (n, |F_N|, a_i), k_in while the spheres
    approach and k_out while they part."""
    d = wp.sqrt(d2)
    n = r_ij / d
    delta = overlap(d, radius_i, radius_j)
    k = spring_constant(wp.dot(velocity_i - velocity_j, n), model.k_in, model.k_out)
    return n, normal_force_magnitude(delta, k), lever_arm(r_ij, radius_i, radius_j)


@wp.func
def normal_and_sliding(
    model: ContactModel,
    r_ij: wp.vec3d,
    d2: wp.float64,
    radius_i: wp.float64,
    velocity_i: wp.vec3d,
    omega_i: wp.vec3d,
    radius_j: wp.float64,
    velocity_j: wp.vec3d,
    omega_j: wp.vec3d,
):
    """Spring and sliding friction on i from j, for a pair in contact.

    Returns (spring force on i, sliding force on i, its torque on i, n, |F_N|, a_i).
    """
    n, normal_magnitude, arm_i = normal_spring(model, r_ij, d2, radius_i, velocity_i, radius_j, velocity_j)
    arm_j = lever_arm(-r_ij, radius_j, radius_i)  # j's own arm, seen from j
    slip = surface_slip(n, velocity_i, omega_i, arm_i, velocity_j, omega_j, arm_j)
    scale = velocity_scale(velocity_i, omega_i, radius_i, velocity_j, omega_j, radius_j)
    friction = sliding_friction(slip, n, normal_magnitude, model.mu_k, scale)
    return normal_magnitude * n, friction, wp.cross(arm_i, friction), n, normal_magnitude, arm_i


# A contact returns its force and torque on i split by channel, so that the
# energy ledger can follow each: (spring force, sliding force, sliding torque,
# rolling force, rolling torque).


@wp.func
def contact_with_rolling_couple(
    model: ContactModel,
    r_ij: wp.vec3d,
    d2: wp.float64,
    radius_i: wp.float64,
    velocity_i: wp.vec3d,
    omega_i: wp.vec3d,
    radius_j: wp.float64,
    velocity_j: wp.vec3d,
    omega_j: wp.vec3d,
    i_is_first: bool,
):
    """Channels of a touching j's action on i; rolling friction as a couple (default)."""
    spring, sliding, sliding_torque, n, normal_magnitude, arm_i = normal_and_sliding(
        model, r_ij, d2, radius_i, velocity_i, omega_i, radius_j, velocity_j, omega_j
    )
    reduced_radius = radius_i * radius_j / (radius_i + radius_j)
    rolling_torque = rolling_couple(n, omega_i, omega_j, normal_magnitude, model.mu_r, reduced_radius)
    return spring, sliding, sliding_torque, vec3d(), rolling_torque


@wp.func
def contact_with_printed_rolling(
    model: ContactModel,
    r_ij: wp.vec3d,
    d2: wp.float64,
    radius_i: wp.float64,
    velocity_i: wp.vec3d,
    omega_i: wp.vec3d,
    radius_j: wp.float64,
    velocity_j: wp.vec3d,
    omega_j: wp.vec3d,
    i_is_first: bool,
):
    """Channels of a touching j's action on i; rolling friction as the paper prints it."""
    spring, sliding, sliding_torque, n, normal_magnitude, arm_i = normal_and_sliding(
        model, r_ij, d2, radius_i, velocity_i, omega_i, radius_j, velocity_j, omega_j
    )
    rolling = rolling_force_printed(r_ij, omega_i, omega_j, normal_magnitude, model.mu_r, i_is_first)
    return spring, sliding, sliding_torque, rolling, wp.cross(arm_i, rolling)


# --- DECCO's code (LucasKolanz/DECCO at fae89d3, ColliderSingleCore.cpp sim_one_step) -------------
#
# DECCO meets each pair once, as (A, B) with A the higher index, and computes from A's side: its
# lever arm r_a = (R_A / S) (x_B - x_A) (our a_A), the slip of B seen from A with both spins on A's
# arm, u = (v_B - v_A)_t - w_A x r_a - w_B x r_a, sliding friction mu_k |F_N| u / |u| on A (-that on B)
# where |u| > 1e-13 cm/s, and rolling friction -mu_r |F_N| (w_A - w_B) x r_a / |(w_A - w_B) x r_a|
# where |w_A - w_B| > 1e-13 rad/s, applied as torques alone: r_a x it on A and r_b x it on B. These
# functions give i's part of that, i being A or B.

#: DECCO's absolute thresholds of slip [cm/s] and relative spin [rad/s] below which no friction acts.
DECCO_THRESHOLD = 1e-13


@wp.func
def decco_friction(
    n: wp.vec3d,
    normal_magnitude: wp.float64,
    mu_k: wp.float64,
    mu_r: wp.float64,
    velocity_a: wp.vec3d,
    omega_a: wp.vec3d,
    arm_a: wp.vec3d,
    velocity_b: wp.vec3d,
    omega_b: wp.vec3d,
):
    """(sliding force on A, rolling force whose torques act on both) of DECCO's code for a pair seen
    from A (its arm ``arm_a``; n along A's outward normal, from B to A)."""
    relative = velocity_b - velocity_a
    slip = relative - wp.dot(relative, n) * n - wp.cross(omega_a, arm_a) - wp.cross(omega_b, arm_a)
    sliding = vec3d()
    speed = wp.length(slip)
    if speed > f64(DECCO_THRESHOLD):
        sliding = (mu_k * normal_magnitude / speed) * slip
    rolling = vec3d()
    spin = omega_a - omega_b
    if wp.length(spin) > f64(DECCO_THRESHOLD):
        direction = wp.cross(spin, arm_a)
        size = wp.length(direction)
        if size > f64(0.0):  # (DECCO divides by it unguarded: a spin along the normal gives NaN there)
            rolling = (-mu_r * normal_magnitude / size) * direction
    return sliding, rolling


@wp.func
def contact_as_decco_code(
    model: ContactModel,
    r_ij: wp.vec3d,
    d2: wp.float64,
    radius_i: wp.float64,
    velocity_i: wp.vec3d,
    omega_i: wp.vec3d,
    radius_j: wp.float64,
    velocity_j: wp.vec3d,
    omega_j: wp.vec3d,
    i_is_first: bool,
):
    """Channels of a touching j's action on i by DECCO's code: the paper's spring, DECCO's sliding and
    rolling friction computed from the pair's higher index (A), i taking A's part or B's."""
    n, normal_magnitude, arm_i = normal_spring(model, r_ij, d2, radius_i, velocity_i, radius_j, velocity_j)
    sliding = vec3d()
    rolling = vec3d()
    if i_is_first:  # i is B: the pair seen from j (A), whose normal is -n
        sliding_a, rolling_a = decco_friction(-n, normal_magnitude, model.mu_k, model.mu_r, velocity_j, omega_j,
                                              lever_arm(-r_ij, radius_j, radius_i), velocity_i, omega_i)  # fmt: skip
        sliding = -sliding_a
        rolling = rolling_a
    else:
        sliding, rolling = decco_friction(n, normal_magnitude, model.mu_k, model.mu_r, velocity_i, omega_i, arm_i, velocity_j, omega_j)
    return normal_magnitude * n, sliding, wp.cross(arm_i, sliding), vec3d(), wp.cross(arm_i, rolling)


# --- the soft-sphere law of pkdgrav (Schwartz, Richardson & Michel 2012; docs/model.md "ssdem") -------
#
# pkdgrav (WH-Zhou/pkdgrav_current fe25b05, smoothfcn.c DoDEM; docs/ssdem-design.md) meets each pair
# once, from its lower index p, with n the unit vector from p to the other, q.  So do these functions:
# a contact's springs live in that frame, and both particles evaluate the pair from p's side with the
# same arguments in the same order, so that the two get the same bits (exact action and reaction)
# and keep the same copy of the pair's springs (kernels/contacts.py).


@wp.struct
class PairSprings:
    """A contact's springs, in the frame of its lower index p (docs/model.md "ssdem")."""

    spring: wp.vec3d  # S, the tangential spring's stretch [cm], in the tangent plane
    normal: wp.vec3d  # n at the step before, from p to q (zero: no step before, a new contact)
    rolling: wp.vec3d  # theta_r, the rolling spring's angle [rad], in the tangent plane
    twist: wp.float64  # theta_t, the twisting spring's angle about n [rad]


@wp.func
def rotated(v: wp.vec3d, axis: wp.vec3d, sine: wp.float64, cosine: wp.float64) -> wp.vec3d:
    """v turned right-handedly about the unit ``axis`` by the angle of that sine and cosine (Rodrigues)."""
    return cosine * v + sine * wp.cross(axis, v) + ((f64(1.0) - cosine) * wp.dot(axis, v)) * axis


@wp.func
def carried(spring: wp.vec3d, rolling: wp.vec3d, normal_before: wp.vec3d, n: wp.vec3d, spin_sum: wp.vec3d, dt: wp.float64):
    """The tangential and rolling springs of the step before carried into the current tangent plane,
    in pkdgrav's two stages (smoothfcn.c 4753-4846; [S12] sect. 2.2): turned about the mean normal by
    the pair's mean spin about it over the step, 1/2 dt (w_p + w_q).n_mean, then with the normal from
    ``normal_before`` onto ``n``; then projected onto the plane (pkdgrav does not project: the
    stages leave them off the plane by round-off and by the second order of the turns).  Both
    springs take the same turns, computed once."""
    mean = normal_before + n
    mean = mean / wp.length(mean)  # the normal turns by far less than 90 degrees in a step
    angle = f64(0.5) * dt * wp.dot(spin_sum, mean)
    sin_spin = wp.sin(angle)
    cos_spin = wp.cos(angle)
    spring = rotated(spring, mean, sin_spin, cos_spin)
    rolling = rotated(rolling, mean, sin_spin, cos_spin)
    axis = wp.cross(normal_before, n)
    sine = wp.length(axis)
    if sine > f64(0.0):
        unit = axis / sine
        cosine = wp.dot(n, normal_before)
        spring = rotated(spring, unit, sine, cosine)
        rolling = rotated(rolling, unit, sine, cosine)
    return spring - wp.dot(spring, n) * n, rolling - wp.dot(rolling, n) * n


@wp.func
def cohesive_force(cohesion: wp.float64, radius_r: wp.float64) -> wp.float64:
    """|F_c| = c 4 R_r^2 [dyne]: a tensile strength c over the area (2 R_r)^2, R_r = beta R* (pkdgrav's model 0)."""
    return f64(4.0) * cohesion * radius_r * radius_r


@wp.func
def ssdem_contact(
    model: ContactModel,
    position_p: wp.vec3d,
    velocity_p: wp.vec3d,
    omega_p: wp.vec3d,
    radius_p: wp.float64,
    mass_p: wp.float64,
    position_q: wp.vec3d,
    velocity_q: wp.vec3d,
    omega_q: wp.vec3d,
    radius_q: wp.float64,
    mass_q: wp.float64,
    before: PairSprings,
    found: bool,
):
    """One contact of the soft-sphere law, from its lower index p (docs/model.md "ssdem"), given its
    springs of the step before (``found``: the pair touched then).

    Returns (F_N on p, F_T on p, F_T's torque on p, F_T's torque on q, the rolling and twisting couple
    on p (q gets minus it), the springs now).  Forces [dyne], torques [dyne cm]."""
    r = position_q - position_p
    d = wp.sqrt(wp.dot(r, r))
    n = r / d  # from p to q
    x = radius_p + radius_q - d  # overlap
    lever_p = (radius_p * radius_p - radius_q * radius_q + d * d) / (f64(2.0) * d)  # centre to contact plane [S12] eq. 9
    lever_q = d - lever_p
    # Velocity of q's material relative to p's at the contact, and its parts.
    u = (velocity_q - velocity_p) + lever_q * wp.cross(n, omega_q) + lever_p * wp.cross(n, omega_p)
    u_n = wp.dot(u, n) * n
    u_t = u - u_n
    root_mass = wp.sqrt(mass_p * mass_q / (mass_p + mass_q))
    damping_n = model.damping_n * root_mass  # C_n [S12] eq. 15
    damping_t = model.damping_t * root_mass  # C_t
    radius_r = model.beta * radius_p * radius_q / (radius_p + radius_q)  # R_r
    area = radius_r * radius_r
    # Rolling and twisting rates (pkdgrav's spring-dashpot-slider; smoothfcn.c 4716-4738).
    spin = omega_q - omega_p
    twist_rate = wp.dot(n, spin)
    rolling_rate = spin - twist_rate * n
    levers = lever_p * lever_q
    if levers > f64(0.0):  # (a centre inside the other sphere has no contact plane between them)
        rolling_rate = rolling_rate + ((lever_q - lever_p) / (f64(2.0) * levers)) * wp.cross(n, u)
    now = PairSprings()
    if found:
        spin_sum = omega_p + omega_q
        spring, rolling = carried(before.spring, before.rolling, before.normal, n, spin_sum, model.dt)
        now.spring = spring
        now.rolling = rolling
        now.twist = before.twist
    now.normal = n
    now.spring = now.spring + model.dt * u_t  # [S12] eq. 7: this step's stretch first
    now.rolling = now.rolling + model.dt * rolling_rate
    now.twist = now.twist + model.dt * twist_rate
    normal = (-model.k_n * x) * n + damping_n * u_n  # [S12] eqs. 3, 13, 16: never clamped
    normal_magnitude = wp.length(normal)  # N: the caps' normal force, damping included
    tangential = model.k_t * now.spring + damping_t * u_t  # [S12] eqs. 6, 14, 17
    # Static friction: past mu_s N the force is mu_s N along the trial force and the spring is set to
    # what gives it (Coulomb sliding; pkdgrav zeroes the spring instead, docs/model.md).
    cap = model.mu_s * normal_magnitude
    size = wp.length(tangential)
    if size > cap:
        tangential = (cap / size) * tangential
        now.spring = vec3d()
        if model.k_t > f64(0.0):
            now.spring = (tangential - damping_t * u_t) / model.k_t
    # Rolling: a spring k_r = k_n R_r^2 with its dashpot, slid at mu_r R_r N (the spring then kept).
    rolling = (model.k_n * area) * now.rolling
    rolling_cap = model.mu_r * radius_r * normal_magnitude
    rolling_size = wp.length(rolling)
    if rolling_size > rolling_cap:
        rolling = (rolling_cap / rolling_size) * rolling
        now.rolling = now.rolling - model.dt * rolling_rate
    else:
        rolling = rolling + (damping_n * area) * rolling_rate
    # Twisting: a spring k_q = 2 k_t R_r^2 with its dashpot, slid at mu_t mu_s R_r N (pkdgrav's cap).
    twisting = f64(2.0) * model.k_t * area * now.twist
    twist_cap = model.mu_t * model.mu_s * radius_r * normal_magnitude
    if wp.abs(twisting) > twist_cap:
        twisting = wp.sign(twisting) * twist_cap
        now.twist = now.twist - model.dt * twist_rate
    else:
        twisting = twisting + f64(2.0) * damping_t * area * twist_rate
    # Cohesion (pkdgrav's model 0, Zhang & Richardson's note eqs. 2-3): c over the area (2 R_r)^2, towards
    # q while touching; added after the caps, which it does not raise.
    normal = normal + cohesive_force(model.cohesion, radius_r) * n
    lever_torque = wp.cross(n, tangential)
    return normal, tangential, lever_p * lever_torque, lever_q * lever_torque, rolling + twisting * n, now


#: The contact laws, by name (params.py ``Params.law``): each gives the channels of a touching j's
#: action on i.  "paper": the paper's law, rolling friction as a couple (docs/model.md);
#: "paper-printed-rolling": the same, rolling friction as the force printed as the paper's eq. 9;
#: "decco-code": DECCO's pair forces as its code computes them.  A new law is one function of that
#: signature and its line here (the spec, the CLI and Params take their names from this table).  "ssdem", pkdgrav's soft-sphere law, keeps springs per pair: its
#: function (:func:`ssdem_contact`) takes the pair from its lower index with the springs of the step
#: before, and kernels/contacts.py keeps them (:data:`LAWS_WITH_SPRINGS`).
CONTACT_LAWS = {
    "paper": contact_with_rolling_couple,
    "paper-printed-rolling": contact_with_printed_rolling,
    "decco-code": contact_as_decco_code,
    "ssdem": ssdem_contact,
}

#: The laws that keep springs per pair (a contact history, kernels/contacts.py PairHistory).
LAWS_WITH_SPRINGS = ("ssdem",)
#: Laws of CONTACT_LAWS that are another law's variant, chosen by a constant of that law (Params'
#: rolling_friction), not by name: what a user may ask for by name is the rest (params.CONTACT_LAWS).
LAW_VARIANTS = {"paper-printed-rolling": "paper"}

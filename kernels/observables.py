"""Per-particle pair observables for diagnostics and output, in float64.

Not on the hot path: launched only when diagnostics or output are due.  All pairs:
``pair_observables_tiled``, a block of threads per particle striding over j, then reduced in a
fixed order (``pair_observables``, one thread per particle, is its plain yardstick); on the tree
path, one thread per particle over its contact candidates, the potential coming from the tree
(kernels/tree.py ``tree_potential``).
"""

import functools

import warp as wp

from .contacts import candidate_at, candidates_walk
from .pair import ContactModel, cohesive_force, in_contact, normal_force_magnitude, overlap, spring_constant

wp.set_module_options({"enable_backward": False})


@wp.struct
class ContactObservables:
    """One particle's contacts, summed: half their elastic energy, how many, the largest overlap
    [cm], and the deepest as a fraction of the pair's smaller radius, with that partner (-1: none)."""

    elastic: wp.float64
    contacts: int
    max_overlap: wp.float64
    depth: wp.float64
    partner: int


@wp.func
def add_contact_observables(
    model: ContactModel, total: ContactObservables, i: int, j: int, d2: wp.float64, r_ij: wp.vec3d,
    radius_in: wp.array(dtype=wp.float64), velocity_in: wp.array(dtype=wp.vec3d),
) -> ContactObservables:  # fmt: skip
    """``total`` with the pair (i, j), at separation r_ij (d2 = |r_ij|^2 > 0), added if they touch."""
    out = total
    radius_i, radius_j = radius_in[i], radius_in[j]
    if in_contact(d2, radius_i, radius_j):
        d = wp.sqrt(d2)
        delta = overlap(d, radius_i, radius_j)
        k = spring_constant(wp.dot(velocity_in[i] - velocity_in[j], r_ij / d), model.k_in, model.k_out)
        # Energy of the spring pair, (k/4) delta^2 for the force (k/2) delta, halved per side.
        out.elastic = total.elastic + wp.float64(0.5) * wp.float64(0.5) * normal_force_magnitude(delta, k) * delta
        # ssdem's cohesion, a force F_c towards the other while touching: its potential -F_c delta, halved
        # per side (zero for the other laws: their cohesion and beta are 0).
        radius_r = model.beta * radius_i * radius_j / (radius_i + radius_j)
        out.elastic = out.elastic - wp.float64(0.5) * cohesive_force(model.cohesion, radius_r) * delta
        out.contacts = total.contacts + 1
        out.max_overlap = wp.max(total.max_overlap, delta)
        # Depth relative to the smaller sphere: past 1 a centre lies inside the other sphere.
        fraction = delta / wp.min(radius_i, radius_j)
        if fraction > total.depth:
            out.depth = fraction
            out.partner = j
    return out


@wp.func
def write_contact_observables(
    total: ContactObservables, i: int, elastic_out: wp.array(dtype=wp.float64), contacts_out: wp.array(dtype=wp.int32),
    max_overlap_out: wp.array(dtype=wp.float64), overlap_depth_out: wp.array(dtype=wp.float64),
    overlap_partner_out: wp.array(dtype=wp.int32),
):  # fmt: skip
    elastic_out[i] = total.elastic
    contacts_out[i] = wp.int32(total.contacts)
    max_overlap_out[i] = total.max_overlap
    overlap_depth_out[i] = total.depth
    overlap_partner_out[i] = wp.int32(total.partner)


@wp.func
def no_contacts() -> ContactObservables:
    total = ContactObservables()
    total.partner = -1
    return total


@wp.func
def pair_sums(
    model: ContactModel, i: int, first: int, end: int, stride: int, radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64), position_in: wp.array(dtype=wp.vec3d), velocity_in: wp.array(dtype=wp.vec3d),
):  # fmt: skip
    """Half of i's pair potential and its contacts' observables over j = first, first + stride, ... < end."""
    position_i = position_in[i]
    g_mass_i = model.G * mass_in[i]
    potential = wp.float64(0.0)
    total = no_contacts()
    for j in range(first, end, stride):
        r_ij = position_i - position_in[j]
        d2 = wp.dot(r_ij, r_ij)
        if d2 > wp.float64(0.0):
            potential -= wp.float64(0.5) * g_mass_i * mass_in[j] / wp.sqrt(d2)
            total = add_contact_observables(model, total, i, j, d2, r_ij, radius_in, velocity_in)
    return potential, total


@wp.kernel
def pair_observables(
    # Model:
    model: ContactModel,
    ranges_in: wp.array(dtype=wp.vec2i),  # per particle: its system's particles, [first, end)
    radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64),
    # In:
    position_in: wp.array(dtype=wp.vec3d),
    velocity_in: wp.array(dtype=wp.vec3d),
    # Out:
    potential_out: wp.array(dtype=wp.float64),
    elastic_out: wp.array(dtype=wp.float64),
    contacts_out: wp.array(dtype=wp.int32),
    max_overlap_out: wp.array(dtype=wp.float64),
    overlap_depth_out: wp.array(dtype=wp.float64),
    overlap_partner_out: wp.array(dtype=wp.int32),
):
    """Half of i's pair energies (so that summing over particles counts each pair once),
    its number of contacts, its largest overlap (its "stress", docs/model.md), and its
    deepest contact as a fraction of the smaller radius of the pair, with that partner
    (-1 without contacts)."""
    i = wp.tid()
    potential, total = pair_sums(model, i, ranges_in[i][0], ranges_in[i][1], 1, radius_in, mass_in, position_in, velocity_in)
    potential_out[i] = potential
    write_contact_observables(total, i, elastic_out, contacts_out, max_overlap_out, overlap_depth_out, overlap_partner_out)


#: No partner: larger than any particle index, so that a minimum over lanes ignores it.
NO_PARTNER = 2147483647


@wp.func
def deeper(a: wp.vec2d, b: wp.vec2d) -> wp.vec2d:
    """Of two (depth, -partner): the deeper contact, and of equally deep ones the lower partner
    (a total order, so a block's reduction gives the plain loop's first-found deepest)."""
    if b[0] > a[0] or (b[0] == a[0] and b[1] > a[1]):
        return b
    return a


@functools.cache
def pair_observables_tiled(block_dim: int):
    """:func:`pair_observables` with a block of ``block_dim`` threads per particle (1 on the CPU,
    where it sums in the plain kernel's order): each thread takes every block_dim-th j, then the
    block reduces its sums, largest overlaps and deepest contact (the smallest j among equally
    deep ones, as the plain loop keeps the first).  Launch with ``wp.launch_tiled``, dim [N]."""

    @wp.kernel(module="unique", enable_backward=False)
    def pair_observables_tiled_kernel(
        # Model:
        model: ContactModel,
        ranges_in: wp.array(dtype=wp.vec2i),  # per particle: its system's particles, [first, end)
        radius_in: wp.array(dtype=wp.float64),
        mass_in: wp.array(dtype=wp.float64),
        # In:
        position_in: wp.array(dtype=wp.vec3d),
        velocity_in: wp.array(dtype=wp.vec3d),
        # Out:
        potential_out: wp.array(dtype=wp.float64),
        elastic_out: wp.array(dtype=wp.float64),
        contacts_out: wp.array(dtype=wp.int32),
        max_overlap_out: wp.array(dtype=wp.float64),
        overlap_depth_out: wp.array(dtype=wp.float64),
        overlap_partner_out: wp.array(dtype=wp.int32),
    ):
        i, lane = wp.tid()
        potential, total = pair_sums(
            model, i, ranges_in[i][0] + lane, ranges_in[i][1], wp.block_dim(), radius_in, mass_in, position_in, velocity_in
        )
        # (Struct fields are copied into values first: a tile is made of values.)
        elastic = wp.tile_sum(wp.tile(wp.float64(total.elastic)))
        contacts = wp.tile_sum(wp.tile(int(total.contacts)))
        max_overlap = wp.tile_max(wp.tile(wp.float64(total.max_overlap)))
        partner = wp.float64(-NO_PARTNER)
        if total.partner >= 0:
            partner = -wp.float64(total.partner)
        deepest = wp.tile_reduce(deeper, wp.tile(wp.vec2d(total.depth, partner), preserve_type=True))
        potential_sum = wp.tile_sum(wp.tile(potential))
        if lane == 0:  # the reductions' results are read by the lane that writes
            block = no_contacts()
            block.elastic = elastic[0]
            block.contacts = contacts[0]
            block.max_overlap = max_overlap[0]
            found = deepest[0]
            block.depth = found[0]
            if found[1] != wp.float64(-NO_PARTNER):
                block.partner = -int(found[1])
            potential_out[i] = potential_sum[0]
            write_contact_observables(block, i, elastic_out, contacts_out, max_overlap_out, overlap_depth_out, overlap_partner_out)

    return pair_observables_tiled_kernel


@wp.kernel
def candidate_observables(
    # Model:
    model: ContactModel,
    ranges_in: wp.array(dtype=wp.vec2i),  # per particle: its system's particles, [first, end)
    radius_in: wp.array(dtype=wp.float64),
    # In:
    position_in: wp.array(dtype=wp.vec3d),
    velocity_in: wp.array(dtype=wp.vec3d),
    candidate_count_in: wp.array(dtype=wp.int32),  # per particle: candidates noted (past the list's width: an overflow)
    candidates_in: wp.array2d(dtype=wp.int32),  # per particle: its candidates, in increasing j
    # Out:
    elastic_out: wp.array(dtype=wp.float64),
    contacts_out: wp.array(dtype=wp.int32),
    max_overlap_out: wp.array(dtype=wp.float64),
    overlap_depth_out: wp.array(dtype=wp.float64),
    overlap_partner_out: wp.array(dtype=wp.int32),
):
    """The contact part of :func:`pair_observables` from each particle's contact candidates (the
    tree path's hash grid), in the same order of j, so with the same sums."""
    i = wp.tid()
    listed, walk = candidates_walk(i, ranges_in, candidate_count_in, candidates_in)
    total = no_contacts()
    for s in range(walk):
        j = candidate_at(i, listed, ranges_in, candidates_in, s)
        r_ij = position_in[i] - position_in[j]
        d2 = wp.dot(r_ij, r_ij)
        if d2 > wp.float64(0.0):
            total = add_contact_observables(model, total, i, j, d2, r_ij, radius_in, velocity_in)
    write_contact_observables(total, i, elastic_out, contacts_out, max_overlap_out, overlap_depth_out, overlap_partner_out)


@wp.kernel
def smoothed_density(
    # In:
    source_position_in: wp.array(dtype=wp.vec3d),
    source_norm_in: wp.array(dtype=wp.float64),  # per source: m_j / ((2 pi)^(3/2) sigma_j^3)
    source_inv_two_var_in: wp.array(dtype=wp.float64),  # per source: 1 / (2 sigma_j^2)
    target_position_in: wp.array(dtype=wp.vec3d),
    # Out:
    density_out: wp.array(dtype=wp.float64),
):
    """The cluster finder's smoothed density (paper sect. 2.7) at each target: sum over the sources of
    m_j / ((2 pi)^(3/2) sigma_j^3) exp(-|y - x_j|^2 / (2 sigma_j^2)), the factors given per source.
    O(N^2) in float64: the Gaussian is 10 radii wide, so it reaches across a whole pile."""
    t = wp.tid()
    y = target_position_in[t]
    total = wp.float64(0.0)
    for j in range(source_position_in.shape[0]):
        r = y - source_position_in[j]
        total += source_norm_in[j] * wp.exp(-wp.dot(r, r) * source_inv_two_var_in[j])
    density_out[t] = total

"""Per-particle pair observables for diagnostics and output, in float64.

Not on the hot path: launched only when diagnostics or output are due, one
thread per particle over all j.
"""

import warp as wp

from .pair import ContactModel, in_contact, normal_force_magnitude, overlap, spring_constant

wp.set_module_options({"enable_backward": False})


@wp.kernel
def pair_observables(
    # Model:
    model: ContactModel,
    ranges: wp.array(dtype=wp.vec2i),  # per particle: its system's particles, [first, end)
    radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64),
    # State in:
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
    position_i = position_in[i]
    velocity_i = velocity_in[i]
    radius_i = radius_in[i]
    g_mass_i = model.G * mass_in[i]
    potential = wp.float64(0.0)
    elastic = wp.float64(0.0)
    contacts = int(0)
    max_overlap = wp.float64(0.0)
    depth = wp.float64(0.0)
    partner = int(-1)
    for j in range(ranges[i][0], ranges[i][1]):
        r_ij = position_i - position_in[j]
        d2 = wp.dot(r_ij, r_ij)
        if d2 > wp.float64(0.0):
            d = wp.sqrt(d2)
            potential -= wp.float64(0.5) * g_mass_i * mass_in[j] / d
            if in_contact(d2, radius_i, radius_in[j]):
                delta = overlap(d, radius_i, radius_in[j])
                k = spring_constant(wp.dot(velocity_i - velocity_in[j], r_ij / d), model.k_in, model.k_out)
                # Energy of the spring pair, (k/4) delta^2 for the force (k/2) delta, halved per side.
                elastic += wp.float64(0.5) * wp.float64(0.5) * normal_force_magnitude(delta, k) * delta
                contacts += 1
                max_overlap = wp.max(max_overlap, delta)
                # Depth relative to the smaller sphere: past 1 a centre lies inside the other sphere.
                fraction = delta / wp.min(radius_i, radius_in[j])
                if fraction > depth:
                    depth = fraction
                    partner = j
    potential_out[i] = potential
    elastic_out[i] = elastic
    contacts_out[i] = wp.int32(contacts)
    max_overlap_out[i] = max_overlap
    overlap_depth_out[i] = depth
    overlap_partner_out[i] = wp.int32(partner)

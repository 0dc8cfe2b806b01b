"""The reference kernel: one thread per particle, a plain loop over every j of its system.

It has no layout to get wrong, so it is the yardstick of the tiled layouts in the tests and the
baseline of ``decco-warp bench``, and the all-pairs engine of diagnostics
(``force_kernel="reference"``).  Gravity pair by pair in the precision's arithmetic on the float64
separation, contacts with the same functions as every layout (:mod:`.contacts`).
"""

import functools

import warp as wp

from .bodies import real_types
from .contacts import ContactRows, PairHistory, close_rows, contact_sum_function, write_contacts
from .pair import ContactModel, gravity, in_contact

wp.set_module_options({"enable_backward": False})


@functools.cache
def pair_forces_reference(precision: str = "mixed", law: str = "paper"):
    """Build the one-thread-per-particle kernel; launch with ``dim=N``.  The ledger's channels are
    written when ``channels_out`` has rows."""
    real, vec_real = real_types(precision)
    add_contact = contact_sum_function(law)

    @wp.kernel(module="unique", enable_backward=False)
    def pair_forces_reference_kernel(
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
        # Out:
        force_out: wp.array(dtype=wp.vec3d),
        torque_out: wp.array(dtype=wp.vec3d),
        channels_out: wp.array2d(dtype=wp.vec3d),
        deepest_inout: wp.array(dtype=wp.int64),  # raised to each contact's depth (note_depth), or empty
        history_out: PairHistory,  # the contacts' springs now, in increasing j (a law with springs)
    ):
        i = wp.tid()
        position_i = position_in[i]
        g_mass_i = model.G * mass_in[i]
        gravity_sum = vec_real()
        total = ContactRows()
        rows = int(0)
        for j in range(ranges_in[i][0], ranges_in[i][1]):
            r_ij = position_i - position_in[j]
            d2 = wp.dot(r_ij, r_ij)
            if d2 > wp.float64(0.0):
                gravity_sum += gravity(vec_real(r_ij), real(g_mass_i * mass_in[j]))
                if in_contact(d2, radius_in[i], radius_in[j]):
                    total, rows = add_contact(
                        model, i, j, radius_in, mass_in, position_in, velocity_in, omega_in, history_in, rows, history_out, deepest_inout, total
                    )
        close_rows(history_out, i, rows)
        contact_force = write_contacts(total, i, torque_out, channels_out)
        force_out[i] = wp.vec3d(gravity_sum) + contact_force

    return pair_forces_reference_kernel

"""Kick-drift-kick velocity Verlet (paper eq. 1, physics.md "Integration").

One step is ``kick_drift`` (half kick with the forces of the previous evaluation,
then a full drift), the force evaluation at the new positions with the half-step
velocities, and ``kick`` (the second half kick).  All in float64.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.kernel
def kick_drift(
    # Model:
    dt: wp.float64,
    mass_in: wp.array(dtype=wp.float64),
    inertia_in: wp.array(dtype=wp.float64),
    # Data in:
    force_in: wp.array(dtype=wp.vec3d),
    torque_in: wp.array(dtype=wp.vec3d),
    # Data in/out:
    position_inout: wp.array(dtype=wp.vec3d),
    velocity_inout: wp.array(dtype=wp.vec3d),
    omega_inout: wp.array(dtype=wp.vec3d),
):
    i = wp.tid()
    half_dt = wp.float64(0.5) * dt
    velocity = velocity_inout[i] + (half_dt / mass_in[i]) * force_in[i]
    velocity_inout[i] = velocity
    omega_inout[i] = omega_inout[i] + (half_dt / inertia_in[i]) * torque_in[i]
    position_inout[i] = position_inout[i] + dt * velocity


@wp.kernel
def kick(
    # Model:
    dt: wp.float64,
    mass_in: wp.array(dtype=wp.float64),
    inertia_in: wp.array(dtype=wp.float64),
    # Data in:
    force_in: wp.array(dtype=wp.vec3d),
    torque_in: wp.array(dtype=wp.vec3d),
    # Data in/out:
    velocity_inout: wp.array(dtype=wp.vec3d),
    omega_inout: wp.array(dtype=wp.vec3d),
):
    i = wp.tid()
    half_dt = wp.float64(0.5) * dt
    velocity_inout[i] = velocity_inout[i] + (half_dt / mass_in[i]) * force_in[i]
    omega_inout[i] = omega_inout[i] + (half_dt / inertia_in[i]) * torque_in[i]

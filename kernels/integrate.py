"""Kick-drift-kick velocity Verlet (paper eq. 1, docs/model.md "Integration").

One step is ``kick_drift`` (half kick with the forces of the previous evaluation,
then a full drift), the force evaluation at the new positions with the half-step
velocities, and ``kick`` (the second half kick).  All in float64.

Energy ledger: a half kick changes a particle's kinetic energy by exactly
F . (v_old + v_new)/2 dt/2 (and T . (w_old + w_new)/2 dt/2), which is linear in
F and T and so splits exactly into the work of each force channel.  With the
ledger on, each kick adds those works to ``work_inout`` per particle, as
(gravity, spring, sliding friction, rolling friction).

Fused kicks: the second half kick of a step and the first of the next use the same forces, and
the sweep's packed bodies (kernels/bodies.py) follow right after the drift, so ``Engine.advance``
does k steps as ``kick_drift`` with the packing, then k - 1 times the same with ``close_step``
(each after a force evaluation), then ``kick``: per particle the same expressions in the same order
as ``kick``, ``kick_drift`` and the pack kernel one after another, in fewer launches.
"""

from typing import Any

import warp as wp

from .bodies import body_overloads, pack_body
from .channels import WORK_CHANNELS

wp.set_module_options({"enable_backward": False})

#: A particle's work, one entry per energy channel (kernels/channels.py WORK_CHANNELS).
Work = wp.types.vector(length=len(WORK_CHANNELS), dtype=wp.float64)


@wp.func
def half_kick_work(
    force: wp.vec3d,
    torque: wp.vec3d,
    spring_force: wp.vec3d,
    sliding_force: wp.vec3d,
    sliding_torque: wp.vec3d,
    rolling_force: wp.vec3d,
    velocity_old: wp.vec3d,
    velocity_new: wp.vec3d,
    omega_old: wp.vec3d,
    omega_new: wp.vec3d,
    half_dt: wp.float64,
) -> Work:
    """Work of (gravity, spring, sliding, rolling) during one half kick; sums to the kinetic energy change."""
    v = wp.float64(0.5) * (velocity_old + velocity_new)
    w = wp.float64(0.5) * (omega_old + omega_new)
    gravity = force - spring_force - sliding_force - rolling_force  # the rest of the force
    return half_dt * Work(
        wp.dot(gravity, v),
        wp.dot(spring_force, v),
        wp.dot(sliding_force, v) + wp.dot(sliding_torque, w),
        wp.dot(rolling_force, v) + wp.dot(torque - sliding_torque, w),
    )


@wp.struct
class Motion:
    """A particle's velocity, spin and ledger work, loaded once per launch and stored once: the
    kicks of a launch follow one another in registers, not through memory."""

    velocity: wp.vec3d
    omega: wp.vec3d
    work: Work  # (gravity, spring, sliding, rolling); zero without the ledger


@wp.func
def load_motion(
    i: int, velocity_in: wp.array(dtype=wp.vec3d), omega_in: wp.array(dtype=wp.vec3d), work_in: wp.array(dtype=Work)
) -> Motion:
    motion = Motion()
    motion.velocity = velocity_in[i]
    motion.omega = omega_in[i]
    if work_in.shape[0] > 0:
        motion.work = work_in[i]
    return motion


@wp.func
def store_motion(
    motion: Motion, i: int, velocity_out: wp.array(dtype=wp.vec3d), omega_out: wp.array(dtype=wp.vec3d), work_out: wp.array(dtype=Work)
):
    velocity_out[i] = motion.velocity
    omega_out[i] = motion.omega
    if work_out.shape[0] > 0:
        work_out[i] = motion.work


@wp.func
def half_kick(
    i: int,
    half_dt: wp.float64,
    mass_in: wp.array(dtype=wp.float64),
    inertia_in: wp.array(dtype=wp.float64),
    force_in: wp.array(dtype=wp.vec3d),
    torque_in: wp.array(dtype=wp.vec3d),
    channels_in: wp.array2d(dtype=wp.vec3d),  # (N, 4) with the ledger, else empty
    motion: Motion,
) -> Motion:
    """v += F/m dt/2, w += T/I dt/2 for particle i, with its ledger (when ``channels_in`` has rows)."""
    force = force_in[i]
    torque = torque_in[i]
    out = Motion()
    out.velocity = motion.velocity + (half_dt / mass_in[i]) * force
    out.omega = motion.omega + (half_dt / inertia_in[i]) * torque
    out.work = motion.work
    if channels_in.shape[0] > 0:
        out.work = motion.work + half_kick_work(
            force,
            torque,
            channels_in[i, 0],
            channels_in[i, 1],
            channels_in[i, 2],
            channels_in[i, 3],
            motion.velocity,
            out.velocity,
            motion.omega,
            out.omega,
            half_dt,
        )
    return out


@wp.kernel
def kick(
    # Model:
    dt: wp.float64,
    mass_in: wp.array(dtype=wp.float64),
    inertia_in: wp.array(dtype=wp.float64),
    # In:
    force_in: wp.array(dtype=wp.vec3d),
    torque_in: wp.array(dtype=wp.vec3d),
    channels_in: wp.array2d(dtype=wp.vec3d),
    # Out:
    velocity_inout: wp.array(dtype=wp.vec3d),
    omega_inout: wp.array(dtype=wp.vec3d),
    work_inout: wp.array(dtype=Work),
):
    i = wp.tid()
    motion = load_motion(i, velocity_inout, omega_inout, work_inout)
    motion = half_kick(i, wp.float64(0.5) * dt, mass_in, inertia_in, force_in, torque_in, channels_in, motion)
    store_motion(motion, i, velocity_inout, omega_inout, work_inout)


@wp.kernel
def kick_drift(
    # Model:
    dt: wp.float64,
    G: wp.float64,
    radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64),
    inertia_in: wp.array(dtype=wp.float64),
    # In:
    force_in: wp.array(dtype=wp.vec3d),
    torque_in: wp.array(dtype=wp.vec3d),
    channels_in: wp.array2d(dtype=wp.vec3d),  # (N, 4) with the ledger, else empty
    close_step: bool,  # first the last half kick of the step before (the same forces: those just evaluated)
    # Out:
    position_inout: wp.array(dtype=wp.vec3d),
    velocity_inout: wp.array(dtype=wp.vec3d),
    omega_inout: wp.array(dtype=wp.vec3d),
    work_inout: wp.array(dtype=Work),  # (N,) with the ledger, else empty
    body_out: wp.array(dtype=Any),  # the sweep's packed bodies (kernels/bodies.py), or empty: none packed
):
    """Half kick with the current forces, then a full drift; with ``close_step`` first ``kick``, and
    with a ``body_out`` then the pack kernel, in the same launch."""
    i = wp.tid()
    half_dt = wp.float64(0.5) * dt
    motion = load_motion(i, velocity_inout, omega_inout, work_inout)
    if close_step:
        motion = half_kick(i, half_dt, mass_in, inertia_in, force_in, torque_in, channels_in, motion)
    motion = half_kick(i, half_dt, mass_in, inertia_in, force_in, torque_in, channels_in, motion)
    store_motion(motion, i, velocity_inout, omega_inout, work_inout)
    position = position_inout[i] + dt * motion.velocity
    position_inout[i] = position
    if body_out.shape[0] > 0:
        pack_body(G, radius_in[i], mass_in[i], position, body_out, i)


#: ``kick_drift`` per precision (the type of its packed bodies).
KICK_DRIFT = body_overloads(kick_drift)


# --- Gravity on its own clock (docs/model.md): impulse multiple time stepping ---------------------
#
# One outer step of K steps of dt: a gravity half kick of K dt / 2 with the gravity at the current
# positions, K kick-drift-kick steps with the contact forces alone, gravity at the new positions,
# and the second gravity half kick.  ``Engine.advance`` shares launches as above: the contact half
# kick closing a step, the gravity half kicks closing an outer step and opening the next, and the
# next contact half kick and drift are one ``kick_drift_inner`` (per particle, the same expressions
# in the same order as the launches of ``Engine.step``).


@wp.func
def gravity_half_kick(
    i: int,
    half_dt: wp.float64,
    mass_in: wp.array(dtype=wp.float64),
    gravity_in: wp.array(dtype=wp.vec3d),
    ledger: bool,
    motion: Motion,
) -> Motion:
    """v += g/m half_dt for particle i (gravity exerts no torque on a sphere), its kinetic energy
    change booked to gravity's work (``half_kick_work`` without contact channels: all of it gravity's)."""
    gravity = gravity_in[i]
    out = Motion()
    out.velocity = motion.velocity + (half_dt / mass_in[i]) * gravity
    out.omega = motion.omega
    out.work = motion.work
    if ledger:
        none = wp.vec3d()
        out.work = motion.work + half_kick_work(gravity, none, none, none, none, none, motion.velocity, out.velocity, none, none, half_dt)
    return out


@wp.kernel
def kick_outer(
    # Model:
    dt: wp.float64,
    outer_dt: wp.float64,  # K dt
    mass_in: wp.array(dtype=wp.float64),
    inertia_in: wp.array(dtype=wp.float64),
    # In:
    force_in: wp.array(dtype=wp.vec3d),  # the contact force
    torque_in: wp.array(dtype=wp.vec3d),
    channels_in: wp.array2d(dtype=wp.vec3d),
    gravity_in: wp.array(dtype=wp.vec3d),
    close_step: bool,  # first the last contact half kick of the inner step before
    # Out:
    velocity_inout: wp.array(dtype=wp.vec3d),
    omega_inout: wp.array(dtype=wp.vec3d),
    work_inout: wp.array(dtype=Work),
):
    """A gravity half kick of K dt / 2; with ``close_step`` first ``kick`` (which closes an outer step)."""
    i = wp.tid()
    motion = load_motion(i, velocity_inout, omega_inout, work_inout)
    if close_step:
        motion = half_kick(i, wp.float64(0.5) * dt, mass_in, inertia_in, force_in, torque_in, channels_in, motion)
    motion = gravity_half_kick(i, wp.float64(0.5) * outer_dt, mass_in, gravity_in, work_inout.shape[0] > 0, motion)
    store_motion(motion, i, velocity_inout, omega_inout, work_inout)


@wp.kernel
def kick_drift_inner(
    # Model:
    dt: wp.float64,
    outer_dt: wp.float64,  # K dt
    G: wp.float64,
    radius_in: wp.array(dtype=wp.float64),
    mass_in: wp.array(dtype=wp.float64),
    inertia_in: wp.array(dtype=wp.float64),
    system_in: wp.array(dtype=wp.int32),  # per particle: its system (of an ensemble)
    half_skin: wp.float64,  # half the neighbour list's skin
    # In:
    force_in: wp.array(dtype=wp.vec3d),  # the contact force
    torque_in: wp.array(dtype=wp.vec3d),
    channels_in: wp.array2d(dtype=wp.vec3d),  # (N, 4) with the ledger, else empty
    gravity_in: wp.array(dtype=wp.vec3d),
    close_step: bool,  # first the last contact half kick of the step before
    gravity_kicks: int,  # then gravity half kicks: 1 opens an outer step, 2 also closes the one before
    reference_in: wp.array(dtype=wp.vec3d),  # the positions of the neighbour list's build
    # Out:
    position_inout: wp.array(dtype=wp.vec3d),
    velocity_inout: wp.array(dtype=wp.vec3d),
    omega_inout: wp.array(dtype=wp.vec3d),
    work_inout: wp.array(dtype=Work),
    stale_out: wp.array(dtype=wp.int32),  # [0] = 1 when a particle is now past skin / 2 from its build position
    stale_system_out: wp.array(dtype=wp.int32),  # [s] = 1 when one of system s's particles is
    body_out: wp.array(dtype=Any),  # the gravity sweep's packed bodies (the last inner step), or empty
):
    """A contact half kick, then a full drift, as ``kick_drift``; before them the kicks it closes and
    opens, after them the neighbour list's displacement check (kernels/neighbours.py)."""
    i = wp.tid()
    half_dt = wp.float64(0.5) * dt
    motion = load_motion(i, velocity_inout, omega_inout, work_inout)
    if close_step:
        motion = half_kick(i, half_dt, mass_in, inertia_in, force_in, torque_in, channels_in, motion)
    for _ in range(gravity_kicks):
        motion = gravity_half_kick(i, wp.float64(0.5) * outer_dt, mass_in, gravity_in, work_inout.shape[0] > 0, motion)
    motion = half_kick(i, half_dt, mass_in, inertia_in, force_in, torque_in, channels_in, motion)
    store_motion(motion, i, velocity_inout, omega_inout, work_inout)
    position = position_inout[i] + dt * motion.velocity
    position_inout[i] = position
    moved = position - reference_in[i]
    if wp.dot(moved, moved) > half_skin * half_skin:
        stale_out[0] = 1  # every writer writes 1: no race on the value
        stale_system_out[system_in[i]] = 1
    if body_out.shape[0] > 0:
        pack_body(G, radius_in[i], mass_in[i], position, body_out, i)


#: ``kick_drift_inner`` per precision (the type of its packed bodies).
KICK_DRIFT_INNER = body_overloads(kick_drift_inner)

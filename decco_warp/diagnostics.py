"""Conserved and dissipated quantities of a state (float64)."""

from __future__ import annotations

import numpy as np

from .engine import Engine
from .params import Params
from .state import State


def diagnostics(state: State, params: Params, device: str | None = None) -> dict:
    """Energies [erg], momentum [g cm/s] and angular momentum [g cm^2/s] of ``state``.

    Keys: kinetic_translational, kinetic_rotational, potential (sum over pairs
    of -G m_i m_j / d), elastic (sum over contacts of (k/4) delta^2, with k the
    spring the force kernel would use now), total_energy, momentum (3,),
    angular_momentum (3,) about the origin, orbital (sum m x cross v) plus spin
    (sum I w), number_of_contacts and max_overlap [cm].
    """
    pairs = Engine(state, params, device, force_kernel="reference").pair_observables()
    masses, inertia = state.masses, state.inertia
    kinetic_translational = 0.5 * float(np.sum(masses * np.einsum("ij,ij->i", state.velocities, state.velocities)))
    kinetic_rotational = 0.5 * float(np.sum(inertia * np.einsum("ij,ij->i", state.omegas, state.omegas)))
    potential = float(pairs["potential"].sum())
    elastic = float(pairs["elastic"].sum())
    momentum = (masses[:, None] * state.velocities).sum(axis=0)
    orbital = (masses[:, None] * np.cross(state.positions, state.velocities)).sum(axis=0)
    spin = (inertia[:, None] * state.omegas).sum(axis=0)
    return {
        "kinetic_translational": kinetic_translational,
        "kinetic_rotational": kinetic_rotational,
        "potential": potential,
        "elastic": elastic,
        "total_energy": kinetic_translational + kinetic_rotational + potential + elastic,
        "momentum": momentum,
        "angular_momentum": orbital + spin,
        "number_of_contacts": int(pairs["contacts"].sum()) // 2,
        "max_overlap": float(pairs["max_overlap"].max()),
    }

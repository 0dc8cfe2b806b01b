"""The device arrays of a particle system, in two parts as MuJoCo Warp and Newton keep them: what
does not change while it steps (:class:`ModelArrays`: radii, masses, which system a particle is in,
the contact constants) and what does (:class:`StateArrays`: positions, velocities, spins, the last
forces and the ledger).  The gravity solvers, contact finders, contact passes and integrators of
decco_warp/{gravity_solvers,contact_finders,forces,integrators}.py read these two, and nothing else
of the engine.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import warp as wp

from .errors import InputError
from .kernels.contacts import CANDIDATES, LEDGER_CHANNELS
from .kernels.pair import ContactModel
from .params import Params
from .sizes import contact_list_rule
from .state import State


#: Per-particle outputs of kernels/observables.py, in the kernel's order.
PAIR_OBSERVABLES = {
    "potential": wp.float64,
    "elastic": wp.float64,
    "contacts": wp.int32,
    "max_overlap": wp.float64,
    "overlap_depth": wp.float64,
    "overlap_partner": wp.int32,
}


def candidate_width(min_radius: float, max_radius: float) -> int:
    """Contact candidates a particle's list holds on the paths that list them (the Newton layout, the
    tree, the neighbour list of gravity on its own clock): CANDIDATES, or more for a wide size range
    (sizes.contact_list_rule of the radius ratio), so that a large grain among many small ones does
    not overflow into a walk over its whole system."""
    return max(CANDIDATES, contact_list_rule(max_radius / min_radius))


def system_sizes(systems: Sequence[int] | None, count: int) -> np.ndarray:
    """The sizes of an ensemble's systems, checked against the particle count (None: one system)."""
    sizes = np.array([count] if systems is None else list(systems), dtype=np.int64)
    if sizes.ndim != 1 or len(sizes) == 0 or (sizes <= 0).any() or sizes.sum() != count:
        raise InputError(f"systems must be positive sizes adding up to the {count} particles; got {list(sizes)}")
    return sizes


def contact_model(params: Params) -> ContactModel:
    """The constants every force kernel reads, as the kernels' struct."""
    model = ContactModel()
    model.G = wp.float64(params.G)
    model.k_in = wp.float64(params.k_in)
    model.k_out = wp.float64(params.k_out)
    model.mu_k = wp.float64(params.mu_k)
    model.mu_r = wp.float64(params.mu_r)
    return model


class ModelArrays:
    """What stays fixed while a system steps, on its device: per particle its radius, mass, moment of
    inertia and system; the systems' bounds; the constants of the model."""

    def __init__(self, state: State, params: Params, device: str, precision: str, systems: Sequence[int] | None, candidate_width: int):
        self.device = device
        self.params = params
        self.count = state.n
        self.systems = system_sizes(systems, self.count)
        """Sizes of the systems laid one after another (an ensemble; one system: [N])."""
        self.ends = np.cumsum(self.systems)
        self.starts = self.ends - self.systems
        self.contact = contact_model(params)
        """The constants of the pair laws (kernels/pair.py ContactModel)."""
        self.radius = wp.array(state.radii, dtype=wp.float64, device=device)
        self.mass = wp.array(state.masses, dtype=wp.float64, device=device)
        self.inertia = wp.array(state.inertia, dtype=wp.float64, device=device)
        ranges = np.repeat(np.stack([self.starts, self.ends], axis=1), self.systems, axis=0).astype(np.int32)
        self.ranges = wp.array(ranges, dtype=wp.vec2i, device=device)
        """Per particle: its system's particles, [first, end)."""
        self.max_radius = float(state.radii.max())
        self.min_radius = float(state.radii.min())
        # The sweeps' per-i contact bound, in their arithmetic (float32 rounding of the largest
        # radius is no smaller than that of any other radius, so the bound holds).
        self.sweep_max_radius = (wp.float32 if precision == "mixed" else wp.float64)(self.max_radius)
        self.candidate_width = candidate_width
        """Contact candidates a particle's list holds on the paths that list them."""


class StateArrays:
    """What changes as a system steps, on its device: positions, velocities and spins, the forces of
    the last evaluation and, with the ledger, their channels and work."""

    def __init__(self, state: State, device: str, ledger: bool):
        count = state.n
        self.ledger = ledger
        self.position = wp.array(state.positions, dtype=wp.vec3d, device=device)
        self.velocity = wp.array(state.velocities, dtype=wp.vec3d, device=device)
        self.omega = wp.array(state.omegas, dtype=wp.vec3d, device=device)
        self.force = wp.zeros(count, dtype=wp.vec3d, device=device)
        """The last evaluated force [dyne] (with gravity on its own clock, the contact force alone)."""
        self.torque = wp.zeros(count, dtype=wp.vec3d, device=device)
        # Energy ledger (kernels/integrate.py): contact channels of the last force evaluation, and the
        # work of each channel since the start, per particle (no rows without the ledger).
        rows = count if ledger else 0
        self.channels = wp.zeros((rows, len(LEDGER_CHANNELS)), dtype=wp.vec3d, device=device)
        self.work = wp.zeros(rows, dtype=wp.vec4d, device=device)
        # Each particle's deepest contact met by any force evaluation since the host last took it
        # (kernels/contacts.py note_depth): frames report the peak between them, not a sample.
        self.deepest_contact = wp.zeros(count, dtype=wp.int64, device=device)

    def contact_outputs(self) -> list:
        """What a contact evaluation writes: force, torque, channels, deepest contact."""
        return [self.force, self.torque, self.channels, self.deepest_contact]

    def contact_inputs(self) -> list:
        """What a contact pass reads of the particles beside their radii: position, velocity, spin."""
        return [self.position, self.velocity, self.omega]

"""The device arrays of a particle system, in two parts as MuJoCo Warp and Newton keep them: what
does not change while it steps (:class:`ModelArrays`: radii, masses, which system a particle is in,
the contact constants) and what does (:class:`StateArrays`: positions, velocities, spins, the last
forces and the ledger).  The gravity solvers, contact finders, contact passes and integrators of
decco_warp/{gravity_solvers,contact_finders,forces,integrators}.py read these two, and nothing else
of the engine.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import warp as wp

from .errors import InputError
from .kernels.channels import LEDGER_CHANNELS
from .kernels.contacts import CANDIDATES, PairHistory, copy_springs
from .kernels.integrate import Work
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


def damping_factor(restitution: float, stiffness: float) -> float:
    """A dashpot per sqrt(reduced mass) that gives a linear spring of ``stiffness`` that restitution:
    -2 ln(eps) sqrt(k / (pi^2 + ln^2 eps)) [g^1/2 s^-1] (Schwartz, Richardson & Michel 2012 eq. 15)."""
    log = math.log(restitution)
    return -2.0 * log * math.sqrt(stiffness / (math.pi**2 + log * log))


def contact_model(params: Params) -> ContactModel:
    """The constants every force kernel reads, as the kernels' struct."""
    model = ContactModel()
    model.G = wp.float64(params.G)
    model.k_in = wp.float64(params.k_in)
    model.k_out = wp.float64(params.k_out)
    model.mu_k = wp.float64(params.mu_k)
    model.mu_r = wp.float64(params.mu_r)
    if params.contact_law == "ssdem":
        # The elastic energy of the observables, (k/4) delta^2 with k = k_in on either side of the
        # pair, is then ssdem's k_n delta^2 / 2 whether the pair approaches or recedes.
        model.k_out = wp.float64(params.k_in)
        model.k_n = wp.float64(params.k_n)
        model.k_t = wp.float64(params.k_t)
        model.damping_n = wp.float64(damping_factor(params.restitution, params.k_n))
        model.damping_t = wp.float64(damping_factor(params.eps_t, params.k_t))
        model.mu_s = wp.float64(params.mu_s)
        model.mu_t = wp.float64(params.mu_t)
        model.beta = wp.float64(params.beta)
        model.cohesion = wp.float64(params.cohesion)
        model.dt = wp.float64(params.dt)
    return model


#: The snapshot keys of a contact history (ContactHistory.arrays), per particle: its contacts' count,
#: and per contact the partner and the springs.
HISTORY_ARRAYS = ("contact_count", "contact_partner", "contact_spring", "contact_normal", "contact_rolling", "contact_twist")


def pair_history(count: int, width: int, device: str) -> PairHistory:
    """A PairHistory of ``count`` particles with ``width`` rows each, zeroed."""
    history = PairHistory()
    history.count = wp.zeros(count, dtype=wp.int32, device=device)
    history.partner = wp.zeros((count, width), dtype=wp.int32, device=device)
    history.spring = wp.zeros((count, width), dtype=wp.vec3d, device=device)
    history.normal = wp.zeros((count, width), dtype=wp.vec3d, device=device)
    history.rolling = wp.zeros((count, width), dtype=wp.vec3d, device=device)
    history.twist = wp.zeros((count, width), dtype=wp.float64, device=device)
    return history


def history_arrays(count: np.ndarray, rows: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Contact histories as a snapshot holds them (host copies): ``count`` per particle and its rows
    (HISTORY_ARRAYS' columns), as many columns as the most contacts use (at least one); the rows past
    a particle's count, left from earlier evaluations and never read, zeros."""
    width = next(iter(rows.values())).shape[1]
    used = max(1, int(min(count.max(initial=0), width)))
    live = np.arange(used)[None, :] < np.minimum(count, width)[:, None]
    return {"contact_count": count, **{key: np.where(live.reshape(live.shape + (1,) * (values.ndim - 2)), values[:, :used], 0).astype(values.dtype)
                                       for key, values in rows.items()}}  # fmt: skip


class ContactHistory:
    """Each particle's contacts with pair identity (the partner's index) and the pair's springs, for a
    contact law that keeps springs (params.Params.keeps_springs; kernels/contacts.py PairHistory):
    ``current`` holds the last contact evaluation's, which the next reads while writing ``next``;
    :meth:`commit` then makes those current.  Keyed by partner, a contact's springs are carried
    across any rebuild of the candidate lists; a pair that stops touching is dropped.  ``width``
    rows a particle (0: none kept, the arrays empty).

    The two are one pair of buffers whose roles swap at each commit (no copy: the copy was a sixth of
    an ssdem step at K = 10).  ``current`` and ``next`` are therefore looked up at each use, never
    kept: a launch takes them as they are when it is made.  A recorded graph (simulation.py) holds
    the buffers its launches were recorded with, so it must begin and end with the roles it was
    recorded with: :attr:`flipped` says which way round they are, :meth:`settle` turns them."""

    def __init__(self, count: int, width: int, device: str):
        self.count, self.width, self.device = count, width, device
        rows = count if width > 0 else 0
        self._buffers = (pair_history(rows, width, device), pair_history(rows, width, device))
        self.flipped = False
        """Whether the second buffer is the current one."""

    @property
    def current(self) -> PairHistory:
        """The rows of the last contact evaluation (what the next one reads)."""
        return self._buffers[self.flipped]

    @property
    def next(self) -> PairHistory:
        """The rows the next contact evaluation writes."""
        return self._buffers[not self.flipped]

    @property
    def kept(self) -> bool:
        return self.width > 0

    def commit(self) -> None:
        """The rows the last contact evaluation wrote become the current ones: the buffers swap roles
        (no-op where none are kept).  The rows of ``next`` are then those of two evaluations ago, past
        each particle's count never read (the evaluation writes every count and the rows below it)."""
        if self.kept:
            self.flipped = not self.flipped

    def settle(self, flipped: bool) -> None:
        """Turn the roles to ``flipped`` (a recorded graph's), the current rows copied into the other
        buffer if they are the other way round (one launch of ``copy_springs``): the same rows,
        the same bits, in the buffer the graph reads."""
        if self.kept and self.flipped != flipped:
            wp.launch(copy_springs, dim=(self.count, self.width), inputs=[self.current], outputs=[self.next], device=self.device)
            self.flipped = flipped

    def overflows(self, first: int = 0, end: int | None = None) -> int:
        """Particles (of rows [first, end)) with more contacts than rows at the last evaluation: the springs
        of those past the rows were not kept (they start afresh at each step)."""
        if not self.kept:
            return 0
        return int((self.current.count.numpy()[first:end] > self.width).sum())

    def arrays(self) -> dict[str, np.ndarray]:
        """The rows as a snapshot holds them (host copies), as many columns as the most contacts use
        (at least one); none where none are kept."""
        if not self.kept:
            return {}
        h = self.current
        columns = (h.partner, h.spring, h.normal, h.rolling, h.twist)
        return history_arrays(h.count.numpy().copy(), {key: array.numpy() for key, array in zip(HISTORY_ARRAYS[1:], columns)})

    def load(self, arrays: dict[str, np.ndarray]) -> None:
        """Rows from :meth:`arrays` (InputError for a snapshot without them, or of other shapes)."""
        if not self.kept:
            return
        missing = [key for key in HISTORY_ARRAYS if key not in arrays]
        if missing:
            raise InputError(f"snapshot holds no contact history ({', '.join(missing)}): a law with springs per pair needs it to go on")
        n = self.count
        count = np.asarray(arrays["contact_count"], dtype=np.int32)
        used = np.asarray(arrays["contact_partner"]).shape[1] if np.ndim(arrays["contact_partner"]) == 2 else -1
        if count.shape != (n,) or not 0 < used <= self.width:
            raise InputError(f"snapshot contact history has shapes {count.shape}, {np.shape(arrays['contact_partner'])}; "
                             f"expected ({n},), ({n}, <= {self.width})")  # fmt: skip
        h = self.current
        h.count.assign(wp.array(count, dtype=wp.int32, device=self.device))
        for key, target, dtype, tail in zip(
            HISTORY_ARRAYS[1:], (h.partner, h.spring, h.normal, h.rolling, h.twist),
            (np.int32, np.float64, np.float64, np.float64, np.float64), ((), (3,), (3,), (3,), ()),
        ):  # fmt: skip
            values = np.asarray(arrays[key], dtype=dtype)
            if values.shape != (n, used, *tail):
                raise InputError(f"snapshot {key} has shape {values.shape}; expected {(n, used, *tail)}")
            rows = np.zeros((n, self.width, *tail), dtype=dtype)
            rows[:, :used] = values
            target.assign(wp.array(rows, dtype=target.dtype, device=self.device))

    def spring_energies(self, radii: np.ndarray, params: Params) -> tuple[np.ndarray, np.ndarray]:
        """Per particle, half the energy held in its contacts' springs [erg]: the tangential spring's
        (k_t |S|^2 / 2 a pair), and the rolling and twisting springs' (k_r |theta_r|^2 / 2 +
        k_q theta_t^2 / 2, k_r = k_n R_r^2, k_q = 2 k_t R_r^2); zeros where none are kept."""
        if not self.kept:
            return np.zeros(self.count), np.zeros(self.count)
        h = self.current
        count = h.count.numpy()
        used = np.arange(self.width)[None, :] < np.minimum(count, self.width)[:, None]
        partner = np.where(used, h.partner.numpy(), 0)
        spring, rolling, twist = h.spring.numpy(), h.rolling.numpy(), h.twist.numpy()
        other = radii[partner]
        radius_r = params.beta * radii[:, None] * other / (radii[:, None] + other)
        tangential = 0.25 * params.k_t * np.einsum("ijk,ijk->ij", spring, spring)
        turning = 0.25 * radius_r**2 * (params.k_n * np.einsum("ijk,ijk->ij", rolling, rolling) + 2.0 * params.k_t * twist**2)
        return np.where(used, tangential, 0.0).sum(axis=1), np.where(used, turning, 0.0).sum(axis=1)


class ModelArrays:
    """What stays fixed while a system steps, on its device: per particle its radius, mass, moment of
    inertia and system; the systems' bounds; the constants of the model."""

    def __init__(self, state: State, params: Params, device: str, precision: str, systems: Sequence[int] | None):
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
        self.candidate_width = candidate_width(self.min_radius, self.max_radius)
        """Contact candidates a particle's list holds on the paths that list them."""


class StateArrays:
    """What changes as a system steps, on its device: positions, velocities and spins, the forces of
    the last evaluation and, with the ledger, their channels and work."""

    def __init__(self, state: State, device: str, ledger: bool, history_width: int = 0):
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
        self.work = wp.zeros(rows, dtype=Work, device=device)
        # Each particle's deepest contact met by any force evaluation since the host last took it
        # (kernels/contacts.py note_depth): frames report the peak between them, not a sample.
        self.deepest_contact = wp.zeros(count, dtype=wp.int64, device=device)
        self.history = ContactHistory(count, history_width, device)
        """Each particle's contacts and their springs, for a law that keeps springs per pair (else empty)."""

    def contact_outputs(self) -> list:
        """What a contact evaluation writes: force, torque, channels, deepest contact, the contacts' springs."""
        return [self.force, self.torque, self.channels, self.deepest_contact, self.history.next]

    def contact_inputs(self) -> list:
        """What a contact evaluation reads of the particles beside their radii and masses: position,
        velocity, spin and the contacts' springs at the evaluation before."""
        return [self.position, self.velocity, self.omega, self.history.current]

"""Particle state on the host: NumPy float64 arrays in cgs."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field, replace

import numpy as np

from .errors import InputError


@dataclass
class State:
    """The particles of a run at one instant.

    >>> s = State.from_arrays(x, v, w, radii, masses)
    >>> sim = Simulation(s, Params()); sim.step(10); s = sim.state
    """

    positions: np.ndarray
    """Centres x_i [cm], (N, 3) float64."""
    velocities: np.ndarray
    """Velocities v_i [cm/s], (N, 3) float64."""
    omegas: np.ndarray
    """Angular velocities w_i [rad/s], (N, 3) float64."""
    radii: np.ndarray
    """Radii R_i [cm], (N,) float64."""
    masses: np.ndarray
    """Masses m_i [g], (N,) float64."""
    pile_id: np.ndarray = field(default=None)
    """Which pile a particle started in (0 target, 1 projectile), (N,) int32."""
    size_class: np.ndarray = field(default=None)
    """Index of the particle's size class (0 smallest), (N,) int32."""
    time: float = 0.0
    """Simulated time [s]."""
    step: int = 0
    """Number of steps taken since the run began."""
    metadata: dict = field(default_factory=dict)
    """What made this state (pile formation, collision set-up): plain numbers, strings and arrays."""

    @classmethod
    def from_arrays(
        cls,
        positions,
        velocities,
        omegas,
        radii,
        masses,
        pile_id=None,
        size_class=None,
        time: float = 0.0,
        step: int = 0,
        metadata: dict | None = None,
    ) -> "State":
        """Copy and check arrays into a State; raises ValueError naming the bad input."""
        radii = _float_array("radii", radii, None)
        n = radii.shape[0]
        if n == 0:
            raise InputError("a State needs at least one particle")
        state = cls(
            positions=_float_array("positions", positions, (n, 3)),
            velocities=_float_array("velocities", velocities, (n, 3)),
            omegas=_float_array("omegas", omegas, (n, 3)),
            radii=radii,
            masses=_float_array("masses", masses, (n,)),
            pile_id=_int_array("pile_id", pile_id, n),
            size_class=_int_array("size_class", size_class, n),
            time=float(time),
            step=int(step),
            metadata=copy.deepcopy(metadata) if metadata else {},
        )
        for name in ("radii", "masses"):
            values = getattr(state, name)
            bad = np.flatnonzero(values <= 0)
            if bad.size:
                raise InputError(f"{name} must be > 0; particle {bad[0]} has {values[bad[0]]!r}")
        return state

    @property
    def n(self) -> int:
        """Number of particles."""
        return self.radii.shape[0]

    @property
    def inertia(self) -> np.ndarray:
        """Moments of inertia I_i = 2/5 m_i R_i^2 [g cm^2], (N,)."""
        return 0.4 * self.masses * self.radii**2

    @property
    def total_mass(self) -> float:
        return float(self.masses.sum())

    @property
    def centre_of_mass(self) -> np.ndarray:
        """Mass-weighted mean position [cm], (3,)."""
        return (self.masses[:, None] * self.positions).sum(axis=0) / self.total_mass

    @property
    def bulk_velocity(self) -> np.ndarray:
        """Velocity of the centre of mass [cm/s], (3,)."""
        return (self.masses[:, None] * self.velocities).sum(axis=0) / self.total_mass

    def inertia_tensor(self) -> np.ndarray:
        """Moment of inertia tensor about the centre of mass [g cm^2], (3, 3): the particles' orbital
        part plus their own moments of inertia."""
        x = self.positions - self.centre_of_mass
        m = self.masses
        r2 = (x * x).sum(axis=1)
        return ((m * r2).sum() + self.inertia.sum()) * np.eye(3) - np.einsum("i,ij,ik->jk", m, x, x)

    def spin(self) -> np.ndarray:
        """Rigid-body angular velocity about the centre of mass [rad/s], (3,): I^-1 L.

        L and I both include the particles' own spins and moments of inertia.
        """
        x = self.positions - self.centre_of_mass
        v = self.velocities - self.bulk_velocity
        angular_momentum = (self.masses[:, None] * np.cross(x, v)).sum(axis=0) + (self.inertia[:, None] * self.omegas).sum(axis=0)
        if self.n == 1:
            return self.omegas[0].copy()
        return np.linalg.solve(self.inertia_tensor(), angular_momentum)

    def copy(self) -> "State":
        arrays = ("positions", "velocities", "omegas", "radii", "masses", "pile_id", "size_class")
        return replace(self, **{name: getattr(self, name).copy() for name in arrays}, metadata=copy.deepcopy(self.metadata))

    def subset(self, mask) -> "State":
        """The particles selected by a boolean mask or index array (a copy)."""
        arrays = ("positions", "velocities", "omegas", "radii", "masses", "pile_id", "size_class")
        return replace(self, **{name: getattr(self, name)[mask].copy() for name in arrays}, metadata={})


def remove_net_motion(state: State) -> State:
    """Centre the pile and remove its net momentum and rigid spin (orbital plus particle spins).

    The spin removed is omega = I_pile^-1 L about the centre of mass, with I_pile
    including the particles' own moments of inertia; afterwards the total
    angular momentum about the centre is zero to round-off.
    """
    state = state.copy()
    spin = state.spin()
    state.positions -= state.centre_of_mass
    state.velocities -= state.bulk_velocity
    state.velocities -= np.cross(spin, state.positions)
    state.omegas -= spin
    return state


def _float_array(name: str, values, shape) -> np.ndarray:
    try:
        array = np.array(values, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as error:
        raise InputError(f"{name} must be numeric: {error}") from None
    expected = shape if shape is not None else (array.shape[0],) if array.ndim == 1 else None
    if expected is None or array.shape != expected:
        want = "(N,)" if shape is None else str(shape)
        raise InputError(f"{name} must have shape {want}; got {array.shape}")
    bad = np.flatnonzero(~np.isfinite(array).reshape(max(array.shape[0], 1), -1).all(axis=1))
    if bad.size:
        raise InputError(f"{name} must be finite; particle {bad[0]} has {array[bad[0]]!r}")
    return array


def _int_array(name: str, values, n: int) -> np.ndarray:
    if values is None:
        return np.zeros(n, dtype=np.int32)
    array = np.asarray(values)
    if array.shape != (n,) or not np.issubdtype(array.dtype, np.integer):
        raise InputError(f"{name} must be an integer array of shape ({n},); got {array.dtype} {array.shape}")
    return array.astype(np.int32, copy=True)

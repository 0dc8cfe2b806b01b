"""Collision set-up (paper sect. 3.1 and 4.2, docs/model.md).

The target (the more massive pile) sits ahead of the projectile along +x; the
projectile's centre is offset by the impact parameter b = (R_p + R_t) sin(theta)
along +y and starts with its bounding sphere ``gap`` short of the target's along
x.  Everything is in the centre-of-mass frame, with the centre of mass at the
origin and the relative velocity along +x (the projectile moves towards +x).
"""

from __future__ import annotations

import math

import numpy as np

from .diagnostics import diagnostics
from .params import G_CGS, Params
from .state import State
from .errors import InputError

#: What eta = KE / |U| (paper eq. 18) takes as U: "self" sums each pile's own pairs (the default,
#: and the reading of every committed run); "all" sums every pair of both piles at set-up, the
#: cross term between the piles included (docs/model.md).
ETA_POTENTIALS = ("self", "all")

SPIN_AXES = {
    "+x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}


def pile_radius(state: State) -> float:
    """Largest |x_k - x_cm| + R_k over the pile's particles [cm] (docs/model.md)."""
    return float((np.linalg.norm(state.positions - state.centre_of_mass, axis=1) + state.radii).max())


def breakup_spin(state: State, G: float = G_CGS) -> float:
    """sqrt(G M / R^3): the angular velocity at which the pile's surface would orbit [rad/s]."""
    return math.sqrt(G * state.total_mass / pile_radius(state) ** 3)


def random_rotations(seed: int, count: int = 2) -> np.ndarray:
    """``count`` rotation matrices drawn uniformly over all rotations (the Haar measure) from ``seed``,
    in order: the same seed always gives the same rotations, on any machine.

    A unit quaternion with four independent normal components is uniform on the 3-sphere, and so
    its rotation is uniform over SO(3) (Shoemake 1992)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise InputError(f"orientation_seed must be an integer >= 0; got {seed!r}")
    quaternions = np.random.default_rng(int(seed)).standard_normal((count, 4))
    w, x, y, z = (quaternions / np.linalg.norm(quaternions, axis=1, keepdims=True)).T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


def rotate_pile(state: State, rotation: np.ndarray) -> State:
    """A copy of ``state`` turned rigidly about its centre of mass by the 3x3 ``rotation``: positions
    about the centre, velocities about the bulk velocity, and spins."""
    turned = state.copy()
    centre, bulk = state.centre_of_mass, state.bulk_velocity
    turned.positions = centre + (state.positions - centre) @ rotation.T
    turned.velocities = bulk + (state.velocities - bulk) @ rotation.T
    turned.omegas = state.omegas @ rotation.T
    return turned


def spin_axis(axis, what: str = "spin axis") -> np.ndarray:
    """The unit vector of a spin axis: one of SPIN_AXES by name ("+z"), or any vector of three
    finite numbers, not all zero (normalised here)."""
    if isinstance(axis, str):
        if axis not in SPIN_AXES:
            raise InputError(f"{what} must be one of {', '.join(SPIN_AXES)} or a vector of three numbers; got {axis!r}")
        return np.array(SPIN_AXES[axis])
    try:
        vector = np.array([float(c) for c in axis]) if not isinstance(axis, bool) and len(axis) == 3 else None
    except (TypeError, ValueError):
        vector = None
    if vector is None or not np.isfinite(vector).all() or not np.linalg.norm(vector) > 0:
        raise InputError(f"{what} must be one of {', '.join(SPIN_AXES)} or a vector of three numbers, not all zero; got {axis!r}")
    return vector / np.linalg.norm(vector)


def _spin_vector(spin, state: State, G: float, which: str) -> np.ndarray | None:
    if spin is None:
        return None
    try:
        fraction, axis = spin
    except (TypeError, ValueError):
        raise InputError(f"{which}_spin must be (fraction, axis), e.g. (0.5, '+z'); got {spin!r}") from None
    if isinstance(fraction, bool) or not isinstance(fraction, (int, float)) or not 0 <= fraction <= 1:
        raise InputError(f"{which}_spin fraction of breakup must be in [0, 1]; got {fraction!r}")
    return fraction * breakup_spin(state, G) * spin_axis(axis, f"{which}_spin axis")


#: The impact angle when none is given, here and in a run specification [degrees]: the paper's
#: oblique collision of Fig. 8 (the shipped default collision, runs/default.toml).
DEFAULT_THETA_DEG = 22.0


def setup_collision(
    target: State,
    projectile: State,
    eta: float | None = None,
    theta_deg: float = DEFAULT_THETA_DEG,
    gap: float = 1e5,
    target_spin=None,
    projectile_spin=None,
    speed: float | None = None,
    G: float = G_CGS,
    device: str | None = None,
    orientation_seed: int | None = None,
    eta_potential: str = "self",
) -> State:
    """Both piles in the centre-of-mass frame, set to collide.

    ``eta`` = KE / |U| (paper eq. 18): KE is the translational kinetic energy of
    the two piles' centres, U the sum of their self-potential energies (``eta_potential``
    "self"), or the potential of all pairs of both piles at set-up, the cross term included
    ("all"; :data:`ETA_POTENTIALS`).  Give
    either ``eta`` or ``speed`` (the relative speed [cm/s]).  ``theta_deg`` is
    the impact angle, ``gap`` [cm] the initial surface separation along x, and a
    spin is (fraction of breakup, axis) with axis one of +x, -x, +y, -y, +z, -z or
    any vector (x along the velocity, y towards the impact parameter).
    ``orientation_seed`` turns each pile about its centre of mass by a random rotation, uniform
    over all rotations and drawn from the seed (:func:`random_rotations`: the target's first),
    before anything else: a realization of the same collision (docs/model.md).  None keeps the
    piles as their files hold them.

    The result has ``pile_id`` 0 (target) and 1 (projectile), and ``metadata``
    holding eta (in the reading asked for), eta_potential, eta_self and eta_all (both readings),
    speed, b, both radii and masses, KE, both self-potentials and the cross term at t = 0, and
    the spins' motion at the first contact point (:func:`first_contact_motion`).

    >>> s = setup_collision(target, projectile, eta=2.0, theta_deg=22.0, gap=1e5,
    ...                     target_spin=None, projectile_spin=(0.5, "+z"))
    """
    if (eta is None) == (speed is None):
        raise InputError("give exactly one of eta (KE/|U|) or speed (relative speed in cm/s)")
    if eta is not None and not (_is_number(eta) and eta > 0):
        raise InputError(f"eta must be > 0; got {eta!r}")
    if speed is not None and not (_is_number(speed) and speed > 0):
        raise InputError(f"speed must be > 0 cm/s; got {speed!r}")
    if not (_is_number(theta_deg) and 0 <= theta_deg < 90):
        raise InputError(f"theta_deg must be in [0, 90); got {theta_deg!r}")
    if not (_is_number(gap) and gap >= 0):
        raise InputError(f"gap must be >= 0 cm; got {gap!r}")
    if eta_potential not in ETA_POTENTIALS:
        raise InputError(f"eta_potential must be one of {', '.join(ETA_POTENTIALS)}; got {eta_potential!r}")
    if projectile.total_mass > target.total_mass:
        raise InputError(
            f"the target must be the more massive pile: target {target.total_mass:.4g} g < "
            f"projectile {projectile.total_mass:.4g} g; swap them"
        )
    rotations = None if orientation_seed is None else random_rotations(orientation_seed)
    if rotations is not None:  # turned as the files hold them, before spins (along fixed axes) are given
        target, projectile = rotate_pile(target, rotations[0]), rotate_pile(projectile, rotations[1])
    target_spin_vector = _spin_vector(target_spin, target, G, "target")
    projectile_spin_vector = _spin_vector(projectile_spin, projectile, G, "projectile")

    params = Params(G=G)
    piles = []
    for pile, spin in ((target, target_spin_vector), (projectile, projectile_spin_vector)):
        pile = pile.copy()
        pile.positions -= pile.centre_of_mass
        pile.velocities -= pile.bulk_velocity
        if spin is not None:
            pile.velocities += np.cross(spin, pile.positions)
            pile.omegas[:] = spin
        piles.append(pile)
    target, projectile = piles
    radius_t, radius_p = pile_radius(target), pile_radius(projectile)
    mass_t, mass_p = target.total_mass, projectile.total_mass
    potential_t = diagnostics(target, params, device)["potential"]
    potential_p = diagnostics(projectile, params, device)["potential"]

    reduced_mass = mass_t * mass_p / (mass_t + mass_p)
    theta = math.radians(theta_deg)
    impact_parameter = (radius_t + radius_p) * math.sin(theta)
    separation_x = (radius_t + radius_p) * math.cos(theta) + gap

    # Projectile at (-separation_x, b) relative to the target; then both about the common centre.
    # The places do not depend on the speed, so the cross term (eta_potential "all") is known first.
    offset = np.array([-separation_x, impact_parameter, 0.0])
    target.positions += -mass_p / (mass_t + mass_p) * offset
    projectile.positions += mass_t / (mass_t + mass_p) * offset
    combined = State.from_arrays(
        np.concatenate([target.positions, projectile.positions]),
        np.concatenate([target.velocities, projectile.velocities]),
        np.concatenate([target.omegas, projectile.omegas]),
        np.concatenate([target.radii, projectile.radii]),
        np.concatenate([target.masses, projectile.masses]),
        pile_id=np.repeat(np.array([0, 1], dtype=np.int32), [target.n, projectile.n]),
        size_class=np.concatenate([target.size_class, projectile.size_class]),
    )
    potential_self = potential_t + potential_p
    potential_all = diagnostics(combined, params, device)["potential"]
    if speed is None:
        potential = potential_self if eta_potential == "self" else potential_all
        speed = math.sqrt(2.0 * eta * abs(potential) / reduced_mass)
    kinetic = 0.5 * reduced_mass * speed**2
    combined.velocities[: target.n, 0] -= speed * mass_p / (mass_t + mass_p)
    combined.velocities[target.n :, 0] += speed * mass_t / (mass_t + mass_p)

    eta_self, eta_all = kinetic / abs(potential_self), kinetic / abs(potential_all)
    combined.metadata = {
        "eta": eta_self if eta_potential == "self" else eta_all,
        "eta_potential": eta_potential,
        "eta_self": eta_self,
        "eta_all": eta_all,
        "speed": speed,
        "theta_deg": float(theta_deg),
        "impact_parameter": impact_parameter,
        "gap": float(gap),
        "target_radius": radius_t,
        "projectile_radius": radius_p,
        "target_mass": mass_t,
        "projectile_mass": mass_p,
        "target_spin": np.zeros(3) if target_spin_vector is None else target_spin_vector,
        "projectile_spin": np.zeros(3) if projectile_spin_vector is None else projectile_spin_vector,
        "kinetic_energy": kinetic,
        "target_potential": potential_t,
        "projectile_potential": potential_p,
        "cross_potential": potential_all - potential_self,
    }
    combined.metadata.update(first_contact_motion(combined.metadata))
    if rotations is not None:
        combined.metadata.update(orientation_seed=int(orientation_seed), target_rotation=rotations[0], projectile_rotation=rotations[1])
    return combined


def first_contact_motion(collision: dict) -> dict:
    """How the spins move the two surfaces against each other where the piles first touch.

    The first contact point is where the piles' bounding spheres meet as the projectile arrives
    (direction u from the target's centre to the projectile's: (-cos theta, sin theta, 0)).  There
    the spins alone give the projectile's surface the velocity w_p x (-R_p u) relative to its
    centre, and the target's w_t x (R_t u).  Returns ``contact_surface_speed`` [cm/s], the
    magnitude of their difference (a shear across the contact: parallel spins about z make it
    w (R_t + R_p), anti-parallel ones w |R_t - R_p|), and ``contact_twist_rate`` [rad/s], the
    relative spin about u (a twist of the contact: spins along the velocity, +x with -x).
    ``collision``: the set-up's metadata (spins as vectors [rad/s], radii, theta_deg)."""
    theta = math.radians(collision["theta_deg"])
    u = np.array([-math.cos(theta), math.sin(theta), 0.0])
    target_spin = np.asarray(collision["target_spin"], dtype=float)
    projectile_spin = np.asarray(collision["projectile_spin"], dtype=float)
    slip = np.cross(projectile_spin, -collision["projectile_radius"] * u) - np.cross(target_spin, collision["target_radius"] * u)
    return {
        "contact_surface_speed": float(np.linalg.norm(slip)),
        "contact_twist_rate": float(abs((projectile_spin - target_spin) @ u)),
    }


def _is_number(value) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)

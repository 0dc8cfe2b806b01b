"""Rubble-pile formation (paper sect. 2.6, docs/model.md).

Seed spheres of three sizes (equal total mass per size) uniformly in a sphere
without overlaps, then let the cloud collapse under its own gravity until its
kinetic energy is below ``ke_threshold`` |U|; finally remove the pile's net
momentum and spin and centre it.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .params import Params
from .simulation import Simulation
from .checks import DENSITY_RANGE, RADIUS_RANGE
from .state import State

#: The paper's particle radii [cm] (Table 1) and density [g/cm^3].
PAPER_RADII = (0.75e6, 1.5e6, 2.25e6)
PAPER_DENSITY = 2.7
#: Placement attempts per particle before the seeding sphere grows (docs/model.md).
SEED_TRIES = 200
#: Formation stops once kinetic energy < KE_THRESHOLD |U| (paper: 1e-5).
KE_THRESHOLD = 1e-5
#: ... but only after the collapse: the peak KE/|U| must have reached this first
#: (a cloud seeded at rest starts below any threshold).
COLLAPSE_PEAK = 1e-3


@dataclass
class FormationProgress:
    """What a progress display gets after each check of a forming pile."""

    step: int
    time: float
    ke_over_u: float
    peak_ke_over_u: float
    threshold: float
    elapsed: float

    @property
    def fraction_done(self) -> float:
        """A rough 0..1 measure: the decades KE/|U| has fallen from its peak towards the threshold."""
        if self.peak_ke_over_u < COLLAPSE_PEAK or self.ke_over_u <= 0:
            return 0.0
        total = math.log10(self.peak_ke_over_u / self.threshold)
        fallen = math.log10(self.peak_ke_over_u / max(self.ke_over_u, self.threshold))
        return min(max(fallen / total, 0.0), 1.0)


class FormationError(RuntimeError):
    """A pile that did not settle within the allowed number of steps."""


def size_class_counts(n_particles: int, radii=PAPER_RADII) -> np.ndarray:
    """Particles per size class for equal total mass per class: N_c proportional to R_c^-3.

    Rounded by largest remainder so that the counts add up to ``n_particles``
    (5000 gives 4303, 538, 159).
    """
    radii = np.asarray(radii, dtype=float)
    share = radii**-3 / (radii**-3).sum() * n_particles
    counts = np.floor(share).astype(int)
    for k in np.argsort(-(share - counts), kind="stable")[: n_particles - counts.sum()]:
        counts[k] += 1
    return counts


def seed_cloud(radii: np.ndarray, rng: np.random.Generator, fill: float = 0.3) -> tuple[np.ndarray, float]:
    """Positions of non-overlapping spheres, uniform in a sphere; and that sphere's radius [cm].

    Spheres are placed largest first, each at up to SEED_TRIES random spots; if
    one finds no free spot, the seeding sphere grows by the largest diameter and
    every sphere is placed again.  ``fill`` sets the first sphere's size from the
    spheres' total volume.
    """
    order = np.argsort(-radii, kind="stable")
    seed_radius = ((radii**3).sum() / fill) ** (1.0 / 3.0)
    while True:
        positions = np.empty((radii.size, 3))
        placed = 0
        for k in order:
            room = seed_radius - radii[k]
            for _ in range(SEED_TRIES):
                candidate = _uniform_in_ball(rng, room)
                gaps = np.linalg.norm(positions[order[:placed]] - candidate, axis=1) - radii[order[:placed]] - radii[k]
                if placed == 0 or gaps.min() >= 0.0:
                    positions[k] = candidate
                    placed += 1
                    break
            else:
                break
        if placed == radii.size:
            return positions, seed_radius
        seed_radius += 2.0 * radii.max()


def _uniform_in_ball(rng: np.random.Generator, radius: float) -> np.ndarray:
    while True:
        point = rng.uniform(-1.0, 1.0, size=3)
        if point @ point <= 1.0:
            return radius * point


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


def form_pile(
    n_particles: int = 300,
    seed: int = 1,
    device: str | None = None,
    radii=PAPER_RADII,
    density: float = PAPER_DENSITY,
    params: Params | None = None,
    ke_threshold: float = KE_THRESHOLD,
    fill: float = 0.3,
    check_every: int = 250,
    max_steps: int = 5_000_000,
    precision: str = "mixed",
    progress: Callable[[FormationProgress], None] | None = None,
) -> State:
    """Build a rubble pile: seed, collapse until KE < ke_threshold |U|, remove net motion, centre.

    Deterministic for a given ``seed`` on a given device.  The returned State has
    ``size_class`` (0 = smallest radius) and ``metadata`` with the formation
    history (time, KE/|U|) and the settings used.

    >>> pile = form_pile(n_particles=300, seed=1, device="cpu")
    """
    params = params or Params()
    radii = np.asarray(radii, dtype=float)
    check_formation_inputs(n_particles, radii, density, ke_threshold, fill, check_every, max_steps)
    rng = np.random.default_rng(seed)
    counts = size_class_counts(n_particles, radii)
    size_class = np.repeat(np.arange(radii.size, dtype=np.int32), counts)
    particle_radii = radii[size_class]
    masses = 4.0 / 3.0 * math.pi * density * particle_radii**3
    positions, seed_radius = seed_cloud(particle_radii, rng, fill)
    cloud = State.from_arrays(
        positions, np.zeros_like(positions), np.zeros_like(positions), particle_radii, masses, size_class=size_class
    )
    sim = Simulation(cloud, params, device=device, precision=precision)
    history_time, history_ratio = [0.0], [0.0]
    peak = 0.0
    started = _time.perf_counter()
    while True:
        if sim.step_count >= max_steps:
            raise FormationError(
                f"the pile did not settle within {max_steps} steps: KE/|U| = {history_ratio[-1]:.3g} "
                f"> {ke_threshold:g}; raise max_steps or ke_threshold"
            )
        sim.step(min(check_every, max_steps - sim.step_count))
        state = sim.state
        ratio = _kinetic_over_potential(sim, state)
        peak = max(peak, ratio)
        history_time.append(sim.time)
        history_ratio.append(ratio)
        if progress is not None:
            progress(FormationProgress(sim.step_count, sim.time, ratio, peak, ke_threshold, _time.perf_counter() - started))
        if peak >= COLLAPSE_PEAK and ratio < ke_threshold:
            break
    pile = remove_net_motion(state)
    pile.time, pile.step = 0.0, 0
    settled = sim.diagnostics(pile)
    pile.metadata = {
        "seed": int(seed),
        "n_particles": int(n_particles),
        "size_radii": radii,
        "size_counts": counts,
        "density": float(density),
        "ke_threshold": float(ke_threshold),
        "fill": float(fill),
        "seed_radius": float(seed_radius),
        "formation_steps": int(sim.step_count),
        "formation_time": float(sim.time),
        "formation_wall_seconds": float(_time.perf_counter() - started),
        "device": sim.device,
        "precision": precision,
        "history_time": np.array(history_time),
        "history_ke_over_u": np.array(history_ratio),
        "potential": settled["potential"],
        "params": params.to_dict(),
    }
    return pile


def _kinetic_over_potential(sim: Simulation, state: State) -> float:
    """(Translational + rotational kinetic energy in the centre-of-mass frame) / |U|."""
    d = sim.diagnostics(state)
    bulk = 0.5 * state.total_mass * float(state.bulk_velocity @ state.bulk_velocity)
    kinetic = d["kinetic_translational"] - bulk + d["kinetic_rotational"]
    return kinetic / abs(d["potential"])


def check_formation_inputs(n_particles, radii, density, ke_threshold, fill, check_every=250, max_steps=1) -> None:
    """Raise ValueError naming the first input of :func:`form_pile` that cannot make a pile."""
    radii = np.asarray(radii, dtype=float)
    if isinstance(n_particles, bool) or not isinstance(n_particles, (int, np.integer)) or n_particles < 2:
        raise ValueError(f"n_particles must be an integer >= 2; got {n_particles!r}")
    low, high = RADIUS_RANGE
    if radii.ndim != 1 or radii.size == 0 or not np.all(np.isfinite(radii)) or np.any(radii < low) or np.any(radii > high):
        raise ValueError(f"radii must be sizes from {low:g} to {high:g} cm; got {radii.tolist()}")
    low, high = DENSITY_RANGE
    if not (math.isfinite(density) and low <= density <= high):
        raise ValueError(f"density must be from {low:g} to {high:g} g/cm^3; got {density!r}")
    if not (0 < ke_threshold < COLLAPSE_PEAK):
        raise ValueError(f"ke_threshold must be in (0, {COLLAPSE_PEAK:g}); got {ke_threshold!r}")
    if not (0 < fill < 0.5):
        raise ValueError(f"fill must be in (0, 0.5); got {fill!r}")
    if check_every < 1 or max_steps < 1:
        raise ValueError("check_every and max_steps must be >= 1")

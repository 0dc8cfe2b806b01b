"""Rubble-pile formation (paper sect. 2.6, docs/model.md).

Seed spheres of three sizes (equal total mass per size), or of radii drawn from a power law
(sizes.PowerLaw), uniformly in a sphere without overlaps, then let the cloud collapse under its own
gravity until its kinetic energy is below ``ke_threshold`` |U|; finally remove the pile's net
momentum and spin and centre it.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from .params import Params
from .scheme import Scheme
from .simulation import Simulation
from .checks import DENSITY_RANGE, RADIUS_RANGE
from .sizes import PowerLaw, classify, parse_size_distribution
from .state import State, remove_net_motion
from .errors import FormationError, InputError  # noqa: F401 (re-exported: the error lives in errors.py)

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


def grain_sizes(n_particles: int, seed: int, radii=PAPER_RADII, size_distribution: PowerLaw | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """Each particle's radius [cm] and size class, smallest first, and what the pile file records of
    its sizes: the discrete ``radii`` with equal mass per size (``size_radii``, ``size_counts``), or
    radii drawn from ``size_distribution`` with ``seed`` in its log-R classes (``size_distribution``,
    ``size_class_edges``, ``size_counts``)."""
    if size_distribution is None:
        radii = np.asarray(radii, dtype=float)
        counts = size_class_counts(n_particles, radii)
        size_class = np.repeat(np.arange(radii.size, dtype=np.int32), counts)
        return radii[size_class], size_class, {"size_radii": radii, "size_counts": counts}
    particle_radii = size_distribution.sample(n_particles, seed)
    edges = size_distribution.edges()
    size_class = classify(particle_radii, edges)
    counts = np.bincount(size_class, minlength=size_distribution.classes)
    return particle_radii, size_class, {"size_distribution": size_distribution.text(), "size_class_edges": edges, "size_counts": counts}


def seed_cloud(radii: np.ndarray, rng: np.random.Generator, fill: float = 0.3) -> tuple[np.ndarray, float]:
    """Positions of non-overlapping spheres, uniform in a sphere; and that sphere's radius [cm].

    Spheres are placed largest first, each at up to SEED_TRIES random spots; if
    one finds no free spot, the seeding sphere grows by the largest diameter and
    every sphere is placed again.  ``fill`` sets the first sphere's size from the
    spheres' total volume.  A spot is tested against the spheres already placed in
    the 27 grid cells (of the largest diameter) around it, the only ones it can
    touch: O(N) for the whole cloud, and the same spots as testing every sphere.
    """
    order = np.argsort(-radii, kind="stable")
    seed_radius = ((radii**3).sum() / fill) ** (1.0 / 3.0)
    cell = 2.0 * radii.max()
    while True:
        positions = np.empty((radii.size, 3))
        cells: dict[tuple[int, int, int], list[int]] = {}
        placed = 0
        for k in order:
            room = seed_radius - radii[k]
            for _ in range(SEED_TRIES):
                candidate = _uniform_in_ball(rng, room)
                cx, cy, cz = (int(c) for c in np.floor(candidate / cell))
                near = [j for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1) for j in cells.get((cx + dx, cy + dy, cz + dz), ())]
                if near:
                    gaps = np.linalg.norm(positions[near] - candidate, axis=1) - radii[near] - radii[k]
                if not near or gaps.min() >= 0.0:
                    positions[k] = candidate
                    cells.setdefault((cx, cy, cz), []).append(int(k))
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


class Formation:
    """A pile forming: a seeded cloud collapsing under its own gravity, advanced one check at a time.

    :func:`form_pile` runs one to the end; a caller that keeps long formations safe
    (``decco-warp pile``) saves :meth:`snapshot` now and then and continues from it with
    ``Formation(..., snapshot=...)``: the pile is the same, bit for bit, as one formed without a stop.

    >>> formation = Formation(n_particles=300, seed=1, device="cpu")
    >>> while not formation.settled: formation.advance()
    >>> pile = formation.pile()
    """

    def __init__(
        self,
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
        snapshot: dict | None = None,
        size_distribution: PowerLaw | str | None = None,
        gravity: str = "all-pairs",
    ):
        """``size_distribution``: radii drawn from a power law (a PowerLaw, or its text) instead of
        ``radii``; ``gravity``: the gravity solver (scheme.GRAVITY_SOLVERS)."""
        params = params or Params()
        law = parse_size_distribution(size_distribution) if isinstance(size_distribution, str) else size_distribution
        radii = np.asarray(radii, dtype=float) if law is None else np.array([law.r_min, law.r_max])
        check_formation_inputs(n_particles, radii, density, ke_threshold, fill, check_every, max_steps)
        self.precision, self.check_every, self.max_steps = precision, check_every, max_steps
        self.settings = {
            "seed": int(seed),
            "n_particles": int(n_particles),
            **({"size_radii": radii} if law is None else {"size_distribution": law.text()}),
            "density": float(density),
            "ke_threshold": float(ke_threshold),
            "fill": float(fill),
            "check_every": int(check_every),
            "precision": precision,
            "gravity": gravity,
            "params": params.to_dict(),
        }
        scheme = Scheme(precision=precision, gravity=gravity)
        particle_radii, size_class, self.sizes = grain_sizes(n_particles, seed, radii, law)
        masses = 4.0 / 3.0 * math.pi * density * particle_radii**3
        # Where this session's wall time goes (seconds): set-up (seeding, the simulation), stepping
        # (waited for), checks (KE/|U| every check_every steps), saves (counted by the caller).
        self.seconds = {"set-up": 0.0, "stepping": 0.0, "checks": 0.0, "saves": 0.0}
        self.steps_this_session = 0
        setup_started = _time.perf_counter()
        if snapshot is None:
            positions, self.seed_radius = seed_cloud(particle_radii, np.random.default_rng(seed), fill)
            zeros = np.zeros_like(positions)
            cloud = State.from_arrays(positions, zeros, zeros, particle_radii, masses, size_class=size_class)
            self.sim = Simulation(cloud, params, device=device, scheme=scheme)
            self.history_time, self.history_ratio, self.peak, self.wall_before = [0.0], [0.0], 0.0, 0.0
        else:
            formation = snapshot["formation"]
            _check_same_settings(formation["settings"], self.settings)
            cloud = State.from_arrays(
                snapshot["positions"], snapshot["velocities"], snapshot["omegas"], particle_radii, masses, size_class=size_class
            )
            self.sim = Simulation.from_snapshot(cloud, params, snapshot, device=device, scheme=scheme)
            self.seed_radius = float(formation["seed_radius"])
            self.history_time = [float(v) for v in formation["history_time"]]
            self.history_ratio = [float(v) for v in formation["history_ke_over_u"]]
            self.peak, self.wall_before = float(formation["peak"]), float(formation["wall_seconds"])
        self._started = _time.perf_counter()
        self.seconds["set-up"] = self._started - setup_started
        self.wall_before += self.seconds["set-up"]
        self.state = self.sim.state

    @property
    def settled(self) -> bool:
        """Collapsed (KE/|U| peaked past COLLAPSE_PEAK) and calm again (below the threshold)."""
        return self.peak >= COLLAPSE_PEAK and self.history_ratio[-1] < self.settings["ke_threshold"]

    @property
    def wall_seconds(self) -> float:
        """Wall time of the formation so far, over all its sessions."""
        return self.wall_before + _time.perf_counter() - self._started

    def progress(self) -> FormationProgress:
        return FormationProgress(
            self.sim.step_count, self.sim.time, self.history_ratio[-1], self.peak, self.settings["ke_threshold"], self.wall_seconds
        )

    def advance(self) -> None:
        """``check_every`` steps, then KE/|U|; raises FormationError past ``max_steps``."""
        sim = self.sim
        if sim.step_count >= self.max_steps:
            raise FormationError(
                f"the pile did not settle within {self.max_steps} steps: KE/|U| = {self.history_ratio[-1]:.3g} "
                f"> {self.settings['ke_threshold']:g}; raise max_steps or ke_threshold"
            )
        started = _time.perf_counter()
        steps = min(self.check_every, self.max_steps - sim.step_count)
        sim.step(steps)
        sim.finish()  # so that stepping, not the check's read-back, is charged with the device's work
        checked = _time.perf_counter()
        self.state = sim.state
        ratio = _kinetic_over_potential(sim, self.state)
        self.seconds["stepping"] += checked - started
        self.seconds["checks"] += _time.perf_counter() - checked
        self.steps_this_session += steps
        self.peak = max(self.peak, ratio)
        self.history_time.append(sim.time)
        self.history_ratio.append(ratio)

    def timing(self) -> str:
        """This session's wall time, itemised: e.g. 'set-up 1.2 s, stepping 30.1 s (0.12 ms a step over 250 000 steps), ...'."""
        t, steps = self.seconds, self.steps_this_session
        per_step = f" ({1e3 * t['stepping'] / steps:.3g} ms a step over {steps} steps)" if steps else ""
        return f"set-up {t['set-up']:.1f} s, stepping {t['stepping']:.1f} s{per_step}, checks {t['checks']:.1f} s, saves {t['saves']:.1f} s"

    def snapshot(self) -> dict:
        """Everything :class:`Formation` needs to continue exactly (``snapshot=``): the simulation's
        arrays plus a ``formation`` table (settings, KE/|U| history, peak, seed radius, wall time)."""
        snap = self.sim.snapshot()
        snap["formation"] = {
            "settings": self.settings,
            "seed_radius": self.seed_radius,
            "history_time": np.array(self.history_time),
            "history_ke_over_u": np.array(self.history_ratio),
            "peak": self.peak,
            "wall_seconds": self.wall_seconds,
        }
        return snap

    def pile(self) -> State:
        """The settled pile: net motion removed, centred, time 0, with its formation history."""
        pile = remove_net_motion(self.state)
        pile.time, pile.step = 0.0, 0
        settled = self.sim.diagnostics(pile)
        settings = self.settings
        pile.metadata = {
            "seed": settings["seed"],
            "n_particles": settings["n_particles"],
            **self.sizes,
            "density": settings["density"],
            "ke_threshold": settings["ke_threshold"],
            "fill": settings["fill"],
            "seed_radius": float(self.seed_radius),
            "formation_steps": int(self.sim.step_count),
            "formation_time": float(self.sim.time),
            "formation_wall_seconds": float(self.wall_seconds),
            "device": self.sim.device,
            "precision": self.precision,
            "history_time": np.array(self.history_time),
            "history_ke_over_u": np.array(self.history_ratio),
            "potential": settled["potential"],
            "params": settings["params"],
        }
        return pile


def _check_same_settings(saved: dict, asked: dict) -> None:
    """A formation continues only with the settings it began with."""
    for key, value in asked.items():
        before = saved.get(key)
        if key == "gravity" and before is None:  # formations begun when the solver was a field of params
            before = saved.get("params", {}).get("gravity", value)
        if key == "params":
            differs = {k: v for k, v in value.items() if before is None or before.get(k) != v}
        elif isinstance(value, np.ndarray):
            differs = before is None or np.shape(before) != value.shape or not np.array_equal(before, value)
        else:
            differs = before != value
        if differs:
            raise InputError(
                f"the saved formation was begun with {key} = {before!r}, not {value!r}: "
                "continue it with the same options, or delete its file to begin afresh"
            )


def form_pile(*args, progress: Callable[[FormationProgress], None] | None = None, **options) -> State:
    """Build a rubble pile: seed, collapse until KE < ke_threshold |U|, remove net motion, centre.

    The arguments are :class:`Formation`'s (n_particles, seed, device, radii, density,
    params, ke_threshold, fill, check_every, max_steps, precision, size_distribution); ``progress`` is told
    after each check.  Deterministic for a given ``seed`` on a given device.  The
    returned State has ``size_class`` (0 = smallest radius) and ``metadata`` with the
    formation history (time, KE/|U|) and the settings used.  (:class:`Formation` does
    the same one check at a time, and can stop and continue.)

    >>> pile = form_pile(n_particles=300, seed=1, device="cpu")
    """
    formation = Formation(*args, **options)
    while not formation.settled:
        formation.advance()
        if progress is not None:
            progress(formation.progress())
    return formation.pile()


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
        raise InputError(f"n_particles must be an integer >= 2; got {n_particles!r}")
    low, high = RADIUS_RANGE
    if radii.ndim != 1 or radii.size == 0 or not np.all(np.isfinite(radii)) or np.any(radii < low) or np.any(radii > high):
        raise InputError(f"radii must be sizes from {low:g} to {high:g} cm; got {radii.tolist()}")
    low, high = DENSITY_RANGE
    if not (math.isfinite(density) and low <= density <= high):
        raise InputError(f"density must be from {low:g} to {high:g} g/cm^3; got {density!r}")
    if not (0 < ke_threshold < COLLAPSE_PEAK):
        raise InputError(f"ke_threshold must be in (0, {COLLAPSE_PEAK:g}); got {ke_threshold!r}")
    if not (0 < fill < 0.5):
        raise InputError(f"fill must be in (0, 0.5); got {fill!r}")
    if check_every < 1 or max_steps < 1:
        raise InputError("check_every and max_steps must be >= 1")

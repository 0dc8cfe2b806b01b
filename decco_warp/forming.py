"""A pile formed into a file, safely: a checkpoint beside the file now and then, and a stop
(Ctrl-C, SIGTERM) or a step limit that saves before it ends.  The same command continues from the
checkpoint (``OUT.forming``), and the pile is then the same, bit for bit, as one formed in one go.
Large piles need this: the paper's 5 000-particle piles took ~1.5e5 steps, and a step grows with N."""

from __future__ import annotations

import functools
import math
import time as _time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from .device import resolve_device
from .arrays import candidate_width
from .costs import check_fits
from .io import FileFormatError, read_checkpoint, save_pile, write_checkpoint
from .params import Params
from .scheme import GRAVITY_CHOICES, Scheme, choose_gravity
from .pile import Formation, FormationError, FormationProgress, check_formation_inputs, grain_sizes
from .sizes import PowerLaw, parse_size_distribution, touching_limit
from .stability import MIN_TIME_STEP_MARGIN
from .state import State
from .stops import StopRequests, drive
from .errors import FormationStopped, InputError  # noqa: F401 (re-exported: the error lives in errors.py)

#: A forming pile's checkpoint is its file's name plus this.
FORMING_SUFFIX = ".forming"
#: Steps a pile typically takes to settle (the paper's 5 000-particle piles: ~1.5e5), for the
#: estimate of its time before it starts.
TYPICAL_FORMATION_STEPS = 150_000
#: Wall seconds between checkpoints of a forming pile.
CHECKPOINT_SECONDS = 60.0


@dataclass(frozen=True)
class PilePlan:
    """A pile's formation resolved once (its device and its gravity chosen, its inputs checked): what
    ``decco-warp pile --check`` reports and :func:`form_pile_file` forms (with :meth:`options`)."""

    out: Path
    particles: int
    seed: int
    radii: tuple[float, ...]
    density: float
    ke_threshold: float
    fill: float
    max_steps: int
    params: Params
    precision: str
    device: str
    note: str | None  # the line that says a formation would take hours here, else None
    size_distribution: PowerLaw | None = None  # radii drawn from a power law instead of ``radii``
    gravity: str = "all-pairs"  # the gravity solver, "auto" settled

    def options(self) -> dict:
        """:class:`decco_warp.pile.Formation`'s options."""
        return {"n_particles": self.particles, "seed": self.seed, "device": self.device, "radii": self.radii, "density": self.density,
                "params": self.params, "ke_threshold": self.ke_threshold, "fill": self.fill, "max_steps": self.max_steps,
                "precision": self.precision, "size_distribution": self.size_distribution, "gravity": self.gravity}  # fmt: skip

    @functools.cached_property
    def grains(self) -> tuple:
        """The pile's grains as Formation draws them (pile.grain_sizes: radii, size classes, sizes), drawn once."""
        return grain_sizes(self.particles, self.seed, self.radii, self.size_distribution)

    def grain_lines(self) -> list[str]:
        """``pile --check``'s lines on the grains: their sizes; what the smallest costs (paper eq. 17:
        the time step it allows); how many grains the largest can touch, beside what the contact lists
        hold (arrays.candidate_width)."""
        radii, _, sizes = self.grains
        counts = ", ".join(str(int(c)) for c in sizes["size_counts"])
        if self.size_distribution is None:
            kinds = f"radii {', '.join(f'{r / 1e5:g}' for r in self.radii)} km, equal mass per size ({counts} particles)"
        else:
            law = self.size_distribution
            edges = ", ".join(f"{e / 1e5:.3g}" for e in sizes["size_class_edges"])
            kinds = (f"radii drawn from dN/dR ~ R^{law.q:g} on {law.r_min / 1e5:.4g} to {law.r_max / 1e5:.4g} km, in {law.classes} size classes "
                     f"of equal width in log R (edges {edges} km) of {counts} particles")  # fmt: skip
        r_min, r_max = float(radii.min()), float(radii.max())
        scale = self._time_scale(r_min)
        return [
            f"sizes: {kinds}",
            f"smallest grain: radius {r_min / 1e5:.4g} km, {4.0 / 3.0 * math.pi * self.density * r_min**3:.3g} g; eq. 17's time scale "
            f"sqrt(m/k_in) = {scale:.3g} s: dt = {self.params.dt:g} s has a margin of {scale / self.params.dt:.3g} (need >= {MIN_TIME_STEP_MARGIN:g})",
            f"largest grain: radius {r_max / 1e5:.4g} km ({r_max / r_min:.3g} x the smallest), touched by at most {touching_limit(r_max, r_min)} "
            f"of the smallest (were they to cover it); the contact lists hold {candidate_width(r_min, r_max)} "
            "a particle (8 + 4 (R_max/R_min)^2, at least 64; a particle that meets more looks at its whole pile, slower)",
        ]  # fmt: skip

    def refusal(self) -> str | None:
        """Why the formation would be refused before it starts (its smallest grain's eq. 17 margin), or None."""
        radii = self.grains[0]
        safe = self._time_scale(float(radii.min())) / MIN_TIME_STEP_MARGIN
        if self.params.dt <= safe:
            return None
        return (f"dt = {self.params.dt:g} s is too long for the smallest grain (eq. 17 margin {MIN_TIME_STEP_MARGIN * safe / self.params.dt:.3g}, "
                f"need >= {MIN_TIME_STEP_MARGIN:g}): --dt {safe:.3g} or shorter, {self.params.dt / safe:.3g} times the steps")  # fmt: skip

    def _time_scale(self, radius: float) -> float:
        """sqrt(m / k_in) of a grain of ``radius`` [s] (paper eq. 17)."""
        return math.sqrt(4.0 / 3.0 * math.pi * self.density * radius**3 / self.params.k_in)


def plan_pile(
    out, *, particles: int, seed: int, radii, density: float, ke_threshold: float, fill: float, max_steps: int, k_in: float,
    restitution: float, mu_k: float, mu_r: float, dt: float, precision: str, gravity: str, device: str | None = None,
    size_distribution: str | None = None,
) -> PilePlan:  # fmt: skip
    """The plan of a pile's formation (``decco-warp pile``'s options; spec.PILE_SCHEMA): ValueError
    (an InputError for what the checks refuse) on bad input, before anything is formed.
    ``size_distribution``: a power law's text (sizes.parse_size_distribution), in place of ``radii``."""
    chosen = resolve_device(device)
    if gravity not in GRAVITY_CHOICES:
        raise InputError(f"--gravity must be one of {', '.join(GRAVITY_CHOICES)}; got {gravity!r}")
    if gravity == "auto":
        gravity = choose_gravity(particles, chosen)
    params = Params(k_in=k_in, restitution=restitution, mu_k=mu_k, mu_r=mu_r, dt=dt)
    radii = tuple(float(r) for r in radii)
    law = None if size_distribution is None else parse_size_distribution(size_distribution)
    sizes = radii if law is None else (law.r_min, law.r_max)
    check_formation_inputs(particles, sizes, density, ke_threshold, fill, max_steps=max_steps)
    width = candidate_width(min(sizes), max(sizes))
    note = check_fits(particles, Scheme(gravity=gravity, precision=precision), chosen, min(max_steps, TYPICAL_FORMATION_STEPS), "forming a pile", candidate_width=width)
    return PilePlan(Path(out), particles, seed, radii, density, ke_threshold, fill, max_steps, params, precision, chosen, note, law, gravity)


def partial_path(out: Path) -> Path:
    """Where the pile bound for ``out`` keeps its checkpoint while it forms."""
    return out.with_name(out.name + FORMING_SUFFIX)


def read_partial(partial: Path) -> dict:
    """A formation's snapshot saved by :func:`form_pile_file` (for ``Formation(..., snapshot=)``)."""
    snapshot, _, extra = read_checkpoint(partial)
    if "settings" not in extra:
        raise FileFormatError(f"{partial} is a checkpoint, but not of a forming pile")
    snapshot["formation"] = extra
    return snapshot


def _save(formation: Formation, partial: Path) -> None:
    started = _time.perf_counter()
    snapshot = formation.snapshot()
    write_checkpoint(partial, {k: v for k, v in snapshot.items() if k != "formation"}, formation.sim.static, snapshot["formation"])
    formation.seconds["saves"] += _time.perf_counter() - started


class _Forming:
    """A forming pile, for :func:`~decco_warp.stops.drive`: a batch of steps at a time, a checkpoint
    every ``checkpoint_seconds`` of wall time, and one before a stop or the step limit ends it."""

    def __init__(self, formation: Formation, partial: Path, progress, checkpoint_seconds: float):
        self.formation, self.partial, self.progress, self.checkpoint_seconds = formation, partial, progress, checkpoint_seconds
        self.saved = _time.perf_counter()

    @property
    def done(self) -> bool:
        return self.formation.settled

    def advance(self) -> None:
        try:
            self.formation.advance()
        except FormationError:
            _save(self.formation, self.partial)
            raise

    def after(self, seconds: float, stop: StopRequests) -> None:
        formation = self.formation
        if self.progress is not None:
            self.progress(formation.progress())
        requested = stop.signal  # read after the progress: a stop asked for there is answered now
        if requested is not None:
            _save(formation, self.partial)
            raise FormationStopped(requested, formation.sim.step_count, self.partial, formation.timing())
        if _time.perf_counter() - self.saved >= self.checkpoint_seconds:
            _save(formation, self.partial)
            self.saved = _time.perf_counter()


def form_pile_file(
    out: Path,
    progress: Callable[[FormationProgress], None] | None = None,
    checkpoint_seconds: float = CHECKPOINT_SECONDS,
    on_resume: Callable[[int], None] | None = None,
    on_done: Callable[[str], None] | None = None,
    **options,
) -> State:
    """Form a pile (``options`` as :class:`decco_warp.pile.Formation`'s) and write it to ``out``.

    Continues from ``out``'s checkpoint when there is one (``on_resume(step)`` is told; ``on_done``
    is told this session's wall time, itemised, once the pile is written), saves one
    every ``checkpoint_seconds`` of wall time, and on SIGINT/SIGTERM (:class:`FormationStopped`) or
    past ``max_steps`` (:class:`FormationError`; a larger ``max_steps`` continues) before it raises.
    The checkpoint is removed once the pile is written.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = partial_path(out)
    snapshot = read_partial(partial) if partial.exists() else None
    formation = Formation(**options, snapshot=snapshot)
    if snapshot is not None and on_resume is not None:
        on_resume(formation.sim.step_count)
    drive(_Forming(formation, partial, progress, checkpoint_seconds))
    pile = formation.pile()
    save_pile(pile, out)
    partial.unlink(missing_ok=True)
    if on_done is not None:
        on_done(formation.timing())
    return pile

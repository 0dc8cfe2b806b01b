"""A run's plan: a specification resolved once, in one pass, into everything a run needs.

:func:`plan_start` loads and checks the piles, sets up the collision, settles every "auto"
(k_in, dt, gravity; a duration into steps), and chooses the device and the force layout; it
predicts the stability margins and the deepest compression.  :func:`plan_resume` does the same
for a run folder's own specification and checkpoint.  A :class:`Plan` is frozen: run.py,
ensembles and sweeps execute it and never go back to the specification.  Nothing here writes a
file.  Planning touches the device in one place: the set-up's potential energies (the target's,
the projectile's and their sum, which fix the impact speed from eta) are summed over every pair by
the reference kernel (collision.setup_collision -> diagnostics -> Engine), compiled on its first
use; a NumPy sum would be O(N^2) on the host (a minute at 1e5 particles) and would change the
speed's last bits, and with them every run's motion.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

from . import spec as specs
from .checks import check_particles, deepest_rest_overlap
from .collision import setup_collision
from .device import resolve_device
from .layouts import Layout, layout_for
from .io import FileFormatError, load_pile
from .params import Params
from .scheme import Scheme, choose_scheme
from .stability import CompressionForecast, StabilityReport, check_stability, predict_compression
from .state import State
from .errors import RunError  # noqa: F401 (re-exported: the error lives in errors.py)

BUILTIN_PREFIX = "builtin:"


# --- piles and folders ---------------------------------------------------------------


def builtin_pile(name: str) -> Path:
    """Path of a pile shipped with the package (``target`` or ``projectile``)."""
    path = Path(str(resources.files("decco_warp") / "data" / "piles" / f"{name}.h5"))
    if not path.is_file():
        raise RunError(f"there is no builtin pile {name!r}; shipped: target, projectile")
    return path


def pile_path(reference: str) -> Path:
    if reference.startswith(BUILTIN_PREFIX):
        return builtin_pile(reference[len(BUILTIN_PREFIX) :])
    path = Path(reference).expanduser()
    if not path.is_file():
        raise RunError(f"pile file {reference} does not exist")
    return path


def run_dir_of(spec: dict) -> Path:
    return Path(spec["run"]["out"]).expanduser() / spec["run"]["name"]


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


# --- the plan ------------------------------------------------------------------------


@dataclass(frozen=True)
class PileSource:
    """One pile of a collision as the run read it."""

    which: str
    """target or projectile"""
    file: str
    """The file's resolved path."""
    sha256: str


@dataclass(frozen=True)
class Outputs:
    """Where and how often a run writes."""

    run_dir: Path
    output_every: int
    """Steps between two frames of the trajectory."""
    checkpoint_every: int
    """Steps between two checkpoints."""


def _contact_words(p: Params) -> str:
    """The contact law's constants in words, for ``--check``."""
    if p.contact_law == "ssdem":
        return (f"contact law ssdem (k_n {p.k_n:.6g} dyne/cm, k_t {p.k_t:.6g} dyne/cm, eps_n {p.restitution:g}, eps_t {p.eps_t:g}, "
                f"mu_s {p.mu_s:g}, mu_r {p.mu_r:g}, mu_t {p.mu_t:g}, beta {p.beta:g}, cohesion {p.cohesion:g} dyne/cm^2)")  # fmt: skip
    return f"restitution {p.restitution:g}, mu_k {p.mu_k:g}, mu_r {p.mu_r:g} ({p.rolling_friction})"


@dataclass(frozen=True)
class Plan:
    """A run resolved from its specification, nothing compiled or written: what a run executes
    and what ``simulate --check`` shows.  Frozen, and holding no "auto"."""

    spec_items: tuple
    """The resolved specification with every "auto" settled, as frozen (table, ((key, value), ...)) pairs:
    :attr:`spec` gives it as the dict that spec.toml and /parameters record."""
    state: State
    """The collision set up (a new run), or the checkpoint's static arrays (a resumed one)."""
    params: Params
    """What the model is: the contact law and its constants, G, dt."""
    scheme: Scheme
    """How it is evaluated: precision, gravity solver, its clock, and the force kernel's layout for
    this run's size on its device."""
    device: str
    """The Warp device ("cpu", "cuda:N")."""
    steps: int
    """The total steps the run reaches."""
    outputs: Outputs
    allow_unstable: bool
    max_overlap: float | None
    """Contacts deeper than this (fraction of the smaller radius) stop the run; None: no limit."""
    piles: tuple[PileSource, ...] = ()
    """The piles read (a new run; a resumed one reads none)."""
    stability: StabilityReport | None = None
    """Margins of eqs. 15 and 17 at the start (a new run; a resumed run was accepted when it began)."""
    forecast: CompressionForecast | None = None
    """The predicted deepest compression (a new run)."""
    rest_overlap: tuple[float, int, int] = (0.0, -1, -1)
    """The deepest overlap at the start, as a fraction of the smaller radius, and its pair."""
    notes: tuple[str, ...] = ()
    """One line per value chosen from the set-up (k_in = "auto", ...)."""

    @property
    def spec(self) -> dict:
        """The resolved specification (a fresh copy: the plan itself cannot be changed through it)."""
        return {table: dict(values) for table, values in self.spec_items}

    @property
    def layout(self) -> Layout:
        """The force kernel's layout for this run's size on its device."""
        return self.scheme.layout

    @property
    def precision(self) -> str:
        return self.scheme.precision

    @property
    def run_dir(self) -> Path:
        return self.outputs.run_dir

    @property
    def size_classes(self) -> int:
        return int(self.state.size_class.max()) + 1

    @property
    def pile_info(self) -> dict:
        """The piles as /parameters records them: each file's path and SHA-256."""
        info = {}
        for pile in self.piles:
            info[f"{pile.which}_file"] = pile.file
            info[f"{pile.which}_sha256"] = pile.sha256
        return info

    def lines(self) -> list[str]:
        """What run.log and ``--check`` say about the set-up before any step."""
        meta = self.state.metadata
        params, scheme, run = self.params, self.scheme, self.spec["run"]
        return [
            f"collision: {self.state.n} particles ({int((self.state.pile_id == 0).sum())} target + "
            f"{int((self.state.pile_id == 1).sum())} projectile), eta {meta['eta']:.6g}"
            + (f" (U of all pairs; {meta['eta_self']:.4g} with each pile's own)" if meta.get("eta_potential") == "all" else "")
            + f", speed {meta['speed']:.6g} cm/s, "
            f"theta {meta['theta_deg']:g} deg, b {meta['impact_parameter']:.6g} cm"
            + (f", piles turned by random rotations of orientation_seed {meta['orientation_seed']}" if "orientation_seed" in meta else ""),
            *self.notes,
            f"parameters: k_in {params.k_in:.6g} dyne/cm, dt {params.dt:.6g} s, {self.steps} steps "
            f"({self.steps * params.dt:.6g} s)"
            + (f", {scheme.clock_text()}" if scheme.clock_text() else "")
            + (f", force layout {run['layout']}" if run["layout"] != "auto" else ""),
            f"stability: {self.stability.summary()}",
            f"compression: {self.forecast.summary()}",
        ]

    def choices(self) -> list[str]:
        """The plan's resolved choices, beyond :meth:`lines`: what ``--check`` adds."""
        p, s = self.params, self.scheme
        return [
            f"piles: {', '.join(f'{pile.which} {pile.file} (sha256 {pile.sha256[:12]})' for pile in self.piles)}",
            f"physics: {_contact_words(p)}, "
            f"G {p.G:.6g}, gravity {s.gravity}" + (f" (theta_open {s.theta_open:g})" if s.gravity == "tree" else ""),
            f"device: {self.device}, precision {self.precision}, force layout {self.layout.describe()}"
            + (f"; {s.clock_text(solver=True)}, contacts every step from a neighbour list" if s.clock_text() else ""),
            f"outputs: {self.outputs.run_dir}, a frame every {self.outputs.output_every} steps, "
            f"a checkpoint every {self.outputs.checkpoint_every} steps"
            + (f", stop past an overlap of {self.max_overlap:g}" if self.max_overlap is not None else ""),
        ]


def _frozen(spec: dict) -> tuple:
    return tuple((table, tuple(values.items())) for table, values in spec.items())


def _read_only(state: State) -> State:
    """A copy of ``state`` whose arrays cannot be written: what executes a plan copies it first."""
    state = state.copy()
    for name in ("positions", "velocities", "omegas", "radii", "masses", "pile_id", "size_class"):
        getattr(state, name).flags.writeable = False
    return state


def _resolved(spec: dict, state: State, device: str, **given) -> Plan:
    """The plan of a settled ``spec`` (no "auto" left) for ``state`` on ``device``."""
    specs.check_clock(spec)  # a resume's new total of steps too
    run = spec["run"]
    n = state.n
    return Plan(
        spec_items=_frozen(spec),
        state=_read_only(state),
        params=specs.params_of(spec),
        # The layout "auto" is the engine's own choice for one system of n particles, made here once.
        scheme=choose_scheme(n, device, specs.scheme_of(spec), layout=layout_for(run["layout"], n, device)),
        device=device,
        steps=run["steps"],
        outputs=Outputs(run_dir_of(spec), run["output_every"], run["checkpoint_every"]),
        allow_unstable=run["allow_unstable"],
        max_overlap=run.get("max_overlap"),
        **given,
    )


def _device(spec: dict, override: str | None) -> str:
    """The Warp device: ``override`` (the CLI's --device, a sweep worker's GPU), else the spec's."""
    if override is None and spec["run"]["device"] != "auto":
        override = spec["run"]["device"]
    return resolve_device(override)


def load_piles(spec: dict) -> tuple[State, State, tuple[PileSource, ...]]:
    """The target and projectile a spec names, read, with where they came from."""
    states, sources = [], []
    for which in ("target", "projectile"):
        path = pile_path(spec["piles"][which])
        try:
            states.append(load_pile(path))
        except FileFormatError as error:
            raise RunError(str(error)) from None
        sources.append(PileSource(which, str(path.resolve()), _sha256(path)))
    return states[0], states[1], tuple(sources)


def plan_start(spec: dict, device: str | None = None) -> Plan:
    """A new run's plan from a resolved ``spec``: its collision set up and checked (eqs. 12, 15,
    17), every "auto" settled; compiles and writes nothing.  ``device`` overrides ``[run] device``."""
    device = _device(spec, device)
    target, projectile, piles = load_piles(spec)
    collision = spec["collision"]
    state = setup_collision(
        target,
        projectile,
        eta=collision.get("eta"),
        speed=collision.get("speed"),
        theta_deg=collision["theta_deg"],
        gap=collision["gap"],
        target_spin=specs.spin_of(spec, "target"),
        projectile_spin=specs.spin_of(spec, "projectile"),
        G=spec["params"]["G"],
        device=device,
        orientation_seed=collision.get("orientation_seed"),
        eta_potential=collision["eta_potential"],
    )
    check_particles(state, "the collision set-up")  # a speed or spin beyond the model's subsonic regime
    spec, notes = specs.settle_auto(spec, state, device)
    plan = _resolved(spec, state, device, piles=piles, rest_overlap=deepest_rest_overlap(state), notes=tuple(notes))
    stability = check_stability(state, plan.params)
    forecast = predict_compression(state, plan.params.k_in)
    return replace(plan, stability=stability, forecast=forecast)


def plan_resume(spec: dict, static: State, run_dir: Path, device: str | None = None, steps: int | None = None) -> Plan:
    """A resumed run's plan from its folder's settled ``spec`` and its checkpoint's ``static``
    arrays; ``steps`` raises the total to run.  The run continues in ``run_dir``, where it is."""
    spec = {table: dict(values) for table, values in spec.items()}
    if steps is not None:
        spec["run"]["steps"] = steps
    plan = _resolved(spec, static, _device(spec, device))
    return replace(plan, outputs=replace(plan.outputs, run_dir=Path(run_dir)))

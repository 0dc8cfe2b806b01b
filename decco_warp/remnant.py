"""A fragment of a finished collision as a pile of its own, for the next collision.

The paper's own next step is repeated collisions ("a better approach to building initial cluster
configurations is by hierarchically colliding smaller clusters"): :func:`extract_fragment` takes a
cluster of a run's last analysed frame (its members from analysis.h5, its particles from the
trajectory's last frame), centres it, removes its bulk motion and, if asked, its spin, and lets it
settle in isolation; ``decco-warp extract`` writes it as a pile file that ``simulate`` takes as a
target or a projectile.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from .checks import InputError
from .diagnostics import diagnostics
from .folder import RunFolder
from .io import read_trajectory
from .params import Params
from .scheme import SCHEME_KEYS, Scheme
from .simulation import Simulation
from .state import State, remove_net_motion

#: How the fragment's spin is treated: kept (its rigid rotation about its centre stays), or removed.
SPIN_CHOICES = ("keep", "remove")
#: Settled when the kinetic energy of the motion about the rigid rotation is below this x |U|
#: (the formation's threshold, docs/model.md "Rubble-pile formation").
KE_THRESHOLD = 1e-5
#: Steps between two looks at the fragment's internal kinetic energy while it settles.
CHECK_EVERY = 250


def internal_kinetic_energy(state: State) -> float:
    """Kinetic energy of the particles' motion relative to the cluster's bulk velocity and rigid spin
    Omega = I^-1 L: sum 1/2 m |v - V - Omega x r|^2 + 1/2 I |w - Omega|^2 [erg]."""
    spin = state.spin()
    r = state.positions - state.centre_of_mass
    v = state.velocities - state.bulk_velocity - np.cross(spin, r)
    w = state.omegas - spin
    return float(0.5 * (state.masses * (v * v).sum(axis=1)).sum() + 0.5 * (state.inertia * (w * w).sum(axis=1)).sum())


def fragment_of(run_dir, fragment: int = 0) -> tuple[State, dict]:
    """The particles of cluster ``fragment`` (0: the largest) at a run's last frame, as its analysis
    found them, with where they came from."""
    run_dir = Path(run_dir)
    folder = RunFolder(run_dir)
    analysis, trajectory = folder.analysis, folder.trajectory
    if not trajectory.is_file():
        raise InputError(f"{run_dir} holds no {RunFolder.TRAJECTORY}: the fragment's particles come from its last frame")
    if not analysis.is_file():
        raise InputError(f"{run_dir} is not analysed: decco-warp analyze {run_dir} finds its fragments first")
    with h5py.File(analysis, "r") as f:
        label, step, masses = f["final/label"][()], int(f["final/step"][()]), f["final/mass"][()]
    data = read_trajectory(trajectory)
    if int(data.step[-1]) != step:
        raise InputError(f"{run_dir}'s analysis ends at step {step} but its trajectory at step {int(data.step[-1])}: analyze it again")
    if isinstance(fragment, bool) or not isinstance(fragment, (int, np.integer)) or not 0 <= fragment < masses.size:
        count = f"{masses.size} fragment(s), 0 to {masses.size - 1}" if masses.size else "no fragment of the analysis's minimum size"
        raise InputError(f"--fragment must be one of the run's {count} at its last frame (0 the largest); got {fragment!r}")
    members = np.flatnonzero(label == fragment)
    static = data.static
    state = State.from_arrays(
        data.particles["position"][-1][members],
        data.particles["velocity"][-1][members],
        data.particles["omega"][-1][members],
        static["radius"][members],
        static["mass"][members],
        size_class=static["species"][members].astype(np.int32),
    )
    source = {"run": str(run_dir), "fragment": int(fragment), "step": step, "time": float(data.time[-1]),
              "mass": float(masses[fragment]), "members": int(members.size)}  # fmt: skip
    return state, {**source, "params": data.parameters.get("spec", {}).get("params", {})}


#: A settled pile's grains fill 0.40 to 0.50 of the sphere that holds them (the shipped piles and the
#: paper's; :func:`packing`); a "fragment" filling less than this is a loose swarm (grains bound by
#: gravity, hardly touching: debris that the cluster finder's escape-speed rule keeps together).
LOOSE_PACKING = 0.15


def packing(state: State) -> float:
    """The grains' volume over that of the sphere that holds them (radius: collision.pile_radius)."""
    from .collision import pile_radius

    return float((state.radii**3).sum() / pile_radius(state) ** 3)


def loose_note(state: State, fragment: int, settle: bool) -> str | None:
    """A warning for a fragment that is a loose swarm rather than a body (:data:`LOOSE_PACKING`),
    saying what it is and what extracting it gives; None for a body."""
    from .collision import pile_radius

    fill = packing(state)
    if fill >= LOOSE_PACKING:
        return None
    fate = ("settling lets it collapse under its own gravity into a pile first, which can take many steps" if settle
            else "--no-settle writes it as the swarm it is")  # fmt: skip
    return (f"warning: fragment {fragment} is a loose swarm, not a body: {state.n} grains spread over a radius of "
            f"{pile_radius(state) / 1e5:.3g} km fill {fill:.2g} of that sphere (a settled pile fills 0.4 to 0.5); {fate}")


def check_options(spin: str, ke_threshold: float, max_steps: int) -> None:
    """Refuse (InputError) a ``spin`` choice, threshold or step limit that :func:`extract_fragment` cannot use."""
    if spin not in SPIN_CHOICES:
        raise InputError(f"--spin must be one of {', '.join(SPIN_CHOICES)}; got {spin!r}")
    if not (isinstance(ke_threshold, (int, float)) and ke_threshold > 0) or not (isinstance(max_steps, int) and max_steps >= 0):
        raise InputError("--ke-threshold must be > 0 and --max-steps >= 0")


def extract_fragment(run_dir, fragment: int = 0, spin: str = "keep", settle: bool = True, ke_threshold: float = KE_THRESHOLD,
                     max_steps: int = 1_000_000, device: str | None = None, progress=None) -> State:  # fmt: skip
    """Cluster ``fragment`` of a run's last frame as a pile: centred, its bulk motion removed, its
    rigid spin kept or removed (``spin``), and with ``settle`` stepped alone (the run's own Params)
    until its internal kinetic energy is below ``ke_threshold`` |U| (at most ``max_steps`` steps;
    ``progress(step, ratio)`` after each look).  Its metadata says where it came from.  In steps
    (``decco-warp extract`` checks and warns before the work): :func:`check_options`,
    :func:`fragment_of`, :func:`loose_note`, :func:`settle_fragment`."""
    check_options(spin, ke_threshold, max_steps)
    state, source = fragment_of(run_dir, fragment)
    return settle_fragment(state, source, spin, settle, ke_threshold, max_steps, device, progress)


def settle_fragment(state: State, source: dict, spin: str = "keep", settle: bool = True, ke_threshold: float = KE_THRESHOLD,
                    max_steps: int = 1_000_000, device: str | None = None, progress=None) -> State:  # fmt: skip
    """:func:`extract_fragment`'s work on a fragment read by :func:`fragment_of` (its ``state`` and ``source``)."""
    source = dict(source)
    given = source.pop("params")
    params = Params.from_dict({k: v for k, v in given.items() if k in Params.__dataclass_fields__})
    scheme = Scheme(**{k: v for k, v in given.items() if k in SCHEME_KEYS})  # the run's gravity and its clock
    state = _centred(state, spin)
    steps, ratio = 0, None
    if settle:
        sim = Simulation(state, params, device=device, allow_unstable=True, scheme=scheme)
        ratio = _internal_ratio(sim)
        outer = sim.step_multiple  # steps go in whole outer steps
        chunk = max(1, CHECK_EVERY // outer) * outer
        while ratio >= ke_threshold and sim.step_count + outer <= max_steps:
            sim.step(min(chunk, (max_steps - sim.step_count) // outer * outer))
            ratio = _internal_ratio(sim)
            if progress is not None:
                progress(sim.step_count, ratio)
        if ratio >= ke_threshold:
            raise InputError(
                f"the fragment did not settle within {max_steps} steps: internal KE/|U| = {ratio:.3g} > {ke_threshold:g}; "
                "raise --max-steps or --ke-threshold"
            )
        steps, state = sim.step_count, _centred(sim.state, spin)
    state.time, state.step = 0.0, 0
    # On the settling's own engine: its particles are these, only translated, so U is the same.
    potential = sim.diagnostics(state)["potential"] if settle else diagnostics(state, params, device)["potential"]
    state.metadata = {"extracted_from": source, "spin": spin, "settle_steps": int(steps), "internal_ke_over_u": ratio,
                      "spin_vector": state.spin(), "potential": potential}  # fmt: skip
    return state


def _centred(state: State, spin: str) -> State:
    """Centred, bulk motion removed, and the rigid spin too if ``spin`` is "remove"."""
    if spin == "remove":
        return remove_net_motion(state)
    state = state.copy()
    state.positions -= state.centre_of_mass
    state.velocities -= state.bulk_velocity
    return state


def _internal_ratio(sim: Simulation) -> float:
    state = sim.state
    return internal_kinetic_energy(state) / abs(sim.diagnostics(state)["potential"])

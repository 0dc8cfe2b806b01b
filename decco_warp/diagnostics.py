"""Conserved and dissipated quantities of a state (float64, host side).

:func:`diagnostics` serves the public API; :func:`observables` adds what a run
records at each output (energy ledger, stress shares by three measures).  Both take per-particle
pair sums computed on the device by the engine.
"""

from __future__ import annotations

import math

import numpy as np

from .kernels.channels import ENERGY_CHANNELS, HELD_ENERGIES, LEDGER_ENTRIES
from .params import Params
from .state import State

#: Fraction of particles counted as "most stressed" (paper sect. 4.1, Fig. 8).
TOP_STRESS_FRACTION = 0.01


def diagnostics(state: State, params: Params, device: str | None = None) -> dict:
    """Energies [erg], momentum [g cm/s] and angular momentum [g cm^2/s] of ``state``.

    Keys: kinetic_translational, kinetic_rotational, potential (sum over pairs
    of -G m_i m_j / d), elastic (sum over contacts of (k/4) delta^2, with k the
    spring the force kernel would use now; ssdem: k_n delta^2 / 2), elastic_tangential
    and elastic_rolling (ssdem: the energy held in the contacts' tangential springs, and
    in their rolling and twisting springs; 0 for the other laws, and for a state whose
    contacts have no history yet, as here), total_energy (their sum), momentum (3,),
    angular_momentum (3,) about the origin, orbital (sum m x cross v) plus spin
    (sum I w), number_of_contacts, max_overlap [cm], deepest_overlap (the deepest
    contact as a fraction of the smaller radius of its pair; past 1 a centre lies inside
    the other sphere) and deepest_overlap_pair (its two particles, -1 -1 without contacts).
    """
    from .engine import Engine  # here, so that the analysis can use this module without Warp

    # Observables are of one state: the clock gravity is kicked on plays no part in them.
    pairs = Engine(state, params, device, force_kernel="reference").pair_observables()
    return state_diagnostics(state, pairs)


def state_diagnostics(state: State, pairs: dict[str, np.ndarray]) -> dict:
    """:func:`diagnostics` from per-particle pair sums already computed (Engine.pair_observables)."""
    masses, inertia = state.masses, state.inertia
    kinetic_translational = 0.5 * float(np.sum(masses * np.einsum("ij,ij->i", state.velocities, state.velocities)))
    kinetic_rotational = 0.5 * float(np.sum(inertia * np.einsum("ij,ij->i", state.omegas, state.omegas)))
    potential = float(pairs["potential"].sum())
    elastic = float(pairs["elastic"].sum())
    elastic_tangential = float(pairs["elastic_tangential"].sum()) if "elastic_tangential" in pairs else 0.0
    elastic_rolling = float(pairs["elastic_rolling"].sum()) if "elastic_rolling" in pairs else 0.0
    momentum = (masses[:, None] * state.velocities).sum(axis=0)
    orbital = (masses[:, None] * np.cross(state.positions, state.velocities)).sum(axis=0)
    spin = (inertia[:, None] * state.omegas).sum(axis=0)
    return {
        "kinetic_translational": kinetic_translational,
        "kinetic_rotational": kinetic_rotational,
        "potential": potential,
        "elastic": elastic,
        "elastic_tangential": elastic_tangential,
        "elastic_rolling": elastic_rolling,
        "total_energy": kinetic_translational + kinetic_rotational + potential + elastic + elastic_tangential + elastic_rolling,
        "momentum": momentum,
        "angular_momentum": orbital + spin,
        "number_of_contacts": int(pairs["contacts"].sum()) // 2,
        "max_overlap": float(pairs["max_overlap"].max()),
        **deepest_overlap(pairs),
    }


def deepest_overlap(pairs: dict[str, np.ndarray]) -> dict:
    """The deepest contact of a state from per-particle depths: its depth as a fraction of the
    smaller radius of the pair, and the pair (lower index first; -1 -1 when nothing touches)."""
    i = int(np.argmax(pairs["overlap_depth"]))
    j = int(pairs["overlap_partner"][i])
    pair = np.array(sorted((i, j)) if j >= 0 else (-1, -1), dtype=np.int64)
    return {"deepest_overlap": float(pairs["overlap_depth"][i]), "deepest_overlap_pair": pair}


def energy_ledger(current: dict, start: dict, work: np.ndarray) -> dict:
    """Where the energy went since ``start`` (a diagnostics dict), from per-particle channel work (N, 4).

    The kinetic energy change equals the summed work exactly (kernels/integrate.py), so
    total_energy + the four entries below equals the starting total energy to round-off:
      dissipated_sliding, dissipated_rolling: minus the work of each friction, less the change of
        the energy its springs hold (ssdem: the tangential springs; the rolling and twisting springs,
        whose couples are the rolling channel; the other laws keep none);
      dissipated_hysteresis: minus the spring work, less the change of elastic energy
        (the k_in/k_out loss, ssdem's normal dashpot, plus the spring's own integration error);
      integration_error: minus the work of gravity, less the change of potential energy.
    """
    total = work.sum(axis=0)

    def change(key: str) -> float:  # (diagnostics of decco-warp 0.2 have no springs' energies: none held)
        return current.get(key, 0.0) - start.get(key, 0.0)

    took = {channel.entry: -float(total[column]) - change(channel.held) for column, channel in enumerate(ENERGY_CHANNELS)}
    return {entry: took[entry] for entry in LEDGER_ENTRIES}


#: The diagnostics a ledger's starting point keeps (a snapshot's "energy_start").
ENERGY_START_KEYS = (*HELD_ENERGIES, "total_energy")


def energy_scale(start: dict) -> float:
    """|U| + KE at the start: the yardstick of energy errors [erg]."""
    return abs(start["potential"]) + abs(start["total_energy"] - start["potential"])


def ledger_closure(observables: dict, start_energy: float, scale: float):
    """(total energy + every ledger entry - starting total energy) / scale: zero to round-off
    when every erg is accounted for.  Works on one frame or on time series."""
    total = observables["total_energy"] + sum(observables[name] for name in LEDGER_ENTRIES)
    return (total - start_energy) / scale


#: The measures a particle's stress is ranked by (:func:`stress_shares`): the power of its radius
#: R that its largest overlap delta is divided by.  "overlap" is the paper's (sect. 4.1): delta
#: itself, which with one spring constant is proportional to the largest normal force k_in delta,
#: so it ranks force (a large grain, with more and wider contacts, ranks high); "per_area" is
#: delta / R^2, proportional to that force over the grain's cross-section, k_in delta / (pi R^2):
#: a stress; "strain" is delta / R, the contact's strain.
STRESS_MEASURES = {"overlap": 0, "per_area": 2, "strain": 1}

#: Each frame's stress-share observable (run.py, docs/data.md) and the measure it ranks by.
STRESS_SHARE_OBSERVABLES = {"stress_share": "overlap", "stress_share_per_area": "per_area", "stress_share_strain": "strain"}


def stress_shares(max_overlap: np.ndarray, size_class: np.ndarray, classes: int, radii: np.ndarray | None = None,
                  measure: str = "overlap") -> np.ndarray:  # fmt: skip
    """100 N_c,top / N_c for each size class c, the top being the 1 % most stressed particles.

    A particle's stress is ranked by ``measure`` (:data:`STRESS_MEASURES`, docs/model.md): its
    largest overlap delta over its contacts (``max_overlap``, the paper's, "overlap"), delta / R^2
    ("per_area": proportional to its largest normal force per cross-section area, k_in delta /
    (pi R^2), for one spring constant) or delta / R ("strain"), R its radius (``radii``, needed by
    the last two).  The top holds ceil(1 % of N) particles, ties broken by index so the result is
    deterministic.  A value of 1 everywhere means stress is shared evenly.  Classes with no
    particles give NaN.
    """
    if measure not in STRESS_MEASURES:
        raise ValueError(f"unknown stress measure {measure!r} (one of {', '.join(STRESS_MEASURES)})")
    power = STRESS_MEASURES[measure]
    if power and radii is None:
        raise ValueError(f"the stress measure {measure!r} needs the particles' radii")
    stress = max_overlap / radii**power if power else max_overlap
    n = stress.shape[0]
    top = math.ceil(TOP_STRESS_FRACTION * n)
    order = np.lexsort((np.arange(n), -stress))[:top]
    counts = np.bincount(size_class, minlength=classes)[:classes].astype(float)
    top_counts = np.bincount(size_class[order], minlength=classes)[:classes].astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, 100.0 * top_counts / counts, np.nan)


def stress_share_observables(max_overlap: np.ndarray, radii: np.ndarray, size_class: np.ndarray, classes: int) -> dict:
    """Each of :data:`STRESS_SHARE_OBSERVABLES` of one frame: name -> :func:`stress_shares` (classes,)."""
    return {name: stress_shares(max_overlap, size_class, classes, radii, measure)
            for name, measure in STRESS_SHARE_OBSERVABLES.items()}  # fmt: skip


def stress_share_classes(observables: dict, species: np.ndarray) -> int:
    """The size classes a run's stress shares count: as it recorded them, else its particles'."""
    return np.shape(observables["stress_share"])[-1] if "stress_share" in observables else int(np.max(species)) + 1


def recorded_stress_shares(recorded: dict, stress: np.ndarray, radii: np.ndarray, size_class: np.ndarray, classes: int) -> dict:
    """One frame's :data:`STRESS_SHARE_OBSERVABLES`: each as the frame recorded it (``recorded``,
    name -> (classes,)), or where it did not (absent: written before decco-warp recorded it; NaN in
    every class: a frame before a resume added it) of the frame's per-particle ``stress`` (its
    largest overlap) and the radii, which every trajectory holds."""
    shares = {}
    for name, measure in STRESS_SHARE_OBSERVABLES.items():
        value = recorded.get(name)
        if value is None or np.isnan(value).all():
            value = stress_shares(stress, size_class, classes, radii, measure)
        shares[name] = np.asarray(value)
    return shares

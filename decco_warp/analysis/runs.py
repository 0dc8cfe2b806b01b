"""Analysis of a run's trajectory: fragments, the paper's metrics, conservation and the energy ledger.

Reads ``trajectory.h5`` (never the simulation) and writes ``analysis.h5`` and
``summary.json`` in the run folder.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import h5py
import numpy as np

from ..diagnostics import energy_scale, ledger_closure
from ..io import read_trajectory, write_atomic
from ..params import G_CGS
from ..state import State
from .clusters import find_clusters
from .scaling import largest_mass_ratio as ls12_largest_mass_ratio

ENERGY_SERIES = (
    "kinetic_translational",
    "kinetic_rotational",
    "potential",
    "elastic",
    "total_energy",
    "dissipated_sliding",
    "dissipated_rolling",
    "dissipated_hysteresis",
    "integration_error",
)


def particle_size_change(cluster_mass: float, cluster_members: int, parents_mass: float, parents_count: int) -> float:
    """Paper Fig. 6: mean particle mass of a fragment over that of both piles before the collision, minus 1, in %."""
    return 100.0 * ((cluster_mass / cluster_members) / (parents_mass / parents_count) - 1.0)


#: |cos| of the angle between the two spin axes past which they count as (anti-)parallel, and below
#: which as perpendicular (the paper's Fig. 9 consolidates runs by these kinds).
SPIN_ALIGNED = 0.99


def spin_kind(target_spin, projectile_spin) -> str:
    """The paper's Fig. 9 kind of a collision's spins: "none", "target only", "projectile only",
    "parallel", "anti-parallel", "perpendicular" or "oblique" (any other angle)."""
    target = np.zeros(3) if target_spin is None else np.asarray(target_spin, dtype=float)
    projectile = np.zeros(3) if projectile_spin is None else np.asarray(projectile_spin, dtype=float)
    size_t, size_p = float(np.linalg.norm(target)), float(np.linalg.norm(projectile))
    if size_t == 0 or size_p == 0:
        return "none" if size_t == size_p else "target only" if size_p == 0 else "projectile only"
    cosine = float(target @ projectile) / (size_t * size_p)
    if cosine > SPIN_ALIGNED:
        return "parallel"
    if cosine < -SPIN_ALIGNED:
        return "anti-parallel"
    return "perpendicular" if abs(cosine) < 1 - SPIN_ALIGNED else "oblique"


def snapshot_state(data: dict, frame: int) -> State:
    static = data["static"]
    return State.from_arrays(
        data["particles"]["position"][frame],
        data["particles"]["velocity"][frame],
        data["particles"]["omega"][frame],
        static["radius"],
        static["mass"],
        pile_id=static["pile_id"].astype(np.int32),
        size_class=static["species"].astype(np.int32),
    )


def analyse_snapshot(state: State, target_mass: float, min_members: int = 50, G: float | None = None, device: str | None = None) -> dict:
    """Clusters of one snapshot with their properties, and the headline numbers (``device``: where
    the cluster finder's smoothed density is summed, see :func:`.clusters.smoothed_density`)."""
    kwargs = {} if G is None else {"G": G}
    clusters = find_clusters(state, min_members=min_members, device=device, **kwargs)
    classes = int(state.size_class.max()) + 1
    label = np.full(state.n, -1, dtype=np.int32)
    rows = []
    for k, cluster in enumerate(clusters):
        label[cluster.members] = k
        part = state.subset(cluster.members)
        rows.append(
            {
                "mass": cluster.mass,
                "members": cluster.members.size,
                "com": cluster.com,
                "velocity": cluster.velocity,
                "spin": part.spin(),
                "composition": np.bincount(part.size_class, minlength=classes)[:classes],
            }
        )
    largest = rows[0] if rows else None
    return {
        "clusters": rows,
        "label": label,
        "largest_mass_ratio": largest["mass"] / target_mass if largest else 0.0,
        "particle_size_change": (
            particle_size_change(largest["mass"], largest["members"], state.total_mass, state.n) if largest else np.nan
        ),
    }


def analyse_run(run_dir, min_members: int = 50, every: int = 1, progress=None, device: str | None = None) -> dict:
    """Analyse every ``every``-th frame of a run (and always the last); write analysis.h5 and summary.json.
    ``device``: as for :func:`analyse_snapshot`."""
    started = time.perf_counter()
    run_dir = Path(run_dir)
    data = read_trajectory(run_dir / "trajectory.h5")
    static = data["static"]
    spec = data["parameters"].get("spec", {})
    G = spec.get("params", {}).get("G")
    target = static["pile_id"] == 0
    target_mass = float(static["mass"][target].sum())
    frames = list(range(0, len(data["step"]), max(1, every)))
    if frames[-1] != len(data["step"]) - 1:
        frames.append(len(data["step"]) - 1)

    ratio, size_change, n_clusters = [], [], []
    for done, frame in enumerate(frames):
        result = analyse_snapshot(snapshot_state(data, frame), target_mass, min_members, G, device)
        ratio.append(result["largest_mass_ratio"])
        size_change.append(result["particle_size_change"])
        n_clusters.append(len(result["clusters"]))
        if progress is not None:
            progress(done + 1, len(frames))
    final = result

    obs = data["observables"]
    # Trajectories written before decco-warp 0.2 have no deepest_overlap series.
    depth = obs.get("deepest_overlap", np.full(len(data["time"]), np.nan))
    deepest_frame = int(np.nanargmax(depth)) if np.isfinite(depth).any() else 0
    first = snapshot_state(data, 0)
    p_scale = float(np.linalg.norm(first.masses[:, None] * first.velocities, axis=1).sum())
    orbital = first.masses[:, None] * np.cross(first.positions, first.velocities)
    l_scale = float(np.linalg.norm(orbital, axis=1).sum() + np.linalg.norm(first.inertia[:, None] * first.omegas, axis=1).sum())
    analysis = {
        "frames": {
            "step": data["step"][frames],
            "time": data["time"][frames],
            "largest_mass_ratio": np.array(ratio),
            "particle_size_change": np.array(size_change),
            "clusters": np.array(n_clusters),
        },
        "conservation": {
            "time": data["time"],
            "momentum_drift": np.linalg.norm(obs["momentum"] - obs["momentum"][0], axis=1) / p_scale,
            "angular_momentum_drift": np.linalg.norm(obs["angular_momentum"] - obs["angular_momentum"][0], axis=1) / l_scale,
        },
        "stress_share": {"time": data["time"], "value": obs["stress_share"]},
        "energy": {
            "time": data["time"],
            **{name: obs[name] for name in ENERGY_SERIES},
            "ledger_closure": ledger_closure(obs, obs["total_energy"][0], energy_scale(_start_energies(obs))),
        },
        "overlap": {"time": data["time"], "deepest": depth},
        "final": {
            "step": int(data["step"][-1]),
            "time": float(data["time"][-1]),
            "label": final["label"],
            "positions": data["particles"]["position"][-1],
            "radius": static["radius"],
            "mass": np.array([c["mass"] for c in final["clusters"]]),
            "members": np.array([c["members"] for c in final["clusters"]], dtype=np.int64),
            "com": np.array([c["com"] for c in final["clusters"]]).reshape(-1, 3),
            "velocity": np.array([c["velocity"] for c in final["clusters"]]).reshape(-1, 3),
            "spin": np.array([c["spin"] for c in final["clusters"]]).reshape(-1, 3),
            "composition": np.array([c["composition"] for c in final["clusters"]], dtype=np.int64).reshape(
                len(final["clusters"]), int(static["species"].max()) + 1
            ),
        },
    }
    collision = data["parameters"].get("collision", {})
    params = spec.get("params", {})
    summary = {
        "run": run_dir.name,
        "n_particles": int(static["radius"].shape[0]),
        "eta": collision.get("eta"),
        "speed": collision.get("speed"),
        "theta_deg": collision.get("theta_deg"),
        "spin_kind": spin_kind(collision.get("target_spin"), collision.get("projectile_spin")) if collision else None,
        "orientation_seed": int(collision["orientation_seed"]) if "orientation_seed" in collision else None,
        "mass_ratio": (collision.get("projectile_mass", np.nan) / collision.get("target_mass", np.nan)) if collision else None,
        "target_mass": target_mass,
        "k_in": params.get("k_in"),
        "dt": params.get("dt"),
        "steps": int(data["step"][-1]),
        "final_time": float(data["time"][-1]),
        "largest_mass_ratio": float(ratio[-1]),
        "ls12_largest_mass_ratio": _ls12(collision, G),
        "particle_size_change": float(size_change[-1]),
        "clusters": int(n_clusters[-1]),
        "deepest_overlap": float(depth[deepest_frame]),
        "deepest_overlap_time": float(data["time"][deepest_frame]),
        "predicted_overlap": data["parameters"].get("stability", {}).get("predicted_overlap"),
        "momentum_drift": float(analysis["conservation"]["momentum_drift"].max()),
        "angular_momentum_drift": float(analysis["conservation"]["angular_momentum_drift"].max()),
        "ledger_closure": float(np.abs(analysis["energy"]["ledger_closure"]).max()),
        "min_members": int(min_members),
        "analyse_every": int(every),
    }
    summary = {k: (float(v) if isinstance(v, np.floating) else v) for k, v in summary.items()}
    # Kept with the summary, so that a sweep that finds the run analysed reports what it took then.
    summary["analysis_seconds"] = round(time.perf_counter() - started, 3)
    analysis["summary"] = summary
    write_analysis(run_dir / "analysis.h5", analysis)
    write_atomic(run_dir / "summary.json", json.dumps(summary, indent=2) + "\n")
    return analysis


def _ls12(collision: dict, G) -> float | None:
    """The Leinhardt & Stewart (2012) m_lf/m_t for the run's set-up (None without its metadata)."""
    needed = ("target_mass", "projectile_mass", "target_radius", "projectile_radius", "theta_deg", "kinetic_energy")
    if not all(key in collision for key in needed):
        return None
    return float(ls12_largest_mass_ratio(collision, G_CGS if G is None else G))


def _start_energies(observables: dict) -> dict:
    return {name: float(observables[name][0]) for name in ("potential", "total_energy")}


def write_analysis(path: Path, analysis: dict) -> None:
    from ..io import atomic_h5

    with atomic_h5(path) as f:
        for group, values in analysis.items():
            if group == "summary":
                for key, value in values.items():
                    if value is not None:
                        f.attrs[key] = value
                continue
            g = f.create_group(group)
            for key, value in values.items():
                g.create_dataset(key, data=np.asarray(value))


def read_analysis(path) -> dict:
    with h5py.File(path, "r") as f:
        result = {name: {key: f[name][key][()] for key in f[name]} for name in f}
        result["summary"] = {key: (v.item() if isinstance(v, np.generic) else v) for key, v in f.attrs.items()}
    return result

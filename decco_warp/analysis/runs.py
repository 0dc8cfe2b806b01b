"""Analysis of a run's trajectory: fragments, the paper's metrics, conservation and the energy ledger.

Reads ``trajectory.h5`` (never the simulation) and writes ``analysis.h5`` and
``summary.json`` in the run folder.
"""

from __future__ import annotations

import time
from pathlib import Path

import h5py
import numpy as np

from ..diagnostics import STRESS_SHARE_OBSERVABLES, energy_scale, ledger_closure, recorded_stress_shares, stress_share_classes
from ..durable import json_ready, json_text, write_atomic
from ..folder import RunFolder
from ..io import OBSERVABLE_UNITS, read_frames, read_trajectory
from ..params import G_CGS
from ..processes import can_start_processes, in_processes, usable_cores
from ..sizes import class_ranges
from ..state import State
from . import scaling
from .clusters import find_clusters

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


#: A size change below this [%] is the round-off of a ratio of sums (a fragment of the same grains
#: as its parents reads +2.2e-14 %): it is 0.
SIZE_CHANGE_ROUND_OFF = 1e-8


def _percent_change(ratio: float) -> float:
    change = 100.0 * (ratio - 1.0)
    return 0.0 if abs(change) < SIZE_CHANGE_ROUND_OFF else float(change)


def particle_size_change(cluster_mass: float, cluster_members: int, parents_mass: float, parents_count: int) -> float:
    """Paper Fig. 6: mean particle mass of a fragment over that of both piles before the collision, minus 1, in %."""
    return _percent_change((cluster_mass / cluster_members) / (parents_mass / parents_count))


def mass_weighted_size_change(cluster_masses: np.ndarray, parents_masses: np.ndarray) -> float:
    """Fig. 6 weighted by mass: the mass-weighted mean particle mass (sum m^2 / sum m) of a fragment
    over that of both piles before the collision, minus 1, in %.  It follows where the mass sits
    (a grain's weight is its mass), where the paper's per-particle mean follows the grain count."""
    return _percent_change((cluster_masses @ cluster_masses / cluster_masses.sum()) / (parents_masses @ parents_masses / parents_masses.sum()))


#: The late window of a run: its last LATE_FRACTION of simulated time.  Size changes are averaged
#: over it, and a run is settled when its outcome holds still there.
LATE_FRACTION = 0.1
#: A run is settled when, over the analysed frames of its late window, m_lf/m_t moves by at most this
#: (a fraction of the target's mass) and the number of clusters stays the same.
SETTLED_TOLERANCE = 0.01
#: Fewer analysed frames than this in the late window cannot show that a run is settled.
SETTLED_MIN_FRAMES = 3


def late_window(time: np.ndarray, start: float | None = None) -> np.ndarray:
    """Indices of the frames (at ``time``) in the last LATE_FRACTION of the run's simulated time,
    which began at ``start`` (default: the first frame's time)."""
    time = np.asarray(time, dtype=float)
    if time.size == 0:
        return np.zeros(0, dtype=np.int64)
    start = time[0] if start is None else start
    return np.flatnonzero(time >= time[-1] - LATE_FRACTION * (time[-1] - start))


def late_statistics(frames: dict, target_mass: float | None = None, start: float | None = None) -> dict:
    """Over the late window of a run's analysed frames: the mean and spread (standard deviation) of
    each size change, the range of m_lf/m_t, and the verdict ``settled`` with its ``settled_note``.

    The fragment set counted is the clusters of at least SETTLED_TOLERANCE of the target's mass
    (``target_mass``, with the frames' ``cluster_mass``); without those, every cluster, so that one
    of ~``min_members`` grains gaining and losing a member counts as a change.  ``start``: when the
    run began (default: the first frame's time)."""
    late = late_window(frames["time"], start)
    ratio = np.asarray(frames["largest_mass_ratio"], dtype=float)[late]
    if "cluster_mass" in frames and target_mass:
        fragments = (np.asarray(frames["cluster_mass"])[late] >= SETTLED_TOLERANCE * target_mass).sum(axis=1)
        kind = f"fragment(s) of >= {SETTLED_TOLERANCE:g} m_t"
    else:
        fragments, kind = np.asarray(frames["clusters"])[late], "cluster(s)"
    stats = {"late_frames": int(late.size), "late_from_time": float(frames["time"][late[0]]) if late.size else None}
    for column, series in (("size_change_late", "particle_size_change"), ("size_change_mass_weighted_late", "particle_size_change_mass_weighted")):
        values = np.asarray(frames[series], dtype=float)[late] if series in frames else np.full(late.size, np.nan)
        values = values[np.isfinite(values)]
        stats[column] = float(values.mean()) if values.size else None
        stats[f"{column}_std"] = spread(values) if values.size else None
    stats["largest_mass_ratio_late_low"] = float(ratio.min()) if ratio.size else None
    stats["largest_mass_ratio_late_high"] = float(ratio.max()) if ratio.size else None
    stats.update(settled_verdict(ratio, fragments, kind, stats["late_from_time"]))
    return stats


def spread(values: np.ndarray) -> float:
    """The standard deviation of ``values``, 0 where they do not differ beyond round-off (the mean of
    equal numbers is not always that number in floating point: their std would read 3.6e-15)."""
    values = np.asarray(values, dtype=float)
    if values.size == 0 or np.ptp(values) <= ROUND_OFF * float(np.abs(values).max()):
        return 0.0
    return float(values.std())


#: Relative differences below this are floating-point round-off, not a spread.
ROUND_OFF = 1e-12


def settled_verdict(ratio: np.ndarray, fragments: np.ndarray, kind: str, since: float | None) -> dict:
    """``settled`` and the numbers behind it (``settled_note``) for the late window's frames:
    m_lf/m_t (``ratio``) and the count of ``fragments`` (what they are: ``kind``) per frame."""
    frames = ratio.size
    if frames < SETTLED_MIN_FRAMES:
        return {"settled": False, "settled_note": f"{frames} analysed frame(s) in the last {LATE_FRACTION:.0%} of the run; "
                f"at least {SETTLED_MIN_FRAMES} are needed to judge (analyse more frames, or run longer)"}  # fmt: skip
    window = f"over the last {frames} analysed frames (t >= {since:.6g} s)"
    counts = sorted({int(c) for c in fragments})
    if (ratio <= 0).any():
        return {"settled": False, "settled_note": f"no cluster in {int((ratio <= 0).sum())} of the {frames} frames {window}"}
    shown = f"{counts[0]} to {counts[-1]} {kind}" if len(counts) > 1 else f"{counts[0]} {kind}"
    spread = float(ratio.max() - ratio.min())
    if spread > SETTLED_TOLERANCE or len(counts) > 1:
        return {"settled": False, "settled_note": f"m_lf/m_t {ratio.min():.4g} to {ratio.max():.4g} and {shown} {window}"}
    return {"settled": True, "settled_note": f"m_lf/m_t {ratio.min():.4g} to {ratio.max():.4g} (within {SETTLED_TOLERANCE:g}) and {shown} {window}"}


def outcome_text(summary: dict) -> str:
    """A run's result in one line (as ``analyze`` and ``sweep`` print it): m_lf/m_t, the size change
    over the late window, the clusters, and whether the result is final (settled) or not, with the
    numbers that say so."""
    text = f"m_lf/m_t {summary['largest_mass_ratio']:.4g}"
    change, spread = summary.get("size_change_late"), summary.get("size_change_late_std")
    if change is not None:
        text += f", particle size change {change:+.3g} %" + (f" (+- {spread:.2g}, late mean)" if spread is not None else "")
    text += f", {summary['clusters']} cluster(s)"
    if "settled" in summary:
        text += ", settled" if summary["settled"] else f", NOT SETTLED ({summary['settled_note']})"
    return text


#: Significant digits of a ratio computed back from the set-up (eta): a set-up for eta 3 gives
#: KE / |U| = 2.9999999999999996, which the summary keeps as 3.
RATIO_DIGITS = 12


def rounded(value) -> float | None:
    """``value`` to RATIO_DIGITS significant digits (None stays None)."""
    return None if value is None else float(f"{float(value):.{RATIO_DIGITS}g}")


def eta_readings(collision: dict) -> dict:
    """Both readings of eq. 18 for a collision record (docs/model.md): ``eta_self`` (U of each pile's
    own pairs) and ``eta_all`` (U of every pair at set-up), with the reading the run was set up by
    and the cross term [erg].  Records older than the two readings hold the potentials: eta_all is
    computed from them, the reading is "self"."""
    if not all(key in collision for key in ("kinetic_energy", "target_potential", "projectile_potential", "cross_potential")):
        return {"eta_potential": collision.get("eta_potential"), "eta_self": rounded(collision.get("eta")), "eta_all": None, "cross_potential": None}
    own = collision["target_potential"] + collision["projectile_potential"]
    return {
        "eta_potential": collision.get("eta_potential", "self"),
        "eta_self": rounded(collision["kinetic_energy"] / abs(own)),
        "eta_all": rounded(collision["kinetic_energy"] / abs(own + collision["cross_potential"])),
        "cross_potential": float(collision["cross_potential"]),
    }


def contact_motion(collision: dict) -> dict:
    """:func:`decco_warp.collision.first_contact_motion` of a collision record (None each without it)."""
    from ..collision import first_contact_motion

    keys = ("contact_surface_speed", "contact_twist_rate")
    if all(key in collision for key in keys):
        return {key: float(collision[key]) for key in keys}
    needed = ("theta_deg", "target_spin", "projectile_spin", "target_radius", "projectile_radius")
    return first_contact_motion(collision) if all(key in collision for key in needed) else dict.fromkeys(keys)


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


def ellipsoid_axes(part: State) -> np.ndarray:
    """Semi-axes a >= b >= c [cm] of the uniform ellipsoid with a cluster's mass and inertia tensor
    about its centre of mass (the grains' own spins' inertia included): from the principal moments
    I1 <= I2 <= I3, a^2 = 5 (I2 + I3 - I1) / (2 M) and so on."""
    i1, i2, i3 = np.linalg.eigvalsh(part.inertia_tensor())
    scale = 5.0 / (2.0 * part.total_mass)
    return np.sqrt(np.maximum(scale * np.array([i2 + i3 - i1, i1 + i3 - i2, i1 + i2 - i3]), 0.0))


def analyse_snapshot(state: State, target_mass: float, min_members: int = 50, G: float | None = None, device: str | None = None) -> dict:
    """Clusters of one snapshot with their properties, and the headline numbers (``device``: where
    the cluster finder's smoothed density is summed, see :func:`.clusters.smoothed_density`).
    Without a cluster, m_lf/m_t is 0 and the size changes are NaN (no fragment to measure)."""
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
                "axes": ellipsoid_axes(part),
            }
        )
    largest = rows[0] if rows else None
    return {
        "clusters": rows,
        "label": label,
        "largest_mass_ratio": largest["mass"] / target_mass if largest else 0.0,
        "largest_composition": largest["composition"] if largest else np.zeros(classes, dtype=np.int64),
        "free_composition": np.bincount(state.size_class[label < 0], minlength=classes)[:classes],
        "particle_size_change": (
            particle_size_change(largest["mass"], largest["members"], state.total_mass, state.n) if largest else np.nan
        ),
        "particle_size_change_mass_weighted": (
            mass_weighted_size_change(state.masses[clusters[0].members], state.masses) if largest else np.nan
        ),
    }


#: The per-frame series of :func:`analyse_snapshot` that analysis.h5 keeps under /frames.
FRAME_SERIES = (
    "largest_mass_ratio", "particle_size_change", "particle_size_change_mass_weighted", "largest_composition", "free_composition", "label",
)  # fmt: skip


def catalogue_rows(frame: int, step: int, time_s: float, clusters: list[dict]) -> dict[str, list]:
    """The fragment catalogue's rows of one analysed frame: a row per cluster (largest first)."""
    rows: dict[str, list] = {name: [] for name in CATALOGUE_UNITS}
    for k, c in enumerate(clusters):
        a, b, axis_c = c["axes"]
        omega = np.asarray(c["spin"], dtype=float)
        values = {
            "frame": frame, "step": step, "time": time_s, "cluster": k, "mass": c["mass"], "members": c["members"],
            "com": c["com"], "velocity": c["velocity"], "omega": omega, "spin_rate": float(np.linalg.norm(omega)),
            "semi_axes": np.array([a, b, axis_c]), "axis_ratio_b_a": b / a if a > 0 else np.nan,
            "axis_ratio_c_a": axis_c / a if a > 0 else np.nan,
            "bulk_density": c["mass"] / (4.0 / 3.0 * np.pi * a * b * axis_c) if a * b * axis_c > 0 else np.nan,
            "composition": c["composition"],
        }  # fmt: skip
        for name, value in values.items():
            rows[name].append(value)
    return rows


#: The fragment catalogue (analysis.h5 /catalogue): a row per cluster per analysed frame, columns
#: with their units.  ``read_catalogue`` gives it as columns for ``pandas.DataFrame``.
CATALOGUE_UNITS = {
    "frame": "index of the trajectory's frame",
    "step": "1",
    "time": "s",
    "cluster": "rank in its frame, largest first",
    "mass": "g",
    "members": "particles",
    "com": "cm",
    "velocity": "cm s-1",
    "omega": "rad s-1 (rigid-body spin about the centre of mass)",
    "spin_rate": "rad s-1",
    "semi_axes": "cm (a >= b >= c of the ellipsoid with the cluster's inertia)",
    "axis_ratio_b_a": "1",
    "axis_ratio_c_a": "1",
    "bulk_density": "g cm-3 (mass over that ellipsoid's volume)",
    "composition": "particles per size class",
}


def _padded(rows: list[np.ndarray]) -> np.ndarray:
    """Rows of different lengths as one array, padded with zeros (frames x most clusters)."""
    out = np.zeros((len(rows), max([len(r) for r in rows] + [1])))
    for k, row in enumerate(rows):
        out[k, : len(row)] = row
    return out


def _analyse_frames(data: dict, trajectory, frames: list[int], target_mass: float, min_members: int, G, device,
                    progress=None, workers: int = 1) -> tuple[dict, dict, dict]:  # fmt: skip
    """The /frames series and the /catalogue of the frames ``frames`` of the file ``trajectory``
    (``data``: its steps, times and particles' constants), and the last frame's full result
    (:func:`analyse_snapshot`), the frames read a share at a time; ``workers`` > 1: analysed in that
    many processes, each reading its frames itself, their results merged here in frame order (the
    same numbers as here, frame by frame)."""
    if workers > 1:
        args = (str(trajectory), target_mass, min_members, G, device)
        results = in_processes(_analyse_chunk, frames, args, workers, CHUNKS_PER_WORKER, progress)
    else:
        results = _analysed_here(trajectory, frames, target_mass, min_members, G, device, progress)
    series: dict[str, list] = {name: [] for name in FRAME_SERIES}
    n_clusters, cluster_masses = [], []
    catalogue: dict[str, list] = {name: [] for name in CATALOGUE_UNITS}
    result = None
    for frame, result in zip(frames, results):
        for name in FRAME_SERIES:
            series[name].append(result[name])
        for name, values in catalogue_rows(frame, int(data["step"][frame]), float(data["time"][frame]), result["clusters"]).items():
            catalogue[name] += values
        n_clusters.append(len(result["clusters"]))
        cluster_masses.append(np.array([c["mass"] for c in result["clusters"]]))
    arrays = {"step": data["step"][frames], "time": data["time"][frames], **{name: np.array(values) for name, values in series.items()}}
    arrays.update(clusters=np.array(n_clusters), cluster_mass=_padded(cluster_masses))
    classes = int(data["static"]["species"].max()) + 1
    empty = {"com": (0, 3), "velocity": (0, 3), "omega": (0, 3), "semi_axes": (0, 3), "composition": (0, classes)}
    catalogue = {name: np.array(values) if values else np.zeros(empty.get(name, (0,))) for name, values in catalogue.items()}
    return arrays, catalogue, result


def _analysed_here(trajectory, frames: list[int], target_mass: float, min_members: int, G, device, progress=None):
    """:func:`analyse_snapshot` of each of the frames, in this process, one after the other, read
    HERE_CHUNK frames at a time (a run's frames whole would not fit a laptop's memory)."""
    for start in range(0, len(frames), HERE_CHUNK):
        chunk = frames[start : start + HERE_CHUNK]
        for done, result in enumerate(_analyse_chunk(chunk, str(trajectory), target_mass, min_members, G, device), start + 1):
            yield result
            if progress is not None:
                progress(done, len(frames))


def _analyse_chunk(frames: list[int], trajectory: str, target_mass: float, min_members: int, G, device) -> list[dict]:
    """:func:`analyse_snapshot` of the frames ``frames`` of the trajectory file ``trajectory``, read
    here: a worker's share, or a read's worth of a run analysed in its own process (:func:`_analyse_frames`)."""
    particles, static = read_frames(trajectory, frames)
    data = {"particles": particles, "static": static}
    return [analyse_snapshot(snapshot_state(data, k), target_mass, min_members, G, device) for k in range(len(frames))]


#: Frames read at once where a run is analysed in its own process.
HERE_CHUNK = 16
#: A run of fewer particle-frames (frames x particles) than this is analysed in its own process: a
#: worker takes ~1.5 s to start (Python, NumPy, SciPy, Warp; a CUDA context more), where the frames
#: of a few hundred particles take milliseconds each.
PARALLEL_MIN_WORK = 200_000
#: Chunks of frames per worker: the progress moves as each ends, and the worker that drew the debris
#: just after impact (the slow frames) does not hold the others up.
CHUNKS_PER_WORKER = 4
#: At most this many workers sum the density on one GPU: each holds a CUDA context (~0.3 to 0.5 GB
#: of its memory), and 16 keep a 16-core machine's GPU ahead of their cluster finders.
MAX_GPU_WORKERS = 16


def frame_workers(frames: int, particles: int, workers: int | None = None, device: str | None = None) -> int:
    """How many processes analyse a run's ``frames`` frames of ``particles`` particles: ``workers``
    where given (at most one a frame), else one a core this process may use (:func:`usable_cores`,
    MAX_GPU_WORKERS with ``device`` a GPU), or 1 (here) for a run of less than PARALLEL_MIN_WORK or
    a process that may not start processes."""
    if workers is not None:
        return max(1, min(int(workers), frames))
    if frames * particles < PARALLEL_MIN_WORK or not can_start_processes():
        return 1
    chosen = usable_cores()
    if device is not None and str(device).startswith("cuda"):
        chosen = min(chosen, MAX_GPU_WORKERS)
    return max(1, min(chosen, frames))


def late_verdict(run_dir, min_members: int = 50, device: str | None = None, workers: int | None = None) -> dict:
    """:func:`late_statistics` of a run as its trajectory stands, from the frames of its late window
    only (what ``resume --until-settled`` asks after each extension); writes nothing.  ``workers``:
    as for :func:`analyse_run`."""
    trajectory = RunFolder(run_dir).trajectory
    data = read_trajectory(trajectory, particle_frames=[])  # the frames are read a share at a time
    target_mass = float(data["static"]["mass"][data["static"]["pile_id"] == 0].sum())
    G = data["parameters"].get("spec", {}).get("params", {}).get("G")
    late = late_window(data["time"]).tolist()
    workers = frame_workers(len(late), len(data["static"]["mass"]), workers, device)
    frames, _, _ = _analyse_frames(data, trajectory, late, target_mass, min_members, G, device, workers=workers)
    late = late_statistics(frames, target_mass, start=float(data["time"][0]))
    return {"steps": int(data["step"][-1]), "time": float(data["time"][-1]), **late}


def analyse_run(run_dir, min_members: int = 50, every: int = 1, progress=None, device: str | None = None, workers: int | None = None) -> dict:
    """Analyse every ``every``-th frame of a run (and always the last); write analysis.h5 and summary.json.
    ``device``: as for :func:`analyse_snapshot`; ``workers``: processes that analyse the frames side
    by side (:func:`frame_workers`; default chosen from the cores and the run's size; 1: here).
    ``progress(frames done, frames in all)``."""
    started = time.perf_counter()
    run_dir = Path(run_dir)
    trajectory = RunFolder(run_dir).trajectory
    # The first and the last frame's particles here (the scales, the final state); the frames
    # analysed are read a share at a time.
    data = read_trajectory(trajectory, particle_frames=[0, -1])
    static = data["static"]
    spec = data["parameters"].get("spec", {})
    G = spec.get("params", {}).get("G")
    target = static["pile_id"] == 0
    target_mass = float(static["mass"][target].sum())
    frames = list(range(0, len(data["step"]), max(1, every)))
    if frames[-1] != len(data["step"]) - 1:
        frames.append(len(data["step"]) - 1)

    workers = frame_workers(len(frames), len(static["mass"]), workers, device)
    series, catalogue, final = _analyse_frames(data, trajectory, frames, target_mass, min_members, G, device, progress, workers)

    obs = data["observables"]
    # Trajectories written before decco-warp 0.2 have no deepest_overlap series.
    depth = obs.get("deepest_overlap", np.full(len(data["time"]), np.nan))
    first = snapshot_state(data, 0)
    p_scale = float(np.linalg.norm(first.masses[:, None] * first.velocities, axis=1).sum())
    orbital = first.masses[:, None] * np.cross(first.positions, first.velocities)
    l_scale = float(np.linalg.norm(orbital, axis=1).sum() + np.linalg.norm(first.inertia[:, None] * first.omegas, axis=1).sum())
    classes = int(static["species"].max()) + 1
    analysis = {
        "frames": series,
        "catalogue": catalogue,
        "conservation": {
            "time": data["time"],
            "momentum_drift": np.linalg.norm(obs["momentum"] - obs["momentum"][0], axis=1) / p_scale,
            "angular_momentum_drift": np.linalg.norm(obs["angular_momentum"] - obs["angular_momentum"][0], axis=1) / l_scale,
        },
        # The top 1 % by largest overlap (the paper's Fig. 8), by overlap / R^2 and by overlap / R.
        **{name: {"time": data["time"], "value": value} for name, value in stress_share_series(data, trajectory).items()},
        "energy": {
            "time": data["time"],
            **{name: obs[name] for name in ENERGY_SERIES},
            "ledger_closure": ledger_closure(obs, obs["total_energy"][0], energy_scale(_start_energies(obs))),
        },
        "overlap": {"time": data["time"], "deepest": depth},
        # The bins the compositions and stress shares count by, as the particles fill them: one per
        # size for discrete radii, log-R bins for continuous ones (sizes.py).
        "size_classes": class_ranges(static["radius"], static["species"]),
        "final": {
            "step": int(data["step"][-1]),
            "time": float(data["time"][-1]),
            "label": final["label"],
            "positions": data["particles"]["position"][-1],
            "velocities": data["particles"]["velocity"][-1],
            "radius": static["radius"],
            "particle_mass": static["mass"],
            "size_class": static["species"],
            "mass": np.array([c["mass"] for c in final["clusters"]]),
            "members": np.array([c["members"] for c in final["clusters"]], dtype=np.int64),
            "com": np.array([c["com"] for c in final["clusters"]]).reshape(-1, 3),
            "velocity": np.array([c["velocity"] for c in final["clusters"]]).reshape(-1, 3),
            "spin": np.array([c["spin"] for c in final["clusters"]]).reshape(-1, 3),
            "composition": np.array([c["composition"] for c in final["clusters"]], dtype=np.int64).reshape(len(final["clusters"]), classes),
        },
    }
    summary = summarise(
        run_dir.name,
        analysis,
        collision=data["parameters"].get("collision", {}),
        params=spec.get("params", {}),
        n_particles=int(static["radius"].shape[0]),
        target_mass=target_mass,
        predicted_overlap=data["parameters"].get("stability", {}).get("predicted_overlap"),
        min_members=min_members,
        every=every,
        piles=spec.get("piles"),
        spec=spec,
    )
    # Kept with the summary, so that a sweep that finds the run analysed reports what it took then.
    summary["analysis_seconds"] = round(time.perf_counter() - started, 3)
    _write_results(run_dir, analysis, summary)
    return analysis


#: Frames of per-particle stress read at once where a trajectory lacks a stress share.
STRESS_CHUNK = 64


def stress_share_series(data, trajectory) -> dict[str, np.ndarray]:
    """Each of :data:`STRESS_SHARE_OBSERVABLES` at every frame (F, classes), by
    :func:`recorded_stress_shares`: the per-particle stress of only the frames that lack one is read,
    STRESS_CHUNK frames at a time."""
    obs, static = data["observables"], data["static"]
    frames = len(data["time"])
    classes = stress_share_classes(obs, static["species"])
    series = {name: np.array(obs[name], dtype=float) if name in obs else np.full((frames, classes), np.nan) for name in STRESS_SHARE_OBSERVABLES}
    wanted = np.flatnonzero(np.any([np.isnan(value).all(axis=1) for value in series.values()], axis=0)).tolist()
    for start in range(0, len(wanted), STRESS_CHUNK):
        chunk = wanted[start : start + STRESS_CHUNK]
        stress = read_frames(trajectory, chunk, elements=("stress",))[0]["stress"]
        for row, frame in zip(stress, chunk):
            recorded = {name: value[frame] for name, value in series.items()}
            for name, value in recorded_stress_shares(recorded, row, static["radius"], static["species"], classes).items():
                series[name][frame] = value
    return series


def _write_results(run_dir, analysis: dict, summary: dict) -> None:
    """A run's analysis.h5 (the summary within it) and summary.json."""
    folder = RunFolder(run_dir)
    analysis["summary"] = summary
    write_analysis(folder.analysis, analysis)
    write_atomic(folder.summary, json_text(summary))


#: A resolved specification's keys that a summary does not carry as columns of their own: the run's
#: name is ``run``, its folder's parent is not the run's, and the piles' files are named by their
#: stems (``target_pile``, ``projectile_pile``).
NOT_COLUMNS = {("run", "name"), ("run", "out"), ("piles", "target"), ("piles", "projectile")}
#: Keys whose column bears another name, since a summary's own column of that name means another
#: thing (a sweep's ``device`` is where the run went, [run] device what it asked for).
RENAMED = {("run", "device"): "run_device"}


def spec_column(table: str, key: str) -> str | None:
    """The summary column of a specification's ``[table] key`` (None: not a column of its own)."""
    if (table, key) in NOT_COLUMNS:
        return {"target": "target_pile", "projectile": "projectile_pile"}.get(key) if table == "piles" else None
    return RENAMED.get((table, key), key)


def spec_columns(spec: dict) -> dict:
    """The columns of a resolved specification: every key of [params] (every physics parameter of the
    run, the contact law's included), of [collision] and of [run] but those of NOT_COLUMNS, by
    :func:`spec_column`'s names, so that whatever a sweep varies is a column of the run's summary."""
    columns = {}
    for table in ("params", "collision", "run"):
        for key, value in (spec.get(table) or {}).items():
            column = spec_column(table, key)
            if column is not None and (table, key) not in NOT_COLUMNS:
                columns[column] = list(value) if isinstance(value, tuple) else value
    return columns


def summarise(name: str, analysis: dict, collision: dict, params: dict, n_particles: int, target_mass: float,
              predicted_overlap, min_members: int, every: int, piles: dict | None = None, spec: dict | None = None) -> dict:  # fmt: skip
    """A run's summary row from its analysis (the /frames, /conservation, /energy and /overlap
    series) and its set-up (``collision``: the set-up's metadata; ``params``: the resolved [params];
    ``piles``: the resolved [piles], whose files name the realization's piles; ``spec``: the whole
    resolved specification, whose keys join as :func:`spec_columns`, after the outcome's own).
    Numbers that do not exist (no fragment to measure, a record without the set-up) are None."""
    frames = analysis["frames"]
    depth = np.asarray(analysis["overlap"]["deepest"], dtype=float)
    deepest_frame = int(np.nanargmax(depth)) if np.isfinite(depth).any() else 0
    G = params.get("G")
    summary = {
        "run": name,
        "n_particles": n_particles,
        "eta": rounded(collision.get("eta")),
        **eta_readings(collision),
        "speed": collision.get("speed"),
        "theta_deg": collision.get("theta_deg"),
        "spin_kind": spin_kind(collision.get("target_spin"), collision.get("projectile_spin")) if collision else None,
        **contact_motion(collision),
        "orientation_seed": int(collision["orientation_seed"]) if "orientation_seed" in collision else None,
        "mass_ratio": (collision["projectile_mass"] / collision["target_mass"]) if "projectile_mass" in collision else None,
        "target_pile": Path(piles["target"]).stem if piles else None,
        "projectile_pile": Path(piles["projectile"]).stem if piles else None,
        "target_mass": target_mass,
        "k_in": params.get("k_in"),
        "dt": params.get("dt"),
        # The clock of gravity (a run made before it existed: 1, the paper's scheme).
        "gravity_every": params.get("gravity_every", 1) if params else None,
        "steps": int(frames["step"][-1]),
        "final_time": float(frames["time"][-1]),
        "largest_mass_ratio": float(frames["largest_mass_ratio"][-1]),
        **scaling.law_columns(collision, G_CGS if G is None else G),
        **scaling.impact_columns(collision, G_CGS if G is None else G),
        "particle_size_change": float(frames["particle_size_change"][-1]),
        "particle_size_change_mass_weighted": (
            float(frames["particle_size_change_mass_weighted"][-1]) if "particle_size_change_mass_weighted" in frames else None
        ),
        **late_statistics(frames, target_mass),
        "clusters": int(frames["clusters"][-1]),
        "deepest_overlap": float(depth[deepest_frame]),
        "deepest_overlap_time": float(analysis["overlap"]["time"][deepest_frame]),
        "predicted_overlap": predicted_overlap,
        "momentum_drift": float(np.max(analysis["conservation"]["momentum_drift"])),
        "angular_momentum_drift": float(np.max(analysis["conservation"]["angular_momentum_drift"])),
        "ledger_closure": float(np.abs(analysis["energy"]["ledger_closure"]).max()),
        "min_members": int(min_members),
        "analyze_every": int(every),
    }
    for column, value in spec_columns({**(spec or {}), "params": {**(spec or {}).get("params", {}), **params}}).items():
        summary.setdefault(column, value)  # the outcome's own columns (eta, speed, steps: what the run made) stand
    return json_ready(summary)


def _start_energies(observables: dict) -> dict:
    return {name: float(observables[name][0]) for name in ("potential", "total_energy")}


#: Units of analysis.h5's datasets (HDF5 attribute "unit"; docs/data.md says what each holds).
ANALYSIS_UNITS = {
    "time": "s",
    "step": "1",
    "largest_mass_ratio": "1 (of the target's mass)",
    "particle_size_change": "%",
    "particle_size_change_mass_weighted": "%",
    "largest_composition": "particles per size class",
    "label": "cluster index, largest first (-1: in no cluster)",
    "clusters": "1",
    "momentum_drift": "1 (of sum m|v| at t = 0)",
    "angular_momentum_drift": "1 (of sum |m x cross v| + |I w| at t = 0)",
    "value": "1 (100 N_top / N per size class)",
    "ledger_closure": "1 (of |U| + KE at t = 0)",
    "deepest": "1 (of the smaller radius of the pair)",
    "positions": "cm",
    "velocities": "cm s-1",
    "radius": "cm",
    "particle_mass": "g",
    "size_class": "index (0: smallest radius)",
    "mass": "g",
    "members": "particles",
    "com": "cm",
    "velocity": "cm s-1",
    "spin": "rad s-1",
    "composition": "particles per size class",
    "free_composition": "particles per size class, in no cluster",
    "cluster_mass": "g (each frame's clusters, largest first; 0: none)",
    "radius_min": "cm (the smallest radius among the size class's particles)",
    "radius_max": "cm (the largest radius among the size class's particles)",
    "count": "particles (of the size class)",
    **{name: OBSERVABLE_UNITS[name] for name in ENERGY_SERIES},
}


#: Datasets of analysis.h5 below this many bytes are stored whole (a chunk index would cost more than
#: compression saves), larger ones in one gzip-compressed, byte-shuffled chunk: in HDF5's latest
#: format a single chunk's index is small, and a ~200-frame float64 series shrinks by ~20 % (measured
#: on 12 committed runs: 930 -> 743 kB, against 4 kB whole at gzip 6: 935 kB).
WHOLE_BELOW_BYTES = 256


def dataset_storage(value: np.ndarray) -> dict:
    """h5py create_dataset options for an analysis.h5 dataset of ``value``."""
    if value.nbytes < WHOLE_BELOW_BYTES:
        return {}
    return {"compression": "gzip", "compression_opts": 9, "shuffle": True}


def write_analysis(path: Path, analysis: dict) -> None:
    """analysis.h5: a group per part of ``analysis``, each dataset with its unit (the large ones
    compressed, in HDF5's latest format: a run's analysis stays small enough to commit); the summary
    as the file's attributes (None left out)."""
    from ..durable import atomic_h5

    with atomic_h5(path, libver="latest") as f:
        for group, values in analysis.items():
            if group == "summary":
                for key, value in values.items():
                    if value is not None:
                        f.attrs[key] = value
                continue
            g = f.create_group(group)
            for key, value in values.items():
                value = np.asarray(value)
                dataset = g.create_dataset(key, data=value, **dataset_storage(value))
                unit = CATALOGUE_UNITS.get(key) if group == "catalogue" else ANALYSIS_UNITS.get(key)
                if unit is not None:
                    dataset.attrs["unit"] = unit


def read_analysis(path) -> dict:
    with h5py.File(path, "r") as f:
        result = {name: {key: f[name][key][()] for key in f[name]} for name in f}
        result["summary"] = {key: (v.item() if isinstance(v, np.generic) else v) for key, v in f.attrs.items()}
    return result


def read_history(run_dir) -> tuple[np.ndarray, np.ndarray] | None:
    """(time [s], m_lf/m_t) of a run's analysed frames, from its analysis.h5 (None without one)."""
    path = RunFolder(run_dir).analysis
    if not path.is_file():
        return None
    with h5py.File(path, "r") as f:
        return f["frames/time"][()], f["frames/largest_mass_ratio"][()]


def histories_of(run_dirs: dict) -> dict:
    """run name -> (time, m_lf/m_t) of its analysed frames (:func:`read_history`), for the runs (name ->
    folder, or None) that have been analysed."""
    histories = {}
    for name, run_dir in run_dirs.items():
        history = read_history(run_dir) if run_dir else None
        if history is not None:
            histories[name] = history
    return histories


def read_catalogue(path) -> dict[str, np.ndarray]:
    """The fragment catalogue of an analysis.h5 as columns, vectors split into _x, _y, _z and the
    composition into class_0, class_1, ...: ``pandas.DataFrame(read_catalogue(path))`` is a table
    with a row per cluster per analysed frame (units: CATALOGUE_UNITS, docs/data.md)."""
    with h5py.File(path, "r") as f:
        if "catalogue" not in f:
            raise KeyError(f"{path} has no fragment catalogue (analysed by a decco-warp older than the catalogue: analyze it again)")
        columns = {}
        for name in CATALOGUE_UNITS:
            values = f["catalogue"][name][()]
            if name == "composition":
                columns.update({f"class_{k}": values[:, k] for k in range(values.shape[1])})
            elif values.ndim == 2:
                suffixes = ("a", "b", "c") if name == "semi_axes" else ("x", "y", "z")
                columns.update({f"{name}_{axis}": values[:, k] for k, axis in enumerate(suffixes)})
            else:
                columns[name] = values
    return columns


def refresh_summary(run_dir, collision: dict, params: dict, piles: dict | None = None, spec: dict | None = None) -> dict:
    """A run's summary recomputed from its analysis.h5 alone (no trajectory: a run kept without one)
    and its set-up's ``collision`` metadata (set up again from its spec.toml: ``plan_start``; ``spec``
    that resolved specification, whose columns join), with every column of today's
    :func:`summarise`; analysis.h5 is rewritten (compressed, with units) and summary.json replaced.
    Series the analysis did not keep (the mass-weighted size change per frame) give None: those
    need the trajectory."""
    run_dir = Path(run_dir)
    analysis = read_analysis(RunFolder(run_dir).analysis)
    old = analysis["summary"]
    final = analysis["final"]
    summary = summarise(
        old.get("run", run_dir.name),
        analysis,
        collision=collision,
        params=params,
        n_particles=int(old["n_particles"]),
        target_mass=float(old["target_mass"]),
        predicted_overlap=old.get("predicted_overlap"),
        min_members=int(old["min_members"]),
        every=int(old.get("analyze_every", old.get("analyse_every"))),  # the key's earlier spelling too
        piles=piles,
        spec=spec,
    )
    if summary["particle_size_change_mass_weighted"] is None and "label" in final:
        # The last frame's fragment is known (final/label); grains of one density weigh as R^3.
        masses, members = final["radius"] ** 3, final["label"] == 0
        if members.any():
            summary["particle_size_change_mass_weighted"] = mass_weighted_size_change(masses[members], masses)
    summary["analysis_seconds"] = old.get("analysis_seconds")
    _write_results(run_dir, analysis, summary)
    return summary

"""Live inspection and replays with rerun (rerun-sdk, imported only when asked for).

The same :class:`RerunLogger` serves a live run (one frame every ``--rerun-every``
steps) and ``decco-warp view`` (every frame of a trajectory), so a recording
looks the same either way.  Entities (lengths in km, on the timelines ``step``
and ``sim_time``):

    particles/by_size          Points3D, true radii, coloured by size class (annotation context)
    particles/by_stress        Points3D, coloured by largest overlap on a fixed scale (0 to 1 km)
    piles/target, piles/projectile
                               Points3D at each pile's centre of mass, Arrows3D of its velocity
    fragments/largest          Points3D of the largest fragment's members (replays of analysed runs)
    observables/<name>         Scalars: every energy, ledger entry, contacts, max_overlap [cm],
                               exactly as in trajectory.h5
    conservation/momentum_drift, conservation/angular_momentum_drift
                               Scalars: relative drift of |p| and |L| since the first frame
    stress_share/class_<k>     Scalars: paper Fig. 8 share of the top 1 % by stress (largest overlap),
                               per size class (0 = smallest; the series is named by its radius)
    stress_share_per_area/class_<k>, stress_share_strain/class_<k>
                               Scalars: the same by largest overlap / R^2 and by overlap / R (a
                               trajectory without them: computed from its frame's stress and radii)
"""

from __future__ import annotations

import errno
import os

from pathlib import Path

import numpy as np

from .errors import InputError, RerunUnavailable  # noqa: F401 (re-exported: the error lives in errors.py)
from .folder import RunFolder

KM = 1e5
MODES = ("spawn", "save", "connect", "serve")
RECORDING_FILE = "recording.rrd"
SIZE_COLOURS = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189)]
SIZE_NAMES = ("7.5 km", "15 km", "22.5 km")
#: Largest overlap mapped to the top of the stress colour map [cm].
STRESS_SCALE = 1e5
_VIRIDIS = np.array([(68, 1, 84), (59, 82, 139), (33, 145, 140), (94, 201, 98), (253, 231, 37)], dtype=float)

ENERGY_SERIES = {
    "kinetic_translational": (31, 119, 180),
    "kinetic_rotational": (23, 190, 207),
    "potential": (255, 127, 14),
    "elastic": (44, 160, 44),
    "total_energy": (0, 0, 0),
    "dissipated_sliding": (214, 39, 40),
    "dissipated_rolling": (148, 103, 189),
    "dissipated_hysteresis": (140, 86, 75),
    "integration_error": (127, 127, 127),
}
CONTACT_SERIES = {"number_of_contacts": (31, 119, 180), "max_overlap": (214, 39, 40)}
#: The stress shares' views (a tab each), by trajectory observable: with one spring constant the
#: paper's largest overlap ranks force; overlap / R^2 ranks force per area, overlap / R strain.
STRESS_SHARE_VIEWS = {
    "stress_share": "stress share by overlap (Fig. 8)",
    "stress_share_per_area": "by overlap / R^2",
    "stress_share_strain": "by overlap / R",
}


def import_rerun():
    try:
        import rerun
        import rerun.blueprint
    except ImportError as error:
        raise RerunUnavailable(
            f"rerun is not available ({error}); install it with: pip install 'rerun-sdk>=0.41'"
        ) from None
    return rerun


def parse_mode(text: str) -> tuple[str, str | None]:
    """'spawn', 'save', 'serve', 'connect' or 'connect=ADDR' -> (mode, address)."""
    mode, _, address = text.partition("=")
    if mode not in MODES or (address and mode != "connect"):
        raise InputError(f"--rerun must be one of spawn, save, connect[=ADDR], serve; got {text!r}")
    return mode, address or None


def stress_colours(stress: np.ndarray) -> np.ndarray:
    """A fixed viridis-like scale: 0 cm dark purple, STRESS_SCALE and above yellow."""
    level = np.clip(stress / STRESS_SCALE, 0.0, 1.0) * (len(_VIRIDIS) - 1)
    low = np.floor(level).astype(int).clip(0, len(_VIRIDIS) - 2)
    frac = (level - low)[:, None]
    return ((1 - frac) * _VIRIDIS[low] + frac * _VIRIDIS[low + 1]).astype(np.uint8)


class RerunLogger:
    """Frames of one run into one rerun recording."""

    def __init__(self, mode: str, address: str | None, run_dir: Path, static: dict, name: str, save_to: Path | None = None):
        rr = import_rerun()
        self.rr = rr
        self.rec = rr.RecordingStream("decco-warp", recording_id=name)
        self.url = None
        if mode == "save":
            self.path = Path(save_to) if save_to is not None else Path(run_dir) / RECORDING_FILE
            self.path.parent.mkdir(parents=True, exist_ok=True)
            # Recorded beside its destination and renamed into place when whole: a recording cut
            # short (a full disk, a stop) never replaces a good one.
            self._recording = self.path.with_name(f".{self.path.name}.tmp")
            self.rec.save(self._recording)
        elif mode == "spawn":
            self.rec.spawn()
        elif mode == "connect":
            self.rec.connect_grpc(address) if address else self.rec.connect_grpc()
        else:  # serve
            grpc = self.rec.serve_grpc()
            rr.serve_web_viewer(connect_to=grpc, open_browser=False)
            self.url = grpc
        self.radii_cm = np.asarray(static["radius"])
        self.radii = self.radii_cm / KM
        self.species = np.asarray(static["species"])
        self.pile_id = np.asarray(static["pile_id"])
        self.mass = np.asarray(static["mass"])
        self.reference = None
        self._log_static()

    def _log_static(self) -> None:
        rr, rrb = self.rr, self.rr.blueprint
        classes = int(self.species.max()) + 1
        labels = [SIZE_NAMES[k] if k < len(SIZE_NAMES) else f"class {k}" for k in range(classes)]
        self.rec.log(
            "particles/by_size",
            rr.AnnotationContext([(k, labels[k], SIZE_COLOURS[k % len(SIZE_COLOURS)]) for k in range(classes)]),
            static=True,
        )
        for name, colour in {**ENERGY_SERIES, **CONTACT_SERIES}.items():
            self.rec.log(f"observables/{name}", rr.SeriesLines(names=name.replace("_", " "), colors=[colour]), static=True)
        for name, colour in (("momentum_drift", (31, 119, 180)), ("angular_momentum_drift", (214, 39, 40))):
            self.rec.log(f"conservation/{name}", rr.SeriesLines(names=name.replace("_", " "), colors=[colour]), static=True)
        for name in STRESS_SHARE_VIEWS:
            for k in range(classes):
                self.rec.log(
                    f"{name}/class_{k}",
                    rr.SeriesLines(names=f"{labels[k]} top-1 % share", colors=[SIZE_COLOURS[k % len(SIZE_COLOURS)]]),
                    static=True,
                )
        energy = [f"observables/{name}" for name in ENERGY_SERIES]
        self.rec.send_blueprint(
            rrb.Blueprint(
                rrb.Horizontal(
                    rrb.Spatial3DView(name="particles", origin="/", contents=["particles/by_size", "piles/**", "fragments/**"]),
                    rrb.Vertical(
                        rrb.TimeSeriesView(name="energy [erg]", origin="/", contents=energy),
                        rrb.TimeSeriesView(name="conservation", origin="/conservation"),
                        rrb.Tabs(*(rrb.TimeSeriesView(name=title, origin=f"/{name}") for name, title in STRESS_SHARE_VIEWS.items())),
                        rrb.TimeSeriesView(
                            name="contacts", origin="/", contents=[f"observables/{n}" for n in CONTACT_SERIES]
                        ),
                    ),
                    column_shares=[3, 2],
                ),
                collapse_panels=True,
            )
        )

    def log_frame(self, step: int, time: float, particles: dict, observables: dict, largest: np.ndarray | None = None):
        """One frame: particle arrays and observables as written to trajectory.h5."""
        rr, rec = self.rr, self.rec
        rec.set_time("step", sequence=int(step))
        rec.set_time("sim_time", duration=float(time))
        positions = particles["position"] / KM
        rec.log("particles/by_size", rr.Points3D(positions, radii=self.radii, class_ids=self.species))
        rec.log("particles/by_stress", rr.Points3D(positions, radii=self.radii, colors=stress_colours(particles["stress"])))
        for pile, name in ((0, "target"), (1, "projectile")):
            mine = self.pile_id == pile
            if not mine.any():
                continue
            m = self.mass[mine]
            com = (m[:, None] * positions[mine]).sum(axis=0) / m.sum()
            velocity = (m[:, None] * particles["velocity"][mine]).sum(axis=0) / m.sum() / KM
            rec.log(f"piles/{name}", rr.Points3D([com], radii=[2.0], labels=[name]))
            rec.log(f"piles/{name}/velocity", rr.Arrows3D(origins=[com], vectors=[velocity * 100.0]))  # km per 100 s
        if largest is not None:
            rec.log("fragments/largest", rr.Points3D(positions[largest], radii=self.radii[largest], colors=[(255, 215, 0)]))
        for name in (*ENERGY_SERIES, *CONTACT_SERIES):
            rec.log(f"observables/{name}", rr.Scalars(float(observables[name])))
        self._log_drift(observables, particles)
        for name, shares in self._stress_shares(particles, observables).items():
            for k, value in enumerate(shares):
                if np.isfinite(value):
                    rec.log(f"{name}/class_{k}", rr.Scalars(float(value)))

    def _stress_shares(self, particles: dict, observables: dict) -> dict:
        """Each of STRESS_SHARE_VIEWS' shares of a frame, as recorded or of its stress and radii
        (diagnostics.recorded_stress_shares)."""
        from .diagnostics import recorded_stress_shares, stress_share_classes

        recorded = {name: np.asarray(observables[name]) for name in STRESS_SHARE_VIEWS if name in observables}
        classes = stress_share_classes(observables, self.species)
        shares = recorded_stress_shares(recorded, np.asarray(particles["stress"]), self.radii_cm, self.species, classes)
        return {name: shares[name] for name in STRESS_SHARE_VIEWS}

    def set_reference(self, particles: dict, observables: dict) -> None:
        """Measure the drifts from this frame (the run's first), with its momentum scales."""
        v = particles["velocity"]
        p_scale = np.linalg.norm(self.mass[:, None] * v, axis=1).sum() or 1.0
        l_scale = np.linalg.norm(self.mass[:, None] * np.cross(particles["position"], v), axis=1).sum() or 1.0
        self.reference = (np.asarray(observables["momentum"]), np.asarray(observables["angular_momentum"]), p_scale, l_scale)

    def _log_drift(self, observables: dict, particles: dict) -> None:
        if self.reference is None:
            self.set_reference(particles, observables)
        p0, l0, p_scale, l_scale = self.reference
        momentum = np.asarray(observables["momentum"])
        angular = np.asarray(observables["angular_momentum"])
        self.rec.log("conservation/momentum_drift", self.rr.Scalars(float(np.linalg.norm(momentum - p0) / p_scale)))
        self.rec.log("conservation/angular_momentum_drift", self.rr.Scalars(float(np.linalg.norm(angular - l0) / l_scale)))

    def abort(self) -> None:
        """Stop recording, leaving nothing behind (a half-made recording is dropped)."""
        self.rec.disconnect()
        recording, self._recording = getattr(self, "_recording", None), None
        if recording is not None:
            recording.unlink(missing_ok=True)

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()
        recording = getattr(self, "_recording", None)
        if recording is not None:
            self._recording = None
            from .durable import write_point

            try:
                write_point(self.path.name)
                if not recording.is_file():
                    raise OSError(errno.EIO, "the recording was not written", str(self.path))
                os.replace(recording, self.path)
            except OSError as error:
                recording.unlink(missing_ok=True)
                raise OSError(error.errno, error.strerror, str(self.path)) from None


def replay(trajectory_path: Path, mode: str, address: str | None, save_to: Path | None = None, progress=None) -> RerunLogger:
    """Log every frame of a trajectory (finished or running) with the live logger's code."""
    from .io import read_trajectory

    trajectory_path = Path(trajectory_path)
    data = read_trajectory(trajectory_path)
    run_dir = trajectory_path.parent
    largest = _largest_fragments(run_dir, data)
    logger = RerunLogger(mode, address, run_dir, data["static"], name=run_dir.name, save_to=save_to)
    frames = len(data["step"])
    try:
        for k in range(frames):
            particles = {name: data["particles"][name][k] for name in data["particles"]}
            observables = {name: data["observables"][name][k] for name in data["observables"]}
            logger.log_frame(int(data["step"][k]), float(data["time"][k]), particles, observables, largest.get(int(data["step"][k])))
            if progress is not None:
                progress(k + 1, frames)
    except BaseException:
        logger.abort()
        raise
    logger.close()
    return logger


def _largest_fragments(run_dir: Path, data: dict) -> dict:
    """Members of the largest fragment at the last frame, if the run was analysed."""
    path = RunFolder(run_dir).analysis
    if not path.is_file():
        return {}
    import h5py

    with h5py.File(path, "r") as f:
        if "final" not in f or f["final/mass"].shape[0] == 0:
            return {}
        label = f["final/label"][()]
        step = int(f["final/step"][()])
    return {step: np.flatnonzero(label == 0)}

"""A movie of a run, written without a display: its frames projected on the impact plane, each
sphere at its true size, coloured by the cluster it is in at the frames the analysis labelled
(else by pile), through matplotlib's writers (an mp4 with ffmpeg, else a GIF with Pillow).

    path, note = write_movie("runs/out/default", "runs/out/default/figures/movie.mp4")
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..folder import RunFolder  # noqa: E402
from ..io import read_trajectory  # noqa: E402

#: What a movie may be written as: the suffix, and matplotlib's writer for it.
FORMATS = (".mp4", ".gif")
#: The share of all frames' particles inside the view: far debris would shrink the piles to dots.
VIEW_QUANTILE = 0.98


def ffmpeg_available() -> bool:
    """Whether matplotlib finds ffmpeg (its ``animation.ffmpeg_path``, else on PATH)."""
    from matplotlib import animation

    return bool(animation.FFMpegWriter.isAvailable() or shutil.which("ffmpeg"))


def movie_path(out: Path) -> tuple[Path, str | None]:
    """Where a movie asked for at ``out`` is written, and a note when that is not what was asked: an
    .mp4 without ffmpeg becomes a .gif beside it."""
    if out.suffix.lower() not in FORMATS:
        raise ValueError(f"a movie is written as {' or '.join(FORMATS)}; got {out.name}")
    if out.suffix.lower() == ".mp4" and not ffmpeg_available():
        gif = out.with_suffix(".gif")
        return gif, f"ffmpeg is not installed (an mp4 needs it): wrote a GIF, {gif.name}, instead; install ffmpeg for an mp4"
    return out, None


def _labels(run_dir: Path, steps: np.ndarray) -> dict[int, np.ndarray]:
    """Per trajectory frame index, the cluster label of each particle where the analysis has it."""
    import h5py

    path = RunFolder(run_dir).analysis
    if not path.is_file():
        return {}
    with h5py.File(path, "r") as f:
        if "frames" not in f or "label" not in f["frames"]:
            return {}
        analysed = f["frames/step"][()]
        labels = f["frames/label"][()]
    index = {int(step): k for k, step in enumerate(steps)}
    return {index[int(step)]: labels[k] for k, step in enumerate(analysed) if int(step) in index}


def view_limits(positions: np.ndarray, radii: np.ndarray) -> tuple[float, float, float, float]:
    """(x0, x1, y0, y1) [km] of a square view holding VIEW_QUANTILE of every frame's particles."""
    xy = positions[:, :, :2].reshape(-1, 2) / 1e5
    low, high = np.quantile(xy, 1 - VIEW_QUANTILE, axis=0), np.quantile(xy, VIEW_QUANTILE, axis=0)
    centre, half = (low + high) / 2, max(float((high - low).max()) / 2, 1.0) + 2 * float(radii.max()) / 1e5
    return centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half


def write_movie(run_dir, out, every: int = 1, fps: int = 10, progress=None) -> tuple[Path, str | None]:
    """A movie of every ``every``-th frame of a run (and its last) at ``fps`` frames a second, into
    ``out`` (.mp4, or .gif: :func:`movie_path`), replaced whole once written; (the path written, a
    note or None).  ``progress(frames done, frames in all)``."""
    from matplotlib import animation
    from matplotlib.collections import EllipseCollection

    from ..durable import write_point

    run_dir = Path(run_dir)
    path, note = movie_path(Path(out))
    data = read_trajectory(RunFolder(run_dir).trajectory)
    frames = list(range(0, len(data.step), max(1, int(every))))
    if frames[-1] != len(data.step) - 1:
        frames.append(len(data.step) - 1)
    positions = data.particles["position"]
    radii, piles = data.static["radius"], data.static["pile_id"]
    labels = _labels(run_dir, data.step)
    x0, x1, y0, y1 = view_limits(positions[frames], radii)
    diameter = 2.0 * radii / 1e5
    colours = plt.get_cmap("tab10")

    fig, ax = plt.subplots(figsize=(6.0, 6.0))
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [km] (the projectile came along +x)")
    ax.set_ylabel("y [km]")
    spheres = EllipseCollection(diameter, diameter, np.zeros(radii.size), units="xy", offsets=positions[0, :, :2] / 1e5,
                                offset_transform=ax.transData, edgecolors="0.2", linewidths=0.2)  # fmt: skip
    ax.add_collection(spheres)
    title = ax.set_title("")

    def draw(k: int):
        frame = frames[k]
        xy = positions[frame, :, :2] / 1e5
        label = labels.get(frame)
        if label is not None:
            face = np.array([colours(c % 10) if c >= 0 else (0.75, 0.75, 0.75, 1.0) for c in label])
            how = "clusters"
        else:
            face = np.array([colours(0) if p == 0 else colours(1) for p in piles])
            how = "target blue, projectile orange"
        spheres.set_offsets(xy)
        spheres.set_facecolors(face)
        title.set_text(f"{run_dir.name}: t = {data.time[frame] / 3600:.3g} h, step {int(data.step[frame])} ({how})")
        if progress is not None:
            progress(k + 1, len(frames))
        return spheres, title

    writer = animation.FFMpegWriter(fps=fps) if path.suffix.lower() == ".mp4" else animation.PillowWriter(fps=fps)
    partial = path.with_name(f".{path.stem}.tmp{path.suffix}")  # renamed into place only when whole
    try:
        write_point(path.name)
        animation.FuncAnimation(fig, draw, frames=len(frames), blit=False).save(str(partial), writer=writer)
        os.replace(partial, path)
    finally:
        plt.close(fig)
        partial.unlink(missing_ok=True)
    return path, note

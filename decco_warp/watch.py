"""Run folders analysed as they stand (``decco-warp analyze``): a finished run, a running one (its
frames so far, read as a SWMR reader, its writer untouched; followed, if asked, until it ends), or a
folder of runs, which then share one time axis and get a cross-run table and figures.

    runs = find_runs(path)                      # the run itself, or the run folders in it
    check_analysable(path, runs)                # before the first analysis
    results = list(analyse_runs(runs))           # each run's own min_members (or 50)
    if len(runs) > 1:
        write_cross_run_results(path, [result.summary for result in results])
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from .checks import InputError, check_destination
from .durable import json_text, write_atomic, write_table
from .folder import TABLE, RunFolder, missing
from .lock import AnalysisLock, RunFolderBusy, ensure_free, ensure_not_analysed

def find_runs(path) -> list[Path]:
    """The run folders at ``path``: ``path`` itself if it holds a trajectory, else the folders in it
    that do, in order of name; InputError when there are none."""
    path = Path(path)
    if RunFolder(path).trajectory.is_file():
        return [path]
    if not path.is_dir():
        raise InputError(missing(path))
    runs = sorted(p.parent for p in path.glob(f"*/{RunFolder.TRAJECTORY}"))
    if not runs:
        raise InputError(f"{path} holds no {RunFolder.TRAJECTORY} and no run folders with one")
    return runs


def check_analysable(path, runs: list[Path]) -> None:
    """Refuse (InputError), before the first analysis, a run folder that cannot be written or that
    another process is analysing, and for several runs a cross-run table in ``path`` that cannot be
    written."""
    for run_dir in runs:
        check_destination(run_dir, "run folder", folder=True)
        ensure_not_analysed(run_dir)
    if len(runs) > 1:
        check_destination(Path(path) / TABLE, "cross-run table")


def planned_end(runs: list[Path]) -> float | None:
    """The latest simulated time [s] the runs' own spec.toml files plan to reach (None if none reads)."""
    from .spec import SpecError, load_spec_file, resolve_spec

    ends = []
    for run_dir in runs:
        try:
            spec = resolve_spec(load_spec_file(RunFolder(run_dir).spec))
        except SpecError:
            continue  # analysed all the same; its figures keep their own scale
        if isinstance(spec["params"]["dt"], float) and "steps" in spec["run"]:
            ends.append(spec["run"]["steps"] * spec["params"]["dt"])
    return max(ends) if ends else None


def is_running(run_dir) -> bool:
    """Whether a process is writing ``run_dir`` (holds its lock)."""
    try:
        ensure_free(run_dir)
    except RunFolderBusy:
        return True
    return False


def last_step(run_dir) -> int:
    """The step of the last whole frame of a run's trajectory (-1 while none can be read)."""
    from .io import FileFormatError, last_frame_step

    try:
        return last_frame_step(RunFolder(run_dir).trajectory)
    except FileFormatError:
        return -1


def wait_for_frame(run_dir, seen: int, poll: float) -> None:
    """Return once a run has a frame past step ``seen`` or is no longer written, looking every ``poll`` seconds."""
    while is_running(run_dir) and last_step(run_dir) == seen:
        time.sleep(poll)


@dataclass
class RunAnalysis:
    """One analysis of a run folder: ``analysis`` (as analysis.h5 holds it) and whether the run was
    still being written (``live``: its frames so far were analysed)."""

    run_dir: Path
    analysis: dict
    live: bool

    @property
    def summary(self) -> dict:
        return self.analysis["summary"]

    @property
    def frames(self) -> int:
        """The trajectory's frames when it was read."""
        return len(self.analysis["conservation"]["time"])


def analyse_folder(
    run_dir, min_members: int = 50, every: int = 1, device: str | None = None, end_time: float | None = None, progress=None,
    workers: int | None = None,
) -> RunAnalysis:  # fmt: skip
    """Analyse a run folder once (``analysis.runs.analyse_run``: analysis.h5 and summary.json) and
    draw its figures (time axes to ``end_time``, default the run's own).  A finished run is held
    meanwhile (its lock), so that no run starts writing there; a running one is read as a SWMR
    reader, its frames so far.  ``progress(frames done, frames in all)``; ``device``: where the
    cluster finder sums its density; ``workers``: processes that analyse its frames (None: chosen
    from the cores and the run's size)."""
    from .analysis.figures import draw_run
    from .analysis.runs import analyse_run

    writer = RunFolder(run_dir).lock()
    try:
        writer.acquire()
    except RunFolderBusy:
        writer = None  # a running run
    try:
        analysis = analyse_run(run_dir, min_members=min_members, every=every, progress=progress, device=device, workers=workers)
        draw_run(analysis, run_dir, end_time)
    finally:
        if writer is not None:
            writer.release()
    return RunAnalysis(run_dir, analysis, live=writer is None)


def analyse_runs(
    runs: list[Path],
    min_members: int | None = None,
    every: int = 1,
    device: str | None = None,
    follow: bool = False,
    poll: float = 10.0,
    on_run: Callable[[Path], Callable[[int, int], None] | None] | None = None,
    on_follow: Callable[[Path, int], None] | None = None,
    workers: int | None = None,
) -> Iterator[RunAnalysis]:
    """Analyse each of ``runs`` in turn (:func:`analyse_folder`) under its analysis lock, yielding
    each RunAnalysis; several runs share one time axis, to the latest end their spec.toml plan.
    ``follow``: a running run is analysed again as each new frame arrives (looked for every ``poll``
    seconds) until it ends, ``on_follow(run_dir, step analysed to)`` told before each wait.
    ``on_run(run_dir)``, as a run's analysis begins, returns its progress callback (or None).
    ``min_members``: the smallest cluster; None: each run's own (RunFolder.min_members: what it
    was analysed or swept with).  ``workers``: processes that analyse a run's frames side by side
    (None: chosen for each run from the cores and its size, analysis.runs.frame_workers).
    Raises what the analysis meets: FileFormatError, RunFolderBusy (another analysis), OSError."""
    end_time = planned_end(runs) if len(runs) > 1 else None
    for run_dir in runs:
        progress = on_run(run_dir) if on_run is not None else None
        smallest = min_members if min_members is not None else RunFolder(run_dir).min_members()
        with AnalysisLock(run_dir):
            result = analyse_folder(run_dir, smallest, every, device, end_time, progress, workers)
            while follow and result.live:
                if on_follow is not None:
                    on_follow(run_dir, result.summary["steps"])
                wait_for_frame(run_dir, result.summary["steps"], poll)
                result = analyse_folder(run_dir, smallest, every, device, end_time, progress, workers)
        yield result


#: Beside [params], the set-up keys whose values make series of their own in the cross-run figures
#: of a folder of runs (where they vary among its runs): not a sweep, so what varies is found.
SPLIT_COLLISION = ("target_spin", "projectile_spin", "gap", "eta_potential", "precision", "resolution")


def write_cross_run_results(path, summaries: list[dict]) -> None:
    """A folder of runs' summary.csv (a row per run), cross-run figures (figures/, series split by
    the set-up columns that differ among the runs) and summaries.json, each whole or absent."""
    from .analysis.figures import write_cross_run
    from .analysis.runs import histories_of
    from .spec import SCHEMA

    path = Path(path)
    write_table(path / TABLE, summaries, list(dict.fromkeys(key for summary in summaries for key in summary)))
    # The runs of a folder are its subfolders, named as their summaries' run.
    histories = histories_of({summary["run"]: path / summary["run"] for summary in summaries})
    write_cross_run(path, summaries, split=[*SCHEMA["params"], *SPLIT_COLLISION], histories=histories)
    write_atomic(path / "summaries.json", json_text(summaries))

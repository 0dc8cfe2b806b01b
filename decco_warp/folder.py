"""A run's folder: the names of its files in one place, its lock, and how far it has stepped.

    folder = RunFolder("runs/out/fig8/eta3")
    folder.spec, folder.trajectory, folder.checkpoint, folder.log   # what a run writes
    folder.analysis, folder.summary                                  # what its analysis writes
    folder.xdmf                                                      # the trajectory's XDMF description
    folder.lock()                                                    # its writers' lock (lock.py)
    folder.progress(), folder.complete()                             # how far it has stepped
    folder.min_members()                                             # the smallest cluster it is analysed with

Every module that opens a run's file asks a RunFolder for its path, so that the layout is spelled
out here alone.
"""

from __future__ import annotations

import json
from pathlib import Path


def _file(name: str) -> property:
    return property(lambda folder: folder.path / name, doc=f"the folder's {name}")


#: A folder of runs' table, a row per run (a sweep's, or ``decco-warp analyze`` of the folder).
TABLE = "summary.csv"
#: A sweep folder's record (its settings, among them the analysis's).
SWEEP_RECORD = "sweep.json"
#: The smallest cluster (in particles) of an analysis when nothing says otherwise: the paper's Fig. 2.
MIN_MEMBERS = 50


class RunFolder:
    """The files of one run folder (a path; nothing is read until asked)."""

    SPEC = "spec.toml"
    TRAJECTORY = "trajectory.h5"
    CHECKPOINT = "checkpoint.h5"
    LOG = "run.log"
    ANALYSIS = "analysis.h5"
    SUMMARY = "summary.json"
    XDMF = "trajectory.xdmf"
    #: What a run writes: a run that fails before its first checkpoint leaves none of them.
    RUN_FILES = (SPEC, TRAJECTORY, CHECKPOINT, LOG)

    def __init__(self, path):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"RunFolder({str(self.path)!r})"

    spec = _file(SPEC)
    trajectory = _file(TRAJECTORY)
    checkpoint = _file(CHECKPOINT)
    log = _file(LOG)
    analysis = _file(ANALYSIS)
    summary = _file(SUMMARY)
    xdmf = _file(XDMF)

    def lock(self):
        """The lock that one writer of the folder holds (a run, a resume, an analysis)."""
        from .lock import RunFolderLock

        return RunFolderLock(self.path)

    def progress(self) -> tuple[int, int] | None:
        """(steps made, steps its spec.toml asks for), by its checkpoint or, for a run kept without
        one (the committed results), by its summary; None when it holds neither."""
        from . import spec as specs
        from .io import read_checkpoint

        if not self.checkpoint.is_file() and not self.summary.is_file():
            return None
        needed = specs.resolve_spec(specs.load_spec_file(self.spec))["run"]["steps"]
        if self.checkpoint.is_file():
            return int(read_checkpoint(self.checkpoint)[0]["step"]), needed
        return int(json.loads(self.summary.read_text()).get("steps", -1)), needed

    def complete(self) -> bool:
        """Whether the run has made every step its spec.toml asks for."""
        progress = self.progress()
        return progress is not None and progress[0] >= progress[1]

    def min_members(self) -> int:
        """The smallest cluster this run is analysed with: its summary.json's (its last analysis),
        else that of the sweep that made it (the sweep.json of the folder above), else MIN_MEMBERS."""
        for path, keys in ((self.summary, ("min_members",)), (self.path.parent / SWEEP_RECORD, ("settings", "min_members"))):
            try:
                value = json.loads(path.read_text())
                for key in keys:
                    value = value[key]
            except (OSError, ValueError, KeyError, TypeError):
                continue
            if isinstance(value, int) and not isinstance(value, bool) and value >= 1:
                return value
        return MIN_MEMBERS


def missing(path, what: str = "run folder") -> str:
    """The line for a path that is not a ``what``: "does not exist" when nothing is there."""
    return f"{path} does not exist" if not Path(path).exists() else f"{path} is not a {what}"

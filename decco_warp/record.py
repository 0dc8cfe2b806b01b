"""What a run keeps beside its particles' arrays: its record, written into every checkpoint (the
``/run`` group) and read back on resume, so that a resumed run goes on as if never stopped (its
clock of wall time, its deepest contact, the frame it wrote last, the specification it was made by).

    record = RunRecord.from_checkpoint(read_checkpoint(path)[2])    # any checkpoint, old ones too
    record.wall_seconds, record.deepest_overlap
    write_checkpoint(path, snapshot, state, record.as_checkpoint())

Fields a checkpoint of an earlier decco-warp lacks take their defaults (each says what a missing value
means); keys this decco-warp does not know are kept and written back unchanged.  Plain data: no Warp.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

NO_PAIR = (-1, -1)


def _pair(values) -> tuple[int, int]:
    i, j = (int(k) for k in np.asarray(values).reshape(-1)[:2])
    return i, j


@dataclass
class RunRecord:
    """A run's record (the checkpoint's /run group): kept by run.py's driver, read by sweeps and resumes."""

    spec_toml: str = ""
    """The resolved specification the run was made by (spec.toml's text): a resume refuses a changed one."""
    size_classes: int = 3
    """Size classes of the run's particles (a frame's stress shares are per class)."""
    wall_seconds: float = 0.0
    """Wall time over all sessions up to the last checkpoint [s]."""
    stepping_seconds: float | None = None
    """Of it, the time spent stepping [s]; None: a run of decco-warp 0.2 did not count it."""
    start_overlap: float = 0.0
    """The deepest overlap of the set-up, a fraction of the smaller radius of its pair."""
    start_overlap_pair: tuple[int, int] = NO_PAIR
    last_frame_step: int | None = None
    """The step of the last frame written (None: the first frame only, or an old run)."""
    deepest_overlap: float = 0.0
    """The deepest contact met at any frame, a fraction of the smaller radius of its pair."""
    deepest_overlap_step: int = -1
    """The frame it was met at (-1: no contact seen at the frames)."""
    deepest_overlap_pair: tuple[int, int] = NO_PAIR
    deepest_overlap_since: int = -1
    """The frame before: it was met at a step after this one (-1: runs of decco-warp 0.2 kept none)."""
    overlap_warned: float = 0.0
    """The deepest warning level of overlap said so far (run.OVERLAP_WARNINGS), so that none is said twice."""
    other: dict = field(default_factory=dict)
    """Keys of the checkpoint this decco-warp does not know: written back as they were read."""

    @classmethod
    def from_checkpoint(cls, values: dict) -> "RunRecord":
        """The record of a checkpoint's /run group (io.read_checkpoint's third value)."""
        known = {f.name for f in fields(cls)} - {"other"}
        given = {key: value for key, value in values.items() if key in known}
        record = cls(other={key: value for key, value in values.items() if key not in known})
        for key, value in given.items():
            default = getattr(record, key)
            if isinstance(default, tuple):
                value = _pair(value)
            elif isinstance(default, str):
                value = str(value)
            elif key in ("size_classes", "deepest_overlap_step", "deepest_overlap_since", "last_frame_step"):
                value = int(value)
            else:
                value = float(value)
            setattr(record, key, value)
        return record

    def as_checkpoint(self) -> dict:
        """The /run group to write (io.write_checkpoint): pairs as int64 arrays, unset values left out."""
        values = dict(self.other)
        for f in fields(self):
            if f.name == "other":
                continue
            value = getattr(self, f.name)
            if value is None:
                continue
            values[f.name] = np.array(value, dtype=np.int64) if isinstance(value, tuple) else value
        return values

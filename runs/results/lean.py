"""Make committed run folders lean: each analysis.h5 without its per-particle arrays of the final
frame's motion and the per-frame cluster labels, the largest datasets of a run (~0.7 of its ~0.8 MB
at 10 000 particles), stored as ``decco-warp analyze`` now writes it (HDF5's latest format, the small
datasets whole: about half of what an older analysis left), so that whole campaigns fit runs/results' 40 MB.

    python runs/results/lean.py runs/results/gravity_every runs/results/resolution   # folders of runs

Dropped: ``final/positions``, ``final/velocities`` and ``frames/label``.  Kept: every series, the
fragment catalogue, the final frame's labels, radii and masses (``decco-warp extract`` and the
figures read them), the summaries.  The dropped arrays come back from the run's trajectory
(``decco-warp analyze`` of a rerun).  A file is rewritten through a temporary copy, renamed into
place only when whole and marked lean (the attribute ``lean_layout``); lean files are left as they are.
Each run.log is kept gzipped as run.log.gz (``zcat`` or ``gzip -d`` reads it; a tenth of the
bytes: its frame lines repeat a plain pattern).
"""

from __future__ import annotations

import gzip
import os
import shutil
import sys
from pathlib import Path

import h5py

from decco_warp.analysis.runs import dataset_storage

DROPPED = ("final/positions", "final/velocities", "frames/label")
#: A file attribute this script sets: the file is lean already, stored by the storage rule of this
#: version (LAYOUT; 1: datasets under 4 kB whole, 2: under 256 bytes, gzip 9).
MARK = "lean_layout"
LAYOUT = 2


def lean(path: Path) -> bool:
    """Rewrite ``path`` lean; False if it was so already."""
    with h5py.File(path, "r") as source:
        if not any(name in source for name in DROPPED) and source.attrs.get(MARK) == LAYOUT:
            return False
        part = path.with_name(path.name + ".lean")
        with h5py.File(part, "w", libver="latest") as target:
            for key, value in source.attrs.items():
                target.attrs[key] = value
            target.attrs[MARK] = LAYOUT

            def copy(name, item):
                if name in DROPPED:
                    return
                if isinstance(item, h5py.Group):
                    group = target.require_group(name)
                    group.attrs.update(item.attrs)
                else:
                    data = item[()]
                    copied = target.create_dataset(name, data=data, **dataset_storage(data))  # as analyze writes it
                    copied.attrs.update(item.attrs)

            source.visititems(copy)
    os.replace(part, path)
    return True


def compress_log(path: Path) -> Path:
    """``path`` (a run.log) gzipped beside it as run.log.gz (no name or time in its header, so the
    same log gives the same bytes), renamed into place whole, then ``path`` removed."""
    packed = path.with_name(path.name + ".gz")
    part = packed.with_name(packed.name + ".part")
    with path.open("rb") as source, part.open("wb") as raw, gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as target:
        shutil.copyfileobj(source, target)
    os.replace(part, packed)
    path.unlink()
    return packed


def main(folders: list[str]) -> None:
    if not folders:
        sys.exit(__doc__)
    for folder in folders:
        for path in sorted(Path(folder).glob("**/analysis.h5")):
            before = path.stat().st_size
            if lean(path):
                print(f"{path}: {before / 1e3:.0f} -> {path.stat().st_size / 1e3:.0f} kB")
        for path in sorted(Path(folder).glob("**/run.log")):
            before = path.stat().st_size
            packed = compress_log(path)
            print(f"{path}: {before / 1e3:.0f} -> {packed.stat().st_size / 1e3:.0f} kB ({packed.name})")


if __name__ == "__main__":
    main(sys.argv[1:])

"""The README's paper run set up for a measuring script (runs/results/frame_costs.py, step_stages.py):
1/4 at eta 3, 22 deg, gravity_every = "auto", with the run's own plan; at a RESOLUTION other than 1
from runs/paper/piles/*_x<R>.h5, contacts scaled as a sweep scales them (decco_warp/resolution.py).
Its folder is a temporary one, removed afterwards: nothing is written into runs/."""

from __future__ import annotations

import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import warp as wp

from decco_warp import spec as specs
from decco_warp.resolution import scaled_run
from decco_warp.run import PreparedRun, prepare_start


def arguments() -> tuple[str, float]:
    """DEVICE and RESOLUTION from the command line (default: cuda where there is one, and 1)."""
    device = sys.argv[1] if len(sys.argv) > 1 else ("cuda" if wp.get_cuda_device_count() else "cpu")
    return device, float(sys.argv[2]) if len(sys.argv) > 2 else 1.0


@contextmanager
def readme_run(name: str, device: str, resolution: float) -> Iterator[tuple[PreparedRun, Path]]:
    """The run prepared to step (and its temporary folder); its lock released and folder removed after."""
    scratch = Path(tempfile.mkdtemp(prefix=f"{name}_"))
    prepared = None
    try:
        raw = {"run": {"name": name, "duration": 400, "output_every": 100, "out": str(scratch), "device": device},
               "piles": {"target": "runs/paper/piles/target5000.h5", "projectile": "runs/paper/piles/proj1250.h5"},
               "collision": {"eta": 3.0, "theta_deg": 22.0}, "params": {"gravity_every": "auto"}}  # fmt: skip
        if resolution != 1:
            raw = scaled_run(raw, resolution, scale_contacts=True, defaults=specs.resolve_spec({}))
        prepared = prepare_start(specs.resolve_spec(raw), overwrite=True, device=device)
        yield prepared, scratch
    finally:
        if prepared is not None and prepared.lock is not None:
            prepared.lock.release()
        shutil.rmtree(scratch, ignore_errors=True)

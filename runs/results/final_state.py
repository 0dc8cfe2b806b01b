"""m_lf/m_t and the size change of a finished run's last state, from its checkpoint, for runs whose
trajectory is gone before their frames were analysed (the R = 16 runs at eta 9: stepped on a GPU
machine that was given back while the analysis of their 100 000-particle frames was under way).

    python runs/results/final_state.py OUT.csv RUN_DIR...     # each RUN_DIR: checkpoint.h5, spec.toml, run.log[.gz]

A run's checkpoint at its last step is its last frame exactly (the same positions and velocities),
so these numbers are what `decco-warp analyze` gives for that frame; what they lack is the frame
series (no late-window mean or settled verdict). Each row says so in ``source``.
"""

from __future__ import annotations

import csv
import gzip
import re
import sys
import tomllib
from pathlib import Path

from decco_warp.analysis.runs import analyse_snapshot
from decco_warp.device import resolve_device
from decco_warp.io import read_checkpoint

COLUMNS = ["run", "n_particles", "eta", "realization_seed", "steps", "final_time", "largest_mass_ratio", "clusters",
           "particle_size_change", "particle_size_change_mass_weighted", "deepest_overlap", "source"]  # fmt: skip


def _log(run_dir: Path) -> str:
    plain, packed = run_dir / "run.log", run_dir / "run.log.gz"
    return plain.read_text() if plain.is_file() else gzip.decompress(packed.read_bytes()).decode()


def final_row(run_dir: Path, device: str | None = None) -> dict:
    snapshot, state, extra = read_checkpoint(run_dir / "checkpoint.h5")
    spec = tomllib.loads((run_dir / "spec.toml").read_text())
    if int(snapshot["step"]) != spec["run"]["steps"]:
        raise SystemExit(f"{run_dir}: its checkpoint is at step {int(snapshot['step'])}, not the run's last ({spec['run']['steps']})")
    target_mass = float(state.masses[state.pile_id == 0].sum())
    result = analyse_snapshot(state, target_mass, min_members=50, G=spec["params"].get("G"), device=resolve_device(device))
    done = re.findall(r"done: step (\d+), t ([0-9.e+-]+) s", _log(run_dir))
    return {
        "run": spec["run"]["name"],
        "n_particles": state.n,
        "eta": spec["collision"]["eta"],
        "realization_seed": spec["collision"].get("orientation_seed", ""),
        "steps": int(snapshot["step"]),
        "final_time": float(done[-1][1]) if done else "",
        "largest_mass_ratio": result["largest_mass_ratio"],
        "clusters": len(result["clusters"]),
        "particle_size_change": result["particle_size_change"],
        "particle_size_change_mass_weighted": result["particle_size_change_mass_weighted"],
        "deepest_overlap": float(extra["deepest_overlap"]),
        "source": "last checkpoint (the run's last state); frames not analysed",
    }


def main(out: str, run_dirs: list[str]) -> None:
    rows = [final_row(Path(d)) for d in run_dirs]
    with open(out, "w", newline="") as f:
        writer = csv.DictWriter(f, COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    for row in rows:
        print(f"{row['run']}: m_lf/m_t {row['largest_mass_ratio']:.4f}, {row['clusters']} clusters, size change {row['particle_size_change']:+.3f} %")


if __name__ == "__main__":
    if len(sys.argv) < 3:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2:])

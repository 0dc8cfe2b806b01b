"""m_lf/m_t of runs from their last checkpoint alone (the cluster finder of docs/model.md on the
final state, on the CPU), for runs whose trajectories were not kept or not analysed.

    python runs/results/final_frame.py RUN_DIR... > table.csv     # each RUN_DIR holds checkpoint.h5

One CSV row per run: its name, particles, eta (from spec.toml), the final step and time, m_lf/m_t
(the largest cluster of >= 50 members over the target's mass) and the number of such clusters.
Unlike ``decco-warp analyze`` it gives no late-window mean and no settled verdict (one frame).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import decco_warp as dw
from decco_warp import spec as specs
from decco_warp.analysis.clusters import find_clusters
from decco_warp.io import read_checkpoint

MIN_MEMBERS = 50


def final_frame(run_dir: Path) -> dict:
    spec = specs.load_spec_file(run_dir / "spec.toml")
    _, state, extra = read_checkpoint(run_dir / "checkpoint.h5")  # the state at the checkpoint, checked
    target_mass = float(state.masses[state.pile_id == 0].sum())
    clusters = find_clusters(state, min_members=MIN_MEMBERS, G=float(spec.get("params", {}).get("G", dw.G_CGS)), device="cpu")
    return {"run": run_dir.name, "n_particles": state.n, "eta": spec["collision"].get("eta"), "step": int(extra["last_frame_step"]),
            "largest_mass_ratio_final": clusters[0].mass / target_mass if clusters else 0.0, "clusters": len(clusters)}  # fmt: skip


def main(run_dirs: list[str]) -> None:
    if not run_dirs:
        sys.exit(__doc__)
    out = csv.DictWriter(sys.stdout, fieldnames=["run", "n_particles", "eta", "step", "largest_mass_ratio_final", "clusters"])
    out.writeheader()
    for run_dir in run_dirs:
        out.writerow(final_frame(Path(run_dir)))
        sys.stdout.flush()


if __name__ == "__main__":
    main(sys.argv[1:])

"""Reading what runs and sweeps write, with the standard library's csv and json, h5py and NumPy.

    python examples/read_data.py runs/out/friction            # a sweep's folder (its summary.csv and runs)
    python examples/read_data.py runs/out/default             # one run's folder

(pandas is not needed: each table below is a list of dicts or a dict of columns, which
``pandas.DataFrame(...)`` takes as it is where pandas is installed.)  docs/data.md lists every file,
column and dataset with its unit.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import h5py
import numpy as np

import decco_warp as dw
from decco_warp.analysis.compare import compare
from decco_warp.analysis.runs import read_catalogue


def sweep_table(folder: Path) -> list[dict]:
    """A sweep's summary.csv: a dict per run, every cell text (compare() reads them as numbers)."""
    with (folder / "summary.csv").open(newline="") as table:
        rows = list(csv.DictReader(table))
    print(f"{folder / 'summary.csv'}: {len(rows)} runs, {len(rows[0])} columns")
    shown = [c for c in ("run", "status", "eta", "mu_k", "realization", "largest_mass_ratio", "settled", "q_r_over_q_rd_star") if c in rows[0]]
    for row in rows:
        print("  " + "  ".join(f"{c}={row[c]}" for c in shown))
    done = [row for row in rows if row["status"] != "failed"]
    if "mu_k" in rows[0] and len({row["mu_k"] for row in done}) > 1:
        # csv.DictReader's rows go to compare() as they are, as summary.csv's cells.
        for line in compare(done, by="mu_k", metric="largest_mass_ratio", at="eta", allow_single=True).lines():
            print(line)
    return rows


def one_run(run_dir: Path) -> None:
    """A run's summary.json, its analysis.h5 (per frame, and the fragment catalogue) and its trajectory."""
    summary = json.loads((run_dir / "summary.json").read_text())  # strict JSON: null where a number does not exist
    print(f"{run_dir.name}: eta {summary['eta']}, m_lf/m_t {summary['largest_mass_ratio']:.4g}, settled {summary['settled']}, "
          f"mu_k {summary['mu_k']}, v/v_esc {summary['speed_over_escape']:.3g}")  # fmt: skip
    with h5py.File(run_dir / "analysis.h5", "r") as analysis:  # each dataset with its unit as an attribute
        time, ratio = analysis["frames/time"][()], analysis["frames/largest_mass_ratio"][()]
        print(f"  analysis.h5: {time.size} analysed frames; m_lf/m_t from {ratio[0]:.3g} at t = {time[0]:.0f} s "
              f"to {ratio[-1]:.3g} at t = {time[-1]:.0f} {analysis['frames/time'].attrs['unit']}")  # fmt: skip
    catalogue = read_catalogue(run_dir / "analysis.h5")  # a column per quantity, a row per cluster per analysed frame
    last = catalogue["frame"] == catalogue["frame"].max()
    print(f"  catalogue: {catalogue['mass'].size} rows; at the last frame {int(last.sum())} fragment(s) of "
          f"{', '.join(f'{m:.3g}' for m in catalogue['mass'][last])} g")  # fmt: skip
    if (run_dir / "trajectory.h5").is_file():  # a sweep may have dropped it (keep_trajectory = false)
        data = dw.read_trajectory(run_dir / "trajectory.h5")
        # data.particles: what changes from frame to frame, frames first; data.static: one value per particle.
        position, pile = data.particles["position"], data.static["pile_id"]
        centre = np.average(position[-1][pile == 1], axis=0, weights=data.static["mass"][pile == 1])
        print(f"  trajectory.h5: {data.step.size} frames of {position.shape[1]} particles; "
              f"the projectile's grains centred at {np.round(centre / 1e5, 1)} km at the last frame")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a sweep's folder or a run's folder")
    folder = parser.parse_args().folder
    if (folder / "summary.csv").is_file():
        rows = sweep_table(folder)
        analysed = [folder / row["run"] for row in rows if (folder / row["run"] / "analysis.h5").is_file()]
        if analysed:
            one_run(analysed[0])
    else:
        one_run(folder)


if __name__ == "__main__":
    main()

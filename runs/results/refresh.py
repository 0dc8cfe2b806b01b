"""Bring the committed runs' summaries to today's analysis, without their trajectories.

    python runs/results/refresh.py            # from the repository root, on any machine (CPU)

Each run folder under runs/results/ keeps analysis.h5, spec.toml and summary.json but no
trajectory (a folder that keeps summaries only, without analysis.h5, is left as it is).  The set-up of every run is made again from its spec.toml (the same piles, seed and
collision: ``plan_start`` on the CPU, nothing stepped), which gives what the summaries lacked: both
readings of eta, the LS12 small-body law with its band and the planets' law, and the spins' motion
at the first contact point.  The set-up is checked against the run's own record (its speed to 1e-9)
before anything is written.  From analysis.h5 come the late-window means and the settled verdict.
What needs the trajectory (the mass-weighted size change per frame, the cluster finder of today on
each frame) stays as the committed analysis has it; summary.json says which with null.  Each
experiment's summary.csv is rewritten with today's columns, its sweep's own columns (status, wall
time, device) kept.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

from decco_warp import spec as specs
from decco_warp.analysis.runs import refresh_summary
from decco_warp.plan import plan_start
from decco_warp.sweep import summary_fields, write_summary

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "runs" / "results"
#: The set-up made again must give the recorded speed to this relative precision.
SPEED_TOLERANCE = 1e-9


def refresh_run(run_dir: Path) -> dict:
    spec = specs.resolve_spec(specs.load_spec_file(run_dir / "spec.toml"))
    recorded = json.loads((run_dir / "summary.json").read_text())
    plan = plan_start(spec, device="cpu")
    collision = plan.state.metadata
    if abs(collision["speed"] / recorded["speed"] - 1) > SPEED_TOLERANCE:
        raise SystemExit(f"{run_dir}: the set-up made again gives speed {collision['speed']!r}, the run recorded {recorded['speed']!r}")
    return refresh_summary(run_dir, collision, plan.spec["params"], piles=plan.spec["piles"], spec=plan.spec)


def refresh_experiment(folder: Path) -> None:
    run_dirs = sorted(p.parent for p in folder.glob("*/analysis.h5"))
    if not run_dirs:  # a folder that keeps summaries only (fig9_zero_slip/, say): nothing to recompute from
        print(f"{folder.relative_to(ROOT)}: no analysis.h5, left as it is", flush=True)
        return
    table = folder / "summary.csv"
    rows = {row["run"]: row for row in csv.DictReader(table.open())} if table.is_file() else {}
    for run_dir in run_dirs:
        summary = refresh_run(run_dir)
        row = rows.setdefault(run_dir.name, {"run": run_dir.name, "status": "ok"})
        row.update({key: summary[key] for key in summary_fields() if key in summary})
        print(f"{run_dir.relative_to(ROOT)}: m_lf/m_t {summary['largest_mass_ratio']:.4g}, "
              f"{'settled' if summary['settled'] else 'NOT SETTLED'}", flush=True)  # fmt: skip
    write_summary(folder, [{k: ("" if v is None else v) for k, v in row.items()} for row in rows.values()])


def main(folders: list[str]) -> None:
    chosen = [RESULTS / name for name in folders] or sorted(p for p in RESULTS.iterdir() if p.is_dir())
    for folder in chosen:
        refresh_experiment(folder)


if __name__ == "__main__":
    main(sys.argv[1:])

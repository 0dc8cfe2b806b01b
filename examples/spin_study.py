"""Do parallel spins disrupt more than anti-parallel ones?  A spin study from Python, without a sweep.

Both piles spin at half their breakup rate, about +z (the target) and +z or -z (the projectile);
each kind of spin is run in several realizations (the piles turned by random rotations), each run
analysed, and the two kinds compared with the 95 % interval that `decco-warp compare` gives.

    python examples/spin_study.py                       # 2 kinds x 3 realizations of 50 000 steps (~1 min on a 2-core CPU)
    python examples/spin_study.py --steps 300 --realizations 2 --out /tmp/spin   # a quick look

The runs go to OUT/spin/ (a folder per run, as `decco-warp simulate` writes them), a table of their
summaries to OUT/spin/summary.csv.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

from decco_warp import spec as specs
from decco_warp.analysis.compare import compare
from decco_warp.analysis.runs import analyse_run
from decco_warp.run import start_run

KINDS = {"parallel": "+z", "anti-parallel": "-z"}  # the projectile's spin axis; the target's is +z


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=50_000, help="steps of each run (0.04 s each)")
    parser.add_argument("--realizations", type=int, default=3, help="runs of each kind of spin (>= 2: a spread to compare with)")
    parser.add_argument("--eta", type=float, default=3.0, help="KE / |U| of the collisions")
    parser.add_argument("--out", type=Path, default=Path("runs/out"), help="the folder that gets spin/")
    parser.add_argument("--device", default="auto", help="cpu, cuda, ... (default: a GPU if there is one)")
    args = parser.parse_args()

    folder = args.out / "spin"
    summaries = []
    for kind, axis in KINDS.items():
        for k in range(args.realizations):
            name = f"{kind}_r{k}"
            spec = specs.resolve_spec({
                # about 30 frames (a multiple of gravity_every), so that the late window can be judged
                "run": {"name": name, "out": str(folder), "steps": args.steps, "output_every": max(10, args.steps // 300 * 10),
                        "device": args.device},
                "collision": {"eta": args.eta, "theta_deg": 0.0, "target_spin": 0.5, "target_spin_axis": "+z",
                              "projectile_spin": 0.5, "projectile_spin_axis": axis,
                              # realization 0: the piles as their files hold them; then random rotations
                              **({"orientation_seed": 1000 + k} if k else {})},
                "params": {"gravity_every": 10},
            })  # fmt: skip
            result = start_run(spec, overwrite=True)
            summary = analyse_run(result.run_dir, min_members=20)["summary"]
            print(f"{name}: m_lf/m_t {summary['largest_mass_ratio']:.4g}, spin kind {summary['spin_kind']}, "
                  f"Q_R / Q*_RD {summary['q_r_over_q_rd_star']:.3g}")  # fmt: skip
            summaries.append(summary)

    with (folder / "summary.csv").open("w", newline="") as table:
        writer = csv.DictWriter(table, fieldnames=list(summaries[0]))
        writer.writeheader()
        writer.writerows(summaries)
    result = compare(summaries, by="spin_kind", metric="largest_mass_ratio", at="eta", reference="anti-parallel")
    for line in result.lines():
        print(line)
    print(f"runs in {folder}; their table: {folder / 'summary.csv'}")


if __name__ == "__main__":
    main()

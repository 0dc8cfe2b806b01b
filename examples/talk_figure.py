"""A figure for a talk: m_lf/m_t against eta, a line per friction coefficient, each point the mean
of its realizations with its 95 % interval (the numbers of `decco-warp compare`), LS12's small-body
law for reference; large type, no clutter, PNG and PDF.

    python examples/talk_figure.py runs/out/friction                 # after the friction study (README)
    python examples/talk_figure.py runs/out/friction --by mu_k --out friction_talk
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from decco_warp.analysis.compare import error_bars, label, typed_row  # noqa: E402

NAMES = {"mu_k": "sliding friction", "mu_r": "rolling friction", "restitution": "restitution", "spin_kind": "spins"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sweep", type=Path, help="a sweep's folder (its summary.csv)")
    parser.add_argument("--by", default="mu_k", help="the column whose values make the lines (a swept key)")
    parser.add_argument("--out", type=Path, default=None, help="the figure's path without suffix (default: SWEEP/figures/talk_BY)")
    args = parser.parse_args()

    with (args.sweep / "summary.csv").open(newline="") as table:
        rows = [typed_row(row) for row in csv.DictReader(table)]
    rows = [row for row in rows if row.get("status") != "failed"]
    bars = error_bars(rows, by=args.by, metric="largest_mass_ratio", at="eta")  # per group: mean and 95 % interval per eta

    plt.rcParams.update({"font.size": 16, "axes.spines.top": False, "axes.spines.right": False})
    fig, ax = plt.subplots(figsize=(8, 5.5))
    for k, (group, bar) in enumerate(sorted(bars.items(), key=lambda item: str(item[0]))):
        colour = plt.get_cmap("viridis")(k / max(1, len(bars) - 1) * 0.85)
        yerr = [np.nan_to_num(bar["minus"]), np.nan_to_num(bar["plus"])]  # a point of one run: no bar
        ax.errorbar(bar["at"], bar["mean"], yerr=yerr, color=colour, marker="o", markersize=8, linewidth=2.5, capsize=5,
                    label=f"{NAMES.get(args.by, args.by)} {label(group)}")  # fmt: skip
    law = sorted({(float(row["eta"]), float(row["ls12_largest_mass_ratio"])) for row in rows if row.get("ls12_largest_mass_ratio") is not None})
    if law:
        ax.plot(*zip(*law), color="0.5", linestyle="--", linewidth=2, label="LS12, small bodies")
    ax.axhline(1.0, color="0.8", linewidth=1)
    ax.set_xlabel("impact energy, eta = KE / |U|")
    ax.set_ylabel("largest remnant, m_lf / m_t")
    runs = {int(n) for bar in bars.values() for n in bar["n"]}
    ax.set_title(f"mean of {'/'.join(map(str, sorted(runs)))} realizations, 95 % interval", fontsize=13, color="0.3")
    ax.legend(frameon=False, fontsize=13)
    out = args.out or args.sweep / "figures" / f"talk_{args.by}"
    out.parent.mkdir(parents=True, exist_ok=True)
    for suffix in (".png", ".pdf"):
        fig.savefig(out.with_suffix(suffix), dpi=200, bbox_inches="tight")
    print(f"wrote {out.with_suffix('.png')} and {out.with_suffix('.pdf')}")


if __name__ == "__main__":
    main()

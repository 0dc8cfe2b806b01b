"""Fig. 6's size change split into a depth part (where the grains started: pile and depth shell) and
a sorting part (by size among grains that started alike), per mass ratio and eta over the five
realizations, for the committed head-on campaign (docs/validation.md, Fig. 6).

    python runs/results/size_change_split.py                 # from the repository root, on any machine (CPU)
    python runs/results/size_change_split.py --shells 20     # the shells the tables use (default 10)

Reads runs/results/fig6_statistics/*/ (analysis.h5's last frame: labels and grain masses; spec.toml's
pile files, whose grains are the run's in order: the target's, then the projectile's) and the pile
files under runs/paper/piles/ for each grain's starting depth (a pile's random turn leaves its
grains' distances from its centre as they are).  The split is decco_warp.analysis.size_split's.
The size change split is the last frame's (the summaries' particle_size_change and
particle_size_change_mass_weighted, reproduced here before they are split), not the late-window mean.
"""

from __future__ import annotations

import argparse
import json
import tomllib
from collections import defaultdict
from fractions import Fraction
from pathlib import Path

import numpy as np

from decco_warp.analysis.runs import read_analysis
from decco_warp.analysis.size_split import depth_shells, pile_shell_groups, ratio_interval, size_change_split, t_interval
from decco_warp.io import load_pile

ROOT = Path(__file__).resolve().parents[2]
CAMPAIGN = ROOT / "runs/results/fig6_statistics"
#: The shell counts of the sensitivity table.
SHELL_LADDER = (1, 2, 5, 10, 20, 40, 100, 250)
#: The summaries' values are reproduced to this (percentage points) before they are split.
REPRODUCED = 1e-9


def _piles(run_dir: Path, cache: dict) -> list:
    spec = tomllib.loads((run_dir / "spec.toml").read_text())
    piles = []
    for role in ("target", "projectile"):
        path = ROOT / spec["piles"][role]
        if path not in cache:
            cache[path] = load_pile(path)
        piles.append(cache[path])
    return piles


def read_runs(campaign: Path = CAMPAIGN) -> list[dict]:
    """Each run's summary, last-frame fragment (label 0, the finder's largest) and piles, checked
    against its summary: the grains' radii match the piles' in order, and m_lf/m_t and both size
    changes come back from the labels."""
    cache: dict = {}
    runs = []
    for run_dir in sorted(p.parent for p in campaign.glob("*/analysis.h5")):
        summary = json.loads((run_dir / "summary.json").read_text())
        final = read_analysis(run_dir / "analysis.h5")["final"]
        piles = _piles(run_dir, cache)
        if not np.array_equal(np.concatenate([p.radii for p in piles]), final["radius"]):
            raise SystemExit(f"{run_dir.name}: its grains' radii are not its piles', target then projectile")
        masses, fragment = final["particle_mass"], final["label"] == 0
        if not np.array_equal(np.concatenate([p.masses for p in piles]), masses):
            raise SystemExit(f"{run_dir.name}: its grains' masses are not its piles'")
        if not np.isclose(masses[fragment].sum() / summary["target_mass"], summary["largest_mass_ratio"], rtol=1e-12, atol=0):
            raise SystemExit(f"{run_dir.name}: label 0 is not the summary's largest fragment")
        runs.append({"run": run_dir.name, "summary": summary, "masses": masses, "fragment": fragment, "piles": piles})
    return runs


def split_run(run: dict, shells: int):
    groups = pile_shell_groups([p.positions for p in run["piles"]], [p.masses for p in run["piles"]], shells)
    split = size_change_split(run["masses"], run["fragment"], groups)
    summary = run["summary"]
    if abs(split.total - summary["particle_size_change"]) > REPRODUCED or abs(split.total_mass_weighted - summary["particle_size_change_mass_weighted"]) > REPRODUCED:
        raise SystemExit(f"{run['run']}: the size change from its labels ({split.total}, {split.total_mass_weighted}) is not its summary's")
    return split


def _ratio_label(mass_ratio: float) -> str:
    fraction = Fraction(mass_ratio).limit_denominator(20)
    return str(fraction.numerator) if fraction.denominator == 1 else f"{fraction.numerator}/{fraction.denominator}"


def _interval(values) -> str:
    mean, half = t_interval(values)
    return f"{mean:+.2f} +- {half:.2f}"


def _share(depth, total) -> str:
    ratio, low, high = ratio_interval(depth, total)
    text = f"{round(100 * ratio):d} %"
    return f"{text} ({round(100 * low):d} to {round(100 * high):d})" if low is not None else f"{text} (unbounded)"


def surface_table(runs: list[dict]) -> None:
    """The outer fifth of each pile's mass: its mean grain mass over the pile's."""
    print("The outer 20 % of each pile's mass (5 shells, the outermost): mean grain mass / the pile's")
    seen = {}
    for run in runs:
        for role, pile in zip(("target", "projectile"), run["piles"]):
            seen.setdefault(run["summary"][f"{role}_pile"], pile)
    for name, pile in sorted(seen.items()):
        outer = depth_shells(pile.positions, pile.masses, 5) == 4
        print(f"  {name:16s} {pile.n:5d} grains: {pile.masses[outer].mean() / pile.masses.mean():.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--shells", type=int, default=10, help="depth shells per pile (equal mass) of the tables")
    args = parser.parse_args()
    runs = read_runs()
    surface_table(runs)
    splits = {shells: [split_run(run, shells) for run in runs] for shells in sorted({*SHELL_LADDER, args.shells})}
    chosen = splits[args.shells]

    cells = defaultdict(list)
    for k, run in enumerate(runs):
        cells[(-run["summary"]["mass_ratio"], round(run["summary"]["eta"]))].append(k)
    for measure, total_of, depth_of in (
        ("per particle", lambda s: s.total, lambda s: s.depth),
        ("by mass", lambda s: s.total_mass_weighted, lambda s: s.depth_mass_weighted),
    ):
        print(f"\nThe last frame's size change {measure} [%], {args.shells} shells a pile: mean +- 95 % t half-width over the realizations; "
              f"share: depth part / total (Fieller's 95 % interval)")  # fmt: skip
        noise = measure == "per particle"  # the size-blind draws' standard error of a mean sorting part (points)
        print(f"{'ratio':>5} {'eta':>3} {'n':>2}  {'total':>14}  {'depth part':>14}  {'sorting part':>14}  {'noise' if noise else '':>5}  share of depth")
        for (ratio, eta), members in sorted(cells.items()):
            total = [total_of(chosen[k]) for k in members]
            depth = [depth_of(chosen[k]) for k in members]
            sorting = np.subtract(total, depth)
            error = np.sqrt(np.mean([chosen[k].null_sd ** 2 for k in members]) / len(members))
            print(f"{_ratio_label(-ratio):>5} {eta:>3} {len(members):>2}  {_interval(total):>14}  {_interval(depth):>14}  {_interval(sorting):>14}  "
                  f"{f'{error:.2f}' if noise else '':>5}  {_share(depth, total)}")  # fmt: skip
        total = [total_of(s) for s in chosen]
        depth = [depth_of(s) for s in chosen]
        error = np.sqrt(np.mean([s.null_sd**2 for s in chosen]) / len(chosen))
        print(f"{'all':>5} {'':>3} {len(runs):>2}  {_interval(total):>14}  {_interval(depth):>14}  {_interval(np.subtract(total, depth)):>14}  "
              f"{f'{error:.2f}' if noise else '':>5}  {_share(depth, total)}")  # fmt: skip

    print("\nShells a pile against the share of the depth part over all runs (Fieller's 95 % interval), and the")
    print("sorting part's size-blind noise (the median run's null_sd, points per particle)")
    piles = {id(pile): pile for run in runs for pile in run["piles"]}.values()
    for shells, split in splits.items():
        grains = min(np.bincount(depth_shells(p.positions, p.masses, shells), minlength=shells).min() for p in piles)
        share = _share([s.depth for s in split], [s.total for s in split])
        share_mass = _share([s.depth_mass_weighted for s in split], [s.total_mass_weighted for s in split])
        print(f"  {shells:3d} shells (>= {grains:4d} grains a shell): per particle {share:22s} by mass {share_mass:22s} "
              f"null sd {np.median([s.null_sd for s in split]):.2f}")  # fmt: skip


if __name__ == "__main__":
    main()

"""Fig. 9 under three friction rules (docs/validation.md, "Fig. 9: spin"): the committed campaign
made before sliding friction's zero-slip rule (fig9_statistics/, eta 3 and 6), the same set-ups
rerun with it (fig9_zero_slip/, eta 3 and 6), and DECCO's pair forces as its code computes them
(fig9_decco_code/, eta 6); then the energy-matched controls (fig9_energy_matched/: no spin at eta plus
the spin's energy, 0.0624) against no spin and against each kind under today's rule.

    python runs/results/fig9_rules.py          # from the repository root, on any machine (CPU)

For each rule and eta: each kind of spin's m_lf/m_t minus no spin's, with Dunnett's 95 % intervals (the
three kinds against one control together, as `decco-warp compare --by spin_kind --at eta` gives
them). Then the rules against each other, run by run: every set-up (its piles, orientation seed
and spins) is made under each rule, so the difference is taken per set-up and its mean given with
Student's t 95 % interval (paired: the set-up's own chance cancels).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from decco_warp.analysis.compare import Point, compare, read_rows, t_half_width, welch_interval

RESULTS = Path(__file__).resolve().parent
RULES = {  # folder: what made it
    "fig9_statistics": "before the zero-slip rule",
    "fig9_zero_slip": "the paper law today (zero-slip rule)",
    "fig9_decco_code": "decco-code (DECCO's code)",
}
KINDS = ("parallel", "perpendicular", "anti-parallel")
ETAS = (3.0, 6.0)
METRIC = "largest_mass_ratio"
#: The rotational energy of the two piles at half breakup over their binding energy (docs/validation.md,
#: "Fig. 9: spin"): fig9_energy_matched.toml's runs are at eta + this.
SPIN_ENERGY = 0.0624


def runs_of(folder: str, eta: float) -> dict[str, dict]:
    """{run name: summary row} of a folder's summary.csv at ``eta``."""
    rows = csv.DictReader((RESULTS / folder / "summary.csv").open())
    return {row["run"]: row for row in rows if abs(float(row["eta"]) - eta) < 1e-6}


def spin_effects(folder: str, eta: float = 6.0) -> Point:
    """A rule's point at ``eta``: each kind's m_lf/m_t minus no spin's with Dunnett's 95 % intervals,
    as ``decco-warp compare FOLDER/summary.csv --by spin_kind --at eta --where eta=6`` gives them
    (figures.py draws eta 6's)."""
    (point,) = compare(read_rows([RESULTS / folder / "summary.csv"]), "spin_kind", METRIC, at="eta", where={"eta": [eta]}).points
    return point


def energy_matched(eta: float) -> tuple[np.ndarray, np.ndarray, Point]:
    """At ``eta``: the m_lf/m_t of no spin (fig9_zero_slip/) and of its energy-matched control (no spin
    at eta + SPIN_ENERGY, fig9_energy_matched/), and each kind's difference to that control, Dunnett's
    95 % (the kinds relabelled to the control's point, which they match in energy)."""
    today = read_rows([RESULTS / "fig9_zero_slip" / "summary.csv"])
    controls = [row for row in read_rows([RESULTS / "fig9_energy_matched" / "summary.csv"]) if abs(row["eta"] - eta - SPIN_ENERGY) < 1e-6]
    none = np.array([row[METRIC] for row in today if abs(row["eta"] - eta) < 1e-6 and row["spin_kind"] == "none"])
    rows = [row for row in today if abs(row["eta"] - eta) < 1e-6 and row["spin_kind"] != "none"]
    rows += [{**row, "eta": eta, "spin_kind": "energy-matched"} for row in controls]
    (point,) = compare(rows, "spin_kind", METRIC, at="eta", reference="energy-matched").points
    return none, np.array([row[METRIC] for row in controls]), point


def main() -> None:
    for eta in ETAS:
        rules = {folder: runs for folder in RULES if (runs := runs_of(folder, eta))}
        print(f"m_lf/m_t at eta {eta:g}, each kind of spin minus no spin (Dunnett, 95 % together)")
        print(f"{'rule':40s} {'none':>13s}  " + "  ".join(f"{kind:>30s}" for kind in KINDS))
        for folder in rules:
            point = spin_effects(folder, eta)
            control = next(g for g in point.groups if g.group == "none")
            effect = {d.group: d for d in point.differences}
            cells = [f"{effect[k].difference:+.3f} ({effect[k].low:+.3f} to {effect[k].high:+.3f}){' *' if effect[k].resolved else '  '}" for k in KINDS]
            print(f"{RULES[folder]:40s} {control.mean:.3f} (n {control.n})  " + "  ".join(f"{c:>30s}" for c in cells))
        print("  * resolved: the interval excludes 0")

        print(f"\nrule against rule at eta {eta:g}, set-up by set-up (mean of the paired differences, t 95 %)")
        for new, old in (("fig9_zero_slip", "fig9_statistics"), ("fig9_decco_code", "fig9_zero_slip")):
            if new not in rules or old not in rules:
                continue
            a, b = rules[new], rules[old]
            twins = sorted(set(a) & set(b))
            if len(twins) != len(a) or len(twins) != len(b):
                raise SystemExit(f"{new} and {old} do not hold the same set-ups at eta {eta:g} ({len(a)}, {len(b)}, {len(twins)} in both)")
            print(f"{RULES[new]} minus {RULES[old]}:")
            paired = {}
            for kind in ("none", *KINDS, "all"):
                names = [name for name in twins if kind == "all" or a[name]["spin_kind"] == kind]
                differences = paired[kind] = np.array([float(a[name][METRIC]) - float(b[name][METRIC]) for name in names])
                half = t_half_width(differences)  # Student's t at every n (the 39 too), as docs/validation.md quotes them
                print(f"  {kind:14s} n {differences.size:2d}  {differences.mean():+.4f}  ({differences.mean() - half:+.4f} to "
                      f"{differences.mean() + half:+.4f}), std {differences.std(ddof=1):.4f}")
            # How the rule changes a kind's effect (its difference to no spin): its paired differences
            # against no spin's, Welch's 95 %.
            for kind in KINDS:
                low, high = welch_interval(paired[kind], paired["none"])
                print(f"  {kind:14s} effect of spin, {RULES[new]} minus {RULES[old]}: "
                      f"{paired[kind].mean() - paired['none'].mean():+.4f} ({low:+.4f} to {high:+.4f})")
        print()

    for eta in ETAS:
        none, control, point = energy_matched(eta)
        low, high = welch_interval(control, none)
        print(f"eta {eta:g}: no spin at eta + {SPIN_ENERGY} (n {control.size}) {control.mean():.4f} (std {control.std(ddof=1):.4f}) minus no spin "
              f"(n {none.size}) {none.mean():.4f} (std {none.std(ddof=1):.4f}): {control.mean() - none.mean():+.4f} ({low:+.4f} to {high:+.4f}, Welch 95 %)")
        effect = {d.group: d for d in point.differences}
        print("  each kind minus the energy-matched control (the spin's own part; Dunnett, 95 % together): " + ", ".join(
            f"{k} {effect[k].difference:+.4f} ({effect[k].low:+.4f} to {effect[k].high:+.4f}){' *' if effect[k].resolved else ''}" for k in KINDS))


if __name__ == "__main__":
    main()

"""Fig. 6's destructive points under four friction rules (docs/validation.md, "Fig. 6"): the
committed campaign made before sliding friction's zero-slip rule (fig6_statistics/, its eta 9 and
12 runs), the same set-ups rerun with it (fig6_zero_slip/), with DECCO's pair forces as its code
computes them (fig6_decco_code/) and with those and eps as DECCO's cor = 0.8 means it, 0.894
(fig6_decco_code_cor/).

    python runs/results/fig6_rules.py          # from the repository root, on any machine (CPU)

For each rule and point (mass ratio, eta): the late-window size change of the largest fragment's
mean grain, per particle and by mass, its mean with a 95 % interval against 0 and the runs that
shrink it (`decco-warp compare FOLDER/summary.csv --by mass_ratio --at eta --against 0`). Then
the rules against each other over the 30 set-ups, twin by twin (`--by folder --paired`: each
set-up is made under every rule, so its own chance cancels).
"""

from __future__ import annotations

from pathlib import Path

from decco_warp.analysis.compare import compare, label, read_rows

RESULTS = Path(__file__).resolve().parent
RULES = {  # folder: what made it
    "fig6_statistics": "before the zero-slip rule",
    "fig6_zero_slip": "the paper law today (zero-slip rule)",
    "fig6_decco_code": "decco-code (DECCO's code), eps 0.9",
    "fig6_decco_code_cor": "decco-code, eps 0.894 (cor 0.8)",
}
ETAS = (9.0, 12.0)  # the destructive points of every mass ratio
SIZE_CHANGE = {"size_change_late": "per particle", "size_change_mass_weighted_late": "by mass"}
#: Rule against rule: (new, old), each difference new minus old.
STEPS = (("fig6_zero_slip", "fig6_statistics"), ("fig6_decco_code", "fig6_zero_slip"), ("fig6_decco_code_cor", "fig6_decco_code"))


def rows_of(*folders: str) -> list[dict]:
    """The eta 9 and 12 rows of the folders' summary.csv files (each row's folder named)."""
    return [row for row in read_rows([RESULTS / f / "summary.csv" for f in folders]) if any(abs(float(row["eta"]) - e) < 1e-6 for e in ETAS)]


def size_change_table(folder: str, metric: str):
    """Per point (mass ratio at eta), the mean change and its 95 % interval against 0."""
    return compare(rows_of(folder), "mass_ratio", metric, at="eta", against=0.0)


def rule_step(new: str, old: str, metric: str):
    """``new`` minus ``old`` over every destructive set-up, twin by twin."""
    (point,) = compare(rows_of(new, old), "folder", metric, reference=old, paired=True, allow_mixed=True).points
    (difference,) = point.differences
    return difference


def main() -> None:
    print(f"Fig. 6's destructive points (eta {', '.join(f'{e:g}' for e in ETAS)}): the largest fragment's mean grain, late-window change [%]")
    for folder, made in RULES.items():
        print(f"\n{made} ({folder}/)")
        tables = {metric: size_change_table(folder, metric) for metric in SIZE_CHANGE}
        print(f"  {'mass ratio':>10s} {'eta':>4s}  " + "  ".join(f"{what + ': mean (95 %), runs < 0':>36s}" for what in SIZE_CHANGE.values()))
        for points in zip(*(t.points for t in tables.values())):
            for groups in zip(*(p.groups for p in points)):
                cells = []
                for g, d in zip(groups, (dict((x.group, x) for x in p.differences)[g.group] for p, g in zip(points, groups))):
                    cells.append(f"{d.difference:+.2f} ({d.low:+.2f} to {d.high:+.2f}), {sum(v < 0 for v in g.values)} of {g.n}")
                print(f"  {label(groups[0].group):>10s} {label(points[0].at):>4s}  " + "  ".join(f"{c:>36s}" for c in cells))
        counts = [sum(v < 0 for p in t.points for g in p.groups for v in g.values) for t in tables.values()]
        runs = sum(g.n for p in tables["size_change_late"].points for g in p.groups)
        print(f"  runs that shrink it: {counts[0]} of {runs} per particle, {counts[1]} of {runs} by mass")

    print("\nrule against rule, set-up by set-up (mean of the paired differences, 95 %; the bootstrap at 30 pairs)")
    for new, old in STEPS:
        print(f"{RULES[new]} minus {RULES[old]}:")
        for metric, what in {**{m: f"size change {w}" for m, w in SIZE_CHANGE.items()}, "largest_mass_ratio": "m_lf/m_t"}.items():
            d = rule_step(new, old, metric)
            print(f"  {what:24s} {d.difference:+.4f} ({d.low:+.4f} to {d.high:+.4f}), {d.pairs} pairs, r {d.correlation:.2f}"
                  + ("  resolved" if d.resolved else ""))


if __name__ == "__main__":
    main()

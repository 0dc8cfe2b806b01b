"""Draw docs/validation.md's figures from the committed paper runs (runs/results/fig*/).

    python runs/results/figures.py          # from the repository root; writes docs/figures/validation-*.png
    python runs/results/figures.py --runs   # also each run's own figures and each experiment's
                                            # cross-run figures, in place (not committed)
    python runs/results/figures.py validation-stress-shares validation-overlaps   # only these

Named figures (FIGURES' names, without .png) are drawn alone: those whose runs changed, the others
left as they are.

Reads only what the sweeps kept (summary.json and analysis.h5 of each run) and the paper's piles.
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import decco_warp as dw  # noqa: E402
from decco_warp.analysis import scaling  # noqa: E402
from decco_warp.analysis.figures import (  # noqa: E402
    ETA_LABELS,
    RATIO_MARKERS,
    SIZE_LABELS,
    STRESS_SHARE_PANELS,
    draw_points,
    draw_run,
    plot_size_change,
    realization_points,
    save,
    write_cross_run,
)
from decco_warp.analysis.runs import read_analysis  # noqa: E402
from decco_warp.collision import pile_radius  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "runs" / "results"
OUT = ROOT / "docs" / "figures"
PILES = ROOT / "runs" / "paper" / "piles"
PROJECTILES = {0.1: "proj500", 0.25: "proj1250", 1.0: "equal5000"}
MINUTE = 60.0


def runs(sweep: str, ratio: float | None = None) -> list[dict]:
    """Each run of a committed sweep (of one mass ratio if given): its summary and folder."""
    found = []
    for path in sorted((RESULTS / sweep).glob("*/summary.json")):
        summary = json.loads(path.read_text())
        if ratio is None or round(summary["mass_ratio"], 2) == ratio:
            found.append({"summary": summary, "dir": path.parent})
    return sorted(found, key=lambda r: r["summary"]["eta"])


RATIOS = ((0.1, "1/10"), (0.25, "1/4"), (1.0, "1"))
ANGLES = (0.0, 22.0, 44.0)


def ls12_curves(summary: dict, etas: np.ndarray, x: str = "eta_self") -> dict[str, np.ndarray]:
    """LS12 along eta (in the reading ``x``) for the piles and angle of one run, KE scaling with eta:
    the small-body law (c* = 5), its band (c* = 3 and 7) and the planets' fit (c* = 1.9)."""
    target = dw.load_pile(PILES / "target5000.h5")
    ratio = round(summary["mass_ratio"], 2)
    projectile = dw.load_pile(PILES / f"{PROJECTILES[ratio]}.h5")
    m_t, m_p = target.total_mass, projectile.total_mass
    reduced = m_t * m_p / (m_t + m_p)
    kinetic_per_eta = 0.5 * reduced * summary["speed"] ** 2 / summary[x]
    collision = {"target_mass": m_t, "projectile_mass": m_p, "target_radius": pile_radius(target),
                 "projectile_radius": pile_radius(projectile), "theta_deg": summary["theta_deg"]}  # fmt: skip
    curves = {}
    for column, law, c_star in scaling.LAW_COLUMNS:
        curves[column] = np.array([scaling.largest_mass_ratio({**collision, "kinetic_energy": kinetic_per_eta * e}, law=law, c_star=c_star) for e in etas])
    return curves


def points_of(summaries: list[dict], metric: str, x: str = "eta_self", shift: float = 1.0) -> list[dict]:
    """:func:`realization_points` with eta multiplied by ``shift`` (families at one eta set side by side)."""
    return [{**p, "eta": p["eta"] * shift} for p in realization_points(summaries, metric, x)]


#: The head-on runs at R = 4 (the same bodies, 4x the particles, contacts scaled as the ladder does):
#: Fig. 3's panels below the threshold, the ladder's 1/4 point and Q*_RD's disruptive end.
HEADON_R4 = ("fig3_headon_r4", "resolution/x4", "qstar_rd/x4")


def largest_fragment(x: str = "eta_self"):
    """Fig. 3 against eta in the reading ``x``: nine panels, angles by row and mass ratios by column,
    beside the LS12 small-body law with its band and the planets' fit; head-on, the same collisions
    at R = 4 beside them (drawn at 1.06 eta, so that the two sets stand apart)."""
    fig, axes = plt.subplots(3, 3, figsize=(13, 10.5), sharex=True, sharey="col")
    etas = np.geomspace(0.3, 15, 200)
    summaries = [r["summary"] for r in runs("fig3")]
    for row, angle in enumerate(ANGLES):
        for col, (ratio, label) in enumerate(RATIOS):
            ax = axes[row][col]
            mine = [s for s in summaries if round(s["mass_ratio"], 2) == ratio and s["theta_deg"] == angle]
            if mine:
                curves = ls12_curves(mine[0], etas, x)
                ax.fill_between(etas, curves["ls12_band_low"], curves["ls12_band_high"], color="C1", alpha=0.15, linewidth=0,
                                label="LS12 small bodies, c* = 3 to 7")  # fmt: skip
                ax.plot(etas, curves["ls12_largest_mass_ratio"], "--", color="C1", label="LS12 small bodies, c* = 5")
                ax.plot(etas, curves["ls12_planets_largest_mass_ratio"], ":", color="0.4", label="LS12 planets, c* = 1.9")
                draw_points(ax, points_of(mine, "largest_mass_ratio", x), "C0", "decco-warp (mean, range of realizations; hollow: not settled)")
                finer = [r["summary"] for folder in HEADON_R4 for r in runs(folder, ratio)] if angle == 0.0 else []
                if finer:
                    draw_points(ax, points_of(finer, "largest_mass_ratio", x, shift=1.06), "C3", "decco-warp at R = 4: 22 000 to 40 000 particles")
            else:
                ax.text(0.5, 0.5, "not run", transform=ax.transAxes, ha="center", color="0.5")
            ax.axhline(1.0, color="0.6", linewidth=0.6)
            ax.set_xscale("log")
            ax.set_title(f"m_p/m_t = {label}, theta = {angle:g} deg", fontsize=10)
            if row == 2:
                ax.set_xlabel(ETA_LABELS[x])
            if col == 0:
                ax.set_ylabel("m_lf / m_t")
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=4, fontsize=8, bbox_to_anchor=(0.5, -0.005))
    fig.subplots_adjust(bottom=0.1)
    return fig


def size_change():
    """Fig. 6: every run's particle-size change, a panel per angle, markers by mass ratio."""
    return plot_size_change([r["summary"] for r in runs("fig3")])


KINDS = ("none", "parallel", "anti-parallel", "perpendicular")


def spins():
    """Fig. 9: equal masses head-on. Left, m_lf/m_t vs eta per kind of spin (the bars span the runs
    that the kind consolidates: axis pairs and realizations); right, each run against the spins'
    shear of the first contact (the relative surface speed there), a marker per kind."""
    spinning = [r["summary"] for r in runs("fig9")]
    still = [r["summary"] for r in runs("fig3", 1.0) if r["summary"]["theta_deg"] == 0 and r["summary"]["eta"] >= 2.9]
    loose = [r["summary"] for r in runs("spin_friction")]
    fig, (ax, shear) = plt.subplots(1, 2, figsize=(12.0, 4.6))
    for k, kind in enumerate(KINDS):
        mine = still if kind == "none" else [s for s in spinning if s.get("spin_kind") == kind]
        if mine:
            draw_points(ax, points_of(mine, "largest_mass_ratio", "eta", 1 + 0.025 * k), f"C{k}", "no spin" if kind == "none" else f"{kind} spins")
        # spin_friction.toml: the same set-up at eta 3 without friction, to see whether friction hides the spin
        without = [s for s in loose if s.get("spin_kind") == kind]
        label = "open squares: without friction (mu_k = mu_r = 0)" if k == 0 else None
        ax.plot([s["eta"] * (1 + 0.025 * k) for s in without], [s["largest_mass_ratio"] for s in without], "s", mfc="none", color=f"C{k}", label=label)
    ax.set_xscale("log")
    ax.set_xlabel("eta = KE / |U| (spinning kinds set 2.5 % apart to be seen)")
    ax.set_ylabel("m_lf / m_t")
    ax.set_title("equal masses, head-on, spins at half breakup")
    ax.legend(fontsize=8)
    markers = dict(zip(KINDS, "osD^"))
    etas = sorted({round(s["eta"]) for s in spinning})
    for e, colour in zip(etas, ("C0", "C1", "C2", "C3")):
        reference = np.mean([s["largest_mass_ratio"] for s in still if round(s["eta"]) == e])
        for kind in KINDS:
            mine = [s for s in (still if kind == "none" else spinning) if round(s["eta"]) == e and (s.get("spin_kind") or "none") == kind]
            if mine:
                shear.plot([s["contact_surface_speed"] / 100.0 for s in mine], [s["largest_mass_ratio"] - reference for s in mine],
                           linestyle="", marker=markers[kind], color=colour, alpha=0.8, label=f"eta {e}, {kind}")  # fmt: skip
    shear.axhline(0.0, color="0.6", linewidth=0.6)
    shear.set_xlabel("relative surface speed from the spins at the first contact [m/s]")
    shear.set_ylabel("m_lf / m_t minus the no-spin mean at its eta")
    shear.set_title("by the shear of the first contact")
    shear.legend(fontsize=7, ncol=1, loc="center left", bbox_to_anchor=(1.01, 0.5))
    return fig


def spin_statistics():
    """Fig. 9 with statistics (runs/results/fig9_statistics): per eta a panel of each kind's
    realizations (dots), mean and 95 % interval of the mean (bar); right, each kind's difference to
    no spin with its 95 % interval (thick) and at 98.3 % (thin: the three kinds together at 95 %,
    Bonferroni): the numbers of ``decco-warp compare ... --by spin_kind --at eta --per-comparison [--confidence 0.983]``."""
    from decco_warp.analysis.compare import compare, read_rows

    rows = read_rows([RESULTS / "fig9_statistics"])
    comparison = compare(rows, "spin_kind", "largest_mass_ratio", at="eta", per_comparison=True)
    family = compare(rows, "spin_kind", "largest_mass_ratio", at="eta", confidence=1 - 0.05 / 3, per_comparison=True)
    colours = {kind: f"C{k}" for k, kind in enumerate(KINDS)}
    fig, axes = plt.subplots(1, len(comparison.points) + 1, figsize=(4.0 * (len(comparison.points) + 1), 4.4))
    diff = axes[-1]
    for e, (point, wide) in enumerate(zip(comparison.points, family.points)):
        ax = axes[e]
        for k, g in enumerate(sorted(point.groups, key=lambda g: KINDS.index(g.group))):
            values = np.array(g.values)
            ax.plot(np.full(len(values), k) + np.linspace(-0.15, 0.15, len(values)), values, ".", color=colours[g.group], alpha=0.5)
            ax.errorbar([k], [g.mean], yerr=[[g.mean - g.low], [g.high - g.mean]], marker="o", color=colours[g.group], capsize=4)
        ax.set_xticks(range(len(KINDS)), [f"{kind}\n(n = {next(g.n for g in point.groups if g.group == kind)})" for kind in KINDS], fontsize=8)
        ax.set_title(f"eta = {point.at:g}: realizations, mean, 95 % interval", fontsize=10)
        ax.set_ylabel("m_lf / m_t")
        x0 = e * (len(KINDS) + 1)
        for d, d_wide in zip(point.differences, wide.differences):
            x = x0 + KINDS.index(d.group)
            diff.errorbar([x], [d.difference], yerr=[[d.difference - d_wide.low], [d_wide.high - d.difference]], color=colours[d.group], linewidth=0.8, capsize=2)
            diff.errorbar([x], [d.difference], yerr=[[d.difference - d.low], [d.high - d.difference]], marker="o", color=colours[d.group],
                          linewidth=2.2, capsize=4, label=(d.group if e == 0 else None))  # fmt: skip
    diff.set_xticks([e * (len(KINDS) + 1) + 2 for e in range(len(comparison.points))], [f"eta {p.at:g}" for p in comparison.points])
    diff.axhline(0.0, color="0.6", linewidth=0.6)
    diff.set_ylabel("m_lf / m_t, kind minus no spin")
    diff.set_title("difference to no spin: 95 % (thick), 98.3 % (thin)", fontsize=10)
    diff.legend(fontsize=8)
    fig.suptitle("Fig. 9 with statistics: equal masses head-on, spins at half the breakup rate", fontsize=10)
    fig.tight_layout()
    return fig


def spin_rules():
    """Fig. 9 at eta 6 under three friction rules: each kind's difference to no spin with Dunnett's
    95 % intervals (the three kinds together), a marker per rule: fig9_rules.py's spin_effects of
    each folder of its RULES."""
    from fig9_rules import RULES, spin_effects  # beside this script

    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    kinds = [kind for kind in KINDS if kind != "none"]
    for r, (folder, name) in enumerate(RULES.items()):
        for d in spin_effects(folder).differences:
            x = kinds.index(d.group) + (r - 1) * 0.22
            ax.errorbar([x], [d.difference], yerr=[[d.difference - d.low], [d.high - d.difference]], marker="os^"[r], color=f"C{r}",
                        capsize=4, label=name if d.group == kinds[0] else None)  # fmt: skip
    ax.axhline(0.0, color="0.6", linewidth=0.6)
    ax.set_xticks(range(len(kinds)), kinds)
    ax.set_ylabel("m_lf / m_t, kind minus no spin")
    ax.set_title("Fig. 9 at eta 6 by friction rule: Dunnett's 95 % (10 runs a kind, 9 without spin)", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def size_change_statistics():
    """Fig. 6 with statistics (runs/results/fig6_statistics): per mass ratio and eta the late-window
    particle-size change of each realization (dots), its mean and the mean's 95 % interval (bar), per
    particle (left) and by mass (right): ``decco-warp compare ... --by mass_ratio --at eta --against 0``."""
    from decco_warp.analysis.compare import compare, read_rows

    rows = read_rows([RESULTS / "fig6_statistics"])
    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.4), sharey=True)
    metrics = (("size_change_late", "per particle"), ("size_change_mass_weighted_late", "by mass"))
    for ax, (metric, title) in zip(axes, metrics):
        comparison = compare(rows, "eta", metric, at="mass_ratio", against=0.0)
        for k, point in enumerate(comparison.points):
            ratio = round(point.at, 2)
            shift = (k - 1) * 0.5  # the ratios side by side at each eta
            colour, marker = f"C{k}", RATIO_MARKERS[ratio]
            for g in point.groups:
                ax.plot(np.full(len(g.values), g.group + shift) + np.linspace(-0.1, 0.1, len(g.values)), g.values, ".", color=colour, alpha=0.4)
            groups = point.groups
            ax.errorbar([g.group + shift for g in groups], [g.mean for g in groups], yerr=[[g.mean - g.low for g in groups], [g.high - g.mean for g in groups]],
                        marker=marker, color=colour, linestyle="", capsize=3, label=f"m_p/m_t = {dict(RATIOS)[ratio]} (n = 5 a point)")  # fmt: skip
        ax.axhline(0.0, color="0.6", linewidth=0.6)
        ax.set_xticks([p.group for p in comparison.points[0].groups])
        ax.set_xlabel("eta = KE / |U|")
        ax.set_title(f"largest fragment's mean grain mass change, {title}", fontsize=10)
    axes[0].set_ylabel("change over the last 10 % of the run [%]")
    axes[0].legend(fontsize=8)
    fig.suptitle("Fig. 6 with statistics: head-on, five realizations a point, mean and its 95 % interval", fontsize=10)
    fig.tight_layout()
    return fig


def stress_shares():
    """Fig. 8: a column per run (eta), a row per stress measure every run's analysis holds: the
    paper's largest overlap (which with one spring constant ranks force), and where the runs
    recorded them overlap / R^2 (force per cross-section area) and overlap / R (strain)."""
    found = runs("fig8")
    analyses = [read_analysis(run["dir"] / "analysis.h5") for run in found]
    measures = [name for name in STRESS_SHARE_PANELS if all(name in analysis for analysis in analyses)]
    size = (4.4, 3.8) if len(measures) == 1 else (3.6, 2.6)  # a frame every 40 s: dense lines, kept small
    fig, axes = plt.subplots(len(measures), len(found), figsize=(size[0] * len(found), size[1] * len(measures)), squeeze=False,
                             sharex=True, sharey="row")  # fmt: skip
    for i, (row, name) in enumerate(zip(axes, measures)):
        for ax, run, analysis in zip(row, found, analyses):
            share = analysis[name]
            t = share["time"] / MINUTE
            for k in range(share["value"].shape[1]):
                ax.plot(t[1:], share["value"][1:, k], color=f"C{k}", linewidth=0.8, label=SIZE_LABELS[k])
                ax.axhline(share["value"][0, k], color=f"C{k}", linestyle="--", linewidth=0.8)
            ax.axhline(1.0, color="0.5", linewidth=0.6)  # an even share
            ax.set_xscale("log")
            if i == len(measures) - 1:
                ax.set_xlabel("time since the start [min]")
            title = f"eta = {run['summary']['eta']:.3g}"
            ax.set_title(title if len(measures) == 1 else f"{title}, {STRESS_SHARE_PANELS[name]}", fontsize=None if len(measures) == 1 else 9)
        row[0].set_ylabel("100 N_top / N  (top 1 % by stress)" if len(measures) == 1 else "100 N_top / N  (top 1 %)")
    axes[0][0].legend(fontsize=8)
    if len(measures) > 1:
        fig.tight_layout()
    return fig


def conservation():
    run = runs("fig8")[-1]  # the fastest: eta = 12
    c = read_analysis(run["dir"] / "analysis.h5")["conservation"]
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    ax.plot(c["time"] / 3600, c["momentum_drift"], label="momentum")
    ax.plot(c["time"] / 3600, c["angular_momentum_drift"], label="angular momentum (orbital + spin)")
    ax.set_yscale("log")
    ax.set_xlabel("time [h]")
    ax.set_ylabel("drift / scale")
    ax.set_title(f"eta = {run['summary']['eta']:.3g}, theta = 22 deg, 1250 onto 5000 particles")
    ax.legend(fontsize=8)
    return fig


def overlaps():
    fig, ax = plt.subplots(figsize=(5.0, 4.0))
    sets = [("fig8", None, "Fig. 8 runs (the deepest of every step)")]
    sets += [("fig3", ratio, f"Fig. 3, m_p/m_t = {label} (every 5 000)") for ratio, label in RATIOS]
    for sweep, ratio, title in sets:
        s = [r["summary"] for r in runs(sweep, ratio)]
        marker = "o" if sweep == "fig8" else "s"
        if s:
            ax.plot([x["predicted_overlap"] for x in s], [x["deepest_overlap"] for x in s], marker, label=title,
                    zorder=3 if sweep == "fig8" else 2)  # fmt: skip
    line = np.array([0.1, 4.0])
    ax.plot(line, line, color="0.5", linewidth=0.8, label="measured = predicted")
    ax.plot(line, 0.1 * line, color="0.5", linestyle=":", linewidth=0.8, label="1/10 of predicted")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("predicted deepest overlap (fraction of the smallest radius)")
    ax.set_ylabel("deepest overlap recorded")
    ax.legend(fontsize=8)
    return fig


LADDER_ETAS = (3.0, 6.0, 9.0)


#: The ladder's two series: k_in and dt scaled with the radius (the same predicted compression at
#: every rung), and the paper's k_in and dt at every rung; R = 1 (Fig. 3's runs) belongs to both.
LADDER_SERIES = (("k_in, dt x N^(-1/3)", ("resolution", "resolution/x4", "resolution/x16")),
                 ("the paper's k_in, dt", ("resolution_paper_contacts", "resolution_paper_contacts/x4")))  # fmt: skip


def ladder_points(folders) -> list[dict]:
    """A series of the resolution ladder (1/4 head-on) from its result folders and the paper's
    runs: particles, eta, m_lf/m_t, the late-window size change and whether the run settled.  A
    folder's final_states.csv (runs/results/final_state.py: runs whose frames were not analysed)
    adds its runs' last states, m_lf/m_t only, drawn as not known to be settled."""
    points = []
    for folder in folders:
        table = RESULTS / folder / "final_states.csv"
        if table.is_file():
            for row in csv.DictReader(table.open()):
                points.append({"n": int(row["n_particles"]), "eta": round(float(row["eta"]), 6),
                               "value": float(row["largest_mass_ratio"]), "size_change": None, "firm": False})  # fmt: skip
    for run in [r for folder in folders for r in runs(folder)] + runs("fig3", 0.25):
        s = run["summary"]
        if s["theta_deg"] == 0.0 and round(s["eta"], 6) in LADDER_ETAS:
            points.append({"n": s["n_particles"], "eta": round(s["eta"], 6), "value": s["largest_mass_ratio"],
                           "size_change": s.get("size_change_late"), "firm": s.get("settled") is not False})  # fmt: skip
    return points


def resolution():
    """m_lf/m_t (left) and the late-window particle-size change (right) of the 1/4 head-on collision
    against the particle count, per eta and series: every run (hollow: not settled, or its last state only), the mean of
    each rung with its spread (one standard deviation); the paper's-contacts series dashed and
    drawn a little to the right."""
    fig, axes = plt.subplots(1, 2, figsize=(11.0, 4.6))
    every = set()
    for series, (label, folders) in enumerate(LADDER_SERIES):
        points = ladder_points(folders)
        every |= {p["n"] for p in points}
        shift = 1.08 if series else 1.0
        for ax, key in ((axes[0], "value"), (axes[1], "size_change")):
            for k, eta in enumerate(LADDER_ETAS):
                colour = f"C{k}"
                mine = [p for p in points if p["eta"] == eta and p[key] is not None]
                for p in mine:
                    ax.plot(p["n"] * shift, p[key], "o^"[series], color=colour, alpha=0.45, markersize=4,
                            markerfacecolor=colour if p["firm"] else "none")  # fmt: skip
                counts = sorted({p["n"] for p in mine})
                rungs = [[p[key] for p in mine if p["n"] == n] for n in counts]
                spreads = [np.std(r, ddof=1) if len(r) > 1 else 0.0 for r in rungs]
                ax.errorbar([n * shift for n in counts], [np.mean(r) for r in rungs], yerr=spreads, color=colour,
                            marker="s^"[series], linestyle="-" if series == 0 else "--", capsize=3,
                            label=f"eta = {eta:g}, {label}")  # fmt: skip
    counts = sorted(every)
    for ax, ylabel in ((axes[0], "m_lf / m_t"), (axes[1], "particle-size change, late mean [%]")):
        ax.set_xscale("log")
        ax.set_xticks(counts, [f"{n:,}".replace(",", " ") for n in counts])
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xlabel("particles (target + projectile)")
        ax.set_ylabel(ylabel)
    axes[0].legend(fontsize=7)
    fig.suptitle("1/4 head-on: the same bodies at 1/4 to 16 times the paper's particles, two contact series", fontsize=10)
    fig.tight_layout()
    return fig


def run_figures() -> None:
    """Each committed run's own figures into its figures/, each experiment's cross-run ones into its figures/."""
    for folder in sorted(p for p in RESULTS.iterdir() if p.is_dir()):
        found = runs(folder.name)
        for run in found:
            if (run["dir"] / "analysis.h5").is_file():  # summary-only folders keep no per-frame series
                draw_run(read_analysis(run["dir"] / "analysis.h5"), run["dir"])
        write_cross_run(folder, [r["summary"] for r in found])
        print(f"drew {folder.relative_to(ROOT)}: {len(found)} runs")


#: docs/figures' validation figures: name -> what draws it (from the committed runs).
FIGURES = {
    "validation-largest-fragment": lambda: largest_fragment("eta_self"),
    "validation-largest-fragment-eta-all": lambda: largest_fragment("eta_all"),
    "validation-size-change": size_change,
    "validation-spins": spins,
    "validation-spin-statistics": spin_statistics,
    "validation-spin-rules": spin_rules,
    "validation-size-change-statistics": size_change_statistics,
    "validation-stress-shares": stress_shares,
    "validation-conservation": conservation,
    "validation-overlaps": overlaps,
    "validation-resolution": resolution,
}


def main() -> None:
    args = sys.argv[1:]
    names = [a for a in args if not a.startswith("--")]
    unknown = [name for name in names if name not in FIGURES]
    if unknown:
        sys.exit(f"no figure {', '.join(unknown)} (one of {', '.join(FIGURES)})")
    if "--runs" in args:
        run_figures()
    for name in names or FIGURES:
        path = save(FIGURES[name](), OUT, name)[0]
        path.with_suffix(".pdf").unlink()
        print(f"wrote {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()

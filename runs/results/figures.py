"""Draw docs/validation.md's figures from the committed paper runs (runs/results/fig*/).

    python runs/results/figures.py          # from the repository root; writes docs/figures/validation-*.png

Reads only what the sweeps kept (summary.json and analysis.h5 of each run) and the paper's piles.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import decco_warp as dw  # noqa: E402
from decco_warp.analysis import scaling  # noqa: E402
from decco_warp.analysis.figures import SIZE_LABELS, plot_size_change, realization_points, save  # noqa: E402
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


def ls12_curve(summary: dict, etas: np.ndarray) -> np.ndarray:
    """The LS12 law's m_lf/m_t along eta for the piles and angle of one run (KE scales with eta)."""
    target = dw.load_pile(PILES / "target5000.h5")
    ratio = round(summary["mass_ratio"], 2)
    projectile = dw.load_pile(PILES / f"{PROJECTILES[ratio]}.h5")
    m_t, m_p = target.total_mass, projectile.total_mass
    reduced = m_t * m_p / (m_t + m_p)
    kinetic_per_eta = 0.5 * reduced * summary["speed"] ** 2 / summary["eta"]
    collision = {"target_mass": m_t, "projectile_mass": m_p, "target_radius": pile_radius(target),
                 "projectile_radius": pile_radius(projectile), "theta_deg": summary["theta_deg"]}  # fmt: skip
    return np.array([scaling.largest_mass_ratio({**collision, "kinetic_energy": kinetic_per_eta * e}) for e in etas])


def draw_points(ax, summaries: list[dict], metric: str, colour: str, label: str, shift: float = 1.0) -> None:
    """Each point's mean (marker and line), every realization faintly, a bar from the smallest to the
    largest; ``shift`` multiplies eta, to set families at the same eta side by side."""
    points = [{**p, "eta": p["eta"] * shift} for p in realization_points(summaries, metric)]
    etas, means = [p["eta"] for p in points], [p["mean"] for p in points]
    spread = [[m - p["low"] for m, p in zip(means, points)], [p["high"] - m for m, p in zip(means, points)]]
    ax.errorbar(etas, means, yerr=spread, marker="o", color=colour, capsize=3, label=label)
    several = [p for p in points if len(p["values"]) > 1]
    ax.plot([p["eta"] for p in several for _ in p["values"]], [v for p in several for v in p["values"]], ".", color=colour, alpha=0.35)


def largest_fragment():
    """Fig. 3: nine panels, angles by row and mass ratios by column, beside the LS12 law."""
    fig, axes = plt.subplots(3, 3, figsize=(13, 10.5), sharex=True, sharey="col")
    etas = np.geomspace(0.3, 15, 200)
    summaries = [r["summary"] for r in runs("fig3")]
    for row, angle in enumerate(ANGLES):
        for col, (ratio, label) in enumerate(RATIOS):
            ax = axes[row][col]
            mine = [s for s in summaries if round(s["mass_ratio"], 2) == ratio and s["theta_deg"] == angle]
            if mine:
                draw_points(ax, mine, "largest_mass_ratio", "C0", "decco-warp (mean, range of realizations)")
                ax.plot(etas, ls12_curve(mine[0], etas), "--", color="C1", label="LS12 universal law (small bodies)")
            else:
                ax.text(0.5, 0.5, "not run", transform=ax.transAxes, ha="center", color="0.5")
            if (ratio, angle) == (0.25, 22.0):  # the Fig. 8 runs: the same set-ups, stepped in another layout
                fig8 = [r["summary"] for r in runs("fig8")]
                ax.plot([x["eta"] for x in fig8], [x["largest_mass_ratio"] for x in fig8], "x", color="C2", label="Fig. 8 runs (fused layout)")
                ax.legend(fontsize=7, loc="lower left")
            ax.axhline(1.0, color="0.6", linewidth=0.6)
            ax.set_xscale("log")
            ax.set_title(f"m_p/m_t = {label}, theta = {angle:g} deg", fontsize=10)
            if row == 2:
                ax.set_xlabel("eta = KE / |U|")
            if col == 0:
                ax.set_ylabel("m_lf / m_t")
    axes[0][0].legend(fontsize=7, loc="lower left")  # merged runs sit top left, the law's tail bottom right
    return fig


def size_change():
    """Fig. 6: every run's particle-size change, a panel per angle, markers by mass ratio."""
    return plot_size_change([r["summary"] for r in runs("fig3")])


def spins():
    """Fig. 9: equal masses head-on, m_lf/m_t vs eta per kind of spin; the bars span the runs that the
    kind consolidates (axis pairs and realizations)."""
    spinning = [r["summary"] for r in runs("fig9")]
    still = [r["summary"] for r in runs("fig3", 1.0) if r["summary"]["theta_deg"] == 0 and r["summary"]["eta"] >= 2.9]
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for k, kind in enumerate(("none", "parallel", "anti-parallel", "perpendicular")):
        mine = still if kind == "none" else [s for s in spinning if s.get("spin_kind") == kind]
        if mine:
            draw_points(ax, mine, "largest_mass_ratio", f"C{k}", "no spin" if kind == "none" else f"{kind} spins", 1 + 0.025 * k)
        # spin_friction.toml: the same set-up at eta 3 without friction, to see whether friction hides the spin
        loose = [r["summary"] for r in runs("spin_friction") if r["summary"].get("spin_kind") == kind]
        label = "open squares: without friction (mu_k = mu_r = 0)" if k == 0 else None
        ax.plot([s["eta"] * (1 + 0.025 * k) for s in loose], [s["largest_mass_ratio"] for s in loose], "s", mfc="none", color=f"C{k}", label=label)
    ax.set_xscale("log")
    ax.set_xlabel("eta = KE / |U| (spinning kinds set 2.5 % apart to be seen)")
    ax.set_ylabel("m_lf / m_t")
    ax.set_title("equal masses, head-on, spins at half breakup")
    ax.legend(fontsize=8)
    return fig


def stress_shares():
    found = runs("fig8")
    fig, axes = plt.subplots(1, len(found), figsize=(4.4 * len(found), 3.8), squeeze=False, sharey=True)
    for ax, run in zip(axes[0], found):
        share = read_analysis(run["dir"] / "analysis.h5")["stress_share"]
        t = share["time"] / MINUTE
        for k in range(share["value"].shape[1]):
            ax.plot(t[1:], share["value"][1:, k], color=f"C{k}", linewidth=0.8, label=SIZE_LABELS[k])
            ax.axhline(share["value"][0, k], color=f"C{k}", linestyle="--", linewidth=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("time since the start [min]")
        ax.set_title(f"eta = {run['summary']['eta']:.3g}")
    axes[0][0].set_ylabel("100 N_top / N  (top 1 % by stress)")
    axes[0][0].legend(fontsize=8)
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
    sets = [("fig8", None, "Fig. 8 runs (a frame every 1 000 steps)")]
    sets += [("fig3", ratio, f"Fig. 3, m_p/m_t = {label} (every 5 000)") for ratio, label in RATIOS]
    for sweep, ratio, title in sets:
        s = [r["summary"] for r in runs(sweep, ratio)]
        marker = "o" if sweep == "fig8" else "s"
        if s:
            ax.plot([x["predicted_overlap"] for x in s], [x["deepest_overlap"] for x in s], marker, label=title)
    line = np.array([0.1, 4.0])
    ax.plot(line, line, color="0.5", linewidth=0.8, label="measured = predicted")
    ax.plot(line, 0.1 * line, color="0.5", linestyle=":", linewidth=0.8, label="1/10 of predicted")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("predicted deepest overlap (fraction of the smallest radius)")
    ax.set_ylabel("deepest overlap seen at the frames")
    ax.legend(fontsize=8)
    return fig


def main() -> None:
    for name, fig in [
        ("validation-largest-fragment", largest_fragment()),
        ("validation-size-change", size_change()),
        ("validation-spins", spins()),
        ("validation-stress-shares", stress_shares()),
        ("validation-conservation", conservation()),
        ("validation-overlaps", overlaps()),
    ]:
        path = save(fig, OUT, name)[0]
        path.with_suffix(".pdf").unlink()
        print(f"wrote {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()

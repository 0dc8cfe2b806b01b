"""Figures of a run's analysis and of a set of runs (matplotlib, PNG and PDF)."""

from __future__ import annotations

import io
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display needed
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

HOUR = 3600.0
#: A top 1 % of fewer grains than this makes the stress shares coarse: the figure says so.
COARSE_TOP = 20
SIZE_LABELS = ("R = 7.5 km", "R = 15 km", "R = 22.5 km")


def _size_label(k: int, radii=None) -> str:
    """Size class ``k`` by its radius: from the run's own radii where given (smallest first), else the paper's."""
    if radii is not None and k < len(radii):
        return f"R = {radii[k] / 1e5:g} km"
    return SIZE_LABELS[k] if k < len(SIZE_LABELS) else f"class {k}"


def save(fig, folder: Path, name: str) -> list[Path]:
    """Write ``name``.png and ``name``.pdf into ``folder``, each atomically; returns the paths."""
    from ..durable import write_atomic

    folder.mkdir(parents=True, exist_ok=True)
    paths = [folder / f"{name}.png", folder / f"{name}.pdf"]
    try:
        for path in paths:
            image = io.BytesIO()
            fig.savefig(image, format=path.suffix[1:], dpi=150, bbox_inches="tight")
            write_atomic(path, image.getvalue())
    finally:
        plt.close(fig)
    return paths


def plot_clusters(analysis: dict):
    """Fig. 2 style: the final snapshot projected on x-y, spheres at true size, coloured by cluster."""
    from matplotlib.collections import EllipseCollection
    from matplotlib.lines import Line2D

    final = analysis["final"]
    x = final["positions"] / 1e5
    diameter = 2.0 * final["radius"] / 1e5
    label = final["label"]
    order = np.argsort(x[:, 2])  # draw from -z to +z, so the near side is on top
    colours = plt.get_cmap("tab10")
    face = np.array([colours(k % 10) if k >= 0 else (0.75, 0.75, 0.75, 1.0) for k in label[order]])
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ax.add_collection(
        EllipseCollection(
            diameter[order], diameter[order], np.zeros(label.size), units="xy", offsets=x[order, :2],
            offset_transform=ax.transData, facecolors=face, edgecolors="0.2", linewidths=0.2,
        )
    )  # fmt: skip
    ax.autoscale_view()
    handles = [Line2D([], [], marker="o", linestyle="", color="0.75", label="unbound")] if (label < 0).any() else []
    for k in range(int(label.max()) + 1):
        share = final["mass"][k] / analysis["summary"]["target_mass"]
        handles.append(Line2D([], [], marker="o", linestyle="", color=colours(k % 10), label=f"{k + 1}: {share:.3g} m_t"))
    ax.set_aspect("equal")
    # As the paper's Fig. 2: the area where the clusters are (all particles if there are none),
    # since the unbound debris of a fast collision spreads over thousands of km.
    shown = x[label >= 0] if (label >= 0).any() else x
    low, high = shown[:, :2].min(axis=0), shown[:, :2].max(axis=0)
    margin = max(diameter.max(), 0.1 * float((high - low).max()))
    ax.set_xlim(low[0] - margin, high[0] + margin)
    ax.set_ylim(low[1] - margin, high[1] + margin)
    ax.set_xlabel("x [km] (the projectile came along +x)")
    ax.set_ylabel("y [km] (towards the impact parameter)")
    ax.set_title(f"clusters at t = {final['time'] / HOUR:.3g} h, in the impact plane")
    ax.annotate("", xy=(0.2, 0.06), xytext=(0.05, 0.06), xycoords="axes fraction",
                arrowprops={"arrowstyle": "->", "color": "0.3"})  # fmt: skip
    ax.text(0.05, 0.08, "impact", transform=ax.transAxes, fontsize=8, color="0.3")
    ax.legend(handles=handles, loc="best", fontsize=8)
    return fig


#: Drifts below this are drawn at it on the conservation figure's log axis (round-off at t = 0 is 0).
DRIFT_FLOOR = 1e-16


def plot_conservation(analysis: dict):
    """Fig. 4 style: relative drift of total momentum and angular momentum, on a log axis (values
    below DRIFT_FLOOR, the exact 0 at t = 0 among them, drawn at it)."""
    c = analysis["conservation"]
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    t = c["time"] / HOUR
    ax.plot(t, np.maximum(c["momentum_drift"], DRIFT_FLOOR), label="momentum")
    ax.plot(t, np.maximum(c["angular_momentum_drift"], DRIFT_FLOOR), label="angular momentum (orbital + spin)")
    ax.set_yscale("log")
    ax.set_xlabel("time [h]")
    ax.set_ylabel("drift, of the sum of |m v| (|L|) at t = 0")
    ax.set_title("conservation of momentum and angular momentum")
    ax.legend(fontsize=8, loc="lower right")
    return fig


#: The stress shares a run's figure compares, a panel each where the analysis has them (one kept
#: before decco-warp recorded the last two has the first only): analysis group -> panel title.
STRESS_SHARE_PANELS = {
    "stress_share": "by largest overlap delta (the paper's;\nwith one spring constant: by force)",
    "stress_share_per_area": "by delta / R^2\n(force per cross-section area)",
    "stress_share_strain": "by delta / R\n(contact strain)",
}


def plot_stress_shares(analysis: dict):
    """Fig. 8 style: 100 N_c,top / N_c for each size class vs time, dashed the value at t = 0, in a
    panel for each measure the analysis has (STRESS_SHARE_PANELS): the paper's largest overlap,
    which with one spring constant ranks force, beside overlap / R^2 (stress) and overlap / R (strain)."""
    panels = [name for name in STRESS_SHARE_PANELS if name in analysis]
    radii = np.unique(analysis["final"]["radius"]) if "final" in analysis else None
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels) + 1.8 * (len(panels) == 1), 4.0), squeeze=False, sharex=True)
    colours = plt.get_cmap("tab10")
    for ax, name in zip(axes[0], panels):
        s = analysis[name]
        t = s["time"] / HOUR
        for k in range(s["value"].shape[1]):
            ax.plot(t, s["value"][:, k], color=colours(k), label=_size_label(k, radii))
            ax.axhline(s["value"][0, k], color=colours(k), linestyle="--", linewidth=0.8)
        ax.axhline(1.0, color="0.5", linewidth=0.6)
        ax.set_xlabel("time [h]")
        ax.set_title(STRESS_SHARE_PANELS[name], fontsize=9)
    axes[0][0].set_ylabel("100 N_top / N  (top 1 % by stress)" if len(panels) == 1 else "100 N_top / N  (top 1 % by the panel's measure)")
    axes[0][0].legend(fontsize=8)
    top = math.ceil(0.01 * analysis["final"]["label"].size) if "final" in analysis else None
    coarse = top is not None and top < COARSE_TOP
    fig.suptitle("share of the most stressed particles by size" + (f"\n(top 1 % = {top} grains: each grain moves a share by a lot)" if coarse else ""),
                 color="C3" if coarse else "black", fontsize=10)  # fmt: skip
    fig.tight_layout()
    return fig


ENERGY_LINES = (
    ("kinetic", lambda e: e["kinetic_translational"] + e["kinetic_rotational"]),
    ("potential", lambda e: e["potential"]),
    ("elastic", lambda e: e["elastic"]),
    ("dissipated: sliding", lambda e: e["dissipated_sliding"]),
    ("dissipated: rolling", lambda e: e["dissipated_rolling"]),
    ("dissipated: hysteresis", lambda e: e["dissipated_hysteresis"]),
    ("total + dissipated", lambda e: e["total_energy"] + e["dissipated_sliding"] + e["dissipated_rolling"]
     + e["dissipated_hysteresis"] + e["integration_error"]),
)


def plot_energy(analysis: dict):
    """The energy ledger: where the collision's energy went."""
    e = analysis["energy"]
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    t = e["time"] / HOUR
    for name, value in ENERGY_LINES:
        ax.plot(t, value(e), label=name, linestyle="--" if name.startswith("total") else "-")
    ax.set_xlabel("time [h]")
    ax.set_ylabel("energy [erg]")
    ax.set_title("energy ledger")
    ax.legend(fontsize=8)
    return fig


def plot_largest_fragment_time(analysis: dict):
    """m_lf/m_t against time, each analysed frame a point on the line; the late window (the last
    10 % of the run, where the settled verdict is judged) shaded."""
    from .runs import late_window

    frames = analysis["frames"]
    t = np.asarray(frames["time"]) / HOUR
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.plot(t, frames["largest_mass_ratio"], marker=".", color="C0")
    late = late_window(frames["time"])
    if late.size:
        ax.axvspan(t[late[0]], t[-1], color="0.85", zorder=0, label="late window (settled verdict)")
        ax.legend(fontsize=8, loc="best")
    ax.axhline(1.0, color="0.6", linewidth=0.6)
    ax.set_xlabel("time [h]")
    ax.set_ylabel("m_lf / m_t")
    settled = analysis.get("summary", {}).get("settled")
    ax.set_title("largest fragment over the target's mass" + ("" if settled is None else ", settled" if settled else ", NOT settled"))
    return fig


def debris_sizes(final: dict) -> tuple[np.ndarray, np.ndarray]:
    """The debris size distribution of a run's last frame: fragment masses in decreasing order (every
    cluster, and each grain in no cluster as a fragment of its own) [g], and the cumulative mass of
    the fragments at least that massive [g]."""
    masses = np.concatenate([np.asarray(final["mass"], dtype=float), np.asarray(final["particle_mass"], dtype=float)[np.asarray(final["label"]) < 0]])
    masses = np.sort(masses)[::-1]
    return masses, np.cumsum(masses)


def plot_debris_sizes(analysis: dict):
    """The debris size distribution at the last frame: the cumulative mass of the fragments of mass
    >= m, over the total, against m over the total (log), each grain in no cluster a fragment of one grain."""
    final = analysis["final"]
    masses, cumulative = debris_sizes(final)
    total = float(np.asarray(final["particle_mass"], dtype=float).sum())
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.step(masses / total, cumulative / total, where="post", color="C0")
    ax.plot(masses / total, cumulative / total, linestyle="", marker=".", color="C0")
    ax.set_xscale("log")
    ax.set_ylim(0.0, 1.02)
    ax.invert_xaxis()
    ax.set_xlabel("fragment mass m / M_tot")
    ax.set_ylabel("mass in fragments of >= m, / M_tot")
    minimum = analysis.get("summary", {}).get("min_members")
    clusters = f"clusters of >= {minimum} grains" if minimum else "clusters"
    ax.set_title(f"debris at t = {final['time'] / HOUR:.3g} h ({clusters}; lone grains each a fragment)", fontsize=9)
    return fig


RUN_FIGURES = {
    "clusters": plot_clusters,
    "conservation": plot_conservation,
    "stress_shares": plot_stress_shares,
    "energy": plot_energy,
    "largest_fragment_time": plot_largest_fragment_time,
    "debris_sizes": plot_debris_sizes,
}


#: The run figures drawn from the final frame, and the array of it each needs (a lean analysis.h5,
#: runs/results/lean.py, keeps no final positions): no time axis, and none drawn without it.
FINAL_FRAME_FIGURES = {"clusters": "positions", "debris_sizes": "particle_mass"}


def draw_run(analysis: dict, run_dir: Path, end_time: float | None = None) -> list[Path]:
    """Every figure of RUN_FIGURES for one analysed run (those of the final frame only where it keeps
    what they draw), into ``run_dir``/figures; with ``end_time`` [s] the time axes run from 0 to it
    (the same scale for every run of a set)."""
    paths = []
    for name, plot in RUN_FIGURES.items():
        needs = FINAL_FRAME_FIGURES.get(name)
        if needs is not None and needs not in analysis.get("final", {}):
            continue
        fig = plot(analysis)
        if end_time is not None and needs is None:
            for ax in fig.axes:
                ax.set_xlim(0.0, end_time / HOUR)
        paths += save(fig, Path(run_dir) / "figures", name)
    return paths


def realization_points(summaries: list[dict], metric: str, x: str = "eta") -> list[dict]:
    """Runs of one set-up family grouped by ``x`` (eta in one reading: realizations of one point,
    the same piles, angle and spins, the piles turned otherwise), in increasing ``x``: per point its
    ``eta`` (the value of ``x``), every run's ``values``, their ``mean``, ``low`` and ``high``,
    whether every run is ``settled`` (a run analysed before the verdict counts as settled), and
    the LS12 law's value (``law``, small bodies), its band (``band_low``, ``band_high``) and the
    planets' fit (``planets``), each None where unknown.  Runs without a value are left out."""
    points: dict[float, list[dict]] = {}
    for s in summaries:
        if s.get(metric) is not None and s.get(x) is not None:
            points.setdefault(round(float(s[x]), 6), []).append(s)
    out = []
    for eta in sorted(points):
        runs = points[eta]
        values = np.array([float(r[metric]) for r in runs])
        first = runs[0]
        out.append({"eta": float(first[x]), "values": values, "mean": float(values.mean()), "low": float(values.min()),
                    "high": float(values.max()), "settled": all(r.get("settled", True) is not False for r in runs),
                    "law": first.get(f"ls12_{metric}"), "band_low": first.get("ls12_band_low"),
                    "band_high": first.get("ls12_band_high"), "planets": first.get("ls12_planets_largest_mass_ratio")})  # fmt: skip
    return out


ETA_LABELS = {"eta": "eta = KE / |U|", "eta_self": "eta = KE / |U| (U: each pile's own pairs)",
              "eta_all": "eta = KE / |U| (U: all pairs at set-up)"}  # fmt: skip


def draw_points(ax, points: list[dict], colour, label: str | None) -> None:
    """Each point's mean (a line through them), every realization faintly, a bar from the smallest
    to the largest; a point whose runs are not all settled is drawn hollow (its value is not final)."""
    etas, means = [p["eta"] for p in points], [p["mean"] for p in points]
    ax.plot(etas, means, color=colour, label=label)
    for settled in (True, False):
        chosen = [p for p in points if p["settled"] == settled]
        if chosen:
            ax.plot([p["eta"] for p in chosen], [p["mean"] for p in chosen], linestyle="", marker="o", color=colour,
                    mfc=colour if settled else "white")  # fmt: skip
    several = [p for p in points if len(p["values"]) > 1]
    if several:
        ax.plot([p["eta"] for p in several for _ in p["values"]], [v for p in several for v in p["values"]],
                linestyle="", marker=".", alpha=0.35, color=colour)  # fmt: skip
        spread = [[p["mean"] - p["low"] for p in several], [p["high"] - p["mean"] for p in several]]
        ax.errorbar([p["eta"] for p in several], [p["mean"] for p in several], yerr=spread, linestyle="", color=colour, capsize=3)


def draw_law(ax, points: list[dict], colour, label: str) -> None:
    """LS12 at the runs' own set-ups: the small-body law (dashed) in its band c* = 3 to 7 (shaded),
    and the planets' fit (dotted)."""
    known = [p for p in points if p["law"] is not None]
    if not known:
        return
    etas = [p["eta"] for p in known]
    ax.plot(etas, [p["law"] for p in known], linestyle="--", color=colour, label=f"{label}: LS12 small bodies (c* = 5, band 3 to 7)")
    if all(p["band_low"] is not None for p in known):
        ax.fill_between(etas, [p["band_low"] for p in known], [p["band_high"] for p in known], color=colour, alpha=0.12, linewidth=0)
    if all(p["planets"] is not None for p in known):
        ax.plot(etas, [p["planets"] for p in known], linestyle=":", color=colour, label=f"{label}: LS12 planets (c* = 1.9)")


#: Set-up columns that never split runs into series of their own: the x axis (eta, or the speed that
#: gave it), the angle and the kind of spin (each figure's own families), and what a realization draws
#: (its orientation seed, its piles; spin axes count by their kind).
NOT_SPLIT = ("eta", "speed", "theta_deg", "orientation_seed", "target_spin_axis", "projectile_spin_axis", "target_pile", "projectile_pile")


def split_columns(summaries: list[dict], candidates) -> list[str]:
    """Of the ``candidates`` (a sweep's swept columns, say), those that take more than one value
    among ``summaries`` (numbers to 6 significant digits, compare.value_key) and are not NOT_SPLIT:
    the columns whose values make series of their own."""
    from .compare import value_key

    return [c for c in dict.fromkeys(candidates) if c not in NOT_SPLIT and len({_key(value_key, s.get(c)) for s in summaries}) > 1]


def _key(value_key, value):
    """A value as a group's key: numbers rounded, lists (a spin axis) as tuples."""
    return tuple(value) if isinstance(value, list) else value_key(value)


def group_key(summary: dict, split: list[str]) -> tuple:
    """The values of the ``split`` columns of a run, rounded (compare.value_key): runs with the same
    key are realizations of one series."""
    from .compare import value_key

    return tuple(_key(value_key, summary.get(c)) for c in split)


def group_label(key: tuple, split: list[str]) -> str:
    """A series' values in words: "mu_k 0.3, restitution 0.5"."""
    from .compare import label

    return ", ".join(f"{c} {label(v)}" for c, v in zip(split, key))


def family_order(key: tuple):
    """Sort key of (angle, spin kind, *split values) over numbers, text and None together."""
    return tuple((0, v, "") if isinstance(v, (int, float)) and not isinstance(v, bool) else (1, 0, str(v)) for v in key)


def family_of(summary: dict, split: list[str]) -> tuple:
    """A run's series: its angle, kind of spin and values of the ``split`` columns."""
    return (summary.get("theta_deg"), summary.get("spin_kind") or "none", *group_key(summary, split))


def family_label(key: tuple, split: list[str]) -> str:
    """A series (:func:`family_of`) in words: "22 deg, parallel spins, mu_k 0.3"."""
    angle, spins = key[:2]
    return f"{angle:g} deg" + (f", {spins} spins" if spins != "none" else "") + (f", {group_label(key[2:], split)}" if split else "")


def ratio_panels(summaries: list[dict], split: list[str]):
    """A figure of a panel per mass ratio (sharing their axes), and for each panel (ax, ratio, its
    series): (k, series key, its label, its runs), in order."""
    ratios = sorted({round(s["mass_ratio"], 3) for s in summaries})
    fig, axes = plt.subplots(1, len(ratios), figsize=(4.4 * len(ratios), 3.8), squeeze=False, sharey=True, sharex=True)
    panels = []
    for ax, ratio in zip(axes[0], ratios):
        mine = [s for s in summaries if round(s["mass_ratio"], 3) == ratio]
        keys = sorted({family_of(s, split) for s in mine}, key=family_order)
        panels.append((ax, ratio, [(k, key, family_label(key, split), [s for s in mine if family_of(s, split) == key]) for k, key in enumerate(keys)]))
    return fig, panels


def series_points(panels, points_of, metric: str, x: str):
    """Over :func:`ratio_panels`' panels, each series with points: (ax, k, series in its panel,
    label, ``points_of(runs, metric, x)``)."""
    for ax, _, series in panels:
        for k, _, label, runs in series:
            points = points_of(runs, metric, x)
            if points:
                yield ax, k, len(series), label, points


def label_panel(ax, ratio: float, x: str) -> None:
    """A mass ratio's panel: its title, its eta axis, its legend."""
    ax.set_title(f"m_p / m_t = {ratio:g}")
    ax.set_xlabel(ETA_LABELS.get(x, x))
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)


def plot_runs(summaries: list[dict], metric: str, ylabel: str, x: str = "eta", split: list[str] = ()):
    """Cross-run figure (Fig. 3 / Fig. 9 style): ``metric`` vs eta (``x``: "eta", "eta_self" or
    "eta_all"), one panel per mass ratio, a line per angle, kind of spin and values of the ``split``
    columns (a sweep's swept keys) through each point's mean; where a point has several
    realizations, each drawn faintly and a bar from the smallest to the largest; unsettled points
    hollow; for m_lf/m_t, the Leinhardt & Stewart (2012) law at the same set-ups (:func:`draw_law`).
    Panels share their axes."""
    fig, panels = ratio_panels(summaries, split)
    for ax, k, _, label, points in series_points(panels, realization_points, metric, x):
        colour = plt.get_cmap("tab10")(k % 10)
        draw_points(ax, points, colour, label)
        if metric == "largest_mass_ratio":
            draw_law(ax, points, colour, label)
    for ax, ratio, _ in panels:
        label_panel(ax, ratio, x)
    fig.axes[0].set_ylabel(ylabel + "  (hollow: not settled)")
    return fig


#: Fig. 6's markers by mass ratio m_p/m_t (others: a diamond).
RATIO_MARKERS = {0.1: "s", 0.25: "^", 1.0: "o"}


def size_change_value(summary: dict) -> tuple[float | None, float]:
    """A run's particle-size change for Fig. 6: the mean over its late window and the spread there
    (0 where only the last frame is known), else the last frame's value."""
    if summary.get("size_change_late") is not None:
        return summary["size_change_late"], summary.get("size_change_late_std") or 0.0
    return summary.get("particle_size_change"), 0.0


def plot_size_change(summaries: list[dict], split: list[str] = ()):
    """Fig. 6 style: the largest fragment's particle-size change (mean over the last 10 % of the run,
    a bar of one standard deviation of its frames there) vs eta from every run, one panel per angle
    (and per values of the ``split`` columns), markers by mass ratio, constructive (m_lf > m_t) blue
    and destructive orange, unsettled hollow."""
    panels = sorted({(s["theta_deg"], *group_key(s, split)) for s in summaries}, key=family_order)
    fig, axes = plt.subplots(1, len(panels), figsize=(4.4 * len(panels), 3.8), squeeze=False, sharey=True, sharex=True)
    for ax, panel in zip(axes[0], panels):
        angle = panel[0]
        mine = [s for s in summaries if (s["theta_deg"], *group_key(s, split)) == panel and size_change_value(s)[0] is not None]
        for ratio in sorted({round(s["mass_ratio"], 2) for s in mine}):
            runs = [s for s in mine if round(s["mass_ratio"], 2) == ratio]
            for constructive, colour in ((True, "C0"), (False, "C1")):
                chosen = [s for s in runs if (s["largest_mass_ratio"] > 1) == constructive]
                if not chosen:
                    continue
                values = [size_change_value(s) for s in chosen]
                marker = RATIO_MARKERS.get(ratio, "D")
                ax.errorbar([s["eta"] for s in chosen], [v for v, _ in values], yerr=[e for _, e in values], linestyle="",
                            color=colour, alpha=0.8, capsize=2)  # fmt: skip
                for settled in (True, False):
                    mark = [(s, v) for s, (v, _) in zip(chosen, values) if (s.get("settled") is not False) == settled]
                    if mark:
                        kind = "constructive" if constructive else "destructive"
                        ax.plot([s["eta"] for s, _ in mark], [v for _, v in mark], linestyle="", marker=marker, color=colour,
                                mfc=colour if settled else "white", label=f"m_p/m_t = {ratio:g}, {kind}" + ("" if settled else ", not settled"))  # fmt: skip
        ax.axhline(0.0, color="0.6", linewidth=0.6)
        ax.set_xscale("log")
        ax.set_xlabel("eta = KE / |U|")
        ax.set_title(f"theta = {angle:g} deg" + (f"\n{group_label(panel[1:], split)}" if split else ""))
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    axes[0][0].set_ylabel("largest fragment's mean grain mass change [%]")
    return fig


def interval_points(summaries: list[dict], metric: str, x: str = "eta", confidence: float = 0.95) -> list[dict]:
    """Per value of ``x`` (rounded as compare's points), the realizations' mean of ``metric`` and its
    ``confidence`` interval (Student's t below 30 runs, as decco-warp compare: compare.mean_interval;
    None for one run), with ``n``."""
    from .compare import mean_interval, value_key

    points: dict = {}
    for s in summaries:
        if s.get(metric) is not None and s.get(x) is not None:
            points.setdefault(value_key(float(s[x])), []).append(float(s[metric]))
    out = []
    for at in sorted(points):
        values = np.array(points[at])
        low, high, _ = mean_interval(values, confidence)
        out.append({"at": at, "n": int(values.size), "mean": float(values.mean()), "low": low, "high": high})
    return out


def plot_intervals(summaries: list[dict], metric: str, ylabel: str, split: list[str] = (), x: str = "eta"):
    """A sweep's outcome against eta, a series per angle, kind of spin and values of the ``split``
    columns (its swept keys), each point the realizations' mean with its 95 % interval (Student's t;
    a point of one run without a bar, its n shown): what ``decco-warp compare --at eta`` compares."""
    fig, panels = ratio_panels(summaries, split)
    for ax, k, count, label, points in series_points(panels, interval_points, metric, x):
        colour = plt.get_cmap("tab10")(k % 10)
        offset = 1.0 + 0.01 * (k - (count - 1) / 2)  # series side by side, not on top of each other
        at = np.array([p["at"] for p in points], dtype=float) * offset
        means = np.array([p["mean"] for p in points])
        minus = np.array([p["mean"] - p["low"] if p["low"] is not None else np.nan for p in points])
        plus = np.array([p["high"] - p["mean"] if p["high"] is not None else np.nan for p in points])
        ax.errorbar(at, means, yerr=[minus, plus], color=colour, marker="o", capsize=3, label=label)
        for xv, yv, p in zip(at, means, points):
            ax.annotate(f"n={p['n']}", (xv, yv), textcoords="offset points", xytext=(4, 4), fontsize=6, color=colour)
    for ax, ratio, _ in panels:
        label_panel(ax, ratio, x)
    fig.axes[0].set_ylabel(ylabel + " (mean, 95 % interval)")
    return fig


def plot_histories(summaries: list[dict], histories: dict, split: list[str] = ()):
    """m_lf/m_t against time of every run of a set, overlaid, a colour per angle, kind of spin and
    values of the ``split`` columns (``histories``: run name -> (time [s], m_lf/m_t) of its analysed frames)."""
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    drawn = [s for s in summaries if s.get("run") in histories]
    for k, key in enumerate(sorted({family_of(s, split) for s in drawn}, key=family_order)):
        colour = plt.get_cmap("tab10")(k % 10)
        runs = [s for s in drawn if family_of(s, split) == key]
        for n, s in enumerate(runs):
            time, ratio = histories[s["run"]]
            label = f"{family_label(key, split)} ({len(runs)} run{'s' if len(runs) > 1 else ''})" if n == 0 else None
            ax.plot(np.asarray(time) / HOUR, ratio, color=colour, alpha=0.7, linewidth=1.0, label=label)
    ax.axhline(1.0, color="0.6", linewidth=0.6)
    ax.set_xlabel("time [h]")
    ax.set_ylabel("m_lf / m_t")
    ax.set_title("largest fragment of every run")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=7)
    return fig


CROSS_RUN_FIGURES = {
    "largest_fragment": lambda summaries, split: plot_runs(summaries, "largest_mass_ratio", "m_lf / m_t", split=split),
    "largest_fragment_intervals": lambda summaries, split: plot_intervals(summaries, "largest_mass_ratio", "m_lf / m_t", split=split),
    "particle_size_change": plot_size_change,
}


def line_data(fig) -> list[tuple[np.ndarray, np.ndarray]]:
    """(x, y) of every line drawn in a figure, for checking a figure against its data."""
    return [(np.asarray(line.get_xdata()), np.asarray(line.get_ydata())) for ax in fig.axes for line in ax.lines]


def write_cross_run(folder: Path, summaries: list[dict], split=(), histories: dict | None = None) -> list[Path]:
    """The cross-run figures of a set of analysed runs (those with an eta and a mass ratio), their
    series split by those of the columns ``split`` (a sweep's swept keys) that vary among them, and
    with ``histories`` (run name -> (time, m_lf/m_t), runs.read_history) every run's m_lf/m_t
    against time overlaid (largest_fragment_time)."""
    usable = [s for s in summaries if s.get("eta") is not None and s.get("mass_ratio") is not None]
    paths = []
    if usable:
        columns = split_columns(usable, split)
        for name, plot in CROSS_RUN_FIGURES.items():
            paths += save(plot(usable, columns), folder / "figures", name)
        if histories:
            paths += save(plot_histories(usable, histories, columns), folder / "figures", "largest_fragment_time")
    return paths

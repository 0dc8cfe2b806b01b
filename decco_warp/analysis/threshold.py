"""The catastrophic disruption threshold Q*_RD of a set of runs, with its interval, and the constants
of Leinhardt & Stewart's (2012) law (c*, mu_bar) from the thresholds of several mass ratios.

Each run gives one point: its specific impact energy Q_R = 1/2 mu V^2 / M_tot (mu = m_t m_p / M_tot,
V the relative speed at set-up) and its largest remnant as a fraction of the total mass,
M_lr / M_tot = (m_lf / m_t) / (1 + gamma).  In the law's linear regime (0.1 < M_lr / M_tot < 0.9
here) the remnant falls on a line in Q_R; Q*_RD is the Q_R where the least-squares line through the
runs there crosses 1/2.  The line's slope is fitted, not fixed by the law (which puts the line
through 1 at Q_R = 0): its intercept is reported beside the threshold, so that how well the law's
shape holds can be read off.

    rows = read_rows(["runs/results/qstar_rd"])            # analysis/compare.py
    for ratio, threshold in thresholds(rows).items():
        print(ratio, threshold.q_star, threshold.low, threshold.high)
    fit = law_constants(list(thresholds(rows).values()))
    fit.c_star, fit.mu_bar
    threshold_ratio(thresholds(rows)[0.25], thresholds(other_rows)[0.25]).ratio   # one set's Q*_RD over another's

Intervals: Q*_RD's is Fieller's interval of the line's crossing (exact for a straight line with
normal scatter of one size; the runs' realizations are the scatter), c* and mu_bar's come from the
thresholds' own errors (the delta method) through the law's log-linear form, and a ratio of two
sets' thresholds (friction off over on, R = 4 over R = 1) from theirs on its log.  Pure NumPy and SciPy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..checks import InputError
from ..params import G_CGS
from .scaling import equal_mass_threshold, mass_ratio_factor  # noqa: F401 (threshold's names too)

#: Runs whose remnant holds this fraction of the total mass or more, or this little or less, lie off
#: the law's straight line (a merger's plateau, the super-catastrophic tail) and are not fitted.
LINEAR_REGIME = (0.1, 0.9)
#: Intervals are at this confidence (two-sided).
CONFIDENCE = 0.95


def specific_impact_energy(target_mass: float, mass_ratio: float, speed: float) -> float:
    """Q_R = 1/2 mu V^2 / M_tot [erg/g] of a collision of a target of ``target_mass`` [g] with a
    projectile of ``mass_ratio`` times it at relative ``speed`` [cm/s]."""
    projectile_mass = mass_ratio * target_mass
    total = target_mass + projectile_mass
    return 0.5 * target_mass * projectile_mass / total * speed**2 / total


def remnant_fraction(largest_mass_ratio: float, mass_ratio: float) -> float:
    """M_lr / M_tot of a run whose largest fragment holds ``largest_mass_ratio`` target masses."""
    return largest_mass_ratio / (1.0 + mass_ratio)


@dataclass(frozen=True)
class Threshold:
    """Q*_RD of one set of runs (one mass ratio, one angle) and the line it is read from."""

    q_star: float
    """Q*_RD [erg/g]: where the fitted line crosses M_lr / M_tot = 1/2."""
    low: float
    """Lower end of its interval [erg/g] (Fieller's, at ``confidence``)."""
    high: float
    """Upper end [erg/g]; inf where the slope is not resolved from zero (the runs do not bracket it)."""
    std: float
    """Its standard error by the delta method [erg/g] (what law_constants propagates)."""
    slope: float
    """d(M_lr / M_tot) / dQ_R [g/erg] of the fitted line (the law's: -1 / (2 Q*_RD))."""
    intercept: float
    """The fitted line at Q_R = 0 (the law's: 1)."""
    runs: int
    """Runs in the linear regime, fitted."""
    energies: int
    """Distinct impact energies among them."""
    target_mass: float
    """[g], of the runs (LS12's R_C1 is that of M_tot)."""
    mass_ratio: float
    """gamma, of the runs."""
    confidence: float = CONFIDENCE

    @property
    def law_slope_ratio(self) -> float:
        """The fitted slope over the law's, -1 / (2 Q*_RD): 1 where the law's shape holds."""
        return self.slope * -2.0 * self.q_star


def disruption_threshold(
    q_r, fraction, target_mass: float, mass_ratio: float, confidence: float = CONFIDENCE, regime: tuple[float, float] = LINEAR_REGIME
) -> Threshold:
    """Q*_RD from runs' specific impact energies ``q_r`` [erg/g] and remnant fractions ``fraction``
    (M_lr / M_tot), fitting those inside ``regime``; InputError where fewer than three runs at two
    energies lie there, or where the remnant does not fall with energy."""
    q_r, fraction = np.asarray(q_r, dtype=float), np.asarray(fraction, dtype=float)
    inside = (fraction > regime[0]) & (fraction < regime[1])
    x, y = q_r[inside], fraction[inside]
    energies = len({float(f"{value:.6g}") for value in x})  # the same set-up's runs differ at round-off
    if x.size < 3 or energies < 2:
        raise InputError(
            f"Q*_RD needs at least three runs at two impact energies with M_lr/M_tot in {regime}; "
            f"got {x.size} at {energies} (of {q_r.size} runs)"
        )
    n = x.size
    x_mean, y_mean = x.mean(), y.mean()
    sxx = ((x - x_mean) ** 2).sum()
    slope = ((x - x_mean) * (y - y_mean)).sum() / sxx
    intercept = y_mean - slope * x_mean
    if slope >= 0:
        raise InputError(f"the remnant does not fall with impact energy over these runs (slope {slope:.3g} g/erg): no Q*_RD")
    residual = y - (intercept + slope * x)
    s2 = (residual**2).sum() / (n - 2) if n > 2 else 0.0
    crossing = (0.5 - intercept) / slope
    # Delta method: x0 = x_mean + (1/2 - y_mean) / b, with y_mean and b independent for OLS.
    std = math.sqrt(s2 / slope**2 * (1.0 / n + (crossing - x_mean) ** 2 / sxx))
    low, high = _fieller(crossing, x_mean, slope, s2, sxx, n, confidence)
    return Threshold(float(crossing), low, high, float(std), float(slope), float(intercept), n, energies, float(target_mass), float(mass_ratio), confidence)


def _fieller(crossing: float, x_mean: float, slope: float, s2: float, sxx: float, n: int, confidence: float) -> tuple[float, float]:
    """Fieller's interval of the x where a least-squares line crosses a level (calibration of the
    mean line): the x whose fitted mean is not distinguishable from the level at ``confidence``."""
    t = stats.t.ppf(0.5 + confidence / 2, n - 2)
    g = t**2 * s2 / (slope**2 * sxx)
    if g >= 1:  # the slope is not resolved from zero: the crossing is bounded on neither side
        return -math.inf, math.inf
    offset = crossing - x_mean
    half = t * math.sqrt(s2) / abs(slope) * math.sqrt(offset**2 / sxx + (1.0 - g) / n)
    ends = sorted((x_mean + (offset + half) / (1.0 - g), x_mean + (offset - half) / (1.0 - g)))
    return float(ends[0]), float(ends[1])


def thresholds(rows: list[dict], confidence: float = CONFIDENCE, regime: tuple[float, float] = LINEAR_REGIME) -> dict[float, Threshold]:
    """Q*_RD per mass ratio of run summaries (rows of summary.csv or summary.json: target_mass,
    mass_ratio, speed, largest_mass_ratio; the 1/10 runs' 0.1003 and 0.1 are one ratio), for the
    ratios with enough runs in the linear regime; head-on and oblique runs must not be mixed."""
    groups: dict[float, list[dict]] = {}
    for row in rows:
        try:
            values = [float(row[key]) for key in ("target_mass", "mass_ratio", "speed", "largest_mass_ratio")]
        except (KeyError, TypeError, ValueError):
            raise InputError(
                f"run {row.get('run', '?')}: Q*_RD needs target_mass, mass_ratio, speed and largest_mass_ratio "
                "(a run's summary.json and its sweep's summary.csv hold them)"
            ) from None
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"run {row.get('run', '?')}: Q*_RD needs finite target_mass, mass_ratio, speed and largest_mass_ratio")
        groups.setdefault(float(f"{values[1]:.2g}"), []).append(row)
    angles = {float(row.get("theta_deg") or 0.0) for row in rows}
    if len(angles) > 1:
        raise InputError(f"Q*_RD of one impact angle at a time; these runs have theta_deg {sorted(angles)}")
    found = {}
    for ratio, members in sorted(groups.items()):
        target_mass = float(np.mean([float(r["target_mass"]) for r in members]))
        gamma = float(np.mean([float(r["mass_ratio"]) for r in members]))
        q_r = [specific_impact_energy(float(r["target_mass"]), float(r["mass_ratio"]), float(r["speed"])) for r in members]
        fraction = [remnant_fraction(float(r["largest_mass_ratio"]), float(r["mass_ratio"])) for r in members]
        found[ratio] = disruption_threshold(q_r, fraction, target_mass, gamma, confidence, regime)
    return found


@dataclass(frozen=True)
class LawFit:
    """c* and mu_bar of LS12's law fitted to thresholds of several mass ratios (head-on)."""

    c_star: float
    c_star_low: float
    c_star_high: float
    mu_bar: float
    """nan where every threshold is of one mass ratio (the exponent is then not fitted)."""
    mu_bar_low: float
    mu_bar_high: float
    ratios: int
    confidence: float = CONFIDENCE


def law_constants(found: list[Threshold], G: float = G_CGS, confidence: float = CONFIDENCE) -> LawFit:
    """c* and mu_bar from ``found`` thresholds (head-on, of two or more mass ratios; of equal masses
    alone, c* alone: their factor is 1 whatever mu_bar).

    ln Q*_RD = ln c* + ln(4/5 pi rho1 G R_C1^2) + k ln((gamma + 1)^2 / (4 gamma)), k = 2 / (3 mu_bar) - 1:
    a weighted least-squares line (weights from each threshold's delta-method error, relative:
    var(ln Q) = (std / Q)^2), whose covariance gives c*'s and k's intervals (normal, at
    ``confidence``, widened by Birge's ratio where more than two ratios leave a misfit); mu_bar's
    interval is k's mapped through mu_bar = 2 / (3 (k + 1))."""
    if not found:
        raise InputError("law constants need at least one Q*_RD")
    factors = np.array([math.log(mass_ratio_factor(t.mass_ratio)) for t in found])
    scale = np.array([math.log(equal_mass_threshold(t.target_mass * (1.0 + t.mass_ratio), 1.0, G)) for t in found])
    y = np.array([math.log(t.q_star) for t in found]) - scale
    variance = np.array([(t.std / t.q_star) ** 2 for t in found])
    z = stats.norm.ppf(0.5 + confidence / 2)
    distinct = np.unique(np.round(factors, 9)).size
    if distinct < 2:
        if np.any(np.abs(factors) > 1e-12):
            raise InputError("c* from one mass ratio needs equal masses (its factor is 1 whatever mu_bar); give two ratios or more")
        w = 1.0 / variance
        ln_c = float((w * y).sum() / w.sum())
        half = z / math.sqrt(w.sum())
        return LawFit(math.exp(ln_c), math.exp(ln_c - half), math.exp(ln_c + half), math.nan, math.nan, math.nan, len(found), confidence)
    design = np.stack([np.ones_like(factors), factors], axis=1)
    w = 1.0 / variance
    covariance = np.linalg.inv(design.T @ (design * w[:, None]))
    ln_c, k = covariance @ (design.T @ (w * y))
    # Where more ratios than constants are fitted, scatter beyond the thresholds' own errors (the
    # law's shape not holding exactly) widens the intervals: the covariance times chi^2 / dof
    # (Birge's ratio) when that exceeds 1.
    freedom = len(found) - 2
    if freedom > 0:
        chi2 = float((w * (y - design @ np.array([ln_c, k])) ** 2).sum())
        covariance = covariance * max(1.0, chi2 / freedom)
    ln_c_half, k_half = z * math.sqrt(covariance[0, 0]), z * math.sqrt(covariance[1, 1])
    mu_ends = sorted((_mu_bar(k - k_half), _mu_bar(k + k_half)))
    return LawFit(
        math.exp(ln_c), math.exp(ln_c - ln_c_half), math.exp(ln_c + ln_c_half),
        float(_mu_bar(k)), float(mu_ends[0]), float(mu_ends[1]), len(found), confidence,
    )  # fmt: skip


@dataclass(frozen=True)
class ThresholdRatio:
    """One set of runs' Q*_RD over another's, at one mass ratio, with its interval."""

    mass_ratio: float
    ratio: float
    low: float
    high: float
    dof: float
    """Degrees of freedom of its t quantile (Welch-Satterthwaite's, from each line's runs - 2)."""
    confidence: float = CONFIDENCE


def threshold_ratio(found: Threshold, reference: Threshold, confidence: float = CONFIDENCE) -> ThresholdRatio:
    """``found``'s Q*_RD over ``reference``'s, the two from independent runs: the delta method on
    the ratio's log (each threshold's standard error over its value, added in quadrature), with
    Student's t at Welch-Satterthwaite's degrees of freedom.  Twins (runs of one set-up in both
    sets) correlate, which this interval ignores: for them it is wide."""
    a, b = (found.std / found.q_star) ** 2, (reference.std / reference.q_star) ** 2
    ratio = found.q_star / reference.q_star
    if a + b == 0.0:  # both lines through their runs exactly
        return ThresholdRatio(found.mass_ratio, ratio, ratio, ratio, math.inf, confidence)
    dof = (a + b) ** 2 / (a**2 / (found.runs - 2) + b**2 / (reference.runs - 2))
    half = stats.t.ppf(0.5 + confidence / 2, dof) * math.sqrt(a + b)
    return ThresholdRatio(found.mass_ratio, ratio, ratio * math.exp(-half), ratio * math.exp(half), float(dof), confidence)


def report_ratios(found: dict[float, Threshold], reference: dict[float, Threshold], against: str) -> list[str]:
    """Each mass ratio's Q*_RD over ``reference``'s (the runs of ``against``), as lines for a terminal."""
    level = f"{100 * next(iter(found.values())).confidence:g} %" if found else ""
    lines = [f"over the Q*_RD of {against} ({level} intervals: the delta method on the log, the two sets of runs independent):"]
    for ratio, t in found.items():
        if ratio not in reference:
            lines.append(f"  mass ratio {ratio:g}: not among its thresholds")
            continue
        r = threshold_ratio(t, reference[ratio], t.confidence)
        lines.append(f"  mass ratio {ratio:g}: {r.ratio:.3f} ({r.low:.3f} to {r.high:.3f})")
    return lines


def _mu_bar(k: float) -> float:
    """mu_bar from the exponent k = 2 / (3 mu_bar) - 1 (k <= -1: no finite mu_bar, inf)."""
    return 2.0 / (3.0 * (k + 1.0)) if k > -1 else math.inf


def implied_c_star(found: Threshold, mu_bar: float, G: float = G_CGS) -> float:
    """The c* that LS12's law needs, at exponent ``mu_bar``, to give ``found``'s Q*_RD at its masses."""
    factor = mass_ratio_factor(found.mass_ratio) ** (2.0 / (3.0 * mu_bar) - 1.0)
    return found.q_star / (equal_mass_threshold(found.target_mass * (1.0 + found.mass_ratio), 1.0, G) * factor)


def report(found: dict[float, Threshold], G: float = G_CGS, mu_bar: float = 0.37) -> list[str]:
    """The thresholds and, where they allow, the law's constants, as lines for a terminal."""
    if not found:
        return []
    level = f"{100 * next(iter(found.values())).confidence:g} %"
    lines = [f"Q*_RD [erg/g] where the line through the runs with M_lr/M_tot in {LINEAR_REGIME} crosses 1/2 ({level} intervals, Fieller):"]
    for ratio, t in found.items():
        high = "inf" if math.isinf(t.high) else f"{t.high:.3g}"
        lines.append(
            f"  mass ratio {ratio:g}: {t.q_star:.3g} ({t.low:.3g} to {high}), {t.runs} runs at {t.energies} energies; "
            f"line at Q_R = 0: {t.intercept:.3f} (law: 1), slope {t.law_slope_ratio:.2f} x the law's; c* at mu_bar {mu_bar:g}: "
            f"{implied_c_star(t, mu_bar, G):.2f}"
        )
    try:
        fit = law_constants(list(found.values()), G)
    except InputError as error:
        lines.append(f"LS12's constants: not fitted ({error})")
        return lines
    text = f"LS12's constants from {fit.ratios} mass ratio(s): c* = {fit.c_star:.2f} ({fit.c_star_low:.2f} to {fit.c_star_high:.2f})"
    if not math.isnan(fit.mu_bar):
        text += f", mu_bar = {fit.mu_bar:.3f} ({fit.mu_bar_low:.3f} to {fit.mu_bar_high:.3f})"
    lines.append(text + "; LS12's small bodies: c* = 5 +- 2, mu_bar = 0.37")
    return lines

"""What a quantity tends to as the grains shrink, with its interval, from runs at several resolutions.

A resolution ladder runs the same bodies in N = R x the paper's particles (docs/model.md,
"Resolution"). Two readings of it:

- :func:`resolution_limit`: m(N) = m_inf - c N^(-beta), fitted to every run by weighted least
  squares (each run weighted by the realizations' scatter at its N, so that a noisy coarse rung does
  not pull the limit), m_inf with a t interval on n - 3 degrees of freedom from the fit's
  covariance. On synthetic ladders like the committed one (four rungs, three runs a rung) the 95 %
  interval holds the truth ~91 % of the time: the scatter itself is estimated from few runs.
- :func:`power_law_slope`: y ~ N^slope for a quantity that vanishes with N (the particle-size
  change), a straight line in log y against log N through every run, the slope with its t interval.

    limit = resolution_limit(particles, remnants)       # one eta's runs of the ladder
    limit.value, limit.low, limit.high, limit.beta

Pure NumPy and SciPy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from ..checks import InputError

#: Intervals are at this confidence (two-sided).
CONFIDENCE = 0.95
#: The exponent of the approach is kept inside these bounds: above, the rungs would already be the limit.
BETA_BOUNDS = (1e-3, 5.0)


@dataclass(frozen=True)
class Limit:
    """The extrapolated value of a quantity at infinitely many grains."""

    value: float
    """m_inf."""
    low: float
    """Lower end of its interval (t on runs - 3 degrees of freedom)."""
    high: float
    """Upper end."""
    beta: float
    """The fitted exponent of the approach, m_inf - m(N) ~ N^(-beta)."""
    scale: float
    """c: m_inf - m at one particle (of the fit, not physical)."""
    runs: int
    """Runs fitted."""
    rungs: int
    """Distinct particle counts among them."""
    confidence: float = CONFIDENCE

    def at(self, particles: float) -> float:
        """The fitted m at ``particles``."""
        return self.value - self.scale * particles ** (-self.beta)


def _rungs(particles: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    counts = np.unique(particles)
    if counts.size < 3:
        raise InputError(f"a limit needs runs at three or more particle counts; got {counts.size}")
    return counts, np.array([values[particles == n] for n in counts], dtype=object)


def rung_scatter(particles, values) -> np.ndarray:
    """Each run's weight in the fit: the realizations' standard deviation as a power of N, a line
    in log sd against log N through the rungs that have several runs (the scatter falls with the
    grains; a line steadies sds of three runs each and gives a lone rung its value). One rung with
    several runs gives its sd to all; none gives equal weights."""
    particles, values = np.asarray(particles, dtype=float), np.asarray(values, dtype=float)
    counts, groups = _rungs(particles, values)
    known = [(math.log(n), math.log(float(np.std(g, ddof=1)))) for n, g in zip(counts, groups) if len(g) > 1 and np.std(g) > 0]
    if not known:
        return np.ones_like(values)
    if len(known) == 1:
        return np.full_like(values, math.exp(known[0][1]))
    slope, intercept = np.polyfit(*np.array(known).T, 1)
    return np.exp(intercept + slope * np.log(particles))


def resolution_limit(particles, values, confidence: float = CONFIDENCE) -> Limit:
    """m_inf of m(N) = m_inf - c N^(-beta) through every run (module docstring)."""
    particles, values = np.asarray(particles, dtype=float), np.asarray(values, dtype=float)
    if particles.shape != values.shape or particles.ndim != 1:
        raise InputError("particles and values must be two lists of one length")
    if not np.all(np.isfinite(values)) or np.any(particles <= 0):
        raise InputError("values must be finite and particle counts positive")
    counts, groups = _rungs(particles, values)
    if values.size < 4:
        raise InputError(f"a limit with an interval needs four or more runs; got {values.size}")
    sigma = rung_scatter(particles, values)
    # Start from the last two rungs' means: their step and the one before set beta and c.
    means = np.array([np.mean(g) for g in groups])
    steps = np.diff(means)
    ratio = abs(steps[-1] / steps[-2]) if steps[-2] != 0 else 0.5
    beta0 = float(np.clip(-math.log(max(min(ratio, 0.95), 0.05)) / math.log(counts[-1] / counts[-2]), *BETA_BOUNDS))
    c0 = (means[-1] - means[0]) / (counts[0] ** -beta0 - counts[-1] ** -beta0)
    m0 = means[-1] + c0 * counts[-1] ** -beta0

    def model(n, m_inf, c, beta):
        return m_inf - c * n ** (-beta)

    bounds = ([-np.inf, -np.inf, BETA_BOUNDS[0]], [np.inf, np.inf, BETA_BOUNDS[1]])
    fit, cov = optimize.curve_fit(model, particles, values, p0=[m0, c0, beta0], sigma=sigma, bounds=bounds, maxfev=20000)
    if fit[2] <= BETA_BOUNDS[0] * 1.01 or fit[2] >= BETA_BOUNDS[1] * 0.99:
        raise InputError(f"the rungs approach no limit the fit can find (its exponent ran to {fit[2]:.3g}): more rungs are needed")
    dof = values.size - 3
    half = stats.t.ppf(0.5 + confidence / 2, dof) * math.sqrt(cov[0, 0]) if np.isfinite(cov[0, 0]) else math.inf
    return Limit(value=float(fit[0]), low=float(fit[0] - half), high=float(fit[0] + half), beta=float(fit[2]),
                 scale=float(fit[1]), runs=int(values.size), rungs=int(counts.size), confidence=confidence)  # fmt: skip


@dataclass(frozen=True)
class Slope:
    """The exponent of y ~ N^slope through every run."""

    value: float
    low: float
    high: float
    runs: int
    confidence: float = CONFIDENCE

    @property
    def per_fourfold(self) -> float:
        """The factor y takes with each fourfold N: 4^slope (one half at slope -1/2)."""
        return 4.0**self.value


def power_law_slope(particles, values, confidence: float = CONFIDENCE) -> Slope:
    """Least-squares slope of log y against log N through every run, with its t interval (runs - 2
    degrees of freedom). Every y must be positive: a quantity that changes sign is no power law."""
    particles, values = np.asarray(particles, dtype=float), np.asarray(values, dtype=float)
    if particles.shape != values.shape or particles.ndim != 1:
        raise InputError("particles and values must be two lists of one length")
    if np.any(values <= 0) or not np.all(np.isfinite(values)):
        raise InputError("a power law's values must be positive and finite")
    if np.unique(particles).size < 2 or values.size < 3:
        raise InputError("a slope with an interval needs three or more runs at two or more particle counts")
    fit = stats.linregress(np.log(particles), np.log(values))
    half = stats.t.ppf(0.5 + confidence / 2, values.size - 2) * fit.stderr
    return Slope(value=float(fit.slope), low=float(fit.slope - half), high=float(fit.slope + half), runs=int(values.size), confidence=confidence)

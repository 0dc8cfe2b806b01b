"""Does X change the outcome, and how sure are we?  Groups of runs compared with 95 % intervals.

The rows are run summaries (``summary.json`` of a run folder, or the rows of a sweep's
``summary.csv``) as plain dicts.  :func:`compare` groups them by one column (``by``: spin_kind, say)
and optionally by a second (``at``: eta), and gives, per point and group, the metric's mean and
spread, and for each group its difference to a reference group with a 95 % confidence interval, a
verdict (resolved, or not at the runs there are) and the runs per group that a given difference
needs.  With ``against`` each group's mean is compared with a fixed value instead ("does the
fragment's mean grain grow?": against 0), and ``confidence`` sets the level (0.983 for three
comparisons at a family-wise 95 %, Bonferroni).  :func:`error_bars` gives the same numbers as a
figure's error bars.

    rows = read_rows(["runs/results/fig9", "runs/results/fig3"])
    result = compare(rows, by="spin_kind", metric="largest_mass_ratio", at="eta",
                     where={"mass_ratio": [1], "theta_deg": [0]}, allow_single=True)
    for line in result.lines():
        print(line)

Pure NumPy and SciPy over dicts: no Warp, no HDF5.
"""

from __future__ import annotations

import csv
import functools
import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy import stats

from ..checks import InputError
from ..folder import RunFolder

#: Intervals and verdicts are at this confidence (two-sided).
CONFIDENCE = 0.95
#: The runs-per-group estimate is for this power (and the two-sided 5 % of CONFIDENCE).
POWER = 0.8
#: Groups of at least this many runs each get a bootstrap interval, smaller ones Welch's t.  Below
#: ~30 the bootstrap undercovers: over 1 000 trials of normal groups with a known difference (and
#: unequal spreads), BCa covered it 90 % of the time at 10 runs a group and 93.7 % at 20, against
#: Welch's 95 %; 94.5 % at 40.
BOOTSTRAP_FROM = 30
#: Bootstrap resamples, and the seed they are drawn from (each interval draws afresh from it, so
#: that an interval does not depend on which other groups are in the table).
RESAMPLES = 9999
SEED = 0
#: Numbers are the same point (``at``), group (``by``) or set-up when equal to this many significant
#: digits: eta 3.0000000000000004 and 3.0 are one point.
KEY_DIGITS = 6
#: A ``where`` number picks the values within this relative tolerance: mass_ratio=0.1 picks the
#: 1/10 runs, whose ratio is 0.10031.
WHERE_TOLERANCE = 0.01
#: The columns that define a set-up: rows compared at one point must agree in each of these (where
#: present: summaries older than the physics columns have no restitution, friction, G or law) unless
#: it is the ``by`` or ``at`` column.
SETUP_COLUMNS = ("mass_ratio", "theta_deg", "k_in", "dt", "gravity_every", "eta_potential", "n_particles", "restitution", "mu_k", "mu_r",
                 "G", "rolling_friction", "contact_law", "k_t_ratio", "eps_t", "mu_s", "mu_t", "beta", "cohesion")  # fmt: skip
#: With ``paired``, twins are two runs, one of a group and one of the reference group, that agree in
#: each of these columns other than ``by`` (to KEY_DIGITS digits; a value missing in both agrees): the
#: set-up, the energy, the spins (a kind holds several axis pairs), the realization and its turn of
#: the piles, and the piles.
PAIR_COLUMNS = (*SETUP_COLUMNS, "eta", "spin_kind", "target_spin", "projectile_spin", "target_spin_axis", "projectile_spin_axis",
                "realization", "orientation_seed", "target_pile", "projectile_pile")  # fmt: skip
#: The column each row gets from where it was read, unless it has one: the name of the sweep's folder
#: (a summary.csv's folder, or the folder of the run folders given), so that twins of two campaigns
#: that no set-up column tells apart (one sweep file run by two versions of the code, say) can be
#: compared as groups: ``--by folder --paired``.
FOLDER = "folder"


def pair_columns(by: str, at: str | None) -> list[str]:
    """The columns in which twins agree: PAIR_COLUMNS but ``by`` and ``at``; by FOLDER (one sweep
    file's runs in two folders) the run's name too, which names its set-up in both."""
    return [c for c in PAIR_COLUMNS if c not in (by, at)] + (["run"] if by == FOLDER else [])


#: The group that ``spin_kind`` is compared against by default, where present.
NO_SPIN = "none"
#: Columns that a sweep's summary.csv gives each run beside its summary.json's (a run folder alone
#: does not know its realization number, say).
SWEEP_COLUMNS = ("status", "reason", "realization", "wall_seconds", "stepping_seconds", "device", "device_name", "ensemble")


class CompareError(InputError):
    """A comparison that cannot be made as asked: the message (one line) says what, and what to do."""


class UnknownColumn(CompareError):
    """A column that no row has."""


class MixedSetups(CompareError):
    """Rows of one point that differ in a set-up column (``column``) other than ``by`` and ``at``."""

    def __init__(self, message: str, column: str):
        super().__init__(message)
        self.column = column


class SingleRunGroup(CompareError):
    """Groups of one run (their spread is unknown); ``comparison`` holds the rest, computed."""

    def __init__(self, message: str, comparison: "Comparison"):
        super().__init__(message)
        self.comparison = comparison


class UnpairedRuns(CompareError):
    """With ``paired``: a group with fewer than 2 twins of the reference's runs, or two runs of one
    group that agree in every pairing column (which is whose twin?)."""


# --- reading summaries ----------------------------------------------------------------------------

def read_rows(paths) -> list[dict]:
    """The summary rows under ``paths``: each a run folder (its summary.json), a folder of run
    folders (theirs), or a sweep's summary.csv (its rows; blank cells are None, numbers floats).
    A run read twice (a sweep's folder and its summary.csv, say) is refused: it would count twice.
    Each row without a ``folder`` column gets its sweep folder's name there (FOLDER)."""
    rows, origin = [], {}
    for path in map(Path, paths):
        for identity, where, row in _rows_of(path):
            if identity in origin:
                raise CompareError(f"run {row.get('run', identity)} is read twice ({origin[identity]} and {where}): give each run once")
            origin[identity] = where
            rows.append(row)
    if not rows:
        raise CompareError(f"no summaries in {', '.join(map(str, paths))}")
    names = folder_names({identity.parent for identity in origin})
    for identity, row in zip(origin, rows):
        row.setdefault(FOLDER, names[identity.parent])
    seen = {}
    for row in rows:  # two runs of one set-up under two names: one outcome that would count twice
        signature = tuple(row.get(column) for column in OUTCOME_COLUMNS)
        if sum(value is not None for value in signature) >= 3:
            if signature in seen:
                raise CompareError(
                    f"runs {seen[signature]} and {row.get('run')} have the same outcome to the last digit "
                    f"({', '.join(c for c, v in zip(OUTCOME_COLUMNS, signature) if v is not None)}): one set-up run twice "
                    "under two names; give it once"
                )
            seen[signature] = row.get("run")
    return rows


def folder_names(folders) -> dict[Path, str]:
    """{folder: its name in the ``folder`` column}: its last path component, or as many of its last
    components as tell it from the others (runs/results/resolution/x4 and runs/results/qstar_rd/x4
    are resolution/x4 and qstar_rd/x4), so that two folders are never one group."""
    folders = sorted(set(folders))
    depth = {folder: 1 for folder in folders}
    while True:
        names = {folder: "/".join(folder.parts[-depth[folder]:]) for folder in folders}
        clash = [folder for folder in folders if list(names.values()).count(names[folder]) > 1]
        if not clash:
            return names
        for folder in clash:
            depth[folder] += 1


#: Outcome columns that two distinct runs never share all of, to the last digit (chaotic motion).
OUTCOME_COLUMNS = ("largest_mass_ratio", "particle_size_change", "deepest_overlap", "momentum_drift", "angular_momentum_drift", "ledger_closure")


def _rows_of(path: Path) -> list[tuple[Path, str, dict]]:
    """(identity of the run, where it was read, row) for each run at ``path``."""
    if path.is_file() and path.suffix == ".csv":
        try:
            with path.open(newline="") as f:
                table = list(csv.DictReader(f))
        except (OSError, UnicodeDecodeError, csv.Error) as error:
            raise CompareError(f"{path}: cannot read it as a table ({' '.join(str(error).split())})") from None
        if not table:
            raise CompareError(f"{path} holds no rows")
        rows = [typed_row(row) for row in table]
        return [((path.parent / str(row.get("run", f"line {k + 2}"))).resolve(), f"{path} line {k + 2}", row) for k, row in enumerate(rows)]
    if (path / RunFolder.SUMMARY).is_file():
        summaries = [path / RunFolder.SUMMARY]
    elif path.is_dir():
        summaries = sorted(path.glob(f"*/{RunFolder.SUMMARY}"))
        if not summaries:
            raise CompareError(f"{path} holds no {RunFolder.SUMMARY} and no run folders with one (a sweep's table: give its summary.csv)")
    elif not path.exists():
        raise CompareError(f"{path} does not exist")
    else:
        raise CompareError(f"{path} is neither a run folder, a folder of run folders nor a summary.csv")
    return [(summary.parent.resolve(), str(summary), _read_summary(summary)) for summary in summaries]


def _read_summary(path: Path) -> dict:
    try:
        row = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise CompareError(f"{path}: not a run summary ({' '.join(str(error).split())})") from None
    if not isinstance(row, dict):
        raise CompareError(f"{path}: not a run summary (a JSON object is expected)")
    return row


def parse_cell(text: str | None):
    """A summary.csv cell (or a ``where`` value) as the value summary.json would hold: None for a
    blank, True/False, a float for a number, else the text."""
    if text is None or text.strip() == "":
        return None
    text = text.strip()
    if text in ("True", "False"):
        return text == "True"
    try:
        number = float(text)
    except ValueError:
        return text
    return number if math.isfinite(number) else None


#: The types a row's values may have: those of summary.json's (strict JSON) values.
CELL_TYPES = (int, float, str, bool, type(None))


def typed_row(row) -> dict:
    """A run's row as :func:`compare` takes it: text cells (a ``csv.DictReader`` row's, every one
    text) read as summary.csv's are (:func:`parse_cell`), a list (a spin axis given as a vector) as
    a tuple, so that it can name a group, the rest as they are; a value of another type (a dict, an
    object) is refused, naming the run and the column."""
    if not isinstance(row, dict):
        raise CompareError(f"a row must be a dict of a run's columns (summary.json's, or a csv.DictReader row); got {type(row).__name__}")
    typed = {}
    for key, value in row.items():
        if key is None:  # csv.DictReader's cells past the header
            continue
        if isinstance(value, str):
            value = parse_cell(value)
        elif isinstance(value, np.generic):
            value = value.item()
        elif isinstance(value, (list, tuple, np.ndarray)):
            value = tuple(np.asarray(value).tolist())
        elif not isinstance(value, CELL_TYPES):
            raise CompareError(f"run {row.get('run', '?')}: column {key} holds a {type(value).__name__}; "
                               "a row's values are numbers, text, True/False, None or lists (as summary.json's)")  # fmt: skip
        typed[key] = value
    return typed


def parse_where(texts) -> dict[str, list]:
    """``COLUMN=VALUE[,VALUE...]`` strings as {column: values}; a column named twice takes the
    values of both."""
    where: dict[str, list] = {}
    for text in texts:
        column, equals, values = text.partition("=")
        column = column.strip()
        parsed = [parse_cell(v) for v in values.split(",")]
        if not equals or not column or any(v is None for v in parsed):
            raise CompareError(f"--where takes COLUMN=VALUE[,VALUE...], e.g. mass_ratio=1 or eta=3,6; got {text!r}")
        where.setdefault(column, []).extend(parsed)
    return where


# --- values as keys ------------------------------------------------------------------------------


def value_key(value):
    """The value a row is grouped by: numbers to KEY_DIGITS significant digits, None for a missing
    or non-finite one, anything else as it is."""
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(f"{value:.{KEY_DIGITS}g}") if math.isfinite(value) else None
    return value


def label(key) -> str:
    """A key as printed: 3.0 as 3, text as it is."""
    return f"{key:g}" if isinstance(key, float) else str(key)


def _order(key):
    """Sort key over numbers, text and tuples (vectors) together: numbers first."""
    if isinstance(key, (int, float)) and not isinstance(key, bool):
        return (0, float(key), "")
    return (1, 0.0, key) if isinstance(key, str) else (2, 0.0, str(key))


def _matches(value, wanted) -> bool:
    if isinstance(wanted, (int, float)) and not isinstance(wanted, bool):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        return ok and math.isclose(value, wanted, rel_tol=WHERE_TOLERANCE, abs_tol=1e-12)
    return value == wanted


# --- statistics --------------------------------------------------------------------------------


def runs_needed(spread: float, delta: float, confidence: float = CONFIDENCE, power: float = POWER, samples: int = 2) -> int | None:
    """Runs per group that resolve a difference ``delta`` between two groups of scatter ``spread``
    (the metric's standard deviation, its units as ``delta``'s) at two-sided ``1 - confidence`` and
    ``power``: the two-sample normal approximation n = 2 (z_(1-a/2) + z_power)^2 s^2 / delta^2,
    rounded up, at least 2 (a group of one has no spread).  ``samples = 1``: the runs that resolve
    one group's mean ``delta`` away from a fixed value, n = (z_(1-a/2) + z_power)^2 s^2 / delta^2.
    None: delta 0, never resolved."""
    if delta == 0:
        return None
    z = stats.norm.ppf(0.5 + confidence / 2) + stats.norm.ppf(power)
    return max(2, math.ceil(samples * z**2 * spread**2 / delta**2))


def detectable_difference(error: float, freedom: float | None = None, confidence: float = CONFIDENCE, power: float = POWER,
                          critical: float | None = None) -> float:  # fmt: skip
    """The minimum detectable difference: the smallest true difference that an interval whose
    difference has standard error ``error`` resolves (leaves out 0) with probability ``power``,
    (critical + q_power) x error.  ``critical`` is the interval's own two-sided quantile at
    ``confidence``: Student's t at ``freedom`` degrees of freedom (Welch's, or n - 1 for one mean or
    n pairs), the normal z where ``freedom`` is None (a bootstrap interval), or as given (Dunnett's
    simultaneous one); q_power is the ``power`` quantile of the same t (z).  With the normal
    quantiles it is :func:`runs_needed` inverted: two groups of n runs and mean variance s^2 have
    error s sqrt(2 / n), and (z_(1-a/2) + z_power) s sqrt(2 / n) is the delta for which runs_needed
    gives n.  With few runs the t quantiles are the larger (at n = 3 and 3, 3.7 errors against the
    normal 2.8): the normal figure would name differences below the interval's own half-width, which
    those runs never resolve.  ``error`` comes from the groups' spreads and sizes, never from the
    difference seen: post-hoc power from the observed difference says nothing the interval does not."""
    if freedom is not None and not freedom > 0:
        raise ValueError(f"degrees of freedom must be > 0; got {freedom}")
    quantile = stats.norm if freedom is None else stats.t(freedom)
    if critical is None:
        critical = quantile.ppf(0.5 + confidence / 2)
    return float((critical + quantile.ppf(power)) * error)


def welch_freedom(a: np.ndarray, b: np.ndarray) -> float:
    """The Welch-Satterthwaite degrees of freedom of mean(a) - mean(b) (infinite for two groups
    without any scatter, where the interval is the difference itself)."""
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    if va + vb == 0:
        return math.inf
    return float((va + vb) ** 2 / (va**2 / (a.size - 1) + vb**2 / (b.size - 1)))


def welch_interval(a: np.ndarray, b: np.ndarray, confidence: float = CONFIDENCE) -> tuple[float, float]:
    """Welch's t interval of mean(a) - mean(b) (unequal variances, Welch-Satterthwaite degrees of
    freedom); two groups without any scatter give the difference itself."""
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    difference = a.mean() - b.mean()
    if va + vb == 0:
        return float(difference), float(difference)
    half = stats.t.ppf(0.5 + confidence / 2, welch_freedom(a, b)) * math.sqrt(va + vb)
    return float(difference - half), float(difference + half)


def bootstrap_interval(samples: tuple[np.ndarray, ...], confidence: float = CONFIDENCE, resamples: int = RESAMPLES) -> tuple[float, float]:
    """The BCa bootstrap interval of mean(samples[0]) (one sample) or of mean(samples[0]) -
    mean(samples[1]) (two, resampled each on its own), drawn from SEED; samples without any
    scatter give the statistic itself (BCa is undefined there)."""
    statistic = _mean if len(samples) == 1 else _mean_difference
    value = float(statistic(*samples, axis=-1))
    if all(np.ptp(s) == 0 for s in samples):
        return value, value
    # random_state, not rng: the keyword of every SciPy from the 1.11 that pyproject admits.
    result = stats.bootstrap(samples, statistic, n_resamples=resamples, confidence_level=confidence, vectorized=True,
                             random_state=np.random.default_rng(SEED))  # fmt: skip
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def _mean(a, axis=-1):
    return np.mean(a, axis=axis)


def _mean_difference(a, b, axis=-1):
    return np.mean(a, axis=axis) - np.mean(b, axis=axis)


def t_half_width(values: np.ndarray, confidence: float = CONFIDENCE) -> float:
    """The half-width of Student's t ``confidence`` interval of the mean of ``values`` (>= 2)."""
    return float(stats.t.ppf(0.5 + confidence / 2, values.size - 1) * values.std(ddof=1) / math.sqrt(values.size))


def mean_interval(values: np.ndarray, confidence: float = CONFIDENCE, resamples: int = RESAMPLES) -> tuple[float | None, float | None, str | None]:
    """(low, high, method) of the ``confidence`` interval of the mean of ``values``: Student's t
    below BOOTSTRAP_FROM values, the bootstrap from there; (None, None, None) for one value."""
    if values.size < 2:
        return None, None, None
    if values.size < BOOTSTRAP_FROM:
        half = t_half_width(values, confidence)
        return float(values.mean() - half), float(values.mean() + half), "t"
    return (*bootstrap_interval((values,), confidence, resamples), "bootstrap")


def difference_interval(a: np.ndarray, b: np.ndarray, confidence: float = CONFIDENCE, resamples: int = RESAMPLES) -> tuple[float, float, str]:
    """(low, high, method) of the ``confidence`` interval of mean(a) - mean(b), both of at least 2
    values: Welch's t where either has fewer than BOOTSTRAP_FROM, else the bootstrap."""
    if min(a.size, b.size) < BOOTSTRAP_FROM:
        return (*welch_interval(a, b, confidence), "Welch t")
    return (*bootstrap_interval((a, b), confidence, resamples), "bootstrap")


@functools.lru_cache(maxsize=256)
def dunnett_critical(control: int, sizes: tuple[int, ...], confidence: float = CONFIDENCE) -> float:
    """Dunnett's two-sided critical value for groups of ``sizes`` runs each compared with a control
    of ``control`` runs at ``confidence`` together: the quantile of max |T_i| for the multivariate t
    of sum(sizes) + control - len(sizes) - 1 degrees of freedom and correlations
    1 / sqrt((control / n_i + 1)(control / n_j + 1)), as scipy.stats.dunnett computes it (randomized
    quasi-Monte Carlo drawn from SEED, so the same each time).  It depends on the sizes and the level
    only, not on the values: it is computed once a design, from stand-in samples, and equals
    scipy.stats.dunnett's on the runs themselves with the same seed."""
    stand_ins = [np.arange(n, dtype=float) for n in sizes]
    reference = np.arange(control, dtype=float)
    # random_state, not rng: the keyword of every SciPy from the 1.11 that pyproject admits.
    result = stats.dunnett(*stand_ins, control=reference, random_state=np.random.default_rng(SEED))
    interval = result.confidence_interval(confidence)
    error = pooled_std([*stand_ins, reference]) * math.sqrt(1 / sizes[0] + 1 / control)
    return float((interval.high[0] - interval.low[0]) / 2 / error)


def pooled_std(samples: list[np.ndarray]) -> float:
    """The pooled standard deviation of ``samples`` (one spread for all, as Dunnett's test assumes):
    sqrt(sum (n_i - 1) s_i^2 / (sum n_i - k))."""
    return math.sqrt(sum(float(((s - s.mean()) ** 2).sum()) for s in samples) / (sum(s.size for s in samples) - len(samples)))


def dunnett_intervals(samples: list[np.ndarray], control: np.ndarray, confidence: float = CONFIDENCE) -> list[tuple[float, float, dict]]:
    """Dunnett's many-to-one simultaneous intervals of mean(sample) - mean(control), one per sample
    (each of at least 2 values, two or more samples): together they hold all their true
    differences ``confidence`` of the time.  Each is difference -+ c s sqrt(1 / n_i + 1 / n_0), with
    s the pooled standard deviation of every group and the control (Dunnett assumes one spread) and
    c :func:`dunnett_critical`'s.  With each: {"critical": c, "freedom": sum n - k, "error": s
    sqrt(1 / n_i + 1 / n_0)}."""
    critical = dunnett_critical(control.size, tuple(s.size for s in samples), confidence)
    spread = pooled_std([*samples, control])
    freedom = sum(s.size for s in samples) + control.size - len(samples) - 1
    intervals = []
    for sample in samples:
        error = spread * math.sqrt(1 / sample.size + 1 / control.size)
        difference = float(sample.mean() - control.mean())
        intervals.append((difference - critical * error, difference + critical * error, {"critical": critical, "freedom": freedom, "error": error}))
    return intervals


# --- the comparison ----------------------------------------------------------------------------


@dataclass
class Group:
    """One group at one point: its runs' metric values and their statistics."""

    group: object  #: the ``by`` value (a key: numbers to KEY_DIGITS significant digits)
    n: int  #: runs
    mean: float  #: mean of the metric [the metric's units]
    std: float | None  #: standard deviation (ddof 1) [the metric's units]; None for one run
    low: float | None  #: the mean's interval (95 % unless asked otherwise) [the metric's units]
    high: float | None
    method: str | None  #: "t" or "bootstrap"
    runs: list  #: the runs' names, as their summaries give them
    values: list  #: the metric per run, in the order of ``runs``


@dataclass
class Difference:
    """A group's mean minus the reference group's (or the ``against`` value) at one point, and what
    it takes to resolve it."""

    group: object
    reference: object  #: the reference group, or the value compared against
    difference: float  #: [the metric's units]
    low: float | None  #: its interval (95 % unless asked otherwise); None where a group has one run
    high: float | None
    method: str | None  #: "Welch t" or "bootstrap" (two groups); "t" or "bootstrap" (against a value)
    delta: float  #: the difference the runs estimate is for (``resolve``, else |difference|)
    runs_needed: int | None  #: per group, for ``delta`` at the two groups' mean variance; None: never
    resolved: bool
    verdict: str
    #: the minimum detectable difference of the runs at hand [the metric's units]: the smallest one
    #: they resolve at ``confidence`` with power POWER (:func:`detectable_difference`); None where a
    #: group has one run
    detectable: float | None = None
    #: the comparisons whose intervals hold together at ``confidence`` (Dunnett's, method "Dunnett"),
    #: this one among them; 1: an interval of its own
    family: int = 1
    pairs: int | None = None  #: with ``paired``: the twins whose differences are averaged; else None
    correlation: float | None = None  #: with ``paired``: Pearson's r of the twins' values (None: a side without spread)


@dataclass
class Point:
    """The groups at one value of the ``at`` column (None without one)."""

    at: object
    groups: list[Group]
    differences: list[Difference]


@dataclass
class Comparison:
    """The result of :func:`compare`: :meth:`lines` prints it, :meth:`as_dict` is its JSON."""

    metric: str
    by: str
    at: str | None
    reference: object
    resolve: float | None
    points: list[Point]
    read: int  #: rows read
    failed: int  #: rows of failed runs, left out
    where: dict  #: the ``where`` asked, {column: values}
    met: dict  #: the values of each ``where`` column that rows matched
    missing: dict = field(default_factory=dict)  #: {column: rows left out without a value there}
    resamples: int = RESAMPLES  #: of each bootstrap interval
    against: float | None = None  #: each group's mean compared with this value (``reference`` is it)
    confidence: float = CONFIDENCE  #: of every interval and verdict (two-sided)
    per_comparison: bool = False  #: each difference its own interval, never Dunnett's simultaneous ones
    paired: bool = False  #: each difference the mean of its twins' differences (PAIR_COLUMNS)
    unpaired: list = field(default_factory=list)  #: with ``paired``: the runs left out without a twin, "RUN (BY VALUE)"
    #: with ``paired``: the pairing columns that one side's runs record and the other's do not (older
    #: summaries lack some), so that twins were not matched on them
    unrecorded: list = field(default_factory=list)
    #: by folder: the set-up columns in which each folder's runs hold one value and the folders differ
    #: (the law, the restitution: what the campaigns compare); with ``paired``, twins were paired
    #: across them
    varied: list = field(default_factory=list)
    #: with ``paired``, by folder: each group's own columns of ``varied`` (its label: the columns it
    #: was paired across with the reference), where the groups' differ
    paired_across: dict = field(default_factory=dict)

    @property
    def pair_columns(self) -> list[str]:
        """The columns in which twins agree (``paired``): PAIR_COLUMNS but ``by`` and ``at`` (a point's
        runs share its value), and but those one side does not record (``unrecorded``) or that tell
        the folders apart (``varied``)."""
        return [c for c in pair_columns(self.by, self.at) if c not in self.unrecorded and c not in self.varied]

    def _across(self) -> str:
        """What twins were paired across: ``varied``, or group by group where the groups' differ."""
        columns = {tuple(c) for c in self.paired_across.values()}
        if len(columns) <= 1:
            return ", ".join(self.varied)
        return "; ".join(f"{group}: {', '.join(c) or 'nothing'}" for group, c in self.paired_across.items())

    def as_dict(self) -> dict:
        """Plain data (numbers as floats, None where none exists), for JSON."""
        return {"power": POWER, "bootstrap_from": BOOTSTRAP_FROM, "seed": SEED, **asdict(self),
                "pair_columns": self.pair_columns if self.paired else None}  # fmt: skip

    def single(self) -> list[tuple[object, object]]:
        """(point, group) of every group of one run."""
        return [(p.at, g.group) for p in self.points for g in p.groups if g.n < 2]

    def lines(self) -> list[str]:
        """The comparison as text: a header, then a table per point."""
        where = " ".join(f"{_where_text({c: v})} (met: {', '.join(map(label, self.met[c])) or 'none'})" for c, v in self.where.items())
        kept = sum(g.n for p in self.points for g in p.groups)
        left = [f"{self.failed} failed"] if self.failed else []
        left += [f"{n} without {column}" for column, n in self.missing.items()]
        level = f"{100 * self.confidence:.4g} %"
        methods = {d.method for p in self.points for d in p.differences}
        if self.against is None:
            intervals = f"difference to {label(self.reference)}: "
            if self.paired:
                intervals += (f"the mean of the twins' differences (twins: a run and a run of {self.by} {label(self.reference)} that agree in each of "
                              f"{', '.join(self.pair_columns)}), {level} interval by Student's t on them (pairs - 1 dof)"
                              + (" of each group on its own (--per-comparison)" if self.per_comparison else "") + " where fewer than ")  # fmt: skip
            elif "Dunnett" in methods:
                several = "" if methods <= {"Dunnett", None} else f" where several groups meet {label(self.reference)} at a point"
                intervals += (f"{level} simultaneous intervals by Dunnett's test{several} (the groups of a point together, one pooled "
                              "spread; --per-comparison gives each its own)")  # fmt: skip
                intervals += "" if not several else ", else by Welch's t where a group has fewer than "
            elif self.per_comparison:
                intervals += f"{level} interval of each comparison on its own (--per-comparison) by Welch's t where a group has fewer than "
            else:
                intervals += f"{level} interval by Welch's t where a group has fewer than "
        else:
            intervals = f"each mean minus {self.against:g}: {level} interval by Student's t where a group has fewer than "
        sided = f"two-sided {100 * (1 - self.confidence):.3g} %, power {POWER:g}"
        text = [
            f"{self.metric} by {self.by}" + (f" at {self.at}" if self.at else "")
            + (f"; reference: {label(self.reference)}" if self.against is None else f"; against: {self.against:g}"),
            f"runs: {self.read} read" + (f", {', '.join(left)} left out" if left else "") + (f", {kept} kept by --where {where}" if where else f", {kept} kept"),
            intervals + ("" if intervals.endswith(")") else f"{BOOTSTRAP_FROM} {'pairs' if self.paired else 'runs'}, else by bootstrap "
                         f"(BCa, {self.resamples} resamples, seed {SEED})"),
            f"detectable: the smallest true difference that the runs at hand resolve ({sided}): the interval's quantile plus the power's "
            "(t, or z for a bootstrap) times the difference's standard error, from the spreads, never from the difference seen; "
            + ("pairs to resolve" if self.paired else "runs to resolve") + ": per group, for "
            + (f"a difference of {self.resolve:g}" if self.resolve is not None else "the difference seen") + f" ({sided})",
        ]
        if self.varied and not self.paired:
            text.insert(3, f"the folders differ in {', '.join(self.varied)} (one value in each folder: what they compare)")
        if self.paired:
            twins = sum(d.pairs or 0 for p in self.points for d in p.differences)
            text.insert(3, f"pairs: {twins} twins; " + (f"{len(self.unpaired)} run(s) without a twin left out: {', '.join(self.unpaired)}"
                                                        if self.unpaired else "every run has its twin")
                        + (f"; not matched on {', '.join(self.unrecorded)} (recorded by one side's runs only)" if self.unrecorded else "")
                        + (f"; paired across {self._across()} (one value in each folder, another in the reference: what the folders "
                           "compare)" if self.varied else ""))  # fmt: skip
        pairing = ["pairs", "r"] if self.paired else []
        resolve = "pairs to resolve" if self.paired else "runs to resolve"
        columns = [self.by, "n", "mean", "std", "diff", f"{level} interval", "method", *pairing, "detectable", resolve, "verdict"]
        left_aligned = {self.by, f"{level} interval", "method", "verdict"}
        for point in self.points:
            rows = [dict(zip(columns, columns))]
            differences = {d.group: d for d in point.differences}
            for g in point.groups:
                d = differences.get(g.group)
                row = dict.fromkeys(columns, "")
                row.update({self.by: label(g.group), "n": str(g.n), "mean": _digits(g.mean, 4), "std": _digits(g.std, 2)})
                if d is None:
                    row["verdict"] = "reference" if g.group == self.reference else ""
                else:
                    interval = f"[{_digits(d.low, 3, '+')}, {_digits(d.high, 3, '+')}]" if d.low is not None else "-"
                    needed = "-" if d.low is None else "never" if d.runs_needed is None else str(d.runs_needed)  # "-": a spread unknown
                    row.update({"diff": _digits(d.difference, 3, "+"), f"{level} interval": interval, "method": d.method or "-",
                                "detectable": _digits(d.detectable, 2), resolve: needed, "verdict": d.verdict})  # fmt: skip
                    if self.paired:
                        row.update({"pairs": str(d.pairs), "r": f"{d.correlation:.2f}" if d.correlation is not None else "-"})
                rows.append(row)
            if self.against is None and self.reference not in {g.group for g in point.groups}:
                rows.append({**dict.fromkeys(columns, ""), f"{level} interval": f"no {label(self.reference)} here: nothing to compare with"})
            widths = {c: max(len(r[c]) for r in rows) for c in columns}
            text.append(f"{self.at} {label(point.at)}:" if self.at else "all runs:")
            text += ["  " + "  ".join(r[c].ljust(widths[c]) if c in left_aligned else r[c].rjust(widths[c]) for c in columns).rstrip() for r in rows]
        return text


def _where_text(where: dict) -> str:
    """``where`` as the options that give it: mass_ratio=1 eta=3,6."""
    return " ".join(f"{column}=" + ",".join(map(label, values)) for column, values in where.items())


def _digits(value: float | None, digits: int, sign: str = "") -> str:
    """``value`` to ``digits`` significant digits, trailing zeros kept (1.390, 0.020); "-" for None."""
    return "-" if value is None else format(value, f"{sign}#.{digits}g").rstrip(".")


def select(rows: list[dict], where: dict) -> tuple[list[dict], dict]:
    """The rows whose every ``where`` column matches one of its values (numbers within
    WHERE_TOLERANCE, anything else exactly), and the values met per column."""
    kept = [row for row in rows if all(any(_matches(row.get(c), v) for v in values) for c, values in where.items())]
    met = {c: sorted({value_key(row.get(c)) for row in kept}, key=_order) for c in where}
    return kept, met


def _check_columns(rows: list[dict], columns: dict[str, str]) -> None:
    """Refuse a column (of the options ``columns``: {option: column}) that no row has."""
    known = set().union(*(row.keys() for row in rows))
    for option, column in columns.items():
        if column not in known:
            sheet = f" ({column} is a column of a sweep's summary.csv: give that file instead of its run folders)" if column in SWEEP_COLUMNS else ""
            raise UnknownColumn(f"{option} {column}: no such column{sheet}; the runs have: {', '.join(sorted(known))}")


def folder_columns(rows: list[dict], by: str, at: str | None) -> list[str]:
    """By folder, the set-up columns (not ``at``) that the rows differ in while each folder's runs
    hold one value (a missing one aside): what the folders compare (a campaign rerun under another
    law or restitution), not a mix of set-ups; none by any other column."""
    if by != FOLDER:
        return []
    held: dict = {}
    for row in rows:
        for column in SETUP_COLUMNS:
            held.setdefault(column, {}).setdefault(row.get(FOLDER), set()).add(value_key(row.get(column)))
    columns = []
    for column, folders in held.items():
        values = [v - {None} for v in folders.values()]
        if column != at and len(set().union(*values)) > 1 and all(len(v) <= 1 for v in values):
            columns.append(column)
    return columns


def _check_setups(point, rows: list[dict], by: str, at: str | None, compared=()) -> None:
    """Refuse rows at one point that differ in a set-up column other than ``by`` and ``at``, and
    other than ``compared``, what the folders compare (:func:`folder_columns` of the rows)."""
    for column in SETUP_COLUMNS:
        if column in (by, at) or column in compared:
            continue
        seen = sorted({value_key(row.get(column)) for row in rows} - {None}, key=_order)
        if len(seen) > 1:
            where = f" at {at} {label(point)}" if at else ""
            raise MixedSetups(
                f"the runs{where} differ in {column} ({', '.join(map(label, seen))}), not only in {by}: pick one with "
                f"--where {column}=VALUE, or pass --allow-mixed to compare them anyway", column
            )


def compare(rows: list[dict], by: str, metric: str, at: str | None = None, reference=None, resolve: float | None = None,
            where: dict | None = None, allow_mixed: bool = False, allow_single: bool = False,
            resamples: int = RESAMPLES, against: float | None = None, confidence: float = CONFIDENCE,
            per_comparison: bool = False, paired: bool = False) -> Comparison:  # fmt: skip
    """Group ``rows`` (run summaries) by ``by`` and ``at``, and compare each group's ``metric`` with
    the ``reference`` group's at each point (default: "none" for spin_kind where present, else the
    first group in sorted order), or, with ``against``, each group's mean with that value (a
    reference group and ``against`` exclude each other).  Intervals and verdicts are at
    ``confidence`` (two-sided, 0.5 to 0.9999).  Where two or more groups (of 2 runs or more) meet
    the reference at a point, their intervals are Dunnett's many-to-one simultaneous ones (together
    they hold every true difference there ``confidence`` of the time; one pooled spread; at any
    group size, the bootstrap serving a lone comparison); ``per_comparison`` gives each its own
    instead (Welch's t or the bootstrap; 1 - 0.05 / m for m of them at a family-wise 95 %,
    Bonferroni).  ``paired``: each group's runs are paired with their twins in the reference group
    (the runs that agree in every PAIR_COLUMNS column but ``by``: the same set-up, realization and
    piles) and the difference is the mean of the twins' differences, with Student's t interval on
    them (pairs - 1 dof; the bootstrap from 30 pairs); runs without a twin are left out and named
    (``unpaired``).  It takes one group against the reference per point, or ``per_comparison``.

    Rows of failed runs (status "failed") are left out, and so are rows without a value of ``by``,
    ``at`` or ``metric`` (counted in ``missing``).  ``where``: {column: values}, keep only the rows
    that match (:func:`select`).  ``resolve``: the difference [the metric's units] the runs-needed
    estimate is for (default: each difference seen).

    Raises UnknownColumn, MixedSetups (unless ``allow_mixed``), SingleRunGroup (a group of one run
    somewhere, unless ``allow_single``; the exception carries the comparison of the rest),
    UnpairedRuns (``paired``: a group with fewer than 2 twins, or twins that are not one to one), and
    CompareError for a metric that is not numeric, no rows left, or an unknown reference."""
    where = where or {}
    if not rows:
        raise CompareError("no runs to compare")
    rows = [typed_row(row) for row in rows]
    options = {"--by": by, "--metric": metric, **({"--at": at} if at else {}), **{"--where": c for c in where}}
    _check_columns(rows, options)
    if resolve is not None and not (math.isfinite(resolve) and resolve > 0):
        raise CompareError(f"--resolve must be a difference > 0; got {resolve:g}")
    if not (math.isfinite(confidence) and 0.5 <= confidence <= 0.9999):
        raise CompareError(f"--confidence must be a level from 0.5 to 0.9999 (0.95: 95 %); got {confidence:g}")
    if against is not None and not math.isfinite(against):
        raise CompareError(f"--against must be a finite value; got {against:g}")
    if against is not None and reference is not None:
        raise CompareError("--reference and --against: compare with a group or with a value, not both")
    if against is not None and paired:
        raise CompareError("--paired and --against: pairs are a group's runs and their twins in the reference group; "
                           "against a value there is nothing to pair")  # fmt: skip
    if against is not None and per_comparison:
        raise CompareError("--per-comparison and --against: each mean against a value has its own interval already; "
                           "--per-comparison is for several groups against a reference group (Dunnett's otherwise)")  # fmt: skip
    done = [row for row in rows if row.get("status") != "failed"]
    kept, met = select(done, where)
    if not kept:
        raise CompareError(f"no run matches --where {_where_text(where)}")
    missing = {}
    for column in dict.fromkeys(c for c in (by, at, metric) if c):
        present = [row for row in kept if value_key(row.get(column)) is not None]
        if len(present) < len(kept):
            missing[column] = len(kept) - len(present)
        kept = present
    if not kept:
        raise CompareError(f"no run has values of {by}, {metric}" + (f" and {at}" if at else "") + " together")
    for row in kept:
        value = row[metric]
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            raise CompareError(f"--metric {metric} is not numeric (run {row.get('run', '?')}: {value!r}); pick a column of numbers")

    points: dict = {}
    for row in kept:
        points.setdefault(value_key(row[at]) if at else None, {}).setdefault(value_key(row[by]), []).append(row)
    groups = sorted({g for point in points.values() for g in point}, key=_order)
    if against is not None:
        reference = against
    elif reference is None:
        reference = NO_SPIN if by == "spin_kind" and NO_SPIN in groups else groups[0]
    else:
        reference = value_key(parse_cell(str(reference)))
        if reference not in groups:
            raise CompareError(f"--reference {label(reference)}: no such {by} among the runs; they have: {', '.join(map(label, groups))}")

    result, unpaired, unrecorded, varied, across_of = [], [], [], [], {}
    for at_key in sorted(points, key=lambda k: _order(k) if k is not None else (0, 0.0, "")):
        point = points[at_key]
        everyone = [row for members in point.values() for row in members]
        compared = folder_columns(everyone, by, at) if against is None else []  # against a value, a group is one folder
        varied += compared
        if not allow_mixed:  # the rows compared with each other: all at the point, or each group's against a value
            for members in (everyone,) if against is None else point.values():
                _check_setups(at_key, members, by, at, compared)
        if against is None:
            order = sorted(point, key=lambda g: (g != reference, _order(g)))  # the reference first
            stats_of = {g: _group(g, point[g], metric, resamples, confidence) for g in order}
            if not paired:
                differences = _differences(stats_of, reference, resolve, resamples, confidence, per_comparison) if reference in point else []
            else:
                differences = _paired_differences(point, at_key, by, at, metric, reference, resolve, resamples, confidence, per_comparison,
                                                  unpaired, unrecorded, across_of)  # fmt: skip
        else:
            order = sorted(point, key=_order)
            stats_of = {g: _group(g, point[g], metric, resamples, confidence) for g in order}
            differences = [_against(stats_of[g], against, resolve, confidence) for g in order]
        result.append(Point(at_key, [stats_of[g] for g in order], differences))
    comparison = Comparison(metric, by, at, reference, resolve, result, len(rows), len(rows) - len(done), where, met, missing, resamples,
                            against, confidence, per_comparison, paired, list(dict.fromkeys(unpaired)), list(dict.fromkeys(unrecorded)),
                            list(dict.fromkeys(varied)), {label(g): list(dict.fromkeys(c)) for g, c in sorted(across_of.items(), key=lambda i: _order(i[0]))})  # fmt: skip
    single = comparison.single()
    if single and not allow_single:
        named = "; ".join(f"{label(g)}" + (f" at {at} {label(p)}" if at else "") for p, g in single)
        raise SingleRunGroup(f"{len(single)} group(s) of one run, whose spread is unknown: {named}; add runs, narrow "
                             "with --where, or pass --allow-single to compare the rest", comparison)  # fmt: skip
    return comparison


def _group(key, rows: list[dict], metric: str, resamples: int, confidence: float = CONFIDENCE) -> Group:
    values = np.array([float(row[metric]) for row in rows])
    low, high, method = mean_interval(values, confidence, resamples)
    std = float(values.std(ddof=1)) if values.size > 1 else None
    return Group(key, int(values.size), float(values.mean()), std, low, high, method, [row.get("run") for row in rows], values.tolist())


def _differences(stats_of: dict, reference, resolve: float | None, resamples: int, confidence: float, per_comparison: bool) -> list[Difference]:
    """Each group's difference to the reference group at one point: Dunnett's simultaneous
    intervals where two or more groups of at least 2 runs meet a reference of at least 2 (unless
    ``per_comparison``), else each its own (Welch's t or the bootstrap)."""
    others = [g for g in stats_of if g != reference]
    family = [g for g in others if stats_of[g].n >= 2] if stats_of[reference].n >= 2 and not per_comparison else []
    together = {}
    if len(family) >= 2:
        intervals = dunnett_intervals([np.array(stats_of[g].values) for g in family], np.array(stats_of[reference].values), confidence)
        together = dict(zip(family, intervals))
    return [_difference(stats_of[g], stats_of[reference], resolve, resamples, confidence, together.get(g), len(together) or 1) for g in others]


def pair_runs(rows: list[dict], reference_rows: list[dict], columns) -> tuple[list[tuple[dict, dict]], list[dict]]:
    """(twins, the rest): each run of ``rows`` with the run of ``reference_rows`` that agrees with it
    in every one of ``columns`` (values as keys: to KEY_DIGITS digits, a missing value agreeing
    with a missing one), in the order of ``rows``; the rest are the runs of either side without a
    twin.  Two runs of one side that agree in every column are refused (UnpairedRuns): whose twin
    would the other side's be?"""
    columns = list(columns)

    def keyed(side: list[dict]) -> dict:
        keys: dict = {}
        for row in side:
            key = tuple(value_key(row.get(c)) for c in columns)
            if key in keys:
                raise UnpairedRuns(f"runs {keys[key].get('run', '?')} and {row.get('run', '?')} agree in every pairing column "
                                   f"({', '.join(columns)}): which is whose twin? Narrow with --where, or give a sweep's summary.csv "
                                   "(its realization column tells realizations apart)")  # fmt: skip
            keys[key] = row
        return keys

    mine, theirs = keyed(rows), keyed(reference_rows)
    twins = [(row, theirs[key]) for key, row in mine.items() if key in theirs]
    rest = [row for key, row in mine.items() if key not in theirs] + [row for key, row in theirs.items() if key not in mine]
    return twins, rest


def _paired_differences(point: dict, at_key, by: str, at: str | None, metric: str, reference, resolve: float | None, resamples: int,
                        confidence: float, per_comparison: bool, unpaired: list, unrecorded: list,
                        across_of: dict) -> list[Difference]:  # fmt: skip
    """Each group's paired difference to the reference at one point (``unpaired`` gets the runs
    left without a twin, "RUN (BY VALUE)"; ``unrecorded`` the pairing columns that one side records
    and the other does not, which twins are not matched on: as the set-up check, a value missing is
    no disagreement; ``across_of``, by folder, each group's columns that hold one value in each side
    and different ones: a campaign rerun under another law or restitution pairs with the first
    across them; together they are the point's :func:`folder_columns`, which compare keeps)."""
    if reference not in point:
        return []
    others = sorted((g for g in point if g != reference), key=_order)
    where = f" at {at} {label(at_key)}" if at else ""
    if len(others) > 1 and not per_comparison:
        raise CompareError(f"--paired{where}: {len(others)} groups meet {label(reference)} ({', '.join(map(label, others))}); Dunnett's "
                           "simultaneous intervals are for independent groups, not pairs: pass --per-comparison for each group's paired "
                           f"interval on its own (--confidence {1 - 0.05 / len(others):.4g} keeps the {len(others)} at 95 % together, Bonferroni)")  # fmt: skip
    every = pair_columns(by, at)
    differences = []
    for g in others:  # each group against the reference: what the two sides both record
        recorded = [{c for c in every if any(value_key(row.get(c)) is not None for row in side)} for side in (point[g], point[reference])]
        unrecorded += [c for c in every if c in recorded[0] ^ recorded[1]]
        columns = [c for c in every if c not in recorded[0] ^ recorded[1]]
        across = folder_columns(point[g] + point[reference], by, at)  # what the two folders compare: paired across
        across_of.setdefault(g, []).extend(across)
        columns = [c for c in columns if c not in across]
        twins, rest = pair_runs(point[g], point[reference], columns)
        named = [f"{row.get('run', '?')} ({by} {label(value_key(row[by]))})" for row in rest]
        if len(twins) < 2:
            named = named[:6] + ([f"and {len(named) - 6} more"] if len(named) > 6 else [])
            apart = [c for c in columns if {value_key(r.get(c)) for r in point[g]}.isdisjoint({value_key(r.get(c)) for r in point[reference]})]
            raise UnpairedRuns(f"--paired: {by} {label(g)}{where} has {len(twins)} twin(s) among the {by} {label(reference)} runs "
                               f"(twins agree in each of {', '.join(columns)})"
                               + (f"; the two groups share no value of {', '.join(apart)}" if apart else "")
                               + (f"; without a twin: {', '.join(named)}" if named else "")
                               + "; a paired difference needs 2 pairs or more: compare without --paired")  # fmt: skip
        unpaired += named
        differences.append(_paired(g, reference, twins, metric, resolve, resamples, confidence))
    return differences


def _paired(group, reference, twins: list[tuple[dict, dict]], metric: str, resolve: float | None, resamples: int,
            confidence: float) -> Difference:  # fmt: skip
    """The mean of the twins' differences, its interval (Student's t at pairs - 1 dof, or the
    bootstrap from BOOTSTRAP_FROM pairs), the pairs that ``resolve`` needs and the detectable
    difference (one sample of differences), and the twins' correlation."""
    a = np.array([float(row[metric]) for row, _ in twins])
    b = np.array([float(row[metric]) for _, row in twins])
    differences = a - b
    difference = float(differences.mean())
    delta = resolve if resolve is not None else abs(difference)
    low, high, method = mean_interval(differences, confidence, resamples)
    spread = float(differences.std(ddof=1))
    detectable = detectable_difference(spread / math.sqrt(differences.size), differences.size - 1 if method == "t" else None, confidence)
    correlation = float(np.corrcoef(a, b)[0, 1]) if np.ptp(a) > 0 and np.ptp(b) > 0 else None
    return Difference(group, reference, difference, low, high, f"paired {method}", delta, runs_needed(spread, delta, confidence, samples=1),
                      *_verdict(low, high, f"n = {differences.size} pairs"), detectable=detectable, pairs=int(differences.size),
                      correlation=correlation)  # fmt: skip


def _difference(group: Group, reference: Group, resolve: float | None, resamples: int, confidence: float = CONFIDENCE,
                simultaneous: tuple | None = None, family: int = 1) -> Difference:  # fmt: skip
    difference = group.mean - reference.mean
    delta = resolve if resolve is not None else abs(difference)
    if group.n < 2 or reference.n < 2:
        one = group.group if group.n < 2 else reference.group
        return Difference(group.group, reference.group, difference, None, None, None, delta, None, False, f"spread unknown: 1 run of {label(one)}")
    needed = runs_needed(math.sqrt((group.std**2 + reference.std**2) / 2), delta, confidence)
    if simultaneous is not None:
        low, high, design = simultaneous
        method = "Dunnett"
        detectable = detectable_difference(design["error"], design["freedom"], confidence, critical=design["critical"])
    else:
        a, b = np.array(group.values), np.array(reference.values)
        low, high, method = difference_interval(a, b, confidence, resamples)
        freedom = welch_freedom(a, b) if method == "Welch t" else None
        detectable = detectable_difference(math.sqrt(group.std**2 / group.n + reference.std**2 / reference.n), freedom, confidence)
    return Difference(group.group, reference.group, difference, low, high, method, delta, needed,
                      *_verdict(low, high, f"n = {group.n} and {reference.n}"), detectable=detectable, family=family)  # fmt: skip


def _against(group: Group, value: float, resolve: float | None, confidence: float) -> Difference:
    """A group's mean minus a fixed ``value``: the mean's own interval, shifted."""
    difference = group.mean - value
    delta = resolve if resolve is not None else abs(difference)
    if group.n < 2:
        return Difference(group.group, value, difference, None, None, None, delta, None, False, f"spread unknown: 1 run of {label(group.group)}")
    needed = runs_needed(group.std, delta, confidence, samples=1)
    low, high = group.low - value, group.high - value
    detectable = detectable_difference(group.std / math.sqrt(group.n), group.n - 1 if group.method == "t" else None, confidence)
    return Difference(group.group, value, difference, low, high, group.method, delta, needed, *_verdict(low, high, f"n = {group.n}"), detectable=detectable)


def _verdict(low: float, high: float, runs: str) -> tuple[bool, str]:
    """(resolved, verdict) of an interval: resolved where it leaves out 0, else not at ``runs``."""
    resolved = low > 0 or high < 0
    return resolved, "resolved" if resolved else f"not resolved at {runs}"


def error_bars(rows: list[dict], by: str, metric: str, at: str | None = None, where: dict | None = None,
               allow_mixed: bool = False) -> dict:  # fmt: skip
    """A figure's error bars: per ``by`` group, arrays over the points of ``at`` (sorted): ``at``,
    ``mean``, ``minus`` and ``plus`` (the 95 % interval of the mean below and above it, the
    metric's units; NaN for a group of one run), ``n`` and ``method`` ("t" or "bootstrap", None for
    one run), as :func:`compare` computes them.  ``ax.errorbar(b["at"], b["mean"],
    yerr=[b["minus"], b["plus"]])`` draws them."""
    comparison = compare(rows, by, metric, at, where=where, allow_mixed=allow_mixed, allow_single=True, per_comparison=True)
    bars: dict = {}
    for point in comparison.points:
        for g in point.groups:
            bar = bars.setdefault(g.group, {"at": [], "mean": [], "minus": [], "plus": [], "n": [], "method": []})
            bar["at"].append(point.at)
            bar["mean"].append(g.mean)
            bar["minus"].append(g.mean - g.low if g.low is not None else math.nan)
            bar["plus"].append(g.high - g.mean if g.high is not None else math.nan)
            bar["n"].append(g.n)
            bar["method"].append(g.method)
    return {group: {k: (v if k == "method" else np.array(v)) for k, v in bar.items()} for group, bar in bars.items()}

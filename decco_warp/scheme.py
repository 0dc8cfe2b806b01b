"""How a run is computed, apart from what it computes: the numerical scheme.

:class:`~decco_warp.params.Params` says what the model is (the contact constants, G, dt); a
:class:`Scheme` says how the engine evaluates it: the precision of the all-pairs sweep, the gravity
solver (every pair, or a tree with its opening angle), the clock (gravity every K steps), the force
kernels' layout, and whether the plain reference kernel steps it.  :func:`choose_scheme` reads the
thresholds that choose by size and device (the tree from N, the Newton layout's reach) in one place.
A scheme names its gravity solver among those registered (decco_warp/gravity_solvers.py); the force
paths that compute its forces say which schemes they serve (decco_warp/forces.py ``force_path``).
Plain data: no launches.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, replace

from .errors import InputError
from .gravity_solvers import GRAVITY_SOLVERS
from .kernels.bodies import PRECISIONS
from .layouts import Layout, choose_layout, newton_layout
from .params import Params, Range, require_number

#: The force kernels a scheme may step with: "tiled" (the layouts of the GPU and CPU) or the plain
#: one-thread-per-particle "reference" kernel (the tests' yardstick, the bench's baseline).
FORCE_KERNELS = ("tiled", "reference")

# Gravity solvers (GRAVITY_SOLVERS, by name, as gravity_solvers.py registers them): "all-pairs" sums
# every pair (exact, O(N^2)); "tree" walks a radix tree with monopole + quadrupole nodes (O(N log N),
# error set by theta_open; contacts from a hash grid).
#: What a specification or the CLI may ask for: a solver, or "auto" (:func:`choose_gravity`).
GRAVITY_CHOICES = (*GRAVITY_SOLVERS, "auto")

#: From this many particles ``gravity = "auto"`` takes the tree, per device kind. CPU: measured
#: (docs/benchmarks.md: on copies of a settled pile the tree's step is the faster from ~1 150
#: particles, since its hash grid notes only touching neighbours). CUDA: measured on an H100 on
#: real piles (the innermost 32 768, 49 152 and 65 536 particles of a settled 80 000-particle pile):
#: a step takes 1.15, 2.42 and 4.19 ms with all-pairs in the Newton layout, 1.72, 2.20 and 2.74 ms
#: with the tree, so the two meet near 45 000 (docs/benchmarks.md, "The tree path").
TREE_FROM = {"cpu": 1200, "cuda": 45_000}


def choose_gravity(n: int, device: str) -> str:
    """The gravity solver ``gravity = "auto"`` takes for ``n`` particles on ``device`` ("cpu", "cuda:0")."""
    return "tree" if n >= TREE_FROM["cuda" if device.startswith("cuda") else "cpu"] else "all-pairs"


#: The interval of gravity that ``gravity_every = "auto"`` stands for [s]: K is the whole number of
#: steps of dt nearest it (:func:`auto_gravity_every`), so that what is held where the evidence is,
#: as dt changes, is the interval, not the step count.  The evidence (docs/benchmarks.md,
#: "Equivalence before speed"; docs/validation.md, "Convergence with resolution"): at the paper's dt
#: of 0.04 s every K from 5 to 50 (0.2 to 2 s) lands inside the spread of K = 1's realizations or
#: within 0.015 of it on the Fig. 8 collision and the equal-mass head-on ones at eta 3, 9 and 12, no
#: difference resolved or growing with K, and K = 50 against K = 10 on fifteen twin runs (the 1/4
#: head-on at eta 3, 6, 9, five realizations; runs/results/ladder_clock/) moves m_lf/m_t by +0.004
#: (95 %: -0.002 to +0.011); at R = 4 (25 000 particles, dt 0.0252 s) eight twin runs at K = 40
#: (1.0 s) against K = 16 (0.4 s) differ by +0.0003 (-0.008 to +0.009), every twin within 0.016
#: (runs/results/throughput_r4_k40/ against throughput_r4_k16/), and step 1.35x as fast.  1.0 s is
#: K = 25 at the paper's dt, 40 at R = 4 and 63 at R = 16 with the contacts scaled.  (It was 0.4 s,
#: K = 10 at the paper's dt, until the R = 4 twins tested 1.0 s; the files of runs made then pin
#: their K.)
GRAVITY_INTERVAL_AUTO = 1.0


def auto_gravity_every(dt: float) -> int:
    """The K of ``gravity_every = "auto"`` at the time step ``dt`` [s]: the whole number of steps
    nearest GRAVITY_INTERVAL_AUTO / dt (a half rounds up, one short of it by round-off too), at
    least 1.  25 at the paper's 0.04 s; 40 and 63 at R = 4 and 16 with the contacts scaled
    (dt x R^(-1/3))."""
    if isinstance(dt, bool) or not isinstance(dt, numbers.Real) or not math.isfinite(dt) or dt <= 0:
        raise InputError(f'gravity_every = "auto" needs a time step > 0 to choose K from; got dt = {dt!r}')
    return max(1, math.floor(GRAVITY_INTERVAL_AUTO / dt + 0.5 + 1e-9))


#: The Scheme fields that a run specification keeps in its [params] table, beside the physics (its
#: precision is a [run] key; its layout is chosen from [run] layout and the device).
SCHEME_KEYS = ("gravity", "theta_open", "gravity_every")

#: The scheme's numbers' ranges: Scheme checks them, and the run specification's schema (spec.py)
#: reads the same.
SCHEME_RANGES = {
    "theta_open": Range(lambda v: 0 < v < 2, "in (0, 2)", "tree opening angle"),
}


@dataclass(frozen=True)
class Scheme:
    """How an engine evaluates the model: the numerical choices beside the physics of Params.

    >>> sim = Simulation(state, Params(), scheme=Scheme(gravity="tree", gravity_every=10))
    """

    precision: str = "mixed"
    """Arithmetic of the all-pairs sweep: "mixed" (float32 gravity on float64 separations) or "float64"."""
    gravity: str = "all-pairs"
    """Gravity solver, a name in GRAVITY_SOLVERS: "all-pairs" (every pair), "tree" (Barnes-Hut), or another registered there."""
    theta_open: float = 0.4
    """The tree's opening angle: a node is used whole beyond size / theta_open (plus its centre's
    offset); 0.4 keeps the rms relative gravity error on settled piles below 1e-3 (tests/test_tree.py)."""
    gravity_every: int = 1
    """K, the clock: steps of dt per evaluation of gravity.  1 is the paper's scheme (gravity and
    contacts every step); K > 1 kicks gravity every K dt around K steps of contacts alone (impulse
    multiple time stepping, docs/model.md "Gravity on its own clock"), and step counts are multiples of K."""
    layout: Layout | None = None
    """The all-pairs kernels' layout (None: the device's own for the size, settled by :func:`choose_scheme`)."""
    force_kernel: str = "tiled"

    def __post_init__(self):
        if self.precision not in PRECISIONS:
            raise InputError(f"precision must be one of {', '.join(PRECISIONS)}; got {self.precision!r}")
        if self.force_kernel not in FORCE_KERNELS:
            raise InputError(f"force_kernel must be one of {', '.join(FORCE_KERNELS)}; got {self.force_kernel!r}")
        if self.gravity not in GRAVITY_SOLVERS:
            raise InputError(f"gravity must be one of {', '.join(GRAVITY_SOLVERS)}; got {self.gravity!r}")
        for name, allowed in SCHEME_RANGES.items():
            require_number(self, name, allowed)
        every = self.gravity_every
        if isinstance(every, bool) or not isinstance(every, numbers.Integral) or every < 1:
            raise InputError(f"gravity_every must be an integer >= 1 (steps of dt per gravity evaluation); got {every!r}")
        object.__setattr__(self, "gravity_every", int(every))

    @property
    def step_multiple(self) -> int:
        """K, the steps of an outer step: every step count of a run is a multiple of it (1 at the paper's
        clock).  Code that steps, checks step counts or costs a step asks this, not the field."""
        return self.gravity_every

    @property
    def clocks(self) -> int:
        """1 where gravity and contacts share the step (K = 1), 2 where gravity has its own clock."""
        return 1 if self.gravity_every == 1 else 2

    def newton_sweep(self, n: int, device: str) -> Layout | None:
        """The layout with which all-pairs gravity is summed by the Newton sweep (each pair once):
        the scheme's own where that is a Newton layout, else, for gravity on its own clock (which
        takes that sweep on any device), the device's :func:`~decco_warp.layouts.newton_layout`; None
        where no Newton sweep runs (the tree, or the fused layout at K = 1).  ``n``: the largest
        system's particles, which choose the layout where the scheme has none yet."""
        if self.gravity == "tree":
            return None
        layout = self.layout or choose_layout(n, device)
        if layout.newton:
            return layout
        return newton_layout(device) if self.gravity_every > 1 else None

    def clock_text(self, solver: bool = False) -> str:
        """The clock in words ("gravity every K steps", with ``solver`` how it is summed), "" for the
        paper's (gravity and contacts every step)."""
        if self.gravity_every == 1:
            return ""
        how = f" ({'the tree' if self.gravity == 'tree' else 'each pair once'})" if solver else ""
        return f"gravity every {self.gravity_every} steps{how}"


def step_multiple_of(table: dict) -> int | None:
    """K of a specification's [params] table as given (not yet checked): its ``gravity_every``, 1
    where the key is absent, an "auto" read as :func:`auto_gravity_every` of the table's dt (Params'
    default where it gives none); None for an "auto" whose dt is "auto" too (given, or implied by
    ``k_in = "auto"``): that K is settled with the dt, from the collision set-up (spec.settle_auto)."""
    every = table.get("gravity_every", 1)
    if every != "auto":
        return int(every)
    dt = table.get("dt", "auto" if table.get("k_in") == "auto" else Params().dt)
    return None if dt == "auto" else auto_gravity_every(float(dt))


def choose_scheme(largest: int, device: str, asked: Scheme | None = None, **choices) -> Scheme:
    """The scheme of an engine whose largest system has ``largest`` particles on ``device``: ``asked``
    (default Scheme()) with ``choices`` (its fields, None: as asked) and its layout, where none is
    asked for, the device's own for that size (layouts.choose_layout)."""
    scheme = replace(asked or Scheme(), **{name: value for name, value in choices.items() if value is not None})
    return scheme if scheme.layout is not None else replace(scheme, layout=choose_layout(largest, device))

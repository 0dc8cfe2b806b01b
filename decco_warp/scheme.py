"""How a run is computed, apart from what it computes: the numerical scheme.

:class:`~decco_warp.params.Params` says what the model is (the contact constants, G, dt); a
:class:`Scheme` says how the engine evaluates it: the precision of the all-pairs sweep, the gravity
solver (every pair, or a tree with its opening angle), the clock (gravity every K steps), the force
kernels' layout, and whether the plain reference kernel steps it.  :func:`choose_scheme` reads the
thresholds that choose by size and device (the tree from N, the Newton layout's reach) in one place,
and :func:`force_path` is the one switch from a scheme to the parts that compute its forces
(decco_warp/forces.py composes them).  Plain data: no launches.
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import InputError
from .kernels.bodies import PRECISIONS  # noqa: F401 (the scheme's names: spec.py reads them here)
from .layouts import Layout, choose_layout

#: The force kernels a scheme may step with: "tiled" (the layouts of the GPU and CPU) or the plain
#: one-thread-per-particle "reference" kernel (the tests' yardstick, the bench's baseline).
FORCE_KERNELS = ("tiled", "reference")


@dataclass(frozen=True)
class Scheme:
    """The numerical choices of an engine, settled (no "auto")."""

    precision: str = "mixed"
    """Arithmetic of the all-pairs sweep: "mixed" (float32 gravity on float64 separations) or "float64"."""
    gravity: str = "all-pairs"
    """Gravity solver: "all-pairs" (every pair) or "tree" (Barnes-Hut, error set by ``theta_open``)."""
    theta_open: float = 0.4
    """The tree's opening angle."""
    clock: int = 1
    """K, steps of dt per gravity evaluation (``gravity_every``): 1 the paper's scheme, K > 1 gravity
    on its own clock (impulse multiple time stepping, docs/model.md)."""
    layout: Layout | None = None
    """The all-pairs kernels' layout (None: not settled yet; :func:`choose_scheme` settles it)."""
    force_kernel: str = "tiled"

    def __post_init__(self):
        if self.precision not in PRECISIONS:
            raise InputError(f"precision must be one of {', '.join(PRECISIONS)}; got {self.precision!r}")
        if self.force_kernel not in FORCE_KERNELS:
            raise InputError(f"force_kernel must be one of {', '.join(FORCE_KERNELS)}; got {self.force_kernel!r}")


def choose_scheme(largest: int, device: str, params, precision: str = "mixed", force_kernel: str = "tiled", layout: Layout | None = None) -> Scheme:
    """The scheme of an engine whose largest system has ``largest`` particles on ``device``, from the
    numerical keys of ``params`` (gravity, theta_open, gravity_every) and the engine's options; the
    layout, where not given, is the device's own for that size (layouts.choose_layout)."""
    return Scheme(
        precision=precision,
        gravity=params.gravity,
        theta_open=params.theta_open,
        clock=params.gravity_every,
        layout=layout or choose_layout(largest, device),
        force_kernel=force_kernel,
    )


def force_path(scheme: Scheme) -> str:
    """The one switch: which composition of parts computes a scheme's forces (decco_warp/forces.py
    FORCE_PATHS): "reference" or "fused" (one kernel: gravity and contacts), "newton" (each pair's
    gravity once, listing candidates for the contact pass), "tree" (the tree's gravity, a hash
    grid's candidates) or "clocked" (gravity every K steps, contacts every step from a neighbour list)."""
    if scheme.force_kernel == "reference":
        if scheme.clock > 1:
            raise InputError("the reference kernel evaluates gravity with every force: it steps with gravity_every = 1 only")
        return "reference"
    if scheme.clock > 1:
        return "clocked"
    if scheme.gravity == "tree":
        return "tree"
    return "newton" if scheme.layout.newton else "fused"

"""Throughput of the force kernel and of the full step, beside a plain baseline in the same process.

The test system (``system``) is either a jittered cubic lattice of the paper's
smallest spheres, spaced so that each touches its six neighbours with overlaps
of ~1e2 cm (``lattice``: the tables of docs/benchmarks.md), or copies of the
shipped settled target pile side by side (``piles``: the paper's three radii,
a large grain touching up to ~27 small ones, as in a run).  Throughput is N^2 /
time (pairs per second, every ordered pair evaluated once per force evaluation).
With gravity on its own clock (``gravity_every`` K > 1) a step evaluates gravity once every K
steps and the contacts from a neighbour list: its pairs/s is the all-pairs step's N^2 over its
mean step time, the rate an all-pairs step would need to keep up.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import time
from dataclasses import asdict, dataclass

import numpy as np
import warp as wp

from . import layouts as thread_layouts  # (its PARTICLE_BLOCK is set per row; "layouts" names the option)
from .engine import Engine
from .layouts import Layout, choose_layout
from .params import Params
from .scheme import Scheme
from .simulation import Simulation, graph_steps
from .state import State
from .errors import InputError

#: Arithmetic per pair used for the device limit (gravity ~20 flops), as in the issue tracker.
FLOPS_PER_PAIR = 20
#: FP32 lanes per SM by compute capability (major, minor).
_FP32_LANES = {(7, 0): 64, (8, 0): 64, (8, 6): 128, (8, 7): 128, (8, 9): 128, (9, 0): 128, (10, 0): 128, (12, 0): 128}

RADIUS = 0.75e6
DENSITY = 2.7


@dataclass
class BenchRow:
    n: int
    device: str
    layout: str
    force_seconds: float
    force_pairs_per_s: float
    step_seconds: float
    step_pairs_per_s: float
    baseline_seconds: float
    baseline_pairs_per_s: float
    speedup: float
    fraction_of_limit: float | None
    """The gravity pairs the step evaluates per second (N^2 a gravity evaluation, one every K steps:
    N^2 / K a step) over the device's arithmetic limit: at most 1 (None: no limit here, or a tree)."""
    systems: int = 1
    """Systems of n particles stepped together (an ensemble); pairs/s counts all of them."""
    system: str = "lattice"
    """The test system: ``lattice`` or ``piles`` (see the module's docstring)."""
    particles_per_s: float = math.nan
    """Particles advanced per second by the full step (all systems)."""
    gravity: str = "all-pairs"
    """The gravity solver: a tree row has no pairs/s and no fraction of the all-pairs limit (it does
    not compute the pairs); ``versus_all_pairs`` compares it with all-pairs where both were timed."""
    versus_all_pairs: float | None = None
    """All-pairs step time over this row's, at the same N in the same call (tree rows)."""
    fuse_kicks: bool = True
    """The steps shared launches (Layout.fuse_kicks); False: each step's kicks and packing in
    launches of their own (``--layouts ...:unfused``)."""
    gravity_every: int = 1
    """K: steps per gravity evaluation (K > 1: contacts from a neighbour list)."""
    list_builds_per_step: float | None = None
    """Neighbour-list builds per step while the full step was timed (K > 1)."""
    versus_every_step: float | None = None
    """The K = 1 step time over this row's, at the same N in the same call (K > 1 rows)."""
    particle_block: int | None = None
    """Threads a block of the kernels of one thread a particle, where a row sets it (layouts.PARTICLE_BLOCK otherwise)."""
    versus_default_block: float | None = None
    """The step time at the default PARTICLE_BLOCK over this row's, same N, K and call."""
    contact_law: str = "paper"
    """The contact law stepped (params.CONTACT_LAWS, its default constants)."""
    versus_first_law: float | None = None
    """The step time of the first law asked for (``--contact-law``'s first) over this row's, the same
    row otherwise, in the same call (rows of the other laws)."""


#: The test systems of :func:`bench_size`.
TEST_SYSTEMS = ("lattice", "piles")


def lattice_pile(n: int, seed: int = 0) -> State:
    """``n`` spheres on a jittered cubic lattice, each overlapping its neighbours by ~1e2 cm."""
    rng = np.random.default_rng(seed)
    side = math.ceil(n ** (1.0 / 3.0))
    spacing = 2.0 * RADIUS - 300.0
    grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)[:n]
    positions = (grid - (side - 1) / 2.0) * spacing + rng.uniform(-100.0, 100.0, size=(n, 3))
    velocities = rng.normal(size=(n, 3)) * 10.0
    omegas = rng.normal(size=(n, 3)) * 1e-5
    radii = np.full(n, RADIUS)
    masses = np.full(n, 4.0 / 3.0 * math.pi * DENSITY * RADIUS**3)
    return State.from_arrays(positions, velocities, omegas, radii, masses)


def pile_mosaic(n: int, seed: int = 0) -> State:
    """``n`` spheres from copies of the shipped settled target pile, each turned at random, on a
    cubic grid with gaps between them (the last copy cut short): a pile's contacts at any N."""
    from .io import load_pile
    from .plan import builtin_pile

    pile = load_pile(builtin_pile("target"))
    centred = pile.positions - pile.positions.mean(axis=0)
    spacing = 2.0 * (np.linalg.norm(centred, axis=1).max() + 2.0 * pile.radii.max())
    copies = math.ceil(n / pile.n)
    side = math.ceil(copies ** (1.0 / 3.0))
    rng = np.random.default_rng(seed)
    parts = []
    for k in range(copies):
        turn, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        cell = np.array([k % side, (k // side) % side, k // side**2]) - (side - 1) / 2.0
        parts.append(centred @ turn.T + cell * spacing)

    def tiled(values: np.ndarray) -> np.ndarray:
        return np.concatenate([values] * copies)[:n]

    return State.from_arrays(np.concatenate(parts)[:n], tiled(pile.velocities), tiled(pile.omegas), tiled(pile.radii), tiled(pile.masses))


def bench_system(kind: str, n: int, systems: int = 1) -> State:
    """The bench's ``kind`` of system at ``n`` particles, or ``systems`` of them one after another
    (an ensemble: each different)."""
    if kind not in TEST_SYSTEMS:
        raise InputError(f"the test system must be one of {', '.join(TEST_SYSTEMS)}; got {kind!r}")
    make = lattice_pile if kind == "lattice" else pile_mosaic
    piles = [make(n, seed=k) for k in range(systems)]

    def joined(name: str) -> np.ndarray:
        return np.concatenate([getattr(p, name) for p in piles])

    return State.from_arrays(joined("positions"), joined("velocities"), joined("omegas"), joined("radii"), joined("masses"))


def device_limit_pairs_per_s(device: str) -> tuple[float | None, str]:
    """The device's float32 arithmetic limit in pairs/s, and how it was worked out."""
    if not device.startswith("cuda"):
        return None, "no limit is computed for the CPU"
    d = wp.get_device(device)
    lanes = _FP32_LANES.get((d.arch // 10, d.arch % 10))
    clock_ghz = _max_sm_clock_ghz(d.ordinal)
    if lanes is None or clock_ghz is None:
        return None, f"unknown FP32 lanes or clock for sm_{d.arch}"
    flops = d.sm_count * lanes * 2 * clock_ghz * 1e9  # an FMA is 2 flops
    return flops / FLOPS_PER_PAIR, (
        f"{d.sm_count} SMs x {lanes} FP32 lanes x 2 x {clock_ghz:.2f} GHz = {flops / 1e12:.1f} TFLOP/s, "
        f"/ {FLOPS_PER_PAIR} flops per pair"
    )


def _max_sm_clock_ghz(ordinal: int) -> float | None:
    try:
        out = subprocess.run(
            ["nvidia-smi", f"--id={ordinal}", "--query-gpu=clocks.max.sm", "--format=csv,noheader,nounits"],
            capture_output=True,
            text=True,
            timeout=20,
        )
        return float(out.stdout.strip().splitlines()[0]) / 1e3
    except (OSError, ValueError, IndexError, subprocess.SubprocessError):
        return None


def _seconds_per_call(fn, device: str, budget: float) -> float:
    """Mean wall time of fn() over enough calls to fill ``budget`` seconds (after a warm-up)."""
    fn()
    wp.synchronize_device(device)
    start = time.perf_counter()
    fn()
    wp.synchronize_device(device)
    once = max(time.perf_counter() - start, 1e-7)
    calls = max(1, min(10_000, int(budget / once)))
    start = time.perf_counter()
    for _ in range(calls):
        fn()
    wp.synchronize_device(device)
    return (time.perf_counter() - start) / calls


def bench_size(
    n: int,
    device: str,
    precision: str = "mixed",
    layout: Layout | None = None,
    budget: float = 1.0,
    steps: int = 100,
    baseline: bool = True,
    gravity: str = "all-pairs",
    systems: int = 1,
    system: str = "lattice",
    gravity_every: int = 1,
    particle_block: int | None = None,
    law: str = "paper",
) -> BenchRow:
    """One row: the force evaluation and the full step at ``n`` (pairs/s counts N^2 pairs a step, what
    an every-step all-pairs code needs, also at K > 1; the fraction of the device's limit counts the
    pairs the step evaluates, N^2 / K; a tree row gives neither, only its times and particles/s),
    beside the one-thread-per-particle kernel.
    With ``systems`` > 1, that many systems of ``n`` stepped together, and pairs/s counts them all.
    A call is ``steps`` rounded up to whole recorded graphs (simulation.graph_steps: 50 steps, or
    whole outer steps of K), as a run steps: steps left over are launched one by one, and at K > 1
    each of those reads the list's stale flag on the host.  With ``gravity_every`` K > 1 the row
    counts the neighbour list's builds per step.  ``particle_block``: the threads a block of the
    kernels of one thread a particle, in place of layouts.PARTICLE_BLOCK for this row.  ``law``: the
    contact law (its default constants)."""
    default = thread_layouts.PARTICLE_BLOCK
    thread_layouts.PARTICLE_BLOCK = particle_block or default
    try:
        row = _bench_size(n, device, precision, layout, budget, steps, baseline, gravity, systems, system, gravity_every, law)
    finally:
        thread_layouts.PARTICLE_BLOCK = default
    row.particle_block = particle_block
    return row


def _bench_size(n, device, precision, layout, budget, steps, baseline, gravity, systems, system, gravity_every, law) -> BenchRow:
    state = bench_system(system, n, systems)
    sizes = [n] * systems
    params = Params(contact_law=law)
    layout = layout or choose_layout(n, device)
    scheme = Scheme(precision=precision, gravity=gravity, gravity_every=gravity_every, layout=layout)
    tiled = Engine(state, params, device, systems=sizes, scheme=scheme)
    force_seconds = _seconds_per_call(tiled.eval_forces, device, budget)
    # The full step as runs take it: with the energy ledger.
    sim = Simulation(state, params, device=device, scheme=scheme, allow_unstable=True, ledger=True, systems=sizes)
    block = graph_steps(sim.step_multiple)
    steps = block * math.ceil(steps / block)
    first_step, first_builds = sim.step_count, sim.neighbour_list_builds()
    step_seconds = _seconds_per_call(lambda: sim.step(steps), device, budget) / steps
    builds = None if first_builds is None else (sim.neighbour_list_builds() - first_builds) / (sim.step_count - first_step)
    if baseline:
        reference = Engine(state, params, device, precision, "reference")
        baseline_seconds = _seconds_per_call(reference.eval_forces, device, budget)
    else:
        baseline_seconds = math.nan
    limit, _ = device_limit_pairs_per_s(device)
    pairs = float(n) * n * systems if gravity == "all-pairs" else math.nan
    if scheme.clock_text():
        what = f"{scheme.clock_text(solver=True)}, neighbour-list contacts"
    else:
        what = layout.describe() if gravity == "all-pairs" else f"tree (theta_open {scheme.theta_open:g}), hash-grid contacts"
    return BenchRow(
        n=n,
        device=device,
        layout=what + (f", {systems} systems together" if systems > 1 else ""),
        force_seconds=force_seconds,
        force_pairs_per_s=pairs / force_seconds,
        step_seconds=step_seconds,
        step_pairs_per_s=pairs / step_seconds,
        baseline_seconds=baseline_seconds,
        baseline_pairs_per_s=float(n) * n * systems / baseline_seconds,
        speedup=baseline_seconds / force_seconds,
        fraction_of_limit=None if limit is None or gravity != "all-pairs" else (pairs / gravity_every / step_seconds) / limit,
        systems=systems,
        system=system,
        particles_per_s=n * systems / step_seconds,
        gravity=gravity,
        fuse_kicks=layout.fuse_kicks,
        gravity_every=gravity_every,
        list_builds_per_step=builds,
        contact_law=law,
    )


def bench_rows(
    sizes, kinds, device: str, precision: str = "mixed", budget: float = 1.0, steps: int = 100, solvers=("all-pairs",),
    layouts=(), ensembles=(), clocks=(), particle_blocks=(), laws=("paper",),
):  # fmt: skip
    """Every row of ``decco-warp bench``, in order, as each is measured: per contact law of ``laws``
    (each row of a law after the first against the first law's same row), :func:`law_rows`."""
    first: list[BenchRow] = []  # each law's rows come in the same order
    for k, law in enumerate(laws):
        rows = law_rows(sizes, kinds, device, precision, budget, steps, solvers, layouts, ensembles, clocks, particle_blocks, law)
        for index, row in enumerate(rows):
            if k == 0:
                first.append(row)
            else:
                row.versus_first_law = first[index].step_seconds / row.step_seconds
                row.layout += f", contact law {law}: {row.versus_first_law:.2f}x the {laws[0]} law's step"
            yield row


def law_rows(sizes, kinds, device, precision, budget, steps, solvers, layouts, ensembles, clocks, particle_blocks, law):
    """The rows of one contact law, in order, as each is measured: per size and test system, the
    default all-pairs layout (beside the one-thread-per-particle baseline) and ``layouts``, the tree,
    ensembles of ``ensembles`` systems (against one at a time), and gravity every K of ``clocks``
    (against K = 1 with the same solver; with ``ensembles``, each ensemble at each K too, against one
    system at that K: K > 1 changes what fills the GPU), and the default layout at K = 1 and each K of ``clocks``
    with ``particle_blocks`` threads a block for the kernels of one thread a particle (against
    layouts.PARTICLE_BLOCK); each comparison is added to the row's layout text."""
    for size, kind in itertools.product(sizes, kinds):
        runs = [("all-pairs", layout) for layout in [None, *layouts]] if "all-pairs" in solvers else []
        runs += [("tree", None)] if "tree" in solvers else []
        runs = [(solver, layout, 1, 1, None) for solver, layout in runs]
        runs += [("all-pairs", None, k, 1, None) for k in ensembles]
        runs += [(solver, None, 1, every, None) for every in clocks for solver in solvers]
        runs += [("all-pairs", None, k, every, None) for every in clocks for k in ensembles] if "all-pairs" in solvers else []
        runs += [(solver, None, 1, every, block) for block in particle_blocks for every in [1, *clocks] for solver in solvers]
        alone, every_step, default_block = {}, {}, {}
        for solver, layout, systems, every, block in runs:
            first = (solver, layout, systems, every, block) == runs[0]
            row = bench_size(
                size, device, precision, layout, budget, steps, baseline=first, gravity=solver, systems=systems, system=kind,
                gravity_every=every, particle_block=block, law=law,
            )  # fmt: skip
            if len(kinds) > 1:
                row.layout += f", {kind}"
            if systems == 1 and layout is None and block is None:
                default_block[(solver, every)] = row
            if block is not None:  # against the default block, same solver and clock
                row.versus_default_block = default_block[(solver, every)].step_seconds / row.step_seconds
                row.layout += f", {block} threads a block for the per-particle kernels: {row.versus_default_block:.2f}x {thread_layouts.PARTICLE_BLOCK}"
                yield row
                continue
            if systems == 1 and layout is None and every == 1:
                every_step[solver] = row
            if systems == 1 and layout is None and solver == "all-pairs":
                alone[every] = row  # one system at this clock: what an ensemble at that clock is against
            if systems > 1 and every in alone:
                row.layout += f": {row.step_pairs_per_s / alone[every].step_pairs_per_s:.2f}x one at a time"
            if solver == "tree" and every == 1 and 1 in alone:  # the tree in its own terms: its time against all-pairs'
                row.versus_all_pairs = alone[1].step_seconds / row.step_seconds
                row.layout += f": {row.versus_all_pairs:.2f}x the all-pairs step"
            if every > 1 and systems == 1:  # against gravity every step with the same solver, and how often the list was built
                row.versus_every_step = every_step[solver].step_seconds / row.step_seconds
                row.layout += f": {row.versus_every_step:.2f}x the K = 1 step, {row.list_builds_per_step:.3g} list builds a step"
            yield row


def as_dict(row: BenchRow) -> dict:
    """The row for JSON: a quantity not measured (NaN) becomes null."""
    return {key: None if isinstance(value, float) and math.isnan(value) else value for key, value in asdict(row).items()}

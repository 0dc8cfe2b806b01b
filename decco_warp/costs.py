"""What a job will cost before it starts: the memory it needs on its device, the time of a step on a
device, of a run, of a formation.

Estimates for ``--check``, from measured rates (docs/benchmarks.md), not promises: on a CPU the
all-pairs sum at ~5 ns a pair on 2 cores (CPU_SECONDS_PER_PAIR, scaled by the cores here),
on a GPU the H100's rates (other GPUs differ by their arithmetic throughput).
"""

from __future__ import annotations

import math
import os

import numpy as np

from .arrays import PAIR_OBSERVABLES
from .gravity_tree import walk_parts
from .kernels.channels import LEDGER_CHANNELS, WORK_CHANNELS
from .kernels.contacts import CANDIDATES
from .kernels.neighbours import STENCIL
from .layouts import newton_scratch_bytes
from .params import G_CGS
from .scheme import Scheme

#: H100, the Newton layout's full step (docs/benchmarks.md): 4.5e11 pairs/s at 6 250 particles,
#: 6.3e11 at 10 240, 1.04e12 at 65 536 (pairs: N^2 a step); the rate grows as the GPU fills.
GPU_PAIRS_PER_S_AT = (6250, 4.5e11)
GPU_PAIRS_PER_S_MAX = 1.04e12
#: H100, the tree path a step: 2.69 ms at 131 072 particles, 22.9 ms at 1e6 (~2.2e-8 s a particle).
GPU_TREE_SECONDS_PER_PARTICLE = 2.2e-8
#: A step's launches cost at least this on a GPU, whatever the size [s].
GPU_STEP_FLOOR = 2e-5
#: A pile settles (KE below 1e-5 |U|) in 3 to 10 free-fall times of its seeding sphere (measured:
#: 400 particles in ~4, 50 particles in ~8.5).
FORMATION_FREE_FALLS = (3.0, 10.0)


#: Gravity on its own clock (gravity_every = K > 1): a step costs the K = 1 step's gravity over K plus
#: the contacts from the neighbour list, about this much a particle [s] (the list's rebuilds at the
#: impact included).  2-core CPU: the default collision (450 particles) stepped 50 000 steps in 48.8 s
#: at K = 1 and 6.2 s at K = 10 (0.124 ms a step, 0.101 of it gravity: 5e-8 s a particle).  H100,
#: whole runs at K = 10: the Fig. 8 collision (6 250) 43.9 s and the 10 000-particle ones 51.8 to
#: 59.5 s for 1e6 steps, gravity's share taken out: 4e-9 to 6e-9 s a particle.
CPU_CONTACT_SECONDS_PER_PARTICLE = 5e-8
GPU_CONTACT_SECONDS_PER_PARTICLE = 5e-9


def step_seconds(n: int, scheme: Scheme, device: str) -> float:
    """About how long one step of ``n`` particles takes on ``device`` [s] by ``scheme`` (its gravity
    solver, evaluated every ``scheme.step_multiple`` steps, the contacts every step)."""
    gravity, every = scheme.gravity, scheme.step_multiple
    if not device.startswith("cuda"):
        step = cpu_step_seconds(n, gravity)
        if every > 1:  # the same cores' share as the pair sums (cpu_step_seconds)
            step = step / every + CPU_CONTACT_SECONDS_PER_PARTICLE * n / (max(1, os.cpu_count() or 1) / 2.0)
        return step
    if gravity == "tree":
        step = max(GPU_STEP_FLOOR, GPU_TREE_SECONDS_PER_PARTICLE * n)
    else:
        size, rate = GPU_PAIRS_PER_S_AT
        rate = min(GPU_PAIRS_PER_S_MAX, rate * math.sqrt(n / size))
        step = max(GPU_STEP_FLOOR, float(n) * float(n) / rate)
    if every > 1:
        step = max(GPU_STEP_FLOOR, step / every + GPU_CONTACT_SECONDS_PER_PARTICLE * n)
    return step


def duration(seconds: float) -> str:
    """A wall time in the unit that reads best."""
    if seconds < 90:
        return f"{seconds:.2g} s"
    if seconds < 5400:
        return f"{seconds / 60:.2g} min"
    if seconds < 48 * 3600:
        return f"{seconds / 3600:.2g} h"
    return f"{seconds / 86400:.2g} days"


def run_cost(n: int, scheme: Scheme, device: str, steps: int) -> str:
    """One line: the wall time of ``steps`` steps of ``n`` particles on ``device`` by ``scheme``
    (:func:`step_seconds`), and how it is made."""
    step = step_seconds(n, scheme, device)
    where = "an H100's rates" if device.startswith("cuda") else "this CPU"
    clock = f" at {scheme.clock_text()}" if scheme.clocks > 1 else ""
    return f"about {duration(step * steps)} on {device} ({1e3 * step:.3g} ms a step x {steps} steps{clock}; {where}, docs/benchmarks.md)"


#: Said once where a cost is made at gravity_every > 1: how the estimate is made, and how far to trust it.
GRAVITY_EVERY_NOTE = (
    "note: at gravity every K steps a step is estimated as the K = 1 step's gravity over K plus the contacts "
    "(measured whole runs: the default collision 7.9x as fast at K = 10 on a 2-core CPU, the paper's 2.0x to 3.1x on an H100); "
    "a collision whose contacts churn rebuilds its neighbour list more often and takes longer"
)


def cost_note(scheme: Scheme) -> str | None:
    """What a cost by ``scheme`` rests on, where a line should say so (gravity on its own clock)."""
    return GRAVITY_EVERY_NOTE if scheme.clocks > 1 else None


def formation_steps(density: float, fill: float, dt: float) -> tuple[int, int]:
    """The range of steps of ``dt`` [s] a pile of grains of ``density`` [g/cm^3] takes to settle from a
    seeding sphere filled to ``fill``: FORMATION_FREE_FALLS free-fall times sqrt(3 pi / (32 G rho_seed))
    of that sphere's mean density (whatever the particle count and radii)."""
    rho = fill * density
    free_fall = math.sqrt(3.0 * math.pi / (32.0 * G_CGS * rho))
    low, high = FORMATION_FREE_FALLS
    return int(low * free_fall / dt), int(high * free_fall / dt)


def formation_cost(n: int, density: float, fill: float, dt: float, gravity: str, device: str) -> str:
    """One line: the steps and wall time a formation of ``n`` particles is likely to take on ``device``."""
    low, high = formation_steps(density, fill, dt)
    step = step_seconds(n, Scheme(gravity=gravity), device)
    return (f"settling takes {low} to {high} steps ({FORMATION_FREE_FALLS[0]:g} to {FORMATION_FREE_FALLS[1]:g} free-fall times of the seeding sphere): about "
            f"{duration(step * low)} to {duration(step * high)} on {device} ({1e3 * step:.3g} ms a step)")  # fmt: skip


# --- what a job needs, before it starts ---------------------------------------------------------

#: Bytes a particle takes on the host beside the engine's arrays: the State, a frame's record, a
#: snapshot, the checks (NumPy copies of a few vectors each), with room.
HOST_BYTES_PER_PARTICLE = 600
#: Bytes of a job whatever its size: Warp's modules, the hash grid's cells, launch bookkeeping.
FIXED_BYTES = 256 << 20
#: CPU step time of this project's 2-core CI-class machine (docs/benchmarks.md, the tree section):
#: all-pairs ~5 ns a pair (8 000 particles: 0.31 s a step); the tree ~7.5 us a particle at 8 000,
#: growing as log N.  Scaled by the cores here.
CPU_SECONDS_PER_PAIR = 5e-9
CPU_TREE_SECONDS_PER_PARTICLE = 7.5e-6


def memory_estimate(
    n: int, scheme: Scheme, device: str = "cpu", ledger: bool = True, *, candidate_width: int = CANDIDATES, contact_history: bool = False,
) -> int:
    """Bytes a job of ``n`` particles by ``scheme`` needs on its device (and on the host), an upper
    estimate: the arrays Engine and GravityTree allocate, taken as for the largest layout, the
    Newton sweep's rows where all-pairs gravity takes it (Scheme.newton_sweep: a Newton layout, as
    CUDA's default is up to NEWTON_MAX particles, or gravity on its own clock on any device), and with
    ``contact_history`` the contact history of a law with springs per pair (arrays.ContactHistory:
    ``candidate_width`` rows a particle, current and next)."""
    gravity = scheme.gravity
    vec3d, f64, i32 = 24, 8, 4
    per = 3 * f64 + 5 * vec3d  # radius, mass, inertia; position, velocity, omega, force, torque
    per += (len(LEDGER_CHANNELS) * vec3d + len(WORK_CHANNELS) * f64) if ledger else 0  # channels, work
    per += 8 + 32 + 8  # deepest contact, packed body, system range
    per += i32 * (1 + candidate_width)  # the contact candidates of the Newton layout, the tree or the neighbour list
    per += 3 * vec3d + f64 + 5 * i32  # gravity on its own clock: gravity, the list's build positions, the build's sorted
    # positions and radii; system, cell keys and order (2 N)
    if scheme.clocks > 1:  # the list's build by cell (contact_finders.NeighbourList.scan): each cell's count, the neighbours as met
        per += i32 * (STENCIL + candidate_width)
    per += len(PAIR_OBSERVABLES) * f64  # a frame's pair observables
    if contact_history:  # count; per row partner, spring, normal, rolling, twist; twice (current and next)
        per += 2 * (i32 + candidate_width * (i32 + 3 * vec3d + f64)) + 2 * f64  # (and the springs' energies of a frame)
    if gravity == "tree":  # nodes (2n): mass, centre, quadrupole, box, size, offset, links (16), child, first,
        # last, parent, escape; keys, order (2n); leaf positions, grid points; each walk part's field and potential
        per += 2 * (f64 + vec3d + 72 + 2 * vec3d + 2 * f64 + 16 + 5 * i32) + 4 * i32 + vec3d + 12
        per += walk_parts(n, device) * (vec3d + f64)
    newton = scheme.newton_sweep(n, device)
    scratch = newton_scratch_bytes(n, newton, 12 if scheme.precision == "mixed" else 24, listing=scheme.clocks == 1) if newton else 0
    return int(n * (per + HOST_BYTES_PER_PARTICLE) + scratch + FIXED_BYTES)


def cpu_step_seconds(n: int, gravity: str) -> float:
    """About how long one step of ``n`` particles takes on this machine's CPU."""
    cores = max(1, os.cpu_count() or 1) / 2.0
    if gravity == "tree":
        return CPU_TREE_SECONDS_PER_PARTICLE * n * max(1.0, np.log2(max(n, 2)) / np.log2(8000)) / cores
    return CPU_SECONDS_PER_PAIR * float(n) * float(n) / cores


#: A CPU job expected to take longer than this says so before it starts [s].
LONG_ON_CPU = 3600.0


def check_fits(
    n: int, scheme: Scheme, device: str, steps: int, what: str, *, candidate_width: int = CANDIDATES, contact_history: bool = False,
) -> str | None:
    """Refuse (InputError) a job by ``scheme`` whose memory estimate passes the device's free memory
    (``contact_history``: its law keeps springs per pair); for one that fits but would take hours on
    the CPU, the line that says so (else None)."""
    from .checks import InputError
    from .device import free_memory

    gravity = scheme.gravity
    need = memory_estimate(n, scheme, device, candidate_width=candidate_width, contact_history=contact_history)
    free = free_memory(device)
    if need > free:
        tree = "" if gravity == "tree" else ", gravity = \"tree\" (its memory grows as N, all-pairs' as N^2 here)"
        raise InputError(
            f"{what} of {n} particles needs about {need / 2**30:.3g} GiB on {device}, which has {free / 2**30:.3g} GiB free; "
            f"use fewer particles{tree} or a device with more memory"
        )
    if device.startswith("cuda"):
        return None
    step = step_seconds(n, scheme, device)
    seconds = steps * step
    if seconds < LONG_ON_CPU:
        return None
    return (
        f"note: {what} of {n} particles ({gravity} gravity) will take about {_duration(seconds)} on the CPU "
        f"({step:.3g} s a step, {steps} steps); a GPU (--device cuda) is far faster"
    )


def _duration(seconds: float) -> str:
    hours = seconds / 3600.0
    if hours < 48:
        return f"{hours:.3g} hours"
    days = hours / 24.0
    return f"{days:.3g} days" if days < 730 else f"{days / 365.25:.3g} years"

"""What a job will cost before it starts: the time of a step on a device, of a run, of a formation.

Estimates for ``--check``, from measured rates (docs/benchmarks.md), not promises: on a CPU the
all-pairs sum at ~5 ns a pair on 2 cores (engine.CPU_SECONDS_PER_PAIR, scaled by the cores here),
on a GPU the H100's rates (other GPUs differ by their arithmetic throughput).
"""

from __future__ import annotations

import math
import os

from .engine import cpu_step_seconds
from .params import G_CGS

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


def step_seconds(n: int, gravity: str, device: str, gravity_every: int = 1) -> float:
    """About how long one step of ``n`` particles takes on ``device`` [s], with gravity evaluated
    every ``gravity_every`` steps (the contacts every step)."""
    if not device.startswith("cuda"):
        step = cpu_step_seconds(n, gravity)
        if gravity_every > 1:  # the same cores' share as the pair sums (engine.cpu_step_seconds)
            step = step / gravity_every + CPU_CONTACT_SECONDS_PER_PARTICLE * n / (max(1, os.cpu_count() or 1) / 2.0)
        return step
    if gravity == "tree":
        step = max(GPU_STEP_FLOOR, GPU_TREE_SECONDS_PER_PARTICLE * n)
    else:
        size, rate = GPU_PAIRS_PER_S_AT
        rate = min(GPU_PAIRS_PER_S_MAX, rate * math.sqrt(n / size))
        step = max(GPU_STEP_FLOOR, float(n) * float(n) / rate)
    if gravity_every > 1:
        step = max(GPU_STEP_FLOOR, step / gravity_every + GPU_CONTACT_SECONDS_PER_PARTICLE * n)
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


def run_cost(n: int, gravity: str, device: str, steps: int, gravity_every: int = 1) -> str:
    """One line: the wall time of ``steps`` steps of ``n`` particles on ``device`` at ``gravity_every``
    (:func:`step_seconds`), and how it is made."""
    step = step_seconds(n, gravity, device, gravity_every)
    where = "an H100's rates" if device.startswith("cuda") else "this CPU"
    clock = f" at gravity every {gravity_every} steps" if gravity_every > 1 else ""
    return f"about {duration(step * steps)} on {device} ({1e3 * step:.3g} ms a step x {steps} steps{clock}; {where}, docs/benchmarks.md)"


#: Said once where a cost is made at gravity_every > 1: how the estimate is made, and how far to trust it.
GRAVITY_EVERY_NOTE = (
    "note: at gravity every K steps a step is estimated as the K = 1 step's gravity over K plus the contacts "
    "(measured whole runs: the default collision 7.9x as fast at K = 10 on a 2-core CPU, the paper's 2.0x to 3.1x on an H100); "
    "a collision whose contacts churn rebuilds its neighbour list more often and takes longer"
)


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
    step = step_seconds(n, gravity, device)
    return (f"settling takes {low} to {high} steps ({FORMATION_FREE_FALLS[0]:g} to {FORMATION_FREE_FALLS[1]:g} free-fall times of the seeding sphere): about "
            f"{duration(step * low)} to {duration(step * high)} on {device} ({1e3 * step:.3g} ms a step)")  # fmt: skip

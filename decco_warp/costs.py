"""What a job will cost before it starts: the time of a step on a device, of a run, of a formation.

Estimates for ``--check``, from measured rates (docs/benchmarks.md), not promises: on a CPU the
all-pairs sum at ~5 ns a pair on 2 cores (engine.CPU_SECONDS_PER_PAIR, scaled by the cores here),
on a GPU the H100's rates (other GPUs differ by their arithmetic throughput).
"""

from __future__ import annotations

import math

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


def step_seconds(n: int, gravity: str, device: str) -> float:
    """About how long one step of ``n`` particles takes on ``device`` [s]."""
    if not device.startswith("cuda"):
        return cpu_step_seconds(n, gravity)
    if gravity == "tree":
        return max(GPU_STEP_FLOOR, GPU_TREE_SECONDS_PER_PARTICLE * n)
    size, rate = GPU_PAIRS_PER_S_AT
    rate = min(GPU_PAIRS_PER_S_MAX, rate * math.sqrt(n / size))
    return max(GPU_STEP_FLOOR, float(n) * float(n) / rate)


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
    """One line: the wall time of ``steps`` steps of ``n`` particles on ``device``, and how it is made.
    Gravity on its own clock (``gravity_every`` > 1) is not modelled: the K = 1 estimate is given,
    with what whole runs measured."""
    step = step_seconds(n, gravity, device)
    where = "an H100's rates" if device.startswith("cuda") else "this CPU"
    line = f"about {duration(step * steps)} on {device} ({1e3 * step:.3g} ms a step x {steps} steps; {where}, docs/benchmarks.md)"
    if gravity_every > 1:
        line += (f"; the K = 1 rate: at gravity_every = {gravity_every} whole runs on an H100 stepped 1.8x to 2.3x as fast at "
                 "6 250 particles and 2.3x to 3.8x at 10 000 (K = 5 to 50), a CPU less")  # fmt: skip
    return line


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

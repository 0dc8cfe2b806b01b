"""The cluster finder on a ~100 000-particle debris frame (docs/benchmarks.md, "At a glance"):
8 remnants (the paper's 5 000 target at rest, 6 radii apart), 9 000 touching co-moving groups of 2
to 4 of its grains flying apart, and 30 000 single grains; 97 034 particles. Each try times
`find_clusters` with the sweeps' min_members = 50 and, apart, the smoothed density alone.

    python runs/results/debris_frame.py [DEVICE]     # cuda (the density on the GPU) or cpu; default cuda if present

On a CPU the density alone (all 9.4e9 pairs) takes minutes a try.
"""

from __future__ import annotations

import sys
import time

import numpy as np

import decco_warp as dw
from decco_warp.analysis import clusters as finder


def debris_frame(seed: int = 1) -> dw.State:
    rng = np.random.default_rng(seed)
    pile = dw.load_pile("runs/paper/piles/target5000.h5")
    size = float(np.linalg.norm(pile.positions - pile.centre_of_mass, axis=1).max())
    xs, vs, rs, ms = [], [], [], []
    for k in range(8):  # remnants at rest, far enough apart to be told apart by eye, not by gravity
        xs.append(pile.positions - pile.centre_of_mass + np.array([k * 6 * size, 0, 0]))
        vs.append(np.random.default_rng(k).normal(scale=1.0, size=(pile.n, 3)))
        rs.append(pile.radii)
        ms.append(pile.masses)
    cloud = 40 * size
    for _ in range(9000):  # short groups: each a seed that falls short of min_members
        members = rng.integers(2, 5)
        idx = rng.choice(pile.n, size=members, replace=False)
        r = pile.radii[idx]
        x = [rng.uniform(-cloud, cloud, 3) + np.array([0, 10 * size, 0])]
        for j in range(1, members):  # a chain of touching grains
            d = rng.normal(size=3)
            x.append(x[j - 1] + d / np.linalg.norm(d) * 0.995 * (r[j - 1] + r[j]))
        v0 = 1e-3 * x[0] + rng.normal(scale=3000.0, size=3)
        xs.append(np.array(x))
        vs.append(np.tile(v0, (members, 1)) + rng.normal(scale=1.0, size=(members, 3)))
        rs.append(r)
        ms.append(pile.masses[idx])
    idx = rng.choice(pile.n, size=30000)
    x = rng.uniform(-cloud, cloud, (30000, 3)) + np.array([0, -10 * size, 0])
    xs.append(x)
    vs.append(1e-3 * x + rng.normal(scale=3000.0, size=x.shape))
    rs.append(pile.radii[idx])
    ms.append(pile.masses[idx])
    x, v = np.concatenate(xs), np.concatenate(vs)
    return dw.State.from_arrays(x, v, np.zeros_like(x), np.concatenate(rs), np.concatenate(ms))


if __name__ == "__main__":
    import warp as wp

    device = sys.argv[1] if len(sys.argv) > 1 else ("cuda" if wp.get_cuda_device_count() else "cpu")
    state = debris_frame()
    print(f"{state.n} particles on {device}")
    for attempt in range(3):  # the first pays Warp's module load
        start = time.perf_counter()
        finder.smoothed_density(state.positions, state.masses, finder.SMOOTHING_RADII * state.radii, device=device)
        density = time.perf_counter() - start
        start = time.perf_counter()
        clusters = finder.find_clusters(state, 50, device=device)
        print(f"try {attempt}: find_clusters {time.perf_counter() - start:.2f} s (the density alone {density:.2f} s); "
              f"{len(clusters)} cluster(s) of {[c.members.size for c in clusters]} particles")

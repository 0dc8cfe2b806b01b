"""The neighbour list's build (gravity on its own clock) at the Fig. 8 impact, by particle and by
cell (contact_finders.NeighbourList.scan): the same lists, and how long a build of each takes.

    python runs/results/list_build.py [DEVICE] [STEPS]    # default cuda, 5 000 steps at K = 10 first

The paper's 1/4 collision at eta 3, 22 deg (6 250 particles) is stepped to the impact, then each
build of every system's lists is replayed TRIES times in a recorded graph (CUDA) and timed as a
whole; the radix sort and the cell tables' memsets are in both.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import warp as wp

import decco_warp as dw
from decco_warp import contact_finders

TRIES = 100


def main() -> None:
    device = sys.argv[1] if len(sys.argv) > 1 else ("cuda" if wp.get_cuda_device_count() else "cpu")
    steps = int(sys.argv[2]) if len(sys.argv) > 2 else 5000
    target, projectile = dw.load_pile("runs/paper/piles/target5000.h5"), dw.load_pile("runs/paper/piles/proj1250.h5")
    state = dw.setup_collision(target, projectile, eta=3.0, theta_deg=22.0, gap=0.0)
    lists = {}
    for scan in ("by particle", "by cell"):
        contact_finders.NeighbourList.scan = scan
        sim = dw.Simulation(state, dw.Params(), device=device, allow_unstable=True, scheme=dw.Scheme(gravity_every=10))
        sim.step(steps)
        sim.finish()
        finder, arrays = sim.engine.path.finder, sim.engine.state
        finder.build(arrays, everything=True)
        wp.synchronize_device(device)
        graph = None
        if device.startswith("cuda"):
            with wp.ScopedCapture(device=device) as capture:
                for _ in range(TRIES):
                    finder.build(arrays, everything=True)
            graph = capture.graph
        start = time.perf_counter()
        if graph is not None:
            wp.capture_launch(graph)
        else:
            for _ in range(TRIES):
                finder.build(arrays, everything=True)
        wp.synchronize_device(device)
        seconds = (time.perf_counter() - start) / TRIES
        count = finder.candidate_count.numpy()
        lists[scan] = (sim.state.positions, count, finder.candidates.numpy())
        print(f"{scan}: {seconds * 1e6:.1f} us a build on {device} ({state.n} particles after {steps} steps; lists of {count.mean():.2f}, at most {count.max()})")
    (x0, c0, l0), (x1, c1, l1) = lists.values()
    print("same positions", np.array_equal(x0, x1), "same lists", np.array_equal(c0, c1) and np.array_equal(l0, l1))


if __name__ == "__main__":
    main()

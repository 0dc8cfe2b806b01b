"""What a step of gravity on its own clock costs, stage by stage, at the impact of the README's run.

    python runs/results/step_stages.py [DEVICE] [RESOLUTION]    # default cuda, 1 (the README's run)

The README's paper run (1/4 at eta 3, 22 deg, gravity_every = "auto") is set up with the run's own
plan (RESOLUTION 4: 25 000 particles from runs/paper/piles/*_x4.h5, contacts scaled as the ladder
does) and stepped to 200 s, the impact.  Each stage of the step is then recorded REPS times in a row
into a CUDA graph and replayed (on a CPU launched REPS times), and its time a launch is the median of
five replays: the inner kick-drift (with the neighbour list's displacement check), the list's refresh
when nothing is stale (a conditional graph node), a build of the lists, the contact pass, gravity,
the outer kick, and the whole step (``advance`` of one outer step, over K).  The stages' sum differs
from the whole by what a graph of them overlaps.  Nothing is written into runs/.
"""

from __future__ import annotations

import statistics
import time

import warp as wp

from readme_run import arguments, readme_run

REPS = 100


def per_launch(device: str, launch, reps: int = REPS) -> float:
    """Seconds a launch of ``launch()``: REPS in a recorded graph (CUDA) or in a row, the median of five."""
    launch()  # first call apart: a module's load
    wp.synchronize_device(device)
    graph = None
    if device.startswith("cuda"):
        with wp.ScopedCapture(device=device) as capture:
            for _ in range(reps):
                launch()
        graph = capture.graph
    times = []
    for _ in range(5):
        wp.synchronize_device(device)
        began = time.perf_counter()
        if graph is not None:
            wp.capture_launch(graph)
        else:
            for _ in range(reps):
                launch()
        wp.synchronize_device(device)
        times.append(time.perf_counter() - began)
    return statistics.median(times) / reps


def main() -> None:
    device, resolution = arguments()
    with readme_run("step_stages", device, resolution) as (prepared, _):
        sim = prepared.sim
        engine = sim.engine
        every = sim.step_multiple
        if engine.integrator.clocks < 2:
            raise SystemExit("step_stages times gravity on its own clock: gravity_every = 'auto' gave K = 1")
        steps = round(200.0 / sim.params.dt / every) * every
        builds = sim.neighbour_list_builds() or 0
        sim.step(steps)
        sim.finish()
        builds = (sim.neighbour_list_builds() or 0) - builds
        integrator, path, state = engine.integrator, engine.path, engine.state
        finder = path.finder

        def nothing_stale():
            finder.stale.zero_()
            finder.stale_system.zero_()

        print(f"{sim.static.n} particles on {device} ({wp.get_device(device).name}), warp {wp.__version__}, "
              f"gravity every {every} steps, dt {sim.params.dt:g} s; {steps} steps to t = 200 s, {builds} list builds "
              f"(every {steps / max(builds, 1):.0f} steps)")  # fmt: skip
        kept = [wp.clone(getattr(state, name)) for name in ("position", "velocity", "omega")]

        def restore():  # the stages that move the particles leave them where the impact had them
            for name, values in zip(("position", "velocity", "omega"), kept):
                wp.copy(getattr(state, name), values)

        stages = {}
        stages["kick-drift (inner, displacement check)"] = per_launch(device, lambda: integrator.kick_drift_inner(close_step=True))
        restore()
        nothing_stale()
        stages["list refresh, nothing stale"] = per_launch(device, lambda: finder.refresh(state))
        stages["list build"] = per_launch(device, lambda: finder.build(state, everything=True), reps=20)
        stages["contact pass"] = per_launch(device, lambda: path.contact_pass.launch(state, finder))
        stages["gravity"] = per_launch(device, path.gravity_step, reps=20)
        stages["outer kick"] = per_launch(device, integrator.kick_outer, reps=20)
        restore()
        nothing_stale()
        whole = per_launch(device, lambda: integrator.advance(every), reps=max(1, REPS // every)) / every
        for name, seconds in stages.items():
            print(f"  {name:40s} {1e6 * seconds:9.1f} us")
        inner = sum(stages[k] for k in ("kick-drift (inner, displacement check)", "list refresh, nothing stale", "contact pass"))
        builds_share = stages["list build"] * builds / steps  # a step's share of the builds, as often as stepping made them
        gravity_share = (stages["gravity"] + stages["outer kick"]) / every
        print(f"  {'a step: inner stages, builds and gravity shared':40s} {1e6 * (inner + builds_share + gravity_share):9.1f} us "
              f"(builds {1e6 * builds_share:.1f}, gravity and outer kick {1e6 * gravity_share:.1f})")  # fmt: skip
        print(f"  {'a step, advance of an outer step / K':40s} {1e6 * whole:9.1f} us (its builds as they come)")


if __name__ == "__main__":
    main()

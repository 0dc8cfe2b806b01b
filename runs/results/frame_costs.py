"""What a frame and a checkpoint cost a run, part by part, on one device: the time a run spends
outside stepping (run.log's "observables" and "checkpoints"), taken apart with the run's own calls.

    python runs/results/frame_costs.py [DEVICE] [RESOLUTION]    # default cuda, 1 (the README's run)

The README's paper run (1/4 at eta 3, 22 deg, gravity_every = "auto") is set up with the run's own
plan (RESOLUTION 4: 25 000 particles from runs/paper/piles/*_x4.h5, contacts scaled as the ladder
does), stepped 2 000 steps, and each part of run.py's frame (``record`` and what ``after_steps`` adds)
and of a checkpoint is timed REPS times in a row; every device read is a copy to the host, so each
part's time includes the wait for it.  Nothing is written into runs/: the trajectory and checkpoint
go to a temporary folder.  Each line is the median of REPS calls in milliseconds.
"""

from __future__ import annotations

import statistics
import time

from decco_warp.diagnostics import energy_ledger, state_diagnostics, stress_share_observables
from decco_warp.io import Trajectory, write_checkpoint
from decco_warp.run import RunLog, check_sanity, record
from readme_run import arguments, readme_run

REPS = 20


def timed(name: str, call, reps: int = REPS):
    call()  # first call apart: allocations, a module's load
    times = []
    for _ in range(reps):
        began = time.perf_counter()
        result = call()
        times.append(time.perf_counter() - began)
    print(f"  {name:48s} {1e3 * statistics.median(times):9.3f} ms", flush=True)
    return result


def main() -> None:
    device, resolution = arguments()
    began = time.perf_counter()
    with readme_run("frame_costs", device, resolution) as (prepared, scratch):
        sim = prepared.sim
        print(f"{sim.static.n} particles on {device}, gravity every {sim.step_multiple} steps; set-up {time.perf_counter() - began:.2f} s")
        sim.step(2000 // sim.step_multiple * sim.step_multiple)
        sim.finish()
        size_classes = prepared.record.size_classes
        print("a frame (run.py record and after_steps), part by part:")
        state = timed("sim.state: positions, velocities, omegas", lambda: sim.state)
        pairs = timed("sim.pair_observables: all pairs in float64", sim.pair_observables)
        work = timed("sim.work", sim.work)
        timed("sim.take_deepest_contact", sim.take_deepest_contact)
        timed("sim.candidate_overflows", sim.candidate_overflows)
        diagnostics = timed("state_diagnostics (host)", lambda: state_diagnostics(state, pairs))
        timed("energy_ledger (host)", lambda: energy_ledger(diagnostics, sim.energy_start, work))
        timed("stress_share_observables (host)", lambda: stress_share_observables(pairs["max_overlap"], state.radii, state.size_class, size_classes))
        particles, observables = timed("record, the whole", lambda: record(sim, size_classes))
        timed("check_sanity (host)", lambda: check_sanity(1, particles))
        trajectory = Trajectory.create(scratch / "trajectory.h5", state, observables, {"frame_costs": 1})
        step = [0]

        def write():
            step[0] += 1
            trajectory.write(step[0], float(step[0]), particles, observables)

        timed("Trajectory.write (h5py; on the writer thread in a run)", write)
        trajectory.close()
        log = RunLog(scratch / "run.log")
        timed("a run.log line (flushed)", lambda: log("frame: step 1, t 1 s, E 1 erg"))
        print("a checkpoint:")
        snapshot = timed("sim.snapshot: every array the next step needs", sim.snapshot)
        timed("write_checkpoint (atomic, fsync'd)", lambda: write_checkpoint(scratch / "checkpoint.h5", snapshot, sim.static, prepared.record.as_checkpoint()), reps=10)


if __name__ == "__main__":
    main()

"""A job's memory and time, estimated before it starts: refused past the device's free memory
(exit 2), a line when it would take hours on the CPU."""

import numpy as np
import pytest
import warp as wp
from typer.testing import CliRunner

import decco_warp as dw
from decco_warp import costs
from decco_warp.cli import EXIT_INPUT, app
from decco_warp.run import builtin_pile


def _array_bytes(holder) -> int:
    """Bytes of the Warp arrays an object holds, as its attributes or through the objects and
    Warp structs it holds (the engine's force path, its gravity tree and the tree's nodes)."""
    arrays, seen = {}, set()

    def visit(thing):
        if id(thing) in seen:
            return
        seen.add(id(thing))
        for name in dir(thing):
            if name.startswith("__"):
                continue
            value = getattr(thing, name, None)
            if isinstance(value, wp.array):
                arrays[id(value)] = value
            elif any(kind.__module__.startswith("decco_warp") for kind in type(value).__mro__):
                visit(value)

    visit(holder)
    return sum(a.capacity for a in arrays.values())


@pytest.mark.parametrize("gravity", ["all-pairs", "tree"])
def test_the_memory_estimate_bounds_the_engines_arrays(gravity):
    pile = dw.load_pile(builtin_pile("target"))
    sim = dw.Simulation(pile, dw.Params(), device="cpu", ledger=True, scheme=dw.Scheme(gravity=gravity))
    engine = sim.engine
    held = _array_bytes(engine)
    device_part = costs.memory_estimate(pile.n, dw.Scheme(gravity=gravity)) - costs.FIXED_BYTES - pile.n * costs.HOST_BYTES_PER_PARTICLE
    # An upper estimate (the largest layout), but not a loose one: within a factor of 3.
    assert held <= device_part <= 3 * held, (held, device_part)


def test_the_memory_estimate_counts_the_contact_history_of_the_law_with_springs():
    pile = dw.load_pile(builtin_pile("target"))
    sim = dw.Simulation(pile, dw.Params(contact_law="ssdem"), device="cpu", ledger=True)
    held = _array_bytes(sim.engine)
    width = sim.engine.candidate_width
    device_part = costs.memory_estimate(pile.n, dw.Scheme(), candidate_width=width, contact_history=True)
    device_part -= costs.FIXED_BYTES + pile.n * costs.HOST_BYTES_PER_PARTICLE
    history = _array_bytes(sim.engine.state.history)
    assert history > 0.5 * held  # the history's rows are most of the engine here
    assert held <= device_part <= 3 * held, (held, device_part)


def test_the_memory_estimate_counts_the_newton_sweeps_rows_where_gravity_takes_it():
    """Gravity on its own clock sums all-pairs gravity with the Newton sweep on every device, whose
    rows grow as N^2 / tile (the CPU's tiles of 4): the estimate bounds what the engine holds, and
    the rows dominate it at a few thousand particles."""
    from scenes import overlapping_cloud

    state = overlapping_cloud(2000, seed=3)
    held = {}
    for every in (1, 10):
        sim = dw.Simulation(state, dw.Params(), device="cpu", ledger=True, scheme=dw.Scheme(gravity_every=every))
        held[every] = _array_bytes(sim.engine)
        estimate = costs.memory_estimate(state.n, dw.Scheme(gravity_every=every)) - costs.FIXED_BYTES
        estimate -= state.n * costs.HOST_BYTES_PER_PARTICLE
        assert held[every] <= estimate <= 3 * held[every], (every, held[every], estimate)
    rows = 2000**2 // 4 * 12  # a float32 vec3 per particle of a tile, for each of the (N / 4)^2 rows
    assert held[10] - held[1] > 0.9 * rows


def test_an_all_pairs_run_whose_newton_rows_do_not_fit_is_refused_before_it_starts(monkeypatch):
    """100 000 particles at gravity_every = 10 on a CPU hold ~30 GiB of Newton rows: a machine with
    less is told so and pointed to the tree, instead of the kernel killing the run."""
    import decco_warp.device as devices

    from decco_warp.errors import InputError

    monkeypatch.setattr(devices, "free_memory", lambda device: 16 << 30)
    assert costs.check_fits(100_000, dw.Scheme(gravity="tree", gravity_every=10), "cpu", 1_000_000, "a run").startswith("note: a run")  # days, but it fits
    assert costs.check_fits(2_000, dw.Scheme(gravity_every=10), "cpu", 10, "a run") is None
    with pytest.raises(InputError, match=r"a run of 100000 particles needs about \d+(\.\d+)? GiB on cpu, which has 16 GiB free; .*gravity = \"tree\""):
        costs.check_fits(100_000, dw.Scheme(gravity_every=10), "cpu", 10, "a run")
    assert costs.memory_estimate(100_000, dw.Scheme(gravity_every=10), "cpu") > 25 * 2**30
    assert costs.memory_estimate(100_000, dw.Scheme(), "cpu") < 1 * 2**30  # the CPU's fused layout keeps no rows


def test_the_cpu_time_estimate_follows_the_benchmarks_two_core_steps(monkeypatch):
    monkeypatch.setattr(costs.os, "cpu_count", lambda: 2)
    # docs/benchmarks.md, 2-core CPU: all-pairs 8 000: 308 to 341 ms; tree (piles) 8 000: 60.6 ms.
    assert 0.25 < costs.cpu_step_seconds(8000, "all-pairs") < 0.4
    assert 0.05 < costs.cpu_step_seconds(8000, "tree") < 0.075
    assert costs.cpu_step_seconds(16000, "all-pairs") == pytest.approx(4 * costs.cpu_step_seconds(8000, "all-pairs"))


def test_a_job_too_large_for_the_device_is_refused_with_the_estimate_and_the_free_memory(tmp_path, monkeypatch):
    import decco_warp.device as devices

    monkeypatch.setattr(devices, "free_memory", lambda device: 300 << 20)  # 300 MiB
    need = costs.memory_estimate(200_000, dw.Scheme(gravity="tree")) / 2**30
    result = CliRunner().invoke(app, ["pile", "--particles", "200000", "--out", str(tmp_path / "p.h5"), "--device", "cpu"])
    assert result.exit_code == EXIT_INPUT, result.stderr
    line = result.stderr.strip().splitlines()[-1]
    assert f"needs about {need:.3g} GiB on cpu, which has 0.293 GiB free" in line, line
    run = CliRunner().invoke(app, ["simulate", "--out", str(tmp_path), "--name", "big", "--steps", "10", "--device", "cpu"])
    assert run.exit_code == 0, run.stderr  # the demo's 450 particles fit
    monkeypatch.setattr(devices, "free_memory", lambda device: 1 << 20)
    refused = CliRunner().invoke(app, ["simulate", "--out", str(tmp_path), "--name", "small", "--steps", "10", "--device", "cpu"])
    assert refused.exit_code == EXIT_INPUT and "a run of 450 particles needs about" in refused.stderr, refused.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big"]


def test_the_cpu_s_free_memory_counts_the_file_cache_the_kernel_can_drop(monkeypatch):
    """On the CPU a job is held to the host's available memory (MemAvailable), not to its free pages
    alone: a machine whose file cache fills its memory (after a pip install, say) has a few hundred
    MB free and gigabytes available, and the shipped demo must not be refused there."""
    import collections

    import psutil

    import decco_warp.device as devices

    memory = collections.namedtuple("svmem", "total available free")
    monkeypatch.setattr(psutil, "virtual_memory", lambda: memory(24 << 30, 23 << 30, 240 << 20))
    assert devices.free_memory("cpu") == 23 << 30
    assert costs.check_fits(450, dw.Scheme(), "cpu", 100, "a run") is None


def test_a_job_of_hours_on_the_cpu_says_so_and_goes_on(tmp_path, monkeypatch):
    note = costs.check_fits(50_000, dw.Scheme(gravity="tree"), "cpu", 150_000, "forming a pile")
    hours = 150_000 * costs.cpu_step_seconds(50_000, "tree") / 3600
    assert note.startswith("note: forming a pile of 50000 particles (tree gravity) will take about") and hours > 1
    assert costs.check_fits(450, dw.Scheme(), "cpu", 2400, "a run") is None  # the demo: seconds
    monkeypatch.setattr(costs, "LONG_ON_CPU", 0.0)  # every CPU job counts as long: the line, then the work
    result = CliRunner().invoke(
        app, ["pile", "--particles", "12", "--seed", "9", "--dt", "0.2", "--ke-threshold", "1e-4", "--out", str(tmp_path / "p.h5"), "--device", "cpu"]
    )
    assert result.exit_code == 0, result.stderr
    assert "note: forming a pile of 12 particles (all-pairs gravity) will take about" in result.stderr
    assert np.isfinite(dw.load_pile(tmp_path / "p.h5").positions).all()

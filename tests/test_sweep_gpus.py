"""A sweep on a machine of several GPUs, checked on the CPU with mocked GPUs: local workers pinned
to distinct devices, the --gpus checks, `decco-warp info`'s list of GPUs, each analysis on the GPU
that stepped its run, ensembles packed for a scheduler's workers and cut to their device's memory.  (A sweep
stopped part-way and resumed: tests/test_sweep.py::test_a_stopped_sweep_keeps_its_table_and_continues.)"""

import pytest
from typer.testing import CliRunner

from decco_warp import device, sweep
from decco_warp.cli import app

pytest.importorskip("distributed")

SWEEP = """
[sweep]
name = "grid"
out = "{out}"
[sweep.grid]
"collision.eta" = [0.5, 1.0]
[run]
steps = 20
"""


@pytest.fixture
def three_gpus(monkeypatch):
    """Warp sees 3 GPUs (only their count: nothing here starts CUDA)."""
    monkeypatch.setattr(device, "cuda_device_count", lambda: 3)
    monkeypatch.delenv(device.ENV_VARIABLE, raising=False)


def test_local_workers_are_pinned_to_distinct_gpus(three_gpus):
    """By default one worker per visible GPU, worker k on cuda:k, as each worker's own task sees it."""
    from distributed import Client

    gpus = device.gpus_to_use()
    assert gpus == 3 and device.gpus_to_use(2) == 2
    with sweep.local_cluster(gpus, gpus) as cluster, Client(cluster) as client:
        workers = client.scheduler_info()["workers"]
        seen = {info["name"]: client.submit(sweep._worker_device, workers=[address], pure=False) for address, info in workers.items()}
        assert {name: future.result() for name, future in seen.items()} == {0: "cuda:0", 1: "cuda:1", 2: "cuda:2"}


def test_a_remote_worker_keeps_its_own_device(monkeypatch, tmp_path):
    """A worker started by someone else (dask-jobqueue, by hand) runs where its environment says,
    with a Warp kernel cache of its own named after it."""
    import distributed
    import warp as wp

    class Worker:
        name = "SLURMCluster-3-0"

    monkeypatch.setattr(distributed, "get_worker", lambda: Worker())
    monkeypatch.setattr(wp.config, "kernel_cache_dir", None)
    monkeypatch.setenv("DECCO_CACHE", str(tmp_path))
    monkeypatch.delenv(device.ENV_VARIABLE, raising=False)
    assert sweep._worker_device() is None  # the run's own choice: its spec, else the first GPU, else the CPU
    assert wp.config.kernel_cache_dir == str(tmp_path / "warp-worker-SLURMCluster-3-0")
    monkeypatch.setenv(device.ENV_VARIABLE, "cuda:5")
    assert sweep._worker_device() == "cuda:5"


@pytest.mark.parametrize(
    "args, gpus, message",
    [
        (["--gpus", "0"], 3, "--gpus 0: must be >= 1"),
        (["--gpus", "4"], 3, "--gpus 4: only 3 GPU(s) visible here, cuda:0 to cuda:2"),
        (["--gpus", "1"], 0, "--gpus 1: Warp finds no GPU here; leave --gpus out to run on CPU workers"),
        (["--gpus", "2", "--scheduler", "tcp://127.0.0.1:1"], 3, "with --scheduler each worker uses its own device"),
    ],
)
def test_bad_gpus_are_one_line_exit_2_before_anything_is_written(monkeypatch, tmp_path, args, gpus, message):
    monkeypatch.setattr(device, "cuda_device_count", lambda: gpus)
    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path / "out"))
    result = CliRunner().invoke(app, ["sweep", str(path), *args])
    assert result.exit_code == 2 and message in result.stderr and result.stderr.count("\n") == 1, result.stderr
    assert not (tmp_path / "out").exists()


def test_info_lists_every_gpu_with_its_memory(three_gpus, monkeypatch):
    devices = [{"name": "cpu", "description": "x86_64", "is_cuda": False, "memory": None}]
    devices += [{"name": f"cuda:{k}", "description": "NVIDIA H200", "is_cuda": True, "memory": 141 * 2**30} for k in range(3)]
    monkeypatch.setattr(device, "describe_devices", lambda: devices)
    lines = CliRunner().invoke(app, ["info"]).stdout.splitlines()
    assert [line.split()[:2] for line in lines if "NVIDIA H200" in line] == [["*", "cuda:0"], ["cuda:1", "NVIDIA"], ["cuda:2", "NVIDIA"]]
    assert sum("141.0 GiB" in line for line in lines) == 3
    assert "would use: cuda:0" in lines and any("3 worker(s), one per GPU, cuda:0 to cuda:2" in line for line in lines)


# --- analysis, ensembles and memory from the workers' devices -------------------------------------

GPUS = {"GPU-aaa": "cuda:0", "GPU-bbb": "cuda:1", "GPU-ccc": "cuda:2"}


def test_each_analysis_goes_to_the_gpu_that_stepped_its_run_in_a_pool_of_its_own(monkeypatch):
    """A paper-size run is analysed on the GPU that stepped it (named by UUID, whatever the worker
    called it), a small one on the CPU, one stepped on another host's GPU on this machine's in turn,
    and all on the CPU where this machine has no GPU; each device has its own pool of processes."""
    assert sweep.analysis_device({"device_uuid": "GPU-bbb", "n_particles": 6250}, GPUS) == "cuda:1"
    assert sweep.analysis_device({"device_uuid": "GPU-bbb", "n_particles": 450}, GPUS) == "cpu"
    assert [sweep.analysis_device({"device_uuid": "GPU-elsewhere", "n_particles": 6250}, GPUS, turn) for turn in range(4)] == [
        "cuda:0", "cuda:1", "cuda:2", "cuda:0"
    ]  # fmt: skip
    assert sweep.analysis_device({"device_uuid": None}, GPUS, 1) == "cuda:1"  # stepped on a CPU worker, size unknown
    assert sweep.analysis_device({"device_uuid": "GPU-bbb", "n_particles": 6250}, {}) == "cpu"

    pools = []

    class Pool:
        def __init__(self, max_workers, mp_context, initializer):
            self.size, self.calls = max_workers, []
            pools.append(self)

        def submit(self, function, *args):
            self.calls.append(args)
            return args

    monkeypatch.setattr(sweep, "ProcessPoolExecutor", Pool)
    analyses = sweep.Analyses(16, GPUS)
    settings = {"min_members": 50, "analyze_every": 5, "keep_trajectory": False}
    rows = [{"run_dir": f"r{k}", "device_uuid": uuid, "n_particles": n}
            for k, (uuid, n) in enumerate([("GPU-ccc", 6250), ("GPU-aaa", 10_000), ("GPU-ccc", 5500), ("GPU-aaa", 450)])]  # fmt: skip
    assert [analyses.submit(row, settings)[-1] for row in rows] == ["cuda:2", "cuda:0", "cuda:2", "cpu"]
    assert {device: (pool.size, [call[0] for call in pool.calls]) for device, pool in analyses.pools.items()} == {
        "cuda:2": (6, ["r0", "r2"]), "cuda:0": (6, ["r1"]), "cpu": (16, ["r3"])
    }  # fmt: skip


class FakeClient:
    """A client of a scheduler whose workers report their devices (sweep.worker_device's dicts)."""

    def __init__(self, devices):
        self.devices = devices

    def scheduler_info(self):
        return {"workers": dict.fromkeys(self.devices, {})}

    def run(self, function):
        assert function is sweep.worker_device
        return self.devices


def test_with_a_scheduler_ensembles_are_packed_for_the_workers_gpus_not_this_machines(monkeypatch):
    """This machine (a login node) has no GPU; the scheduler's workers have two and a CPU: the sweep
    packs its ensembles as for two GPU workers among three."""
    monkeypatch.setattr(device, "cuda_device_count", lambda: 0)
    workers = {"tcp://a:1": {"device": "cuda:0", "uuid": "GPU-aaa", "problem": None},
               "tcp://b:1": {"device": "cuda:0", "uuid": "GPU-bbb", "problem": None},
               "tcp://c:1": {"device": "cpu", "uuid": None, "problem": None}}  # fmt: skip
    monkeypatch.setattr(sweep, "connect", lambda address: FakeClient(workers))
    client, cluster, gpus, simulating = sweep._workers_for("tcp://s:8786", None, None, print)
    assert cluster is None and (gpus, simulating) == (2, 3)
    assert sweep.ensemble_plan("auto", gpus, runs=32, workers=simulating) == (8, sweep.ENSEMBLE_MAX_PARTICLES)
    assert sweep.ensemble_plan("auto", device.cuda_device_count(), runs=32, workers=simulating) == (1, None)  # as it was counted before


def test_a_worker_reports_its_device_and_a_gpu_it_does_not_have(monkeypatch, tmp_path):
    class Worker:
        name = "gpu-node-7"

    monkeypatch.setenv("DECCO_CACHE", str(tmp_path))
    monkeypatch.setenv(device.ENV_VARIABLE, "cpu")
    assert sweep.worker_device(Worker()) == {"device": "cpu", "uuid": None, "problem": None}
    monkeypatch.setenv(device.ENV_VARIABLE, "cuda:5")
    monkeypatch.setattr(device, "cuda_device_count", lambda: 2)
    report = sweep.worker_device(Worker())
    assert report["uuid"] is None and "only 2 CUDA device(s)" in report["problem"], report


def _stand_in(n):
    """A prepared run as fit_in_memory reads it: its plan (size, force path, device)."""
    from types import SimpleNamespace

    import numpy as np

    from decco_warp.layouts import choose_layout
    from decco_warp.params import Params
    from decco_warp.scheme import Scheme

    state = SimpleNamespace(n=n, radii=np.array([7.5e5, 2.25e6]))
    scheme = Scheme(layout=choose_layout(n, "cuda:0"))
    return SimpleNamespace(plan=SimpleNamespace(state=state, params=Params(), scheme=scheme, device="cuda:0"))


def test_an_ensemble_is_cut_where_its_device_cannot_hold_it_whole(monkeypatch):
    """Each run fits alone; joined, an ensemble needs its members' memory again (less Warp's fixed
    part, counted once): three of 20 000 particles go together, two and one, or one at a time, as
    the GPU's free memory allows."""
    from decco_warp.costs import FIXED_BYTES
    from decco_warp.run import plan_memory

    prepared = [_stand_in(20_000) for _ in range(3)]
    one = plan_memory(prepared[0].plan)
    joined = [one + (k - 1) * (one - FIXED_BYTES) for k in (1, 2, 3)]  # what 1, 2 and 3 joined need
    assert joined[2] > joined[1] > joined[0] > FIXED_BYTES
    for free, groups in [(joined[2], [[0, 1, 2]]), (joined[2] - 1, [[0, 1], [2]]), (joined[1] - 1, [[0], [1], [2]])]:
        monkeypatch.setattr(device, "free_memory", lambda name, free=free: free)
        assert sweep.fit_in_memory([0, 1, 2], prepared) == groups, free
    assert sweep.fit_in_memory([1], prepared) == [[1]]


def test_a_batch_whose_ensemble_does_not_fit_steps_its_runs_one_at_a_time(monkeypatch, tmp_path):
    """Two small runs that would step together, on a device (mocked: the CPU's free memory) that holds
    either alone but not both joined: each steps alone, both finish."""
    from decco_warp.plan import plan_start
    from decco_warp.run import plan_memory

    path = tmp_path / "s.toml"
    path.write_text(SWEEP.format(out=tmp_path / "out") + 'device = "cpu"\noutput_every = 10\n')
    runs = sweep.load_sweep(path)[1]
    one = plan_memory(plan_start(runs[0], "cpu"))
    monkeypatch.setattr(device, "free_memory", lambda name: one + 1)
    rows = sweep.simulate_batch(runs, max_particles=10**6)
    assert [(row["status"], row["ensemble"]) for row in rows] == [("ok", 1), ("ok", 1)], rows

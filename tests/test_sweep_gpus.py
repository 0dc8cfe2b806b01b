"""A sweep on a machine of several GPUs, checked on the CPU with a mocked GPU count: local workers
pinned to distinct devices, the --gpus checks, and `decco-warp info`'s list of GPUs.  (A sweep
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

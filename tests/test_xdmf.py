"""The XDMF sidecar: VTK's XDMF reader (ParaView's and VisIt's) reads a run's frames from trajectory.h5 in place."""

import subprocess
import sys
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from helpers import cli
from typer.testing import CliRunner

import decco_warp as dw
from decco_warp.cli import app
from decco_warp.io import Trajectory
from decco_warp.lock import RunFolderLock

STEPS = ["--steps", "30", "--output-every", "10", "--device", "cpu"]


def export(*args):
    """``decco-warp export`` in this process (no interpreter to start): typer's result, with stdout and stderr."""
    return CliRunner().invoke(app, ["export", *args])


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """The default collision (the shipped small piles), 30 steps, a frame every 10: 4 frames."""
    out = tmp_path_factory.mktemp("xdmf")
    result = cli("simulate", *STEPS, "--out", str(out))
    assert result.returncode == 0, result.stderr
    return out / "default"


def read_through_vtk(xdmf):
    """(times, [per frame: {"position": ..., point data name: ...}]) as VTK's XDMF reader gives them."""
    vtk_io = pytest.importorskip("vtkmodules.vtkIOXdmf2")
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline

    reader = vtk_io.vtkXdmfReader()
    reader.SetFileName(str(xdmf))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    frames = []
    for time in times:
        reader.UpdateTimeStep(time)
        grid = reader.GetOutputDataObject(0)
        assert grid.GetNumberOfCells() == grid.GetNumberOfPoints()  # one vertex per particle
        point_data = grid.GetPointData()
        frame = {point_data.GetArrayName(i): vtk_to_numpy(point_data.GetArray(i)).copy() for i in range(point_data.GetNumberOfArrays())}
        frame["position"] = vtk_to_numpy(grid.GetPoints().GetData()).copy()
        frames.append(frame)
    return np.array(times), frames


def assert_reads_back(xdmf, data):
    """Every frame the reader gives equals the trajectory's values, at the trajectory's times."""
    times, frames = read_through_vtk(xdmf)
    np.testing.assert_array_equal(times, data["time"])
    assert len(frames) == len(data["time"]) >= 3
    for k, frame in enumerate(frames):
        for name in ("position", "stress", "velocity", "omega"):
            np.testing.assert_array_equal(frame[name], data["particles"][name][k], err_msg=f"{name}, frame {k}")
        np.testing.assert_array_equal(frame["radius"], data["static"]["radius"])
        np.testing.assert_array_equal(frame["size_class"], data["static"]["species"])
        np.testing.assert_array_equal(frame["pile_id"], data["static"]["pile_id"])
    assert not np.array_equal(frames[0]["position"], frames[-1]["position"])  # each frame its own hyperslab


def test_a_run_ends_with_a_sidecar_that_vtk_reads_as_the_hdf5_frames(run_dir):
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    assert data["step"].tolist() == [0, 10, 20, 30]
    assert np.ptp(data["particles"]["stress"][-1]) > 0  # contacts: the stress read back is not all zeros
    assert_reads_back(run_dir / "trajectory.xdmf", data)


def test_export_writes_the_same_sidecar_and_refuses_a_folder_without_a_trajectory(run_dir, tmp_path):
    written = (run_dir / "trajectory.xdmf").read_text()
    (run_dir / "trajectory.xdmf").unlink()
    result = export(str(run_dir), "--xdmf")
    assert result.exit_code == 0, result.stderr
    assert "4 frame(s)" in result.stdout
    assert (run_dir / "trajectory.xdmf").read_text() == written
    # The sidecar points into trajectory.h5 and holds none of its numbers: its only inline items are hyperslab selections.
    items = list(ET.parse(run_dir / "trajectory.xdmf").iter("DataItem"))
    assert {(item.get("ItemType"), item.get("Format")) for item in items} == {("HyperSlab", None), (None, "XML"), (None, "HDF")}
    assert all(item.get("Dimensions").startswith("3 ") for item in items if item.get("Format") == "XML")
    assert all(item.text.startswith("trajectory.h5:/particles/all/") for item in items if item.get("Format") == "HDF")
    for args in ([str(tmp_path), "--xdmf"], [str(tmp_path / "absent"), "--xdmf"], [str(run_dir)]):
        refused = export(*args)
        assert refused.exit_code == 2 and refused.stderr.count("\n") == 1, (args, refused.stderr)


WRITER = """
import os, sys
import numpy as np
from decco_warp.io import Trajectory
from decco_warp.state import State

rng = np.random.default_rng(7)
n = 50
state = State.from_arrays(rng.normal(size=(n, 3)) * 1e6, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
                          np.full(n, 1e5), np.full(n, 1e15), pile_id=np.arange(n) % 2, size_class=np.arange(n) % 3)
trajectory = Trajectory.create(sys.argv[1], state, {"potential": 0.0}, {})
for k in range(3):
    particles = {"position": rng.normal(size=(n, 3)), "velocity": rng.normal(size=(n, 3)),
                 "omega": rng.normal(size=(n, 3)), "stress": rng.random(n)}
    trajectory.append(10 * k, 0.4 * k, particles, {"potential": -1.0})
# A fourth frame cut short: its position written, its step not (as by a kill in mid-write).
position = trajectory.file["particles/all/position"]
for name in ("step", "time", "value"):
    position[name].resize(4, axis=0)
position["value"][3] = 0.0
trajectory.file.flush()
os._exit(0)  # no close: the file keeps the flags of a writer, as a killed run's does
"""


def test_export_of_a_killed_or_running_run_covers_its_whole_frames(tmp_path):
    trajectory = tmp_path / "trajectory.h5"
    subprocess.run([sys.executable, "-c", WRITER, str(trajectory)], check=True)
    with RunFolderLock(tmp_path):  # a run still writing holds its folder
        result = export(str(tmp_path), "--xdmf")
    assert result.exit_code == 0, result.stderr
    assert "3 frame(s)" in result.stdout and "still going" in result.stdout
    grids = ET.parse(tmp_path / "trajectory.xdmf").find("Domain/Grid").findall("Grid")
    assert [float(grid.find("Time").get("Value")) for grid in grids] == [0.0, 0.4, 0.8]
    result = export(str(tmp_path / "trajectory.h5"), "--xdmf")  # killed: its writer's flags are cleared
    assert result.exit_code == 0 and "still going" not in result.stdout, result.stderr
    data = {**dw.read_trajectory(trajectory)}  # a plain dict of its fields, to cut
    for name in ("time", "step"):
        data[name] = data[name][:3]
    assert_reads_back(tmp_path / "trajectory.xdmf", {**data, "particles": {k: v[:3] for k, v in data["particles"].items()}})

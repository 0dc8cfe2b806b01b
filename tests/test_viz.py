"""rerun: live recordings and replays carry the particles and exactly the HDF5 observables."""

import subprocess
import sys
from collections import defaultdict

import numpy as np
import pytest
from helpers import cli

import decco_warp as dw

rerun = pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

STEPS = ["--steps", "300", "--output-every", "100"]




def read_recording(path):
    """{entity: {column: [values by row]}} of the temporal chunks, and the static entities' columns."""
    temporal = defaultdict(lambda: defaultdict(list))
    static = defaultdict(dict)
    for chunk in RrdReader(path).stream():
        batch = chunk.to_record_batch()
        names = [n for n in batch.schema.names if n not in ("rerun.controls.RowId", "log_time", "sim_time")]
        for name in names:
            values = batch.column(name).to_pylist()
            if chunk.is_static:
                static[str(chunk.entity_path)][name] = values
            else:
                temporal[str(chunk.entity_path)][name].extend(values)
    return temporal, static


def _series(temporal, entity):
    rows = temporal[entity]
    order = np.argsort(rows["step"])
    return np.array(rows["step"])[order], np.array([v[0] for v in rows["Scalars:scalars"]])[order]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    out = tmp_path_factory.mktemp("rr")
    result = cli("simulate", *STEPS, "--rerun", "save", "--out", str(out), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    run_dir = out / "default"
    outputs = next(line for line in result.stdout.splitlines() if line.startswith("outputs in"))
    assert ", recording.rrd (rerun's recording: " in outputs and (run_dir / "recording.rrd").is_file()  # listed with the run's outputs
    view = cli("view", str(run_dir), "--save", str(out / "replay.rrd"))
    assert view.returncode == 0, view.stderr
    return run_dir, out / "replay.rrd"


def test_live_recording_has_the_particles_and_the_hdf5_observables(recorded):
    run_dir, _ = recorded
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    temporal, static = read_recording(run_dir / "recording.rrd")
    radii = data["static"]["radius"]
    points = temporal["/particles/by_size"]
    assert sorted(points["step"]) == [0, 100, 200, 300]
    for positions, point_radii, classes in zip(points["Points3D:positions"], points["Points3D:radii"], points["Points3D:class_ids"]):
        assert len(positions) == len(radii)
        np.testing.assert_allclose(point_radii, radii / 1e5, rtol=1e-6)
        assert classes == data["static"]["species"].tolist()
    k = points["step"].index(300)
    np.testing.assert_allclose(points["Points3D:positions"][k], data["particles"]["position"][3] / 1e5, rtol=1e-6)
    assert len(temporal["/particles/by_stress"]["Points3D:colors"][0]) == len(radii)
    for name in ("kinetic_translational", "potential", "dissipated_sliding", "number_of_contacts", "max_overlap"):
        steps, values = _series(temporal, f"/observables/{name}")
        assert steps.tolist() == data["step"].tolist()
        np.testing.assert_array_equal(values, data["observables"][name].astype(float))
    for name in ("stress_share", "stress_share_per_area", "stress_share_strain"):
        for k in range(3):
            if np.isfinite(data["observables"][name][:, k]).all():
                steps, share = _series(temporal, f"/{name}/class_{k}")
                assert steps.tolist() == data["step"].tolist(), name
                np.testing.assert_array_equal(share, data["observables"][name][:, k], err_msg=name)
    assert "AnnotationContext:context" in static["/particles/by_size"]
    assert static["/observables/potential"]["SeriesLines:names"] == [["potential"]]
    assert set(temporal) >= {"/piles/target", "/piles/projectile/velocity", "/conservation/momentum_drift"}


def test_replay_is_equivalent_to_the_live_recording(recorded):
    run_dir, replay = recorded
    live, live_static = read_recording(run_dir / "recording.rrd")
    again, again_static = read_recording(replay)
    assert set(live) == set(again) and set(live_static) == set(again_static)
    for entity in live:
        for column in live[entity]:
            a, b = live[entity][column], again[entity][column]
            order_a, order_b = np.argsort(live[entity]["step"]), np.argsort(again[entity]["step"])
            assert [a[i] for i in order_a] == [b[i] for i in order_b], (entity, column)


def test_a_replay_of_a_trajectory_without_the_newer_stress_shares_computes_them(recorded, tmp_path):
    """`view` of a trajectory written before stress_share_per_area and stress_share_strain were
    recorded (deleted here) logs them from each frame's stress and radii: the live recording's series."""
    import shutil

    import h5py

    run_dir = tmp_path / "old"
    shutil.copytree(recorded[0], run_dir)
    with h5py.File(run_dir / "trajectory.h5", "r+") as f:
        del f["observables/stress_share_per_area"], f["observables/stress_share_strain"]
    result = cli("view", str(run_dir), "--save", str(tmp_path / "old.rrd"))
    assert result.returncode == 0, result.stderr
    old, _ = read_recording(tmp_path / "old.rrd")
    live, _ = read_recording(recorded[0] / "recording.rrd")
    data = dw.read_trajectory(recorded[0] / "trajectory.h5")
    for name in ("stress_share_per_area", "stress_share_strain"):
        for k in range(3):
            entity = f"/{name}/class_{k}"
            assert (entity in old) == (entity in live) == bool(np.isfinite(data["observables"][name][:, k]).all()), entity
            if entity in live:
                np.testing.assert_array_equal(_series(old, entity)[1], _series(live, entity)[1], err_msg=entity)


def test_rerun_is_not_imported_unless_asked(tmp_path):
    code = (
        "import sys\nfrom decco_warp.cli import app\n"
        f"try:\n    app(['simulate', '--steps', '20', '--output-every', '10', '--out', r'{tmp_path}', '--device', 'cpu'])\n"
        "except SystemExit:\n    pass\nprint('rerun imported:', 'rerun' in sys.modules)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert "rerun imported: False" in result.stdout, result.stderr


def test_missing_rerun_is_one_line_telling_how_to_install(tmp_path):
    fake = tmp_path / "fake"
    (fake / "rerun").mkdir(parents=True)
    (fake / "rerun" / "__init__.py").write_text("raise ImportError('no module named rerun')\n")
    import os

    env = dict(os.environ, PYTHONPATH=str(fake))
    result = cli("simulate", *STEPS, "--rerun", "save", "--out", str(tmp_path / "out"), "--device", "cpu", env=env)
    assert result.returncode == 2
    assert "pip install" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    bad = cli("simulate", *STEPS, "--rerun", "tv", "--out", str(tmp_path / "out2"), "--device", "cpu")
    assert bad.returncode == 2 and "spawn, save, connect[=ADDR], serve" in bad.stderr


def test_view_mode_save_writes_the_recording_into_the_run_folder(recorded, tmp_path):
    """`view RUN --mode save` (no --save path) writes RUN/recording.rrd, as the live `--rerun save` does."""
    import shutil

    run_dir = tmp_path / "run"
    shutil.copytree(recorded[0], run_dir)
    (run_dir / "recording.rrd").unlink()
    result = cli("view", str(run_dir), "--mode", "save")
    assert result.returncode == 0, result.stderr
    again, _ = read_recording(run_dir / "recording.rrd")
    live, _ = read_recording(recorded[0] / "recording.rrd")
    assert set(again) == set(live)


def test_a_movie_of_a_run_is_written_without_a_display(recorded, tmp_path, monkeypatch):
    """`decco-warp movie` draws every frame (or every Nth, the last always) into a file, without a
    display: an mp4 where ffmpeg is, else a GIF beside it with a note saying so; each movie frame
    is one of the run's, the last one titled with the run's last step."""
    from PIL import Image

    import decco_warp.analysis.movie as movies

    from helpers import cli_here

    run_dir, _ = recorded
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.setattr(movies, "ffmpeg_available", lambda: False)
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    result = cli_here("movie", str(run_dir), "--out", str(tmp_path / "run.mp4"), "--every", "2")
    assert result.returncode == 0, result.stderr
    assert "ffmpeg is not installed" in result.stderr and f"wrote {tmp_path / 'run.gif'}" in result.stdout
    assert not (tmp_path / "run.mp4").exists()
    with Image.open(tmp_path / "run.gif") as movie:
        assert movie.n_frames == len(range(0, data.step.size, 2)) + (0 if (data.step.size - 1) % 2 == 0 else 1)
    result = cli_here("movie", str(run_dir), "--out", str(tmp_path / "run.gif"))
    with Image.open(tmp_path / "run.gif") as movie:
        assert result.returncode == 0 and movie.n_frames == data.step.size and "note" not in result.stderr
    bad = cli_here("movie", str(run_dir), "--out", str(tmp_path / "run.avi"))
    assert bad.returncode == 2 and "written as .mp4 or .gif" in bad.stderr and not bad.stdout

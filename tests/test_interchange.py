"""A run handed to other codes: its frames as pkdgrav .ss files, and an analysed frame's fragments as
a REBOUND simulation, checked against the trajectory and the labels with float64 NumPy of our own."""

import math

import numpy as np
import pytest

import decco_warp as dw
from decco_warp.errors import InputError
from decco_warp.interchange import handoff_bodies, write_rebound
from decco_warp.ss import read_ss
from helpers import cli_here

M_SUN = 1.9891e33
AU = 1.49597870e13
YEAR_OVER_TWO_PI = 3.15581497632e7 / (2.0 * math.pi)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """The default collision, 100 steps (frames at 0, 50, 100), analysed with clusters of 200 grains
    or more: the target is a fragment, the projectile's 150 grains belong to none."""
    out = tmp_path_factory.mktemp("runs")
    result = cli_here("simulate", "--steps", "100", "--output-every", "50", "--out", str(out), "--device", "cpu")
    assert result.returncode == 0, result.stderr
    result = cli_here("analyze", str(out / "default"), "--min-members", "200", "--device", "cpu")
    assert result.returncode == 0, result.stderr
    return out / "default"


def test_frames_go_out_as_ss_in_pkdgrav_units(run_dir, tmp_path):
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    result = cli_here("export", str(run_dir), "--ss", str(tmp_path / "last.ss"))
    assert result.returncode == 0, result.stderr
    last = read_ss(tmp_path / "last.ss")
    assert last.time == pytest.approx(data.time[-1], rel=1e-15)
    np.testing.assert_allclose(last.position, data.particles["position"][-1], rtol=1e-15)
    np.testing.assert_allclose(last.velocity, data.particles["velocity"][-1], rtol=1e-15)
    np.testing.assert_allclose(last.spin, data.particles["omega"][-1], rtol=1e-15)
    np.testing.assert_array_equal(last.radius, data.static["radius"])
    assert last.color.tolist() == [3 if p == 0 else 12 for p in data.static["pile_id"]] and last.org_idx.tolist() == list(range(450))
    raw = (tmp_path / "last.ss").read_bytes()
    assert np.frombuffer(raw, ">f8", count=1, offset=16 + 16)[0] == pytest.approx(data.particles["position"][-1][0, 0] / AU, rel=1e-15)
    result = cli_here("export", str(run_dir), "--ss", str(tmp_path / "frames"), "--frame", "all", "--reduced")
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == [f"frame_{s:010d}.ss" for s in (0, 50, 100)]
    first = read_ss(tmp_path / "frames" / "frame_0000000000.ss")
    assert first.reduced and len((tmp_path / "frames" / "frame_0000000000.ss").read_bytes()) == 16 + 28 * 450
    np.testing.assert_allclose(first.position, data.particles["position"][0], rtol=2e-7)
    result = cli_here("export", str(run_dir), "--ss", str(tmp_path / "x.ss"), "--frame", "3")
    assert result.returncode == 2 and "has 3 frame(s), 0 to 2" in result.stderr and result.stderr.count("\n") == 1


def test_the_analysis_states_the_radii_of_its_size_classes(run_dir):
    """analysis.h5 /size_classes: per class the smallest and largest radius of its particles and their
    count, here the shipped piles' three sizes (258 + 129, 32 + 16, 10 + 5 grains)."""
    import h5py

    data = dw.read_trajectory(run_dir / "trajectory.h5")
    radius, species = data.static["radius"], data.static["species"]
    with h5py.File(run_dir / "analysis.h5", "r") as f:
        classes = {name: f["size_classes"][name][()] for name in ("radius_min", "radius_max", "count")}
        assert f["size_classes/radius_min"].attrs["unit"].startswith("cm")
    for k in range(3):
        assert classes["radius_min"][k] == radius[species == k].min() and classes["radius_max"][k] == radius[species == k].max()
    np.testing.assert_array_equal(classes["radius_min"], [0.75e6, 1.5e6, 2.25e6])
    assert classes["count"].tolist() == [387, 48, 15]


def _fragments_by_hand(run_dir):
    """The last frame's fragments from the trajectory and the analysis's labels, in float64: mass,
    centre of mass, velocity, and the radius of the sphere of the volume of the uniform ellipsoid
    with the fragment's mass and inertia tensor; then the grains of no fragment."""
    import h5py

    data = dw.read_trajectory(run_dir / "trajectory.h5")
    with h5py.File(run_dir / "analysis.h5", "r") as f:
        label = f["frames/label"][-1]
    x, v = data.particles["position"][-1], data.particles["velocity"][-1]
    m, r = data.static["mass"], data.static["radius"]
    bodies = []
    for k in range(label.max() + 1):
        mine = label == k
        mass = m[mine].sum()
        com = (m[mine, None] * x[mine]).sum(axis=0) / mass
        d = x[mine] - com
        inertia = sum(mk * (dk @ dk * np.eye(3) - np.outer(dk, dk)) + 0.4 * mk * rk**2 * np.eye(3) for mk, dk, rk in zip(m[mine], d, r[mine]))
        i1, i2, i3 = np.linalg.eigvalsh(inertia)
        semi = np.sqrt(5.0 / (2.0 * mass) * np.array([i2 + i3 - i1, i1 + i3 - i2, i1 + i2 - i3]))
        bodies.append((mass, com, (m[mine, None] * v[mine]).sum(axis=0) / mass, np.cbrt(semi.prod())))
    for i in np.flatnonzero(label < 0):
        bodies.append((m[i], x[i], v[i], r[i]))
    return data, bodies


#: What a user sees who opens the file: REBOUND in a fresh interpreter (in a process that has freed a
#: simulation with named particles, REBOUND 5.2 reads the names of a file's particles wrongly).
OPEN_IN_REBOUND = """
import json, sys
import rebound
sim = rebound.Simulation(sys.argv[1])
print(json.dumps({"N": sim.N, "G": sim.G, "t": sim.t, "units": sim.units, "energy": sim.energy(),
                  "particles": [[p.name, p.m, p.r, *p.xyz, *p.vxyz] for p in sim.particles]}))
"""


def test_an_analysed_frame_goes_to_rebound_as_fragments_and_loose_grains(run_dir, tmp_path):
    import json
    import subprocess
    import sys

    pytest.importorskip("rebound")
    data, want = _fragments_by_hand(run_dir)
    result = cli_here("export", str(run_dir), "--rebound", str(tmp_path / "fragments.bin"))
    assert result.returncode == 0, result.stderr
    assert "1 fragment(s) and 150 grain(s) of none" in result.stdout
    opened = subprocess.run([sys.executable, "-c", OPEN_IN_REBOUND, str(tmp_path / "fragments.bin")], capture_output=True, text=True)
    assert opened.returncode == 0, opened.stderr
    sim = json.loads(opened.stdout)
    assert sim["N"] == len(want) == 151
    assert sim["G"] == 6.6743e-8 and sim["t"] == data.time[-1]
    assert sim["units"] == {"length": "cm", "mass": "g", "time": "s"}
    names = [p[0] for p in sim["particles"]]
    assert names == ["fragment_0"] + [f"grain_{i}" for i in range(300, 450)]  # the target, then the projectile's grains
    for (_, m, r, *xv), (mass, x, v, radius) in zip(sim["particles"], want):
        assert m == pytest.approx(mass, rel=1e-12) and r == pytest.approx(radius, rel=1e-9)
        np.testing.assert_allclose(xv[:3], x, rtol=1e-12, atol=1e-3)
        np.testing.assert_allclose(xv[3:], v, rtol=1e-9, atol=1e-9)
    # Mass and momentum of the frame are all handed over; REBOUND's energy is that of point masses under the run's G.
    masses = np.array([w[0] for w in want])
    x = np.array([w[1] for w in want])
    v = np.array([w[2] for w in want])
    assert masses.sum() == pytest.approx(data.static["mass"].sum(), rel=1e-14)
    momentum = (data.static["mass"][:, None] * data.particles["velocity"][-1]).sum(axis=0)
    np.testing.assert_allclose((masses[:, None] * v).sum(axis=0), momentum, atol=1e-9 * np.abs(data.static["mass"][:, None] * data.particles["velocity"][-1]).sum())
    i, j = np.triu_indices(len(want), 1)
    energy = 0.5 * (masses * (v * v).sum(axis=1)).sum() - (6.6743e-8 * masses[i] * masses[j] / np.linalg.norm(x[i] - x[j], axis=1)).sum()
    assert sim["energy"] == pytest.approx(energy, rel=1e-10)
    result = cli_here("export", str(run_dir), "--rebound", str(tmp_path / "middle.bin"), "--frame", "1")
    assert result.returncode == 0 and "frame 1 (step 50, t = 2 s)" in result.stdout, result.stderr  # every frame was analysed


def test_rebound_needs_an_analysed_frame_and_says_how_to_get_rebound(run_dir, tmp_path, monkeypatch):
    """Refusals that come before REBOUND is needed, and the line for a machine without it."""
    unanalysed = tmp_path / "copy"
    unanalysed.mkdir()
    (unanalysed / "trajectory.h5").write_bytes((run_dir / "trajectory.h5").read_bytes())
    result = cli_here("export", str(unanalysed), "--rebound", str(tmp_path / "g.bin"))
    assert result.returncode == 2 and "decco-warp analyze" in result.stderr and result.stderr.count("\n") == 1
    assert not (tmp_path / "g.bin").exists()
    monkeypatch.setitem(__import__("sys").modules, "rebound", None)  # as if it were not installed
    with pytest.raises(InputError, match=r"pip install rebound"):
        write_rebound(tmp_path / "h.bin", handoff_bodies(run_dir))
    assert not (tmp_path / "h.bin").exists()

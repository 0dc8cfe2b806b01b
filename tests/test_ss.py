"""pkdgrav .ss files: files written here by an independent writer (struct, big-endian, the bytes of
pkdgrav's ssio.h) read in cgs, the writer's bytes read back with struct, round trips through files
and pile files, and bad files refused in one line (exit 2 from the command line)."""

import math
import struct

import numpy as np
import pytest

from decco_warp.errors import FileFormatError
from decco_warp.interchange import export_ss, pile_from_ss
from decco_warp.io import load_pile, save_pile
from decco_warp.ss import SSParticles, read_ss, ss_bytes, write_ss
from helpers import cli_here

# pkdgrav's units in cgs as its sources give them (src/ss/companion.c: AU, M_SUN, SID_YR / 2 pi),
# typed here rather than read from decco_warp.ss.
M_SUN = 1.9891e33
AU = 1.49597870e13
YEAR_OVER_TWO_PI = 3.15581497632e7 / (2.0 * math.pi)


def write_standard(path, time, rows, magic=-1, n=None):
    """A standard .ss file, record by record: (mass, radius, pos, vel, spin, color, org_idx) in pkdgrav's units."""
    with open(path, "wb") as f:
        f.write(struct.pack(">dii", time, len(rows) if n is None else n, magic))
        for m, r, x, v, w, color, org in rows:
            f.write(struct.pack(">11dii", m, r, *x, *v, *w, color, org))


def write_reduced(path, time, rows):
    with open(path, "wb") as f:
        f.write(struct.pack(">dii", time, len(rows), -10101))
        for m, r, x, _, _, color, org in rows:
            f.write(struct.pack(">5fii", m, r, *x, color, org))


def lattice_rows(n_side=3, radius=1.0e6, density=2.7, offset=(1.0, 0.0, 0.0), velocity=(0.0, 1.0, 0.0), spin_rate=1e-4):
    """A cube of touching-free spheres far from the origin (1 AU), moving and turning rigidly, in
    pkdgrav's units: what a pkdgrav user's rubble pile in orbit would look like."""
    rng = np.random.default_rng(3)
    rows = []
    axis = np.array([0.0, 0.0, spin_rate])  # rad/s
    k = 0
    for ix in range(n_side):
        for iy in range(n_side):
            for iz in range(n_side):
                r = radius * (1.0 if k % 2 else 2.0)
                x_cm = (np.array([ix, iy, iz]) - (n_side - 1) / 2) * 4.5 * radius + rng.normal(scale=1e3, size=3)
                mass = 4.0 / 3.0 * math.pi * density * r**3
                v_cm = np.cross(axis, x_cm)
                rows.append((mass / M_SUN, r / AU, tuple(np.array(offset) + x_cm / AU), tuple(np.array(velocity) + v_cm / AU * YEAR_OVER_TWO_PI),
                             tuple(axis * YEAR_OVER_TWO_PI), 3, k))  # fmt: skip
                k += 1
    return rows


def test_a_standard_file_of_an_independent_writer_reads_in_cgs(tmp_path):
    rows = lattice_rows()
    write_standard(tmp_path / "pile.ss", 2.5, rows)
    got = read_ss(tmp_path / "pile.ss")
    assert got.n == 27 and not got.reduced
    assert got.time == 2.5 * YEAR_OVER_TWO_PI
    for k, (m, r, x, v, w, color, org) in enumerate(rows):
        assert got.mass[k] == m * M_SUN and got.radius[k] == r * AU
        np.testing.assert_allclose(got.position[k], np.array(x) * AU, rtol=1e-15)
        np.testing.assert_allclose(got.velocity[k], np.array(v) * AU / YEAR_OVER_TWO_PI, rtol=1e-15)
        np.testing.assert_allclose(got.spin[k], np.array(w) / YEAR_OVER_TWO_PI, rtol=1e-15)
        assert (got.color[k], got.org_idx[k]) == (color, org)


def test_a_reduced_file_reads_its_floats_and_has_no_motion(tmp_path):
    rows = lattice_rows()
    write_reduced(tmp_path / "pile.ss", 0.0, rows)
    got = read_ss(tmp_path / "pile.ss")
    assert got.reduced and got.n == 27
    for k, (m, r, x, *_rest) in enumerate(rows):
        assert got.mass[k] == float(np.float32(m)) * M_SUN
        np.testing.assert_array_equal(got.position[k], np.array(x, dtype=np.float32).astype(float) * AU)
    assert not got.velocity.any() and not got.spin.any()


@pytest.mark.parametrize("reduced", [False, True])
def test_the_writer_lays_out_the_bytes_of_ssio_h(reduced):
    """Bytes from ss_bytes, unpacked with struct: the header, one record per particle of 96 (or 28)
    bytes, each value the cgs one over pkdgrav's unit."""
    rng = np.random.default_rng(9)
    n = 5
    particles = SSParticles(
        time=123.0, mass=rng.uniform(1e18, 1e20, n), radius=rng.uniform(1e5, 1e6, n), position=rng.normal(size=(n, 3)) * 1e7,
        velocity=rng.normal(size=(n, 3)) * 100, spin=rng.normal(size=(n, 3)) * 1e-4, color=np.arange(n, dtype=np.int32) + 3,
        org_idx=-np.arange(n, dtype=np.int32), reduced=reduced,
    )  # fmt: skip
    data = ss_bytes(particles)
    record = ">5fii" if reduced else ">11dii"
    assert len(data) == 16 + n * struct.calcsize(record) == 16 + n * (28 if reduced else 96)
    time, count, magic = struct.unpack(">dii", data[:16])
    assert (count, magic) == (n, -10101 if reduced else -1)
    assert time == pytest.approx(123.0 / YEAR_OVER_TWO_PI, rel=1e-15)
    size = struct.calcsize(record)
    for k in range(n):
        values = struct.unpack(record, data[16 + k * size : 16 + (k + 1) * size])
        want = [particles.mass[k] / M_SUN, particles.radius[k] / AU, *(particles.position[k] / AU)]
        if not reduced:
            want += [*(particles.velocity[k] / AU * YEAR_OVER_TWO_PI), *(particles.spin[k] * YEAR_OVER_TWO_PI)]
        np.testing.assert_allclose(values[:-2], want, rtol=1e-7 if reduced else 1e-15)
        assert values[-2:] == (k + 3, -k)


def test_files_round_trip_to_the_last_bit_of_their_own_precision(tmp_path):
    rng = np.random.default_rng(4)
    n = 40
    particles = SSParticles(7.0, rng.uniform(1e18, 1e20, n), rng.uniform(1e5, 1e6, n), rng.normal(size=(n, 3)) * 1e7,
                            rng.normal(size=(n, 3)) * 100, rng.normal(size=(n, 3)) * 1e-4, np.full(n, 3, np.int32), np.arange(n, dtype=np.int32))  # fmt: skip
    write_ss(tmp_path / "a.ss", particles)
    back = read_ss(tmp_path / "a.ss")
    for name in ("mass", "radius", "position", "velocity", "spin"):
        np.testing.assert_allclose(getattr(back, name), getattr(particles, name), rtol=4e-16, err_msg=name)
    assert back.time == pytest.approx(7.0, rel=4e-16)
    write_ss(tmp_path / "b.ss", back)  # a second pass changes nothing
    assert (tmp_path / "b.ss").read_bytes() == (tmp_path / "a.ss").read_bytes()
    particles.reduced = True
    write_ss(tmp_path / "r.ss", particles)
    reduced = read_ss(tmp_path / "r.ss")
    np.testing.assert_allclose(reduced.position, particles.position, rtol=1e-7)


def _damaged(tmp_path, how):
    rows = lattice_rows(n_side=2)
    path = tmp_path / f"{how}.ss"
    if how == "magic":
        write_standard(path, 0.0, rows, magic=7)
    elif how == "no particles":
        write_standard(path, 0.0, [], n=0)
    elif how == "nan":
        m, r, x, v, w, c, o = rows[3]
        rows[3] = (m, r, (x[0], math.nan, x[2]), v, w, c, o)
        write_standard(path, 0.0, rows)
    elif how == "zero radius":
        m, r, x, v, w, c, o = rows[1]
        rows[1] = (m, 0.0, x, v, w, c, o)
        write_standard(path, 0.0, rows)
    elif how == "little-endian":
        with open(path, "wb") as f:
            f.write(struct.pack("<dii", 0.0, len(rows), -1))
            for m, r, x, v, w, c, o in rows:
                f.write(struct.pack("<11dii", m, r, *x, *v, *w, c, o))
    else:
        write_standard(path, 0.0, rows)
        data = path.read_bytes()
        path.write_bytes({"truncated": data[:-10], "header cut": data[:10], "trailing bytes": data + b"\0" * 7}[how])
    return path


@pytest.mark.parametrize(
    "how, said",
    [("truncated", "is truncated: its header declares 8 standard particles"), ("header cut", "fewer than its 16-byte header"),
     ("magic", "magic number 7 (standard -1, reduced -10101)"), ("no particles", "declares 0 particles"),
     ("nan", "particle 3 has a non-finite pos"), ("zero radius", "particle 1 has radius 0"),
     ("trailing bytes", "has 7 bytes after its 8 standard particles"), ("little-endian", "little-endian")],
)  # fmt: skip
def test_bad_files_are_refused_in_one_line_with_exit_2(tmp_path, how, said):
    path = _damaged(tmp_path, how)
    with pytest.raises(FileFormatError, match=None) as caught:
        read_ss(path)
    assert said in str(caught.value) and "\n" not in str(caught.value)
    result = cli_here("pile", "--from", str(path), "--out", str(tmp_path / "pile.h5"))
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and said in result.stderr and result.stderr.startswith("decco-warp: error:")
    assert not (tmp_path / "pile.h5").exists()


def test_a_pile_from_a_file_is_centred_at_rest_and_keeps_its_sizes_colours_and_indices(tmp_path):
    rows = lattice_rows()
    write_standard(tmp_path / "pile.ss", 0.0, rows)
    result = cli_here("pile", "--from", str(tmp_path / "pile.ss"), "--out", str(tmp_path / "pile.h5"))
    assert result.returncode == 0, result.stderr
    assert "27 particles (13 of radius 10 km, 14 of radius 20 km)" in result.stdout
    pile = load_pile(tmp_path / "pile.h5")
    np.testing.assert_allclose(pile.centre_of_mass, 0.0, atol=1e-2)  # positions at 1 AU carry 2e-3 cm
    momentum = (pile.masses[:, None] * pile.velocities).sum(axis=0)
    assert np.abs(momentum).max() < 1e-12 * pile.total_mass * 1e6  # the 1 AU/(yr/2pi) ~ 30 km/s removed to round-off
    np.testing.assert_allclose(pile.spin(), 0.0, atol=1e-16)
    # What was removed is the file's own motion: its centre at 1 AU, its orbital speed, its spin of 1e-4 rad/s.
    meta = pile.metadata
    masses = np.array([row[0] for row in rows]) * M_SUN
    centre = (masses[:, None] * np.array([row[2] for row in rows]) * AU).sum(axis=0) / masses.sum()
    np.testing.assert_allclose(meta["removed_centre"], centre, rtol=1e-12)
    bulk = (masses[:, None] * np.array([row[3] for row in rows]) * AU / YEAR_OVER_TWO_PI).sum(axis=0) / masses.sum()
    np.testing.assert_allclose(meta["removed_velocity"], bulk, rtol=1e-12, atol=1e-6)
    assert abs(bulk[1] - AU / YEAR_OVER_TWO_PI) < 1.0  # ~30 km/s: the orbit's speed, plus the spin about the lattice's centre
    np.testing.assert_allclose(meta["removed_spin"], [0.0, 0.0, 1e-4], rtol=1e-9, atol=1e-12)  # x at 1 AU: 2e-3 cm
    assert pile.size_class.tolist() == [1 if k % 2 == 0 else 0 for k in range(27)]
    np.testing.assert_allclose(meta["size_radii"], [1e6, 2e6], rtol=1e-12)
    # Out again: the same particles in the pile's own frame, with the file's colours and indices.
    export_ss(tmp_path / "pile.h5", tmp_path / "again.ss")
    again = read_ss(tmp_path / "again.ss")
    assert again.color.tolist() == [3] * 27 and again.org_idx.tolist() == list(range(27))
    np.testing.assert_allclose(again.position, pile.positions, rtol=1e-15, atol=1e-9)
    np.testing.assert_allclose(again.radius, [row[1] * AU for row in rows], rtol=1e-15)


def test_a_file_that_is_no_settled_pile_is_refused(tmp_path):
    rows = lattice_rows(n_side=2)
    m, r, x, v, w, c, o = rows[5]
    rows[5] = (m, r, rows[2][2], v, w, c, o)  # on top of particle 2
    write_standard(tmp_path / "coincident.ss", 0.0, rows)
    result = cli_here("pile", "--from", str(tmp_path / "coincident.ss"), "--out", str(tmp_path / "p.h5"))
    assert result.returncode == 2 and "particles 2 and 5 overlap" in result.stderr and result.stderr.count("\n") == 1
    rows = lattice_rows(n_side=2, radius=2e8 / 3)  # grains of 1300 km: not grains of a rubble pile in cgs
    write_standard(tmp_path / "huge.ss", 0.0, rows)
    result = cli_here("pile", "--from", str(tmp_path / "huge.ss"), "--out", str(tmp_path / "p.h5"))
    assert result.returncode == 2 and "radius" in result.stderr and "outside 1 cm to 1e+08 cm" in result.stderr
    result = cli_here("pile", "--from", str(tmp_path / "huge.ss"), "--out", str(tmp_path / "p.h5"), "--seed", "3")
    assert result.returncode == 2 and "--seed does not apply" in result.stderr
    assert not (tmp_path / "p.h5").exists()


def test_continuous_radii_fall_into_three_log_bins_that_the_pile_file_states(tmp_path):
    rng = np.random.default_rng(5)
    rows = []
    for k in range(30):
        r = 1e5 * 10 ** (k / 29)  # 1 to 10 km, 30 sizes
        x = np.array([k * 3e6, 0.0, 0.0])
        rows.append((4 / 3 * math.pi * 2.7 * r**3 / M_SUN, r / AU, tuple(x / AU), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 3, k))
    rng.shuffle(rows)
    write_standard(tmp_path / "spread.ss", 0.0, rows)
    pile = pile_from_ss(tmp_path / "spread.ss")
    save_pile(pile, tmp_path / "spread.h5")
    edges = load_pile(tmp_path / "spread.h5").metadata["size_class_edges"]
    np.testing.assert_allclose(edges, [1e5, 10 ** (5 + 1 / 3), 10 ** (5 + 2 / 3), 1e6], rtol=1e-12)
    radii = np.array([row[1] for row in rows]) * AU
    want = np.digitize(np.log10(radii), [5 + 1 / 3, 5 + 2 / 3])  # float64, independent of sizes.classify
    assert pile.size_class.tolist() == want.tolist() and np.bincount(want).tolist() == [10, 10, 10]

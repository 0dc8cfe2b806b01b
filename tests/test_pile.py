"""Rubble-pile formation and pile files."""

import os
import re

import h5py
import numpy as np
import pytest

import decco_warp as dw
from decco_warp.collision import pile_radius
from decco_warp.io import FileFormatError, load_pile, save_pile
from decco_warp.pile import KE_THRESHOLD, remove_net_motion, seed_cloud, size_class_counts

#: Overlaps left in a settled pile: well under 1 % of the smallest radius.
SETTLED_OVERLAP_FRACTION = 0.01


def test_size_class_counts_give_equal_mass_per_class():
    counts = size_class_counts(5000)
    assert counts.tolist() == [4303, 538, 159]  # docs/model.md
    radii = np.array([0.75e6, 1.5e6, 2.25e6])
    mass = counts * radii**3
    assert np.ptp(mass) / mass.mean() < 0.01
    for n in (2, 7, 100, 1250):
        assert size_class_counts(n).sum() == n


def test_seed_cloud_has_no_overlaps_and_grows_when_crowded():
    rng = np.random.default_rng(0)
    radii = np.repeat([0.75e6, 1.5e6, 2.25e6], [80, 10, 3])
    positions, seed_radius = seed_cloud(radii, rng, fill=0.45)  # too crowded: the sphere must grow
    first = ((radii**3).sum() / 0.45) ** (1 / 3)
    assert seed_radius > first
    d = np.linalg.norm(positions[:, None] - positions[None], axis=2)
    gaps = d - radii[:, None] - radii[None]
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() >= 0
    assert np.all(np.linalg.norm(positions, axis=1) + radii <= seed_radius * (1 + 1e-12))


def test_seed_cloud_takes_the_spots_that_testing_every_placed_sphere_takes():
    """The grid of cells only narrows which placed spheres a spot is tested against: a plain
    placement, testing all of them with the same random draws, gives the same cloud."""
    from decco_warp.pile import SEED_TRIES, _uniform_in_ball

    radii = np.repeat([0.75e6, 1.5e6, 2.25e6], [1290, 160, 48])
    fill = 0.4  # crowded: many tries fail, near spheres of every size
    positions, seed_radius = seed_cloud(radii, np.random.default_rng(5), fill=fill)
    rng = np.random.default_rng(5)
    order = np.argsort(-radii, kind="stable")
    plain_radius = ((radii**3).sum() / fill) ** (1 / 3)
    while True:
        plain = np.empty_like(positions)
        placed = 0
        for k in order:
            for _ in range(SEED_TRIES):
                spot = _uniform_in_ball(rng, plain_radius - radii[k])
                if placed == 0 or (np.linalg.norm(plain[order[:placed]] - spot, axis=1) - radii[order[:placed]] - radii[k]).min() >= 0:
                    plain[k] = spot
                    placed += 1
                    break
            else:
                break
        if placed == radii.size:
            break
        plain_radius += 2.0 * radii.max()
    assert seed_radius == plain_radius
    np.testing.assert_array_equal(positions, plain)


def test_remove_net_motion_zeroes_momentum_and_spin():
    rng = np.random.default_rng(1)
    n = 50
    state = dw.State.from_arrays(
        rng.normal(size=(n, 3)) * 1e7 + 3e7,
        rng.normal(size=(n, 3)) * 100 + 40,
        rng.normal(size=(n, 3)) * 1e-4,
        np.full(n, 1e6),
        np.full(n, 1e19),
    )
    still = remove_net_motion(state)
    d = dw.diagnostics(still, dw.Params())
    p_scale = np.linalg.norm(state.masses[:, None] * state.velocities, axis=1).sum()
    assert np.linalg.norm(d["momentum"]) < 1e-12 * p_scale
    l_scale = np.linalg.norm(state.masses[:, None] * np.cross(still.positions, state.velocities), axis=1).sum()
    assert np.linalg.norm(d["angular_momentum"]) < 1e-12 * l_scale
    assert np.linalg.norm(still.centre_of_mass) < 1e-9 * 1e7


@pytest.fixture(scope="module")
def small_pile():
    # A larger dt than the paper's (eq. 17 margin 22) keeps this test short.
    return dw.form_pile(n_particles=100, seed=4, device="cpu", params=dw.Params(dt=0.1))


def test_formed_pile_is_settled_centred_and_still(small_pile):
    pile = small_pile
    params = dw.Params()
    assert pile.n == 100 and pile.size_class.tolist() == sorted(pile.size_class.tolist())
    assert np.bincount(pile.size_class).tolist() == size_class_counts(100).tolist()
    d = dw.diagnostics(pile, params)
    kinetic = d["kinetic_translational"] + d["kinetic_rotational"]
    # Removing the net spin can only lower the kinetic energy below the formation threshold.
    assert kinetic < KE_THRESHOLD * abs(d["potential"])
    assert small_pile.metadata["history_ke_over_u"].max() > 1e-3  # it collapsed first
    assert d["number_of_contacts"] > pile.n  # a pile, not a cloud
    assert d["max_overlap"] < SETTLED_OVERLAP_FRACTION * pile.radii.min()
    assert np.linalg.norm(pile.centre_of_mass) < 1e-6 * pile_radius(pile)
    assert np.linalg.norm(d["momentum"]) < 1e-9 * pile.total_mass * 1.0


def test_formation_is_deterministic_for_a_seed():
    params = dw.Params(dt=0.2)  # eq. 17 margin 11: fine for a 12-particle check
    a = dw.form_pile(n_particles=12, seed=9, device="cpu", params=params, ke_threshold=1e-4)
    b = dw.form_pile(n_particles=12, seed=9, device="cpu", params=params, ke_threshold=1e-4)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.velocities, b.velocities)
    radii = np.repeat([0.75e6, 1.5e6, 2.25e6], [10, 1, 1])
    seeded_9, _ = seed_cloud(radii, np.random.default_rng(9))
    seeded_10, _ = seed_cloud(radii, np.random.default_rng(10))
    assert not np.array_equal(seeded_9, seeded_10)


def test_pile_file_round_trip(small_pile, tmp_path):
    path = tmp_path / "p.h5"
    save_pile(small_pile, path)
    back = load_pile(path)
    for name in ("positions", "velocities", "omegas", "radii", "masses", "size_class"):
        assert np.array_equal(getattr(back, name), getattr(small_pile, name)), name
    assert back.metadata["seed"] == 4
    np.testing.assert_array_equal(back.metadata["history_ke_over_u"], small_pile.metadata["history_ke_over_u"])
    with h5py.File(path) as f:
        assert f["pile/summary"].attrs["mass"] == pytest.approx(small_pile.total_mass)
        assert f["pile/summary"].attrs["radius"] == pytest.approx(pile_radius(small_pile))
        assert f["pile/summary"].attrs["potential"] == pytest.approx(dw.diagnostics(small_pile, dw.Params())["potential"], rel=1e-12)
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_bad_pile_files_are_refused_with_a_reason(small_pile, tmp_path):
    with pytest.raises(FileFormatError, match="does not exist"):
        load_pile(tmp_path / "missing.h5")
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"not hdf5 at all")
    with pytest.raises(FileFormatError, match="not a readable HDF5 file"):
        load_pile(junk)
    good = tmp_path / "good.h5"
    save_pile(small_pile, good)
    truncated = tmp_path / "truncated.h5"
    truncated.write_bytes(good.read_bytes()[: good.stat().st_size // 3])
    with pytest.raises(FileFormatError):
        load_pile(truncated)
    negative = tmp_path / "negative.h5"
    save_pile(small_pile, negative)
    with h5py.File(negative, "r+") as f:
        f["pile/radii"][3] = -1.0
    with pytest.raises(FileFormatError, match="radii must be > 0; particle 3"):
        load_pile(negative)
    gutted = tmp_path / "gutted.h5"
    save_pile(small_pile, gutted)
    with h5py.File(gutted, "r+") as f:
        del f["pile/masses"]
    with pytest.raises(FileFormatError, match="lacks masses"):
        load_pile(gutted)


#: A 12-particle pile that forms in ~50 000 steps in under a second (eq. 17 margin 11).
QUICK = {"n_particles": 12, "seed": 9, "device": "cpu", "params": dw.Params(dt=0.2), "ke_threshold": 1e-4}


def _same_pile(a, b):
    for name in ("positions", "velocities", "omegas"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    np.testing.assert_array_equal(a.metadata["history_ke_over_u"], b.metadata["history_ke_over_u"])
    assert a.metadata["formation_steps"] == b.metadata["formation_steps"]


def test_a_formation_stopped_by_a_signal_or_its_step_limit_continues_to_the_same_pile(tmp_path):
    import os
    import signal

    from decco_warp.forming import FormationStopped, form_pile_file, partial_path
    from decco_warp.pile import FormationError

    reference = dw.form_pile(**QUICK)
    out = tmp_path / "pile.h5"
    partial = partial_path(out)
    checks = []

    def ctrl_c_at_the_third_check(progress):
        checks.append(progress.step)
        if len(checks) == 3:
            os.kill(os.getpid(), signal.SIGINT)  # noted, then the formation saves and stops

    with pytest.raises(FormationStopped, match=r"SIGINT at step 750; .* \(this session: set-up .* over 750 steps\), checks"):
        form_pile_file(out, progress=ctrl_c_at_the_third_check, checkpoint_seconds=1e9, **QUICK)
    assert partial.is_file() and not out.exists()
    with pytest.raises(ValueError, match="seed = 9, not 10"):
        form_pile_file(out, **{**QUICK, "seed": 10})
    # Past its step limit a formation saves too; a larger limit continues it.
    with pytest.raises(FormationError, match="did not settle within 20000 steps"):
        form_pile_file(out, max_steps=20_000, **QUICK)
    resumed_at = []
    pile = form_pile_file(out, on_resume=resumed_at.append, checkpoint_seconds=0.0, **QUICK)
    assert resumed_at == [20_000]
    _same_pile(pile, reference)
    _same_pile(load_pile(out), reference)
    assert not partial.exists()


def test_pile_command_continues_a_formation_past_its_step_limit(tmp_path):
    from helpers import cli

    out = tmp_path / "p.h5"
    args = ["pile", "--particles", "12", "--seed", "9", "--dt", "0.2", "--ke-threshold", "1e-4", "--out", str(out), "--device", "cpu"]
    first = cli(*args, "--max-steps", "10000")
    assert first.returncode == 1 and "larger --max-steps continues" in first.stderr
    assert (tmp_path / "p.h5.forming").is_file() and not out.exists()
    second = cli(*args, env={**os.environ, "DECCO_LOG_EVERY": "0"})
    assert second.returncode == 0, second.stderr
    # stderr is a pipe: rich draws the bar's line once, at the end, unless asked for a line every
    # DECCO_LOG_EVERY seconds (default 30 s, longer than the first call took).
    progress_line = r"(collapsing|settling) +step \d+ KE/\|U\| "
    assert len(re.findall(progress_line, first.stderr)) == 1, first.stderr
    assert len(re.findall(progress_line, second.stderr)) >= 3, second.stderr
    assert "continuing the formation saved in" in second.stderr and "at step 10000" in second.stderr
    # The wall time of the session, itemised: only the steps of this session are counted.
    spent = re.search(r"this session: set-up [0-9.]+ s, stepping ([0-9.]+) s \(([0-9.]+) ms a step over (\d+) steps\), checks [0-9.]+ s, saves [0-9.]+ s", second.stdout)
    assert spent, second.stdout
    formed = load_pile(out).metadata["formation_steps"]
    assert int(spent[3]) == formed - 10000
    _same_pile(load_pile(out), dw.form_pile(**QUICK))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.h5"]

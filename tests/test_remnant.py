"""A fragment of a finished run as a pile (decco_warp/remnant.py, ``decco-warp extract``), and a
second collision with it."""

import numpy as np
import pytest
from helpers import cli

import decco_warp as dw
from decco_warp.checks import InputError
from decco_warp.remnant import extract_fragment, internal_kinetic_energy


@pytest.fixture(scope="module")
def first(tmp_path_factory):
    """A short collision of the shipped piles, the projectile spinning, analysed: at its end the
    two piles are still two clusters, the target the larger."""
    out = tmp_path_factory.mktemp("first")
    result = cli("simulate", "--name", "a", "--eta", "0.5", "--steps", "200", "--output-every", "100", "--spin-projectile", "0.5,+z",
                 "--out", str(out), "--device", "cpu")  # fmt: skip
    assert result.returncode == 0, result.stderr
    result = cli("analyze", str(out / "a"), "--min-members", "20")
    assert result.returncode == 0, result.stderr
    return out / "a"


def test_a_fragment_is_its_clusters_particles_centred_with_its_spin_kept_or_removed(first):
    data = dw.read_trajectory(first / "trajectory.h5")
    spinning = extract_fragment(first, fragment=1, spin="keep", settle=False)
    assert spinning.n == int((data.static["pile_id"] == 1).sum())  # the projectile
    assert np.linalg.norm(spinning.centre_of_mass) < 1e-6 * spinning.radii.max()
    assert np.linalg.norm(spinning.bulk_velocity) < 1e-9 * np.abs(spinning.velocities).max()
    omega = np.linalg.norm(spinning.spin())
    assert spinning.spin()[2] == pytest.approx(omega, rel=1e-6) and omega > 0  # still about +z
    still = extract_fragment(first, fragment=1, spin="remove", settle=False)
    assert np.linalg.norm(still.spin()) < 1e-9 * omega
    assert still.metadata["extracted_from"]["fragment"] == 1 and still.metadata["spin"] == "remove"
    # Settled: the motion about the rigid rotation below the threshold of |U|.
    settled = extract_fragment(first, fragment=1, spin="remove", settle=True, ke_threshold=1e-3, max_steps=20_000)
    assert settled.metadata["internal_ke_over_u"] < 1e-3
    assert internal_kinetic_energy(settled) < 1e-3 * abs(settled.metadata["potential"])
    with pytest.raises(InputError, match="--fragment must be one of the run.s 2"):
        extract_fragment(first, fragment=2)


def test_a_remnant_collides_again(first, tmp_path):
    """extract writes a pile that simulate takes as a target: a second collision runs and its run
    records the remnant's file."""
    remnant = tmp_path / "remnant.h5"
    result = cli("extract", str(first), "--fragment", "0", "--out", str(remnant), "--spin", "remove", "--device", "cpu")
    assert result.returncode == 0, result.stderr
    assert f"wrote {remnant}: fragment 0 of" in result.stdout and "settled in" in result.stdout
    pile = dw.load_pile(remnant)
    result = cli("simulate", "--name", "second", "--target", str(remnant), "--projectile", "builtin:projectile", "--eta", "0.5",
                 "--steps", "100", "--output-every", "50", "--out", str(tmp_path), "--device", "cpu")  # fmt: skip
    assert result.returncode == 0, result.stderr
    data = dw.read_trajectory(tmp_path / "second" / "trajectory.h5")
    assert int((data.static["pile_id"] == 0).sum()) == pile.n and data.parameters["piles"]["target_file"] == str(remnant.resolve())
    assert "loose swarm" not in result.stderr  # a body, not debris
    for args, message in ((["--fragment", "7"], "--fragment must be one of"), (["--spin", "both"], "--spin must be one of"),
                          (["--ke-threshold", "0"], "--ke-threshold must be > 0")):  # fmt: skip
        result = cli("extract", str(first), "--out", str(tmp_path / "x.h5"), *args)
        assert result.returncode == 2 and message in result.stderr, result.stderr
        assert result.stderr.strip().splitlines() == [result.stderr.strip()] and not result.stdout  # no progress line first
    result = cli("extract", str(tmp_path / "nowhere"), "--out", str(tmp_path / "x.h5"))
    assert result.returncode == 2 and "does not exist" in result.stderr


def test_a_loose_swarm_is_told_from_a_body():
    """22 grains spread through a sphere of 119 km fill ~2 % of it: a swarm, and the warning says so
    (with what extracting it does); a settled pile (the shipped ones fill 0.40 and 0.41) is a body."""
    from decco_warp.collision import pile_radius
    from decco_warp.remnant import LOOSE_PACKING, loose_note, packing
    from decco_warp.run import builtin_pile

    rng = np.random.default_rng(3)
    directions = rng.normal(size=(22, 3))
    positions = directions / np.linalg.norm(directions, axis=1)[:, None] * 1.0e7 * rng.uniform(0.2, 1.0, (22, 1)) ** (1 / 3)
    radii = rng.choice([0.75e6, 1.5e6, 2.25e6], size=22)
    swarm = dw.State.from_arrays(positions, np.zeros((22, 3)), np.zeros((22, 3)), radii, 4 / 3 * np.pi * 2.7 * radii**3)
    fill = packing(swarm)
    assert fill == pytest.approx((radii**3).sum() / pile_radius(swarm) ** 3) and fill < LOOSE_PACKING
    note = loose_note(swarm, 3, settle=True)
    assert note.startswith("warning: fragment 3 is a loose swarm, not a body: 22 grains") and f"{pile_radius(swarm) / 1e5:.3g} km" in note
    assert "collapse" in note and "as the swarm it is" in loose_note(swarm, 3, settle=False)
    for which in ("target", "projectile"):
        pile = dw.load_pile(builtin_pile(which))
        assert packing(pile) > 2 * LOOSE_PACKING and loose_note(pile, 0, settle=True) is None

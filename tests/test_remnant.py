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
    for args, message in ((["--fragment", "7"], "--fragment must be one of"), (["--spin", "both"], "--spin must be one of")):
        result = cli("extract", str(first), "--out", str(tmp_path / "x.h5"), *args)
        assert result.returncode == 2 and message in result.stderr, result.stderr
    result = cli("extract", str(tmp_path / "nowhere"), "--out", str(tmp_path / "x.h5"))
    assert result.returncode == 2 and "does not exist" in result.stderr

"""Ensembles: several independent systems laid one after another and stepped by the same launches
(Simulation(..., systems=sizes)); each must move exactly as it would alone."""

import numpy as np
import pytest
from conftest import DEVICES
from scenes import contact_cluster

import decco_warp as dw

SIZES = (37, 64, 23)

ENGINES = [
    (device, name, options)
    for device in DEVICES
    for name, options in (
        [("default", {}), ("contact pass", {"layout": dw.Layout(1, 3, contact_pass=True)}), ("reference", {"force_kernel": "reference"})]
        if device == "cpu"
        else [("default", {}), ("128x4 contact pass", {"layout": dw.Layout(128, 4, contact_pass=True)}), ("32x3", {"layout": dw.Layout(32, 3, 2)})]
    )
]


def _systems():
    """Three clumps centred on the same point: had they felt each other, they would overlap wholesale."""
    return [contact_cluster(n, seed=seed, speed=1e3) for seed, n in enumerate(SIZES)]


def _together(states):
    def joined(name):
        return np.concatenate([getattr(s, name) for s in states])

    return dw.State.from_arrays(joined("positions"), joined("velocities"), joined("omegas"), joined("radii"), joined("masses"))


@pytest.mark.parametrize(("device", "name", "options"), ENGINES, ids=[f"{d}-{n}" for d, n, _ in ENGINES])
def test_each_system_of_an_ensemble_moves_bit_for_bit_as_it_would_alone(device, name, options):
    states = _systems()
    params = dw.Params()
    ensemble = dw.Simulation(_together(states), params, device=device, systems=SIZES, ledger=True, **options)
    alone = [dw.Simulation(s, params, device=device, ledger=True, **options) for s in states]
    cuts = np.cumsum((0, *SIZES))
    for steps in (0, 40):
        ensemble.step(steps)
        force, torque = ensemble.forces()
        positions = ensemble.state.positions
        pairs = ensemble.pair_observables()
        for k, sim in enumerate(alone):
            sim.step(steps)
            part = slice(cuts[k], cuts[k + 1])
            own_force, own_torque = sim.forces()
            assert np.array_equal(force[part], own_force) and np.array_equal(torque[part], own_torque)
            assert np.array_equal(positions[part], sim.state.positions)
            for key, values in sim.pair_observables().items():
                mine = pairs[key][part]
                if key == "overlap_partner":  # an index into the whole ensemble
                    mine = np.where(mine >= 0, mine - cuts[k], mine)
                assert np.array_equal(mine, values), key
            assert np.array_equal(ensemble.work()[part], sim.work())
    assert np.abs(force).max() > 0 and pairs["contacts"].sum() > 0  # gravity and contacts at work


def test_ensemble_sizes_are_checked_and_the_tree_steps_one_system():
    state = _together(_systems())
    for sizes in ((37, 64), (37, 64, 23, 1), (0, 101, 23), ()):
        with pytest.raises(ValueError, match="systems must be positive sizes"):
            dw.Simulation(state, dw.Params(), device="cpu", systems=sizes)
    with pytest.raises(ValueError, match="one system at a time"):
        dw.Simulation(state, dw.Params(gravity="tree"), device="cpu", systems=SIZES)

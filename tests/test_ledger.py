"""The energy ledger: every erg accounted for, per channel; and exact restarts from a snapshot."""

import numpy as np
import pytest
from scenes import contact_cluster, two_spheres

import decco_warp as dw
from decco_warp.diagnostics import energy_ledger

#: Ledger closure: the books balance to round-off of float64 sums.
CLOSURE_TOLERANCE = 1e-10


def _books(sim):
    now = sim.diagnostics()
    ledger = energy_ledger(now, sim.energy_start, sim.work())
    balance = now["total_energy"] + sum(ledger.values())
    return now, ledger, balance


def test_head_on_collision_loses_one_minus_eps_squared_to_hysteresis(device):
    radius = 1.5e6
    params = dw.Params(restitution=0.9, G=0.0)
    state = two_spheres(2 * radius + 1e3, velocity_i=(100.0, 0, 0), velocity_j=(-100.0, 0, 0), radius=radius)
    sim = dw.Simulation(state, params, device=device, precision="float64", ledger=True)
    e0 = sim.energy_start["total_energy"]
    sim.step(1500)  # in, bounce, out
    now, ledger, balance = _books(sim)
    assert now["number_of_contacts"] == 0
    assert abs(balance - e0) <= CLOSURE_TOLERANCE * e0
    assert ledger["dissipated_hysteresis"] == pytest.approx((1 - params.restitution**2) * e0, rel=0.02)
    assert ledger["dissipated_sliding"] == 0.0 and ledger["dissipated_rolling"] == 0.0


@pytest.mark.parametrize("rolling", ["couple", "paper"])
def test_oblique_collision_books_balance(rolling, device):
    radius = 1.5e6
    offset = 1.2 * radius
    state = two_spheres(
        np.sqrt((2 * radius + 1e3) ** 2 - offset**2), velocity_i=(100.0, 0, 0), velocity_j=(-100.0, 0, 0), radius=radius
    )
    state.positions[:, 1] += [-offset / 2, offset / 2]
    state.omegas[0] = (0, 0, 1e-4)
    params = dw.Params(G=0.0, rolling_friction=rolling)
    sim = dw.Simulation(state, params, device=device, precision="float64", ledger=True)
    e0 = sim.energy_start["total_energy"]
    sim.step(1500)
    _, ledger, balance = _books(sim)
    assert abs(balance - e0) <= CLOSURE_TOLERANCE * e0
    assert ledger["dissipated_sliding"] > 1e-3 * e0
    assert ledger["dissipated_hysteresis"] > 1e-3 * e0
    if rolling == "couple":
        assert ledger["dissipated_rolling"] > 0
    # No gravity: the gravity column is only the round-off of force minus contact channels.
    assert abs(ledger["integration_error"]) <= 1e-12 * e0


def test_elastic_frictionless_clump_dissipates_nothing(device):
    clump = contact_cluster(100, seed=3, overlap_range=(1.0, 1e3), speed=20.0)
    params = dw.Params(restitution=1.0, mu_k=0.0, mu_r=0.0)
    sim = dw.Simulation(clump, params, device=device, precision="float64", ledger=True)
    sim.step(1000)
    now, ledger, balance = _books(sim)
    scale = abs(sim.energy_start["total_energy"])
    assert abs(balance - sim.energy_start["total_energy"]) <= CLOSURE_TOLERANCE * scale
    assert ledger["dissipated_sliding"] == 0.0 and ledger["dissipated_rolling"] == 0.0
    # What remains is the integrator's own error, tiny against the kinetic energy exchanged.
    assert abs(ledger["dissipated_hysteresis"]) < 1e-4 * now["kinetic_translational"]
    assert abs(ledger["integration_error"]) < 1e-4 * now["kinetic_translational"]


@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_dissipative_clump_books_balance(precision, device):
    clump = contact_cluster(100, seed=3, overlap_range=(1.0, 1e3), speed=20.0, spin=1e-4)
    sim = dw.Simulation(clump, dw.Params(), device=device, precision=precision, ledger=True)
    sim.step(1000)
    _, ledger, balance = _books(sim)
    scale = abs(sim.energy_start["total_energy"])
    assert abs(balance - sim.energy_start["total_energy"]) <= CLOSURE_TOLERANCE * scale
    for channel in ("dissipated_sliding", "dissipated_rolling", "dissipated_hysteresis"):
        assert ledger[channel] > 0, channel


def test_snapshot_restart_is_bit_identical(device):
    clump = contact_cluster(60, seed=9, speed=20.0, spin=1e-4)
    params = dw.Params()
    straight = dw.Simulation(clump, params, device=device, ledger=True)
    straight.step(130)
    first = dw.Simulation(clump, params, device=device, ledger=True)
    first.step(57)
    snap = first.snapshot()
    del first
    second = dw.Simulation.from_snapshot(clump, params, snap, device=device)
    assert second.step_count == 57
    second.step(73)
    a, b = straight.snapshot(), second.snapshot()
    for key in ("positions", "velocities", "omegas", "force", "torque"):
        assert np.array_equal(a[key], b[key]), key
    # Every layout sums the ledger's channels in a fixed order (no atomics): bit for bit on a GPU too.
    for key in ("channels", "work"):
        assert np.array_equal(a[key], b[key]), key
    assert straight.time == second.time and second.step_count == 130
    for key in ("potential", "elastic", "total_energy"):
        assert straight.energy_start[key] == second.energy_start[key]


@pytest.mark.parametrize("precision", ["mixed", "float64"])
def test_the_other_layout_keeps_the_books_and_matches_the_default_layout(precision, device):
    """The layout a device does not take by default (the Newton layout on the CPU: each pair's
    gravity once, then contacts per particle; the fused layout on CUDA) closes the ledger over 300
    steps, and over 20 its motion equals the default layout's to the round-off of its sums (the
    fused layout sums contacts in float32 in mixed precision; a contact clump amplifies differences later)."""
    clump = contact_cluster(120, seed=5, overlap_range=(1.0, 1e3), speed=20.0, spin=1e-5)
    params = dw.Params()
    other = dw.Layout(128, 4, 4) if device.startswith("cuda") else dw.Layout(1, 4, newton=True)
    early = []
    for layout in (None, other):
        sim = dw.Simulation(clump, params, device=device, precision=precision, layout=layout, ledger=True)
        e0 = sim.energy_start["total_energy"]
        sim.step(20)
        early.append(sim.state.positions)
        sim.step(280)
        _, ledger, balance = _books(sim)
        assert abs(balance - e0) <= CLOSURE_TOLERANCE * abs(e0)
        assert ledger["dissipated_sliding"] > 0 and ledger["dissipated_hysteresis"] > 0
    moved = np.abs(early[0] - clump.positions).max()
    tolerance = 1e-12 if precision == "float64" else 1e-6
    assert moved > 0 and np.abs(early[1] - early[0]).max() <= tolerance * moved


def test_the_channel_table_sizes_the_kernels_types_and_names_the_outputs():
    """kernels/channels.py is the one list of energy channels: the kernels' rows and work vector are
    as long as it says, the ledger's entries are its own, and docs/data.md names each energy."""
    from pathlib import Path

    from decco_warp.io import OBSERVABLE_UNITS
    from decco_warp.kernels import channels, contacts, integrate

    assert contacts.ContactRows._shape_ == (len(channels.CONTACT_CHANNELS), 3)
    assert contacts.LedgerRows._shape_ == (len(channels.LEDGER_CHANNELS), 3)
    assert channels.CONTACT_CHANNELS[: len(channels.LEDGER_CHANNELS)] == channels.LEDGER_CHANNELS
    assert integrate.Work._length_ == len(channels.WORK_CHANNELS) == integrate.Motion.vars["work"].type._length_
    sim = dw.Simulation(contact_cluster(8, 1), dw.Params(), device="cpu", ledger=True)
    assert sim.work().shape == (sim.state.n, len(channels.WORK_CHANNELS))
    assert set(energy_ledger(sim.diagnostics(), sim.energy_start, sim.work())) == set(channels.LEDGER_ENTRIES)
    data_md = (Path(__file__).parent.parent / "docs" / "data.md").read_text()
    for name in (*channels.HELD_ENERGIES, *channels.LEDGER_ENTRIES):
        assert OBSERVABLE_UNITS[name] == "erg" and f"`{name}`" in data_md, name

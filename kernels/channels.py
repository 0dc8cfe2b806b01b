"""The energy channels, each said once: the table from which the kernels' sized types (the contact
and ledger rows, the work vector) and the host's names (the ledger's entries, the observables'
units) are made.  Plain data, no Warp: the host's ledger and outputs read it too.

A channel's work on a particle is a column of the ledger's work (kernels/integrate.py), the work of
its contact channels, rows of the ledger's channels (kernels/contacts.py); the energy it holds is a
diagnostics key, and what it took since the start is its ledger entry (an observable of a run,
docs/data.md).
"""

from typing import NamedTuple


class EnergyChannel(NamedTuple):
    name: str
    """Its column of a particle's work, in the table's order."""
    forces: tuple
    """The contact channels whose work it is (rows of the ledger's channels); gravity's is the rest of the force."""
    held: str
    """The energy it holds (a diagnostics key)."""
    entry: str
    """Its ledger entry: the energy it took since the start, less the change of what it holds [erg]."""


ENERGY_CHANNELS = (
    EnergyChannel("gravity", (), "potential", "integration_error"),
    EnergyChannel("spring", ("spring_force",), "elastic", "dissipated_hysteresis"),
    EnergyChannel("sliding", ("sliding_force", "sliding_torque"), "elastic_tangential", "dissipated_sliding"),
    EnergyChannel("rolling", ("rolling_force",), "elastic_rolling", "dissipated_rolling"),
)

#: The columns of a particle's work.
WORK_CHANNELS = tuple(channel.name for channel in ENERGY_CHANNELS)
#: The ledger's rows on a particle, summed over its contacts.
LEDGER_CHANNELS = tuple(force for channel in ENERGY_CHANNELS for force in channel.forces)
#: A contact's channels on i, in the order of kernels/contacts.py contact_function's results: the
#: ledger's, then the rolling couple (whose work the ledger takes as the rest of the torque).
CONTACT_CHANNELS = (*LEDGER_CHANNELS, "rolling_torque")
#: The energies the channels hold, in the order of their columns.
HELD_ENERGIES = tuple(channel.held for channel in ENERGY_CHANNELS)
#: The ledger's entries in the order a run lists and sums them (the frictions, the hysteresis, the
#: integration error): added to the total energy, they give back the starting total energy.
LEDGER_ENTRIES = tuple(ENERGY_CHANNELS[k].entry for k in (2, 3, 1, 0))

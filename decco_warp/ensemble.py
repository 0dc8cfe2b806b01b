"""Ensembles: several independent runs advanced by one Simulation, each seen by its run as its own.

The runs of a sweep at paper scale leave a GPU partly idle (docs/benchmarks.md); laid one after
another in one state and stepped by the same launches (``Simulation(..., systems=sizes)``), each
system moves bit for bit as it would alone.  A :class:`SystemView` gives a run what it reads of a
Simulation (state, observables, deepest contact, snapshot), cut to its own system, so that frames,
checkpoints and resume are those of a run stepped alone.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .arrays import HISTORY_ARRAYS, history_arrays
from .diagnostics import state_diagnostics
from .contact_finders import NEIGHBOUR_ARRAYS, neighbour_arrays
from .simulation import Simulation
from .stability import StabilityReport
from .state import State
from .errors import InputError


class Ensemble:
    """Independent simulations (same Params, same step) stepped together on one device.

    Built from each member's Simulation (as a run prepares it): their snapshots, joined, continue
    exactly where each would have; the members' own Simulations are no longer stepped.
    """

    def __init__(self, members: list[Simulation]):
        if not members:
            raise InputError("an ensemble needs at least one member")
        first = members[0]
        for sim in members[1:]:
            if sim.params != first.params:
                raise InputError("the members of an ensemble must share their Params")
            if sim.step_count != first.step_count or sim.device != first.device:
                raise InputError("the members of an ensemble must be at the same step on the same device")
            # One scheme for all (its layout and precision): a member stepped otherwise would not move as it would alone.
            if sim.engine.scheme != first.engine.scheme:
                raise InputError("the members of an ensemble must share their force layout and precision, and gravity and its clock (their Scheme)")
        if not all(sim.engine.ledger for sim in members):
            raise InputError("the members of an ensemble keep the energy ledger (ledger=True)")
        snapshots = [sim.snapshot() for sim in members]
        statics = [sim.static for sim in members]
        sizes = np.array([s.n for s in statics])
        ends = np.cumsum(sizes)
        starts = ends - sizes
        joined = {key: np.concatenate([snap[key] for snap in snapshots]) for key in _ARRAYS}
        joined["deepest_contact"] = np.concatenate([_partners_moved(snap["deepest_contact"], first) for snap, first in zip(snapshots, starts)])
        if all(key in snap for snap in snapshots for key in NEIGHBOUR_ARRAYS):  # each system's lists as alone
            joined.update(_joined_lists(snapshots, starts))
        if all(key in snap for snap in snapshots for key in HISTORY_ARRAYS):  # each system's contacts and springs
            joined.update(_joined_history(snapshots, starts))
        state = State.from_arrays(
            joined["positions"], joined["velocities"], joined["omegas"],
            np.concatenate([s.radii for s in statics]), np.concatenate([s.masses for s in statics]),
        )  # fmt: skip
        # At the members' step (each view keeps its own clock's origin).
        state = replace(state, step=first.step_count, time=first.step_count * first.params.dt)
        self.sim = Simulation(
            state, first.params, device=first.device, scheme=first.engine.scheme, allow_unstable=True, ledger=True, systems=sizes.tolist(),
        )  # fmt: skip
        self.sim.engine.restore(joined)
        self.views = [
            SystemView(self, system, int(start), int(end), sim.static, snap, sim.stability)
            for system, (sim, snap, start, end) in enumerate(zip(members, snapshots, starts, ends))
        ]
        self._cache: dict = {}

    def step(self, n: int) -> None:
        self.sim.step(n)

    def finish(self) -> None:
        self.sim.finish()

    def _at_step(self, key: str, compute):
        """``compute()`` once per step, shared by the views (the host copies of all systems)."""
        if self._cache.get("step") != self.sim.step_count:
            self._cache = {"step": self.sim.step_count}
        if key not in self._cache:
            self._cache[key] = compute()
        return self._cache[key]

    def read(self):
        return self._at_step("read", self.sim.engine.read)

    def pairs(self) -> dict[str, np.ndarray]:
        return self._at_step("pairs", self.sim.pair_observables)

    def work(self) -> np.ndarray:
        return self._at_step("work", self.sim.work)

    def snapshot(self) -> dict:
        return self._at_step("snapshot", self.sim.engine.snapshot)


#: The per-particle arrays of a snapshot, joined along the particles in an ensemble.
_ARRAYS = ("positions", "velocities", "omegas", "force", "torque", "channels", "work", "deepest_contact")


def _partners_moved(records: np.ndarray, offset: int) -> np.ndarray:
    """Deepest-contact records (kernels/contacts.py note_depth) with their partner's index moved by
    ``offset``: a system's own numbering in its snapshot, the ensemble's inside the ensemble."""
    return np.where(records > 0, records + offset, records)


def _lists_moved(count: np.ndarray, listed: np.ndarray, offset: int) -> np.ndarray:
    """Neighbour lists (contact_finders.py ``NeighbourList.arrays``) with each listed index moved by ``offset``."""
    used = np.arange(listed.shape[1])[None, :] < count[:, None]
    return np.where(used, listed + offset, 0).astype(np.int32)


def _joined_lists(snapshots: list[dict], starts: np.ndarray) -> dict[str, np.ndarray]:
    """The members' neighbour lists in the ensemble's numbering, as wide as the widest."""
    width = max(snap["neighbour_list"].shape[1] for snap in snapshots)
    rows = []
    for snap, first in zip(snapshots, starts):
        listed = np.zeros((len(snap["neighbour_count"]), width), dtype=np.int32)
        listed[:, : snap["neighbour_list"].shape[1]] = snap["neighbour_list"]
        rows.append(_lists_moved(snap["neighbour_count"], listed, int(first)))
    return {
        "neighbour_reference": np.concatenate([snap["neighbour_reference"] for snap in snapshots]),
        "neighbour_count": np.concatenate([snap["neighbour_count"] for snap in snapshots]),
        "neighbour_list": np.concatenate(rows),
    }


def _history_moved(history: dict[str, np.ndarray], offset: int, width: int | None = None) -> dict[str, np.ndarray]:
    """A contact history (arrays.ContactHistory.arrays) with each partner's index moved by ``offset``,
    its rows padded to ``width`` columns (None: as they are)."""
    count, partner = history["contact_count"], history["contact_partner"]
    width = partner.shape[1] if width is None else width
    moved = {"contact_count": count.copy()}
    for key in HISTORY_ARRAYS[1:]:
        values = history[key]
        padded = np.zeros((values.shape[0], width, *values.shape[2:]), dtype=values.dtype)
        padded[:, : values.shape[1]] = values
        moved[key] = padded
    used = np.arange(width)[None, :] < np.minimum(count, partner.shape[1])[:, None]  # (rows past the count are zeros)
    moved["contact_partner"] = np.where(used, moved["contact_partner"] + offset, 0).astype(np.int32)
    return moved


def _joined_history(snapshots: list[dict], starts: np.ndarray) -> dict[str, np.ndarray]:
    """The members' contact histories in the ensemble's numbering, as wide as the widest."""
    width = max(snap["contact_partner"].shape[1] for snap in snapshots)
    parts = [_history_moved({key: snap[key] for key in HISTORY_ARRAYS}, int(first), width) for snap, first in zip(snapshots, starts)]
    return {key: np.concatenate([part[key] for part in parts]) for key in HISTORY_ARRAYS}


class SystemView:
    """One system of an :class:`Ensemble`, with the reading side of a :class:`Simulation`."""

    def __init__(self, ensemble: Ensemble, system: int, first: int, end: int, static: State, snapshot: dict, stability: StabilityReport):
        self._ensemble, self.system, self.first, self.end = ensemble, system, first, end
        self._static = static.copy()
        self._time_origin = float(snapshot["time_origin"])
        self.params = ensemble.sim.params
        self.stability = stability
        self.energy_start = {key: float(value) for key, value in snapshot["energy_start"].items()}

    @property
    def device(self) -> str:
        return self._ensemble.sim.device

    @property
    def step_multiple(self) -> int:
        """Steps of an outer step of the ensemble (every member's)."""
        return self._ensemble.sim.step_multiple

    @property
    def step_count(self) -> int:
        return self._ensemble.sim.step_count

    @property
    def time(self) -> float:
        return self._time_origin + self.step_count * self.params.dt

    def step(self, n: int = 1) -> None:
        raise RuntimeError("a system of an ensemble is stepped with the whole ensemble (Ensemble.step)")

    def finish(self) -> None:
        self._ensemble.finish()

    @property
    def static(self) -> State:
        """The state this system began from, for its per-particle constants (radii, masses, ...)."""
        return self._static

    @property
    def state(self) -> State:
        positions, velocities, omegas = (values[self.first : self.end].copy() for values in self._ensemble.read())
        return replace(
            self._static.copy(), positions=positions, velocities=velocities, omegas=omegas, time=self.time, step=self.step_count
        )

    def pair_observables(self) -> dict[str, np.ndarray]:
        pairs = {key: values[self.first : self.end].copy() for key, values in self._ensemble.pairs().items()}
        partner = pairs["overlap_partner"]
        pairs["overlap_partner"] = np.where(partner >= 0, partner - self.first, partner).astype(partner.dtype)
        return pairs

    def diagnostics(self, state: State | None = None, pairs: dict | None = None) -> dict:
        state = self.state if state is None else state
        return state_diagnostics(state, self.pair_observables() if pairs is None else pairs)

    def work(self) -> np.ndarray:
        return self._ensemble.work()[self.first : self.end].copy()

    def take_deepest_contact(self) -> dict:
        return self._ensemble.sim.engine.take_deepest_contact(self.first, self.end)

    def candidate_overflows(self) -> int:
        return self._ensemble.sim.engine.candidate_overflows(self.first, self.end)

    def history_overflows(self) -> int:
        return self._ensemble.sim.engine.history_overflows(self.first, self.end)

    def neighbour_list_builds(self) -> int | None:
        """This system's (each system's lists are rebuilt when its own particles have moved)."""
        return self._ensemble.sim.neighbour_list_builds(self.system)

    def snapshot(self) -> dict:
        """This system's part of the ensemble's snapshot: what a Simulation stepped alone would give.
        The ensemble's is copied from the device once a step for all its systems (each copy is every
        system's particles: taken per system it made an ensemble of 8's checkpoint 8 copies), all but
        the deepest-contact records, which a system's frame starts afresh between two systems' turns."""
        whole = self._ensemble.snapshot()
        snap = {key: whole[key][self.first : self.end].copy() for key in _ARRAYS if key != "deepest_contact"}
        records = self._ensemble.sim.engine.deepest_contact_records(self.first, self.end)
        snap["deepest_contact"] = _partners_moved(records, -self.first)
        if all(key in whole for key in NEIGHBOUR_ARRAYS):
            reference, count, listed = (whole[key][self.first : self.end] for key in NEIGHBOUR_ARRAYS)
            snap.update(neighbour_arrays(reference, count, _lists_moved(count, listed, -self.first)))
        if all(key in whole for key in HISTORY_ARRAYS):
            mine = _history_moved({key: whole[key][self.first : self.end] for key in HISTORY_ARRAYS}, -self.first)
            snap.update(history_arrays(mine["contact_count"], {key: mine[key] for key in HISTORY_ARRAYS[1:]}))
        snap.update(step=self.step_count, time_origin=self._time_origin, ledger=True, energy_start=dict(self.energy_start))
        return snap

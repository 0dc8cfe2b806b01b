"""The motion of small scenes, bit for bit, on every force path and clock: the states after 200 steps
hash to what the code made when tests/data/motion_hashes.json was recorded.

This is the guard of changes that must not change arithmetic (a reshaped engine, a new module
layout): every path (the reference kernel, the fused and Newton layouts, the tree, gravity on its
own clock with all-pairs and tree gravity), both precisions, both rolling forms, an ensemble and a
resume.  A change that is meant to change the motion records the hashes anew
(``python tests/test_motion_hashes.py --record``) and comes with its equivalence table.

Warp compiles CPU kernels for the host (-march=native), so bits may differ on another processor
family; the file records the processor it was made on, and elsewhere the test skips.
"""

from __future__ import annotations

import hashlib
import json
import platform
import sys
from pathlib import Path

import numpy as np
import pytest

import decco_warp as dw
from decco_warp.layouts import newton_layout
from decco_warp.run import builtin_pile
from decco_warp.scheme import SCHEME_KEYS

RECORD = Path(__file__).parent / "data" / "motion_hashes.json"
STEPS = 200
HASHED = ("positions", "velocities", "omegas", "force", "torque", "channels", "work", "deepest_contact",
          "neighbour_reference", "neighbour_count", "neighbour_list")  # fmt: skip


def fingerprint() -> str:
    """What decides the CPU kernels' bits: Warp's version, the machine, its vector and FMA features."""
    flags = set()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                flags = set(line.split(":", 1)[1].split())
                break
    except OSError:
        pass
    features = ",".join(sorted(flags & {"fma", "avx", "avx2", "avx512f", "avx512vl", "sse4_2"}))
    return f"warp {dw._wp.config.version} {platform.machine()} {features}"


def _collision():
    """The shipped piles just touching, the target spinning (every contact channel acts)."""
    target, projectile = dw.load_pile(builtin_pile("target")), dw.load_pile(builtin_pile("projectile"))
    return dw.setup_collision(target, projectile, eta=2.0, theta_deg=30.0, gap=0.0, target_spin=(0.3, "+z"))


def _pair(state):
    """Two copies of ``state`` one after another: an ensemble of two systems."""
    other = state.copy()
    other.velocities *= 0.9
    return dw.State.from_arrays(
        np.concatenate([state.positions, other.positions]), np.concatenate([state.velocities, other.velocities]),
        np.concatenate([state.omegas, other.omegas]), np.concatenate([state.radii, other.radii]),
        np.concatenate([state.masses, other.masses]),
    )  # fmt: skip


#: name: (Params overrides, Simulation keywords, ensemble, resumed halfway)
SCENES = {
    "reference": ({}, {"force_kernel": "reference"}, False, False),
    "fused": ({}, {}, False, False),
    "fused_float64": ({}, {"precision": "float64"}, False, False),
    "fused_paper_rolling": ({"rolling_friction": "paper"}, {}, False, False),
    "newton": ({}, {"layout": "newton"}, False, False),
    "tree": ({"gravity": "tree"}, {}, False, False),
    "respa": ({"gravity_every": 5}, {}, False, False),
    "respa_float64": ({"gravity_every": 5}, {"precision": "float64"}, False, False),
    "respa_tree": ({"gravity_every": 5, "gravity": "tree"}, {}, False, False),
    "ensemble": ({}, {}, True, False),
    "ensemble_respa": ({"gravity_every": 5}, {}, True, False),
    "resume_fused": ({}, {}, False, True),
    "resume_respa": ({"gravity_every": 5}, {}, False, True),
}


def motion_hash(name: str) -> str:
    """sha256 of the scene's snapshot after STEPS steps (the arrays of HASHED that it holds)."""
    overrides, options, ensemble, resumed = SCENES[name]
    state = _collision()
    if ensemble:
        state = _pair(state)
        options = {**options, "systems": [state.n // 2, state.n // 2]}
    if options.get("layout") == "newton":
        options = {**options, "layout": newton_layout("cpu")}
    params = dw.Params(**{k: v for k, v in overrides.items() if k not in SCHEME_KEYS})
    options = {**options, "scheme": dw.Scheme(**{k: v for k, v in overrides.items() if k in SCHEME_KEYS})}
    sim = dw.Simulation(state, params, device="cpu", ledger=True, allow_unstable=True, **options)
    if resumed:
        sim.step(STEPS // 2)
        snapshot = sim.snapshot()
        sim = dw.Simulation.from_snapshot(state, params, snapshot, device="cpu", **options)
        sim.step(STEPS // 2)
    else:
        sim.step(STEPS)
    snapshot = sim.snapshot()
    digest = hashlib.sha256()
    for key in HASHED:
        if key in snapshot:
            array = np.ascontiguousarray(snapshot[key])
            digest.update(key.encode() + str(array.dtype).encode() + str(array.shape).encode() + array.tobytes())
    return digest.hexdigest()


def _recorded() -> dict:
    return json.loads(RECORD.read_text())


@pytest.mark.parametrize("name", sorted(SCENES))
def test_motion_is_bit_for_bit_what_was_recorded(name):
    recorded = _recorded()
    if recorded["fingerprint"] != fingerprint():
        pytest.skip(f"recorded on {recorded['fingerprint']}; this machine is {fingerprint()}")
    assert motion_hash(name) == recorded["scenes"][name]


def test_the_scenes_touch_and_the_resumed_runs_match_the_uninterrupted_ones():
    """The record is worth its name: the collision's piles are in contact (every channel acts), and
    a run resumed from a snapshot halfway is the uninterrupted run, bit for bit."""
    recorded = _recorded()["scenes"]
    assert recorded["resume_fused"] == recorded["fused"] and recorded["resume_respa"] == recorded["respa"]
    assert len(set(recorded.values())) == len(recorded) - 2
    state = _collision()
    sim = dw.Simulation(state, dw.Params(), device="cpu", allow_unstable=True)
    assert sim.diagnostics()["number_of_contacts"] > state.n


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        sys.exit("usage: python tests/test_motion_hashes.py --record   (records today's motion as the reference)")
    RECORD.parent.mkdir(exist_ok=True)
    scenes = {name: motion_hash(name) for name in sorted(SCENES)}
    RECORD.write_text(json.dumps({"fingerprint": fingerprint(), "steps": STEPS, "scenes": scenes}, indent=1) + "\n")
    print(f"recorded {len(scenes)} scenes in {RECORD}")

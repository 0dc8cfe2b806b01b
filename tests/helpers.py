"""Helpers shared by the tests that drive the command line and compare runs."""

import subprocess
import sys

import numpy as np


def cli(*args, env=None, cwd=None):
    """Run the ``decco-warp`` console entry in a fresh interpreter; returns the CompletedProcess."""
    return subprocess.run(
        [sys.executable, "-c", "from decco_warp.cli import main_entry; main_entry()", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=cwd,
    )


def assert_same_run(a: dict, b: dict) -> None:
    """Two trajectories (read_trajectory) hold the same frames, bit for bit, with no frame lost or repeated."""
    assert a["step"].tolist() == b["step"].tolist()
    for name in a["particles"]:
        assert np.array_equal(a["particles"][name], b["particles"][name]), name
    for name in a["observables"]:
        assert np.array_equal(a["observables"][name], b["observables"][name], equal_nan=True), name
        for data in (a, b):
            assert data["observable_step"][name].tolist() == data["step"].tolist(), name

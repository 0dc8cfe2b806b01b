"""decco-warp: soft-sphere DEM of self-gravitating rubble piles on NVIDIA Warp.

>>> import decco_warp as dw
>>> p = dw.Params(k_in=1e18, restitution=0.9, mu_k=0.3, mu_r=1e-3, dt=0.04)
>>> s = dw.State.from_arrays(positions, velocities, omegas, radii, masses)
>>> force, torque = dw.compute_forces(s, p, device="cpu")
>>> sim = dw.Simulation(s, p, device="cpu"); sim.step(100)
>>> dw.diagnostics(sim.state, p)
"""

import warp as _wp

# Warp's start-up banner and per-module compile lines are noise for users.
_wp.config.log_level = _wp.LOG_WARNING

from ._version import __version__  # noqa: E402
from .analysis import Cluster, find_clusters  # noqa: E402
from .collision import setup_collision  # noqa: E402
from .device import DeviceError, resolve_device  # noqa: E402
from .errors import DeccoError  # noqa: E402
from .diagnostics import diagnostics  # noqa: E402
from .folder import RunFolder  # noqa: E402
from .layouts import Layout  # noqa: E402
from .io import load_pile, read_trajectory, save_pile  # noqa: E402
from .params import CONTACT_LAWS, G_CGS, ROLLING_FRICTION_FORMS, Params  # noqa: E402
from .scheme import Scheme  # noqa: E402
from .pile import Formation, form_pile  # noqa: E402
from .simulation import Simulation, compute_forces  # noqa: E402
from .stability import (  # noqa: E402
    CompressionForecast,
    StabilityError,
    StabilityReport,
    check_stability,
    choose_stiffness,
    choose_time_step,
    predict_compression,
)
from .state import State  # noqa: E402

__all__ = [
    "__version__",
    "Cluster",
    "CompressionForecast",
    "find_clusters",
    "DeviceError",
    "G_CGS",
    "Layout",
    "Params",
    "Scheme",
    "ROLLING_FRICTION_FORMS",
    "CONTACT_LAWS",
    "Simulation",
    "StabilityError",
    "StabilityReport",
    "State",
    "check_stability",
    "choose_stiffness",
    "choose_time_step",
    "compute_forces",
    "DeccoError",
    "diagnostics",
    "Formation",
    "form_pile",
    "load_pile",
    "predict_compression",
    "read_trajectory",
    "resolve_device",
    "RunFolder",
    "save_pile",
    "setup_collision",
]

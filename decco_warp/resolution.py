"""Runs at another resolution: R times the particles of the same bodies (docs/model.md, "Resolution").

A pile at resolution R holds R times the particles of its recipe, each size class's radius scaled by
f = R^(-1/3), so that the body's mass and size stay.  A collision at resolution R takes the piles of
resolution R and, to keep the same contact physics, a spring k_in x f (eq. 12: the deepest overlap
then stays the same fraction of the smallest radius) and a time step dt x f (eq. 17), so that it
runs 1/f times the steps over the same simulated time; ``scale_contacts = false`` keeps the paper's
k_in and dt instead, to see how much of a change the stiffness makes.  Plain functions over raw
specification tables: the sweep (``[sweep] resolution``) and ``decco-warp piles --resolution`` use
them; what they write records ``[run] resolution``.
"""

from __future__ import annotations

import math
from pathlib import Path

from .scheme import step_multiple_of
from .sizes import parse_size_distribution
from .errors import InputError


def length_factor(resolution: float) -> float:
    """f = R^(-1/3): how a length (a radius) scales at resolution R."""
    if isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or not math.isfinite(resolution) or resolution <= 0:
        raise InputError(f"resolution must be a number > 0 (the factor on the particle count); got {resolution!r}")
    return float(resolution) ** (-1.0 / 3.0)


def pile_file(path: str, resolution: float) -> str:
    """The pile file of ``path``'s recipe at ``resolution``: NAME_xR.h5 beside NAME.h5 (R = 1: itself)."""
    if resolution == 1:
        return path
    if path.startswith("builtin:"):
        raise InputError(f"the shipped pile {path} has no other resolution; build your own (decco-warp piles FILE --resolution R)")
    p = Path(path)
    return str(p.with_name(f"{p.stem}_x{resolution:g}{p.suffix}"))


def pile_entry(entry: dict, resolution: float, default_radii: str) -> dict:
    """A ``[[pile]]`` table of ``decco-warp piles`` at ``resolution``: R x the particles, radii (or a
    power law's r_min and r_max) x f, the output renamed by :func:`pile_file`; the seed stays."""
    f = length_factor(resolution)
    if "size_distribution" in entry:
        law = parse_size_distribution(entry["size_distribution"]).scaled(f)
        return {**entry, "out": pile_file(entry["out"], resolution), "particles": max(1, round(entry["particles"] * resolution)),
                "size_distribution": law.text()}  # fmt: skip
    radii = entry.get("radii", default_radii)
    radii = [float(r) for r in (radii.split(",") if isinstance(radii, str) else radii)]
    return {**entry, "out": pile_file(entry["out"], resolution), "particles": max(1, round(entry["particles"] * resolution)),
            "radii": [r * f for r in radii]}  # fmt: skip


def scaled_run(run: dict, resolution: float, scale_contacts: bool, defaults: dict) -> dict:
    """A raw run specification (tables) at ``resolution``: its piles those of the resolution, and with
    ``scale_contacts`` k_in and dt x f (an "auto" stays "auto": it is chosen from the set-up anyway)
    and the step counts / f (frames at the same times), rounded up to whole outer steps of the K
    at the scaled dt (``gravity_every = "auto"`` an interval: more steps of the shorter dt, 16 at
    R = 4 where 10 at R = 1; with an "auto" dt its K, and the rounding, wait for that dt:
    spec.settle_auto); ``[run] resolution`` records R.  ``defaults``: the [run], [piles] and [params]
    values of keys the run does not give."""
    f = length_factor(resolution)
    run = {table: dict(values) for table, values in run.items()}
    for which in ("target", "projectile"):
        run.setdefault("piles", {})[which] = pile_file(run.get("piles", {}).get(which, defaults["piles"][which]), resolution)
    if scale_contacts:
        params = run.setdefault("params", {})
        for key in ("k_in", "dt"):
            value = params.get(key, defaults["params"][key])
            if value != "auto":
                params[key] = float(value) * f
        outer = step_multiple_of({**defaults["params"], **params}) or 1  # None: K of an "auto" dt, settled with it
        table = run.setdefault("run", {})
        for key in ("steps", "output_every", "checkpoint_every"):
            if key == "steps" and "duration" in table:
                continue  # a duration becomes steps of the scaled dt by itself
            given = table.get(key, defaults["run"].get(key))
            if given is not None:  # whole outer steps, as many more as dt is shorter (a duration converts itself)
                table[key] = max(1, math.ceil(given / f / outer)) * outer
    run.setdefault("run", {})["resolution"] = float(resolution)
    return run

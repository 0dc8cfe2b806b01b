"""Run specifications: TOML in, checked and fully resolved, TOML out.

A specification has four tables, every key optional (defaults below):

    [run]        name, steps | duration, output_every, checkpoint_every, device, precision, out,
                 allow_unstable, max_overlap
    [piles]      target, projectile          (pile files, or builtin:target / builtin:projectile)
    [collision]  eta | speed, eta_potential, theta_deg, gap, target_spin, target_spin_axis, projectile_spin,
                 projectile_spin_axis, orientation_seed
    [params]     k_in, restitution, mu_k, mu_r, dt, G, rolling_friction, contact_law, k_t_ratio, eps_t, mu_s, mu_t, beta, cohesion,
                 gravity, theta_open, gravity_every,
                 max_compression

Every problem is a :class:`SpecError` naming the table, the key and what is allowed.
The resolved form has every default filled in, ``steps`` rather than
``duration`` and exactly one of ``eta`` / ``speed``, so that a run folder's
``spec.toml`` repeats the run exactly.  ``k_in = "auto"`` (and ``dt = "auto"``,
which it implies unless dt is given) depend on the collision: they stay "auto",
with ``duration`` kept, until :func:`settle_auto` fills them in from the set-up
(decco_warp/plan.py does, once per run).  With ``gravity_every = K`` > 1 every step count (steps,
output_every, checkpoint_every) is a whole number of outer steps, a multiple of K (:func:`check_clock`);
a duration becomes steps rounded up to one.  ``gravity_every = "auto"`` is an interval of gravity,
K = the steps of dt nearest it (scheme.auto_gravity_every): resolved here where dt is a number,
settled with an "auto" dt otherwise.
"""

from __future__ import annotations

import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from .collision import DEFAULT_THETA_DEG, ETA_POTENTIALS, SPIN_AXES, spin_axis
from .scheme import GRAVITY_CHOICES, GRAVITY_INTERVAL_AUTO, PRECISIONS, SCHEME_KEYS, SCHEME_RANGES, Scheme, auto_gravity_every, choose_gravity
from .layouts import LAYOUT_CHOICES
from .params import CONTACT_LAWS, PHYSICS_RANGES, ROLLING_FRICTION_FORMS, SSDEM_CONSTANTS, Params, Range
from .stability import DEFAULT_MAX_COMPRESSION, choose_stiffness, choose_time_step
from .errors import SpecError  # noqa: F401 (re-exported: the error lives in errors.py)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib


@dataclass(frozen=True)
class Key:
    kind: type
    default: Any
    check: Callable[[Any], bool]
    allowed: str
    auto: bool = False
    """Whether the string "auto" is accepted: chosen from the set-up at run time (k_in, dt, gravity),
    or, for gravity_every, from dt as soon as dt is a number."""


def _positive(v):
    return v > 0


def _non_negative(v):
    return v >= 0


def _any(v):
    return True


def _axis(value) -> bool:
    try:
        spin_axis(value)
    except ValueError:
        return False
    return True


_AXES = ", ".join(SPIN_AXES) + " or a vector [x, y, z] (x along the velocity)"

_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")
_DEVICE = re.compile(r"auto|cpu|cuda(:\d+)?")

_PARAMS_DEFAULT = Params()
_SCHEME_DEFAULT = Scheme()


def _ranged(default, allowed: Range, auto: bool = False) -> Key:
    """A number's key with the range that Params or Scheme checks (params.py, scheme.py: one table)."""
    return Key(float, default, allowed.test, allowed.text("()") + (' or "auto"' if auto else ""), auto=auto)


SCHEMA: dict[str, dict[str, Key]] = {
    "run": {
        "name": Key(str, "default", lambda v: bool(_NAME.fullmatch(v)), "letters, digits, '.', '_' and '-'"),
        "steps": Key(int, None, _positive, "an integer >= 1"),
        "duration": Key(float, None, _positive, "> 0 (seconds of simulated time)"),
        "output_every": Key(int, 500, _positive, "an integer >= 1 (steps)"),
        "checkpoint_every": Key(int, 10_000, _positive, "an integer >= 1 (steps)"),
        "device": Key(str, "auto", lambda v: bool(_DEVICE.fullmatch(v)), "auto, cpu, cuda or cuda:N"),
        "precision": Key(str, "mixed", lambda v: v in PRECISIONS, " or ".join(PRECISIONS)),
        "layout": Key(str, "auto", lambda v: v in LAYOUT_CHOICES, ", ".join(LAYOUT_CHOICES) + " (the force kernel's layout)"),
        "out": Key(str, "runs/out", lambda v: bool(v.strip()), "a folder path"),
        "allow_unstable": Key(bool, False, _any, "true or false"),
        "max_overlap": Key(
            float, None, _positive, "> 0 (fraction of the smaller radius of a pair; a deeper contact stops the run)"
        ),
        "resolution": Key(
            float, 1.0, _positive, "> 0: a record of the resolution a sweep scaled this run to (radii, k_in, dt; docs/model.md), changing nothing itself"
        ),
    },
    "piles": {
        "target": Key(str, "builtin:target", lambda v: bool(v.strip()), "a pile file or builtin:target"),
        "projectile": Key(str, "builtin:projectile", lambda v: bool(v.strip()), "a pile file or builtin:projectile"),
    },
    "collision": {
        "eta": Key(float, None, _positive, "> 0 (KE / |U|, paper eq. 18)"),
        "speed": Key(float, None, _positive, "> 0 (relative speed, cm/s)"),
        "eta_potential": Key(
            str, "self", lambda v: v in ETA_POTENTIALS,
            "self (U: each pile's own pairs) or all (U: every pair of both piles at set-up, the cross term included)",
        ),
        "theta_deg": Key(float, DEFAULT_THETA_DEG, lambda v: 0 <= v < 90, "in [0, 90) degrees"),
        "gap": Key(float, 1e5, _non_negative, ">= 0 (cm)"),
        "target_spin": Key(float, 0.0, lambda v: 0 <= v <= 1, "in [0, 1] (fraction of breakup spin)"),
        "target_spin_axis": Key(object, "+z", _axis, _AXES),
        "projectile_spin": Key(float, 0.0, lambda v: 0 <= v <= 1, "in [0, 1] (fraction of breakup spin)"),
        "projectile_spin_axis": Key(object, "+z", _axis, _AXES),
        "orientation_seed": Key(
            int, None, _non_negative, "an integer >= 0 (turns each pile by a random rotation drawn from it: a realization)"
        ),
    },
    "params": {
        "k_in": _ranged(_PARAMS_DEFAULT.k_in, PHYSICS_RANGES["k_in"], auto=True),
        "restitution": _ranged(_PARAMS_DEFAULT.restitution, PHYSICS_RANGES["restitution"]),
        "mu_k": _ranged(_PARAMS_DEFAULT.mu_k, PHYSICS_RANGES["mu_k"]),
        "mu_r": _ranged(_PARAMS_DEFAULT.mu_r, PHYSICS_RANGES["mu_r"]),
        "dt": _ranged(_PARAMS_DEFAULT.dt, PHYSICS_RANGES["dt"], auto=True),
        "G": _ranged(_PARAMS_DEFAULT.G, PHYSICS_RANGES["G"]),
        "rolling_friction": Key(str, "couple", lambda v: v in ROLLING_FRICTION_FORMS, " or ".join(ROLLING_FRICTION_FORMS)),
        "contact_law": Key(str, _PARAMS_DEFAULT.contact_law, lambda v: v in CONTACT_LAWS, " or ".join(CONTACT_LAWS)),
        # The soft-sphere law's own constants (contact_law = "ssdem"; params.py, docs/model.md).
        **{name: _ranged(getattr(_PARAMS_DEFAULT, name), PHYSICS_RANGES[name]) for name in SSDEM_CONSTANTS},
        # The scheme's keys (scheme.py): how the model is evaluated, beside it in [params].
        "gravity": Key(str, _SCHEME_DEFAULT.gravity, lambda v: v in GRAVITY_CHOICES, " or ".join(GRAVITY_CHOICES)),
        "theta_open": _ranged(_SCHEME_DEFAULT.theta_open, SCHEME_RANGES["theta_open"]),
        "gravity_every": Key(
            int, _SCHEME_DEFAULT.gravity_every, _positive, 'an integer >= 1 (steps of dt per gravity evaluation) or "auto"', auto=True
        ),
        "max_compression": Key(
            float, DEFAULT_MAX_COMPRESSION, lambda v: 0 < v <= 1, "in (0, 1] (deepest overlap for k_in = \"auto\", fraction of the smallest radius)"
        ),
    },
}

def _count(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, int) and v >= 1


#: A sweep's settings ([sweep] of a sweep file, beside its [sweep.grid] and
#: [sweep.pile_alternatives], which sweep.py expands into runs): default, check, what it must be.
SWEEP_SCHEMA: dict[str, tuple[Any, Callable[[Any], bool], str]] = {
    "name": (None, lambda v: isinstance(v, str) and bool(_NAME.fullmatch(v)), "letters, digits, '.', '_' and '-'"),
    "out": ("runs/out", _any, ""),
    "min_members": (50, _count, "an integer >= 1"),
    "analyze_every": (1, _count, "an integer >= 1"),
    "keep_trajectory": (True, lambda v: isinstance(v, bool), "true or false"),
    "ensemble": ("auto", lambda v: v == AUTO or _count(v), 'an integer >= 1 or "auto"'),
    "realizations": (1, _count, "an integer >= 1"),
    "resolution": (1, _any, ""),  # checked by resolution.length_factor, which says why
    "scale_contacts": (True, lambda v: isinstance(v, bool), "true or false"),
}
#: What else a [sweep] table holds.
SWEEP_TABLES = ("grid", "pile_alternatives")
#: Keys of [sweep] by their earlier names, still read: {old: new}.
SWEEP_RENAMED = {"analyse_every": "analyze_every"}


def sweep_settings(sweep: dict, default_name: str) -> dict:
    """The checked settings of a [sweep] table (SWEEP_SCHEMA's defaults for what it omits; the name
    defaults to ``default_name``); SpecError names the first that is wrong."""
    for old, new in SWEEP_RENAMED.items():  # the sweep files written before the key took the command's spelling
        if old in sweep:
            if new in sweep:
                raise SpecError(f"[sweep] {old} is the earlier name of {new}: give one of them")
            sweep = {**{k: v for k, v in sweep.items() if k != old}, new: sweep[old]}
    allowed = set(SWEEP_SCHEMA) | set(SWEEP_TABLES)
    unknown = sorted(set(sweep) - allowed)
    if unknown:
        raise SpecError(f"unknown key [sweep] {unknown[0]}; allowed: {', '.join(sorted(allowed))}")
    settings = {key: sweep.get(key, default) for key, (default, _, _) in SWEEP_SCHEMA.items()}
    settings["name"] = sweep.get("name", default_name)
    settings["out"] = str(settings["out"])
    for key, (_, check, must) in SWEEP_SCHEMA.items():
        if not check(settings[key]):
            raise SpecError(f"[sweep] {key} = {settings[key]!r}: must be {must}")
    return settings


#: A pile's formation: the keys of a [[pile]] table of ``decco-warp piles`` and the defaults of
#: ``decco-warp pile``'s options.  Only their types are checked here; their ranges where a pile is
#: formed (pile.check_formation_inputs, Params), with the same messages for either command.
#: radii: a list in a [[pile]] table, comma-separated on the command line (the default's form);
#: size_distribution: a power law (sizes.POWER_LAW_FORM) in place of radii.
PILE_SCHEMA: dict[str, tuple[type, Any]] = {  # key: (type, default)
    "out": (str, None),
    "particles": (int, 5000),
    "seed": (int, 1),
    "radii": (list, "0.75e6,1.5e6,2.25e6"),
    "size_distribution": (str, None),
    "density": (float, 2.7),
    "ke_threshold": (float, 1e-5),
    "fill": (float, 0.3),
    "max_steps": (int, 5_000_000),
    "k_in": (float, _PARAMS_DEFAULT.k_in),
    "restitution": (float, _PARAMS_DEFAULT.restitution),
    "mu_k": (float, _PARAMS_DEFAULT.mu_k),
    "mu_r": (float, _PARAMS_DEFAULT.mu_r),
    "dt": (float, _PARAMS_DEFAULT.dt),
    "precision": (str, "mixed"),
    "gravity": (str, "auto"),
}


def pile_defaults() -> dict:
    """``decco-warp pile``'s option defaults (every key of PILE_SCHEMA but out)."""
    return {key: default for key, (_, default) in PILE_SCHEMA.items() if key != "out"}


def check_pile_list(raw: dict, path) -> list[dict]:
    """The [[pile]] tables of a ``decco-warp piles`` file (raw TOML), each key known and of its type,
    out and particles given (SpecError otherwise)."""
    entries = raw.get("pile")
    if set(raw) - {"pile"} or not isinstance(entries, list) or not entries:
        raise SpecError(f"{path} must hold only [[pile]] tables")
    for k, entry in enumerate(entries):
        for key, value in entry.items():
            if key not in PILE_SCHEMA:
                raise SpecError(f"[[pile]] {k + 1}: unknown key {key}; allowed: {', '.join(PILE_SCHEMA)}")
            kind = PILE_SCHEMA[key][0]
            if not (isinstance(value, kind) or kind is float and isinstance(value, int)) or isinstance(value, bool):
                raise SpecError(f"[[pile]] {k + 1}: {key} = {value!r} must be {kind.__name__}")
        if "out" not in entry or "particles" not in entry:
            raise SpecError(f"[[pile]] {k + 1}: out and particles are required")
        if "radii" in entry and "size_distribution" in entry:
            raise SpecError(f"[[pile]] {k + 1}: radii or size_distribution, not both")
    return entries


def pile_options(entry: dict) -> dict:
    """A checked [[pile]] table as ``decco-warp pile``'s options (its defaults for what it omits)."""
    options = {**pile_defaults(), **{key: value for key, value in entry.items() if key != "out"}}
    if isinstance(options["radii"], list):
        options["radii"] = ",".join(str(v) for v in options["radii"])
    return options


#: Default collision energy when neither eta nor speed is given: the low end of the paper's range,
#: where the shipped demo piles merge within the demo's 2000 s.
DEFAULT_ETA = 0.5


def load_spec_file(path) -> dict:
    """Parse a TOML file into a raw (unchecked) dictionary."""
    path = Path(path)
    if not path.is_file():
        raise SpecError(f"specification {path} does not exist")
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except tomllib.TOMLDecodeError as error:
        raise SpecError(f"specification {path} is not valid TOML: {error}") from None
    except (OSError, UnicodeDecodeError) as error:
        raise SpecError(f"specification {path} cannot be read: {error}") from None


def resolve_spec(raw: dict | None = None, overrides: dict | None = None) -> dict:
    """Check ``raw`` (from TOML) plus ``overrides`` ({table: {key: value}}, e.g. from the CLI) and fill defaults."""
    raw = raw or {}
    if not isinstance(raw, dict):
        raise SpecError("a specification must be a table of tables")
    merged: dict[str, dict] = {}
    for source in (raw, overrides or {}):
        for table, values in source.items():
            if table not in SCHEMA:
                raise SpecError(f"unknown table [{_shown(table)}]; allowed: {', '.join(f'[{t}]' for t in SCHEMA)}")
            if not isinstance(values, dict):
                raise SpecError(f"[{table}] must be a table of keys, not {values!r}")
            for key, value in values.items():
                if key not in SCHEMA[table]:
                    raise SpecError(f"unknown key [{table}] {_shown(key)}; allowed: {', '.join(SCHEMA[table])}")
                if value is not None:
                    merged.setdefault(table, {})[key] = value

    spec: dict[str, dict] = {}
    for table, keys in SCHEMA.items():
        given = merged.get(table, {})
        spec[table] = {}
        for key, rule in keys.items():
            if key in given:
                spec[table][key] = _checked(table, key, given[key], rule)
            elif rule.default is not None:
                spec[table][key] = rule.default

    run, collision, params = spec["run"], spec["collision"], spec["params"]
    if params["k_in"] == AUTO and "dt" not in merged.get("params", {}):
        params["dt"] = AUTO  # a spring chosen from the set-up needs its own time step
    if params["gravity_every"] == AUTO and params["dt"] != AUTO:  # an interval: K of this dt (an "auto" dt's with it)
        params["gravity_every"] = auto_gravity_every(params["dt"])
        auto_clock = True
    else:
        auto_clock = False
    if "steps" in run and "duration" in run:
        raise SpecError("[run] give steps or duration, not both")
    if "duration" in run and params["dt"] != AUTO:
        run["steps"] = steps_of(run.pop("duration"), params["dt"], params["gravity_every"])
    if "duration" not in run:
        run.setdefault("steps", 50_000)
    if "eta" in collision and "speed" in collision:
        raise SpecError("[collision] give eta or speed, not both")
    if "eta" not in collision and "speed" not in collision:
        collision["eta"] = DEFAULT_ETA
    try:
        Params(**{key: value for key, value in params_values(spec).items() if value != AUTO})
        Scheme(**{key: value for key, value in scheme_values(spec).items() if value != AUTO})
    except ValueError as error:
        raise SpecError(f"[params] {error}") from None
    check_clock(spec, auto_clock)
    return spec


def check_clock(spec: dict, auto: bool = False) -> None:
    """Refuse (SpecError, naming them) step counts that are not whole outer steps of gravity_every
    (an "auto" one not yet settled: checked once it is); ``auto``: K was chosen from dt (the line says how)."""
    params, run = spec["params"], spec["run"]
    every = params["gravity_every"]
    if every == AUTO:
        return
    bad = [f"{key} = {run[key]}" for key in ("steps", "output_every", "checkpoint_every") if key in run and run[key] % every]
    if bad:
        how = f' ("auto": gravity every {GRAVITY_INTERVAL_AUTO:g} s at dt = {params["dt"]:g} s; a duration becomes whole outer steps)' if auto else ""
        raise SpecError(
            f"[run] {', '.join(bad)}: with [params] gravity_every = {every}{how}, steps, output_every and checkpoint_every "
            f"must be multiples of {every} (whole outer steps)"
        )


#: The value of a key chosen from the collision set-up at run time.
AUTO = "auto"


def whole_outer_steps(steps: int, every: int) -> int:
    """``steps`` rounded up to a multiple of ``every`` (whole outer steps of gravity_every)."""
    return every * math.ceil(steps / every)


def steps_of(duration: float, dt: float, every: int = 1) -> int:
    """The steps of dt that cover ``duration``, rounded up to whole outer steps of ``every``."""
    return whole_outer_steps(max(1, math.ceil(duration / dt - 1e-9)), every)


def settle_auto(spec: dict, state, device: str = "cpu") -> tuple[dict, list[str]]:
    """A copy of ``spec`` with "auto" k_in and dt chosen for the collision ``state`` (paper eqs. 12
    and 17, docs/model.md), an "auto" gravity solver for its size on ``device``, an "auto"
    gravity_every that waited for that dt chosen from it (its step counts rounded up to whole outer
    steps: they could not be given as multiples of a K not yet known), and a duration turned into
    steps; plus one line per choice made."""
    spec = {table: dict(values) for table, values in spec.items()}
    params, run = spec["params"], spec["run"]
    notes = []
    if params["gravity"] == AUTO:
        params["gravity"] = choose_gravity(state.n, device)
        notes.append(f'gravity = "auto": {params["gravity"]} for {state.n} particles on {device}')
    if params["k_in"] == AUTO:
        try:
            params["k_in"] = choose_stiffness(state, params["max_compression"])
        except ValueError as error:
            raise SpecError(f'[params] k_in = "auto": {error}') from None
        notes.append(
            f'k_in = "auto": {params["k_in"]:.3g} dyne/cm, the softest spring whose predicted deepest overlap '
            f"is {params['max_compression']:g} of the smallest radius"
        )
    if params["dt"] == AUTO:
        params["dt"] = choose_time_step(state, params["k_in"])
        notes.append(f'dt = "auto": {params["dt"]:.3g} s, eq. 17 with the required margin for k_in = {params["k_in"]:.3g} dyne/cm')
    if params["gravity_every"] == AUTO:
        every = params["gravity_every"] = auto_gravity_every(params["dt"])
        notes.append(f'gravity_every = "auto": {every}, gravity every {every * params["dt"]:.3g} s '
                     f'(the steps of {params["dt"]:.3g} s nearest {GRAVITY_INTERVAL_AUTO:g} s)')  # fmt: skip
        for key in ("steps", "output_every", "checkpoint_every"):
            if key in run and run[key] % every:
                rounded = whole_outer_steps(run[key], every)
                notes.append(f"{key} {run[key]} rounded up to {rounded}: whole outer steps of gravity_every = {every}")
                run[key] = rounded
    if "duration" in run:
        duration = run.pop("duration")
        run["steps"] = steps_of(duration, params["dt"], params["gravity_every"])
        notes.append(f"duration {duration:g} s: {run['steps']} steps of {params['dt']:.3g} s")
    check_clock(spec)
    return spec, notes


def _shown(name) -> str:
    """A name from the user's file as it can be shown on one line."""
    text = str(name)
    return text if text.isprintable() and text.strip() == text and text else repr(text)


def _checked(table: str, key: str, value, rule: Key):
    where = f"[{table}] {key} = {value!r}"
    if rule.auto and value == AUTO:
        return value
    if rule.kind is bool:
        ok = isinstance(value, bool)
    elif rule.kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif rule.kind is float:
        ok = isinstance(value, (int, float)) and not isinstance(value, bool)
        if ok:
            value = float(value)
            ok = math.isfinite(value)
    elif rule.kind is object:  # checked by its rule alone (a spin axis: a name or a vector)
        ok = True
    else:
        ok = isinstance(value, str)
    if not ok:
        raise SpecError(f"{where}: must be {rule.kind.__name__} {rule.allowed}")
    if not rule.check(value):
        raise SpecError(f"{where}: must be {rule.allowed}")
    return value


def params_values(spec: dict) -> dict:
    """The [params] entries that are Params fields (the scheme's keys are Scheme's; max_compression
    only steers k_in = "auto")."""
    return {key: value for key, value in spec["params"].items() if key != "max_compression" and key not in SCHEME_KEYS}


def scheme_values(spec: dict) -> dict:
    """The entries of a specification that are Scheme fields: the scheme's [params] keys and [run] precision."""
    return {**{key: spec["params"][key] for key in SCHEME_KEYS if key in spec["params"]}, "precision": spec["run"]["precision"]}


def params_of(spec: dict) -> Params:
    values = params_values(spec)
    if AUTO in values.values():
        raise SpecError("[params] k_in and dt must be settled from the collision set-up first (settle_auto)")
    return Params(**values)


def scheme_of(spec: dict) -> Scheme:
    """The Scheme a specification asks for (its layout settled by the plan, which knows the device)."""
    values = scheme_values(spec)
    if AUTO in values.values():
        raise SpecError("[params] gravity must be settled from the collision set-up first (settle_auto)")
    return Scheme(**values)


def spin_of(spec: dict, which: str):
    fraction = spec["collision"][f"{which}_spin"]
    return (fraction, spec["collision"][f"{which}_spin_axis"]) if fraction > 0 else None


def dumps(spec: dict, header: str = "") -> str:
    """TOML text of a resolved specification (tables of scalars)."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    for table, values in spec.items():
        lines.append("")
        lines.append(f"[{table}]")
        for key, value in values.items():
            lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines).lstrip("\n") + "\n"


def _toml_value(value) -> str:
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value)
    text = str(value).replace("\\", "\\\\").replace('"', '\\"')
    return f'"{text}"'

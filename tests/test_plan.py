"""A run's plan: a specification resolved once, in one pass, into a frozen Plan; ``--check`` prints it."""

import dataclasses
import hashlib
import math

import pytest
from helpers import cli

import decco_warp as dw
from decco_warp.scheme import SCHEME_KEYS
from decco_warp import spec as specs
from decco_warp.layouts import choose_layout
from decco_warp.plan import Plan, builtin_pile
from decco_warp.run import prepare_resume, prepare_start, start_run


def _sha256(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def counted(monkeypatch):
    """Calls into spec.py's resolution functions, counted by name."""
    calls = {"settle_auto": 0, "params_of": 0, "spin_of": 0, "resolve_spec": 0}
    for name in calls:
        original = getattr(specs, name)

        def counting(*args, _name=name, _original=original, **kwargs):
            calls[_name] += 1
            return _original(*args, **kwargs)

        monkeypatch.setattr(specs, name, counting)
    return calls


def _auto_spec(tmp_path, **run):
    return specs.resolve_spec(
        {
            "run": {"name": "p", "out": str(tmp_path), "device": "cpu", "duration": 4.0, "output_every": 50, **run},
            "params": {"k_in": "auto"},
            "collision": {"speed": 2.4e5, "theta_deg": 0.0, "orientation_seed": 7},
        }
    )


def test_a_spec_is_resolved_once_into_a_frozen_plan_with_no_auto_left(tmp_path, counted):
    spec = _auto_spec(tmp_path)
    assert spec["params"]["k_in"] == spec["params"]["dt"] == "auto" and spec["run"]["duration"] == 4.0
    counted["resolve_spec"] = 0
    prepared = prepare_start(spec)
    plan = prepared.plan
    # One pass: the spec's "auto" values settled once, its Params made once, each pile's spin read once.
    assert counted == {"settle_auto": 1, "params_of": 1, "spin_of": 2, "resolve_spec": 0}

    assert isinstance(plan, Plan)
    settled = plan.spec
    # Every "auto" settled: in [params] (recorded in spec.toml), and in the plan's own choices
    # ([run] device and layout keep the user's words in spec.toml; the plan holds what they chose).
    assert "auto" not in settled["params"].values() and "duration" not in settled["run"]
    fields = {field.name: getattr(plan, field.name) for field in dataclasses.fields(plan) if field.name != "spec_items"}
    assert "auto" not in [value for value in fields.values() if isinstance(value, str)]
    assert "auto" not in dataclasses.asdict(plan.params).values()
    assert plan.params == dw.Params(**{k: v for k, v in settled["params"].items() if k != "max_compression" and k not in SCHEME_KEYS})
    assert plan.scheme == dw.Scheme(**{k: settled["params"][k] for k in SCHEME_KEYS}, precision=settled["run"]["precision"], layout=plan.layout)
    assert plan.steps == settled["run"]["steps"] == math.ceil(4.0 / plan.params.dt - 1e-9)
    # k_in = "auto" is the softest spring whose predicted deepest overlap is max_compression (0.1).
    assert plan.forecast.fraction == pytest.approx(0.1, rel=0.02)
    assert plan.stability.stable and plan.stability.k_in == plan.params.k_in and plan.stability.dt == plan.params.dt
    assert plan.scheme.gravity == "all-pairs"  # "auto" for a few hundred particles on the CPU

    # Piles read with their files and SHA-256; the collision turned by orientation_seed.
    assert [(p.which, p.file, p.sha256) for p in plan.piles] == [
        (which, str(builtin_pile(which).resolve()), _sha256(builtin_pile(which))) for which in ("target", "projectile")
    ]
    assert plan.state.metadata["orientation_seed"] == 7 and plan.state.n == 450
    # The device, layout and precision the simulation runs with are the plan's.
    assert plan.device == prepared.sim.device == "cpu"
    assert plan.layout == prepared.sim.engine.layout == choose_layout(plan.state.n, "cpu")
    assert plan.precision == prepared.sim.engine.precision == "mixed"
    assert prepared.sim.stability is plan.stability  # made once, not again by the Simulation
    assert plan.outputs.run_dir == prepared.run_dir == tmp_path / "p"
    assert (plan.outputs.output_every, plan.outputs.checkpoint_every) == (50, 10_000)
    assert not (tmp_path / "p").exists()  # planning writes nothing

    # Frozen: no field can be set, and the spec it hands out is a copy.
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.steps = 1
    with pytest.raises(dataclasses.FrozenInstanceError):
        plan.outputs.output_every = 1
    with pytest.raises(ValueError, match="read-only"):
        plan.state.positions[0, 0] = 0.0
    settled["run"]["steps"] = 1
    settled["params"]["k_in"] = 1.0
    assert plan.spec["run"]["steps"] == plan.steps != 1 and plan.spec["params"]["k_in"] == plan.params.k_in


def test_a_resumed_run_is_planned_from_its_folder_without_resolving_again(tmp_path, monkeypatch):
    first = start_run(_auto_spec(tmp_path, duration=None, steps=100, checkpoint_every=50))
    started = specs.resolve_spec(specs.load_spec_file(first.run_dir / "spec.toml"))
    calls = {"settle_auto": 0}
    monkeypatch.setattr(specs, "settle_auto", lambda *a, **k: calls.__setitem__("settle_auto", 1))
    prepared = prepare_resume(first.run_dir, steps=150)
    try:
        plan = prepared.plan
        assert calls["settle_auto"] == 0  # the folder's spec.toml is settled already
        assert plan.steps == 150 and plan.spec["run"]["steps"] == 150
        assert plan.params == dw.Params(**{k: v for k, v in started["params"].items() if k != "max_compression" and k not in SCHEME_KEYS})
        assert plan.run_dir == first.run_dir and plan.device == prepared.sim.device == "cpu"
        assert plan.layout == prepared.sim.engine.layout and prepared.sim.step_count == 100
        # Until the run is executed its folder keeps the steps it was started with.
        assert specs.load_spec_file(first.run_dir / "spec.toml")["run"]["steps"] == 100
    finally:
        prepared.lock.release()


def test_check_prints_the_plan_and_writes_nothing(tmp_path):
    result = cli(
        "simulate", "--check", "--device", "cpu", "--steps", "300", "--output-every", "30", "--layout", "newton",
        "--out", str(tmp_path),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("collision: 450 particles (300 target + 150 projectile)")
    assert "parameters: k_in 1e+18 dyne/cm, dt 0.04 s, 300 steps (12 s), force layout newton" in lines
    target, projectile = builtin_pile("target"), builtin_pile("projectile")
    assert (
        f"piles: target {target.resolve()} (sha256 {_sha256(target)[:12]}), "
        f"projectile {projectile.resolve()} (sha256 {_sha256(projectile)[:12]})"
    ) in lines
    newton = dw.Layout(block_dim=1, particles_per_block=4, newton=True)
    assert f"device: cpu, precision mixed, force layout {newton.describe()}" in lines
    assert f"outputs: {tmp_path / 'default'}, a frame every 30 steps, a checkpoint every 10000 steps" in lines
    assert any(line.startswith("physics: restitution 0.9, mu_k 0.3") and "gravity all-pairs" in line for line in lines)
    assert lines[-1].startswith("verdict: would run")
    assert not any(tmp_path.iterdir())

"""Deep overlaps (docs/model.md): recorded and warned about, never a stop by themselves; the
predicted deepest compression (eq. 12 with i the heavier sphere); ``--check``; ``k_in = "auto"``."""

import math
import re

import numpy as np
import pytest
from helpers import cli
from scenes import RADII, overlapping_cloud, sphere_mass

import decco_warp as dw
from decco_warp import spec as specs
from decco_warp.stability import MIN_TIME_STEP_MARGIN, choose_stiffness, choose_time_step, impact_speed, predict_compression

#: Head-on at 2.4 km/s, the shipped piles: contacts pass half and then the whole small radius.
FAST = ["--speed", "240000", "--theta", "0", "--device", "cpu"]


def numpy_deepest(positions, radii):
    """Independent float64: the deepest overlap over all pairs as a fraction of the pair's smaller radius."""
    i, j = np.triu_indices(len(radii), k=1)
    d = np.linalg.norm(positions[i] - positions[j], axis=1)
    depth = (radii[i] + radii[j] - d) / np.minimum(radii[i], radii[j])
    k = int(np.argmax(depth))
    return depth[k], (int(i[k]), int(j[k]))


def test_deepest_overlap_of_a_state_matches_numpy(device):
    state = overlapping_cloud(150, seed=5, fill=0.9)
    d = dw.diagnostics(state, dw.Params(), device=device)
    depth, pair = numpy_deepest(state.positions, state.radii)
    assert depth > 0.3  # the scene has deep contacts
    assert d["deepest_overlap"] == pytest.approx(depth, rel=1e-12)
    assert tuple(d["deepest_overlap_pair"]) == pair


def test_no_contact_reports_zero_and_no_pair():
    state = dw.State.from_arrays([[0, 0, 0], [1e8, 0, 0]], np.zeros((2, 3)), np.zeros((2, 3)), RADII[:2], sphere_mass(RADII[:2]))
    d = dw.diagnostics(state, dw.Params(), device="cpu")
    assert d["deepest_overlap"] == 0.0 and tuple(d["deepest_overlap_pair"]) == (-1, -1)


def _two_piles(speed, spin=0.0):
    """Two small 'piles': a target at rest (optionally spinning about z) and a projectile moving at +x."""
    rng = np.random.default_rng(3)
    radii = rng.choice(RADII, size=12)
    x = rng.normal(size=(12, 3)) * 5e6
    x[6:, 0] -= 5e7
    v = np.zeros((12, 3))
    v[6:, 0] = speed
    v[:6] += spin * np.cross([0.0, 0.0, 1.0], x[:6])
    pile_id = np.repeat([0, 1], 6).astype(np.int32)
    return dw.State.from_arrays(x, v, np.zeros((12, 3)), radii, sphere_mass(radii), pile_id=pile_id)


def test_prediction_is_eq_12_with_the_heaviest_sphere_into_the_lightest():
    state = _two_piles(speed=1.0e5)
    k_in = 1e18
    forecast = predict_compression(state, k_in)
    heavy, light = state.masses.max(), state.masses.min()
    assert forecast.impact_speed == pytest.approx(1.0e5, rel=1e-12)
    # 1/2 m_H v^2 = (k/4) delta^2: eq. 12 with m_j -> infinity, delta twice the spring compression.
    delta = 2.0 * math.sqrt(0.5 * heavy * 1.0e5**2 / k_in)
    assert forecast.overlap == pytest.approx(delta, rel=1e-12)
    assert forecast.fraction == pytest.approx(delta / state.radii[np.argmin(state.masses)], rel=1e-12)
    assert forecast.light_mass == light
    # A spinning target adds its fastest surface speed relative to its own bulk motion.
    spinning = _two_piles(speed=1.0e5, spin=1e-3)
    m, v = spinning.masses[:6], spinning.velocities
    bulk = (m[:, None] * v[:6]).sum(axis=0) / m.sum()
    expected = np.linalg.norm(v[6:] - bulk, axis=1).max() + np.linalg.norm(v[:6] - bulk, axis=1).max()
    assert impact_speed(spinning) == pytest.approx(expected, rel=1e-12) and expected > 1.0e5 + 1e3


def test_auto_stiffness_meets_the_compression_asked_for_and_eq_17():
    state = _two_piles(speed=1.2e5)
    for wanted in (0.05, 0.1, 0.3):
        k_in = choose_stiffness(state, wanted)
        assert wanted * (1 - 2e-3) <= predict_compression(state, k_in).fraction <= wanted
        dt = choose_time_step(state, k_in)
        margin = dw.check_stability(state, dw.Params(k_in=k_in, dt=dt)).time_step_margin
        assert MIN_TIME_STEP_MARGIN <= margin < MIN_TIME_STEP_MARGIN * (1 + 2e-3)
    with pytest.raises(ValueError, match="max_compression"):
        choose_stiffness(state, 0.0)


def test_auto_keys_in_specs():
    spec = specs.resolve_spec({"params": {"k_in": "auto"}, "run": {"duration": 100.0}})
    assert spec["params"]["k_in"] == "auto" and spec["params"]["dt"] == "auto"
    assert spec["run"]["duration"] == 100.0 and "steps" not in spec["run"]  # steps wait for dt
    assert spec["params"]["max_compression"] == 0.1
    given_dt = specs.resolve_spec({"params": {"k_in": "auto", "dt": 0.01}, "run": {"duration": 100.0}})
    assert given_dt["params"]["dt"] == 0.01 and given_dt["run"]["steps"] == 10_000
    settled, notes = specs.settle_auto(spec, _two_piles(speed=1.2e5))
    assert isinstance(settled["params"]["k_in"], float) and isinstance(settled["params"]["dt"], float)
    assert settled["run"]["steps"] == math.ceil(100.0 / settled["params"]["dt"] - 1e-9) and len(notes) == 3
    assert specs.resolve_spec(settled) == settled  # the settled spec repeats itself
    for bad in ({"params": {"mu_k": "auto"}}, {"params": {"k_in": "soft"}}, {"params": {"max_compression": 2.0}}):
        with pytest.raises(specs.SpecError):
            specs.resolve_spec(bad)
    with pytest.raises(specs.SpecError, match="settle"):
        specs.params_of(spec)


@pytest.fixture(scope="module")
def fast_run(tmp_path_factory):
    """The shipped piles head-on at 2.4 km/s with the paper's k_in: contacts deeper than a small radius."""
    out = tmp_path_factory.mktemp("fast")
    result = cli("simulate", *FAST, "--steps", "1200", "--output-every", "50", "--name", "fast", "--out", str(out))
    return out / "fast", result


def test_deep_overlaps_are_warned_about_and_the_run_goes_on(fast_run):
    run_dir, result = fast_run
    assert result.returncode == 0, result.stderr
    log = (run_dir / "run.log").read_text()
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    radii = data["static"]["radius"]
    # Every frame's deepest overlap (the deepest since the previous frame) is at least that of the
    # frame's own positions, by NumPy; the step-by-step equality is the test below.
    steps, depths = data["step"].tolist(), data["observables"]["deepest_overlap"]
    for k in range(len(steps)):
        depth, pair = numpy_deepest(data["particles"]["position"][k], radii)
        assert depths[k] >= max(depth, 0.0) * (1 - 1e-9)
        if depths[k] == pytest.approx(depth, rel=1e-9):
            assert tuple(data["observables"]["deepest_overlap_pair"][k]) == pair
    assert (depths[1:] > 1e-3 + np.array([numpy_deepest(x, radii)[0] for x in data["particles"]["position"][1:]])).any()
    # One warning past 0.5 and one past 1, each naming the steps since the previous frame and the
    # pair, also on the progress line.
    warnings = re.findall(r"warning: steps (\d+) to (\d+): particles (\d+) and (\d+) overlap by ([\d.]+) of the smaller radius", log)
    assert len(warnings) == 2, log
    for (first, step, i, j, depth), level in zip(warnings, (0.5, 1.0)):
        k = steps.index(int(step))
        assert int(first) == steps[k - 1] + 1
        assert float(depth) > level and depths[:k].max() <= level
        assert tuple(data["observables"]["deepest_overlap_pair"][k]) == (int(i), int(j))
        assert f"warning: steps {first} to {step}" in result.stderr
    k = int(np.argmax(depths))
    assert re.search(rf"done: step 1200.*deepest overlap {depths[k]:.3g} of the smaller radius at steps {steps[k - 1] + 1} to {steps[k]}", log)
    # The energy books still balance (the ledger closes) and momentum is kept.
    obs = data["observables"]
    books = obs["total_energy"] + obs["dissipated_sliding"] + obs["dissipated_rolling"] + obs["dissipated_hysteresis"] + obs["integration_error"]
    np.testing.assert_allclose(books, obs["total_energy"][0], rtol=1e-10)
    assert "ledger closed to" in log


ENGINES = {
    "tiled": {},
    "newton": {"layout": dw.Layout(block_dim=1, particles_per_block=3, newton=True)},
    "reference": {"force_kernel": "reference"},
    "tree": {"gravity": "tree"},
}


@pytest.mark.parametrize("engine", ENGINES)
def test_the_record_holds_the_deepest_contact_of_every_step_since_it_was_taken(device, engine):
    """Taken every step, the record is that step's deepest contact by NumPy (to its 6e-8
    quantisation); taken every 8 steps, it is the deepest of those 8 (same pair)."""
    options = dict(ENGINES[engine])
    if engine == "newton" and device.startswith("cuda"):  # a Newton block is one warp there, each lane keeping two particles
        options["layout"] = dw.Layout(block_dim=32, particles_per_block=64, newton=True)
    params, scheme = dw.Params(dt=0.01), dw.Scheme(gravity=options.pop("gravity", "all-pairs"))
    state = overlapping_cloud(150, seed=7, fill=0.9)
    every_step = dw.Simulation(state, params, device=device, allow_unstable=True, scheme=scheme, **options)
    every_eighth = dw.Simulation(state, params, device=device, allow_unstable=True, scheme=scheme, **options)
    start = every_step.take_deepest_contact()
    depth, pair = numpy_deepest(state.positions, state.radii)
    assert start["deepest_overlap"] == pytest.approx(depth, abs=1e-7) and tuple(start["deepest_overlap_pair"]) == pair
    every_eighth.take_deepest_contact()
    seen = []
    for block in range(4):
        for _ in range(8):
            every_step.step(1)
            record = every_step.take_deepest_contact()
            depth, pair = numpy_deepest(every_step.state.positions, state.radii)
            assert record["deepest_overlap"] == pytest.approx(depth, abs=1e-7) and depth > 0.05
            assert tuple(record["deepest_overlap_pair"]) == pair
            seen.append(record)
        every_eighth.step(8)
        record = every_eighth.take_deepest_contact()
        deepest = max(seen[-8:], key=lambda r: r["deepest_overlap"])
        assert record["deepest_overlap"] == pytest.approx(deepest["deepest_overlap"], abs=1e-7)
        assert tuple(record["deepest_overlap_pair"]) == tuple(deepest["deepest_overlap_pair"])
    depths = [r["deepest_overlap"] for r in seen]
    assert depths[0] > depths[-1] + 1e-3  # the cloud's deepest contact relaxes: a record only sampled would differ
    assert every_step.take_deepest_contact()["deepest_overlap_pair"].tolist() == [-1, -1]  # taken: nothing since


def test_predicted_deepest_overlap_bounds_the_measured_one(fast_run):
    """The prediction (in run.log and the trajectory) is an upper estimate, and not a vacuous one."""
    run_dir, _ = fast_run
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    predicted = data["parameters"]["stability"]["predicted_overlap"]
    measured = data["observables"]["deepest_overlap"].max()
    assert f"predicted deepest overlap {predicted:.3g}" in (run_dir / "run.log").read_text()
    assert 0.2 * predicted < measured < predicted


def test_max_overlap_stops_a_run_at_the_limit(tmp_path):
    result = cli("simulate", *FAST, "--steps", "1200", "--output-every", "50", "--max-overlap", "0.3", "--out", str(tmp_path))
    assert result.returncode == 4, result.stderr
    message = result.stderr.strip().splitlines()[-1]
    assert "max_overlap = 0.3" in message and re.search(r"particles \d+ and \d+ overlap by", message)
    assert (tmp_path / "default" / "checkpoint.h5").is_file()


def test_check_prints_the_margins_and_prediction_and_writes_nothing(tmp_path):
    result = cli("simulate", *FAST, "--check", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    assert "eq. 15 stiffness margin" in result.stdout and "eq. 17 time-step margin" in result.stdout
    predicted = float(re.search(r"predicted deepest overlap ([\d.e+-]+) of the smallest radius", result.stdout).group(1))
    assert predicted > 1 and "outside the model's validity" in result.stdout
    assert not any(tmp_path.iterdir())
    unstable = cli("simulate", "--check", "--dt", "5", "--device", "cpu", "--out", str(tmp_path))
    assert unstable.returncode == 2 and "eq. 17" in unstable.stderr and not any(tmp_path.iterdir())
    auto = cli("simulate", *FAST, "--check", "--k-in", "auto", "--duration", "60", "--out", str(tmp_path))
    assert auto.returncode == 0, auto.stderr
    assert 'k_in = "auto"' in auto.stdout and "predicted deepest overlap 0.1 of the smallest radius" in auto.stdout
    bad = cli("simulate", "--check", "--k-in", "stiff")
    assert bad.returncode == 2 and "--k-in" in bad.stderr


def test_auto_stiffness_run_keeps_contacts_shallow_and_records_its_choice(tmp_path):
    result = cli("simulate", *FAST, "--k-in", "auto", "--duration", "50", "--output-every", "250", "--out", str(tmp_path))
    assert result.returncode == 0, result.stderr
    run_dir = tmp_path / "default"
    spec = specs.resolve_spec(specs.load_spec_file(run_dir / "spec.toml"))
    k_in, dt = spec["params"]["k_in"], spec["params"]["dt"]
    assert isinstance(k_in, float) and isinstance(dt, float) and k_in > 1e20
    assert spec["run"]["steps"] == math.ceil(50 / dt - 1e-9)
    data = dw.read_trajectory(run_dir / "trajectory.h5")
    assert data["observables"]["deepest_overlap"].max() < 0.1  # what max_compression asked for
    assert 'k_in = "auto"' in (run_dir / "run.log").read_text()
    # The settled spec resumes and extends like any other.
    more = cli("resume", str(run_dir), "--steps", str(spec["run"]["steps"] + 250))
    assert more.returncode == 0, more.stderr


def test_block_per_particle_observables_equal_the_plain_loop(device):
    """The observables kernel that frames use (a block of threads per particle, reduced) against
    the plain loop, one thread per particle, particle by particle: sums to round-off (the same
    bits on the CPU, where a block is one thread), counts, largest overlaps and deepest contacts
    exactly, and among equally deep contacts the partner of lowest index, as the loop keeps."""
    import warp as wp

    from decco_warp.engine import PAIR_OBSERVABLES
    from decco_warp.kernels import observables

    cloud = overlapping_cloud(300, seed=6, fill=0.9)
    # Particle 0 pressed equally by 1 and 2 (mirror images: the same depth to the last bit), and by 3 less.
    r = RADII[0]
    tie = np.array([[0.0, 0.0, 0.0], [1.5 * r, 0.0, 0.0], [-1.5 * r, 0.0, 0.0], [0.0, 1.8 * r, 0.0]]) + 4e9
    radii = np.concatenate([np.full(4, r), cloud.radii])
    positions = np.vstack([tie, cloud.positions])
    state = dw.State.from_arrays(positions, np.zeros_like(positions), np.zeros_like(positions), radii, sphere_mass(radii))
    engine = dw.Simulation(state, dw.Params(), device=device, allow_unstable=True).engine
    tiled = engine.pair_observables()
    outputs = [wp.zeros(engine.count, dtype=dtype, device=engine.device) for dtype in PAIR_OBSERVABLES.values()]
    wp.launch(observables.pair_observables, dim=engine.count, device=engine.device, outputs=outputs,
              inputs=[engine.contact, engine.ranges, engine.radius, engine.mass, engine.position, engine.velocity])  # fmt: skip
    plain = {name: array.numpy() for name, array in zip(PAIR_OBSERVABLES, outputs)}
    assert tiled["overlap_partner"][0] == 1 and plain["overlap_partner"][0] == 1
    assert tiled["contacts"].sum() > engine.count  # a crowded scene
    for name in PAIR_OBSERVABLES:
        if name in ("potential", "elastic") and device.startswith("cuda"):
            np.testing.assert_allclose(tiled[name], plain[name], rtol=1e-12, atol=0)
        else:
            np.testing.assert_array_equal(tiled[name], plain[name], err_msg=name)


CPU_BLOCKS = """
import sys
import numpy as np, warp as wp
wp.config.enable_cpu_blocks = True  # the CPU runs every lane of a block: the reductions are exercised
wp.config.kernel_cache_dir = sys.argv[1]
import decco_warp as dw
from decco_warp.engine import PAIR_OBSERVABLES
from decco_warp.kernels import observables
scene = np.load(sys.argv[2])
zeros = np.zeros_like(scene["positions"])
state = dw.State.from_arrays(scene["positions"], zeros, zeros, scene["radii"], scene["masses"])
engine = dw.Simulation(state, dw.Params(), device="cpu", allow_unstable=True).engine
def run(kernel, block):
    outs = [wp.zeros(engine.count, dtype=d, device="cpu") for d in PAIR_OBSERVABLES.values()]
    args = dict(inputs=[engine.contact, engine.ranges, engine.radius, engine.mass, engine.position, engine.velocity], outputs=outs, device="cpu")
    wp.launch(kernel, dim=engine.count, **args) if block == 0 else wp.launch_tiled(kernel, dim=[engine.count], block_dim=block, **args)
    return {n: a.numpy() for n, a in zip(PAIR_OBSERVABLES, outs)}
plain = run(observables.pair_observables, 0)
assert plain["overlap_partner"][0] == 1
for block in (8, 32):
    got = run(observables.pair_observables_tiled(block), block)
    for n in PAIR_OBSERVABLES:
        same = np.allclose(got[n], plain[n], rtol=1e-12, atol=0) if n in ("potential", "elastic") else np.array_equal(got[n], plain[n])
        assert same, (block, n)
print("SAME")
"""


def test_observables_reduced_across_many_lanes_equal_the_plain_loop(tmp_path):
    """The same check with blocks of 8 and 32 lanes really run on the CPU (Warp's CPU blocks, in a
    fresh interpreter), on a squeezed copy of the shipped pile and an exact tie, so that the sums,
    maxima and the deepest-partner choice are reduced across lanes as on a GPU."""
    import subprocess
    import sys

    from decco_warp.run import builtin_pile

    pile = dw.load_pile(builtin_pile("target"))
    r = RADII[0]  # particle 0 pressed equally by 1 and 2 (mirror images), which sit on different lanes
    tie = np.array([[0.0, 0.0, 0.0], [1.5 * r, 0.0, 0.0], [-1.5 * r, 0.0, 0.0], [0.0, 1.8 * r, 0.0]]) + 4e9
    positions = np.vstack([tie, 0.97 * pile.positions])  # squeezed: deeper contacts
    radii = np.concatenate([np.full(4, r), pile.radii])
    np.savez(tmp_path / "scene.npz", positions=positions, radii=radii, masses=sphere_mass(radii))
    done = subprocess.run([sys.executable, "-c", CPU_BLOCKS, str(tmp_path / "cache"), str(tmp_path / "scene.npz")],
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0 and "SAME" in done.stdout, (done.stdout + done.stderr)[-3000:]

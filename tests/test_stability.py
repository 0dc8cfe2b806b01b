"""Paper sect. 2.5: the margins of eqs. 15 and 17 and the refusal of unstable set-ups."""

import math

import numpy as np
import pytest
from scenes import sphere_mass, two_spheres

import decco_warp as dw
from decco_warp.stability import MIN_STIFFNESS_MARGIN, MIN_TIME_STEP_MARGIN


def _pair(speed=100.0):
    return two_spheres(4e6, velocity_i=(speed, 0, 0), velocity_j=(-speed, 0, 0), radius=1.5e6)


def test_margins_by_hand():
    state = _pair(speed=100.0)
    params = dw.Params(k_in=1e18, dt=0.04)
    report = dw.check_stability(state, params)
    mass = float(sphere_mass(1.5e6))
    # eq. 17: sqrt(m_min / k) / dt
    assert report.time_step_margin == pytest.approx(math.sqrt(mass / 1e18) / 0.04, rel=1e-12)
    # eq. 15: k / ((4 pi / 3) rho r v_max^2), v_max in the centre-of-mass frame
    needed = 4 * math.pi / 3 * 2.7 * 1.5e6 * 100.0**2
    assert report.stiffness_margin == pytest.approx(1e18 / needed, rel=1e-12)
    assert report.stable and report.problems() == []


def test_paper_parameters_are_stable_at_the_papers_fastest_collision():
    """Largest paper particle at ~1 km/s, k_in = 1e18: the paper says eq. 15 holds (margin ~4)."""
    radii = np.array([0.75e6, 2.25e6])
    state = dw.State.from_arrays(
        [[0, 0, 0], [1e8, 0, 0]], [[-1e5, 0, 0], [1e5, 0, 0]], np.zeros((2, 3)), radii, sphere_mass(radii)
    )
    report = dw.check_stability(state, dw.Params())
    assert 1 < report.stiffness_margin < 10
    assert report.time_step_margin > 50


def test_too_long_time_step_is_refused_with_a_safe_value(device):
    state = _pair()
    mass = float(sphere_mass(1.5e6))
    limit = math.sqrt(mass / 1e18)
    params = dw.Params(dt=limit / 2)  # margin 2 < 10
    with pytest.raises(dw.StabilityError) as raised:
        dw.Simulation(state, params, device=device)
    message = str(raised.value)
    assert "dt" in message and "eq. 17" in message
    safe = raised.value.report.safe_dt
    assert safe == pytest.approx(limit / MIN_TIME_STEP_MARGIN, rel=1e-12)
    assert f"{safe:.3g}" in message
    # The safe value really is accepted, and the refusal can be overridden on purpose.
    dw.Simulation(state, dw.Params(dt=safe), device=device)
    sim = dw.Simulation(state, params, device=device, allow_unstable=True)
    assert not sim.stability.stable


def test_too_soft_spring_is_refused_with_a_safe_value():
    state = _pair(speed=1e5)
    needed = 4 * math.pi / 3 * 2.7 * 1.5e6 * 1e10
    params = dw.Params(k_in=needed / 3, dt=1e-3)
    with pytest.raises(dw.StabilityError) as raised:
        dw.Simulation(state, params, device="cpu")
    message = str(raised.value)
    assert "k_in" in message and "eq. 15" in message
    assert raised.value.report.safe_k_in == pytest.approx(MIN_STIFFNESS_MARGIN * needed, rel=1e-12)
    assert f"{raised.value.report.safe_k_in:.3g}" in message

import math

import numpy as np
import pytest

from trustfg.agent.config import VehicleConfig
from trustfg.agent.vehicle import VehicleState, step


def test_straight_and_arc_motion_are_exact():
    limits = VehicleConfig(max_accel_mps2=1e9, max_turn_accel_radps2=1e9)
    s = step(VehicleState(0, 0, 0, 0.5, 0.0), 0.5, 0.0, 2.0, limits)
    assert (s.x, s.y) == pytest.approx((1.0, 0.0))
    # A full circle of radius v/w returns to the start.
    v, w = 0.4, 0.8
    state = VehicleState(0, 0, 0, v, w)
    for _ in range(100):
        state = step(state, v, w, 2 * math.pi / w / 100, limits)
    assert (state.x, state.y) == pytest.approx((0.0, 0.0), abs=1e-9)


def test_limits_are_respected():
    limits = VehicleConfig()
    state = VehicleState(0, 0, 0)
    rng = np.random.default_rng(0)
    for _ in range(2000):
        v_cmd, w_cmd = rng.uniform(-5, 5), rng.uniform(-20, 20)
        new = step(state, v_cmd, w_cmd, 0.02, limits)
        assert -limits.max_reverse_mps - 1e-12 <= new.v <= limits.max_speed_mps + 1e-12
        assert abs(new.omega) <= limits.max_turn_rate_radps + 1e-12
        assert abs(new.v - state.v) <= limits.max_accel_mps2 * 0.02 + 1e-12
        assert abs(new.omega - state.omega) <= limits.max_turn_accel_radps2 * 0.02 + 1e-12
        state = new


def test_non_finite_commands_stop_the_car():
    limits = VehicleConfig()
    state = VehicleState(0, 0, 0, 0.5, 0.0)
    for _ in range(50):
        state = step(state, float("nan"), float("inf"), 0.02, limits)
    assert state.v == 0.0 and math.isfinite(state.x)

"""The simulated car-like car (agent.vehicle, ``steering = "car"``): a kinematic bicycle
whose path never curves tighter than its turning radius and which never turns standing."""

import math

import numpy as np
import pytest

from trustfg.agent.config import ConfigError, VehicleConfig
from trustfg.agent.vehicle import VehicleState, steering_angle, step

CAR = VehicleConfig(steering="car", min_turn_radius_m=0.3, wheelbase_m=0.15)


def test_full_lock_drives_the_tightest_circle():
    """Asked for any turn rate, the car drives a circle of R_min: after one lap's length
    it is back where it started, its turn rate v / R."""
    limits = VehicleConfig(steering="car", min_turn_radius_m=0.3, max_accel_mps2=1e9, max_turn_accel_radps2=1e9)
    v = 0.4
    state = VehicleState(0.0, 0.0, 0.0, v, 0.0)
    steps = 400
    dt = 2 * math.pi * 0.3 / v / steps
    for _ in range(steps):
        state = step(state, v, 10.0, dt, limits)
    assert state.omega == pytest.approx(v / 0.3)
    assert state.steer == pytest.approx(limits.max_steer_rad)
    assert (state.x, state.y) == pytest.approx((0.0, 0.0), abs=1e-9)


def test_the_curvature_is_the_commands_whatever_the_speed():
    """omega = v tan(delta) / L: a car still speeding up turns slower on the same curve,
    as a car whose wheels are set at an angle does (the bicycle), not at the commanded rate."""
    limits = VehicleConfig(steering="car", min_turn_radius_m=0.3, max_turn_accel_radps2=1e9)
    state = VehicleState(0.0, 0.0, 0.0, 0.1, 0.0)
    state = step(state, 0.5, 0.5, 0.02, limits)  # curvature asked: 1 /m
    assert state.omega / state.v == pytest.approx(1.0)
    assert state.v < 0.5


def test_it_never_turns_standing_and_keeps_its_wheels_set():
    state = VehicleState(0.0, 0.0, 1.0, 0.0, 0.0, steer=0.2)
    for _ in range(100):
        state = step(state, 0.0, 3.0, 0.02, CAR)
    assert state.yaw == pytest.approx(1.0)
    assert (state.x, state.y, state.omega) == (0.0, 0.0, 0.0)
    assert state.steer == 0.2  # v_cmd = 0 names no angle: the wheels stay as they were


def test_random_commands_keep_every_limit():
    state = VehicleState(0.0, 0.0, 0.0)
    rng = np.random.default_rng(0)
    for _ in range(3000):
        v_cmd, w_cmd = rng.uniform(-1.0, 1.0), rng.uniform(-6.0, 6.0)
        new = step(state, v_cmd, w_cmd, 0.02, CAR)
        assert 0.0 <= new.v <= CAR.max_speed_mps + 1e-12
        assert abs(new.omega) <= new.v / CAR.min_turn_radius_m + 1e-12
        assert abs(new.omega - state.omega) <= CAR.max_turn_accel_radps2 * 0.02 + 1e-12
        assert abs(new.steer) <= CAR.max_steer_rad + 1e-12
        state = new


def test_the_firmware_rule():
    """delta = atan(L omega / v), clamped to full lock; held below a millimetre a second."""
    assert steering_angle(0.4, 0.4, CAR) == pytest.approx(math.atan(0.15 * 1.0))
    assert steering_angle(0.4, -10.0, CAR) == pytest.approx(-CAR.max_steer_rad)
    assert CAR.max_steer_rad == pytest.approx(math.atan(0.15 / 0.3))
    assert steering_angle(0.0, 2.0, CAR, current=0.1) == 0.1


def test_the_unicycle_is_untouched():
    """'in-place' (the default) still turns standing, and its steering angle stays 0."""
    limits = VehicleConfig(max_turn_accel_radps2=1e9)
    state = step(VehicleState(0.0, 0.0, 0.0), 0.0, 1.0, 0.1, limits)
    assert state.omega == 1.0 and state.steer == 0.0 and state.yaw == pytest.approx(0.1)
    assert not VehicleConfig().car_like and VehicleConfig().max_curvature == math.inf


def test_the_config_refuses_what_cannot_steer():
    with pytest.raises(ConfigError, match="steering"):
        VehicleConfig(steering="tank").validate("vehicle")
    with pytest.raises(ConfigError, match="min_turn_radius_m"):
        VehicleConfig(steering="car", min_turn_radius_m=0.0).validate("vehicle")

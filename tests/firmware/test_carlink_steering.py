"""The C reference's steering rule for car-like cars (firmware/carlink/carlink_steering.h)
gives the angle agent.vehicle.steering_angle gives -- the rule mocap-sim's cars run -- to
float precision, built with the reference's strict flags."""

import ctypes
import math

import numpy as np

from tests.firmware.carlink_reference import build
from trustfg.agent.config import VehicleConfig
from trustfg.agent.vehicle import STEER_MIN_SPEED_MPS, steering_angle

WRAPPER = """
#include "carlink_steering.h"
float steering(float v, float omega, float wheelbase, float lock, float current);
float steering(float v, float omega, float wheelbase, float lock, float current)
{
    return carlink_steering_angle(v, omega, wheelbase, lock, current);
}
"""


def test_the_c_rule_is_the_simulators(tmp_path):
    source = tmp_path / "steering.c"
    source.write_text(WRAPPER)
    lib = ctypes.CDLL(str(build(tmp_path / "steering.so", [source], "-O2", "-fPIC", "-shared", "-lm")))
    lib.steering.argtypes = [ctypes.c_float] * 5
    lib.steering.restype = ctypes.c_float
    assert math.isclose(STEER_MIN_SPEED_MPS, 0.001)  # CARLINK_STEER_MIN_SPEED
    rng = np.random.default_rng(0)
    for _ in range(2000):
        vehicle = VehicleConfig(steering="car", min_turn_radius_m=float(rng.uniform(0.2, 1.0)),
                                wheelbase_m=float(rng.uniform(0.1, 0.4)))
        v = float(rng.choice([0.0, 5e-4, -5e-4, *rng.uniform(-0.8, 0.8, 4)]))
        omega, current = float(rng.uniform(-4.0, 4.0)), float(rng.uniform(-0.5, 0.5))
        want = steering_angle(v, omega, vehicle, current)
        got = lib.steering(v, omega, vehicle.wheelbase_m, vehicle.max_steer_rad, current)
        assert abs(got - want) < 1e-5, (v, omega, vehicle, got, want)
        assert abs(got) <= vehicle.max_steer_rad + 1e-6 or abs(v) < STEER_MIN_SPEED_MPS

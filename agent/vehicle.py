"""The simulated car: a unicycle, or a kinematic bicycle for a car that steers its front wheels.

State (x, y, yaw, v, omega, steer); command (v_cmd, omega_cmd). Each step the car moves its
speed towards the command no faster than its acceleration limit allows and clamps it to
the speed limits. Its turn rate:

* ``steering = "in-place"``: moves towards omega_cmd within the turn-rate limits;
* ``steering = "car"``: the command sets the steering angle as firmware does,
  delta = atan(L omega_cmd / v_cmd) clamped to +-atan(L / R_min) (held while v_cmd = 0),
  and the car turns at omega = v tan(delta) / L with the speed it has -- so its path
  never curves tighter than R_min, and it never turns standing.

The step integrates the arc of constant v and omega exactly:

    x' = x + v/omega (sin(yaw + omega*dt) - sin(yaw)),  y' = y - v/omega (cos(yaw + omega*dt) - cos(yaw))

Optional process noise (wheel slip) perturbs the achieved v and omega.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import VehicleConfig


@dataclass(frozen=True)
class VehicleState:
    x: float
    y: float
    yaw: float
    v: float = 0.0
    omega: float = 0.0
    steer: float = 0.0
    """The front wheels' steering angle, rad ('car' steering only; 0 for a unicycle)."""

    @property
    def position(self) -> np.ndarray:
        return np.array([self.x, self.y])

    @property
    def velocity(self) -> np.ndarray:
        return self.v * np.array([math.cos(self.yaw), math.sin(self.yaw)])


def step(state: VehicleState, v_cmd: float, omega_cmd: float, dt: float, limits: VehicleConfig,
         rng: np.random.Generator | None = None, slip_std: float = 0.0) -> VehicleState:
    """Advance the car by dt seconds under a velocity command."""
    if not (math.isfinite(v_cmd) and math.isfinite(omega_cmd)):
        v_cmd, omega_cmd = 0.0, 0.0
    v_target = min(max(v_cmd, -limits.max_reverse_mps), limits.max_speed_mps)
    dv = limits.max_accel_mps2 * dt
    v = state.v + min(max(v_target - state.v, -dv), dv)
    steer = state.steer
    if limits.car_like:
        steer = steering_angle(v_cmd, omega_cmd, limits, state.steer)
        w_target = v * math.tan(steer) / limits.wheelbase_m
    else:
        w_target = omega_cmd
    w_target = min(max(w_target, -limits.max_turn_rate_radps), limits.max_turn_rate_radps)
    dw = limits.max_turn_accel_radps2 * dt
    w = state.omega + min(max(w_target - state.omega, -dw), dw)
    if limits.car_like:  # the wheels' angle bounds the curvature whatever the turn rate was
        w = min(max(w, -abs(v) * limits.max_curvature), abs(v) * limits.max_curvature)
    v_real, w_real = v, w
    if rng is not None and slip_std > 0.0:
        v_real = v * (1.0 + slip_std * rng.standard_normal())
        w_real = w * (1.0 + slip_std * rng.standard_normal())
    yaw = state.yaw
    if abs(w_real) < 1e-6:
        x = state.x + v_real * dt * math.cos(yaw)
        y = state.y + v_real * dt * math.sin(yaw)
    else:
        x = state.x + v_real / w_real * (math.sin(yaw + w_real * dt) - math.sin(yaw))
        y = state.y - v_real / w_real * (math.cos(yaw + w_real * dt) - math.cos(yaw))
    new_yaw = math.atan2(math.sin(yaw + w_real * dt), math.cos(yaw + w_real * dt))
    return VehicleState(x, y, new_yaw, v, w, steer)


STEER_MIN_SPEED_MPS = 1e-3
"""Below this commanded speed a car-like car's steering angle stays where it is: omega / v
names no angle, and standing the car cannot turn whatever its wheels point at."""


def steering_angle(v_cmd: float, omega_cmd: float, limits: VehicleConfig, current: float = 0.0) -> float:
    """The steering angle a car-like car's firmware sets for the command (v_cmd, omega_cmd):
    delta = atan(L omega_cmd / v_cmd), at most +-atan(L / R_min); ``current`` while |v_cmd| is
    below STEER_MIN_SPEED_MPS (docs/carlink.md, "Car-like cars")."""
    if abs(v_cmd) < STEER_MIN_SPEED_MPS:
        return current
    lock = limits.max_steer_rad
    return min(max(math.atan(limits.wheelbase_m * omega_cmd / v_cmd), -lock), lock)

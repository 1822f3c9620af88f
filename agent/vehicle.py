"""The simulated car: a unicycle with speed, acceleration and turn-rate limits.

State (x, y, yaw, v, omega); command (v_cmd, omega_cmd). Each step the car moves its
speed and turn rate towards the command no faster than its acceleration limits allow,
clamps them to the speed limits, and integrates the unicycle exactly over the step
(an arc of constant v and omega):

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
    w_target = min(max(omega_cmd, -limits.max_turn_rate_radps), limits.max_turn_rate_radps)
    dv = limits.max_accel_mps2 * dt
    dw = limits.max_turn_accel_radps2 * dt
    v = state.v + min(max(v_target - state.v, -dv), dv)
    w = state.omega + min(max(w_target - state.omega, -dw), dw)
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
    return VehicleState(x, y, new_yaw, v, w)

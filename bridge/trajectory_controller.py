"""Trajectory tracking: plan + measured pose -> (v, omega).

:func:`track` is the controller of Kanayama et al., "A stable tracking control method for
an autonomous mobile robot" (ICRA 1990); its equations are in its docstring. When the plan
stands still, the car turns towards the reference point and creeps to it, or stops within
``goal_tolerance_m``; when it faces more than ``turn_first_deg`` away from the plan's
direction, it turns on the spot first. :func:`turn_on_the_spot` points a car the guard
holds to where its plan goes. Commands are clamped to the vehicle's limits; no reversing.

A car-like car (VehicleConfig.steering = "car") never gets a turn rate without speed: its
omega is clamped to |v| / R_min (the curvature its wheels reach), it turns standing not at
all, and facing away from its plan it drives on at full lock towards it instead of
turning on the spot.
"""

from __future__ import annotations

import math

import numpy as np

from ..agent.config import TrackingConfig, VehicleConfig
from ..agent.gp import Plan

STANDSTILL_MPS = 0.02


def wrap(angle: float) -> float:
    return math.atan2(math.sin(angle), math.cos(angle))


def track(plan: Plan, t: float, x: float, y: float, yaw: float, gains: TrackingConfig,
          limits: VehicleConfig) -> tuple[float, float]:
    """The (v, omega) command that makes a car at (x, y, yaw) follow ``plan`` at time t.

    With the plan's reference position p_r, velocity v_ref = (v_x, v_y) and acceleration
    (a_x, a_y) at t, and the error expressed in the car's frame (theta = yaw, p = (x, y))

        e_x =  cos(theta) dx + sin(theta) dy,    e_y = -sin(theta) dx + cos(theta) dy,
        e_theta = wrap(theta_r - theta),          (dx, dy) = p_r - p

    the command is

        v     = v_r cos(e_theta) + k_along e_x
        omega = omega_r + v_r (k_cross e_y + k_heading sin(e_theta))

    with theta_r = atan2(v_ref), v_r = |v_ref| and omega_r = (v_x a_y - v_y a_x) / |v_ref|^2.
    """
    (p_ref,), (v_ref,) = plan.state_at(t)
    (a_ref,) = plan.acceleration_at(t)
    dx, dy = p_ref[0] - x, p_ref[1] - y
    speed_ref = float(np.hypot(v_ref[0], v_ref[1]))
    if speed_ref < STANDSTILL_MPS:
        distance = math.hypot(dx, dy)
        if distance < gains.goal_tolerance_m:
            return 0.0, 0.0
        heading_error = wrap(math.atan2(dy, dx) - yaw)
        v = gains.k_along * distance * max(0.0, math.cos(heading_error))
        omega = gains.k_heading * heading_error
        return _clamp(v, omega, limits)
    theta_ref = math.atan2(v_ref[1], v_ref[0])
    omega_ref = (v_ref[0] * a_ref[1] - v_ref[1] * a_ref[0]) / speed_ref**2
    c, s = math.cos(yaw), math.sin(yaw)
    e_x = c * dx + s * dy
    e_y = -s * dx + c * dy
    e_theta = wrap(theta_ref - yaw)
    if gains.turns_first(e_theta):
        # Facing away from where the plan goes (after a stop, say): turn on the spot first.
        # Kanayama's turn rate scales with the reference speed, so a car facing backwards
        # on a plan that sets off gently would hardly turn, and never catch up. A car-like
        # car cannot: it drives on at the plan's speed on full lock towards it.
        if limits.car_like:
            return _clamp(speed_ref, math.copysign(speed_ref * limits.max_curvature, e_theta), limits)
        return _clamp(0.0, gains.k_heading * e_theta, limits)
    v = speed_ref * math.cos(e_theta) + gains.k_along * e_x
    omega = omega_ref + speed_ref * (gains.k_cross * e_y + gains.k_heading * math.sin(e_theta))
    return _clamp(v, omega, limits)


def _clamp(v: float, omega: float, limits: VehicleConfig) -> tuple[float, float]:
    """Within the vehicle's limits; a car-like car's turn rate also within |v| / R_min."""
    v = min(max(v, -limits.max_reverse_mps), limits.max_speed_mps)
    omega = min(max(omega, -limits.max_turn_rate_radps), limits.max_turn_rate_radps)
    if limits.car_like:
        reach = abs(v) * limits.max_curvature
        omega = min(max(omega, -reach), reach)
    return v, omega


def turn_on_the_spot(plan: Plan, t: float, x: float, y: float, yaw: float, gains: TrackingConfig,
                     limits: VehicleConfig) -> float:
    """The turn rate that points a car standing at (x, y, yaw) where the plan goes at t:
    along the plan's velocity, or at its reference point while the plan stands still.
    For a car held still (by the guard, bridge.drive): Kanayama's turn rate assumes the
    car moves at the reference speed; held, it would only spin with the plan's curvature.
    0 for a car-like car, which cannot turn standing."""
    (p_ref,), (v_ref,) = plan.state_at(t)
    if float(np.hypot(v_ref[0], v_ref[1])) >= STANDSTILL_MPS:
        heading = math.atan2(v_ref[1], v_ref[0])
    elif math.hypot(p_ref[0] - x, p_ref[1] - y) >= gains.goal_tolerance_m:
        heading = math.atan2(p_ref[1] - y, p_ref[0] - x)
    else:
        return 0.0
    return turn_towards(heading, yaw, gains, limits)


def turn_towards(heading: float, yaw: float, gains: TrackingConfig, limits: VehicleConfig) -> float:
    """The turn rate, standing, from ``yaw`` towards ``heading``: k_heading (heading - yaw),
    capped; 0 for a car-like car, which cannot turn standing (its plan turns it as it drives)."""
    return _clamp(0.0, gains.k_heading * wrap(heading - yaw), limits)[1]


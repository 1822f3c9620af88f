"""Tracking with a car-like car (bridge.trajectory_controller, bridge.drive): never a turn
rate without speed, no turn on the spot, and a car facing away drives round on full lock."""

import dataclasses
import math

import numpy as np
import pytest

from trustfg.agent.config import Scenario, TrackingConfig, VehicleConfig
from trustfg.agent.gp import Plan, standing
from trustfg.agent.vehicle import VehicleState, step
from trustfg.bridge.drive import drive
from trustfg.bridge.trajectory_controller import track, turn_on_the_spot, turn_towards

CAR = VehicleConfig(steering="car", min_turn_radius_m=0.3)
GAINS = TrackingConfig()


def straight_east(speed: float = 0.4, n: int = 21, dt: float = 0.25) -> Plan:
    t = np.arange(n) * dt
    return Plan(0.0, dt, np.stack([speed * t, np.zeros(n)], axis=1), np.tile([speed, 0.0], (n, 1)))


@pytest.mark.parametrize("yaw", np.linspace(-math.pi, math.pi, 13))
@pytest.mark.parametrize("offset", [(0.0, 0.0), (0.05, 0.1), (-0.1, -0.2)])
def test_never_a_turn_rate_without_speed(yaw, offset):
    for plan in (straight_east(), standing(np.array([0.3, 0.1]), 0.0)):
        for t in (0.0, 0.5, 2.0):
            v, omega = track(plan, t, offset[0], offset[1], yaw, GAINS, CAR)
            assert v >= 0.0
            assert abs(omega) <= v / CAR.min_turn_radius_m + 1e-12


def test_facing_away_it_drives_round_on_full_lock():
    """The unicycle turns on the spot; the car-like car drives at the plan's speed on its
    tightest circle, turning towards the plan."""
    plan = straight_east()
    assert track(plan, 0.0, 0.0, 0.0, math.pi / 2, GAINS, VehicleConfig())[0] == 0.0
    v, omega = track(plan, 0.0, 0.0, 0.0, math.pi / 2, GAINS, CAR)
    assert v == pytest.approx(0.4) and omega == pytest.approx(-0.4 / 0.3)


def test_a_car_facing_away_comes_round_onto_its_plan():
    """Simulated with the bicycle, a car facing west on a plan east loops round within a
    few turning radii and then tracks it."""
    plan = straight_east(0.3, n=41, dt=0.25)
    state = VehicleState(0.0, 0.0, math.pi)
    dt = 0.02
    for k in range(int(10.0 / dt)):
        v, omega = track(plan, k * dt, state.x, state.y, state.yaw, GAINS, CAR)
        state = step(state, v, omega, dt, CAR)
    (p,), _ = plan.state_at(10.0)
    assert abs(state.y) < 0.05  # back on the line
    assert abs(math.atan2(math.sin(state.yaw), math.cos(state.yaw))) < 0.2


def test_held_or_between_laps_it_does_not_turn():
    assert turn_towards(math.pi, 0.0, GAINS, CAR) == 0.0
    assert turn_on_the_spot(straight_east(), 0.0, 0.0, 0.0, math.pi, GAINS, CAR) == 0.0
    assert turn_towards(math.pi, 0.0, GAINS, VehicleConfig()) != 0.0


def test_the_guard_slows_it_on_the_same_curve(intersection):
    """A car the guard caps keeps the curvature the tracker asked for; one it holds stands
    still without turning."""
    scenario: Scenario = dataclasses.replace(intersection, vehicle=CAR)
    t = np.arange(21) * 0.25
    curve = Plan(0.0, 0.25, np.stack([0.5 * np.sin(t), 0.5 - 0.5 * np.cos(t)], axis=1),
                 np.stack([0.5 * np.cos(t), 0.5 * np.sin(t)], axis=1))
    free = drive(curve, 0.5, (0.5 * math.sin(0.5), 0.5 - 0.5 * math.cos(0.5), 0.5), True, lambda: [], 0.1,
                 scenario, None)
    ahead = (0.5 * math.sin(0.5) + 0.45 * math.cos(0.5), 0.5 - 0.5 * math.cos(0.5) + 0.45 * math.sin(0.5), 0.0, 0.1)
    capped = drive(curve, 0.5, (0.5 * math.sin(0.5), 0.5 - 0.5 * math.cos(0.5), 0.5), True, lambda: [ahead], 0.1,
                   scenario, None)
    assert capped.guard_limited and 0.0 < capped.v < free.v
    assert capped.omega / capped.v == pytest.approx(free.omega / free.v)
    close = (0.5 * math.sin(0.5) + 0.3 * math.cos(0.5), 0.5 - 0.5 * math.cos(0.5) + 0.3 * math.sin(0.5), 0.0, 0.1)
    held = drive(curve, 0.5, (0.5 * math.sin(0.5), 0.5 - 0.5 * math.cos(0.5), 0.5), True, lambda: [close], 0.1,
                 scenario, None)
    assert held.guard_limited and held.v == 0.0 and held.omega == 0.0

"""One control tick (bridge.drive), the same in the car process and the in-process fleet:
when it stops, that it tracks the plan, and that the guard caps it when switched on."""

import dataclasses
import math

import numpy as np
import pytest

from trustfg.agent.config import Scenario
from trustfg.agent.gp import Plan
from trustfg.agent.vehicle import VehicleState, step
from trustfg.bridge.drive import STOP, drive


def moving(speed: float = 0.5) -> Plan:
    n = 11
    return Plan(0.0, 1.0, np.stack([np.arange(n) * speed, np.zeros(n)], axis=1), np.tile([speed, 0.0], (n, 1)))


@pytest.fixture(scope="module")
def scenario(intersection) -> Scenario:
    return intersection


def test_no_pose_no_plan_or_no_leave_to_drive_is_a_stop(scenario):
    nobody = lambda: []  # noqa: E731
    assert drive(moving(), 1.0, None, True, nobody, 0.1, scenario, None) is STOP
    assert drive(None, 1.0, (0.5, 0.0, 0.0), True, nobody, 0.1, scenario, None) is STOP
    assert drive(moving(), 1.0, (0.5, 0.0, 0.0), False, nobody, 0.1, scenario, None) is STOP


def test_on_its_plan_a_car_drives_at_the_plan_speed(scenario):
    command = drive(moving(), 1.0, (0.5, 0.0, 0.0), True, lambda: [], 0.1, scenario, None)
    assert not command.stop and command.v == pytest.approx(0.5) and not command.guard_limited


def test_the_guard_caps_the_speed_before_a_car_ahead_and_only_when_on(scenario):
    ahead = lambda: [(0.9, 0.0, np.pi, 0.1)]  # noqa: E731  0.4 m ahead, facing us
    capped = drive(moving(), 1.0, (0.5, 0.0, 0.0), True, ahead, 0.1, scenario, None)
    assert capped.guard_limited and capped.v < 0.5
    off = dataclasses.replace(scenario, guard=dataclasses.replace(scenario.guard, enabled=False))
    asked = []
    free = drive(moving(), 1.0, (0.5, 0.0, 0.0), True, lambda: asked.append(1) or [], 0.1, off, None)
    assert free.v == pytest.approx(0.5) and not asked  # off: the others are not even looked at


def arc(x: float, y: float, t0: float, heading: float, turn_radps: float, speed: float = 0.5) -> Plan:
    """A plan from (x, y) at t0 setting off at ``heading`` and curving at ``turn_radps``."""
    times = np.arange(0.0, 2.0 + 1e-9, 0.1)
    theta = heading + turn_radps * times
    velocities = speed * np.stack([np.cos(theta), np.sin(theta)], axis=1)
    positions = np.array([x, y]) + np.concatenate([[[0.0, 0.0]], np.cumsum(velocities[:-1] * 0.1, axis=0)])
    return Plan(t0, 0.1, positions, velocities)


def held_at_a_wall(scenario, sdf, seconds: float = 6.0) -> tuple[float, float]:
    """A car hugging the street's west wall (x = -0.8), 4 mm inside the guard's keep-off
    line and facing 10 degrees into the wall, on a plan re-made from where it is every
    0.2 s (as a replanning car's is) that sets off north-east, away from the wall, and
    curves left. Returns (how far it got, how much nearer the wall its edge came than at
    the start)."""
    radius = 0.1
    keep = radius + scenario.guard.wall_clearance_m
    car = VehicleState(-0.8 + keep - 0.004, -1.5, math.radians(100.0))
    start = np.array([car.x, car.y])
    clearance = float(sdf.distance(start))
    least, plan, dt = clearance, None, 0.02
    for k in range(int(seconds / dt)):
        t = k * dt
        if k % 10 == 0:
            plan = arc(car.x, car.y, t, math.radians(45.0), 3.0)
        command = drive(plan, t, (car.x, car.y, car.yaw), True, lambda: [], radius, scenario, sdf)
        car = step(car, command.v, command.omega, dt, scenario.vehicle)
        least = min(least, float(sdf.distance(np.array([car.x, car.y]))))
    return float(np.linalg.norm(np.array([car.x, car.y]) - start)), clearance - least


def test_a_car_the_guard_holds_turns_to_where_its_plan_goes_and_gets_away(scenario, intersection_sdf):
    # Held, Kanayama's turn (the plan's curvature times its speed) would spin the car further
    # into the wall and the turn-first rule turn it back: it would swing between headings that
    # all point into the wall and never move (the next test switches the rule off).
    moved, nearer = held_at_a_wall(scenario, intersection_sdf)
    assert moved > 1.0
    assert nearer <= 0.002  # and never into the wall


def test_held_with_the_plan_curvature_the_car_stays_stuck(scenario, intersection_sdf, monkeypatch):
    import trustfg.bridge.drive as drive_module
    monkeypatch.setattr(drive_module, "HELD_MPS", -1.0)  # the rule off: cap and Kanayama's turn
    moved, _ = held_at_a_wall(scenario, intersection_sdf)
    assert moved < 0.05

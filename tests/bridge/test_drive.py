"""One control tick (bridge.drive), the same in the car process and the in-process fleet:
when it stops, that it tracks the plan, and that the guard caps it when switched on."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent.config import Scenario
from trustfg.agent.gp import Plan
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

"""Laps: a car drives its route ``control.laps`` times, back and forth, for long runs.

Lap 1 is the route of the config; lap 2 goes back from the goal to the start along the
same via points reversed; lap 3 out again, and so on. Between laps the car process turns
the car in place towards its next leg for ``control.lap_turn_s`` (the planner plans a
point, not a unicycle, so a car facing away from its plan would not start along it), then
the agent plans the new leg from where the car stands. The car reports ``at_goal`` only
after its last lap.
"""

from __future__ import annotations

import dataclasses
import math

from ...agent.car_agent import CarAgent
from ...agent.config import CarConfig, Scenario, TrackingConfig, VehicleConfig
from ...bridge.trajectory_controller import turn_towards


def leg(car: CarConfig, lap: int) -> CarConfig:
    """The car as it drives lap ``lap`` (1-based): odd laps as configured, even ones back."""
    if lap % 2:
        return car
    return dataclasses.replace(car, start=car.goal, goal=car.start, route=tuple(reversed(car.route)),
                               start_heading_rad=None)


def final_legs(scenario: Scenario) -> Scenario:
    """The scenario with every car on its last leg (where it ends: the judge's goals)."""
    return dataclasses.replace(scenario, cars=tuple(leg(c, scenario.control.laps) for c in scenario.cars))


class Laps:
    """Which lap a car is on, and the turn between laps (see the module docstring)."""

    def __init__(self, car: CarConfig, laps: int, turn_s: float) -> None:
        self.car = car
        self.laps = laps
        self.turn_s = turn_s
        self.lap = 1
        self._turn_until = -math.inf
        self._heading = 0.0

    @property
    def done(self) -> bool:
        return self.lap >= self.laps

    def advance(self, agent: CarAgent, position: tuple[float, float], now: float) -> bool:
        """At a goal with laps to go: give the agent the next leg, departing after the turn."""
        if not agent.at_goal or self.done:
            return False
        self.lap += 1
        agent.car = leg(self.car, self.lap)
        agent.at_goal = False
        agent.plan = None  # a cold start for the new leg, not a warm start from standing
        agent.set_departure(now + self.turn_s, agent.cruise)
        target = agent.car.route[0] if agent.car.route else agent.car.goal
        self._heading = math.atan2(target[1] - position[1], target[0] - position[0])
        self._turn_until = now + self.turn_s
        return True

    @property
    def turn(self) -> tuple[float, float]:
        """(heading, until): the turn between laps towards ``heading`` lasts until ``until``
        (fleet clock; -inf: no turn) -- what the command loop needs of the laps."""
        return self._heading, self._turn_until

    def turn_command(self, now: float, yaw: float, gains: TrackingConfig,
                     limits: VehicleConfig) -> tuple[float, float] | None:
        """(0, omega) towards the next leg while the turn lasts, else None."""
        heading, until = self.turn
        return None if now >= until else (0.0, turn_towards(heading, yaw, gains, limits))

"""Deadlock detours of a car-like car (agent.deadlock with ``steering``): reached by the arc
that turns the car there, never by a turn on the spot, and only where the car can drive on."""

import math

import numpy as np
import pytest

from trustfg.agent.config import Obstacle, WorldConfig
from trustfg.agent.deadlock import _way_to, detour_goal
from trustfg.agent.steering import departure_arc
from trustfg.agent.world import build_sdf

KEEP_CLEAR, WALL_CLEAR, R = 0.45, 0.25, 0.3


@pytest.fixture(scope="module")
def pocket():
    """A room with a wall 0.9 m east of the car (which faces north) and one 1.0 m north."""
    return build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0), obstacles=(
        Obstacle(min=(0.9, -3.0), max=(3.0, 3.0)), Obstacle(min=(-3.0, 1.0), max=(0.9, 3.0)))))


def test_the_way_to_a_detour_is_the_departure_arc_then_straight_and_room_beyond():
    position, heading, goal = np.zeros(2), math.pi / 2, np.array([0.6, 0.0])
    way = _way_to(position, goal, (heading, R))
    arc = departure_arc(position, heading, goal, R)
    assert np.allclose(way[:len(arc)], arc)  # it turns on its radius first: no spot turn
    assert np.allclose(way[len(arc) + 10], goal)  # then straight to the goal
    beyond = way[-1]
    direction = (goal - arc[-1]) / np.linalg.norm(goal - arc[-1])
    assert np.allclose(beyond, goal + 2 * R * direction)  # and a turning circle's width on
    assert np.array_equal(_way_to(position, goal, None)[-1], goal)  # a unicycle: straight, no more


def test_a_car_like_car_never_gives_way_nose_first_into_a_wall(pocket):
    """Away from a car that goes first coming from the west is east, towards the wall 0.9 m
    off: a unicycle takes the point 0.6 m east (it turns on the spot once there); a car-like
    car facing north would end 0.3 m short of the wall facing it, so it takes another point,
    whose arc and the room beyond keep clear of the walls."""
    position = np.array([0.0, 0.0])
    ways = [np.array([[-1.0, 0.0], [-2.0, 0.0]])]
    unicycle = detour_goal(position, ways, [], 0.6, KEEP_CLEAR, pocket, WALL_CLEAR)
    assert np.allclose(unicycle, [0.6, 0.0])
    car = detour_goal(position, ways, [], 0.6, KEEP_CLEAR, pocket, WALL_CLEAR, (math.pi / 2, R))
    assert car is not None and not np.allclose(car, [0.6, 0.0])
    assert float(np.min(pocket.distance(_way_to(position, car, (math.pi / 2, R))))) >= WALL_CLEAR

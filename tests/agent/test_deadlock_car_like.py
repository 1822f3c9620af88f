"""Deadlock detours of a car-like car (agent.deadlock with ``steering``): reached by the arc
that turns the car there, never by a turn on the spot, and only where the car can drive on;
and a parked car steps aside for a car-like car it boxes in."""

import math

import numpy as np
import pytest

from trustfg.agent.config import DeadlockConfig, Obstacle, WorldConfig
from trustfg.agent.deadlock import DeadlockWatch, PeerSeen, _way_to, boxes_in, detour_goal
from trustfg.agent.steering import departure_arc, ways_on
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


@pytest.fixture(scope="module")
def room():
    return build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0)))


def test_the_ways_on_are_a_quarter_turn_either_way_and_straight_on():
    left, right, straight = ways_on(np.zeros(2), 0.0, R)
    assert np.allclose(left[-1], [R, R], atol=0.02) and np.allclose(right[-1], [R, -R], atol=0.02)
    assert np.allclose(straight[-1], [2 * R, 0.0], atol=1e-9)
    for way in (left, right):  # on the circle of radius R about its centre
        centre = np.array([0.0, R if way is left else -R])
        assert np.allclose(np.linalg.norm(way - centre, axis=1), R)


# A car-like car stuck at the origin facing east, a car parked 0.5 m ahead of it: nearer
# than a turn at R = 0.3 lets it pass at KEEP_CLEAR, though farther than KEEP_CLEAR.
STUCK = PeerSeen(np.zeros(2), goal=np.array([2.5, 0.0]), heading=0.0)
AHEAD = np.array([0.5, 0.0])


def test_a_car_parked_close_ahead_boxes_a_car_like_car_in(room):
    assert boxes_in(AHEAD, STUCK, [], KEEP_CLEAR, room, WALL_CLEAR, (math.pi, R))
    assert not boxes_in(AHEAD, STUCK, [], KEEP_CLEAR, room, WALL_CLEAR, None)  # it could turn in place
    facing_away = PeerSeen(np.zeros(2), goal=np.array([-2.5, 0.0]), heading=math.pi)
    assert not boxes_in(AHEAD, facing_away, [], KEEP_CLEAR, room, WALL_CLEAR, (math.pi, R))
    # Boxed in by others as well: a car standing on each side. Not by us alone.
    beside = [((0.0, 0.5), KEEP_CLEAR), ((0.0, -0.5), KEEP_CLEAR), ((0.8, 0.0), KEEP_CLEAR)]
    assert not boxes_in(AHEAD, STUCK, beside, KEEP_CLEAR, room, WALL_CLEAR, (math.pi, R))


def test_a_parked_car_like_car_steps_aside_for_a_car_it_boxes_in_and_stays_clear_of_its_ways(room):
    """Car 2 has stood 0.5 m behind car 1 (parked at its goal, facing west) for a
    window: the room is open, so a car that turns in place would drive round; a car-like
    car 2 cannot, and car 1 steps aside to where each of car 2's ways on is open."""
    def parked(steering):
        watch = DeadlockWatch(1, DeadlockConfig())
        asides = [watch.step_aside(t, AHEAD, AHEAD, {2: STUCK}, KEEP_CLEAR, room, WALL_CLEAR, steering)
                  for t in np.arange(0.0, DeadlockConfig().window_s + 1.0, 0.2)]
        return next((a for a in asides if a is not None), None)

    assert parked(None) is None
    aside = parked((math.pi, R))
    assert aside is not None
    assert not boxes_in(aside, STUCK, [], KEEP_CLEAR, room, WALL_CLEAR, (math.pi, R))

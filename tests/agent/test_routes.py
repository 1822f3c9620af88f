"""Routes of generated scenes keep their clearance from obstacles, or there is none."""

import numpy as np
import pytest

from trustfg.agent.config import Obstacle, WorldConfig
from trustfg.agent.routes import NoRoute, plan_route, segment_clear
from trustfg.agent.world import build_sdf

BOUNDS = (-2.0, -1.5, 2.0, 1.5)
CLEARANCE, COMFORT = 0.25, 0.4


def _sdf(*obstacles):
    return build_sdf(WorldConfig(bounds_m=BOUNDS, resolution_m=0.02, obstacles=tuple(obstacles)))


def test_a_clear_straight_line_needs_no_via_points():
    assert plan_route(_sdf(), BOUNDS, (-1.5, 0.0), (1.5, 0.0), CLEARANCE, COMFORT) == ()


def test_a_route_around_a_wall_keeps_the_clearance_the_straight_line_breaks():
    wall = Obstacle(kind="rect", min=(-0.1, -1.5), max=(0.1, 0.7))  # a gap of 0.8 m at the top
    sdf = _sdf(wall)
    start, goal = np.array([-1.5, -1.0]), np.array([1.5, -1.0])
    assert not segment_clear(sdf, start, goal, CLEARANCE)
    route = plan_route(sdf, BOUNDS, start, goal, CLEARANCE, COMFORT)
    points = np.array([start, *route, goal])
    assert len(route) >= 1
    assert all(segment_clear(sdf, a, b, CLEARANCE) for a, b in zip(points[:-1], points[1:]))
    assert all(p[1] > 0.7 for p in route[:1])  # it goes through the gap


def test_no_route_through_a_wall_without_a_gap():
    sdf = _sdf(Obstacle(kind="rect", min=(-0.1, -1.5), max=(0.1, 1.5)))
    with pytest.raises(NoRoute):
        plan_route(sdf, BOUNDS, (-1.5, 0.0), (1.5, 0.0), CLEARANCE, COMFORT)

"""Car-like cars: the geometry of their turns (agent.steering), and plans the planner makes
and verification passes or refuses for them."""

import dataclasses
import math

import numpy as np
import pytest

from trustfg.agent.config import Obstacle, PlannerConfig, VehicleConfig, VerifyConfig, WorldConfig
from trustfg.agent.gp import Plan
from trustfg.agent.planner import PlanRequest, _seed_entries, plan_trajectory
from trustfg.agent.safe_plan import FIRST, RETRY, plan_safely
from trustfg.agent.steering import departure_arc, initial_headings, turn_then, turning_excess, wrap
from trustfg.agent.verify import Bounds, verify
from trustfg.agent.world import build_sdf

R = 0.3


def heading_at_end(arc: np.ndarray, start: np.ndarray, heading: float, radius: float) -> float:
    """The heading of a car that drove the arc (tangent at its last point)."""
    left = np.array([-math.sin(heading), math.cos(heading)])
    for side in (1.0, -1.0):
        centre = start + radius * side * left
        if abs(np.linalg.norm(arc[-1] - centre) - radius) < 1e-9 and all(
                abs(np.linalg.norm(p - centre) - radius) < 1e-9 for p in arc):
            radial = arc[-1] - centre
            return math.atan2(radial[1], radial[0]) + side * math.pi / 2
    raise AssertionError("not an arc of the radius from the start")


@pytest.mark.parametrize("target", [(0.0, 1.0), (-1.0, 0.0), (0.0, -2.0), (0.1, 0.25), (-0.2, 0.05), (1.0, 0.3)])
def test_a_departure_arc_turns_the_car_to_face_its_target(target):
    start, heading = np.zeros(2), 0.0
    target = np.array(target)
    arc = departure_arc(start, heading, target, R)
    assert len(arc)
    end = heading_at_end(arc, start, heading, R)
    to_target = target - arc[-1]
    assert abs(wrap(math.atan2(to_target[1], to_target[0]) - end)) <= math.radians(5.0) + 1e-9


def test_no_arc_for_a_target_ahead():
    assert departure_arc(np.zeros(2), 0.0, np.array([2.0, 0.05]), R).shape == (0, 2)


def test_a_target_inside_the_turning_circle_is_reached_the_long_way_round():
    """(0.1, 0.25) lies inside the left circle (centre (0, R)): no left arc ever faces it,
    so the car turns right and comes round."""
    arc = departure_arc(np.zeros(2), 0.0, np.array([0.1, 0.25]), R)
    assert arc[0][1] < 0  # it sets off to the right
    assert len(arc) * 10 > 270  # degrees of turning


def circle_path(radius: float, turn: float, start_heading: float = 0.0, points: int = 400) -> np.ndarray:
    theta = start_heading + np.linspace(0.0, turn, points)
    return radius * np.stack([np.sin(theta) - math.sin(start_heading), math.cos(start_heading) - np.cos(theta)],
                             axis=1)


def test_turning_excess_holds_a_path_to_the_radius():
    sample = VerifyConfig().sample_m
    excess, _ = turning_excess(circle_path(R * 1.02, math.pi), 0.0, R, 0.0, sample)
    assert excess <= 0.0
    excess, _ = turning_excess(circle_path(R / 2, math.pi), 0.0, R, 0.0, sample)
    assert excess > 1.0  # half the radius: the half turn needs twice the length it has
    # A path that turns right at a corner: the kink is all excess (less the slack).
    corner = np.vstack([np.linspace([0, 0], [0.5, 0], 30), np.linspace([0.5, 0], [0.5, -0.5], 30)[1:]])
    excess, k = turning_excess(corner, 0.0, R, 0.1, sample)
    assert excess == pytest.approx(math.pi / 2 - 0.1 - 0.0, abs=0.2)
    assert np.allclose(corner[k], [0.5, 0.0], atol=0.05)


def test_turning_excess_counts_the_start_heading_and_reversals():
    sample = VerifyConfig().sample_m
    line = np.linspace([0.0, 0.0], [1.0, 0.0], 100)
    assert turning_excess(line, 0.0, R, 0.1, sample)[0] < 0.0
    assert turning_excess(line, math.pi / 2, R, 0.1, sample)[0] > 1.0  # the car faces north, the path goes east
    assert turning_excess(line, None, R, 0.1, sample)[0] < 0.0  # no heading given: the path's own
    there_and_back = np.vstack([line, line[::-1][1:]])
    assert turning_excess(there_and_back, 0.0, R, 0.1, sample)[0] > 2.5  # a reversal turns pi on no length
    standing = np.zeros((50, 2))
    assert turning_excess(standing, 0.0, R, 0.1, sample)[0] == -math.inf


def test_initial_headings_follow_the_motion_unwrapped():
    v = np.array([[0.0, 0.0], [0.0, 0.3], [-0.3, 0.01], [-0.3, -0.01], [0.0, 0.0], [0.0, -0.3]])
    theta = initial_headings(v, 0.0)
    assert theta[0] == 0.0
    assert theta[1] == pytest.approx(math.pi / 2)
    assert theta[3] > math.pi  # past pi, not wrapped to -pi
    assert theta[4] == theta[3]  # standing: the heading stays
    assert theta[5] == pytest.approx(3 * math.pi / 2)


@pytest.fixture(scope="module")
def open_sdf():
    return build_sdf(WorldConfig())


@pytest.mark.parametrize("heading", [0.0, math.pi / 2, -math.pi / 2, 2.5, math.pi])
def test_a_car_like_plan_sets_off_along_the_heading_and_verifies(open_sdf, heading):
    """From a standstill facing anywhere, a replan (optimised, verified, retried) to a goal
    2 m east turns the car round on arcs it can drive: verification, which holds it to the
    radius from the car's heading, passes it. A plan made for a car that turns in place does not verify for a
    car-like car that faces away."""
    request = PlanRequest(t_now=0.0, position=np.array([-1.0, 0.0]), velocity=np.zeros(2),
                          goal=np.array([1.0, 0.0]), t_arrive=8.0, epsilon_obstacle=0.25,
                          lane=((-1.0, 0.0),), steering=(heading, R))
    planner = PlannerConfig()
    bounds = Bounds.of(0.25, 0.2, [], VehicleConfig(steering="car", min_turn_radius_m=R))
    outcome = plan_safely(request, bounds, planner, VerifyConfig(), open_sdf, None)
    assert outcome.outcome in (FIRST, RETRY), outcome.tried
    plan = outcome.plan
    verdict = verify(plan, [], bounds, open_sdf, VerifyConfig(), start_speed=0.0, start_heading=heading)
    assert verdict.ok, verdict.conflicts
    assert np.linalg.norm(plan.positions[-1] - request.goal) < 0.05
    if abs(wrap(heading)) > math.pi / 4:
        unicycle = plan_trajectory(dataclasses.replace(request, steering=None), planner, open_sdf).plan
        refused = verify(unicycle, [], bounds, open_sdf, VerifyConfig(), start_speed=0.0, start_heading=heading)
        assert [c.kind for c in refused.conflicts] == ["turning"]


def test_a_unicycle_is_never_held_to_a_heading(open_sdf):
    """Bounds of a car that turns in place carry no radius: a path that turns on the spot
    passes (the turning check is a car-like car's only)."""
    bounds = Bounds.of(0.25, 0.2, [], VehicleConfig())
    assert bounds.min_turn_radius_m == 0.0
    there_and_back = Plan(0.0, 1.0, np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.0]]), np.zeros((3, 2)))
    verdict = verify(there_and_back, [], bounds, open_sdf, VerifyConfig(limit_lag_m=10.0), start_heading=math.pi)
    assert verdict.ok


def test_a_car_like_car_moved_off_its_route_heads_on_instead_of_looping_back(open_sdf):
    """A car-like car that stands past its first via point, facing on along its route
    (as after a detour), plans on towards the next via point: its cold plan does not loop
    back round to the point behind it, and it verifies."""
    request = PlanRequest(t_now=0.0, position=np.array([0.0, 0.0]), velocity=np.zeros(2),
                          goal=np.array([2.0, 0.5]), t_arrive=10.0, epsilon_obstacle=0.25,
                          route=((-0.2, -0.1), (1.0, 0.5)), steering=(0.0, R))
    bounds = Bounds.of(0.25, 0.2, [], VehicleConfig(steering="car", min_turn_radius_m=R))
    outcome = plan_safely(request, bounds, PlannerConfig(), VerifyConfig(), open_sdf, None)
    assert outcome.outcome in (FIRST, RETRY), outcome.tried
    path = outcome.plan.position_at(np.linspace(0.0, outcome.plan.t_end, 200))
    assert np.min(path[:, 0]) > -0.05, "looped back to the via point behind the car"
    assert np.linalg.norm(outcome.plan.positions[-1] - request.goal) < 0.05


def test_a_car_like_seed_joins_its_route_only_where_the_way_there_is_clear(open_sdf):
    """Seeds join the route at a via point only along a way clear of the walls: with a
    wall between the car and its goal, the seed that heads straight for the goal (shorter,
    and the first tried in the open) is not among them; the whole route always is. A car
    that turns in place has the one seed along its whole route."""
    request = PlanRequest(t_now=0.0, position=np.array([0.0, 0.0]), velocity=np.zeros(2),
                          goal=np.array([1.5, 0.0]), t_arrive=10.0, epsilon_obstacle=0.15,
                          route=((0.6, 1.2),), steering=(math.pi / 2, R))
    assert _seed_entries(request, 0.15, open_sdf) == [1, 0]  # the goal (k = 1) is nearer
    walled = build_sdf(WorldConfig(obstacles=(Obstacle(kind="rect", min=(0.5, -1.0), max=(0.7, 0.7)),)))
    assert _seed_entries(request, 0.15, walled) == [0]
    assert _seed_entries(dataclasses.replace(request, steering=None), 0.15, walled) == [0]


def test_a_way_on_starts_with_the_turn_to_its_first_point_beyond_the_turning_circle():
    """Facing the way on: no longer than the way. Facing away: the arc first, to the first
    point beyond 2R (points nearer are skipped: the car turns past them), or to the last
    point when every point lies nearer -- a goal just behind the car is a loop away."""
    way = np.array([[0.0, 0.0], [0.2, 0.0], [1.0, 0.0], [2.0, 0.0]])
    assert path_length_of(turn_then(way, 0.0, R)) == pytest.approx(2.0)
    turned = turn_then(way, math.pi, R)
    assert np.array_equal(turned[-2:], way[2:]) and len(turned) > len(way) - 1
    assert path_length_of(turned) > 2.0 + math.pi * R
    near = np.array([[0.0, 0.0], [-0.3, 0.0]])
    assert path_length_of(turn_then(near, 0.0, R)) > math.pi * R


def path_length_of(points: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))

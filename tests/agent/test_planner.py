import dataclasses

import numpy as np
import pytest

from trustfg.agent.config import PlannerConfig, SafetyConfig
from trustfg.agent.gp import Plan
from trustfg.agent.planner import PeerConstraint, PlanningError, PlanRequest, peers_within_reach, plan_trajectory

EPS_OBSTACLE = SafetyConfig().epsilon_obstacle(0.1)
EPS_0 = SafetyConfig().epsilon_0(0.1, 0.1)
LANES = [((0.4, -2.15), (0.4, 2.15)), ((-2.15, -0.4), (2.15, -0.4)), ((-0.4, 2.15), (-0.4, -2.15)),
         ((2.15, 0.4), (-2.15, 0.4))]


def request(start, goal, t_arrive=12.0, **kw):
    return PlanRequest(t_now=0.0, position=np.array(start), velocity=np.zeros(2), goal=np.array(goal),
                       t_arrive=t_arrive, epsilon_obstacle=EPS_OBSTACLE, lane=(start,), **kw)


def min_sdf(plan, sdf):
    times = np.linspace(plan.t0, plan.t_end, 800)
    return float(sdf.distance(plan.position_at(times)).min())


@pytest.mark.parametrize("seed", range(8))
def test_plans_reach_the_goal_clear_of_obstacles(intersection_sdf, seed):
    """Random start and goal in the arms of the intersection, random lanes through it."""
    rng = np.random.default_rng(seed)
    config = PlannerConfig()
    arms = [np.array([0.0, -2.0]), np.array([-2.0, 0.0]), np.array([0.0, 2.0]), np.array([2.0, 0.0])]
    a, b = rng.choice(4, 2, replace=False)
    start = arms[a] + rng.uniform(-0.5, 0.5, 2) * (arms[a] == 0)
    goal = arms[b] + rng.uniform(-0.5, 0.5, 2) * (arms[b] == 0)
    result = plan_trajectory(PlanRequest(0.0, start, np.zeros(2), goal, 12.0, EPS_OBSTACLE, route=((0.0, 0.0),),
                                         lane=(tuple(start), (0.0, 0.0))), config, intersection_sdf)
    plan = result.plan
    assert np.linalg.norm(plan.positions[-1] - goal) < 0.03
    assert np.linalg.norm(plan.velocities[-1]) < 0.05
    # The hinge is soft: a few millimetres inside epsilon, never near the wall.
    assert min_sdf(plan, intersection_sdf) > EPS_OBSTACLE - 0.02


def crossing_peer(t_cross=6.0):
    """A peer going west -> east on y = -0.4, at x = 0.4 at t_cross."""
    n = 25
    times = np.linspace(0.0, 12.0, n)
    speed = 4.3 / 12.0
    x = 0.4 + speed * (times - t_cross)
    positions = np.stack([x, np.full(n, -0.4)], axis=1)
    velocities = np.tile([speed, 0.0], (n, 1))
    return Plan(0.0, times[1] - times[0], positions, velocities)


@pytest.mark.parametrize("t_cross", [5.0, 5.6, 6.0, 6.4, 7.0])
@pytest.mark.parametrize("epsilon", [EPS_0, 2 * EPS_0])
def test_plan_keeps_epsilon_from_a_crossing_peer(intersection_sdf, t_cross, epsilon):
    peer = crossing_peer(t_cross)
    start, goal = LANES[0]
    result = plan_trajectory(request(start, goal, peers=(PeerConstraint(peer, epsilon),)),
                             PlannerConfig(), intersection_sdf)
    times = np.linspace(0, 14, 1400)
    gap = np.linalg.norm(result.plan.position_at(times) - peer.position_at(times), axis=1).min()
    assert gap > epsilon - 0.03


def test_without_proximity_the_plan_ignores_peers(intersection_sdf):
    peer = crossing_peer(6.0)
    start, goal = LANES[0]
    config = PlannerConfig(proximity=False, consistency=False)
    result = plan_trajectory(request(start, goal, peers=(PeerConstraint(peer, EPS_0),)), config, intersection_sdf)
    times = np.linspace(0, 14, 1400)
    gap = np.linalg.norm(result.plan.position_at(times) - peer.position_at(times), axis=1).min()
    assert gap < EPS_0 - 0.1  # nowhere near the epsilon it would keep with the factor


def test_warm_start_replans_in_few_iterations(intersection_sdf):
    peer = crossing_peer(6.0)
    start, goal = LANES[0]
    config = PlannerConfig()
    cold = plan_trajectory(request(start, goal, peers=(PeerConstraint(peer, EPS_0),)), config, intersection_sdf)
    (p,), (v,) = cold.plan.state_at(0.2)
    warm_request = dataclasses.replace(request(start, goal, peers=(PeerConstraint(peer, EPS_0),)),
                                       t_now=0.2, position=p, velocity=v, warm_start=cold.plan)
    warm = plan_trajectory(warm_request, config, intersection_sdf)
    assert warm.warm and warm.iterations <= max(3, cold.iterations // 2)
    # The near future, which the car is tracking, stays put (later parts may still improve).
    near = np.linspace(0.2, 1.0, 9)
    assert np.allclose(warm.plan.position_at(near), cold.plan.position_at(near), atol=0.02)


def test_batched_and_gtsam_interpolation_agree(intersection_sdf):
    peer = crossing_peer(6.0)
    start, goal = LANES[0]
    req = request(start, goal, peers=(PeerConstraint(peer, EPS_0),))
    batched = plan_trajectory(req, PlannerConfig(support_states=11), intersection_sdf)
    native = plan_trajectory(req, PlannerConfig(support_states=11, interpolation="gtsam"), intersection_sdf)
    assert batched.initial_error == pytest.approx(native.initial_error, rel=1e-9)
    assert np.allclose(batched.plan.positions, native.plan.positions, atol=1e-6)


@pytest.mark.parametrize("field, value", [("position", np.array([np.nan, 0.0])),
                                          ("goal", np.array([1.0, 2.0, 3.0])),
                                          ("t_arrive", float("inf"))])
def test_bad_requests_are_refused(intersection_sdf, field, value):
    req = dataclasses.replace(request(*LANES[0]), **{field: value})
    with pytest.raises(PlanningError):
        plan_trajectory(req, PlannerConfig(), intersection_sdf)


def test_bad_peer_epsilon_is_refused(intersection_sdf):
    req = request(*LANES[0], peers=(PeerConstraint(crossing_peer(), -1.0),))
    with pytest.raises(PlanningError):
        plan_trajectory(req, PlannerConfig(), intersection_sdf)


def test_chunked_factors_give_the_plan_of_one_factor_per_interval(intersection_sdf):
    """Chunking changes how GTSAM calls our factors, not the problem it solves."""
    req = request(*LANES[0], peers=(PeerConstraint(crossing_peer(6.0), EPS_0),))
    one = plan_trajectory(req, PlannerConfig(support_states=23, intervals_per_factor=1), intersection_sdf)
    for per_factor in (3, 5, 22):
        chunked = plan_trajectory(req, PlannerConfig(support_states=23, intervals_per_factor=per_factor),
                                  intersection_sdf)
        assert chunked.initial_error == pytest.approx(one.initial_error, rel=1e-9)
        assert chunked.iterations == one.iterations
        assert np.allclose(chunked.plan.positions, one.plan.positions, atol=1e-6)


def standing_peer(position, epsilon=EPS_0):
    return PeerConstraint(Plan(0.0, 1.0, np.tile(position, (3, 1)), np.zeros((3, 2))), epsilon)


def reach_times(horizon):
    """Check times (I, K) from 0 to ``horizon``."""
    return np.linspace(0.0, horizon, 32).reshape(8, 4)


def test_peers_out_of_reach_by_both_speed_bounds_are_left_out():
    config = PlannerConfig(max_speed_mps=0.5, reach_margin_m=0.2)
    times = reach_times(4.0)  # H = 4 s: together the cars close in by at most 4 m
    reach = EPS_0 + 0.2 + 2 * 0.5 * 4.0
    near = standing_peer(np.array([reach - 0.01, 0.0]))
    far = standing_peer(np.array([reach + 0.01, 0.0]))
    wide = standing_peer(np.array([reach + 0.01, 0.0]), epsilon=2 * EPS_0)
    kept = peers_within_reach((near, far, wide), np.zeros(2), times, config)
    assert [id(peer) for peer, _ in kept] == [id(near), id(wide)]
    (_, positions), _ = kept
    assert positions.shape == (*times.shape, 2)


def test_a_far_peer_whose_plan_comes_fast_is_kept():
    """Its plan breaks the speed bound: the graph would use it, so it stays."""
    config = PlannerConfig(max_speed_mps=0.5, reach_margin_m=0.2)
    start = np.array([20.0, 0.0])
    rushing = PeerConstraint(Plan(0.0, 4.0, np.array([start, [0.5, 0.0]]), np.array([[-5.0, 0.0], [0.0, 0.0]])), EPS_0)
    kept = peers_within_reach((rushing, standing_peer(start)), np.zeros(2), reach_times(4.0), config)
    assert [id(peer) for peer, _ in kept] == [id(rushing)]


def test_the_planner_counts_and_ignores_peers_out_of_reach(intersection_sdf):
    start, goal = LANES[0]
    far = standing_peer(np.array([40.0, 40.0]))
    crossing = PeerConstraint(crossing_peer(6.0), EPS_0)
    alone = plan_trajectory(request(start, goal, peers=(crossing,)), PlannerConfig(), intersection_sdf)
    both = plan_trajectory(request(start, goal, peers=(far, crossing)), PlannerConfig(), intersection_sdf)
    assert both.peers_out_of_reach == 1 and alone.peers_out_of_reach == 0
    assert np.allclose(both.plan.positions, alone.plan.positions, atol=1e-9)


def test_a_fleet_parked_at_its_goals_sets_no_pace(intersection_sdf):
    """Peers parked at their goals (far off, out of reach) leave the plan of a car at rest
    as it is alone: a consistency target of 0 would make every acceleration a cost, and
    the last car out would wait to set off. Peers that stand short of their goals (a knot)
    still set the pace of a fleet at rest."""
    start, goal = LANES[0]
    spots = (np.array([40.0, 40.0]), np.array([40.0, 41.0]))
    alone = plan_trajectory(request(start, goal), PlannerConfig(), intersection_sdf)
    parked = tuple(dataclasses.replace(standing_peer(spot), parked=True) for spot in spots)
    among_parked = plan_trajectory(request(start, goal, peers=parked), PlannerConfig(), intersection_sdf)
    assert np.allclose(among_parked.plan.positions, alone.plan.positions, atol=1e-9)
    standing = tuple(standing_peer(spot) for spot in spots)
    in_a_knot = plan_trajectory(request(start, goal, peers=standing), PlannerConfig(), intersection_sdf)
    assert not np.allclose(in_a_knot.plan.positions, alone.plan.positions, atol=1e-3)

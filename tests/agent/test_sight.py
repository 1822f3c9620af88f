"""Limited sight (agent.sight): which peers a car sees, which it knows it does not, the
distance it keeps from those, and the range the proximity guard needs."""

import dataclasses
import math

import numpy as np
import pytest

from trustfg.agent import sight
from trustfg.agent.car_agent import CarAgent
from trustfg.agent.config import ConfigError, Obstacle, SensingConfig, TrustConfig, WorldConfig
from trustfg.agent.config.scene import guard_needs_m
from trustfg.agent.gp import Plan
from trustfg.agent.guard import speed_cap
from trustfg.agent.messages import PeerTrust, PlanMessage, TrustReport
from trustfg.agent.scenario_files import load_scenario
from trustfg.agent.sightings import Track
from trustfg.agent.world import build_sdf

WALL = WorldConfig(bounds_m=(-2.0, -2.0, 2.0, 2.0), obstacles=(Obstacle(min=(-0.05, -1.0), max=(0.05, 1.0)),))


def test_in_sight_is_the_range_and_the_walls():
    others = np.array([[1.0, 0.0], [1.6, 0.0], [-1.2, 0.0], [0.0, 1.4]])
    np.testing.assert_array_equal(sight.in_sight((-0.5, 0.0), others, 1.5), [True, False, True, True])
    sdf = build_sdf(WALL)
    # The wall at x = 0 hides the car across it; the one around its end is seen.
    np.testing.assert_array_equal(sight.in_sight((-0.5, 0.0), others, 1.5, sdf), [False, False, True, True])
    assert sight.in_sight((-0.5, 0.0), others, math.inf, sdf).all()  # no range: the motion capture's view


def test_sight_matrix_and_what_a_car_process_hands_its_mind():
    seen = sight.sight_matrix(np.array([[0.0, 0.0], [1.0, 0.0], [2.2, 0.0]]), [1.5, 1.5, 3.0])
    np.testing.assert_array_equal(seen, [[True, True, False], [True, True, True], [True, True, True]])
    poses = {1: (0.0, 0.0, 0.0), 2: (1.0, 0.0, 0.0), 3: (2.2, 0.0, 0.0)}
    assert set(sight.visible(poses, 1, (0.0, 0.0), 1.5)) == {1, 2}
    assert set(sight.visible(poses, 1, None, 1.5)) == {1}  # not knowing where it is, it sees no peer
    assert sight.visible(poses, 1, None, math.inf) is poses


def test_out_of_sight_means_not_seen_lately():
    tracks = {1: Track(), 3: Track()}
    tracks[1].add(10.0, 0.0, 0.0, 0.0)
    tracks[3].add(9.0, 1.0, 0.0, 0.0)
    assert sight.out_of_sight(tracks, [1, 2, 3, 4], own_id=2, now=10.1) == {3, 4}


def test_the_guard_sees_far_enough_to_stop_for_a_car_head_on():
    """At the distance guard_needs_m gives, the guard's cap against a car coming head on
    is the vehicle's top speed: nearer, it brakes; farther, it need not (agent.guard)."""
    scenario = load_scenario("intersection")
    guard, safety, vmax = scenario.guard, scenario.safety, scenario.vehicle.max_speed_mps
    needs = guard_needs_m(safety.breach_distance(0.1, 0.1), guard.stop_margin_m, vmax, guard.reaction_s,
                          guard.decel_mps2)
    assert needs == pytest.approx(1.15)
    for d, brakes in ((needs - 0.01, True), (needs + 0.01, False)):
        cap = speed_cap(0.0, 0.0, 0.0, 0.1, [(d, 0.0, math.pi, 0.1)], guard, safety)
        assert (cap < vmax) == brakes
    short = dataclasses.replace(scenario, sensing=SensingConfig(range_m=needs - 0.05))
    with pytest.raises(ConfigError, match="sensing.range_m"):
        short.validate()
    dataclasses.replace(scenario, sensing=SensingConfig(range_m=needs + 0.05)).validate()
    car = dataclasses.replace(scenario.cars[0], sensing_range_m=1.0)
    with pytest.raises(ConfigError, match=r"cars\[0\].sensing_range_m"):
        dataclasses.replace(scenario, cars=(car, *scenario.cars[1:])).validate()


def unseen_setup(range_m: float | None, testimonies: bool = True, praise: bool = True):
    """Car 2 sees car 3 (a witness it has watched for a while) and not car 1, which is
    2.5 m away; car 1's plan arrives, and car 3 testifies that car 1 does well."""
    scenario = load_scenario("intersection")
    scenario = dataclasses.replace(scenario, sensing=SensingConfig(range_m=range_m),
                                   trust=dataclasses.replace(scenario.trust, testimonies=testimonies))
    agent = CarAgent(scenario.car(2), scenario, build_sdf(scenario.world))
    for k in range(100):
        t = 0.02 * k
        agent.observe(t, 2, 0.0, 0.0, 0.0)
        agent.observe(t, 3, 0.5, 0.5, 0.0)
        for d in range(3):
            agent.trust.record(3, d, 1.0, 0.0, t)
    t = 2.0
    plan = Plan(t, 0.25, np.tile([2.5, 0.0], (9, 1)), np.zeros((9, 2)))
    agent.receive(PlanMessage(1, 1, t, plan, (2.5, 0.0)), t)
    if praise:
        good = PeerTrust((40.0,) * 3, (0.0,) * 3, (0.98,) * 3, 0.98, 0.45)
        agent.receive(TrustReport(3, 1, t, {1: good}), t)
    return agent, t


def test_an_unseen_peer_is_planned_at_its_witnesses_trust_never_as_if_fully_trusted():
    """Out of sight, car 1's plan cannot be checked: car 2 plans against it at the epsilon
    of the trust car 3's testimony gives it, but never closer than unseen_epsilon; without
    testimonies (or without a witness), at the widest epsilon."""
    widest = {}
    for testimonies, praise in ((True, True), (False, True), (True, False)):
        agent, t = unseen_setup(1.5, testimonies, praise)
        (epsilon,) = [c.epsilon for peer, c in agent.peer_constraints(t) if peer == 1]
        widest[(testimonies, praise)] = epsilon
        assert agent.counters["peers_out_of_sight"] == 1
    eps0 = load_scenario("intersection").safety.epsilon_0(0.1, 0.1)
    floor = sight.unseen_epsilon(eps0, TrustConfig())
    assert widest[(True, True)] == pytest.approx(floor)
    assert floor > eps0 + 0.1
    assert widest[(False, True)] == pytest.approx(2.0 * eps0)
    assert widest[(True, False)] == pytest.approx(2.0 * eps0)


def test_with_unlimited_sight_an_unchecked_plan_is_kept_at_the_widest_epsilon():
    agent, t = unseen_setup(None)
    (epsilon,) = [c.epsilon for peer, c in agent.peer_constraints(t) if peer == 1]
    assert epsilon == pytest.approx(2.0 * load_scenario("intersection").safety.epsilon_0(0.1, 0.1))
    assert "peers_out_of_sight" not in agent.counters

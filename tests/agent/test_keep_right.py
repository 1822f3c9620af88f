"""Keeping right: car-like plans that close on a peer pass it on their left side."""

import dataclasses
import math

import numpy as np
import pytest

from trustfg.agent.config import ConfigError, PlannerConfig, WorldConfig
from trustfg.agent.gp import Plan
from trustfg.agent.keep_right import keep_right
from trustfg.agent.planner import PeerConstraint, PlanRequest, plan_trajectory
from trustfg.agent.world import build_sdf

EPS = 0.45
OFFSET = 0.1


def _one(own, direction, own_velocity, peer, peer_velocity, offset=OFFSET):
    """keep_right at one check time against one peer."""
    shape = (1, 1, 2)
    positions, epsilons = keep_right(np.reshape(own, shape), np.reshape(direction, shape),
                                     np.reshape(own_velocity, shape), np.reshape(peer, (1, 1, 1, 2)),
                                     np.reshape(peer_velocity, (1, 1, 1, 2)), np.array([EPS]), offset)
    return positions[0, 0, 0], epsilons[0]


def test_a_peer_we_close_on_ahead_is_seen_to_the_left_and_kept_as_far_away():
    q, eps = _one([0.0, 0.0], [1.0, 0.0], [0.3, 0.0], [1.0, 0.0], [-0.3, 0.0])
    np.testing.assert_allclose(q, [1.0, OFFSET])
    assert eps == pytest.approx(math.sqrt(EPS ** 2 + OFFSET ** 2))
    rng = np.random.default_rng(0)
    for _ in range(50):  # shifted normal to the line of sight: the distance grows as stated
        own, peer = rng.uniform(-2, 2, 2), rng.uniform(-2, 2, 2)
        direction = (peer - own) / np.linalg.norm(peer - own)
        q, _ = _one(own, direction, 0.3 * direction, peer, -0.2 * direction)
        assert np.linalg.norm(q - own) ** 2 == pytest.approx(np.linalg.norm(peer - own) ** 2 + OFFSET ** 2)


@pytest.mark.parametrize("own_velocity, peer, peer_velocity", [
    ([0.3, 0.0], [-1.0, 0.0], [0.5, 0.0]),   # behind us, catching up
    ([0.3, 0.0], [1.0, 0.0], [0.4, 0.0]),    # ahead, drawing away
    ([0.0, 0.0], [1.0, 0.0], [0.01, 0.0]),   # neither of us moves
])
def test_peers_behind_or_not_closing_are_seen_where_they_are(own_velocity, peer, peer_velocity):
    q, eps = _one([0.0, 0.0], [1.0, 0.0], own_velocity, peer, peer_velocity)
    np.testing.assert_allclose(q, peer)
    assert eps == EPS


def test_off_it_changes_nothing():
    q, eps = _one([0.0, 0.0], [1.0, 0.0], [0.3, 0.0], [1.0, 0.0], [-0.3, 0.0], offset=0.0)
    np.testing.assert_allclose(q, [1.0, 0.0])
    assert eps == EPS


def test_the_offset_must_be_finite_and_not_negative():
    for bad in (-0.1, math.nan, math.inf):
        with pytest.raises(ConfigError, match="keep_right_m"):
            PlannerConfig(keep_right_m=bad).validate("planner")


def _side_passed(plan: Plan, peer: Plan) -> float:
    """Where the peer is across our direction of travel when the two are nearest (+: on
    our left)."""
    times = np.linspace(plan.t0, plan.t_end, 200)
    ours, velocities = plan.state_at(times)
    gaps = ours - peer.position_at(times)
    i = int(np.argmin(np.linalg.norm(gaps, axis=1)))
    v = velocities[i] / np.linalg.norm(velocities[i])
    return float(v[0] * -gaps[i, 1] - v[1] * -gaps[i, 0])


def test_head_on_a_car_like_plan_passes_the_peer_on_its_left():
    """A peer drives straight at us along y = 0 and we start a little left of its line:
    the proximity hinge alone passes it on our right; keeping right passes it on our left,
    in every draw, as far from it as the hinge keeps (from the peer's real plan)."""
    sdf = build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0)))
    sides = {0.0: [], OFFSET: []}
    for seed in range(10):
        rng = np.random.default_rng(seed)
        y0 = rng.uniform(0.0, 0.03)
        speed = rng.uniform(0.3, 0.4)
        times = np.linspace(0.0, 8.0, 9)
        peer = Plan(0.0, 1.0, np.stack([1.5 - speed * times, np.zeros(9)], axis=1),
                    np.tile([-speed, 0.0], (9, 1)))
        request = PlanRequest(t_now=0.0, position=np.array([-1.5, y0]), velocity=np.zeros(2),
                              goal=np.array([1.5, y0]), t_arrive=8.0, epsilon_obstacle=0.25,
                              lane=((-1.5, y0),), peers=(PeerConstraint(peer, EPS),), steering=(0.0, 0.3))
        for offset in sides:
            config = PlannerConfig(keep_right_m=offset)
            plan = plan_trajectory(request, config, sdf).plan
            for _ in range(3):  # replanned from where the last plan left off, as a car does
                plan = plan_trajectory(dataclasses.replace(request, warm_start=plan), config, sdf).plan
            sides[offset].append(_side_passed(plan, peer))
            if offset:
                times = np.linspace(0.0, 8.0, 400)
                least = np.min(np.linalg.norm(plan.position_at(times) - peer.position_at(times), axis=1))
                assert least > EPS - 0.03, (seed, least)
    assert all(side > 0 for side in sides[OFFSET]), sides
    assert sum(side < 0 for side in sides[0.0]) >= 8, sides


def test_a_car_that_turns_in_place_plans_as_without_it():
    """It can turn away on the spot: its graph never sees peers shifted."""
    sdf = build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0)))
    times = np.linspace(0.0, 8.0, 9)
    peer = Plan(0.0, 1.0, np.stack([1.5 - 0.35 * times, np.zeros(9)], axis=1), np.tile([-0.35, 0.0], (9, 1)))
    request = PlanRequest(t_now=0.0, position=np.array([-1.5, 0.01]), velocity=np.zeros(2),
                          goal=np.array([1.5, 0.01]), t_arrive=8.0, epsilon_obstacle=0.25,
                          peers=(PeerConstraint(peer, EPS),))
    kept = plan_trajectory(request, PlannerConfig(keep_right_m=OFFSET), sdf).plan
    plain = plan_trajectory(request, PlannerConfig(keep_right_m=0.0), sdf).plan
    np.testing.assert_array_equal(kept.positions, plain.positions)
    np.testing.assert_array_equal(kept.velocities, plain.velocities)

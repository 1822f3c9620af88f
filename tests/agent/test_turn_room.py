"""Turning room: a car-like plan keeps the room to turn away from a peer ahead
(agent.turn_room): the geometry, its Jacobians, and what it asks of a plan."""

import dataclasses
import math

import gtsam
import numpy as np
import pytest

from trustfg.agent.config import PlannerConfig, WorldConfig
from trustfg.agent.gp import Plan
from trustfg.agent.planner import PeerConstraint, PlanRequest, plan_trajectory, planned_turn_radius
from trustfg.agent.steering import MOVING_MPS
from trustfg.agent.turn_room import add_turn_room_factors, room_rows
from trustfg.agent.world import build_sdf

R, EPS = 0.345, 0.45
FAR = 10.0
"""An epsilon no room reaches: the row is then FAR - room, room itself."""


def room(position, heading, peer, radius=R) -> float:
    return FAR - float(room_rows(np.asarray(position, float), heading, np.asarray([peer], float),
                                 np.array([FAR]), radius)[0][0])


def test_head_on_a_car_needs_the_root_of_eps_squared_plus_two_eps_r():
    """Head on, the turn away keeps eps from the peer exactly when d = sqrt(eps^2 + 2 eps R):
    the room is then eps, and less nearer."""
    d = math.sqrt(EPS ** 2 + 2 * EPS * R)
    assert room((0.0, 0.0), 0.0, (d, 0.0)) == pytest.approx(EPS, abs=1e-12)
    assert room((0.0, 0.0), 0.0, (d - 0.05, 0.0)) < EPS - 0.03


@pytest.mark.parametrize("bearing", np.linspace(-math.pi, math.pi, 25))
def test_room_is_the_distance_beside_and_behind_and_never_more(bearing):
    """A peer beside or behind is left along the way on: room = d; ahead room < d, the more
    the nearer dead ahead; the turning circle's gap, checked against a sampled circle."""
    d, heading = 0.6, 0.7
    peer = d * np.array([math.cos(heading + bearing), math.sin(heading + bearing)])
    got = room((0.0, 0.0), heading, peer)
    if math.cos(bearing) <= 0.0:
        assert got == pytest.approx(d, abs=1e-12)
        return
    assert got <= d + 1e-12
    side = -1.0 if math.sin(bearing) >= 0.0 else 1.0  # the turn away from the peer
    centre = side * R * np.array([-math.sin(heading), math.cos(heading)])
    angles = np.linspace(0.0, 2 * math.pi, 20001)
    circle = centre + R * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    assert got == pytest.approx(float(np.min(np.hypot(*(circle - peer).T))), abs=1e-6)


@pytest.mark.parametrize("seed", range(6))
def test_jacobians_match_numerical(seed):
    rng = np.random.default_rng(seed)
    position, heading = rng.uniform(-1.0, 1.0, 2), rng.uniform(-4.0, 4.0)
    peers = position + rng.uniform(-0.7, 0.7, (12, 2))
    epsilons = np.full(12, 0.6)
    residual, d_p, d_theta = room_rows(position, heading, peers, epsilons, R)
    assert np.count_nonzero(residual) >= 4  # the hinges were tried active, not only flat
    h = 1e-7
    for axis in range(2):
        step = np.eye(2)[axis] * h
        numeric = (room_rows(position + step, heading, peers, epsilons, R)[0]
                   - room_rows(position - step, heading, peers, epsilons, R)[0]) / (2 * h)
        assert np.allclose(d_p[:, axis], numeric, atol=1e-6)
    numeric = (room_rows(position, heading + h, peers, epsilons, R)[0]
               - room_rows(position, heading - h, peers, epsilons, R)[0]) / (2 * h)
    assert np.allclose(d_theta, numeric, atol=1e-6)


def _least_room(plan: Plan, peer: np.ndarray, radius: float) -> float:
    """The least room over the support states between a plan's first and its last, of
    those that move (a moving state's heading is its direction of motion)."""
    return min(room(plan.positions[i], math.atan2(plan.velocities[i, 1], plan.velocities[i, 0]), peer, radius)
               for i in range(1, plan.n - 1) if np.hypot(*plan.velocities[i]) > 0.05)


def test_a_car_like_plan_to_a_goal_short_of_a_standing_peer_keeps_its_turning_room():
    """A goal 0.55 m short of a car that stands ahead, roughly head on: without the rows
    (and without keeping right, which also steers past it) the plan drives at it and its
    states keep well under eps of turning room; with them each keeps more, and nearly eps
    (the rows are soft), in every draw."""
    sdf = build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0)))
    min_turn_radius = 0.3
    for seed in range(12):
        rng = np.random.default_rng(seed)
        goal = np.array([1.5, rng.uniform(-0.2, 0.2)])
        bearing = rng.uniform(-0.3, 0.3)
        peer = goal + 0.55 * np.array([math.cos(bearing), math.sin(bearing)])
        standing = PeerConstraint(Plan(0.0, 10.0, np.array([peer, peer]), np.zeros((2, 2))), EPS)
        request = PlanRequest(t_now=0.0, position=np.array([-1.0, 0.0]), velocity=np.zeros(2), goal=goal,
                              t_arrive=8.0, epsilon_obstacle=0.25, lane=((-1.0, 0.0),), peers=(standing,),
                              steering=(0.0, min_turn_radius))
        radius = planned_turn_radius(request, PlannerConfig())
        alone = PlannerConfig(keep_right_m=0.0)  # the rows alone, without keeping right
        kept = _least_room(plan_trajectory(request, dataclasses.replace(alone, turn_room=True), sdf).plan, peer,
                           radius)
        unkept = _least_room(plan_trajectory(request, alone, sdf).plan, peer, radius)
        assert kept > unkept + 0.02, (seed, kept, unkept)
        assert kept > EPS - 0.07, (seed, kept)


def test_rows_stand_against_peers_that_stand_only():
    """A peer whose plan moves on makes its own room: no rows against it; one that stands
    (or creeps slower than MOVING_MPS) gets them where it stands."""
    n, checks, dt = 9, 5, 0.5
    t = (np.arange(n - 1)[:, None] + np.arange(checks)[None, :] / checks) * dt  # (I, K)

    def rows_against(speed: float) -> int:
        positions = np.stack([1.0 + speed * t, np.zeros_like(t)], axis=-1)[:, :, None, :]  # (I, K, 1, 2)
        graph = gtsam.NonlinearFactorGraph()
        add_turn_room_factors(graph, positions, np.array([EPS]), dt, R, 4, 0.02)
        return graph.size()

    assert rows_against(0.3) == 0
    assert rows_against(-0.3) == 0
    assert rows_against(0.0) == 2  # states 1..7 in chunks of 4
    assert rows_against(0.5 * MOVING_MPS) == 2

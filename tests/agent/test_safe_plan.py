"""A replan made safe (agent.safe_plan) and its fallback (agent.fallback): a plan that fails
verification is not used; other guesses are tried; without one the car brakes along its
last verified plan and stops short of what it knows of."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent.config import Obstacle, PlannerConfig, SafetyConfig, VehicleConfig, VerifyConfig, WorldConfig
from trustfg.agent.fallback import brake_after, fallback
from trustfg.agent.gp import Plan, standing
from trustfg.agent.planner import PeerConstraint, PlanRequest, PlanResult, plan_trajectory
from trustfg.agent.retime import retime
from trustfg.agent.safe_plan import (
    AROUND_MARGIN_M,
    FALLBACK,
    FIRST,
    RETRY,
    SLOWER_HORIZON,
    UNVERIFIED,
    _pass_head_on,
    around_standing,
    backs_away,
    head_on,
    plan_safely,
)
from trustfg.agent.verify import Bounds, verify
from trustfg.agent.world import build_sdf

SAFETY = SafetyConfig()
R = 0.1
EPS = SAFETY.epsilon_0(R, R)
CONFIG = VerifyConfig()
PLANNER = PlannerConfig()


def bounds(peers: int) -> Bounds:
    return Bounds.of(SAFETY.epsilon_obstacle(R), SAFETY.obstacle_breach(R),
                     [SAFETY.breach_distance(R, R)] * peers, VehicleConfig())


def straight(start, end, t0=0.0, duration=10.0, n=21) -> Plan:
    start, end = np.asarray(start, float), np.asarray(end, float)
    u = np.linspace(0.0, 1.0, n)
    s = 3 * u**2 - 2 * u**3  # from rest to rest
    ds = (6 * u - 6 * u**2) / duration
    return Plan(t0, duration / (n - 1), start + s[:, None] * (end - start), ds[:, None] * (end - start))


def least_gap(plan: Plan, peer: Plan) -> float:
    times = np.linspace(plan.t0, plan.t_end, 4000)
    return float(np.min(np.linalg.norm(plan.position_at(times) - peer.position_at(times), axis=1)))


@pytest.fixture(scope="module")
def narrow():
    """A street 0.9 m wide (walls at y = +-0.45)."""
    return build_sdf(WorldConfig(bounds_m=(-3.0, -0.45, 3.0, 0.45)))


@pytest.fixture(scope="module")
def room():
    return build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0)))


def test_a_plan_that_fails_verification_is_not_used_the_car_stops_short(narrow):
    """A peer stands in a street too narrow to pass it at epsilon; the optimiser's plan
    squeezes past (soft hinges), so no plan verifies: the car brakes along its verified
    plan and stops short of the peer."""
    peer = standing(np.array([0.0, 0.15]), 0.0)  # passing it needs 0.41 m, the wall leaves 0.36
    verified = straight((-2.0, 0.0), (2.0, 0.0))  # verified before the peer stood there
    t_now = 2.0
    (p,), (v,) = verified.state_at(t_now)
    request = PlanRequest(t_now, p, v, np.array([2.0, 0.0]), 10.0, SAFETY.epsilon_obstacle(R),
                          peers=(PeerConstraint(peer, EPS),), warm_start=verified)
    outcome = plan_safely(request, bounds(1), PLANNER, CONFIG, narrow, verified)
    need = EPS - CONFIG.tolerance * (EPS - SAFETY.breach_distance(R, R))
    assert outcome.outcome == FALLBACK and outcome.blocked_by == (0,)
    assert outcome.verdict.ok
    assert least_gap(outcome.plan, peer) >= need
    (v_end,) = outcome.plan.state_at(outcome.plan.t_end)[1]
    assert np.linalg.norm(v_end) < 1e-6 and outcome.plan.positions[-1][0] < 0.0  # stopped, short of it
    # What the optimiser alone would have driven:
    unverified = plan_safely(request, bounds(1), PLANNER, dataclasses.replace(CONFIG, enabled=False), narrow, verified)
    assert unverified.outcome == UNVERIFIED and least_gap(unverified.plan, peer) < need


def test_a_plan_through_the_middle_of_a_peer_is_retried_on_its_other_side(room):
    """A warm start right through a peer (creeping towards us) feels no push to either
    side (the hinge's gradient vanishes at its centre): warm and tightened plans fail;
    'other side' passes."""
    peer = straight((0.1, 0.0), (-0.1, 0.0))
    through = straight((-2.0, 0.0), (2.0, 0.0))
    request = PlanRequest(0.0, np.array([-2.0, 0.0]), np.zeros(2), np.array([2.0, 0.0]), 10.0,
                          SAFETY.epsilon_obstacle(R), peers=(PeerConstraint(peer, EPS),), warm_start=through)
    outcome = plan_safely(request, bounds(1), PLANNER, CONFIG, room, None)
    assert outcome.outcome == RETRY and outcome.tried[:3] == ("warm", "tighten", "other side")
    assert outcome.first_broke == ("peer",)  # what the warm plan broke
    assert verify(outcome.plan, request.peers, bounds(1), room, CONFIG).ok
    once = plan_safely(request, bounds(1), PLANNER, dataclasses.replace(CONFIG, max_attempts=1), room, None)
    assert once.outcome == FALLBACK  # without the retries: no verified plan this replan
    out_of_time = plan_safely(request, bounds(1), PLANNER, CONFIG, room, None, wall_limit_s=0.0)
    assert out_of_time.outcome == FALLBACK and out_of_time.tried == ("warm",)  # no retry past the wall limit
    in_time = plan_safely(request, bounds(1), PLANNER, CONFIG, room, None, wall_limit_s=60.0)
    assert in_time.tried == outcome.tried and np.array_equal(in_time.plan.positions, outcome.plan.positions)


def test_a_clear_plan_verifies_first_try(room):
    request = PlanRequest(0.0, np.array([-2.0, 0.0]), np.zeros(2), np.array([2.0, 0.0]), 10.0,
                          SAFETY.epsilon_obstacle(R))
    outcome = plan_safely(request, bounds(0), PLANNER, CONFIG, room, None)
    assert outcome.outcome == FIRST and outcome.tried == ("cold",) and outcome.verdict.ok
    assert outcome.first_broke == ()


def test_a_car_whose_goal_a_waiting_peer_stands_on_sets_off_with_a_finite_hold(room):
    """A ring swap at the go: the peer that starts on our goal waits there (its standing
    plans end 2 s on). Held there for good, it fails every plan to our goal and we stand
    on the fallback, as every car of the ring would; held for 3 s (the car that goes first
    of two that swap places, agent.car_agent), our plan is used -- we are 10 s from the
    goal, and the peer's next plans say where it is then."""
    def request(hold_s):
        peer = PeerConstraint(standing(np.array([2.0, 0.0]), 0.0), EPS, hold_s)
        return PlanRequest(0.0, np.array([-2.0, 0.0]), np.zeros(2), np.array([2.0, 0.0]), 10.0,
                           SAFETY.epsilon_obstacle(R), peers=(peer,))
    held = plan_safely(request(3.0), bounds(1), PLANNER, CONFIG, room, None)
    assert held.outcome in (FIRST, RETRY) and held.verdict.ok, held.tried
    assert np.linalg.norm(held.plan.positions[3] - np.array([-2.0, 0.0])) > 0.05  # it drives
    assert plan_safely(request(None), bounds(1), PLANNER, CONFIG, room, None).outcome == FALLBACK


def test_braking_slows_at_the_given_rate_along_the_path_and_stands():
    timing = straight((-2.0, 0.0), (2.0, 1.0))
    t_b, decel = 4.0, 1.0
    plan = brake_after(timing, t_b, decel, 1.0)
    times = np.linspace(1.0, plan.t_end + 1.0, 600)
    speed = np.linalg.norm(plan.state_at(times)[1], axis=1)
    before = times <= t_b
    assert np.allclose(plan.position_at(times[before]), timing.position_at(times[before]), atol=2e-3)
    braking = np.diff(speed[~before]) / np.diff(times[~before])
    assert np.all(braking <= 0.15) and np.min(braking) >= -1.25 * decel  # never speeds up; ~decel
    assert speed[-1] < 1e-6
    path = timing.position_at(np.linspace(0.0, 10.0, 2000))
    off = [np.min(np.linalg.norm(path - q, axis=1)) for q in plan.position_at(times)]
    assert max(off) < 0.01  # on the path


def test_the_fallback_keeps_a_verified_plan_while_it_is_clear_and_brakes_short_of_a_newcomer(room):
    verified = straight((-2.0, 0.0), (2.0, 0.0))
    t_now = 3.0
    (p,), (v,) = verified.state_at(t_now)
    clear = PlanRequest(t_now, p, v, np.array([2.0, 0.0]), 10.0, SAFETY.epsilon_obstacle(R))
    kept, verdict = fallback(verified, clear, bounds(0), room, CONFIG)
    assert kept is verified and verdict.ok
    newcomer = standing(np.array([1.0, 0.0]), t_now)  # now stands on the way ahead
    blocked = dataclasses.replace(clear, peers=(PeerConstraint(newcomer, EPS),))
    plan, verdict = fallback(verified, blocked, bounds(1), room, CONFIG)
    assert verdict.ok and plan is not verified
    assert least_gap(plan, newcomer) >= EPS - CONFIG.tolerance * (EPS - SAFETY.breach_distance(R, R))
    assert plan.positions[-1][0] > p[0] + 0.1  # it went on as far as it safely could


@pytest.mark.parametrize("speed", [0.025, 0.05, 0.1])
def test_a_car_creeping_off_its_plan_gets_a_fallback_that_comes_to_rest(room, speed):
    """A car a few cm/s off its verified plan's timing gets a cruise at that speed along its
    path; kept as if it stopped (a plan reads zero speed after its end), it would be kept at
    every replan and the car would creep on for good. The fallback's last state rests."""
    verified = straight((-2.0, 0.0), (2.0, 0.0))
    t_now = 5.0  # the plan is at its fastest here; the car, held back, creeps on its path
    (p,), _ = verified.state_at(t_now)
    request = PlanRequest(t_now, p, np.array([speed, 0.0]), np.array([2.0, 0.0]), 10.0, SAFETY.epsilon_obstacle(R))
    plan, verdict = fallback(verified, request, bounds(0), room, CONFIG)
    assert verdict.ok
    assert np.linalg.norm(plan.velocities[-1]) < 1e-6
    assert plan.positions[-1][0] > p[0]  # it still goes on as far as it safely can


def test_a_car_without_a_verified_plan_that_stands_keeps_standing(room):
    request = PlanRequest(0.0, np.array([0.5, 0.5]), np.zeros(2), np.array([2.0, 0.0]), 10.0,
                          SAFETY.epsilon_obstacle(R))
    plan, verdict = fallback(None, request, bounds(0), room, CONFIG)
    assert np.allclose(plan.positions, [0.5, 0.5]) and np.allclose(plan.velocities, 0.0)


def test_an_obstacle_in_the_way_is_passed_by_the_retries():
    """A straight route through the middle of a pillar: no gradient to either side."""
    sdf = build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0),
                                obstacles=(Obstacle(min=(-0.3, -0.3), max=(0.3, 0.3)),)))
    request = PlanRequest(0.0, np.array([-2.0, 0.0]), np.zeros(2), np.array([2.0, 0.0]), 12.0,
                          SAFETY.epsilon_obstacle(R))
    outcome = plan_safely(request, bounds(0), PLANNER, CONFIG, sdf, None)
    assert outcome.outcome in (FIRST, RETRY) and outcome.verdict.ok


def standing_off_its_lane(seed: int) -> PlanRequest:
    """A car standing still 0.3-0.45 m off its lane (y = -0.4, west to east), as after a
    swerve; the rest of the way at 0.39 m/s, as the car agent asks."""
    rng = np.random.default_rng(seed)
    start = np.array([rng.uniform(-1.8, -1.0), -0.4 + rng.uniform(0.3, 0.45)])
    goal = np.array([2.15, -0.4])
    t_arrive = float(np.linalg.norm(goal - start)) / 0.39 + 0.5
    return PlanRequest(0.0, start, np.zeros(2), goal, t_arrive, SAFETY.epsilon_obstacle(R), lane=((-2.15, -0.4),))


@pytest.mark.parametrize("seed", range(12))
def test_a_car_standing_off_its_lane_gets_a_verified_plan(room, seed):
    outcome = plan_safely(standing_off_its_lane(seed), bounds(0), PLANNER, CONFIG, room, None)
    assert outcome.outcome in (FIRST, RETRY) and outcome.verdict.ok, outcome.tried


def test_off_its_lane_the_lane_alone_asks_more_than_the_car_can(room):
    """What the ``retimed`` and ``off lane`` retries are for: with lane keeping, the
    optimiser's plan breaks the vehicle's limits at its pace and at the slower one."""
    broken = 0
    for seed in range(12):
        request = standing_off_its_lane(seed)
        slower = dataclasses.replace(request, t_arrive=request.t_now + SLOWER_HORIZON * (request.t_arrive - request.t_now))
        verdicts = [verify(plan_trajectory(r, PLANNER, room).plan, [], bounds(0), room, CONFIG) for r in (request, slower)]
        broken += all(any(c.kind == "limits" for c in v.conflicts) for v in verdicts)
    assert broken >= 9, broken  # most seeds: the retries exist for a common case, not a rare one


@pytest.mark.parametrize("seed", range(12))
def test_a_plan_that_sets_off_too_fast_is_retimed_along_the_same_path(room, seed):
    """From a standstill the plan sets off faster than the car accelerates; its retimed
    version keeps the path, is never sooner than the plan, and passes the limits."""
    request = standing_off_its_lane(seed)
    plan = plan_trajectory(request, PLANNER, room).plan
    assert any(c.kind == "limits" for c in verify(plan, [], bounds(0), room, CONFIG).conflicts)
    paced = retime(plan, 0.0, VehicleConfig().max_speed_mps, VehicleConfig().max_accel_mps2)
    assert verify(paced, [], bounds(0), room, CONFIG).ok
    fine = plan.position_at(np.linspace(plan.t0, plan.t_end, 2000))
    on_path = np.min(np.linalg.norm(paced.positions[:, None, :] - fine[None, :, :], axis=2), axis=1)
    assert np.all(on_path < 0.01)
    gone = lambda p, t: np.linalg.norm(p.position_at(t) - p.positions[0])  # noqa: E731
    assert all(gone(paced, t) <= gone(plan, t) + 0.01 for t in plan.times())  # never ahead of the plan


def test_a_plan_that_sets_off_while_the_car_stands_is_not_used(room, monkeypatch):
    """The optimiser's start prior on velocity is soft: pressed by a hinge it returns a plan
    moving at 0.5 m/s at its first instant for a car that stands. That plan is checked from
    the car's speed, refused, and retimed to set off from rest."""
    request = PlanRequest(t_now=0.0, position=np.array([-2.0, 0.0]), velocity=np.zeros(2),
                          goal=np.array([2.0, 0.0]), t_arrive=8.0, epsilon_obstacle=SAFETY.epsilon_obstacle(R))
    result = plan_trajectory(request, PLANNER, room)
    times = result.plan.times()
    flying = Plan(0.0, result.plan.dt, np.c_[-2.0 + 0.5 * times, np.zeros_like(times)],
                  np.tile([0.5, 0.0], (len(times), 1)))  # 0.5 m/s from the first instant
    monkeypatch.setattr("trustfg.agent.safe_plan.plan_trajectory",
                        lambda *a, **k: dataclasses.replace(result, plan=flying))
    outcome = plan_safely(request, bounds(0), PLANNER, CONFIG, room, None)
    assert outcome.tried[:2] == ("cold", "retimed"), outcome.tried
    assert outcome.outcome == RETRY and outcome.first_broke == ("limits",)
    assert np.linalg.norm(outcome.plan.velocities[0]) < 0.05


def test_a_plan_that_breaks_only_the_limits_is_retimed_first(room):
    outcome = plan_safely(standing_off_its_lane(0), bounds(0), PLANNER, CONFIG, room, None)
    assert outcome.outcome == RETRY and outcome.tried[1] == "retimed", outcome.tried


def test_a_plan_through_a_parked_peer_is_retried_along_a_route_round_it(room):
    """The same through a peer that stands: 'around' seeds the plan on a grid route that
    keeps the peer's epsilon, and it verifies."""
    peer = standing(np.array([0.0, 0.0]), 0.0)
    through = straight((-2.0, 0.0), (2.0, 0.0))
    request = PlanRequest(0.0, np.array([-2.0, 0.0]), np.zeros(2), np.array([2.0, 0.0]), 10.0,
                          SAFETY.epsilon_obstacle(R), peers=(PeerConstraint(peer, EPS),), warm_start=through,
                          lane=((-2.0, 0.0),))
    outcome = plan_safely(request, bounds(1), PLANNER, CONFIG, room, None)
    assert outcome.outcome == RETRY and "around" in outcome.tried
    assert verify(outcome.plan, request.peers, bounds(1), room, CONFIG).ok
    detour = around_standing(request, verify(through, request.peers, bounds(1), room, CONFIG).conflicts, room)
    assert detour.lane == () and detour.warm_start is None and detour.t_arrive > request.t_arrive
    route = np.array([request.position, *detour.route, request.goal])
    samples = np.vstack([np.linspace(a, b, 50) for a, b in zip(route[:-1], route[1:])])
    assert np.min(np.linalg.norm(samples, axis=1)) >= EPS + AROUND_MARGIN_M - 0.03  # a grid cell's slack


def test_around_is_for_peers_that_stand_only(room):
    creeping = straight((0.0, -0.1), (0.0, 0.1))
    through = straight((-2.0, 0.0), (2.0, 0.0))
    request = PlanRequest(0.0, np.array([-2.0, 0.0]), np.zeros(2), np.array([2.0, 0.0]), 10.0,
                          SAFETY.epsilon_obstacle(R), peers=(PeerConstraint(creeping, EPS),), warm_start=through)
    conflicts = verify(through, request.peers, bounds(1), room, CONFIG).conflicts
    assert conflicts and around_standing(request, conflicts, room) is None


def backing_away(start, duration=10.0) -> Plan:
    """From ``start`` 1.5 m back along -x, waiting there, then on to (2, 0): a plan that
    backs away first."""
    back = straight(start, (start[0] - 1.5, start[1]), duration=duration / 2, n=11)
    on = straight((start[0] - 1.5, start[1]), (2.0, 0.0), t0=duration / 2, duration=duration / 2, n=11)
    return Plan(0.0, back.dt, np.vstack([back.positions, on.positions[1:]]),
                np.vstack([back.velocities, on.velocities[1:]]))


def test_a_plan_backs_away_when_it_leads_further_from_the_goal_within_a_second():
    start = np.array([-0.5, 0.0])
    request = PlanRequest(0.0, start, np.zeros(2), np.array([2.0, 0.0]), 10.0, SAFETY.epsilon_obstacle(R))
    assert backs_away(backing_away(start), request)
    assert not backs_away(straight(start, (2.0, 0.0)), request)
    assert not backs_away(standing(start, 0.0), request)  # waiting is not backing away


def test_a_peer_comes_head_on_when_it_closes_in_ahead_on_our_way():
    start, goal = np.array([-1.0, 0.0]), np.array([2.0, 0.0])

    def request(*peers):
        return PlanRequest(0.0, start, np.zeros(2), goal, 10.0, SAFETY.epsilon_obstacle(R),
                           peers=tuple(PeerConstraint(p, EPS) for p in peers))

    coming = straight((1.5, 0.1), (-2.5, 0.1), duration=8.0)
    assert head_on(request(coming)) is None  # from rest: not closing in yet at t = 0
    moving = Plan(coming.t0, coming.dt, coming.positions, coming.velocities)
    at = dataclasses.replace(request(moving), t_now=2.0)
    assert head_on(at) == 0
    going = straight((1.5, 0.1), (2.5, 0.1), duration=8.0)  # ahead, but driving away
    aside = straight((1.5, 1.5), (-2.5, 1.5), duration=8.0)  # closing in, but off our way
    behind = straight((-2.0, 0.0), (-2.9, 0.0), duration=8.0)
    assert head_on(dataclasses.replace(request(going, aside, behind), t_now=2.0)) is None
    assert head_on(dataclasses.replace(request(going, moving, aside), t_now=2.0)) == 1


def test_a_car_backing_away_from_a_peer_head_on_passes_it_on_its_right(room):
    """Two cars swapping ends of one diameter: a car that backs away from its partner backs
    to its start -- the partner's goal -- and passes it there, too late. Given a verified
    plan that backs away, ``pass`` finds one that passes on the right."""
    peer = straight((2.0, 0.0), (-2.5, 0.0), duration=8.0)
    t_now = 2.0
    start = np.array([-0.5, 0.0])
    request = PlanRequest(t_now, start, np.zeros(2), np.array([2.0, 0.0]), 12.0, SAFETY.epsilon_obstacle(R),
                          peers=(PeerConstraint(peer, EPS),), lane=((-2.0, 0.0),))
    backing = Plan(t_now, 0.5, backing_away(start).positions, backing_away(start).velocities)
    assert backs_away(backing, request) and head_on(request) == 0
    result = PlanResult(backing, 0, 0.0, 0.0, 0.0, True)
    passed = _pass_head_on(request, result, bounds(1), PLANNER, room, CONFIG)
    assert passed is not None
    plan, verdict = passed
    assert verdict.ok and verify(plan.plan, request.peers, bounds(1), room, CONFIG).ok
    assert not backs_away(plan.plan, request)
    times = np.linspace(t_now, plan.plan.t_end, 400)
    ours, theirs = plan.plan.position_at(times), peer.position_at(times)
    k = int(np.argmin(np.abs(ours[:, 0] - theirs[:, 0])))  # where the two are level
    assert ours[k, 1] < theirs[k, 1] - 0.2  # on our right (heading +x: below)
    straight_on = PlanResult(straight(start, (2.0, 0.0), t0=t_now), 0, 0.0, 0.0, 0.0, True)
    assert _pass_head_on(request, straight_on, bounds(1), PLANNER, room, CONFIG) is None  # only a plan that backs away

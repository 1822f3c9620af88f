"""Plan verification (agent.verify): what it catches, at the same absolute times, between
samples, with the tolerance it documents and never beyond the breach distance."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent.config import SafetyConfig, VehicleConfig, VerifyConfig, WorldConfig
from trustfg.agent.follower import follower_speeds
from trustfg.agent.gp import Plan, standing
from trustfg.agent.planner import PeerConstraint
from trustfg.agent.verify import Bounds, follower_lag, verify
from trustfg.agent.world import build_sdf

SAFETY = SafetyConfig()
R = 0.1
EPS = SAFETY.epsilon_0(R, R)  # 0.45
BREACH = SAFETY.breach_distance(R, R)  # 0.3
CONFIG = VerifyConfig()


@pytest.fixture(scope="module")
def room():
    return build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0)))


@pytest.fixture(scope="module")
def walled():
    from trustfg.agent.config import Obstacle
    return build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0),
                                 obstacles=(Obstacle(min=(-0.1, -3.0), max=(0.1, 0.5)),)))


def line(start, end, t0=0.0, duration=6.0, n=13) -> Plan:
    """Constant velocity from start to end over duration (support states n)."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    u = np.linspace(0.0, 1.0, n)[:, None]
    v = (end - start) / duration
    return Plan(t0, duration / (n - 1), start + u * (end - start), np.tile(v, (n, 1)))


def bounds(peers: int = 1) -> Bounds:
    return Bounds.of(SAFETY.epsilon_obstacle(R), SAFETY.obstacle_breach(R), [BREACH] * peers, VehicleConfig())


def test_a_crossing_at_the_same_time_fails_and_the_same_paths_at_other_times_pass(room):
    ours = line((-2.0, 0.0), (2.0, 0.0))
    crossing = line((0.0, -2.0), (0.0, 2.0))  # both at the origin at t = 3 s
    verdict = verify(ours, [PeerConstraint(crossing, EPS)], bounds(), room, CONFIG)
    assert not verdict.ok
    (conflict,) = verdict.conflicts
    assert conflict.kind == "peer" and conflict.peer == 0 and conflict.t == pytest.approx(3.0, abs=0.05)
    assert verdict.clearance < 0.0  # the centres meet: far inside the breach distance
    later = dataclasses.replace(crossing, t0=4.0)  # the peer is at the origin at t = 7 s
    assert verify(ours, [PeerConstraint(later, EPS)], bounds(), room, CONFIG).ok


def test_a_peer_is_held_where_its_plan_ends_for_its_hold_then_no_longer(room):
    """A car waiting on our way (its plan a standing one that ends 2 s on) holds our plan
    back for good by default; with a hold (PeerConstraint.hold_s) only up to that long
    past the end of its plan: by then its next plans say where it is."""
    ours = line((-2.0, 0.0), (2.0, 0.0), duration=8.0)  # within eps of x = 1 from t = 5.1 s
    waiting = standing(np.array([1.0, 0.0]), 0.0)  # its plan ends at t = 2 s
    assert verify(ours, [PeerConstraint(waiting, EPS, hold_s=3.0)], bounds(), room, CONFIG).ok
    assert not verify(ours, [PeerConstraint(waiting, EPS)], bounds(), room, CONFIG).ok
    renewed = standing(np.array([1.0, 0.0]), 2.5)  # its next plan, ending at 4.5 s: held past 6 s
    verdict = verify(ours, [PeerConstraint(renewed, EPS, hold_s=3.0)], bounds(), room, CONFIG)
    assert not verdict.ok and verdict.conflicts[0].kind == "peer" and 5.0 < verdict.conflicts[0].t < 6.1


def test_a_wall_across_the_path_fails_and_a_path_past_its_end_passes(walled):
    through = line((-2.0, 0.0), (2.0, 0.0))
    verdict = verify(through, [], bounds(0), walled, CONFIG)
    assert not verdict.ok and verdict.conflicts[0].kind == "obstacle"
    around = line((-2.0, 1.2), (2.0, 1.2))  # 0.7 m past the wall's end
    assert verify(around, [], bounds(0), walled, CONFIG).ok


@pytest.mark.parametrize("eps", [EPS, 0.6, 0.9])
def test_the_tolerance_eats_at_most_its_share_of_the_margin_never_the_breach_distance(room, eps):
    """A peer passing at distance d: passes iff d >= eps - tolerance * (eps - breach)
    (less half a sample's relative travel, 1 cm here)."""
    need = eps - CONFIG.tolerance * (eps - BREACH)
    assert BREACH < need < eps
    ours = line((-2.0, 0.0), (2.0, 0.0))
    for gap, ok in ((need + 0.02, True), (need - 0.005, False), (BREACH + 0.005, False)):
        peer = line((2.0, gap), (-2.0, gap))  # head-on, passing at the lateral gap at t = 3 s
        assert verify(ours, [PeerConstraint(peer, eps)], bounds(), room, CONFIG).ok is ok, gap


def test_a_conflict_between_support_states_is_caught(room):
    """Two fast plans with a support state every 1.6 s meet between two of them (0.4 s
    before the middle one): the checks are spaced by relative travel, not by the plan."""
    ours = line((-2.5, 0.0), (2.5, 0.0), duration=6.4, n=5)  # 0.78 m/s
    peer = line((0.0, -2.5), (0.0, 2.5), t0=0.4, duration=6.4, n=5)  # at the origin at 3.6 s
    verdict = verify(ours, [PeerConstraint(peer, EPS)], bounds(), room, CONFIG)
    assert not verdict.ok and verdict.conflicts[0].t == pytest.approx(3.4, abs=0.05)
    closing = 1.25 * 2 * np.linalg.norm(ours.velocities[0])  # what check_times allows for
    assert verdict.samples >= 6.4 * closing / CONFIG.sample_m


def test_a_plan_that_starts_too_close_may_move_away_but_not_closer(room):
    peer = standing(np.array([0.0, 0.35]), 0.0)  # 0.35 m off: inside eps already
    away = line((0.0, 0.0), (0.0, -2.0))
    assert verify(away, [PeerConstraint(peer, EPS)], bounds(), room, CONFIG).ok
    closer = line((0.0, 0.0), (2.0, 0.2))  # passes at 0.32 m from it at first
    assert not verify(closer, [PeerConstraint(peer, EPS)], bounds(), room, CONFIG).ok


def test_a_plan_faster_than_the_car_fails_on_its_limits(room):
    slow = line((-2.0, 0.0), (2.0, 0.0), duration=8.0)  # 0.5 m/s from the start
    fast = line((-2.0, 0.0), (2.0, 0.0), duration=4.0)  # 1 m/s: above the car's 0.8
    assert verify(slow, [], bounds(0), room, CONFIG).ok
    verdict = verify(fast, [], bounds(0), room, CONFIG)
    assert not verdict.ok and verdict.conflicts[0].kind == "limits"


def test_a_plan_that_sets_off_faster_than_the_car_moves_fails_on_its_limits(room):
    """A plan at 0.5 m/s from its first instant is drivable by a car already at 0.5 m/s,
    not by one standing there: the follower starts at the car's speed (pressed by a hinge,
    a queued car's plan may set off at 0.6 m/s from a standstill)."""
    cruise = line((-2.0, 0.0), (2.0, 0.0), duration=8.0)  # 0.5 m/s from the start
    assert verify(cruise, [], bounds(0), room, CONFIG).ok  # from the plan's own speed
    assert verify(cruise, [], bounds(0), room, CONFIG, start_speed=0.5).ok
    verdict = verify(cruise, [], bounds(0), room, CONFIG, start_speed=0.0)
    assert not verdict.ok and verdict.conflicts[0].kind == "limits"


def test_follower_lag_is_the_distance_lost_to_the_limits():
    times = np.linspace(0.0, 1.0, 101)
    assert follower_lag(times, np.full(101, 0.5), 0.8, 1.5)[0] == pytest.approx(0.0)
    step_up = np.where(times > 0.0, 0.6, 0.0)  # 0 -> 0.6 m/s at once; the car needs 0.4 s
    lag, _ = follower_lag(times, step_up, 0.8, 1.5)
    assert lag == pytest.approx(0.6 * 0.4 / 2, rel=0.05)  # the triangle it falls behind


def _follower_in_python(wanted, start, max_speed, dv):
    """The recurrence as plain Python (agent.follower's docstring), the reference."""
    u = [min(start, max_speed)]
    for s in wanted[1:]:
        u.append(min(max_speed, u[-1] + min(max(s - u[-1], -dv), dv)))
    return u


def test_the_compiled_follower_is_the_python_loop_to_the_last_bit_nan_and_inf_included():
    rng = np.random.default_rng(7)
    for _ in range(2000):
        wanted = rng.uniform(0.0, 1.2, int(rng.integers(1, 120)))
        if rng.random() < 0.1:
            wanted[rng.integers(len(wanted))] = rng.choice([np.nan, np.inf, -np.inf])
        start = float(rng.choice([wanted[0], rng.uniform(0.0, 1.0), np.nan]))
        max_speed, dv = float(rng.uniform(0.3, 1.0)), float(rng.uniform(0.001, 0.05))
        expected = np.array(_follower_in_python(wanted.tolist(), start, max_speed, dv))
        got = follower_speeds(wanted, start, max_speed, dv)
        assert np.array_equal(got, expected, equal_nan=True)


def test_no_plan_passes_with_non_finite_states(room):
    bad = line((-2.0, 0.0), (2.0, 0.0))
    bad.positions[3] = np.nan
    assert not verify(bad, [], bounds(0), room, CONFIG).ok

"""The proximity guard: its formula, two blind cars driving at each other under it, a car
spiralling in on a car that cannot react, and a blind car driving at a wall."""

import math

import numpy as np
import pytest

from trustfg.agent.config import GuardConfig, SafetyConfig, VehicleConfig
from trustfg.agent.guard import RAY_STEP_M, RAY_STEPS, capped_below, reaction_time, speed_cap, wall_room, wall_rooms
from trustfg.agent.vehicle import VehicleState, step

GUARD = GuardConfig()
SAFETY = SafetyConfig()
RADIUS = 0.1
STOP = SAFETY.breach_distance(RADIUS, RADIUS) + GUARD.stop_margin_m
"""Centre distance at which two cars of RADIUS must have stopped (0.35 m)."""


def cap(x, y, yaw, others, sdf=None):
    """The guard's cap for a car of RADIUS among others (x, y, yaw) of RADIUS."""
    return speed_cap(x, y, yaw, RADIUS, [(*other, RADIUS) for other in others], GUARD, SAFETY, sdf)


def test_nobody_ahead_means_no_cap():
    assert cap(0, 0, 0, []) == math.inf
    assert cap(0, 0, 0, [(-0.35, 0.0, 0.0)]) == math.inf  # behind
    assert cap(0, 0, 0, [(0.0, 0.35, 0.0)]) == math.inf  # beside
    assert cap(0, 0, math.pi / 2, [(0.0, 0.35, 0.0)]) < math.inf  # ahead once we face it


@pytest.mark.parametrize("its_yaw, share", [(math.pi / 2, 1.0), (math.pi, 0.5)])
def test_cap_is_zero_inside_the_stop_distance_and_grows_with_room(its_yaw, share):
    """Reaction plus braking distance from the cap fills the room to the stop distance;
    half of it when the other car faces us (head-on: both close the gap)."""
    distances = np.linspace(0.0, 3.0, 301)
    caps = np.array([cap(0, 0, 0, [(d, 0.0, its_yaw)]) for d in distances])
    assert np.all(caps[distances <= STOP] == 0.0)
    assert np.all(np.diff(caps) >= 0.0) and caps[-1] > 1.0
    room = share * (distances - STOP)
    reaction_plus_braking = caps * GUARD.reaction_s + caps**2 / (2 * GUARD.decel_mps2)
    np.testing.assert_allclose(reaction_plus_braking[room > 0], room[room > 0], atol=1e-12)


def test_the_nearest_car_ahead_sets_the_cap():
    near, far = cap(0, 0, 0, [(0.6, 0.1, 0.0)]), cap(0, 0, 0, [(1.2, 0.0, 0.0)])
    assert cap(0, 0, 0, [(1.2, 0.0, 0.0), (0.6, 0.1, 0.0)]) == near < far


def closest_approach(a: VehicleState, b: VehicleState, limits: VehicleConfig, guard: bool,
                     pose_delay_s: float = 0.04, seconds: float = 6.0) -> float:
    """Both cars command full speed straight ahead (a plan that ignores the other), at 50 Hz
    from poses ``pose_delay_s`` old; physics at 5 ms. Returns the least centre distance."""
    physics_dt, command_every = 0.005, 4
    history = [(a, b)]
    commands = (0.0, 0.0)
    least = math.inf
    for i in range(int(seconds / physics_dt)):
        if i % command_every == 0:
            seen_a, seen_b = history[max(0, len(history) - 1 - int(pose_delay_s / physics_dt))]
            v = limits.max_speed_mps
            commands = (min(v, cap(seen_a.x, seen_a.y, seen_a.yaw, [(seen_b.x, seen_b.y, seen_b.yaw)])) if guard else v,
                        min(v, cap(seen_b.x, seen_b.y, seen_b.yaw, [(seen_a.x, seen_a.y, seen_a.yaw)])) if guard else v)
        a, b = step(a, commands[0], 0.0, physics_dt, limits), step(b, commands[1], 0.0, physics_dt, limits)
        history.append((a, b))
        least = min(least, math.hypot(a.x - b.x, a.y - b.y))
    return least


def encounter(seed: int) -> tuple[VehicleState, VehicleState]:
    """A head-on or crossing encounter at full speed, geometry drawn per seed."""
    rng = np.random.default_rng(seed)
    a = VehicleState(0.0, 0.0, rng.uniform(-0.03, 0.03), v=0.8)
    if seed % 2:  # head-on, slightly offset
        b = VehicleState(rng.uniform(1.5, 2.5), rng.uniform(-0.08, 0.08), math.pi + rng.uniform(-0.03, 0.03), v=0.8)
    else:  # crossing: b drives across a's path towards the point a reaches at the same time
        meet = rng.uniform(1.0, 1.6)
        b = VehicleState(meet + rng.uniform(-0.05, 0.05), -meet, math.pi / 2 + rng.uniform(-0.03, 0.03), v=0.8)
    return a, b


@pytest.mark.parametrize("seed", range(40))
def test_two_blind_cars_under_the_guard_keep_the_stop_distance(seed):
    limits = VehicleConfig()
    a, b = encounter(seed)
    assert closest_approach(a, b, limits, guard=False) < 0.2  # without it they collide (0.2 m: radii)
    assert closest_approach(a, b, limits, guard=True) >= STOP - 0.01


KEEP = RADIUS + GUARD.wall_clearance_m  # centre to wall at the stop


def test_wall_room_is_the_distance_to_the_stop_line(intersection_sdf):
    # The south-east building's west face is x = 0.8 for y <= -0.8.
    assert wall_room(0.0, -1.5, 0.0, intersection_sdf, KEEP) == pytest.approx(0.8 - KEEP, abs=0.03)
    assert wall_room(0.0, -1.5, math.pi, intersection_sdf, KEEP) == pytest.approx(0.8 - KEEP, abs=0.03)  # x = -0.8
    assert wall_room(0.0, -1.5, math.pi / 2, intersection_sdf, KEEP) == math.inf  # up the street: free


def test_the_rays_of_every_heading_marched_together_stop_where_each_marched_alone_would(intersection_sdf):
    """wall_rooms marches the headings a turning car sweeps in one call: each room is where
    a point-by-point march along that heading first comes within the limit."""
    rng = np.random.default_rng(3)
    for _ in range(300):
        x, y = rng.uniform(-2.4, 2.4, 2)
        headings = list(rng.uniform(-math.pi, math.pi, int(rng.integers(1, 5))))
        limit = min(KEEP, float(intersection_sdf.distance(np.array([x, y]))) - 1e-3)
        rooms = wall_rooms(x, y, headings, intersection_sdf, KEEP)
        for heading, room in zip(headings, rooms):
            alone = math.inf
            for ahead in RAY_STEPS:
                point = np.array([x + ahead * math.cos(heading), y + ahead * math.sin(heading)])
                if intersection_sdf.distance(point) < limit:
                    alone = float(ahead - RAY_STEP_M)
                    break
            assert room == alone


def test_a_car_near_a_wall_may_drive_along_or_away_from_it_but_not_into_it(intersection_sdf):
    x = 0.8 - 0.12  # edge 0.02 m from the face, nearer than the guard's clearance
    assert cap(x, -1.5, math.pi / 2, [], intersection_sdf) == math.inf  # along, north
    assert cap(x, -1.5, math.pi, [], intersection_sdf) > 0.5  # away
    assert cap(x, -1.5, 0.0, [], intersection_sdf) == 0.0  # into it


@pytest.mark.parametrize("seed", range(20))
def test_a_blind_car_under_the_guard_stops_short_of_the_wall(intersection_sdf, seed):
    """Full speed at the south-east building from random places and angles; physics at
    5 ms, commands at 50 Hz from poses 40 ms old."""
    rng = np.random.default_rng(seed)
    start = VehicleState(rng.uniform(-0.5, 0.3), rng.uniform(-2.0, -1.4), rng.uniform(-0.3, 0.3), v=0.8)
    limits = VehicleConfig()

    def least_clearance(guard: bool) -> float:
        car, history, least, v = start, [start], math.inf, 0.0
        for i in range(int(3.0 / 0.005)):
            if i % 4 == 0:
                seen = history[max(0, len(history) - 9)]
                v = limits.max_speed_mps
                if guard:
                    v = min(v, cap(seen.x, seen.y, seen.yaw, [], intersection_sdf))
            car = step(car, v, 0.0, 0.005, limits)
            history.append(car)
            least = min(least, float(intersection_sdf.distance(np.array([car.x, car.y]))) - RADIUS)
        return least

    assert least_clearance(guard=False) < 0.0  # without it the car drives into the building
    assert least_clearance(guard=True) >= GUARD.wall_clearance_m - 0.01


def test_a_car_beside_us_limits_how_fast_we_close_in_on_it():
    """Outside the cone, what the guard caps is the part of our speed that closes the gap."""
    assert cap(0, 0, 0, [(0.1, 0.3, 0.0)]) == 0.0  # 72 degrees off, inside the stop distance, closing in
    assert cap(0, 0, 0, [(-0.1, 0.3, 0.0)]) == math.inf  # the same, but we drive away from it
    off = math.radians(70.0)
    for d in np.linspace(STOP + 0.01, 1.0, 20):
        closing = cap(0, 0, 0, [(d * math.cos(off), d * math.sin(off), 0.0)]) * math.cos(off)
        reaction_plus_braking = closing * GUARD.reaction_s + closing**2 / (2 * GUARD.decel_mps2)
        assert reaction_plus_braking == pytest.approx(d - STOP, abs=1e-12)


def spiralling(seed: int, guard: bool) -> float:
    """A car at full speed that keeps a car standing still (stopped, its link cut: it
    cannot react) at a fixed bearing outside the guard's cone, and so spirals in on it.
    Bearing, side and start distance drawn per seed; physics at 5 ms, commands at 50 Hz
    from poses 40 ms old. Returns the least centre distance."""
    rng = np.random.default_rng(seed)
    limits = VehicleConfig()
    bearing = rng.choice([-1.0, 1.0]) * math.radians(rng.uniform(65.0, 80.0))
    distance = rng.uniform(0.6, 0.9)
    still = (distance * math.cos(bearing), distance * math.sin(bearing), rng.uniform(-math.pi, math.pi))
    car, history, least = VehicleState(0.0, 0.0, 0.0, v=0.0), [], math.inf
    v = omega = 0.0
    for i in range(int(6.0 / 0.005)):
        history.append(car)
        if i % 4 == 0:
            seen = history[max(0, len(history) - 9)]
            v = limits.max_speed_mps
            if guard:
                v = min(v, cap(seen.x, seen.y, seen.yaw, [still]))
            off = math.remainder(math.atan2(still[1] - seen.y, still[0] - seen.x) - seen.yaw, 2 * math.pi)
            gap = math.hypot(still[0] - seen.x, still[1] - seen.y)
            omega = seen.v * math.sin(off) / gap + 4.0 * (off - bearing)  # holds the bearing: d(off)/dt = 0
        car = step(car, v, omega, 0.005, limits)
        least = min(least, math.hypot(car.x - still[0], car.y - still[1]))
    return least


@pytest.mark.parametrize("seed", range(30))
def test_a_car_spiralling_in_on_a_stopped_car_never_breaches(seed):
    breach = SAFETY.breach_distance(RADIUS, RADIUS)
    assert spiralling(seed, guard=False) < breach - 0.05  # without the guard it closes in far inside
    assert spiralling(seed, guard=True) >= breach + 0.01  # with it, a centimetre of margin (the cone alone is not enough)


def test_reaction_time_is_the_pose_age_plus_the_command_hold_within_bounds():
    assert reaction_time(0.0, 0.0, GUARD) == GUARD.reaction_s  # never less than configured
    assert reaction_time(0.03, 0.2, GUARD) == pytest.approx(0.23)
    assert reaction_time(0.03, 5.0, GUARD) == pytest.approx(0.03 + GUARD.command_hold_max_s)  # the watchdog


def starved_approach(seed: int, measured: bool) -> float:
    """A car drives at a car that stands still (it cannot react) from a control loop
    starved of CPU, as eight car processes on two cores starve it: ticks late by 0-5 ms
    mostly, 20-130 ms often, and stalled for 0.2-1 s now and then; poses 10-60 ms old at a
    tick. The car holds each command until the next one, or stops
    when its 250 ms watchdog runs out. The guard's reaction time is either measured (the
    pose's age plus the longest gap of the last 5 s, as the car process does) or the
    configured 0.1 s. Physics at 5 ms. Returns the least centre distance."""
    rng = np.random.default_rng(seed)
    limits = VehicleConfig()
    still = (rng.uniform(0.8, 2.0), rng.uniform(-0.05, 0.05), rng.uniform(-math.pi, math.pi))
    car = VehicleState(0.0, 0.0, rng.uniform(-0.05, 0.05), v=rng.uniform(0.3, 0.8))
    history, gaps, least = [car], [], math.inf
    t, next_tick, commanded_at, v = 0.0, 0.0, 0.0, car.v
    while t < 6.0:
        if t >= next_tick:
            age = rng.uniform(0.01, 0.06)
            seen = history[max(0, len(history) - 1 - int(age / 0.005))]
            t_r = reaction_time(age, max(gaps, default=0.02), GUARD) if measured else GUARD.reaction_s
            v = min(limits.max_speed_mps, speed_cap(seen.x, seen.y, seen.yaw, RADIUS, [(*still, RADIUS)],
                                                     GUARD, SAFETY, reaction_s=t_r))
            commanded_at = t
            late = rng.choice([rng.uniform(0, 0.005), rng.uniform(0.02, 0.13), rng.uniform(0.2, 1.0)], p=[0.7, 0.25, 0.05])
            gaps = gaps[-250:] + [0.02 + late]  # the last 5 s at 50 Hz, at most
            next_tick = t + 0.02 + late
        command = v if t - commanded_at <= 0.25 else 0.0  # the car's watchdog
        car = step(car, command, 0.0, 0.005, limits)
        history.append(car)
        t += 0.005
        least = min(least, math.hypot(car.x - still[0], car.y - still[1]))
    return least


@pytest.mark.parametrize("seed", range(40))
def test_a_starved_control_loop_under_the_measured_reaction_time_keeps_the_stop_distance(seed):
    breach = SAFETY.breach_distance(RADIUS, RADIUS)
    assert starved_approach(seed, measured=True) >= breach


def test_the_configured_reaction_time_alone_breaches_when_the_loop_is_starved():
    breach = SAFETY.breach_distance(RADIUS, RADIUS)
    least = [starved_approach(seed, measured=False) for seed in range(40)]
    assert min(least) < breach


def turning_in(seed: int, sweep: bool) -> float:
    """A car at speed turns at its full rate towards a car standing beside it (62-85 deg
    off, 0.45-0.8 m: outside the cone when the turn starts), as a plan that bends into it
    would; commands at 50 Hz from poses 40 ms old, physics at 5 ms. The guard checks the
    headings the turn sweeps before the next command takes effect, or the present one only.
    Returns the least centre distance."""
    rng = np.random.default_rng(seed)
    limits = VehicleConfig()
    side = rng.choice([-1.0, 1.0])
    bearing, distance = side * math.radians(rng.uniform(62.0, 85.0)), rng.uniform(0.45, 0.8)
    still = (distance * math.cos(bearing), distance * math.sin(bearing), rng.uniform(-math.pi, math.pi))
    car = VehicleState(0.0, 0.0, 0.0, v=rng.uniform(0.3, 0.8))
    history, least, v, omega = [car], math.inf, 0.0, side * limits.max_turn_rate_radps
    for i in range(int(3.0 / 0.005)):
        if i % 4 == 0:
            seen = history[max(0, len(history) - 9)]
            turn = omega * GUARD.reaction_s if sweep else 0.0
            v = min(limits.max_speed_mps, speed_cap(seen.x, seen.y, seen.yaw, RADIUS, [(*still, RADIUS)],
                                                     GUARD, SAFETY, turn_rad=turn))
        car = step(car, v, omega, 0.005, limits)
        history.append(car)
        least = min(least, math.hypot(car.x - still[0], car.y - still[1]))
    return least


@pytest.mark.parametrize("seed", range(40))
def test_a_car_turning_into_a_car_beside_it_keeps_the_stop_distance(seed):
    assert turning_in(seed, sweep=True) >= SAFETY.breach_distance(RADIUS, RADIUS) + 0.01  # a centimetre beyond the breach distance


def test_checking_the_present_heading_alone_breaches_in_a_turn():
    least = [turning_in(seed, sweep=False) for seed in range(40)]
    assert sum(d < SAFETY.breach_distance(RADIUS, RADIUS) for d in least) >= 10  # a quarter of the seeds at least


def test_capped_below_answers_as_the_cap_does(intersection_sdf):
    """The truster's cheaper question (is a peer's guard holding it below a speed?) has the
    cap's own answer: random cars among random others, near walls and in the open."""
    rng = np.random.default_rng(7)
    disagree, held = 0, 0
    for _ in range(3000):
        x, y = rng.uniform(-2.5, 2.5, 2)
        yaw = rng.uniform(-math.pi, math.pi)
        others = [(*rng.uniform(-2.5, 2.5, 2), rng.uniform(-math.pi, math.pi), RADIUS)
                  for _ in range(rng.integers(0, 8))]
        sdf = intersection_sdf if rng.random() < 0.7 else None
        speed = float(rng.choice([rng.uniform(-0.2, 1.0), 0.0]))
        full = speed_cap(x, y, yaw, RADIUS, others, GUARD, SAFETY, sdf) < speed
        held += full
        disagree += full != capped_below(x, y, yaw, RADIUS, others, GUARD, SAFETY, sdf, speed)
    assert disagree == 0
    assert 300 < held < 2700  # both answers were asked for

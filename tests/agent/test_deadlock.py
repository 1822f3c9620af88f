"""Deadlocks (agent.deadlock): detected from what each car sees, counted, and resolved by
the lower-priority car giving way."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent.config import ConfigError, DeadlockConfig, Obstacle, TrustConfig, WorldConfig
from trustfg.agent.deadlock import LANE_STEP_M, DeadlockWatch, PeerSeen, goes_first, lane, peers_seen
from trustfg.agent.evidence import PeerView
from trustfg.agent.gp import standing
from trustfg.agent.messages import PlanMessage
from trustfg.agent.routes import connected
from trustfg.agent.sightings import Track
from trustfg.agent.world import build_sdf

CONFIG = DeadlockConfig()
KEEP_CLEAR, WALL_CLEAR = 0.45, 0.25
STEP_S = 0.2


@pytest.fixture(scope="module")
def room():
    return build_sdf(WorldConfig(bounds_m=(-3.0, -3.0, 3.0, 3.0)))


def way(start, goal) -> np.ndarray:
    return np.linspace(start, goal, 20)


# Nose to nose: car 1 at (-0.25, 0) for (2, 0), car 2 at (0.25, 0) for (-2, 0).
ONE = dict(position=np.array([-0.25, 0.0]), goal=np.array([2.0, 0.0]))
TWO = dict(position=np.array([0.25, 0.0]), goal=np.array([-2.0, 0.0]))


def seen(car: dict, moved: float = 0.0) -> PeerSeen:
    position = car["position"] + np.array([moved, 0.0])
    return PeerSeen(position, goal=car["goal"], way=way(position, car["goal"]))


def watch_for(me: int, watch: DeadlockWatch, seconds: float, room, peer_moves: float = 0.0,
              peer_at_goal: bool = False, peer_stuck: bool = False, peer_deadlocks: int = 0) -> list:
    """Feed ``watch`` (car ``me``) the standoff for ``seconds``; the detours it returns."""
    mine, theirs, other = (ONE, TWO, 2) if me == 1 else (TWO, ONE, 1)
    detours = []
    for k, t in enumerate(np.arange(0.0, seconds, STEP_S)):
        peer = seen(theirs, moved=peer_moves * k * STEP_S)
        if peer_at_goal or peer_stuck or peer_deadlocks:
            peer = dataclasses.replace(peer, at_goal=peer_at_goal, stuck=peer_stuck, deadlocks=peer_deadlocks)
        detours.append(watch.goal(t, mine["position"], mine["goal"], {other: peer}, True,
                                  KEEP_CLEAR, room, WALL_CLEAR))
    return detours


def test_a_standoff_is_a_deadlock_for_both_and_only_the_higher_id_gives_way(room):
    one, two = DeadlockWatch(1, CONFIG), DeadlockWatch(2, CONFIG)
    seconds = CONFIG.window_s + 1.0
    first = watch_for(1, one, seconds, room)
    second = watch_for(2, two, seconds, room)
    assert one.deadlocks == 1 and two.deadlocks == 1
    assert all(d is None for d in first)  # car 1 goes first: it keeps its goal
    detour = next(d for d in second if d is not None)
    assert two.yields == 1
    assert np.linalg.norm(detour - TWO["position"]) == pytest.approx(CONFIG.detour_m)
    car_one_way = np.vstack([ONE["position"], way(ONE["position"], ONE["goal"])])
    assert np.min(np.linalg.norm(car_one_way - detour, axis=1)) >= KEEP_CLEAR  # off car 1's way
    assert room.distance(detour) >= WALL_CLEAR


def test_a_car_that_has_been_through_more_deadlocks_goes_first(room):
    """The order ages: car 2 has been through a deadlock already (its plan messages say
    so), so in this standoff car 1 gives way and car 2 keeps its goal -- by id alone a
    car in the middle of a crowd gives way at every deadlock it meets."""
    one, two = DeadlockWatch(1, CONFIG), DeadlockWatch(2, CONFIG)
    two.been_through = 1
    seconds = CONFIG.window_s + 1.0
    first = watch_for(1, one, seconds, room, peer_deadlocks=1)
    second = watch_for(2, two, seconds, room)
    assert one.deadlocks == 1 and two.deadlocks == 1
    assert all(d is None for d in second)  # car 2 goes first now
    assert one.yields == 1 and any(d is not None for d in first)
    assert goes_first(1, 2, 0, 1) and not goes_first(0, 2, 0, 1) and goes_first(2, 7, 2, 9)


def test_a_deadlock_counts_once_it_is_over_for_both_roles(room):
    """Counted while the group decides, the car that detected first would tell a higher
    count and the others would give way to it while it gave way to them; so a deadlock
    counts when it is over: the detour driven, or the group moving again."""
    one, two = DeadlockWatch(1, CONFIG), DeadlockWatch(2, CONFIG)
    seconds = CONFIG.window_s + 1.0
    watch_for(1, one, seconds, room)
    watch_for(2, two, seconds, room)
    assert one.deadlocks == two.deadlocks == 1 and two.yields == 1
    assert one.been_through == two.been_through == 0  # not over yet
    t = seconds + CONFIG.yield_s + 0.5  # car 2's detour driven; car 1's group moves again
    two.goal(t, TWO["position"], TWO["goal"], {1: seen(ONE, moved=1.0)}, True, KEEP_CLEAR, room, WALL_CLEAR)
    one.goal(t, ONE["position"], ONE["goal"], {2: seen(TWO, moved=-1.0)}, True, KEEP_CLEAR, room, WALL_CLEAR)
    assert one.been_through == two.been_through == 1  # the next standoff: car 1 first again


def test_no_deadlock_is_seen_before_a_whole_window_of_no_progress(room):
    two = DeadlockWatch(2, CONFIG)
    assert all(d is None for d in watch_for(2, two, CONFIG.window_s - 0.5, room))
    assert two.deadlocks == 0


@pytest.mark.parametrize("waits", ["we", "peer"])
@pytest.mark.parametrize("car_like", [True, False])
def test_in_a_car_like_fleet_standing_to_wait_for_a_departure_is_no_stall(room, waits, car_like):
    """The standoff, with one car waiting to depart for the first 2 s: just after it sets
    off its window holds more waiting than driving. A car-like fleet does not take that
    for a deadlock -- a whole window after the departure the standoff is one as before --
    and a fleet that turns in place keeps its window as it was (a deadlock a window after
    the start)."""
    two = DeadlockWatch(2, CONFIG)
    depart_s = 2.0
    steering = (float(np.pi), 0.3) if car_like else None  # car 2 faces car 1 (west)
    detours, first_deadlock = [], None
    for t in np.arange(0.0, depart_s + CONFIG.window_s + 1.0, STEP_S):
        peer = dataclasses.replace(seen(ONE), waiting=waits == "peer" and t < depart_s)
        departed = waits != "we" or t >= depart_s
        detours.append(two.goal(t, TWO["position"], TWO["goal"], {1: peer}, departed, KEEP_CLEAR, room, WALL_CLEAR,
                                steering=steering))
        if two.deadlocks and first_deadlock is None:
            first_deadlock = t
    after_departure = depart_s + CONFIG.window_s - 0.25 - 1e-9
    assert first_deadlock is not None and (first_deadlock >= after_departure) == car_like
    assert any(d is not None for d in detours)  # car 2 gives way, as in any standoff


def test_waiting_for_a_car_that_gets_somewhere_is_no_deadlock(room):
    two = DeadlockWatch(2, CONFIG)
    watch_for(2, two, CONFIG.window_s + 1.0, room, peer_moves=0.2)  # car 1 moves on at 0.2 m/s
    assert two.deadlocks == 0 and two.yields == 0


def test_a_peer_at_its_goal_makes_no_group(room):
    two = DeadlockWatch(2, CONFIG)
    watch_for(2, two, CONFIG.window_s + 1.0, room, peer_at_goal=True)
    assert two.deadlocks == 0


def test_a_stuck_peer_makes_no_group_and_nobody_gives_way_to_it(room):
    """A car that says it does not move although told to (its command link cut) would go
    first for ever: it is planned round like a wall, not given way to."""
    two = DeadlockWatch(2, CONFIG)
    detours = watch_for(2, two, CONFIG.window_s + CONFIG.yield_s + 1.0, room, peer_stuck=True)
    assert two.deadlocks == 0 and two.yields == 0 and all(d is None for d in detours)


@pytest.mark.parametrize("peer, alone, nothing_to_wait_for", [
    (dict(), False, True),                 # a car nose to nose with us that stands too: a deadlock
    (dict(peer_moves=0.1), False, False),  # a car near us that gets somewhere: we wait for it
    (dict(peer_at_goal=True), True, True),  # parked: nobody to wait for
    (dict(peer_stuck=True), True, True),    # stuck: a wall
])
def test_a_stalled_car_leaves_its_lane_as_the_rule_says(room, peer, alone, nothing_to_wait_for):
    expected = {"never": False, "alone": alone, "nothing-to-wait-for": nothing_to_wait_for}
    for rule, leaves in expected.items():
        config = dataclasses.replace(CONFIG, enabled=False, leave_lane=rule)  # no detour: we stand
        early, two = DeadlockWatch(2, config), DeadlockWatch(2, config)
        watch_for(2, early, config.window_s - 0.5, room, **peer)
        assert not early.leaves_lane(config.window_s - 0.6, {})  # not a whole window yet
        seconds = config.window_s + 1.0
        watch_for(2, two, seconds, room, **peer)
        moved = peer.get("peer_moves", 0.0) * (seconds - STEP_S)
        last = dataclasses.replace(seen(ONE, moved), at_goal=peer.get("peer_at_goal", False),
                                   stuck=peer.get("peer_stuck", False))
        assert two.leaves_lane(seconds - STEP_S, {1: last}) == leaves, rule
        assert two.leaves_lane(seconds - STEP_S, {}) == (rule != "never")  # nobody near at all


def test_the_lane_rule_is_off_by_default_and_must_be_known():
    assert DeadlockConfig().leave_lane == "never"
    with pytest.raises(ConfigError, match="leave_lane"):
        DeadlockConfig(leave_lane="sometimes").validate("deadlock")


def test_the_detour_ends_after_yield_s_and_needs_a_fresh_window(room):
    two = DeadlockWatch(2, CONFIG)
    detours = watch_for(2, two, CONFIG.window_s + CONFIG.yield_s + 1.0, room)
    given = [d is not None for d in detours]
    start = given.index(True)
    held = given[start:].index(False) if False in given[start:] else len(given) - start
    assert held * STEP_S == pytest.approx(CONFIG.yield_s, abs=STEP_S + 1e-9)
    assert two.yields == 1  # not again straight away


def test_with_resolution_off_deadlocks_are_counted_but_nobody_gives_way(room):
    two = DeadlockWatch(2, dataclasses.replace(CONFIG, enabled=False))
    assert all(d is None for d in watch_for(2, two, CONFIG.window_s + 1.0, room))
    assert two.deadlocks == 1 and two.yields == 0


# A parked car that walls a peer in (a bottleneck): a wall across the room with a 1.2 m
# gap on the right; we are parked in the gap, the peer stands in the pocket below.
POCKET_WALL = Obstacle(kind="rect", min=(-1.5, -0.05), max=(0.3, 0.05))
PARKED_IN_GAP = np.array([0.9, 0.0])
WALLED_IN = PeerSeen(np.array([-0.7, -0.8]), goal=np.array([-0.7, 0.8]))


@pytest.fixture(scope="module")
def pocket():
    return build_sdf(WorldConfig(bounds_m=(-1.5, -1.5, 1.5, 1.5), resolution_m=0.02, obstacles=(POCKET_WALL,)))


def parked_for(watch: DeadlockWatch, seconds: float, pocket, peer: PeerSeen = WALLED_IN, start: float = 0.0,
               others: dict | None = None) -> list:
    """Feed a parked car's watch a peer that stands still; the step-aside goals it returns."""
    return [watch.step_aside(t, PARKED_IN_GAP, PARKED_IN_GAP, {2: peer} | (others or {}), KEEP_CLEAR, pocket,
                             WALL_CLEAR) for t in np.arange(start, start + seconds, STEP_S)]


def test_a_parked_car_that_walls_a_stalled_peer_in_steps_aside_to_where_the_way_is_open(pocket):
    assert not connected(pocket, WALLED_IN.position, WALLED_IN.goal, WALL_CLEAR, [(tuple(PARKED_IN_GAP), KEEP_CLEAR)])
    watch = DeadlockWatch(1, CONFIG)
    asides = parked_for(watch, CONFIG.window_s + 1.0, pocket)
    first = next(i for i, a in enumerate(asides) if a is not None)
    assert first * STEP_S >= CONFIG.window_s - 0.3  # not before the peer has been stalled a window
    aside = asides[first]
    assert watch.steps_aside == 1
    assert np.linalg.norm(aside - PARKED_IN_GAP) == pytest.approx(CONFIG.detour_m)
    assert connected(pocket, WALLED_IN.position, WALLED_IN.goal, WALL_CLEAR, [(tuple(aside), KEEP_CLEAR)])


def test_with_resolution_off_a_parked_car_stays_put(pocket):
    watch = DeadlockWatch(1, dataclasses.replace(CONFIG, enabled=False))
    assert all(a is None for a in parked_for(watch, CONFIG.window_s + 2.0, pocket))


def test_no_step_aside_for_a_peer_that_has_a_way_or_is_walled_in_by_others_too(pocket):
    free = PeerSeen(np.array([-0.7, 0.5]), goal=np.array([-0.7, 1.0]))  # on our side of the wall
    watch = DeadlockWatch(1, CONFIG)
    assert all(a is None for a in parked_for(watch, CONFIG.window_s + 2.0, pocket, peer=free))
    # a second car parked in the gap: our stepping aside alone would not open it
    other = {3: PeerSeen(np.array([0.95, 0.0]), at_goal=True, goal=np.array([0.95, 0.0]))}
    watch = DeadlockWatch(1, CONFIG)
    assert all(a is None for a in parked_for(watch, CONFIG.window_s + 2.0, pocket, others=other))


def test_a_step_aside_holds_while_the_peer_is_walled_in_and_ends_once_it_is_through(pocket):
    watch = DeadlockWatch(1, CONFIG)
    aside = next(a for a in parked_for(watch, CONFIG.window_s + 1.0, pocket) if a is not None)
    started = watch.detour.until - CONFIG.yield_s
    here = {2: WALLED_IN}
    late = started + CONFIG.yield_s + 1.0  # the peer has not moved: we hold on
    assert np.array_equal(watch.goal(late, aside, PARKED_IN_GAP, here, True, KEEP_CLEAR, pocket, WALL_CLEAR), aside)
    through = {2: PeerSeen(np.array([-0.7, 0.5]), goal=WALLED_IN.goal)}  # past the wall
    assert watch.goal(late + STEP_S, aside, PARKED_IN_GAP, through, True, KEEP_CLEAR, pocket, WALL_CLEAR) is None
    stuck_for_good = DeadlockWatch(1, CONFIG)
    next(a for a in parked_for(stuck_for_good, CONFIG.window_s + 1.0, pocket) if a is not None)
    end = stuck_for_good.detour.latest
    assert stuck_for_good.goal(end + 0.01, aside, PARKED_IN_GAP, here, True, KEEP_CLEAR, pocket, WALL_CLEAR) is None


def test_a_peer_stopped_a_little_inside_the_wall_clearance_is_walled_in_all_the_same(pocket, monkeypatch):
    """A stalled car stopped 1.5 cm nearer a pillar than eps_obs: no way leads from its own
    cell, with the parked car or without it, so read by its own cell alone it would never
    count as walled in by the parked car. Its region is the nearest free cell's
    (routes.SNAP_M)."""
    inside = PeerSeen(np.array([-0.7, -0.05 - WALL_CLEAR + 0.015]), goal=WALLED_IN.goal)
    assert float(pocket.distance(inside.position)) < WALL_CLEAR
    assert connected(pocket, inside.position, inside.goal, WALL_CLEAR, [])
    watch = DeadlockWatch(1, CONFIG)
    assert any(a is not None for a in parked_for(watch, CONFIG.window_s + 1.0, pocket, peer=inside))
    import trustfg.agent.routes as routes
    monkeypatch.setattr(routes, "SNAP_M", 0.0)  # a point's own cell only
    assert not connected(pocket, inside.position, inside.goal, WALL_CLEAR, [])
    watch = DeadlockWatch(1, CONFIG)
    assert all(a is None for a in parked_for(watch, CONFIG.window_s + 1.0, pocket, peer=inside))


def test_a_stuck_peer_pressed_into_the_pinch_between_us_and_a_wall_is_walled_in(pocket):
    """A car stuck in the pinch between a pillar's corner and a car parked at its goal, 0.43
    m from the parked car, its goal beyond the pinch. Its region's nearest free cell
    (routes.SNAP_M) lies on the far side, so it would count as having a way with the
    parked car where it stands, and would stand there for good. A stuck peer inside our
    keep-out is walled in by us whatever the snap says."""
    parked = np.array([0.98, 0.0])  # the gap to the wall's end is 0.68 m: 0.7 m would pass
    pressed = PeerSeen(np.array([0.55, 0.01]), goal=WALLED_IN.goal)  # a centimetre past the narrowest line
    assert np.linalg.norm(pressed.position - parked) < KEEP_CLEAR
    assert connected(pocket, pressed.position, pressed.goal, WALL_CLEAR, [(tuple(parked), KEEP_CLEAR)])
    assert not connected(pocket, WALLED_IN.position, WALLED_IN.goal, WALL_CLEAR, [(tuple(parked), KEEP_CLEAR)])
    watch = DeadlockWatch(1, CONFIG)
    asides = [watch.step_aside(t, parked, parked, {2: pressed}, KEEP_CLEAR, pocket, WALL_CLEAR)
              for t in np.arange(0.0, CONFIG.window_s + 1.0, STEP_S)]
    aside = next(a for a in asides if a is not None)
    assert watch.steps_aside == 1 and np.linalg.norm(aside - pressed.position) > KEEP_CLEAR
    # ... and a stuck peer as near that has a way and is not inside our keep-out: we stay
    beside = PeerSeen(np.array([0.5, 0.5]), goal=WALLED_IN.goal)
    assert np.linalg.norm(beside.position - parked) > KEEP_CLEAR
    watch = DeadlockWatch(1, CONFIG)
    assert all(watch.step_aside(t, parked, parked, {2: beside}, KEEP_CLEAR, pocket, WALL_CLEAR) is None
               for t in np.arange(0.0, CONFIG.window_s + 1.0, STEP_S))


def test_a_point_deep_in_a_wall_is_in_no_region(pocket):
    assert not connected(pocket, (-0.7, 0.0), WALLED_IN.goal, WALL_CLEAR, [])  # the wall's middle: 0.3 m from free


@pytest.mark.parametrize("halting", [True, False])
def test_a_peer_creeping_with_every_plan_ending_short_of_its_goal_is_stuck(pocket, halting):
    """A walled-in car creeping at 2.5 cm/s on its fallback comes more than progress_m a
    window nearer its goal, so it never counts as stalled. Every plan it sends ending at
    rest short of its goal makes it stuck all the same, and the parked car steps aside."""
    watch = DeadlockWatch(1, CONFIG)
    creep = 2.5 * CONFIG.progress_m / CONFIG.window_s  # m/s: 2.5 progress_m a window
    asides = []
    for t in np.arange(0.0, CONFIG.window_s + 1.0, STEP_S):
        peer = dataclasses.replace(WALLED_IN, position=WALLED_IN.position + np.array([0.0, creep * t]),
                                   halting=halting)
        asides.append(watch.step_aside(t, PARKED_IN_GAP, PARKED_IN_GAP, {2: peer}, KEEP_CLEAR, pocket, WALL_CLEAR))
    assert not watch.stalled(2, CONFIG.window_s + 0.8)
    assert any(a is not None for a in asides) is halting


# Where a car gives way to (a T-junction's road): a road 1.2 m wide, closed at both ends.
# Car 6 stands near the east end; car 4, which goes first, stands at the west end and
# means to reach the east end's north lane, beside car 5 parked there.
@pytest.fixture(scope="module")
def road():
    return build_sdf(WorldConfig(bounds_m=(-2.8, -0.6, 2.8, 0.6), resolution_m=0.01))


def yields_from(position, peers: dict, room, seconds: float = CONFIG.window_s + 1.0) -> np.ndarray | None:
    """Car 6 at ``position``, every peer standing: the first detour its watch returns."""
    watch = DeadlockWatch(6, CONFIG)
    detours = [watch.goal(t, position, np.array([-2.3, -0.275]), peers, True, KEEP_CLEAR, room, WALL_CLEAR,
                          frozenset({4})) for t in np.arange(0.0, seconds, STEP_S)]
    assert watch.deadlocks == 1
    return next((d for d in detours if d is not None), None)


def test_a_detour_finds_the_one_way_out_of_a_dead_end(road):
    """Straight away from car 4's goal is the south wall, and the turns of 45 degrees hit
    walls or car 5; the road west is the way out."""
    four = PeerSeen(np.array([-2.13, -0.31]), goal=np.array([2.3, 0.275]),
                    way=np.array([[-2.13, -0.31], [2.3, 0.275]]))
    five = PeerSeen(np.array([1.71, 0.26]), at_goal=True, goal=np.array([1.71, 0.26]))
    position = np.array([2.13, -0.24])
    detour = yields_from(position, {4: four, 5: five}, road)
    assert detour is not None
    assert detour[0] < position[0] - 0.3  # along the road, west
    assert float(road.distance(detour)) >= WALL_CLEAR


def first_detour(peers: dict, room) -> np.ndarray:
    """Car 2 of the standoff, with ``peers`` seen besides car 1: the detour it gives way to."""
    watch = DeadlockWatch(2, CONFIG)
    detours = [watch.goal(t, TWO["position"], TWO["goal"], {1: seen(ONE)} | peers, True, KEEP_CLEAR, room,
                          WALL_CLEAR) for t in np.arange(0.0, CONFIG.window_s + 1.0, STEP_S)]
    return next(d for d in detours if d is not None)


def test_a_detour_keeps_off_every_peers_goal(room):
    """Car 3, far off and driving, means to park where car 2 would give way to; a car that
    gave way there would wall car 3 out of its goal (two cars that each give way onto the
    other's goal stand there for good)."""
    alone = first_detour({}, room)
    three = PeerSeen(np.array([0.0, 2.5]), goal=alone)
    detour = first_detour({3: three}, room)
    assert np.linalg.norm(detour - alone) >= KEEP_CLEAR
    assert np.linalg.norm(detour - TWO["position"]) == pytest.approx(CONFIG.detour_m)


def test_a_detour_keeps_off_the_lane_of_a_car_that_stands_and_goes_first(room):
    """Car 1 stands at (-2, 0), its plan a standstill, its goal (2, 0): its way is those two
    points, its lane the straight between them. Car 2, 0.3 m south of that lane, whose
    plans fail against car 1, gives way: straight away from car 1 is east-south-east, whose point 0.6 m off lies 0.39 m
    from the lane -- a car standing there would block the car it gave way to."""
    one = PeerSeen(np.array([-2.0, 0.0]), goal=np.array([2.0, 0.0]), way=np.array([[-2.0, 0.0], [2.0, 0.0]]))
    position = np.array([0.0, -0.3])
    watch = DeadlockWatch(2, CONFIG)
    detours = [watch.goal(t, position, np.array([-2.0, -0.3]), {1: one}, True, KEEP_CLEAR, room, WALL_CLEAR,
                          frozenset({1})) for t in np.arange(0.0, CONFIG.window_s + 1.0, STEP_S)]
    detour = next(d for d in detours if d is not None)
    lane = np.linspace([-2.0, 0.0], [2.0, 0.0], 401)
    assert float(np.min(np.linalg.norm(lane - detour, axis=1))) >= KEEP_CLEAR
    assert np.linalg.norm(detour - position) == pytest.approx(CONFIG.detour_m)


def test_a_lane_stops_where_it_first_meets_a_wall(pocket):
    """The straight to a goal behind a wall is not the way there: the lane ends at the wall."""
    way = np.array([[-1.0, -0.8], [-1.0, 0.8]])  # across the pocket's wall at y = 0
    points = lane(way, pocket)
    assert float(np.min(pocket.distance(points))) >= 0.0
    assert -0.1 < np.max(points[:, 1]) < -0.05 and np.max(np.diff(points[:, 1])) <= LANE_STEP_M + 1e-9


def test_a_peer_is_seen_stuck_exactly_when_its_latest_plan_says_so():
    track = Track()
    for k in range(20):
        track.add(1.0 + 0.01 * k, 0.5, -0.4, 0.0)
    view = PeerView(TrustConfig())
    for stuck in (True, False):
        view.latest = PlanMessage(2, 1, 1.19, standing(np.array([0.5, -0.4]), 1.19), (2.15, -0.4), stuck)
        seen = peers_seen({2: track}, {2: view}, own_id=3, now=1.2, arrival_radius_m=0.1)
        assert seen[2].stuck is stuck and not seen[2].at_goal


def test_a_parked_car_steps_aside_for_a_peer_that_it_walls_in_with_a_car_that_stands(road):
    """A road's dead end (a T-junction): car 4 parked in the north lane,
    car 5 stuck beside it in the south lane on its way to the north lane's end, car 6
    stuck at the south lane's end on its way west. Cars 4 and 6 together wall car 5 in;
    counting parked cars alone, car 4 does not (car 5 would have a way), and car 6 has
    nowhere to give way to. Car 4 steps aside along the road, and holds while car 6
    stands."""
    home = np.array([1.77, 0.28])
    five = PeerSeen(np.array([1.76, -0.20]), goal=np.array([2.3, 0.275]))
    six = PeerSeen(np.array([2.16, -0.36]), goal=np.array([-2.3, -0.275]))
    walls = [(tuple(six.position), KEEP_CLEAR)]
    assert connected(road, five.position, five.goal, WALL_CLEAR, [(tuple(home), KEEP_CLEAR)])  # 4 alone: a way
    assert not connected(road, five.position, five.goal, WALL_CLEAR, [*walls, (tuple(home), KEEP_CLEAR)])
    watch = DeadlockWatch(4, CONFIG)
    asides = [watch.step_aside(t, home, home, {5: five, 6: six}, KEEP_CLEAR, road, WALL_CLEAR)
              for t in np.arange(0.0, CONFIG.window_s + 1.0, STEP_S)]
    aside = next(a for a in asides if a is not None)
    assert watch.steps_aside == 1 and watch.detour.for_peer == 5
    assert connected(road, five.position, five.goal, WALL_CLEAR, [*walls, (tuple(aside), KEEP_CLEAR)])
    late = watch.detour.until + 1.0  # car 6 still stands where it did: we hold on
    assert np.array_equal(watch.goal(late, aside, home, {5: five, 6: six}, True, KEEP_CLEAR, road, WALL_CLEAR),
                          aside)
    six_gone = {5: five, 6: dataclasses.replace(six, position=np.array([-1.0, -0.3]))}
    assert watch.goal(late + STEP_S, aside, home, six_gone, True, KEEP_CLEAR, road, WALL_CLEAR) is None

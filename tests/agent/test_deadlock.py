"""Deadlocks (agent.deadlock): detected from what each car sees, counted, and resolved by
the lower-priority car giving way."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent.config import DeadlockConfig, WorldConfig
from trustfg.agent.deadlock import DeadlockWatch, PeerSeen
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
              peer_at_goal: bool = False) -> list:
    """Feed ``watch`` (car ``me``) the standoff for ``seconds``; the detours it returns."""
    mine, theirs, other = (ONE, TWO, 2) if me == 1 else (TWO, ONE, 1)
    detours = []
    for k, t in enumerate(np.arange(0.0, seconds, STEP_S)):
        peer = seen(theirs, moved=peer_moves * k * STEP_S)
        if peer_at_goal:
            peer = dataclasses.replace(peer, at_goal=True)
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


def test_no_deadlock_is_seen_before_a_whole_window_of_no_progress(room):
    two = DeadlockWatch(2, CONFIG)
    assert all(d is None for d in watch_for(2, two, CONFIG.window_s - 0.5, room))
    assert two.deadlocks == 0


def test_waiting_for_a_car_that_gets_somewhere_is_no_deadlock(room):
    two = DeadlockWatch(2, CONFIG)
    watch_for(2, two, CONFIG.window_s + 1.0, room, peer_moves=0.2)  # car 1 moves on at 0.2 m/s
    assert two.deadlocks == 0 and two.yields == 0


def test_a_peer_at_its_goal_makes_no_group(room):
    two = DeadlockWatch(2, CONFIG)
    watch_for(2, two, CONFIG.window_s + 1.0, room, peer_at_goal=True)
    assert two.deadlocks == 0


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

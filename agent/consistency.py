"""Consistency evidence: did a peer do what it said it would do?

A peer's accelerations, averaged over CONSISTENCY_WINDOW_S (the change of its observed
velocity over the window), are held against the change announced by the plan it had made
when the window began (by the plan's stamp); differencing velocities over half a second
is far less noisy than a second derivative of noisy poses. A window is judged only once
every plan that could still be believed for it has arrived, a change of mind announced in
time excuses what follows it, and a car that its guard held back or that turned on the
spot first is held only to going no faster than it said (docs/design/trust.md,
"Consistency").
"""

from __future__ import annotations

import bisect
import math
import operator
from collections import deque

import numpy as np

from .config import Scenario
from .evidence import PeerView
from .guard import capped_below
from .world import SignedDistanceField

CONSISTENCY_WINDOW_S = 0.5
REPLAN_MARGIN_S = 0.15
"""Consistency is judged only against a plan stamped at most one replan period plus this
before the window began. An older announcement has been superseded by plans we never
received (loss, delay); holding a car to it would read silence as erratic driving."""
ANNOUNCED_MIN_S = 0.2
"""A change of plan excuses what a car did only over at least this long after it."""
GUARD_SLACK_MPS = 0.05
"""A peer counts as held by its guard when the cap we compute for it is this much below
its plan's speed (our view of the poses is not exactly its own)."""


def guard_holds(scenario: Scenario, sdf: SignedDistanceField, peer: int, poses: dict, announced: np.ndarray) -> bool:
    """Would the proximity guard (agent.guard), fed the poses we see, hold ``peer``
    below the speed of the plan it announced (``announced``: that plan's velocity
    now)? Then it is slower than it said for safety's sake -- every honest car's guard
    does that, unannounced. ``poses``: (x, y, yaw, radius) of every car seen, by id."""
    if not scenario.guard.enabled:
        return False
    others = [pose for cid, pose in poses.items() if cid != peer]
    return capped_below(*poses[peer], others, scenario.guard, scenario.safety, sdf,
                        float(np.linalg.norm(announced)) - GUARD_SLACK_MPS)


def turns_first(scenario: Scenario, motion, announced: np.ndarray) -> bool:
    """Does the peer seen in ``motion`` face so far from where the plan it announced goes
    (``announced``: that plan's velocity now) that its tracker (bridge.trajectory_controller,
    TrackingConfig.turns_first) turns it on the spot before it drives? Every honest car
    does that after a stop or a start facing elsewhere, unannounced (the plans are a
    point's, the cars are not)."""
    if np.linalg.norm(announced) < GUARD_SLACK_MPS:
        return False
    facing_off = math.remainder(math.atan2(announced[1], announced[0]) - motion.yaw, math.tau)
    return scenario.tracking.turns_first(facing_off)

def notice_lost(view: PeerView, t_old: float, t: float) -> bool:
    """Could a plan of the peer's that we lost, that came too late to use, or that has
    not reached us yet have told a change of mind in the window from ``t_old`` to ``t``
    (stamped after it began, ANNOUNCED_MIN_S before it ended)? Not reached us yet: we
    heard nothing stamped that late -- the peer's plans are held up in the network (a
    TCP link under loss stalls for seconds) or it went silent."""
    told_by = t - ANNOUNCED_MIN_S
    return view.heard_until < told_by or any(earliest <= told_by and latest > t_old
                                              for earliest, latest in view.lost)


def acceleration_mismatch(view: PeerView, fresh_s: float, until: float) -> tuple[float, float, float] | None:
    """(|mean observed - mean announced acceleration|, window start, window end) over the
    CONSISTENCY_WINDOW_S that ends at the last observation at or before ``until``, the
    announcement being the newest
    accepted plan the peer had made when the window began (by its stamp: a plan that
    arrived late still tells what the peer meant then); None if that plan is older than
    ``fresh_s`` then, there are not enough observations yet, or none within the window's
    start (the peer was out of sight: the window would span what nobody saw). The caller judges a
    window only once every plan that could still be believed for it has had time to
    arrive (``until`` = now - stale_after_s): a plan delayed in the network counts as if
    it had come at once, never as a car that did not say what it did. A change of mind
    announced in time is not inconsistency: if a plan made since (at least
    ANNOUNCED_MIN_S ago) announced what the peer did from its stamp on, the smaller
    mismatch counts -- a car that had to brake for a surprise and said so at its next
    replan is consistent; one that says it brakes and does not is not."""
    velocities = view.velocities  # sorted by t (appended as seen): bisection finds the latest that qualifies
    end = bisect.bisect_right(velocities, until + 1e-9, key=operator.itemgetter(0)) - 1
    if end < 0:
        return None
    t, observed = velocities[end]
    start = bisect.bisect_left(velocities, True, key=lambda tv: t - tv[0] < CONSISTENCY_WINDOW_S - 1e-6) - 1
    if start < 0 or t - velocities[start][0] > 2.0 * CONSISTENCY_WINDOW_S:
        return None  # none yet, or the peer was out of sight over the window: no evidence from not seeing
    t_old, observed_old = velocities[start]
    announced = max(((stamp, p) for stamp, p in view.history if stamp <= t_old), key=lambda sp: sp[0],
                    default=None)
    if announced is None or t_old - announced[0] > fresh_s:
        return None
    # Its guard held it back, or it turned on the spot first, as honest cars do: then it
    # is held only to going no faster than it said.
    first_held = bisect.bisect_left(view.held, t_old)  # stamps in the order seen, so sorted
    held = first_held < len(view.held) and view.held[first_held] <= t
    measure = _overspeed if held else _acceleration_change
    mismatch = measure(announced[1], t_old, observed_old, t, observed)
    since = [(stamp, p) for stamp, p in view.history if t_old < stamp <= t - ANNOUNCED_MIN_S]
    if since:
        stamp, plan = max(since, key=lambda sp: sp[0])  # the latest made, whatever came first
        then = _nearest(view.velocities, stamp)
        if abs(then[0] - stamp) <= 0.5 * ANNOUNCED_MIN_S:
            mismatch = min(mismatch, measure(plan, then[0], then[1], t, observed))
    return mismatch, t_old, t


def _nearest(velocities: deque, stamp: float) -> tuple[float, np.ndarray]:
    """The (t, v) of ``velocities`` (sorted by t: appended as seen) nearest ``stamp``, the
    earlier of two as near: ``min(velocities, key=|t - stamp|)`` by bisection."""
    t = operator.itemgetter(0)
    right = bisect.bisect_left(velocities, stamp, key=t)
    if right == 0:
        return velocities[0]
    if right == len(velocities) or abs(velocities[right - 1][0] - stamp) <= abs(velocities[right][0] - stamp):
        return velocities[bisect.bisect_left(velocities, velocities[right - 1][0], key=t)]  # the first of equals
    return velocities[right]


def _acceleration_change(plan, t_old: float, observed_old: np.ndarray, t: float, observed: np.ndarray) -> float:
    """|observed - announced change of velocity| / window, m/s^2."""
    v_then, v_now = plan.state_at(np.array([t_old, t]))[1]  # one interpolation for both ends
    change = (observed - observed_old) - (v_now - v_then)
    return float(np.linalg.norm(change)) / (t - t_old)


def _overspeed(plan, t_old: float, observed_old: np.ndarray, t: float, observed: np.ndarray) -> float:
    """How much faster than announced the car went by the window's end, per window
    length (m/s^2, judged on the same tolerance): a car its guard held, or that turned
    on the spot, is slower than its plan, and should be no faster."""
    (v_now,) = plan.state_at(np.array([t]))[1]
    return max(0.0, float(np.linalg.norm(observed) - np.linalg.norm(v_now))) / (t - t_old)

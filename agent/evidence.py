"""What a car makes of a peer's plans and motion: which plan to believe, and the evidence.

Pure, with no clock of its own: CarAgent hands in what arrived and what was seen, and the
times (ours) it happened. A plan message (:func:`take_plan`) feeds its sender's clock
estimate (agent.clocks) -- a stamp too far in the future is refused, a transparency
failure -- is dropped if too late, and joins the audit (agent.audit): until it is checked
at its stamp it is planned against only at the widest epsilon; one that passes is the
peer's accepted plan, one that misses by more than ``plan_reject_m`` is refused
(:func:`belief`). Safety evidence blames only the car that closes a gap
(:func:`safety_verdict`). docs/design/trust.md, "Which plan is believed" and "Safety".
"""

from __future__ import annotations

import math
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .audit import Ledger
from .clocks import ClockEstimate
from .config import TrustConfig
from .gp import Plan
from .messages import PlanMessage
from .sightings import Motion, Track
from .trust import TRANSPARENCY

Record = Callable[[int, float, float], None]
"""record(dimension, success, failure): add a graded piece of evidence about the peer."""


@dataclass
class PeerView:
    """What we know of one peer."""

    config: TrustConfig
    replan_period_s: float = 0.0
    """The fleet's (control.replan_period_s): how soon after a plan the peer's next can come."""
    latest: PlanMessage | None = None
    latest_received: float = -np.inf
    accepted: Plan | None = None
    """The last plan that was checked and agreed with where the peer was seen (our clock)."""
    accepted_received: float = -np.inf
    accepted_stamp: float = -np.inf
    unverified: Plan | None = None
    """The newest plan not checked yet (we did not see the peer at its stamp yet)."""
    unverified_received: float = -np.inf
    goal: tuple[float, float] | None = None
    velocities: deque = field(default_factory=lambda: deque(maxlen=64))
    """(t, observed velocity) at evidence ticks."""
    held: deque = field(default_factory=lambda: deque(maxlen=64))
    """Evidence ticks (t) at which, as we see the fleet, the peer could not drive its plan:
    its proximity guard held it below the speed the plan announced (agent.guard), or it
    faced too far from where the plan went and turned on the spot first (bridge.trajectory_controller):
    then it is held only to going no faster than it said (agent.consistency)."""
    lost: deque = field(default_factory=lambda: deque(maxlen=32))
    """(earliest, latest) stamp (our clock) a plan of the peer's that we lost could have
    had, from gaps in its sequence numbers, or that came too late to use: a change of
    mind may have been told there."""
    heard_until: float = -np.inf
    """The newest stamp (our clock) of any plan message heard from the peer, used or not:
    what it said up to then has reached us or is known lost."""
    history: deque = field(default_factory=lambda: deque(maxlen=32))
    """(stamp, plan) of the plans accepted lately, in order of arrival (our clock)."""
    clock: ClockEstimate = field(init=False)
    """Its clock's offset from ours (agent.clocks)."""
    ledger: Ledger = field(init=False)
    """Its plans still being held to their word (agent.audit)."""

    def __post_init__(self) -> None:
        self.clock = ClockEstimate(self.config.clock_window_s, self.config.clock_tolerance_s)
        self.ledger = Ledger(self.config, self.replan_period_s)

    def accept(self, plan: Plan, stamp: float, received: float) -> None:
        self.accepted, self.accepted_received, self.accepted_stamp = plan, received, stamp
        self.history.append((stamp, plan))
        if self.unverified is plan:
            self.unverified = None


def retimed(plan: Plan, shift_s: float) -> Plan:
    """The same plan with every time moved by ``shift_s``."""
    return Plan(plan.t0 + shift_s, plan.dt, plan.positions, plan.velocities)


def take_plan(view: PeerView, message: PlanMessage, now: float, track: Track | None, record: Record,
              counters: Counter) -> None:
    """A plan message from the peer arrived at ``now`` (our clock)."""
    config = view.config
    previous = view.latest
    lost = previous is not None and message.seq > previous.seq + 1
    view.latest, view.latest_received, view.goal = message, now, message.goal
    view.clock.add(message.stamp, now)
    if config.reject_plans and message.stamp - now > config.clock_tolerance_s:
        counters["plans_future_stamped"] += 1
        record(TRANSPARENCY, 0.0, 1.0)
        return
    stamp = view.clock.to_ours(message.stamp)
    view.heard_until = max(view.heard_until, stamp)
    plan = retimed(message.plan, stamp - message.stamp) if stamp != message.stamp else message.plan
    lost_after = view.clock.to_ours(previous.stamp) + view.replan_period_s if lost else None
    if lost_after is not None:
        counters["peer_plans_lost"] += 1
        view.lost.append((lost_after, stamp))
    if now - stamp > config.stale_after_s:
        # Delayed in the network: no use, no evidence -- and, like a lost plan, it may
        # have told a change of mind that the peer's older plans are no longer held to.
        counters["plans_too_late"] += 1
        if lost_after is None:
            view.lost.append((stamp, stamp))
        view.ledger.lost(stamp if lost_after is None else lost_after)
        return
    view.ledger.add(plan, stamp, now, lost_after=lost_after)
    if config.reject_plans:
        view.unverified, view.unverified_received = plan, now
    else:
        view.accept(plan, stamp, now)  # believed as it comes
    audit(view, track, record, counters)


def audit(view: PeerView, track: Track | None, record: Record, counters: Counter) -> None:
    """Compare the peer's kept plans with what we have seen of it since; act on misses.
    Counts ``plans_rejected`` (off at the stamp), ``plans_failed_audit`` (a future that did
    not come true, past reject(lag)) and ``peer_plans_unchecked`` (no observation at the
    stamp to check against)."""
    config = view.config
    unverifiable = view.ledger.unverifiable
    for check in view.ledger.due(track):
        if check.success or check.failure:
            record(TRANSPARENCY, check.success, check.failure)
        if not config.reject_plans:
            continue
        plan = check.claim.plan
        if check.lag_s < 1e-9:
            if check.rejected:
                counters["plans_rejected"] += 1
                if view.unverified is plan:
                    view.unverified = None
            elif view.unverified is plan or check.claim.stamp > view.accepted_stamp:
                view.accept(plan, check.claim.stamp, check.claim.received)
        elif check.rejected:
            counters["plans_failed_audit"] += 1  # its future did not come true: evidence, and counted
    counters["peer_plans_unchecked"] += view.ledger.unverifiable - unverifiable


def belief(view: PeerView, now: float) -> tuple[Plan, bool] | None:
    """The plan to plan against and whether it is verified; None: predict the peer."""
    fresh = view.config.stale_after_s
    if view.accepted is not None and now - view.accepted_received <= fresh:
        return view.accepted, True
    if view.unverified is not None and now - view.unverified_received <= fresh:
        return view.unverified, False
    return None


def safety_verdict(motion: Motion, others: list[tuple[Motion, float]], config: TrustConfig) -> tuple[float, float]:
    """(success, failure) of a peer's safety: it fails only if it is closer than the breach
    distance (given per other car) to a car it is closing on."""
    x, y = motion.position.tolist()
    for other, breach_distance in others:
        gx, gy = other.position[0] - x, other.position[1] - y
        distance = math.hypot(gx, gy)
        if distance >= breach_distance:  # most pairs, most of the time: one hypot, no array
            continue
        vx, vy = motion.velocity.tolist()
        closing = (vx * gx + vy * gy) / max(distance, 1e-9)
        if closing > config.blame_closing_mps:
            return 0.0, 1.0
    return 1.0, 0.0

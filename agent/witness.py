"""What a car makes of what it sees of its peers, once every evidence period.

Every ``trust.evidence_period_s`` the witness audits each peer's plans against where the
peer is seen (agent.audit), judges safety from the observed motion of every pair of cars
(agent.evidence.safety_verdict: only the car that closes a gap is blamed) and consistency
from the peer's accelerations against what it announced (agent.consistency). What it
finds goes into the car's TrustBook. Pure: the car hands in what it saw and heard.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .config import Scenario
from .consistency import REPLAN_MARGIN_S, acceleration_mismatch, guard_holds, notice_lost, turns_first
from .evidence import PeerView, audit, safety_verdict
from .sightings import Track
from .trust import CONSISTENCY, SAFETY, TrustBook, graded
from .world import SignedDistanceField

FRESH_MOTION_S = 0.2
"""Only cars seen within this long count for safety and consistency evidence."""
EVIDENCE_UNIT_S = 0.1
"""A piece of safety or consistency evidence stands for this long of observation: a car
that gathers every ``evidence_period_s`` counts each piece evidence_period_s / this times,
so trust grows and forgets at the same pace however often it looks (docs/design/trust.md,
"Evidence"). The audit's checks come on the plans' own schedule and count once each."""


def recorder(trust: TrustBook, peer: int, now: float) -> Callable[[str, float, float], None]:
    """A callback that records evidence about ``peer`` at ``now`` in ``trust``."""
    return lambda dimension, success, failure: trust.record(peer, dimension, success, failure, now)


@dataclass
class Witness:
    """One car's evidence gathering: rate-limited, with the car's scene and radii."""

    own_id: int
    scenario: Scenario
    sdf: SignedDistanceField
    radius: Callable[[int], float]
    """A car's radius by its id."""
    last_at: float = -np.inf
    """When evidence was last gathered."""

    def next_at(self) -> float:
        """When :meth:`gather` will next gather."""
        return self.last_at + self.scenario.trust.evidence_period_s

    def gather(self, now: float, tracks: dict[int, Track], peers: dict[int, PeerView], trust: TrustBook,
               counters: Counter) -> None:
        """Audits, safety and consistency evidence about every seen peer (at most once a period)."""
        config = self.scenario.trust
        if now - self.last_at < config.evidence_period_s - 1e-9:
            return
        self.last_at = now
        motions = {cid: tr.motion() for cid, tr in tracks.items()}
        motions = {cid: m for cid, m in motions.items() if m is not None and now - m.stamp <= FRESH_MOTION_S}
        for peer, view in peers.items():
            audit(view, tracks.get(peer), recorder(trust, peer, now), counters)
        radii = {cid: self.radius(cid) for cid in motions}
        poses = {cid: (*m.position, m.yaw, radii[cid]) for cid, m in motions.items()}  # as the guard reads them
        breach = self.scenario.safety.breach_distance
        amount = config.evidence_period_s / EVIDENCE_UNIT_S
        for peer, motion in motions.items():
            if peer == self.own_id:
                continue
            others = [(m, breach(radii[peer], radii[cid])) for cid, m in motions.items() if cid != peer]
            if others:
                # Does the peer keep the required clearance from every car it closes on?
                trust.record(peer, SAFETY, *safety_verdict(motion, others, config), now, amount)
            view = peers.get(peer)
            if view is not None:
                self._judge_consistency(now, peer, view, motion, poses, trust, counters, amount)

    def _judge_consistency(self, now: float, peer: int, view: PeerView, motion, poses: dict, trust: TrustBook,
                           counters: Counter, amount: float) -> None:
        """Note what the peer did now, and judge the window that has just become due
        (counted ``amount`` times: :data:`EVIDENCE_UNIT_S`)."""
        config = self.scenario.trust
        view.velocities.append((motion.stamp, motion.velocity))
        if view.accepted is not None:
            announced = view.accepted.state_at(np.array([motion.stamp]))[1][0]
            if (turns_first(self.scenario, motion, announced)
                    or guard_holds(self.scenario, self.sdf, peer, poses, announced)):
                view.held.append(motion.stamp)
        mismatch = acceleration_mismatch(view, self.scenario.control.replan_period_s + REPLAN_MARGIN_S,
                                         now - config.stale_after_s)
        if mismatch is not None:
            s, f = graded(mismatch[0], config.consistency_tolerance_mps2)
            if f > 0 and notice_lost(view, *mismatch[1:]):
                counters["consistency_excused_by_loss"] += 1
            else:
                trust.record(peer, CONSISTENCY, s, f, now, amount)

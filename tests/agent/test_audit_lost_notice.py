"""A change of mind whose notice was lost in the network is not held against a peer
(docs/design/trust.md, "Lost notices"); a liar cannot use the rule to escape for longer than
replanning every period would let it."""

from collections import Counter

import numpy as np

from trustfg.agent.config import TrustConfig
from trustfg.agent.evidence import PeerView, audit, take_plan
from trustfg.agent.gp import Plan
from trustfg.agent.messages import PlanMessage
from trustfg.agent.sightings import Track

CONFIG = TrustConfig()
PERIOD = 0.2  # the fleet's replan period


def driving(t0: float, x0: float, speed: float) -> Plan:
    times = 0.5 * np.arange(9)
    return Plan(t0, 0.5, np.c_[x0 + speed * times, np.zeros(9)], np.tile([speed, 0.0], (9, 1)))


def honest_brake(lost: bool, seconds: float = 3.0, stall_until: float | None = None) -> float:
    """A peer says at 0 it drives +x at 0.5 m/s, changes its mind at 0.2 and stands at
    0.1 m. Its plans at 0.2-1.0 (seq 2-6, the notice) are lost or come at once, and the
    one at 1.2 (seq 7) comes at once; or every plan from 0.2 on is held up in a stalled
    link until ``stall_until`` and comes then, in order. Returns the transparency failure
    recorded against it."""
    view, track, failures = PeerView(CONFIG, PERIOD), Track(), []
    record = lambda dimension, success, failure: failures.append(failure)  # noqa: E731
    sent = {0: driving(0.0, 0.0, 0.5)} | {k: driving(0.2 * k, 0.1, 0.0) for k in range(1, 7)}
    arrivals = sorted((0.2 * k if stall_until is None or k == 0 else max(0.2 * k, stall_until), k) for k in sent
                      if not (lost and 1 <= k <= 5))
    for step in range(int(seconds / 0.02) + 1):
        t = round(0.02 * step, 3)
        track.add(t, min(0.5 * t, 0.1), 0.0, 0.0)
        arrived = False
        while arrivals and arrivals[0][0] <= t + 1e-9:
            _, k = arrivals.pop(0)
            take_plan(view, PlanMessage(2, k + 1, 0.2 * k, sent[k], (3.0, 0.0)), t, track, record, Counter())
            arrived = True
        if not arrived:
            audit(view, track, record, Counter())
    return sum(failures)


def test_a_change_of_mind_told_in_time_is_not_a_lie():
    assert honest_brake(lost=False) == 0.0


def test_a_change_of_mind_whose_notice_was_lost_is_not_a_lie():
    assert honest_brake(lost=True) == 0.0


def test_a_change_of_mind_whose_notice_came_too_late_to_use_is_not_a_lie():
    """A link stalled from 0.2 to 1.7 s (TCP under heavy loss): the notice comes in one
    burst with the plans after it, the first ones too late to use (older than
    stale_after_s), with no gap in the sequence numbers. A plan that came too late may
    have told the change, as a lost one: the first plan is not held to its word beyond."""
    assert honest_brake(lost=False, stall_until=1.7) == 0.0


def test_without_the_rule_the_lost_notice_is_held_against_it(monkeypatch):
    from trustfg.agent import evidence
    real_add = evidence.Ledger.add
    monkeypatch.setattr(evidence.Ledger, "add", lambda self, plan, stamp, received, lost_after=None:
                        real_add(self, plan, stamp, received))
    real_init = evidence.Ledger.__init__
    monkeypatch.setattr(evidence.Ledger, "__init__", lambda self, config, replan_period_s=0.0:
                        real_init(self, config, np.inf))  # and never waits for the next plan
    assert honest_brake(lost=True) > 0.5


def test_skipping_sequence_numbers_buys_a_liar_no_more_than_a_period():
    """A plan followed by a jump of 1000 sequence numbers is still held until a period
    plus the notice after its stamp."""
    view = PeerView(CONFIG, PERIOD)
    take_plan(view, PlanMessage(2, 1, 0.0, driving(0.0, 0.0, 0.5), (3.0, 0.0)), 0.0, None, lambda *a: None,
              Counter())
    take_plan(view, PlanMessage(2, 1001, 0.05, driving(0.05, 0.0, 0.5), (3.0, 0.0)), 0.05, None, lambda *a: None,
              Counter())
    assert view.ledger.claims[0].lost_successor == PERIOD


def test_a_peer_that_falls_silent_is_held_to_its_last_plan_after_the_horizon():
    """Says it drives on, stands instead, and says nothing more: held to it at once up to
    a period plus the notice (0.7 s); the checks beyond wait for a next plan as long as
    the audit's horizon, then hold it to its word."""
    view, track, failures = PeerView(CONFIG, PERIOD), Track(), []
    record = lambda dimension, success, failure: failures.append((track.last_stamp, failure))  # noqa: E731
    track.add(0.0, 0.0, 0.0, 0.0)
    take_plan(view, PlanMessage(2, 1, 0.0, driving(0.0, 0.0, 0.5), (3.0, 0.0)), 0.0, track, record, Counter())
    for step in range(1, 251):
        track.add(0.02 * step, 0.0, 0.0, 0.0)
        audit(view, track, record, Counter())
    when = [t for t, failure in failures if failure > 0]
    assert when and when[0] <= PERIOD + CONFIG.audit_notice_s + CONFIG.audit_grace_s + 1e-9
    late = [t for t in when if t > 1.0]
    assert late and CONFIG.audit_horizon_s <= late[0] < CONFIG.audit_horizon_s + 0.1

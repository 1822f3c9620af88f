"""Holding plans to what they said: every plan is compared with where its sender is seen,
at its stamp and then again as each of its future times comes.

A car that tells the truth now and lies about later passes any check of the present, so
a peer's plans are kept (:class:`Ledger`) and checked every ``audit_period_s`` of their
future, up to ``audit_horizon_s``, against the observation of that moment; the tolerance
grows with the lag (:func:`tolerance`), as honest futures change when cars replan. At
the stamp a miss beyond the tolerance is a whole failure; later misses are graded and
add at most one failure per plan. A plan is held only until ``audit_notice_s`` after its
sender's next plan -- or after a lost plan's earliest stamp, which may have carried that
notice. :func:`first_false_claim` runs the same rules on the truth, for experiments.

docs/design/trust.md, "The audit" and "Lost notices".
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .config import TrustConfig
from .gp import Plan
from .sightings import NEAREST_S, Track


@dataclass
class Claim:
    """One received plan (on our clock) and what is left to check of it."""

    plan: Plan
    stamp: float
    received: float
    """When it arrived (our clock)."""
    times: np.ndarray
    """Times (ours) to check, ascending; the first is the stamp."""
    said: np.ndarray
    """(k, 2) where the plan says its sender is at each of ``times``."""
    next: int = 0
    """Index of the first check not done yet."""
    failure: float = 0.0
    """Failure already recorded against this plan (at most 1)."""
    checked_now: bool = False
    """Whether lag 0 has been checked (the plan verified or refused)."""
    lost_successor: float = np.inf
    """The earliest stamp a plan of the peer's that we lost after this one could have had
    (inf: none lost): that plan may have given notice of a change of mind."""


@dataclass(frozen=True)
class Check:
    """One comparison of a claim with an observation."""

    claim: Claim
    lag_s: float
    miss_m: float
    success: float
    failure: float
    """Graded evidence to record: at lag 0 both; later only the increase in failure."""
    rejected: bool
    """The miss is beyond reject(lag): the plan must not be planned against."""


def tolerance(lag_s, config: TrustConfig):
    """How far a claim at lag ``lag_s`` (s, or an array of them) may miss, m."""
    return config.transparency_tolerance_m + lag_s * config.audit_tolerance_growth_mps


def reject_threshold(lag_s, config: TrustConfig):
    return config.plan_reject_m + lag_s * config.audit_tolerance_growth_mps


def check_times(plan: Plan, stamp: float, config: TrustConfig) -> np.ndarray:
    """The times (ours) a plan stamped ``stamp`` is checked at: its stamp, then every
    ``audit_period_s`` up to ``audit_horizon_s``, no later than the plan's end."""
    times = stamp + np.arange(0.0, config.audit_horizon_s + 1e-9, config.audit_period_s)
    return times[times <= max(plan.t_end, stamp)]


def first_false_claim(told: list[tuple[float, Plan, bool]], truth_at, config: TrustConfig,
                      after: float = -np.inf) -> float | None:
    """When a lie first came due: the earliest audit time, not before ``after``, at which a
    plan told as a lie put its car beyond tolerance(lag) from where it truly was -- the
    first evidence the audit could have recorded. The Ledger's rules (a stamp plus a
    multiple of ``audit_period_s``, within ``audit_horizon_s``, until the next plan's
    notice ran out) with the truth in place of a track: the moment an observer who heard
    and saw everything could first have caught it. A lie withdrawn with notice never comes
    due. ``told``: (stamp, plan, lied) in order of publication; ``truth_at(times)`` ->
    (k, 2) true positions. None: no lie came due."""
    due = false_claim_times(told, truth_at, config, after)
    return float(due[0]) if len(due) else None


def false_claim_times(told: list[tuple[float, Plan, bool]], truth_at, config: TrustConfig,
                      after: float = -np.inf) -> np.ndarray:
    """Every audit time, not before ``after``, at which a lie came due
    (:func:`first_false_claim`'s rules), sorted, each once."""
    c = config
    due = [np.empty(0)]
    for i, (stamp, plan, lied) in enumerate(told):
        if not lied:
            continue
        superseded = told[i + 1][0] + c.audit_notice_s if i + 1 < len(told) else np.inf
        times = check_times(plan, stamp, c)
        times = times[((times == stamp) | (times <= superseded)) & (times >= after)]
        misses = np.linalg.norm(plan.position_at(times) - truth_at(times), axis=1)
        due.append(times[misses > tolerance(times - stamp, c)])
    return np.unique(np.concatenate(due))


def sustained_lie(due: np.ndarray, config: TrustConfig, lasting_s: float) -> float | None:
    """The start of the first run of lies coming due (``due``: sorted times,
    :func:`false_claim_times`) that lasts ``lasting_s`` or more with no pause longer than
    two audit periods; None if no run lasts that long. A lie told for a moment and then
    not again -- a liar that stands has nothing to bend -- is forgotten (trust forgets,
    ``TrustConfig.forgetting``) before it can tell the liar apart: detection is timed
    from a lie that goes on."""
    pause = 2.0 * config.audit_period_s + 1e-9
    start = 0
    for k in range(1, len(due) + 1):
        if k == len(due) or due[k] - due[k - 1] > pause:
            if due[k - 1] - due[start] >= lasting_s - 1e-9:
                return float(due[start])
            start = k
    return None


def false_now(miss_m: float, tolerance_m: float) -> float:
    """A claim of the present: 1 (a failure) beyond the tolerance, else 0."""
    return float(miss_m > tolerance_m)


def graded_failure(miss_m: float, tolerance_m: float) -> float:
    """0 up to the tolerance, 1 from twice the tolerance, linear in between."""
    return min(1.0, max(0.0, (miss_m - tolerance_m) / tolerance_m))


@dataclass
class Ledger:
    """The plans of one peer that still have something to say."""

    config: TrustConfig
    replan_period_s: float = 0.0
    """The fleet's: how soon after a plan its sender's next one can come."""
    claims: deque = field(default_factory=deque)
    dropped: int = 0
    """Claims pushed out unchecked by the memory bound."""
    unverifiable: int = 0
    """Claims whose stamp came with no observation of the peer to check it against."""

    def add(self, plan: Plan, stamp: float, received: float, lost_after: float | None = None) -> Claim:
        """Keep ``plan`` (stamped ``stamp``, our clock) to check. ``lost_after``: plans of
        the peer's were lost between the last one and this, the first of them stamped no
        earlier than that -- the last plan is held only until it could have given notice."""
        c = self.config
        if lost_after is not None:
            self.lost(lost_after)
        times = check_times(plan, stamp, c)
        claim = Claim(plan, stamp, received, times, plan.position_at(times))
        self.claims.append(claim)
        while len(self.claims) > c.audit_max_plans:
            self.claims.popleft()
            self.dropped += 1
        return claim

    def lost(self, earliest: float) -> None:
        """Plans of the peer's stamped from ``earliest`` on were lost or came too late to
        use: the last plan kept is held only until one of them could have given notice."""
        if self.claims:
            last = self.claims[-1]
            last.lost_successor = min(last.lost_successor, max(earliest, last.stamp))

    def due(self, track: Track | None) -> list[Check]:
        """Every check whose time our observations of the peer have reached, in order;
        claims with nothing left are forgotten."""
        if track is None or track.last_stamp is None:
            return []
        c = self.config
        now_reach = track.last_stamp + NEAREST_S  # lag 0: at once
        late_reach = track.last_stamp - c.audit_grace_s  # later: once a newer plan had time to arrive
        due = []  # (claim, start, end): the checks that came due, read against the track at once
        claims = list(self.claims)
        for i, claim in enumerate(claims):
            start = end = claim.next
            if end >= len(claim.times) or claim.times[end] > (now_reach if end == 0 else late_reach):
                continue  # nothing of it has come due (most claims, most ticks)
            heard = i + 1 < len(claims)
            successor = min(claims[i + 1].stamp if heard else np.inf, claim.lost_successor)
            superseded = successor + c.audit_notice_s
            # Nothing heard after it yet: a next plan may be late or lost, and may have given
            # notice. Beyond where that notice would reach, wait for it -- or for a silence
            # as long as the audit's horizon, after which the plan is held to its word.
            undecided = (claim.stamp + self.replan_period_s + c.audit_notice_s
                         if not heard and successor == np.inf
                         and track.last_stamp - claim.received < c.audit_horizon_s else np.inf)
            done = False
            while end < len(claim.times) and claim.times[end] <= (now_reach if end == 0 else late_reach):
                if end > 0 and claim.times[end] > superseded:  # a newer plan gave notice of any change
                    done = True
                    break
                if end > 0 and claim.times[end] > undecided:
                    break
                end += 1
            claim.next = len(claim.times) if done else end
            if end > start:
                due.append((claim, start, end))
        out, rows, k = [], [], 0
        if due:  # one look-up for every claim's due checks (a few each; numpy's cost is per call)
            times = np.concatenate([claim.times[start:end] for claim, start, end in due])
            said = np.concatenate([claim.said[start:end] for claim, start, end in due])
            seen, valid = track.positions_at(times)
            rows = list(zip(times.tolist(), np.linalg.norm(said - seen, axis=1).tolist(), valid.tolist()))
        for claim, start, end in due:
            checks, k = rows[k:k + end - start], k + end - start
            for t, miss, ok in checks:
                first = not claim.checked_now
                claim.checked_now = True
                if not ok:
                    self.unverifiable += first
                    continue  # not seen at that moment: nothing to compare
                lag = t - claim.stamp
                if first and lag < 1e-9:
                    fail = false_now(miss, tolerance(0.0, c))
                    success, failure = 1.0 - fail, fail
                else:
                    fail = graded_failure(miss, tolerance(lag, c))
                    success, failure = 0.0, max(0.0, fail - claim.failure)
                claim.failure = max(claim.failure, fail)
                out.append(Check(claim, lag, miss, success, failure, rejected=miss > reject_threshold(lag, c)))
        while self.claims and self.claims[0].next >= len(self.claims[0].times):
            self.claims.popleft()
        return out

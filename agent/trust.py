"""Trust in peers: Beta reputation per dimension, evidence, testimony fusion, epsilon.

For every peer and dimension (safety, consistency, transparency) a :class:`TrustBook`
holds a Beta(alpha, beta) belief that the peer behaves well, forgetting towards the
prior (the Beta Reputation System); tau = (alpha + 1) / (alpha + beta + 2), and overall
trust is the weakest dimension. Testimonies are fused as dependent evidence that can make
a car more careful, never less (:meth:`TrustBook.fused`). The transparency trust widens
the safety distance (paper Sec. III.D, IV.C):

    eps_ab = eps_0 * g(q),   g(tau) = 1 + (g_max - 1) * clip((tau_full - tau) / (tau_full - tau_floor), 0, 1)

with q a lower quantile of the transparency belief, not its mean, so a peer we know
little about is planned around as its worst plausible case. docs/design/trust.md,
"Beliefs", "Testimonies" and "From trust to distance".
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.special import betaincinv

from .config import TrustConfig
from .messages import DIMENSIONS, PeerTrust, TrustReport

SAFETY, CONSISTENCY, TRANSPARENCY = range(3)


def expected(alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """tau = (alpha + 1) / (alpha + beta + 2), the mean of Beta(alpha + 1, beta + 1)."""
    return (alpha + 1.0) / (alpha + beta + 2.0)


def belief(alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
    """Josang's belief mass b = alpha / (alpha + beta + 2) of an opinion."""
    return alpha / (alpha + beta + 2.0)


def graded(error: float, tolerance: float) -> tuple[float, float]:
    """(success, failure) of an error against a tolerance: full success up to the
    tolerance, full failure from twice the tolerance, linear in between."""
    failure = float(min(max((error - tolerance) / tolerance, 0.0), 1.0))  # np.clip's value, NaN kept, without its call
    return 1.0 - failure, failure


def lower_bound(alpha: float, beta: float, quantile: float) -> float:
    """The ``quantile`` quantile of Beta(alpha + 1, beta + 1): a lower confidence bound of tau."""
    return float(betaincinv(alpha + 1.0, beta + 1.0, quantile))


def epsilon_gain(tau: float, config: TrustConfig) -> float:
    """g(tau): 1 for a trusted peer, up to epsilon_gain_max for an untrusted one."""
    span = config.tau_full - config.tau_floor
    lack = float(min(max((config.tau_full - tau) / span, 0.0), 1.0))
    return 1.0 + (config.epsilon_gain_max - 1.0) * lack


@dataclass
class Opinion:
    """Beta evidence about one peer, all dimensions: alpha, beta of shape (3,)."""

    alpha: np.ndarray
    beta: np.ndarray
    updated: float

    def tau(self) -> np.ndarray:
        return expected(self.alpha, self.beta)


@dataclass
class TrustBook:
    """What one agent believes of its peers, from its own eyes and from testimonies."""

    owner: int
    config: TrustConfig
    direct: dict[int, Opinion] = field(default_factory=dict)
    testimonies: dict[int, tuple[TrustReport, float]] = field(default_factory=dict)
    """The latest testimony of each reporter and when it arrived."""
    limited_sight: bool = False
    """The owner sees only the peers near it (SensingConfig): a testimony that holds no
    evidence about a peer says nothing of it, and testimonies speak for a peer the owner
    has seen little of, and nothing bad (docs/design/trust.md, "Limited sight"). False
    (the motion capture's view): every peer is seen from the start."""
    counters: Counter = field(default_factory=Counter)
    _rejected: dict = field(default_factory=dict, repr=False)
    """(reporter, peer) -> the report (its seq and stamp) last counted as rejected: a
    testimony is fused again at every read until the next one comes, and counted once."""
    _fused: dict = field(default_factory=dict, repr=False)
    """fused() per (peer, now) and discount() per (reporter, now), until the next
    evidence or testimony: a tick's replan and report read every peer's fusion, and
    every fusion every reporter's discount."""

    # --- direct evidence -----------------------------------------------------------------

    def opinion(self, peer: int, now: float) -> Opinion:
        if peer not in self.direct:
            prior_a = np.full(3, self.config.prior_alpha)
            prior_b = np.full(3, self.config.prior_beta)
            self.direct[peer] = Opinion(prior_a, prior_b, now)
        return self.direct[peer]

    def _decay(self, opinion: Opinion, now: float) -> None:
        elapsed = max(0.0, now - opinion.updated)
        keep = self.config.forgetting ** elapsed
        c = self.config
        opinion.alpha = c.prior_alpha + keep * (opinion.alpha - c.prior_alpha)
        opinion.beta = c.prior_beta + keep * (opinion.beta - c.prior_beta)
        opinion.updated = max(opinion.updated, now)

    def record(self, peer: int, dimension: int, success: float, failure: float, now: float,
               amount: float = 1.0) -> None:
        """Add one graded piece of direct evidence about ``peer`` at time ``now``, counted
        ``amount`` times (the witness's pieces stand for its whole evidence period:
        agent.witness.EVIDENCE_UNIT_S). Counts ``evidence_<dimension>`` and, for a piece
        more failure than success, ``failures_<dimension>`` -- once per piece."""
        if peer == self.owner:
            return
        opinion = self.opinion(peer, now)
        self._decay(opinion, now)
        weight = self.config.consistency_failure_weight if dimension == CONSISTENCY else self.config.failure_weight
        self._fused.clear()
        opinion.alpha[dimension] += amount * success
        opinion.beta[dimension] += amount * (weight * failure)
        self.counters[f"evidence_{DIMENSIONS[dimension]}"] += 1
        if failure > 0.5:
            self.counters[f"failures_{DIMENSIONS[dimension]}"] += 1

    # --- testimonies ---------------------------------------------------------------------

    def receive(self, report: TrustReport, now: float | None = None) -> None:
        """Keep the latest testimony of each reporter (``now``: when it arrived, our clock);
        with ``testimonies`` off, none."""
        if report.sender == self.owner or not self.config.testimonies:
            return
        self.testimonies[report.sender] = (report, report.stamp if now is None else now)
        self._fused.clear()
        self.counters["testimonies"] += 1

    def forget_reporter(self, reporter: int) -> None:
        self.testimonies.pop(reporter, None)
        self._fused.clear()

    def fused(self, peer: int, now: float) -> tuple[np.ndarray, np.ndarray]:
        """Own evidence, made more careful where testimonies say so (docs/design/trust.md,
        "Testimonies")."""
        key = (peer, now)
        if key not in self._fused:
            if len(self._fused) > 256:  # bounded, also when no evidence comes for hours
                self._fused.clear()
            self._fused[key] = self._fuse(peer, now)
        alpha, beta = self._fused[key]
        return alpha.copy(), beta.copy()

    def _fuse(self, peer: int, now: float) -> tuple[np.ndarray, np.ndarray]:
        c = self.config
        own = self.opinion(peer, now)
        self._decay(own, now)
        own_tau = own.tau()
        own_amount = (own.alpha - c.prior_alpha) + (own.beta - c.prior_beta)
        reports = [(reporter, report, arrived) for reporter, (report, arrived) in self.testimonies.items()
                   if reporter not in (peer, self.owner) and peer in report.peers]
        if not reports:
            return own.alpha, own.beta
        # Per reporter and dimension, in plain floats, summed as they come: a handful of
        # each, fused tens of thousands of times a run, where numpy's calls on 3-element
        # arrays cost more than the sums.
        pa, pb, cap, deviation = c.prior_alpha, c.prior_beta, c.testimony_max_evidence, c.testimony_deviation
        own_alpha, own_beta = own.alpha.tolist(), own.beta.tolist()
        own_tau, own_amount = own_tau.tolist(), own_amount.tolist()
        checked = [amount >= c.testimony_min_evidence for amount in own_amount]
        # Limited sight: where our own eyes have seen little of the peer (less than the
        # deviation test needs) and nothing bad (its trust not below a stranger's: one
        # failure is), it is believed as its witnesses say, raised or lowered.
        stranger = (pa + 1.0) / (pa + pb + 2.0)
        may_raise = [self.limited_sight and tau >= stranger and not test for tau, test in zip(own_tau, checked)]
        r_sum, s_sum, used = [0, 0, 0], [0, 0, 0], [0, 0, 0]  # per dimension, over the reporters not left out
        heard = False
        for reporter, report, arrived in reports:
            weight = self.discount(reporter, now)
            if weight <= 0.0:
                continue
            heard = True
            age = c.forgetting ** max(0.0, now - arrived)
            said = report.peers[peer]
            deviates = False
            for d in range(3):
                r, s = float(said.alpha[d]), float(said.beta[d])
                silent = self.limited_sight and r + s <= 0.0  # limited sight: it has not seen the peer
                scale = min(1.0, cap / max(r + s, 1e-12))
                r, s = r * scale * age, s * scale * age
                if checked[d] and not silent and abs((r + pa + 1.0) / (r + pa + s + pb + 2.0) - own_tau[d]) > deviation:
                    deviates = True
                elif not silent:
                    r_sum[d] += weight * r
                    s_sum[d] += weight * s
                    used[d] += 1
            if deviates and self._rejected.get((reporter, peer)) != (report.seq, report.stamp):
                self._rejected[(reporter, peer)] = (report.seq, report.stamp)
                self.counters["testimonies_rejected"] += 1
        if not heard:
            return own.alpha, own.beta
        alpha, beta = list(own_alpha), list(own_beta)
        for d in range(3):
            count = max(float(used[d]), 1.0)
            r_said, s_said = r_sum[d] / count, s_sum[d] / count  # averaged: dependent sources
            said_amount = r_said + s_said
            surplus = (said_amount - own_amount[d]) / max(said_amount, 1e-12) if said_amount > own_amount[d] else 0.0
            a, b = own_alpha[d] + surplus * r_said, own_beta[d] + surplus * s_said
            if (a + 1.0) / (a + b + 2.0) < own_tau[d] or (may_raise[d] and used[d]):  # lower, never raise: but
                alpha[d], beta[d] = a, b  # where our eyes hold little, and nothing bad
        return np.array(alpha), np.array(beta)

    def discount(self, reporter: int, now: float) -> float:
        """Weight of a reporter's testimony: a's belief mass in r's weakest dimension
        (kept per (reporter, now) with the fusions: every fusion of a tick asks it)."""
        key = ("discount", reporter, now)
        if key not in self._fused:
            opinion = self.opinion(reporter, now)
            self._decay(opinion, now)
            tau = opinion.tau()
            d = int(np.argmin(tau))
            self._fused[key] = float(belief(opinion.alpha[d], opinion.beta[d]))
        return self._fused[key]

    # --- what the planner and the reports use ----------------------------------------------

    def tau(self, peer: int, now: float) -> np.ndarray:
        """Fused trust per dimension (safety, consistency, transparency)."""
        alpha, beta = self.fused(peer, now)
        return expected(alpha, beta)

    def trust(self, peer: int, now: float) -> float:
        """Overall trust: the weakest dimension."""
        return float(np.min(self.tau(peer, now)))

    def distrusted(self, peer: int, now: float) -> bool:
        """Whether ``peer``'s transparency trust is below a stranger's (the prior's
        expected value): more evidence of false claims than of true ones. A new, silent or
        little-known peer is not distrusted, only uncertain (a wide epsilon all the same)."""
        c = self.config
        return bool(self.tau(peer, now)[TRANSPARENCY] < expected(c.prior_alpha, c.prior_beta))

    def epsilon(self, peer: int, now: float, epsilon_0: float, transparency: bool) -> float:
        """The distance to keep from ``peer``: eps_0 * g(lower bound of transparency trust);
        with the transparency factor off, eps_0 * ``epsilon_gain_fixed`` from everyone."""
        if not transparency:
            return epsilon_0 * self.config.epsilon_gain_fixed
        alpha, beta = self.fused(peer, now)
        bound = lower_bound(alpha[TRANSPARENCY], beta[TRANSPARENCY], self.config.epsilon_quantile)
        return epsilon_0 * epsilon_gain(bound, self.config)

    def report(self, sender: int, seq: int, now: float, epsilon_0: Callable[[int], float],
               transparency: bool) -> TrustReport:
        """Our testimony: direct evidence (without the prior) plus what we believe
        (``epsilon_0(peer)``: the distance we keep from a fully trusted ``peer``)."""
        peers = {}
        for peer in sorted(self.direct):
            opinion = self.direct[peer]
            self._decay(opinion, now)
            tau = self.tau(peer, now)
            peers[peer] = PeerTrust(
                alpha=tuple(np.maximum(0.0, opinion.alpha - self.config.prior_alpha)),
                beta=tuple(np.maximum(0.0, opinion.beta - self.config.prior_beta)),
                tau=tuple(float(x) for x in tau),
                trust=float(np.min(tau)),
                epsilon=self.epsilon(peer, now, epsilon_0(peer), transparency),
            )
        return TrustReport(sender=sender, seq=seq, stamp=now, peers=peers)

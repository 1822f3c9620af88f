"""Trust in peers: Beta reputation per dimension, evidence, testimony fusion, epsilon.

For every peer b and dimension d in (safety, consistency, transparency) an agent holds a
Beta(alpha, beta) belief that "b behaves well", built from its own observations (the
Beta Reputation System, Josang & Ismail 2002):

    alpha <- prior_a + lambda^dt (alpha - prior_a) + s
    beta  <- prior_b + lambda^dt (beta - prior_b) + f           (forgetting towards the prior)
    tau   = (alpha + 1) / (alpha + beta + 2)                     (expected value)

with s, f in [0, 1] the graded success/failure of one piece of evidence. A detected
failure of transparency or safety weighs ``failure_weight`` times a success: a peer that
lies in 40 % of its messages is honest in 60 %, and a lie costs far more than a truth
earns. A consistency failure weighs ``consistency_failure_weight`` (1): cars replan, and
a changed mind is not a lie.

Testimonies (the paper's Bayesian consensus): every agent publishes its DIRECT evidence
only. A receiver a fuses a testimony of reporter r about peer b by discounting it with
its belief in r (Josang's discounting: the reporter's evidence is scaled by a's belief
mass in r, b_ar = alpha/(alpha + beta + 2) of r's weakest dimension) and adding it to its
own evidence (cumulative fusion). Defence against lying testimonies:
  * a reporter's word about itself or about the receiver is ignored;
  * discounting: a reporter we do not believe carries little weight;
  * deviation test (Buchegger & Le Boudec): once a holds enough direct evidence about b,
    a testimony whose expected value differs from a's own by more than
    ``testimony_deviation`` is rejected and counted.
Fused values are never re-published, so rumours cannot loop.

Overall trust in a peer is its weakest dimension, tau = min_d tau_d.

The transparency trust widens the safety distance (paper Sec. III.D, IV.C):

    eps_ab = eps_0 * g(tau_t),   g(tau) = 1 + (g_max - 1) * clip((tau_full - tau) / (tau_full - tau_floor), 0, 1)

so g(1) = 1, g is non-increasing and bounded by g_max.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

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
    failure = float(np.clip((error - tolerance) / tolerance, 0.0, 1.0))
    return 1.0 - failure, failure


def epsilon_gain(tau: float, config: TrustConfig) -> float:
    """g(tau): 1 for a trusted peer, up to epsilon_gain_max for an untrusted one."""
    span = config.tau_full - config.tau_floor
    lack = float(np.clip((config.tau_full - tau) / span, 0.0, 1.0))
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
    testimonies: dict[int, TrustReport] = field(default_factory=dict)
    counters: Counter = field(default_factory=Counter)

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

    def record(self, peer: int, dimension: int, success: float, failure: float, now: float) -> None:
        """Add one graded piece of direct evidence about ``peer`` at time ``now``."""
        if peer == self.owner:
            return
        opinion = self.opinion(peer, now)
        self._decay(opinion, now)
        weight = self.config.consistency_failure_weight if dimension == CONSISTENCY else self.config.failure_weight
        opinion.alpha[dimension] += success
        opinion.beta[dimension] += weight * failure
        self.counters[f"evidence_{DIMENSIONS[dimension]}"] += 1
        if failure > 0.5:
            self.counters[f"failures_{DIMENSIONS[dimension]}"] += 1

    # --- testimonies ---------------------------------------------------------------------

    def receive(self, report: TrustReport) -> None:
        if report.sender == self.owner:
            return
        self.testimonies[report.sender] = report
        self.counters["testimonies"] += 1

    def forget_reporter(self, reporter: int) -> None:
        self.testimonies.pop(reporter, None)

    def fused(self, peer: int, now: float) -> tuple[np.ndarray, np.ndarray]:
        """Own evidence plus discounted, deviation-tested testimonies about ``peer``."""
        own = self.opinion(peer, now)
        self._decay(own, now)
        alpha, beta = own.alpha.copy(), own.beta.copy()
        own_tau = own.tau()
        own_amount = (own.alpha - self.config.prior_alpha) + (own.beta - self.config.prior_beta)
        for reporter, report in self.testimonies.items():
            if reporter in (peer, self.owner) or peer not in report.peers:
                continue
            said = report.peers[peer]
            r_alpha, r_beta = np.array(said.alpha), np.array(said.beta)
            weight = self.discount(reporter, now)
            if weight <= 0.0:
                continue
            said_tau = expected(r_alpha + self.config.prior_alpha, r_beta + self.config.prior_beta)
            for d in range(3):
                if (own_amount[d] >= self.config.testimony_min_evidence
                        and abs(said_tau[d] - own_tau[d]) > self.config.testimony_deviation):
                    self.counters["testimonies_rejected"] += 1
                    continue
                alpha[d] += weight * r_alpha[d]
                beta[d] += weight * r_beta[d]
        return alpha, beta

    def discount(self, reporter: int, now: float) -> float:
        """Weight of a reporter's testimony: a's belief mass in r's weakest dimension."""
        opinion = self.opinion(reporter, now)
        self._decay(opinion, now)
        tau = opinion.tau()
        d = int(np.argmin(tau))
        return float(belief(opinion.alpha[d], opinion.beta[d]))

    # --- what the planner and the reports use ----------------------------------------------

    def tau(self, peer: int, now: float) -> np.ndarray:
        """Fused trust per dimension (safety, consistency, transparency)."""
        alpha, beta = self.fused(peer, now)
        return expected(alpha, beta)

    def trust(self, peer: int, now: float) -> float:
        """Overall trust: the weakest dimension."""
        return float(np.min(self.tau(peer, now)))

    def epsilon(self, peer: int, now: float, epsilon_0: float, transparency: bool) -> float:
        if not transparency:
            return epsilon_0 * self.config.epsilon_gain_fixed
        return epsilon_0 * epsilon_gain(float(self.tau(peer, now)[TRANSPARENCY]), self.config)

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

"""Testimony fusion where it matters: a car that sees only its neighbours (limited sight)
believes a peer out of its sight as the peer's witnesses say, and the rules that bound a
lying witness -- discounting, the deviation test, averaging, and "never less careful than
its own eyes" -- hold there. Pure: a TrustBook fed evidence and reports by hand."""

import dataclasses

import numpy as np
import pytest

from trustfg.agent.config import TrustConfig
from trustfg.agent.messages import PeerTrust, TrustReport
from trustfg.agent.trust import CONSISTENCY, SAFETY, TRANSPARENCY, TrustBook, expected

OWNER, PEER, WITNESS, OTHER = 2, 1, 3, 4
CONFIG = TrustConfig()
STRANGER = float(expected(CONFIG.prior_alpha, CONFIG.prior_beta))


def said(successes: float, failures: float) -> PeerTrust:
    """A testimony entry: the same evidence in every dimension."""
    tau = (successes + 1.0) / (successes + failures + 2.0)
    return PeerTrust((successes,) * 3, (failures,) * 3, (tau,) * 3, tau, 0.45)


def report(sender: int, stamp: float, about: dict[int, PeerTrust], seq: int = 1) -> TrustReport:
    return TrustReport(sender=sender, seq=seq, stamp=stamp, peers=about)


def book(limited: bool = True, config: TrustConfig = CONFIG) -> TrustBook:
    return TrustBook(owner=OWNER, config=config, limited_sight=limited)


def know_well(trust: TrustBook, car: int, until: float, failures_every: int = 0) -> None:
    """Ten seconds of seeing ``car`` behave (every tenth of a second a success in every
    dimension; with ``failures_every`` k, a transparency failure every k-th)."""
    for k, t in enumerate(np.arange(until - 10.0, until, 0.1)):
        for d in (SAFETY, CONSISTENCY, TRANSPARENCY):
            lie = d == TRANSPARENCY and failures_every and k % failures_every == 0
            trust.record(car, d, 0.0 if lie else 1.0, 1.0 if lie else 0.0, float(t))


def test_a_peer_the_car_has_not_seen_is_believed_as_its_trusted_witness_says():
    """A peer the car has never seen: a witness it trusts vouches for it, and the car's
    trust rises above a stranger's; with unlimited sight (every peer seen from the start)
    the same testimony cannot raise it."""
    for limited in (True, False):
        trust = book(limited)
        know_well(trust, WITNESS, until=10.0)
        trust.receive(report(WITNESS, 10.0, {PEER: said(30.0, 0.0)}), 10.0)
        tau = trust.tau(PEER, 10.0)
        if limited:
            assert np.all(tau > 0.9), tau
        else:
            np.testing.assert_allclose(tau, STRANGER)


def test_once_the_car_has_seen_enough_its_own_eyes_rule():
    """Testimonies stand in for own evidence only while that is thin (less than the
    deviation test needs): beyond it, praise cannot raise a peer above what the car saw."""
    trust = book()
    know_well(trust, WITNESS, until=10.0)
    for k in range(3):  # a few successes and one graded half-failure: worse than the witness says
        trust.record(PEER, TRANSPARENCY, 1.0, 0.0, 9.0 + 0.1 * k)
    trust.record(PEER, TRANSPARENCY, 0.5, 0.5, 9.4)
    trust.record(PEER, TRANSPARENCY, 1.0, 0.0, 9.5)
    trust.receive(report(WITNESS, 10.0, {PEER: said(30.0, 0.0)}), 10.0)
    fused = trust.tau(PEER, 10.0)[TRANSPARENCY]  # decays its own opinion to t = 10 first
    assert fused == pytest.approx(float(trust.opinion(PEER, 10.0).tau()[TRANSPARENCY]))
    assert fused < 0.8


def test_testimonies_off_leave_an_unseen_peer_a_stranger():
    trust = book(config=dataclasses.replace(CONFIG, testimonies=False))
    know_well(trust, WITNESS, until=10.0)
    trust.receive(report(WITNESS, 10.0, {PEER: said(30.0, 0.0)}), 10.0)
    assert not trust.testimonies
    np.testing.assert_allclose(trust.tau(PEER, 10.0), STRANGER)


def test_a_witness_that_has_not_seen_the_peer_does_not_dilute_one_that_has():
    """Averaging (dependent witnesses) counts a report of no evidence only with unlimited
    sight, where every car sees every peer; with limited sight it says nothing."""
    trust = book()
    know_well(trust, WITNESS, until=10.0)
    know_well(trust, OTHER, until=10.0)
    trust.receive(report(WITNESS, 10.0, {PEER: said(30.0, 0.0)}), 10.0)
    alone = trust.fused(PEER, 10.0)
    trust.receive(report(OTHER, 10.0, {PEER: said(0.0, 0.0)}), 10.0)
    np.testing.assert_allclose(trust.fused(PEER, 10.0), alone)


def test_witnesses_that_say_the_same_are_averaged_not_added():
    trust = book()
    know_well(trust, WITNESS, until=10.0)
    know_well(trust, OTHER, until=10.0)
    trust.receive(report(WITNESS, 10.0, {PEER: said(30.0, 0.0)}), 10.0)
    one = trust.fused(PEER, 10.0)
    trust.receive(report(OTHER, 10.0, {PEER: said(30.0, 0.0)}), 10.0)
    np.testing.assert_allclose(trust.fused(PEER, 10.0), one, rtol=1e-6)


def test_a_stranger_or_a_liar_counts_less_than_a_trusted_witness():
    """Discounting: a testimony weighs the car's belief mass in its reporter, so praise from
    a reporter seen lying, or never seen, moves an unseen peer far less than from a trusted one."""
    raised = {}
    for who in ("trusted", "stranger", "liar"):
        trust = book()
        if who != "stranger":
            know_well(trust, WITNESS, until=10.0, failures_every=2 if who == "liar" else 0)
        trust.receive(report(WITNESS, 10.0, {PEER: said(60.0, 0.0)}), 10.0)
        alpha, _ = trust.fused(PEER, 10.0)
        raised[who] = alpha[TRANSPARENCY] - CONFIG.prior_alpha
    assert raised["trusted"] > 2.5 * raised["stranger"] > 0
    assert raised["trusted"] > 3 * raised["liar"] > 0  # its belief mass: about a quarter


def test_praise_cannot_clear_a_liar_the_car_has_seen_lying():
    """The car saw the peer lie (its trust in it fell below a stranger's); the peer drives
    out of sight and a trusted witness (a colluder) praises it, report after report, for a
    minute: the car's trust in it never rises above what its own eyes say, however far
    forgetting has taken that."""
    trust = book()
    know_well(trust, WITNESS, until=10.0)
    know_well(trust, PEER, until=10.0, failures_every=3)
    assert trust.distrusted(PEER, 10.0)
    for k, t in enumerate(np.arange(10.0, 70.0, 0.5)):
        trust.receive(report(WITNESS, float(t), {PEER: said(60.0, 0.0)}, seq=k + 1), float(t))
        own = trust.opinion(PEER, float(t))
        assert trust.tau(PEER, float(t))[TRANSPARENCY] <= float(own.tau()[TRANSPARENCY]) + 1e-12
        assert trust.tau(PEER, float(t))[TRANSPARENCY] < STRANGER


def test_a_testimony_against_what_the_car_saw_itself_is_rejected():
    """The deviation test also for a peer out of sight: the car saw it honest for ten
    seconds a moment ago; slander that deviates from that is rejected and counted."""
    trust = book()
    know_well(trust, WITNESS, until=10.0)
    know_well(trust, PEER, until=10.0)
    own = trust.tau(PEER, 10.5)
    trust.receive(report(WITNESS, 10.5, {PEER: said(0.0, 60.0)}), 10.5)
    np.testing.assert_allclose(trust.tau(PEER, 10.5), own)
    assert trust.counters["testimonies_rejected"] == 1


def test_slander_lets_go_of_an_honest_car_soon_after_first_sight():
    """A slanderer the car trusts (its plans are true) says the unseen peer fails at
    everything; an honest witness says it does well. Out of sight the peer is held wide;
    once seen, the car's own evidence comes at the witness's rates (safety and
    transparency at once, consistency from 1.5 s: a window is judged a second after it
    ends) and within 3 s outweighs the slander: trust at least 0.8."""
    trust = book()
    know_well(trust, WITNESS, until=10.0)
    know_well(trust, OTHER, until=10.0)
    trust.receive(report(OTHER, 10.0, {PEER: said(0.0, 60.0)}), 10.0)
    trust.receive(report(WITNESS, 10.0, {PEER: said(30.0, 0.0)}), 10.0)
    assert trust.trust(PEER, 10.0) < 0.6
    # first sight at t = 10
    for k, t in enumerate(np.arange(10.0, 13.0 + 1e-9, 0.1)):
        t = float(t)
        trust.record(PEER, SAFETY, 1.0, 0.0, t)
        if k % 2 == 0:
            trust.record(PEER, TRANSPARENCY, 1.0, 0.0, t)
        if t - 10.0 >= 1.5:
            trust.record(PEER, CONSISTENCY, 1.0, 0.0, t)
        if k % 5 == 0:  # the reports go on every half second
            trust.receive(report(OTHER, t, {PEER: said(0.0, 60.0)}, seq=k + 2), t)
            trust.receive(report(WITNESS, t, {PEER: said(30.0, 0.0)}, seq=k + 2), t)
    assert trust.trust(PEER, 13.0) >= 0.8


@pytest.mark.parametrize("limited", [True, False])
def test_testimonies_never_make_a_seen_peer_less_careful(limited):
    trust = book(limited)
    know_well(trust, WITNESS, until=10.0)
    know_well(trust, PEER, until=10.0, failures_every=4)
    own = trust.tau(PEER, 10.0)
    trust.receive(report(WITNESS, 10.0, {PEER: said(60.0, 0.0)}), 10.0)
    assert np.all(trust.tau(PEER, 10.0) <= own + 1e-12)

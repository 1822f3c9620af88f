import numpy as np
import pytest

from trustfg.agent.attacks import Liar
from trustfg.agent.config import AttackConfig, TrustConfig
from trustfg.agent.messages import PeerTrust, TrustReport
from trustfg.agent.trust import TRANSPARENCY, TrustBook, epsilon_gain, expected, graded


def test_expected_value_of_beta():
    assert expected(np.array(0.0), np.array(0.0)) == 0.5
    assert expected(np.array(8.0), np.array(0.0)) == pytest.approx(0.9)


def test_graded_evidence():
    assert graded(0.0, 0.1) == (1.0, 0.0)
    assert graded(0.1, 0.1) == (1.0, 0.0)
    assert graded(0.15, 0.1) == pytest.approx((0.5, 0.5))
    assert graded(0.3, 0.1) == (0.0, 1.0)


def test_epsilon_gain_is_bounded_and_decreasing():
    config = TrustConfig()
    taus = np.linspace(0, 1, 101)
    gains = np.array([epsilon_gain(t, config) for t in taus])
    assert gains[-1] == 1.0
    assert np.all(np.diff(gains) <= 1e-12)
    assert gains.max() <= config.epsilon_gain_max
    assert epsilon_gain(0.45, config) == pytest.approx(config.epsilon_gain_max)


def test_forgetting_decays_towards_the_prior():
    config = TrustConfig()
    book = TrustBook(owner=1, config=config)
    for k in range(50):
        book.record(2, TRANSPARENCY, 0.0, 1.0, now=0.1 * k)
    low = book.tau(2, 5.0)[TRANSPARENCY]
    later = book.tau(2, 60.0)[TRANSPARENCY]
    prior = expected(np.array(config.prior_alpha), np.array(config.prior_beta))
    assert low < 0.1
    assert later == pytest.approx(prior, abs=0.02)


def simulate_evidence(p_lie, seconds, rng, rate_hz=5.0, config=None):
    """Transparency evidence as a receiver sees it: one check per plan message."""
    book = TrustBook(owner=2, config=config or TrustConfig())
    taus = []
    for k in range(int(seconds * rate_hz)):
        t = k / rate_hz
        lie = rng.random() < p_lie
        miss = rng.uniform(0.4, 0.8) if lie else abs(rng.normal(0, 0.02))
        s, f = graded(miss, book.config.transparency_tolerance_m)
        book.record(1, TRANSPARENCY, s, f, t)
        taus.append((t, book.tau(1, t)[TRANSPARENCY]))
    return np.array(taus)


def test_a_forty_percent_liar_is_separated_from_honest_peers_within_three_seconds():
    """Many seeds: trust in a 40 % liar ends up and stays 0.2 below an honest peer's."""
    failures = 0
    for seed in range(200):
        rng = np.random.default_rng(seed)
        liar = simulate_evidence(0.4, 20.0, rng)
        honest = simulate_evidence(0.0, 20.0, rng)
        after = liar[:, 0] >= 3.0
        failures += not np.all(liar[after, 1] <= honest[after, 1] - 0.2)
        assert np.all(honest[after, 1] > 0.8)
    assert failures <= 4  # <= 2 % of seeds, from binomial tails in the first seconds


def report(sender, peer, alpha, beta):
    return TrustReport(sender, 1, 0.0, {peer: PeerTrust((alpha,) * 3, (beta,) * 3, (0.5,) * 3, 0.5, 0.45)})


def trusted_book(owner=1, peers=(2, 3, 4), n=40):
    book = TrustBook(owner=owner, config=TrustConfig())
    for k in range(n):
        for peer in peers:
            for d in range(3):
                book.record(peer, d, 1.0, 0.0, 0.1 * k)
    return book


def test_testimony_is_discounted_by_trust_in_the_reporter():
    book = TrustBook(owner=1, config=TrustConfig())
    # We know nothing of 4 yet; 2 is trusted, 3 is not.
    for k in range(40):
        for d in range(3):
            book.record(2, d, 1.0, 0.0, 0.1 * k)
            book.record(3, d, 0.0, 1.0, 0.1 * k)
    now = 4.0
    book.receive(report(2, 4, 0.0, 20.0))
    from_trusted = book.tau(4, now)[0]
    book.receive(report(2, 4, 0.0, 0.0))
    book.receive(report(3, 4, 0.0, 20.0))
    from_distrusted = book.tau(4, now)[0]
    assert from_trusted < 0.3
    assert from_distrusted > from_trusted + 0.3


def test_lying_testimonies_do_not_sink_an_honest_peer():
    """A liar that slanders honest cars: deviation test + discounting keep them trusted."""
    book = trusted_book()
    # Make 3 the liar in our own eyes (transparency failures).
    for k in range(40):
        book.record(3, TRANSPARENCY, 0.0, 1.0, 4.0 + 0.1 * k)
    now = 8.0
    honest = TrustReport(2, 1, now, {4: PeerTrust((30.0,) * 3, (0.0,) * 3, (0.97,) * 3, 0.97, 0.45)})
    slander = Liar(3, AttackConfig("false-testimony"), np.random.default_rng(0)).testimony(honest)
    slander = TrustReport(3, 1, now, slander.peers)
    book.receive(slander)
    assert book.trust(4, now) > 0.8
    assert book.counters["testimonies_rejected"] > 0


def test_a_rejected_testimony_is_counted_once_however_often_it_is_fused():
    """A testimony is fused again at every read (each replan and report) until the
    reporter's next one: the counter counts testimonies, not reads."""
    book = trusted_book()
    for k in range(40):
        book.record(3, TRANSPARENCY, 0.0, 1.0, 4.0 + 0.1 * k)
    honest = TrustReport(2, 1, 8.0, {4: PeerTrust((30.0,) * 3, (0.0,) * 3, (0.97,) * 3, 0.97, 0.45)})
    slander = Liar(3, AttackConfig("false-testimony"), np.random.default_rng(0)).testimony(honest)
    book.receive(TrustReport(3, 1, 8.0, slander.peers))
    for k in range(20):  # twenty reads at twenty moments
        book.tau(4, 8.0 + 0.05 * k)
    assert book.counters["testimonies_rejected"] == 1
    book.receive(TrustReport(3, 2, 9.0, slander.peers))  # the slanderer's next report
    for k in range(5):
        book.epsilon(4, 9.0 + 0.05 * k, 0.45, transparency=True)
    assert book.counters["testimonies_rejected"] == 2


def test_self_testimony_and_testimony_about_the_receiver_are_ignored():
    book = trusted_book()
    before = book.tau(2, 4.0).copy()
    book.receive(report(2, 2, 100.0, 0.0))  # 2 praising itself
    book.receive(report(3, 1, 0.0, 100.0))  # 3 about us
    assert np.allclose(book.tau(2, 4.0), before)
    assert 1 not in book.direct


def cumulative_fusion(book, peer, now):
    """Cumulative fusion, the control: every accepted testimony's discounted evidence is
    added to our own (no cap, no averaging, no "only more careful") -- the defences removed."""
    c = book.config
    own = book.opinion(peer, now)
    book._decay(own, now)
    alpha, beta = own.alpha.copy(), own.beta.copy()
    own_amount = (own.alpha - c.prior_alpha) + (own.beta - c.prior_beta)
    for reporter, (report, _) in book.testimonies.items():
        if reporter in (peer, book.owner) or peer not in report.peers:
            continue
        r, s = np.array(report.peers[peer].alpha), np.array(report.peers[peer].beta)
        said = expected(r + c.prior_alpha, s + c.prior_beta)
        ok = ~((own_amount >= c.testimony_min_evidence) & (np.abs(said - own.tau()) > c.testimony_deviation))
        weight = book.discount(reporter, now)
        alpha, beta = alpha + np.where(ok, weight * r, 0.0), beta + np.where(ok, weight * s, 0.0)
    return alpha, beta


def saying(sender, peer, alpha, beta):
    return TrustReport(sender, 1, 4.0, {peer: PeerTrust((alpha,) * 3, (beta,) * 3, (0.5,) * 3, 0.5, 0.45)})


@pytest.mark.parametrize("fusion, holds", [(None, True), (cumulative_fusion, False)])
def test_the_same_evidence_is_not_counted_once_per_reporter(fusion, holds, monkeypatch):
    """Three reporters (trusted) shade an honest peer just inside the deviation test: 40
    successes and 15 failures each, where we saw only successes. Added up, three voices
    sink it below 0.8; averaged as the dependent evidence it is, it stays trusted."""
    if fusion is not None:
        monkeypatch.setattr(TrustBook, "_fuse", fusion)
    book = trusted_book(peers=(2, 3, 4, 5), n=40)
    for reporter in (2, 3, 4):
        book.receive(saying(reporter, 5, 40.0, 15.0), now=4.0)
    assert (book.trust(5, 4.0) > 0.8) == holds


@pytest.mark.parametrize("fusion, holds", [(None, True), (cumulative_fusion, False)])
def test_colluders_cannot_vouch_for_each_other(fusion, holds, monkeypatch):
    """Car 5 has just lied to us once (too little evidence for the deviation test); its
    partner 4, trusted so far, vouches for it with 60 successes. Praise may not raise trust."""
    if fusion is not None:
        monkeypatch.setattr(TrustBook, "_fuse", fusion)
    book = trusted_book(peers=(2, 3, 4), n=40)
    book.record(5, TRANSPARENCY, 0.0, 1.0, 4.0)
    before = book.trust(5, 4.0)
    book.receive(saying(4, 5, 60.0, 0.0), now=4.0)
    assert (book.trust(5, 4.0) <= before + 1e-9) == holds

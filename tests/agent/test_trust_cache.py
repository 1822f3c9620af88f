"""TrustBook.fused() keeps one fusion per (peer, now) until evidence or a testimony comes:
what it returns must be what a fresh fusion computes, whatever came in between."""

import copy

import numpy as np
import pytest

from trustfg.agent.config import TrustConfig
from trustfg.agent.messages import PeerTrust, TrustReport
from trustfg.agent.trust import TrustBook

PEERS = (2, 3, 4, 5, 6)


def said_by(rng, sender, now):
    """A report by ``sender`` about some peers, honest-looking or slanderous."""
    peers = {}
    for peer in rng.choice(PEERS, size=3, replace=False):
        alpha, beta = rng.uniform(0, 30, 3), rng.uniform(0, 30, 3)
        peers[int(peer)] = PeerTrust(tuple(alpha), tuple(beta), (0.5,) * 3, 0.5, 0.45)
    return TrustReport(sender, 1, now, peers)


def fresh(book, peer, now):
    """The fusion computed from scratch, on a copy (the cache plays no part)."""
    return copy.deepcopy(book)._fuse(peer, now)


def assert_fresh(book, peer, now):
    alpha, beta = book.fused(peer, now)
    want_alpha, want_beta = fresh(book, peer, now)
    np.testing.assert_allclose(alpha, want_alpha, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(beta, want_beta, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(4))
def test_cached_fusion_equals_a_fresh_one_through_evidence_testimony_and_forgetting(seed):
    rng = np.random.default_rng(seed)
    book = TrustBook(owner=1, config=TrustConfig())
    now = 0.0
    for _ in range(300):
        now += float(rng.choice([0.0, 0.05, 0.1]))  # several events often share one tick
        event = rng.integers(4)
        if event == 0:
            peer = int(rng.choice(PEERS))
            s = float(rng.random() < 0.7)
            book.record(peer, int(rng.integers(3)), s, 1.0 - s, now)
        elif event == 1:
            book.receive(said_by(rng, int(rng.choice(PEERS)), now), now)
        elif event == 2 and book.testimonies:
            book.forget_reporter(int(rng.choice(list(book.testimonies))))
        for peer in rng.choice(PEERS, size=2):
            assert_fresh(book, int(peer), now)
            assert_fresh(book, int(peer), now)  # the second read comes from the cache


def test_every_input_invalidates_the_cache():
    """Each input changes the fusion of a peer already read at this tick: a cache that
    did not forget would return the old value."""
    book = TrustBook(owner=1, config=TrustConfig())
    now = 1.0
    for k in range(20):
        for reporter in (3, 4):
            for d in range(3):
                book.record(reporter, d, 1.0, 0.0, 0.05 * k)
    book.fused(2, now)
    book.receive(TrustReport(3, 1, now, {2: PeerTrust((0.0,) * 3, (25.0,) * 3, (0.1,) * 3, 0.1, 0.5)}), now)
    slandered = book.fused(2, now)
    assert slandered[1][0] > 1.0  # the testimony counts
    assert_fresh(book, 2, now)
    book.record(2, 0, 1.0, 0.0, now)
    assert book.fused(2, now)[0][0] > slandered[0][0]
    assert_fresh(book, 2, now)
    book.forget_reporter(3)
    assert book.fused(2, now)[1][0] < slandered[1][0]
    assert_fresh(book, 2, now)


def test_the_cache_hands_out_copies():
    book = TrustBook(owner=1, config=TrustConfig())
    book.record(2, 0, 1.0, 0.0, 0.0)
    alpha, _ = book.fused(2, 0.0)
    alpha[:] = 99.0
    assert book.fused(2, 0.0)[0][0] < 99.0

"""The dashboard with a sensing range: who sees whom, from the poses and each car's range,
and whether a reported trust came from the reporter's own eyes or from testimonies."""

import dataclasses

from trustfg.agent import messages
from trustfg.agent.config import SensingConfig, TrustConfig
from trustfg.agent.trust import TrustBook
from trustfg.dashboard.state import FleetView, trust_source


def pose(car, t, x, y):
    return messages.PoseMessage(car, int(t * 100), t, x, y, 0.0, True)


def test_who_sees_whom(intersection):
    cars = (dataclasses.replace(intersection.cars[0], sensing_range_m=2.5), *intersection.cars[1:])
    view = FleetView(dataclasses.replace(intersection, cars=cars, sensing=SensingConfig(range_m=1.5)))
    for car, x in ((1, 0.0), (2, 1.0), (3, 2.0), (4, 5.0)):
        view.update(pose(car, 1.0, x, 0.0), 1.0)
    assert view.sight_now() == [[1, 2], [1, 3], [2, 1], [2, 3], [3, 2]]
    assert view.snapshot()["sight"] == view.sight_now()
    assert view.map()["sensing_range"] == {"1": 2.5, "2": 1.5, "3": 1.5, "4": 1.5}
    assert FleetView(intersection).snapshot()["sight"] is None  # no range: every car sees every peer


def test_trust_source_tells_own_eyes_from_testimonies():
    """A report's alpha and beta are the reporter's own evidence and its tau the fused
    trust: where they disagree, testimonies moved it."""
    config = TrustConfig()
    book = TrustBook(owner=2, config=config, limited_sight=True)
    for k in range(20):
        book.record(3, 2, 1.0, 0.0, 0.1 * k)  # car 2 sees car 3 tell the truth
    praise = messages.PeerTrust((30.0,) * 3, (0.0,) * 3, (0.97,) * 3, 0.97, 0.45)
    book.receive(messages.TrustReport(3, 1, 2.0, {1: praise}), 2.0)
    book.tau(1, 2.0)  # car 2 plans against car 1 (heard, never seen): it is in car 2's book
    report = book.report(2, 1, 2.0, lambda peer: 0.45, True)
    assert trust_source(report.peers[3], config) == "own"
    assert trust_source(report.peers[1], config) == "witnesses"
    book.receive(messages.TrustReport(3, 2, 2.0, {}), 2.0)  # car 3 takes it back: car 1 a stranger
    assert trust_source(book.report(2, 2, 2.0, lambda peer: 0.45, True).peers[1], config) == "none"

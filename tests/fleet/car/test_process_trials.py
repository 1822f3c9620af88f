"""A car process across trials (fleet.car.process): each start plans anew and keeps what
the car knew of its peers."""

import pytest

from trustfg.agent import messages
from trustfg.agent.trust import TRANSPARENCY
from trustfg.fleet.car.process import CarProcess
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys

pytestmark = pytest.mark.realtime


def test_a_new_trial_plans_anew_and_keeps_what_the_car_knew_of_its_peers(intersection, tmp_path):
    fleet = with_link_keys(loopback_fleet(intersection, None, None, 0.0), tmp_path / "keys")
    car, peer = fleet.cars[0], fleet.cars[1].id
    process = CarProcess(fleet, car, clock=lambda: 100.0)
    before = process.agent
    before.observe(99.5, peer, *fleet.cars[1].start, 0.0)
    for _ in range(6):  # a peer caught lying while the fleet waited for the go
        before.trust.record(peer, TRANSPARENCY, 0.0, 1.0, 99.5)
    caught = before.trust_in(peer, 100.0)
    assert caught < 0.5
    process._start(messages.StartMessage(1, 100.0, 1, {car.id: (101.0, 0.4)}))
    agent = process.agent
    assert agent is not before and agent.plan is None and agent.depart_at == 101.0  # a new plan
    assert agent.trust_in(peer, 100.0) == pytest.approx(caught)  # no stranger again
    assert agent.tracks[peer].motion() is not None  # nor unseen

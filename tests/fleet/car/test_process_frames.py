"""A car process's poses from NatNet (fleet.car.process): each is observed at the moment it
arrived, not at the pass of the main loop that takes it (the client is pulled: frames wait
in the socket until the loop comes round)."""

import time

import pytest

from trustfg.bridge.natnet import Frame, RigidBody
from trustfg.fleet.car.process import CarProcess
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys

pytestmark = pytest.mark.realtime


def test_a_frame_is_observed_at_its_arrival_on_the_fleet_clock(intersection, tmp_path):
    fleet = with_link_keys(loopback_fleet(intersection, None, None, 0.0), tmp_path / "keys")
    car, peer = fleet.cars[0], fleet.cars[1]
    process = CarProcess(fleet, car, clock=lambda: 100.0)
    body = RigidBody(peer.body_id, (1.0, 0.0, -2.0), (0.0, 0.0, 0.0, 1.0))  # Motive's Y up
    process._on_frame(Frame(7, (body,), 0.0), time.monotonic() - 0.25)  # arrived 0.25 s ago
    process._observe_frames()
    samples = process.agent.tracks[peer.id].samples
    assert len(samples) == 1
    assert samples[0][0] == pytest.approx(99.75, abs=0.02)  # the fleet clock then, not now (100.0)

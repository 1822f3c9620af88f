"""A car process with a sensing range (fleet.car.process): of each NatNet frame its mind
gets its own pose and the peers within the range of it, and a frame without its own pose
is judged from where it last saw itself."""

import dataclasses
import time

import pytest

from trustfg.agent.config import SensingConfig
from trustfg.bridge import natnet
from trustfg.bridge.natnet import Frame, RigidBody
from trustfg.fleet.car.process import CarProcess
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys

pytestmark = pytest.mark.realtime


def body(car, x, y):
    position, orientation = natnet.from_ground_plane(x, y, 0.0, 0.05)
    return RigidBody(car.body_id, position, orientation)


def test_the_mind_gets_the_peers_within_range_only(intersection, tmp_path):
    limited = dataclasses.replace(intersection, sensing=SensingConfig(range_m=1.5))
    fleet = with_link_keys(loopback_fleet(limited, None, None, 0.0), tmp_path / "keys")
    me, near, far, other = fleet.cars
    process = CarProcess(fleet, me, clock=lambda: 100.0)
    frame = Frame(7, (body(me, 0.0, 0.0), body(near, 1.2, 0.5), body(far, 2.0, 0.5)), 0.0)
    process._on_frame(frame, time.monotonic())
    process._observe_frames()
    assert set(process.agent.tracks) == {me.id, near.id}
    # Its own body missing from the next frame: the range is taken from where it last was.
    process._on_frame(Frame(8, (body(far, 1.0, 0.0), body(other, 1.6, 0.0)), 0.0), time.monotonic())
    process._observe_frames()
    assert set(process.agent.tracks) == {me.id, near.id, far.id}

"""The velocity loop's guard with a sensing range (fleet.car.velocity_loop): of the cars
the motion capture streams, it brakes for those within the car's range only -- what its
mind sees too -- read from a real NatNet server."""

import dataclasses
import math
import time

import pytest

from tests.conftest import wait_for
from trustfg.agent.config import SensingConfig
from trustfg.agent.world import build_sdf
from trustfg.bridge import natnet
from trustfg.bridge.natnet_client import NatNetClient, client_options
from trustfg.fleet.car.velocity_loop import VelocityLoop
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.mocap_sim.natnet_server import NatNetServer, NatNetServerOptions

pytestmark = pytest.mark.realtime

WHERE = {1: (0.0, 0.0), 2: (1.2, 0.5), 3: (2.0, 0.5), 4: (-1.0, 1.0)}


@pytest.mark.parametrize("range_m", [None, 1.5])
def test_the_guard_sees_the_cars_within_range(intersection, range_m):
    fleet = loopback_fleet(dataclasses.replace(intersection, sensing=SensingConfig(range_m=range_m)), None, None, 0.0)
    cars = {car.id: car for car in fleet.cars}

    def bodies(t):
        for car_id, (x, y) in WHERE.items():
            position, orientation = natnet.from_ground_plane(x, y, 0.0, 0.05)
            yield cars[car_id].body_id, f"car{car_id}", position, orientation, True

    options = NatNetServerOptions(address="127.0.0.1", command_port=fleet.natnet.command_port, multicast=False,
                                  data_port=0, natnet_version=natnet.V3_1)
    client_settings = dataclasses.replace(client_options(fleet.natnet), decode_on_read=True, pull=True)
    with NatNetServer(options, bodies), NatNetClient(client_settings) as client:
        loop = VelocityLoop(fleet, cars[1], report=[0.0] * 64, clock=time.time, sdf=build_sdf(fleet.world),
                            natnet=client)
        assert wait_for(lambda: loop.own_pose() is not None and len(client.latest_all()) == 4, 5.0)
        seen = sorted((round(x, 2), round(y, 2)) for x, y, *_ in loop.others_seen())
    expected = [WHERE[c] for c in (2, 3, 4) if range_m is None or math.dist(WHERE[c], WHERE[1]) <= range_m]
    assert seen == sorted(expected)

"""The command loop in a process of its own (fleet.car.velocity_loop): the lease rule, and the
spawned loop against a real NatNet server and a real car link (the authenticated link,
version 2, with a key made for the test)."""

import dataclasses
import math
import threading
import time

import numpy as np
import pytest

from tests.conftest import wait_for
from trustfg.agent.gp import Plan
from trustfg.agent.world import build_sdf
from trustfg.bridge import natnet
from trustfg.bridge.carlink import CommandReceiver, link_key
from trustfg.fleet.car.velocity_handle import VelocityLoopHandle
from trustfg.fleet.car.velocity_loop import Permit, allowed
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys
from trustfg.mocap_sim.natnet_server import NatNetServer, NatNetServerOptions

pytestmark = pytest.mark.realtime

LEASE_S = 0.3


@pytest.mark.parametrize("e_stop", [False, True])
@pytest.mark.parametrize("release", [False, True])
def test_a_lapsed_permit_allows_nothing_but_stopping_and_keeps_an_e_stop(e_stop, release):
    permit = Permit(may_drive=True, e_stop=e_stop, release=release, valid_until=10.0)
    fresh, old = allowed(permit, 9.9), allowed(permit, 10.1)
    assert fresh.go == (not e_stop) and not fresh.lapsed
    assert fresh.release == (release and not e_stop)
    assert old.lapsed and not old.go and not old.release  # never drive, never RELEASE on an old word
    assert old.e_stop == e_stop == fresh.e_stop  # an e-stop outlives its permit


def test_at_the_goal_or_before_any_permit_the_car_does_not_drive():
    assert not allowed(Permit(may_drive=True, at_goal=True, valid_until=math.inf), 0.0).go
    assert not allowed(Permit(), 0.0).go


@pytest.fixture
def one_car(intersection, tmp_path):
    fleet = loopback_fleet(dataclasses.replace(intersection, cars=intersection.cars[:1]), None, None, 0.0)
    fleet = with_link_keys(fleet, tmp_path / "keys")
    control = dataclasses.replace(fleet.control, lease_s=LEASE_S, realtime_priority=0)
    return dataclasses.replace(fleet, control=control)


def northwards(car, now: float) -> Plan:
    """A plan from the car's start north at 0.3 m/s (the car is served facing north)."""
    times = np.arange(41) * 0.25
    positions = np.column_stack([np.full(41, car.start[0]), car.start[1] + 0.3 * times])
    return Plan(now, 0.25, positions, np.tile([0.0, 0.3], (41, 1)))


@pytest.fixture
def loop_and_car(one_car):
    """A spawned command loop for car 1, its car's link played by the test, and Motive
    serving the car standing at its start facing north."""
    car = one_car.cars[0]

    def bodies(t):
        position, orientation = natnet.from_ground_plane(car.start[0], car.start[1], math.pi / 2, 0.05)
        yield car.body_id, "car", position, orientation, True

    options = NatNetServerOptions(address="127.0.0.1", command_port=one_car.natnet.command_port, multicast=False,
                                  data_port=0, natnet_version=natnet.V3_1)
    host, port = car.link[len("udp://"):].rsplit(":", 1)
    command = VelocityLoopHandle(one_car, car, build_sdf(one_car.world))
    with NatNetServer(options, bodies), CommandReceiver(car.id, (host, int(port)), key=link_key(car)) as link:
        command.start()
        try:
            yield command, link, car
        finally:
            command.close()


class Agent:
    """The car process's side, played by the test: grants a permit every 20 ms until paused."""

    def __init__(self, command: VelocityLoopHandle, **permit):
        self.command, self.permit = command, permit
        self.running, self.stop = threading.Event(), threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self):
        while not self.stop.wait(0.02):
            if self.running.is_set():
                self.command.grant(**self.permit)

    def __enter__(self):
        self.running.set()
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join()


DRIVE = dict(may_drive=True, at_goal=False, e_stop=False, release=False, trial=1, turn=(0.0, -math.inf))


def driving(link) -> bool:
    command = link.last_command
    return command is not None and not command.stop and command.v_mps > 0.05


def test_the_loop_drives_on_a_permit_and_stops_the_car_when_the_agent_stops_renewing_it(loop_and_car):
    command, link, car = loop_and_car
    assert link.wait_until(lambda c: c.accepted >= 10, 20.0)  # STOP from its first ticks, before any permit
    assert link.last_command.stop
    command.send_plan(northwards(car, time.time()))
    with Agent(command, **DRIVE) as agent:
        assert wait_for(lambda: driving(link), 10.0)
        assert command.report().lease_lapsed == 0
        agent.running.clear()  # the agent hangs: no more permits
        paused = time.monotonic()
        assert wait_for(lambda: link.last_command.stop, LEASE_S + 2.0)
        assert time.monotonic() - paused >= LEASE_S * 0.5  # the lease, not the first missed renewal
        assert wait_for(lambda: command.report().lease_lapsed > 5, 2.0)
        agent.running.set()  # the agent is back: a fresh permit, the car drives on
        assert wait_for(lambda: driving(link), 5.0)
    command.close()
    assert command.final["lease_lapsed"] > 5 and command.final["sent"] >= command.final["lease_lapsed"]


def test_an_e_stop_outlives_the_permit_that_carried_it(loop_and_car):
    command, link, car = loop_and_car
    command.send_plan(northwards(car, time.time()))
    with Agent(command, **DRIVE):
        assert wait_for(lambda: driving(link), 20.0)
    command.grant(**(DRIVE | {"e_stop": True}))  # one permit with the e-stop, then silence
    assert wait_for(lambda: command.report().lease_lapsed > 10, LEASE_S + 3.0)
    lapsed_e_stops = link.counters.e_stops
    assert wait_for(lambda: link.counters.e_stops > lapsed_e_stops + 10, 2.0)  # E_STOP in every datagram still
    assert link.active_command() == (0.0, 0.0)


def test_the_loop_stops_the_car_and_exits_when_its_car_process_is_gone(loop_and_car):
    command, link, car = loop_and_car
    command.send_plan(northwards(car, time.time()))
    with Agent(command, **DRIVE):
        assert wait_for(lambda: driving(link), 20.0)
    command._conn.close()  # what the loop sees when the car process dies: its pipe closes
    assert wait_for(lambda: not command.alive(), 3.0)
    assert link.last_command.stop

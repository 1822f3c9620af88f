"""One car process against a NatNet server and a car link played by the test (the
authenticated link, version 2, with a key made for the test)."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from tests.conftest import wait_for
from trustfg.agent import messages
from trustfg.agent.scenario_files import dump_scenario
from trustfg.bridge import natnet
from trustfg.bridge.carlink import CommandReceiver, link_key, new_key
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys
from trustfg.fleet.launch.ports import free_port
from trustfg.mocap_sim.natnet_server import NatNetServer, NatNetServerOptions

pytestmark = pytest.mark.realtime


@pytest.fixture
def one_car(intersection, tmp_path):
    fleet = loopback_fleet(dataclasses.replace(intersection, cars=intersection.cars[:1]), None, None, 0.0)
    fleet = with_link_keys(fleet, tmp_path / "keys")
    path = tmp_path / "fleet.toml"
    path.write_text(dump_scenario(fleet))
    return fleet, path


def served(car, tracked):
    def bodies(t):
        position, orientation = natnet.from_ground_plane(car.start[0], car.start[1], 1.5708, 0.05)
        yield car.body_id, "car", position, orientation, tracked()
    return bodies


def test_car_process_stops_without_pose_drives_after_start_and_stops_on_sigterm(one_car, tmp_path):
    fleet, path = one_car
    car = fleet.cars[0]
    tracked = {"on": True}
    options = NatNetServerOptions(address="127.0.0.1", command_port=fleet.natnet.command_port, multicast=False,
                                  data_port=0, natnet_version=natnet.V3_1)
    host, port = car.link[len("udp://"):].rsplit(":", 1)
    stats = tmp_path / "stats.json"
    observer = f"tcp/127.0.0.1:{free_port()}"
    with NatNetServer(options, served(car, lambda: tracked["on"])), \
            CommandReceiver(car.id, (host, int(port)), key=link_key(car)) as link, \
            FleetBus(fleet.bus, fleet.fleet, None, listen=(observer,)) as bus:
        process = subprocess.Popen([sys.executable, "-m", "trustfg", "car", "--id", str(car.id), "--config",
                                    str(path), "--stats", str(stats)], stderr=subprocess.PIPE, text=True)
        try:
            # Before the start: commands flow, and they are STOP.
            assert link.wait_until(lambda c: c.accepted >= 20, 20.0), process.stderr
            assert link.last_command.stop
            assert wait_for(lambda: bus.alive.get(car.id), 10.0)
            # After the start it drives: a non-zero speed command.
            go = messages.StartMessage(1, time.time(), 1, {car.id: (time.time() + 0.2, 0.4)})
            bus.publish("start", messages.encode(go))
            assert wait_for(lambda: link.last_command and link.last_command.v_mps > 0.05, 10.0)
            # Its own pose lost (tracking invalid): it commands STOP within the pose timeout.
            tracked["on"] = False
            assert wait_for(lambda: link.last_command.stop, 1.0)
            lost_at = time.monotonic()
            assert wait_for(lambda: link.last_command.stop, 0.1)
            tracked["on"] = True
            assert wait_for(lambda: not link.last_command.stop, 2.0)
            assert time.monotonic() - lost_at < 2.5
            # SIGTERM: it stops the car and exits cleanly, quickly.
            process.send_signal(signal.SIGTERM)
            assert process.wait(timeout=5) == 0
            assert link.last_command.stop
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
            process.stderr.close()
    summary = json.loads(stats.read_text())
    assert summary["control"]["stale_pose_stops"] > 0
    assert summary["control"]["sent"] > 20 and summary["control"]["rate_hz"] > 25  # 50 Hz from its first moment (loaded: fewer)
    assert summary["agent"].get("plans_first", 0) > 0  # its replans were verified (agent.safe_plan)


def test_a_car_with_another_key_hears_nothing_from_the_car_process(one_car, tmp_path):
    """The mechanism: the car process's datagrams verify only with the car's own key."""
    fleet, path = one_car
    car = fleet.cars[0]
    options = NatNetServerOptions(address="127.0.0.1", command_port=fleet.natnet.command_port, multicast=False,
                                  data_port=0, natnet_version=natnet.V3_1)
    host, port = car.link[len("udp://"):].rsplit(":", 1)
    with NatNetServer(options, served(car, lambda: True)), \
            CommandReceiver(car.id, (host, int(port)), key=new_key()) as link:
        process = subprocess.Popen([sys.executable, "-m", "trustfg", "car", "--id", str(car.id), "--config",
                                    str(path)], stderr=subprocess.PIPE, text=True)
        try:
            assert link.wait_until(lambda c: c.decode_errors.get("mac", 0) >= 20, 20.0), process.stderr
            assert link.counters.accepted == 0 and link.last_command is None
        finally:
            process.send_signal(signal.SIGTERM)
            try:
                process.wait(timeout=5)
            finally:
                if process.poll() is None:
                    process.kill()
                    process.wait()
                process.stderr.close()


def command_loop(pid: int) -> int:
    """The pid of a car process's command loop (its spawned child, not multiprocessing's
    resource tracker)."""
    for child in open(f"/proc/{pid}/task/{pid}/children").read().split():
        if b"resource_tracker" not in open(f"/proc/{child}/cmdline", "rb").read():
            return int(child)
    raise AssertionError(f"car process {pid} has no command loop")


def alive(pid: int) -> bool:
    try:
        return open(f"/proc/{pid}/stat").read().split(")")[-1].split()[0] not in ("Z", "X")
    except OSError:
        return False


def test_a_frozen_car_process_stops_its_car_and_a_killed_one_leaves_it_stopped(one_car, tmp_path):
    """The layer under the agent (fleet.car.velocity_loop): with the car process frozen
    (SIGSTOP: a hung agent) its command loop stops the car once the lease runs out, and
    drives on when the agent comes back; with the car process killed (SIGKILL) the loop
    stops the car and exits."""
    fleet, path = one_car
    car = fleet.cars[0]
    options = NatNetServerOptions(address="127.0.0.1", command_port=fleet.natnet.command_port, multicast=False,
                                  data_port=0, natnet_version=natnet.V3_1)
    host, port = car.link[len("udp://"):].rsplit(":", 1)
    observer = f"tcp/127.0.0.1:{free_port()}"
    with NatNetServer(options, served(car, lambda: True)), \
            CommandReceiver(car.id, (host, int(port)), key=link_key(car)) as link, \
            FleetBus(fleet.bus, fleet.fleet, None, listen=(observer,)) as bus:
        process = subprocess.Popen([sys.executable, "-m", "trustfg", "car", "--id", str(car.id), "--config",
                                    str(path)], stderr=subprocess.DEVNULL)
        loop = None
        try:
            assert wait_for(lambda: bus.alive.get(car.id), 20.0)
            go = messages.StartMessage(1, time.time(), 1, {car.id: (time.time() + 0.2, 0.4)})
            bus.publish("start", messages.encode(go))
            assert wait_for(lambda: link.last_command and link.last_command.v_mps > 0.05, 10.0)
            loop = command_loop(process.pid)
            process.send_signal(signal.SIGSTOP)  # the agent hangs; its command loop does not
            frozen = time.monotonic()
            assert wait_for(lambda: link.last_command.stop, fleet.control.lease_s + 3.0)
            assert time.monotonic() - frozen >= 0.5 * fleet.control.lease_s  # the lease ran out, not the loop
            process.send_signal(signal.SIGCONT)
            assert wait_for(lambda: link.last_command.v_mps > 0.05, 5.0)  # a fresh permit: it drives on
            process.kill()
            process.wait()
            assert wait_for(lambda: not alive(loop), 3.0)
            assert link.last_command.stop
        finally:
            if process.poll() is None:
                process.send_signal(signal.SIGCONT)
                process.kill()
                process.wait()
            if loop is not None and alive(loop):
                os.kill(loop, signal.SIGKILL)

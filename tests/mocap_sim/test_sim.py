"""mocap-sim as a process: its NatNet stream, for every version, and its cars' link."""

import contextlib
import csv
import dataclasses
import subprocess
import sys
import threading
import time

import pytest

from tests.conftest import wait_for
from trustfg.agent.scenario_files import dump_scenario
from trustfg.bridge import natnet
from trustfg.bridge.carlink import CommandSender
from trustfg.bridge.natnet_client import NatNetClient, NatNetClientOptions
from trustfg.fleet.car.ticker import ticks
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys

pytestmark = pytest.mark.realtime


@pytest.fixture
def two_cars(intersection, tmp_path):
    fleet = loopback_fleet(dataclasses.replace(intersection, cars=intersection.cars[:2]), None, None, 0.0)
    fleet = with_link_keys(fleet, tmp_path / "keys")
    path = tmp_path / "fleet.toml"
    path.write_text(dump_scenario(fleet))
    return fleet, path


def start_mocap(path, truth, *extra):
    process = subprocess.Popen([sys.executable, "-m", "trustfg", "mocap-sim", "--config", str(path),
                                "--ground-truth", str(truth), *extra],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    ports = process.stdout.readline()
    assert ports.startswith("mocap-sim: NatNet on "), process.stderr.read()  # the ports it bound
    line = process.stdout.readline()
    assert line.strip() == "READY", process.stderr.read()
    return process


def stop(process):
    process.terminate()
    try:
        assert process.wait(timeout=5) == 0
    finally:
        if process.poll() is None:
            process.kill()
        process.stdout.close()
        process.stderr.close()


@contextlib.contextmanager
def streaming(sender, v_mps, omega_radps, rate_hz=50.0):
    """Send one command at ``rate_hz`` from a thread, as a car process's control loop does."""
    halt = threading.Event()

    def loop():
        for _ in ticks(1.0 / rate_hz, halt):
            sender.send(v_mps, omega_radps)

    thread = threading.Thread(target=loop, name="test-command-stream", daemon=True)
    thread.start()
    try:
        yield
    finally:
        halt.set()
        thread.join(2.0)
        assert not thread.is_alive()


def truth_rows(path, car_id):
    with open(path, newline="") as f:
        return [row for row in csv.DictReader(f) if int(row["car_id"]) == car_id]


@pytest.mark.parametrize("version", list(natnet.STREAM_VERSIONS))
def test_bridge_reads_mocap_sim_poses_in_every_natnet_version(two_cars, tmp_path, version):
    fleet, path = two_cars
    process = start_mocap(path, tmp_path / "truth.csv", "--natnet-version", version)
    try:
        options = NatNetClientOptions(server_address="127.0.0.1", command_port=fleet.natnet.command_port,
                                      multicast=False, local_address="127.0.0.1")
        with NatNetClient(options) as client:
            assert client.version == natnet.Version(*map(int, version.split(".")))
            assert client.wait_for_frames(30, timeout_s=5.0)
            for car in fleet.cars:
                sample = client.latest(car.body_id)
                x, y, _ = natnet.to_ground_plane(sample.body.position, sample.body.orientation, "y")
                assert (x, y) == pytest.approx(car.start, abs=1e-4)
                assert sample.body.tracking_valid
    finally:
        stop(process)


def test_a_mocap_sim_car_obeys_commands_and_stops_by_itself(two_cars, tmp_path):
    fleet, path = two_cars
    truth = tmp_path / "truth.csv"
    process = start_mocap(path, truth)
    car = fleet.cars[0]
    host, port = car.link[len("udp://"):].rsplit(":", 1)
    try:
        with CommandSender.for_car(car) as sender:
            with streaming(sender, 0.3, 0.0):
                assert wait_for(lambda: (rows := truth_rows(truth, car.id)) and float(rows[-1]["v"]) > 0.29, 5.0)
            silent_from = time.time()
            sender.stop()
        # The STOP datagrams or, failing them, the 250 ms watchdog bring it to rest.
        assert wait_for(lambda: float(truth_rows(truth, car.id)[-1]["v"]) == 0.0, 3.0)
        stopped = next(float(r["t"]) for r in truth_rows(truth, car.id)
                       if float(r["t"]) > silent_from and float(r["v"]) == 0.0)
        assert stopped - silent_from < 0.25 + 0.3 / 1.5 + 0.1  # command gap + braking + one log step
        # The other car never moved.
        assert all(float(r["v"]) == 0.0 for r in truth_rows(truth, fleet.cars[1].id))
    finally:
        stop(process)

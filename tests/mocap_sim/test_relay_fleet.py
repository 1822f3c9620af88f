"""A mixed fleet on loopback: the relay against a real NatNet server, then four car
processes of which car 1 is "real" -- tracked and driven by a mocap-sim that stands in for
Motive and car 1 alone -- while a relaying mocap-sim simulates cars 2-4 and serves the
merged stream every car process and the dashboard read."""

from __future__ import annotations

import csv
import dataclasses
import json
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import wait_for
from trustfg.agent import messages, metrics
from trustfg.agent.config import ConfigError, NatNetConfig
from trustfg.agent.scenario_files import dump_scenario
from trustfg.bridge import natnet
from trustfg.bridge.natnet_client import NatNetClient, NatNetClientOptions, fresh_pose
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.launch.launcher import departures
from trustfg.fleet.launch.ports import free_port
from trustfg.fleet.launch.processes import wait_ready
from trustfg.fleet.launch.testbed import LoopbackFleet
from trustfg.mocap_sim.natnet_server import NatNetServer, NatNetServerOptions
from trustfg.mocap_sim.relay import Relay, RelayOptions, served_version

pytestmark = pytest.mark.realtime

UDP = socket.SOCK_DGRAM
P1, Q1 = tuple(float(v) for v in np.float32((0.4123, 0.0517, 2.1377))), (0.0, 0.0, 0.0, 1.0)


def mixed(scenario):
    """The scenario with car 1 real."""
    return dataclasses.replace(scenario, cars=(dataclasses.replace(scenario.cars[0], simulated=False),
                                               *scenario.cars[1:]))


# --- the relay against a NatNet server ---------------------------------------------------


def motive(bodies, **options) -> NatNetServer:
    """A NatNet server standing for Motive on loopback, NatNet 4.2 (Motive 3.2 and later)."""
    return NatNetServer(NatNetServerOptions(**({"natnet_version": natnet.V4_2, "address": "127.0.0.1",
                                               "command_port": 0, "multicast": False} | options)), bodies)


def upstream_of(server: NatNetServer) -> NatNetConfig:
    """The lab config's [natnet] for that server."""
    (host, port), o = server.command_address, server.options
    return NatNetConfig(server=host, command_port=port, mode="multicast" if o.multicast else "unicast",
                        multicast_group=o.multicast_group, data_port=o.data_port, local_interface="127.0.0.1")


def merged_stream(relay: Relay, simulated) -> NatNetServer:
    return NatNetServer(NatNetServerOptions(natnet_version=served_version(relay.upstream_version), address="127.0.0.1",
                                            command_port=0, multicast=False), relay.source(simulated))


def reader(server: NatNetServer) -> NatNetClient:
    """A client set up as a car process sets up its own."""
    host, port = server.command_address
    return NatNetClient(NatNetClientOptions(server_address=host, command_port=port, multicast=False,
                                            local_address="127.0.0.1", pull=True))


def car2(t):
    return [(2, "car2", (-0.4, 0.05, -2.15), (0.0, 0.0, 0.0, 1.0), True)]


@pytest.mark.parametrize("multicast", [False, True], ids=["unicast", "multicast"])
def test_the_relay_passes_motives_poses_and_marks_them_stale_when_motive_stops(intersection, multicast, request):
    options = {}
    if multicast:
        group, port = request.getfixturevalue("multicast_group")
        options = {"multicast": True, "multicast_group": group, "data_port": port}
    upstream = motive(lambda t: [(1, "Car One", P1, Q1, True)], **options)
    with upstream:
        with Relay(RelayOptions(upstream_of(upstream)), mixed(intersection)) as relay, \
                merged_stream(relay, car2) as merged, reader(merged) as car:
            assert car.server_info.natnet_version == natnet.V4_2  # the handshake a car process gets from Motive
            assert car.wait_for_frames(20, 5.0)
            real = car.latest(1).body
            assert (real.position, real.orientation, real.tracking_valid) == (P1, Q1, True)
            assert car.body_ids() == {"Car One": 1, "car2": 2}  # MODELDEF: Motive's name for its body
            upstream.close()  # Motive stops streaming
            assert wait_for(lambda: not car.latest(1).body.tracking_valid, 2.0)
            assert car.latest(1).body.position == P1  # its last pose, flagged untracked
            assert fresh_pose(car, 1, max_age_s=0.2) is None  # so the car's process stops it
            frames = car.stats().decoded
            assert car.wait_for_frames(frames + 20, 2.0)  # the merged stream goes on
            assert car.latest(2).body.tracking_valid and fresh_pose(car, 2, max_age_s=0.2) is not None


def test_the_relay_refuses_a_simulated_car_whose_rigid_body_motive_streams(intersection):
    with motive(lambda t: [(1, "car1", P1, Q1, True), (3, "car3", P1, Q1, False)]) as upstream:
        relay = Relay(RelayOptions(upstream_of(upstream)), mixed(intersection))
        with pytest.raises(ConfigError, match=r"cars \[3\] are simulated, but their rigid bodies \[3\]"):
            relay.__enter__()


# --- four car processes, car 1 real --------------------------------------------------------


def start_mocap(fleet: LoopbackFleet, name: str, *args: str) -> None:
    process = fleet.processes.start(name, ["mocap-sim", *args], fleet.out / f"{name}.log", stdout=subprocess.PIPE)
    wait_ready(process, threading.Event())


def ground_truth(path: Path) -> dict[int, np.ndarray]:
    """Per car, rows (t, x, y) of a mocap-sim's ground truth."""
    rows: dict[int, list] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            rows.setdefault(int(row["car_id"]), []).append((float(row["t"]), float(row["x"]), float(row["y"])))
    return {car: np.array(r) for car, r in rows.items()}


def snapshot(port: int) -> dict:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/snapshot", timeout=2.0) as response:
        return json.loads(response.read())


class TrustWatch:
    """An observer on the bus: the latest trust report of each car."""

    def __init__(self, fleet: LoopbackFleet):
        self.bus = FleetBus(fleet.fleet.bus, fleet.fleet.fleet, None, listen=(f"tcp/127.0.0.1:{free_port()}",),
                            kinds=("trust",), operator_kinds=())
        self.inbox = messages.Inbox()
        self.reports: dict[int, messages.TrustReport] = {}

    def poll(self) -> None:
        for received in self.bus.drain():
            message = self.inbox.accept(received.payload, key_sender=received.sender)
            if isinstance(message, messages.TrustReport):
                self.reports[message.sender] = message


@pytest.fixture(scope="module")
def run(intersection, tmp_path_factory):
    """Motive and car 1 (a mocap-sim of car 1 alone), the relaying mocap-sim of cars 2-4,
    four car processes, the dashboard, and the test as the operator: one trial, driven to
    the end; then Motive stops."""
    out = tmp_path_factory.mktemp("mixed")
    with LoopbackFleet(mixed(intersection), out, cars_first=()) as fleet:
        lab = fleet.fleet  # what the car processes read: the merged stream, car 1 real
        stand_in = dataclasses.replace(lab, name="motive", cars=(dataclasses.replace(lab.cars[0], simulated=True),),
                                       natnet=dataclasses.replace(lab.natnet, command_port=free_port(UDP),
                                                                  data_port=free_port(UDP)))
        (out / "motive.toml").write_text(dump_scenario(stand_in))
        start_mocap(fleet, "motive", "--config", str(out / "motive.toml"), "--natnet-version", "4.2",
                    "--ground-truth", str(out / "truth_motive.csv"))
        refused = refused_clash(lab, out)
        start_mocap(fleet, "mocap-sim", "--config", str(fleet.config), "--relay", str(out / "motive.toml"),
                    "--ground-truth", str(out / "truth_sim.csv"))
        dashboard = free_port()
        fleet.processes.start("dashboard", ["dashboard", "--config", str(fleet.config), "--port", str(dashboard),
                                            "--listen", f"tcp/127.0.0.1:{free_port()}"], out / "dashboard.log")
        fleet.start_cars()
        watch = TrustWatch(fleet)
        with watch.bus:
            assert fleet.wait_states({"waiting"}, timeout_s=60.0), fleet.states()
            t_go = time.time() + max(1.0, lab.sim.settle_s)
            fleet.session.start(departures(lab, seed=5, t_go=t_go))
            deadline = time.monotonic() + 45.0
            while time.monotonic() < deadline and set(fleet.states().values()) != {"arrived"}:
                watch.poll()
                time.sleep(0.05)
            states = fleet.states()
            watch.poll()
            # The dashboard hears the same statuses over its own session: give it a moment.
            wait_for(lambda: all(car["pose"]["valid"] and car["state"] == "arrived"
                                 for car in snapshot(dashboard)["cars"]), 5.0)
            seen = snapshot(dashboard)
            fleet.processes.stop(["motive"])  # Motive (and car 1 with it) goes quiet
            lost = wait_for(lambda: any(a["kind"] == "lost_pose" and a["cars"] == [1]
                                        for a in snapshot(dashboard)["alerts"]), 5.0)
            after = snapshot(dashboard)
        yield {"fleet": lab, "out": out, "states": states, "trust": watch.reports, "dashboard": seen,
               "lost": lost, "after": after, "refused": refused}


def refused_clash(lab, out: Path) -> subprocess.CompletedProcess:
    """mocap-sim run on a config that simulates car 1, whose rigid body Motive streams."""
    cars = (dataclasses.replace(lab.cars[0], simulated=True), dataclasses.replace(lab.cars[1], simulated=False))
    cars = tuple(dataclasses.replace(car, link=f"udp://127.0.0.1:{free_port(UDP)}") for car in cars)
    clash = dataclasses.replace(lab, cars=cars, natnet=dataclasses.replace(lab.natnet, command_port=free_port(UDP)))
    (out / "clash.toml").write_text(dump_scenario(clash))
    return subprocess.run([sys.executable, "-m", "trustfg", "mocap-sim", "--config", str(out / "clash.toml"),
                           "--relay", str(out / "motive.toml")], capture_output=True, text=True, timeout=30)


def test_every_car_reaches_its_goal_without_breach(run):
    lab = run["fleet"]
    assert run["states"] == {1: "arrived", 2: "arrived", 3: "arrived", 4: "arrived"}
    truth = ground_truth(run["out"] / "truth_sim.csv") | ground_truth(run["out"] / "truth_motive.csv")
    assert sorted(truth) == [1, 2, 3, 4]  # car 1 from Motive's stand-in, cars 2-4 from the relaying mocap-sim
    ids = [car.id for car in lab.cars]
    times = truth[2][:, 0]
    positions = np.stack([np.column_stack([np.interp(times, truth[i][:, 0], truth[i][:, k]) for k in (1, 2)])
                          for i in ids], axis=1)  # (T, 4, 2) on the relaying mocap-sim's samples
    gaps = np.linalg.norm(positions[:, :, None] - positions[:, None], axis=-1).min(axis=0)
    breach = metrics.breach_distances([car.radius_m for car in lab.cars], lab.safety.clearance_m)
    np.fill_diagonal(gaps, np.inf)
    assert (gaps >= breach).all(), gaps
    goals = np.array([car.goal for car in lab.cars])
    assert (np.linalg.norm(positions[-1] - goals, axis=1) <= lab.arrival_radius_m).all(), positions[-1]


def test_the_real_car_is_trusted_as_a_simulated_one(run):
    reports = run["trust"]
    assert sorted(reports) == [1, 2, 3, 4]
    for truster in (2, 3, 4):
        for peer in {1, 2, 3, 4} - {truster}:
            seen = reports[truster].peers[peer]
            assert seen.trust >= 0.8, (truster, peer, seen)
            assert seen.alpha[2] > 0 and seen.beta[2] == 0.0, (truster, peer, seen)  # plans audited, none failed


def test_the_dashboard_sees_four_cars_and_then_car_1_lose_its_pose(run):
    cars = {car["id"]: car for car in run["dashboard"]["cars"]}
    assert sorted(cars) == [1, 2, 3, 4]
    assert all(car["pose"]["valid"] and car["state"] == "arrived" for car in cars.values()), cars
    assert all("1" in run["dashboard"]["trust"][str(truster)] for truster in (2, 3, 4))
    assert run["lost"], run["after"]["alerts"]  # Motive stopped: the relay serves car 1 untracked
    assert not any(a["kind"] == "lost_pose" and a["cars"] != [1] for a in run["after"]["alerts"])


def test_a_simulated_car_whose_body_motive_streams_is_refused(run):
    refused = run["refused"]
    assert refused.returncode == 2, refused.stderr
    assert "cars [1] are simulated, but their rigid bodies [1] are also in the stream" in refused.stderr
    assert "Traceback" not in refused.stderr

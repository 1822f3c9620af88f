"""The relay without sockets: upstream frames in (their bytes, through the bridge's
FrameReceiver), merged frames out (the NatNet server's make_frame, encoded and decoded as a
car process decodes them), and the mixed-fleet configs mocap-sim refuses."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from trustfg.agent.config import ConfigError
from trustfg.agent.scenario_files import dump_scenario, load_scenario
from trustfg.bridge import natnet
from trustfg.bridge.natnet import Frame, RigidBody, Version
from trustfg.bridge.natnet_client import FrameReceiver, fresh_pose
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys
from trustfg.mocap_sim.natnet_server import NatNetServer, NatNetServerOptions
from trustfg.mocap_sim.relay import RelayOptions, check_relay, merge, served_version
from trustfg.mocap_sim.sim import MocapSim, MocapSimOptions

STALE_S = RelayOptions.stale_s
REAL = {1: "car1"}
"""The real car's rigid body and its name."""


def f32(*values: float) -> tuple[float, ...]:
    """Values as a NatNet stream carries them (float32), so that a pass-through is exact."""
    return tuple(float(v) for v in np.float32(values))


P1, Q1 = f32(0.4123, 0.0517, 2.1377), f32(0.0, 0.3826834, 0.0, 0.9238795)
P2 = f32(0.4731, 0.0517, 1.9012)


def simulated(t: float) -> list:
    """Cars 2 and 3, standing, as mocap-sim serves them."""
    return [(2, "car2", (-0.4, 0.05, -2.15), (0.0, 0.0, 0.0, 1.0), True),
            (3, "car3", (-2.15, 0.05, 0.4), (0.0, 0.0, 0.0, 1.0), True)]


class Upstream:
    """Motive's frames, as the relay's client takes them: encoded, then handled at a time."""

    def __init__(self, version: Version = natnet.DEFAULT_VERSION):
        self.version = version
        self.receiver = FrameReceiver(version)
        self.number = 5000  # Motive's own numbering, unrelated to the merged stream's

    def send(self, bodies: tuple[RigidBody, ...], received_s: float) -> None:
        self.number += 1
        frame = Frame(self.number, bodies, timestamp=self.number / 120.0)
        assert self.receiver.handle(natnet.serialize(frame, self.version), received_s) is not None


class Merged:
    """The merged stream's server, its frames made at a chosen time and decoded back."""

    def __init__(self, upstream: Upstream, **options):
        self.now = 0.0
        self.upstream = upstream
        self.version = served_version(upstream.version)
        source = lambda t: merge(simulated(t), upstream.receiver.latest_all(), REAL, self.now, STALE_S)  # noqa: E731
        self.server = NatNetServer(NatNetServerOptions(command_port=0, natnet_version=self.version, **options), source)
        self.k = 0

    def frame(self, now: float) -> Frame:
        self.now = now
        packet = natnet.serialize(self.server.make_frame(self.k), self.version)
        self.k += 1
        return natnet.deserialize(packet, self.version)


def bodies(frame: Frame) -> dict[int, RigidBody]:
    return {b.id: b for b in frame.rigid_bodies}


@pytest.mark.parametrize("version", natnet.FRAME_VERSIONS, ids=str)
def test_real_poses_pass_unchanged_among_the_simulated_ones(version):
    upstream = Upstream(version)
    wand = RigidBody(7, (1.0, 1.0, 1.0), (0.0, 0.0, 0.0, 1.0))  # in Motive, not a car of the fleet
    upstream.send((RigidBody(1, P1, Q1, float(np.float32(0.0007)), True), wand), received_s=0.0)
    merged = Merged(upstream, noise_std_m=0.01)
    assert merged.version == version  # the merged stream speaks the upstream's version
    first, second = merged.frame(0.01), merged.frame(0.02)
    assert set(bodies(first)) == {1, 2, 3}  # the fleet's cars only: the wand is not relayed
    real = bodies(first)[1]
    assert (real.position, real.orientation, real.tracking_valid) == (P1, Q1, True)  # exact, no noise
    assert real.mean_error == pytest.approx(0.0007, rel=1e-6)
    assert bodies(first)[2].position != (-0.4, 0.05, -2.15)  # the simulated cars get the noise knob
    # the merged stream's own frame numbers and clock, whatever Motive numbered its frames
    assert (first.frame_number, second.frame_number) == (1, 2)
    assert (first.timestamp, second.timestamp) == (0.0, 1 / 120.0)


def test_the_tracking_flag_passes_and_an_untracked_body_keeps_its_last_real_pose():
    upstream = Upstream()
    merged = Merged(upstream)
    upstream.send((RigidBody(1, P1, Q1),), received_s=0.0)
    assert bodies(merged.frame(0.01))[1].tracking_valid
    upstream.send((RigidBody(1, P2, Q1, 0.0, False),), received_s=0.02)  # Motive lost it
    lost = bodies(merged.frame(0.03))[1]
    assert not lost.tracking_valid and lost.position == P1  # the last pose tracked, flagged


def test_an_upstream_gone_quiet_goes_stale_and_its_car_process_takes_no_pose():
    upstream = Upstream()
    merged = Merged(upstream)
    upstream.send((RigidBody(1, P1, Q1),), received_s=0.0)
    numbers = []
    for now, valid in ((0.01, True), (STALE_S - 0.001, True), (STALE_S + 0.001, False), (1.0, False)):
        frame = merged.frame(now)
        numbers.append(frame.frame_number)
        real = bodies(frame)[1]
        assert real.tracking_valid is valid, now
        assert real.position == P1  # never a pose the relay made up
        assert bodies(frame)[2].tracking_valid  # the simulated cars stream on
    assert numbers == [1, 2, 3, 4]  # frames keep coming, numbered on
    # A car process reading the merged stream has no pose of the real car: its velocity
    # loop and its agent take none from an untracked body, so it commands STOP.
    car = FrameReceiver(merged.version)
    car.handle(natnet.serialize(merged.frame(1.1), merged.version), time.monotonic())
    assert fresh_pose(car, 1, max_age_s=0.2) is None
    assert fresh_pose(car, 2, max_age_s=0.2) is not None
    upstream.send((RigidBody(1, P2, Q1),), received_s=2.0)  # the upstream is back
    back = bodies(merged.frame(2.01))[1]
    assert back.tracking_valid and back.position == P2


def test_a_real_car_never_seen_is_left_out_and_a_simulated_id_is_never_relayed():
    upstream = Upstream()
    merged = Merged(upstream)
    assert set(bodies(merged.frame(0.0))) == {2, 3}  # nothing upstream yet
    upstream.send((RigidBody(2, P1, Q1),), received_s=0.1)  # Motive streams id 2 too
    frame = merged.frame(0.11)
    assert [b.id for b in frame.rigid_bodies] == [2, 3]  # one body 2: the simulated one
    assert bodies(frame)[2].position == f32(-0.4, 0.05, -2.15)


def test_merge_takes_each_real_car_by_its_rigid_body_and_name():
    upstream = Upstream()
    upstream.send((RigidBody(11, P1, Q1, 0.001, True),), received_s=1.0)
    out = merge([], upstream.receiver.latest_all(), {11: "Car One", 12: "car2"}, now=1.0, stale_s=STALE_S)
    assert out == [(11, "Car One", P1, Q1, True, pytest.approx(0.001, rel=1e-6))]


@pytest.mark.parametrize("upstream, served", [("3.0", "3.0"), ("3.1", "3.1"), ("4.1", "4.1"), ("4.2", "4.2"),
                                              ("4.4", "4.2"), ("2.9", "3.1")])
def test_the_merged_stream_speaks_the_upstreams_version_where_it_can(upstream, served):
    assert served_version(Version.parse(upstream)) == Version.parse(served)


# --- configs ----------------------------------------------------------------------------


@pytest.fixture
def mixed(intersection, tmp_path):
    """The crossing wired for loopback, car 1 real, and the lab's config that names Motive."""
    fleet = with_link_keys(loopback_fleet(intersection, None), tmp_path / "keys")
    cars = (dataclasses.replace(fleet.cars[0], simulated=False),) + fleet.cars[1:]
    motive = dataclasses.replace(fleet.natnet, command_port=fleet.natnet.command_port + 1)
    return dataclasses.replace(fleet, cars=cars), RelayOptions(motive)


def test_the_simulated_key_is_read_and_written(mixed, intersection, tmp_path):
    fleet, _ = mixed
    path = tmp_path / "mixed.toml"
    path.write_text(dump_scenario(fleet))
    assert "simulated = false" in path.read_text()
    assert [car.simulated for car in load_scenario(path).cars] == [False, True, True, True]
    assert all(car.simulated for car in intersection.cars)  # every car, by default


def test_mocap_sim_simulates_only_the_cars_marked_simulated(mixed):
    fleet, relay = mixed
    real_car = dataclasses.replace(fleet.cars[0], link="")  # its link is the real car's: none needed here
    sim = MocapSim(dataclasses.replace(fleet, cars=(real_car, *fleet.cars[1:])), MocapSimOptions(relay=relay))
    assert [car.id for car in sim.cars] == [2, 3, 4] and set(sim.states) == {2, 3, 4}
    assert {body[0] for body in sim.bodies(0.0)} == {2, 3, 4}
    assert sim.server_options(Version(4, 4)).natnet_version == natnet.V4_2
    assert sim.server_options().natnet_version == natnet.DEFAULT_VERSION
    assert MocapSim(fleet, MocapSimOptions("4.0", relay=relay)).server_options(Version(3, 1)).natnet_version \
        == natnet.V4_0  # a version asked for stands


def test_what_mocap_sim_refuses(mixed):
    fleet, relay = mixed
    with pytest.raises(ConfigError, match=r"cars \[1\] are real .* --relay"):
        check_relay(fleet, None)
    every_car_simulated = dataclasses.replace(fleet, cars=tuple(dataclasses.replace(c, simulated=True)
                                                                for c in fleet.cars))
    with pytest.raises(ConfigError, match="nothing to relay"):
        check_relay(every_car_simulated, relay)
    with pytest.raises(ConfigError, match="merged stream is served"):
        check_relay(fleet, RelayOptions(fleet.natnet))
    both_multicast = dataclasses.replace(fleet, natnet=dataclasses.replace(fleet.natnet, mode="multicast"))
    motive = dataclasses.replace(both_multicast.natnet, server="10.0.0.2")
    with pytest.raises(ConfigError, match="both multicast to 239.255.42.99"):
        check_relay(both_multicast, RelayOptions(motive))
    check_relay(both_multicast, RelayOptions(dataclasses.replace(motive, data_port=1511)))  # another port: fine
    with pytest.raises(ConfigError, match="up_axis"):
        check_relay(fleet, RelayOptions(dataclasses.replace(relay.upstream, up_axis="z")))
    with pytest.raises(ConfigError, match="stale_s"):
        RelayOptions(relay.upstream, stale_s=0.0)
    check_relay(fleet, relay)

"""Mutual TLS and access control with Zenoh's own features, on real sessions.

Certificates are made at test time by ``trustfg keys``' own steps (never committed).
"""

import dataclasses
import json
import os
import pwd
import time

import pytest
import zenoh

from tests.conftest import wait_for
from trustfg.agent import messages
from trustfg.agent.config import BusConfig
from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.bus.security import secure_config
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.bus.zenoh_setup import zenoh_config
from trustfg.fleet.launch.ports import free_port
from trustfg.fleet.operator.keys import carry_out, owner_of, survey

pytestmark = pytest.mark.realtime

FLEET = "sec"
CARS = [1, 2]


def make_certs(folder, cars):
    """A CA of its own, and the operator's and the cars' keys and certificates: OUT/tls."""
    car = load_scenario("intersection").cars[0]
    euid = os.geteuid()
    carry_out(survey([dataclasses.replace(car, id=c) for c in cars], folder, False, True, euid),
              owner_of(pwd.getpwuid(euid).pw_name, euid))
    return folder / "tls"


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    return make_certs(tmp_path_factory.mktemp("certs"), CARS)


def write(config: dict, path) -> str:
    path.write_text(json.dumps(config))
    return str(path)


def secure_bus(certs, tmp_path, identity, car_id, listen, connect=()):
    config_file = write(secure_config(FLEET, CARS, certs, identity), tmp_path / f"{identity}-{listen[-5:]}.json5")
    return FleetBus(BusConfig(listen=(listen,), connect=tuple(connect), zenoh_config=config_file), FLEET, car_id)


def tls():
    return f"tls/127.0.0.1:{free_port()}"


def pose(sender, seq):
    return messages.encode(messages.PoseMessage(sender, seq, time.time(), 1.0, 2.0, 0.0, True))


def test_cars_with_fleet_certificates_talk(certs, tmp_path):
    a, b = tls(), tls()
    with secure_bus(certs, tmp_path, "car1", 1, a) as one, secure_bus(certs, tmp_path, "car2", 2, b, [a]) as two:
        assert wait_for(lambda: one.alive.get(2) and two.alive.get(1), 10.0)
        got = []
        assert wait_for(lambda: (two.publish("pose", pose(2, len(got) + 1)), got.extend(one.drain()),
                                 any(r.kind == "pose" and r.sender == 2 for r in got))[2], 10.0)


def test_a_session_without_a_valid_certificate_can_neither_receive_nor_publish(certs, tmp_path):
    a = tls()
    # A stranger: its own CA and certificate, not the fleet's.
    stranger_certs = make_certs(tmp_path / "stranger", [9])
    with secure_bus(certs, tmp_path, "car1", 1, a) as car:
        for name, config in [
            ("no certificate", {"transport": {"link": {"tls": {"root_ca_certificate": str(certs / "ca.tls.crt"),
                                                                "verify_name_on_connect": False}}}}),
            ("a foreign CA", secure_config(FLEET, [9], stranger_certs, "car9")),
        ]:
            bus_config = BusConfig(connect=(a,), zenoh_config=write(config, tmp_path / "x.json5"))
            session = zenoh.open(zenoh_config(bus_config))
            try:
                heard = []
                session.declare_subscriber(f"trustfg/{FLEET}/1/**", lambda s: heard.append(s))  # car 1's
                deadline = time.monotonic() + 2.0
                seq = 0
                while time.monotonic() < deadline:  # both directions, for two seconds
                    seq += 1
                    car.publish("pose", pose(1, seq))
                    session.put(f"trustfg/{FLEET}/9/pose", pose(9, seq))
                    time.sleep(0.05)
                assert heard == [], name  # it heard nothing of car 1
                assert not any(r.sender == 9 for r in car.drain()), name
                assert not car.alive.get(9)
            finally:
                session.close()


def test_car_2_cannot_publish_under_car_1s_keys(certs, tmp_path):
    a, b, c = tls(), tls(), tls()
    config_2 = write(secure_config(FLEET, CARS, certs, "car2"), tmp_path / "car2-raw.json5")
    with secure_bus(certs, tmp_path, "car1", 1, a) as one, \
            secure_bus(certs, tmp_path, "operator", None, c, [a]) as observer:
        raw = zenoh.open(zenoh_config(BusConfig(listen=(b,), connect=(a, c), zenoh_config=config_2)))
        try:
            assert wait_for(lambda: observer.alive.get(1), 10.0)
            spoofed = raw.declare_publisher(f"trustfg/{FLEET}/1/plan")
            honest = raw.declare_publisher(f"trustfg/{FLEET}/2/pose")
            heard = []
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline and not any(r.sender == 2 for r in heard):
                spoofed.put(b"car 2 pretending to be car 1")
                honest.put(pose(2, len(heard) + 1))
                heard.extend(observer.drain())
                heard.extend(one.drain())
                time.sleep(0.05)
            assert any(r.sender == 2 and r.kind == "pose" for r in heard), "car 2's own keys must get through"
            assert not any(r.payload == b"car 2 pretending to be car 1" for r in heard)
            # ... and only the operator may start, stop or keep the fleet alive. Same session,
            # same link, same priority: had one got through, it would arrive before the marker.
            for name in ("start", "stop", "heartbeat"):
                raw.put(f"trustfg/{FLEET}/{name}", f"car 2 sending the operator's {name}".encode())
            honest.put(b"marker")
            later = []
            assert wait_for(lambda: (later.extend(one.drain()), any(r.payload == b"marker" for r in later))[1], 10.0)
            assert not any(r.kind in ("start", "stop", "heartbeat") for r in later)
            # while the operator's own stop does reach car 1
            observer.publish("stop", messages.encode(messages.StopMessage(1, time.time(), "estop")))
            assert wait_for(lambda: (later.extend(one.drain()), any(r.kind == "stop" for r in later))[1], 10.0)
        finally:
            raw.close()


def test_without_access_control_the_spoof_would_get_through(certs, tmp_path):
    """The control experiment: same TLS, ACL disabled -- the spoofed plan arrives. (So the
    test above fails if access control stops working.)"""
    def open_config(identity):
        config = secure_config(FLEET, CARS, certs, identity)
        config["access_control"]["enabled"] = False
        return write(config, tmp_path / f"{identity}-open.json5")

    a, b = tls(), tls()
    with FleetBus(BusConfig(listen=(a,), zenoh_config=open_config("car1")), FLEET, None) as observer:
        raw = zenoh.open(zenoh_config(BusConfig(listen=(b,), connect=(a,), zenoh_config=open_config("car2"))))
        try:
            spoofed = raw.declare_publisher(f"trustfg/{FLEET}/1/plan")
            heard = []
            assert wait_for(lambda: (spoofed.put(b"car 2 pretending to be car 1"), heard.extend(observer.drain()),
                                     any(r.payload == b"car 2 pretending to be car 1" for r in heard))[2], 10.0)
        finally:
            raw.close()


def test_secure_config_refuses_an_identity_outside_the_fleet_and_writes_where_certificates_will_be(certs):
    with pytest.raises(ValueError, match="car9"):
        secure_config(FLEET, CARS, certs, "car9")
    config = secure_config(FLEET, CARS, certs, "car2", certs_at="/etc/trustfg/tls")
    tls = config["transport"]["link"]["tls"]
    assert tls["root_ca_certificate"] == "/etc/trustfg/tls/ca.tls.crt"
    assert tls["connect_certificate"] == "/etc/trustfg/tls/car2.tls.crt"
    assert tls["connect_private_key"] == "/etc/trustfg/tls/car2.tls.key"
    with pytest.raises(FileNotFoundError, match="car3"):
        secure_config(FLEET, [1, 2, 3], certs, "car3")

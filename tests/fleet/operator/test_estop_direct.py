"""The e-stop's direct path: the first E_STOPs read the links (and keys) straight from the config file."""

import dataclasses
import json
import socket
import subprocess
import sys

import pytest

from trustfg.agent.scenario_files import dump_scenario
from trustfg.bridge.carlink import SOURCE_OPERATOR, decode_command, decode_command_v2, link_key
from trustfg.fleet.launch.link_keys import with_link_keys
from trustfg.fleet.launch.testbed import links_to_sinks

pytestmark = pytest.mark.realtime


def test_the_first_e_stop_reads_links_from_the_file_and_reaches_only_the_named_cars(intersection, tmp_path):
    from trustfg.fleet.operator.estop_first import first_e_stop

    sinks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in intersection.cars]
    try:
        for sink in sinks:
            sink.bind(("127.0.0.1", 0))
            sink.settimeout(2.0)
        # cars 1-3 speak version 2 (each its own key file), car 4 version 1
        cars = tuple(dataclasses.replace(car, link=f"udp://127.0.0.1:{sink.getsockname()[1]}",
                                         link_version=1 if car.id == 4 else 2)
                     for car, sink in zip(intersection.cars, sinks))
        fleet = with_link_keys(dataclasses.replace(intersection, cars=cars), tmp_path / "keys")
        config = tmp_path / "fleet.toml"
        config.write_text(dump_scenario(fleet))
        assert first_e_stop(str(config), [2, 3, 4]) == [2, 3, 4]
        for car, sink in zip(fleet.cars, sinks):
            if car.id in (2, 3, 4):
                data = sink.recvfrom(64)[0]
                got = decode_command(data) if car.id == 4 else decode_command_v2(data, link_key(car))
                assert got.car_id == car.id and got.e_stop and got.ping and (got.v_mps, got.omega_radps) == (0, 0)
                assert got.source == (0 if car.id == 4 else SOURCE_OPERATOR)
        assert first_e_stop(str(config)) == [1, 2, 3, 4]
        keyless = tmp_path / "keyless.toml"  # a version-2 car whose key does not read: left to the typed path
        keyless.write_text(dump_scenario(dataclasses.replace(intersection, cars=cars)))
        assert first_e_stop(str(keyless)) == [4]
        assert first_e_stop("intersection") == []  # a shipped name: the typed path handles it
        assert first_e_stop(str(tmp_path / "missing.toml")) == []
        (tmp_path / "broken.toml").write_text("cars = [ {id = 1, link = 'udp://nowhere'} ]\nthis is not toml")
        assert first_e_stop(str(tmp_path / "broken.toml")) == []
    finally:
        for sink in sinks:
            sink.close()


_SPY = """
import json, socket, sys
sent = []  # per datagram: were the typed config and logging loaded when it left?
plain = socket.socket.sendto
def sendto(self, data, *rest):
    sent.append([m in sys.modules for m in ("trustfg.agent.config", "logging")])
    return plain(self, data, *rest)
socket.socket.sendto = sendto
from trustfg.cli import main
status = main(sys.argv[1:])
print(json.dumps({"status": status, "sent": sent}))
"""


def test_trustfg_stop_sends_its_first_e_stops_before_the_typed_config_and_logging_load(intersection, tmp_path):
    """The cli's fast path (fleet.operator.estop_first): remove it, or set up logging first, and the
    first datagram leaves after those imports."""
    config, sinks = links_to_sinks(intersection, tmp_path)
    try:
        done = subprocess.run([sys.executable, "-c", _SPY, "stop", "--config", str(config), "--path", "link",
                               "--repeat", "0.1", "--wait", "0.2"], capture_output=True, text=True, timeout=60)
        report = json.loads(done.stdout.strip().splitlines()[-1])
    finally:
        for sink in sinks:
            sink.close()
    sent = report["sent"]
    n = len(intersection.cars)
    assert sent[:n] == [[False, False]] * n  # one E_STOP to each car before anything heavy loaded
    assert len(sent) > n and sent[-1] == [True, True]  # then the typed path, the authority, repeated them

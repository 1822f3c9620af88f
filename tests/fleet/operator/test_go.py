"""``trustfg go`` starts no trial while the e-stop's direct path to a car is missing (its
key does not read here, its address does not resolve), unless told ``--bus-stop-only``;
then it starts, on a real fleet of processes, and says loudly which cars the bus alone stops."""

import dataclasses
import subprocess
import sys

import pytest

from trustfg.agent.scenario_files import dump_scenario, load_scenario
from trustfg.bridge.carlink import new_key, write_key_file
from trustfg.fleet.launch.testbed import LoopbackFleet
from trustfg.fleet.operator.estop_direct import LinkStopper, missing_paths

pytestmark = pytest.mark.realtime


def trustfg(*argv, timeout=60):
    return subprocess.run([sys.executable, "-m", "trustfg", *argv], capture_output=True, text=True, timeout=timeout)


def lab_with_keys(tmp_path, **links):
    """The shipped lab, every car's key in tmp_path (``links``: car id -> another link)."""
    lab = load_scenario("lab/fleet")
    cars = tuple(dataclasses.replace(car, link=links.get(f"car{car.id}", car.link),
                                     link_key_file=str(write_key_file(tmp_path / f"car{car.id}.link.key", new_key())))
                 for car in lab.cars)
    config = tmp_path / "fleet.toml"
    config.write_text(dump_scenario(dataclasses.replace(lab, cars=cars)))
    return config


def test_every_path_there_and_the_check_finds_nothing(tmp_path):
    assert missing_paths(load_scenario(lab_with_keys(tmp_path))) == {}


def test_go_without_a_cars_key_refuses_in_one_line_naming_the_car_and_why(tmp_path):
    config = lab_with_keys(tmp_path)
    (tmp_path / "car2.link.key").unlink()
    done = trustfg("go", "--config", str(config), "--wait", "0")
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0].startswith("trustfg go: not starting: no direct e-stop path to car 2 (")
    assert "car2.link.key: No such file or directory" in lines[0] and "--bus-stop-only" in lines[0]
    assert "car 1" not in lines[0] and "car 3" not in lines[0] and done.stdout == ""


def test_an_address_that_does_not_resolve_is_a_missing_path(tmp_path):
    config = lab_with_keys(tmp_path, car3="udp://no-such-host.invalid:9000")
    missing = missing_paths(load_scenario(config))
    assert list(missing) == [3] and "no-such-host.invalid" in missing[3]
    stopper = LinkStopper(load_scenario(config))  # trustfg stop: the other cars' direct paths stand
    try:
        assert sorted(stopper.senders) == [1, 2, 4] and list(stopper.unreachable) == [3]
    finally:
        stopper.close()
    done = trustfg("go", "--config", str(config), "--wait", "0")
    assert done.returncode == 2 and "car 3 (cars[id=3].link udp://no-such-host.invalid:9000" in done.stderr


def test_with_bus_stop_only_go_starts_the_trial_and_says_so_loudly(intersection, tmp_path):
    two = dataclasses.replace(intersection, cars=intersection.cars[:2])
    with LoopbackFleet(two, tmp_path / "fleet") as fleet:
        assert fleet.wait_states({"waiting"}, timeout_s=60.0), fleet.states()
        keyless = dataclasses.replace(fleet.fleet, cars=(fleet.fleet.cars[0], dataclasses.replace(
            fleet.fleet.cars[1], link_key_file=str(tmp_path / "not-on-this-laptop.key"))))
        config = tmp_path / "operator.toml"
        config.write_text(dump_scenario(keyless))
        refused = trustfg("go", "--config", str(config), "--wait", "10")
        assert refused.returncode == 2 and "car 2 (" in refused.stderr and "trial" not in refused.stdout
        done = trustfg("go", "--config", str(config), "--wait", "10", "--lead", "0.5", "--bus-stop-only",
                       timeout=90)
        assert done.returncode == 0, done.stdout + done.stderr
        assert "started: cars 1 2" in done.stdout and "every car at its goal" in done.stdout
        warning = [line for line in done.stderr.splitlines() if line.startswith("WARNING: --bus-stop-only")]
        assert len(warning) == 1 and "car 2 (" in warning[0] and "car 1 (" not in warning[0]

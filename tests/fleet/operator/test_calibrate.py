"""``trustfg calibrate`` against mocap-sim cars whose bodies are known: it recovers each
limit within 10 % and the command-to-motion delay within 20 ms, writes a [vehicle] table
that loads, and stops the car at once for ``trustfg stop`` and for Ctrl-C."""

import csv
import dataclasses
import math
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.conftest import wait_for
from trustfg.agent.config import Scenario, VehicleConfig
from trustfg.agent.scenario_files import dump_scenario, load_vehicle
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.launch.link_keys import with_link_keys
from trustfg.fleet.operator.calibrate import fit_circle, fit_ramp, ramp_profile

pytestmark = pytest.mark.realtime

DELAY_S = 0.06
BODIES = {
    1: VehicleConfig(max_speed_mps=0.5, max_accel_mps2=1.0, max_turn_rate_radps=2.0, max_turn_accel_radps2=8.0),
    2: VehicleConfig(steering="car", min_turn_radius_m=0.4, wheelbase_m=0.15, max_speed_mps=0.45,
                     max_accel_mps2=1.2),
}
"""The cars' true bodies (mocap-sim --vehicle); the fleet's config says the defaults."""


def vehicle_file(path, vehicle: VehicleConfig):
    """A file with a [vehicle] table, as trustfg calibrate writes one."""
    text = dump_scenario(Scenario(name="", cars=(), vehicle=vehicle))
    path.write_text(text[text.index("[vehicle]"):].split("\n\n")[0] + "\n")
    return path


@pytest.fixture
def lab(intersection, tmp_path):
    """mocap-sim with the two cars, their true bodies and a command delay; the fleet config."""
    fleet = loopback_fleet(dataclasses.replace(intersection, cars=intersection.cars[:2]), None, None, 0.0)
    fleet = with_link_keys(fleet, tmp_path / "keys")
    config = tmp_path / "fleet.toml"
    config.write_text(dump_scenario(fleet))
    truth = tmp_path / "truth.csv"
    bodies = [f"--vehicle={car}={vehicle_file(tmp_path / f'body{car}.toml', body)}" for car, body in BODIES.items()]
    mocap = subprocess.Popen([sys.executable, "-m", "trustfg", "mocap-sim", "--config", str(config),
                              "--ground-truth", str(truth), f"--command-delay={DELAY_S}", *bodies],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert mocap.stdout.readline().startswith("mocap-sim: NatNet on "), mocap.stderr.read()
        assert mocap.stdout.readline().strip() == "READY", mocap.stderr.read()
        yield config, truth
    finally:
        mocap.terminate()
        mocap.wait(timeout=10)
        mocap.stdout.close()
        mocap.stderr.close()


def calibrate(config, car, *extra, **popen):
    return subprocess.Popen([sys.executable, "-m", "trustfg", "calibrate", "--config", str(config), "--car", str(car),
                             "--room", "1.2", "--no-bus", *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, **popen)


def speeds(truth, car) -> list[tuple[float, float]]:
    with open(truth, newline="") as f:
        return [(float(r["t"]), float(r["v"])) for r in csv.DictReader(f) if int(r["car_id"]) == car]


def test_it_recovers_known_limits_and_the_delay(lab, tmp_path):
    config, _ = lab
    for car, body in BODIES.items():
        out = tmp_path / f"car{car}.vehicle.toml"
        done = calibrate(config, car, "--out", str(out))
        stdout, stderr = done.communicate(timeout=60)
        assert done.returncode == 0, stdout + stderr
        measured = load_vehicle(out)
        assert measured.steering == body.steering
        assert measured.max_speed_mps == pytest.approx(body.max_speed_mps, rel=0.1)
        assert measured.max_accel_mps2 == pytest.approx(body.max_accel_mps2, rel=0.1)
        if body.car_like:
            assert measured.min_turn_radius_m == pytest.approx(body.min_turn_radius_m, rel=0.1)
        else:
            assert measured.max_turn_rate_radps == pytest.approx(body.max_turn_rate_radps, rel=0.1)
        delay = float(next(line for line in stdout.splitlines() if line.startswith("command to motion")).split()[3])
        assert abs(delay / 1e3 - DELAY_S) <= 0.02, stdout
        assert "# trustfg calibrate: car" in out.read_text()


@pytest.mark.parametrize("how", ["trustfg stop", "Ctrl-C"])
def test_the_operators_stop_ends_the_pattern_and_the_car_stands(lab, how):
    config, truth = lab
    running = calibrate(config, 1, start_new_session=True)
    try:
        first = running.stdout.readline()
        assert "straight on" in first or "drives a pattern" in first, first + running.stderr.read()
        assert wait_for(lambda: any(v > 0.2 for _, v in speeds(truth, 1)), 10.0)
        stopped_at = time.time()
        if how == "trustfg stop":
            stop = subprocess.run([sys.executable, "-m", "trustfg", "stop", "--config", str(config), "--cars", "1",
                                   "--path", "link", "--wait", "0.5"], capture_output=True, text=True, timeout=60)
            assert stop.returncode == 0, stop.stdout + stop.stderr
        else:
            running.send_signal(signal.SIGINT)
        _, stderr = running.communicate(timeout=20)
        assert running.returncode == (1 if how == "trustfg stop" else 130), stderr
        assert ("e-stopped" if how == "trustfg stop" else "Ctrl-C") in stderr and "nothing written" in stderr
        # It stands within the time a brake from its top speed takes, and stays standing.
        assert wait_for(lambda: [v for t, v in speeds(truth, 1) if t > stopped_at + 1.0][-1:] == [0.0], 5.0)
        time.sleep(0.5)
        assert max(v for t, v in speeds(truth, 1) if t > stopped_at + 1.0) == 0.0
    finally:
        if running.poll() is None:
            running.kill()
            running.communicate()
        subprocess.run([sys.executable, "-m", "trustfg", "stop", "--config", str(config), "--release", "--path",
                        "link", "--wait", "0.2"], capture_output=True, timeout=60)


def test_the_fits_recover_a_ramp_and_a_circle_from_noisy_samples():
    """The pure part: a rate that rises at 1.2 to 0.45 after 60 ms and falls at 1.5, sampled
    at 120 Hz with 1 mm of noise; points on a circle of 0.4 m."""
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 5.0, 1 / 120)
    covered = ramp_profile(t, 0.5, 3.0, 0.06, 1.2, 0.45, 1.5) + rng.normal(0, 0.001, len(t))
    ramp = fit_ramp(t, covered, 0.5, 3.0, (1.5, 0.8, 1.5))
    assert ramp.delay_s == pytest.approx(0.06, abs=0.01) and ramp.reached
    assert (ramp.rise, ramp.top, ramp.fall) == pytest.approx((1.2, 0.45, 1.5), rel=0.03)
    angle = np.linspace(0.3, 4.0, 200)
    cx, cy, r = fit_circle(1.0 + 0.4 * np.cos(angle) + rng.normal(0, 0.001, 200),
                           -2.0 + 0.4 * np.sin(angle) + rng.normal(0, 0.001, 200))
    assert (cx, cy, r) == pytest.approx((1.0, -2.0, 0.4), abs=0.005)
    assert math.isclose(ramp_profile(np.array([10.0]), 0.5, 3.0, 0.06, 1.2, 0.45, 1.5)[0],
                        0.45 * (3.0 - 0.5) - 0.45**2 / 2.4 + 0.45**2 / 3.0, rel_tol=1e-9)

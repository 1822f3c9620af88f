"""The operator's commands against a running ``trustfg sim`` (the launcher, mocap-sim, four
car processes): ``trustfg check`` reports every car; ``trustfg stop`` stops every car on
both paths and they stay stopped until ``trustfg stop --release``."""

import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from tests.conftest import wait_for
from trustfg.fleet.launch.ports import free_port
from trustfg.fleet.launch.testbed import CommandLog

pytestmark = pytest.mark.realtime


def trustfg(*argv):
    return subprocess.run([sys.executable, "-m", "trustfg", *argv], capture_output=True, text=True, timeout=60)


def test_check_and_stop_on_a_running_trustfg_sim(tmp_path):
    run = tmp_path / "run"
    control = free_port(socket.SOCK_DGRAM)
    sim = subprocess.Popen([sys.executable, "-m", "trustfg", "sim", "--no-dashboard", "--stay", "--timeout", "90",
                            "--out", str(run), f"--mocap=--control-port={control}"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        for line in sim.stdout:
            if "go (seed" in line:
                break
        config = str(run / "fleet.toml")
        check = trustfg("check", "--config", config, "--wait", "2")
        rows = [line for line in check.stdout.splitlines() if line[:1].isdigit()]
        assert len(rows) == 4, check.stdout + check.stderr
        for row in rows:  # pose (x y yaw), link, bus and clock, per car
            assert len(row.split()) >= 9 and "answers" in row and "trial 1" in row and " ms" in row, row
        log = CommandLog(run / "commands.csv")
        assert wait_for(lambda: log.moving(), 20.0)
        moving = log.moving()
        issued = time.time()
        stop = trustfg("stop", "--config", config)
        assert stop.returncode == 0 and stop.stdout.count("e-stop latched") == 4, stop.stdout + stop.stderr
        held = log.held_since(issued, moving)
        assert None not in held.values(), held
        time.sleep(1.0)
        assert log.held_since(issued, moving) == held  # stays stopped
        release = trustfg("stop", "--config", config, "--release")
        assert release.returncode == 0 and release.stdout.count("waiting") == 4, release.stdout + release.stderr
        released = time.time()
        time.sleep(1.0)
        assert not log.moved_after(released)  # they wait for a new start
    finally:
        if sim.poll() is None:
            os.killpg(sim.pid, signal.SIGINT)
        sim.communicate(timeout=60)

"""trustfg record: a live fleet (here one car's bus) into a valid MCAP file."""

import dataclasses
import signal
import subprocess
import sys
import threading
import time

import pytest

from trustfg.agent import messages
from trustfg.agent.config import BusConfig
from trustfg.agent.scenario_files import dump_scenario
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.launch.ports import free_port
from trustfg.fleet.recording.mcap_file import read_recording

pytestmark = pytest.mark.realtime


def pose(seq: int) -> bytes:
    return messages.encode(messages.PoseMessage(2, seq, time.time(), 0.1 * seq, 0.0, 0.0, True))


def test_record_writes_what_the_fleet_says(intersection, tmp_path):
    car_endpoint = f"tcp/127.0.0.1:{free_port()}"
    fleet = dataclasses.replace(intersection, bus=BusConfig(connect=(car_endpoint,)))
    config = tmp_path / "fleet.toml"
    config.write_text(dump_scenario(fleet))
    out = tmp_path / "lab.mcap"
    with FleetBus(BusConfig(listen=(car_endpoint,)), fleet.fleet, 2) as car:
        recorder = subprocess.Popen([sys.executable, "-m", "trustfg", "record", "--config", str(config),
                                     "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}"],
                                    stdout=subprocess.PIPE, text=True)
        try:
            assert "recording" in recorder.stdout.readline()
            # Warm up until the recorder says it hears us (its subscriptions have reached us) ...
            heard = threading.Event()
            threading.Thread(target=lambda: "first message" in recorder.stdout.readline() and heard.set(),
                             daemon=True).start()
            deadline = time.monotonic() + 15
            while not heard.wait(0.05) and time.monotonic() < deadline:
                car.publish("pose", pose(1))
            assert heard.is_set(), "the recorder never heard the car"
            # ... then every message must land in the file.
            for seq in range(2, 22):
                car.publish("pose", pose(seq))
                time.sleep(0.02)
        finally:
            recorder.send_signal(signal.SIGINT)
            assert recorder.wait(timeout=10) == 0
            recorder.stdout.close()
    scenario, events = read_recording(out)
    poses = [e.data["seq"] for e in events if e.kind == "pose"]
    assert scenario.name == intersection.name
    assert poses == [1] + list(range(2, 22))  # the warm-up's repeats of seq 1 are replays, dropped

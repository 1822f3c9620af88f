"""examples/read_a_recording.py on recordings written by the recorder trustfg sim uses
(McapRecorder), holding a few seconds of two cars: with ground truth, and with published
poses alone."""

import dataclasses
import re

import numpy as np
import pytest

from tests.examples.conftest import png
from trustfg.agent import messages
from trustfg.fleet.recording.mcap_file import McapRecorder

pytestmark = pytest.mark.realtime

T0, SECONDS, SPEED = 1_700_000_000.0, 4.0, 0.4
"""Car 1 drives north and car 2 east, at SPEED for SECONDS: each drives 1.6 m."""


def record(path, scene, truth: bool) -> None:
    """A start, 50 Hz truth (if ``truth``), 10 Hz poses and a trust report a second."""
    recorder = McapRecorder(path, scene)
    recorder.write("start", 0, T0, messages.to_dict(messages.StartMessage(1, T0, 1, {1: (T0, SPEED), 2: (T0, SPEED)})))
    for k, t in enumerate(np.arange(0.0, SECONDS + 1e-9, 0.02)):
        at = T0 + t
        one, two = (0.4, -2.15 + SPEED * t), (-2.15 + SPEED * t, -0.4)
        if truth:
            cars = {str(i): {"x": x, "y": y, "yaw": 0.0, "v": SPEED, "omega": 0.0} for i, (x, y) in ((1, one), (2, two))}
            recorder.write("truth", 0, at, {"t": at, "cars": cars})
        if k % 5 == 0:
            for i, (x, y) in ((1, one), (2, two)):
                recorder.write("pose", i, at, messages.to_dict(messages.PoseMessage(i, k + 1, at, x, y, 0.0, True)))
        if k % 50 == 0:
            for i, peer, value in ((1, 2, 0.9), (2, 1, 0.3)):
                trust = messages.PeerTrust((1.0,) * 3, (0.0,) * 3, (value,) * 3, value, 0.45)
                recorder.write("trust", i, at, messages.to_dict(messages.TrustReport(i, k + 1, at, {peer: trust})))
    recorder.close()


@pytest.fixture
def two_cars(intersection):
    return dataclasses.replace(intersection, cars=intersection.cars[:2])


def test_a_run_folder_with_ground_truth(run_example, tmp_path, two_cars):
    folder = tmp_path / "sim-x"
    folder.mkdir()
    record(folder / "run.mcap", two_cars, truth=True)
    out = run_example("read_a_recording", str(folder))
    assert "intersection, cars [1, 2]" in out
    assert "{'start': 1, 'truth': 201, 'pose': 82, 'trust': 10}" in out
    driven = re.findall(r"car (\d): drove ([\d.]+) m \(ground truth\), ends ([\d.]+) m from its goal", out)
    assert [(car, float(length)) for car, length, _ in driven] == [("1", 1.6), ("2", 1.6)]
    assert [float(to_goal) for *_, to_goal in driven] == [2.7, 2.7]  # 4.3 m from start to goal
    assert "last trust in its peers {2: 0.90}" in out and "last trust in its peers {1: 0.30}" in out
    assert png(tmp_path / "read_a_recording.png")


def test_an_mcap_file_with_poses_alone(run_example, tmp_path, two_cars):
    record(tmp_path / "lab.mcap", two_cars, truth=False)
    out = run_example("read_a_recording", str(tmp_path / "lab.mcap"))
    assert "'truth'" not in out
    assert re.findall(r"drove ([\d.]+) m \(published poses\)", out) == ["1.60", "1.60"]
    assert png(tmp_path / "read_a_recording.png")

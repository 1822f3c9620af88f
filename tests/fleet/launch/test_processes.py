"""A launcher's children are stopped for sure: SIGTERM, then SIGKILL after a grace that
grows with how many wind down together."""

import signal
import subprocess
import sys
import time

import pytest

from trustfg.fleet.launch import processes
from trustfg.fleet.launch.processes import Processes, grace_s

pytestmark = pytest.mark.realtime


def test_children_stopped_together_get_more_time_the_more_they_are():
    assert grace_s(1) == processes.GRACE_S
    assert grace_s(18) == processes.GRACE_S + 17 * processes.GRACE_PER_CHILD_S  # 16 cars, mocap-sim, dashboard
    assert grace_s(0) == processes.GRACE_S


def test_a_child_that_ignores_sigterm_is_killed_once_its_grace_is_over(tmp_path, monkeypatch):
    monkeypatch.setattr(processes, "GRACE_S", 0.5)
    stubborn = ("import signal, time\nsignal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
                "print('up', flush=True)\ntime.sleep(60)")
    launcher = Processes(wrap=lambda name, argv: [sys.executable, "-c", stubborn])
    child = launcher.start("stubborn", [], tmp_path / "stubborn.log", stdout=subprocess.PIPE)
    assert child.stdout.readline().strip() == "up"  # SIGTERM is ignored from here on
    started = time.monotonic()
    launcher.stop()
    waited = time.monotonic() - started
    assert child.returncode == -signal.SIGKILL
    assert 0.5 <= waited < 4.0, waited

import threading
import time

import pytest

from trustfg.fleet.car.ticker import ticks

pytestmark = pytest.mark.realtime


def test_ticks_keep_absolute_deadlines_and_stop_at_once():
    stop = threading.Event()
    seen = []
    started = time.monotonic()
    for deadline, now in ticks(0.01, stop):
        seen.append((deadline, now))
        if len(seen) == 30:
            stop.set()
    assert len(seen) == 30
    deadlines = [d for d, _ in seen]
    assert all(abs((b - a) - 0.01) < 1e-9 for a, b in zip(deadlines, deadlines[1:]))  # no drift
    assert all(now >= deadline for deadline, now in seen)
    assert time.monotonic() - started < 1.0


def test_a_slow_body_skips_ticks_instead_of_bursting():
    stop = threading.Event()
    deadlines = []
    for deadline, _ in ticks(0.01, stop):
        deadlines.append(deadline)
        if len(deadlines) == 2:
            time.sleep(0.05)  # the body overran five periods
        if len(deadlines) == 4:
            stop.set()
    assert deadlines[2] - deadlines[1] < 0.015  # the late tick is reported at its own deadline ...
    assert deadlines[3] - deadlines[2] >= 0.03  # ... and the ones missed meanwhile are skipped


def test_stop_from_another_thread_ends_a_waiting_loop():
    stop = threading.Event()
    threading.Timer(0.05, stop.set).start()
    started = time.monotonic()
    for _ in ticks(10.0, stop):
        pass
    assert time.monotonic() - started < 1.0

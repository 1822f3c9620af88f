"""CPU accounting from /proc: the stat parser and the meter on a real process."""

import os
import time

import pytest

from trustfg.fleet.cpu import (
    CAR_SHARE,
    CLOCK_TICKS_PER_S,
    FLEET_SHARE,
    CpuMeter,
    Read,
    Sections,
    Snapshot,
    breakdown,
    capacity_note,
    parse_stat_ticks,
    read_thread_ticks,
    read_ticks,
    share,
)

pytestmark = pytest.mark.realtime

# A real /proc/PID/stat line shape (proc(5)), with a command name holding ') (' and spaces.
STAT = ("4242 (trustfg car) (1)) S 1 4242 4242 0 -1 4194560 2810 0 0 0 "
        "1234 567 8 9 20 0 7 0 123456 1490000000 36000 18446744073709551615 1 1 0 0 0 0 0 "
        "16781312 16386 0 0 0 17 1 0 0 0 0 0")


def test_stat_ticks_are_utime_plus_stime_counted_from_the_last_parenthesis():
    assert parse_stat_ticks(STAT) == 1234 + 567


@pytest.mark.parametrize("text", ["", "4242 trustfg S 1", "4242 (x) S 1 2 3"])
def test_a_line_that_is_not_stat_is_refused(text):
    with pytest.raises(ValueError):
        parse_stat_ticks(text)


def test_share_of_a_core_between_two_reads():
    assert share(Read(10.0, 0), Read(12.0, CLOCK_TICKS_PER_S)) == pytest.approx(0.5)
    assert share(Read(10.0, 0), Read(10.0, 5)) is None


def test_a_process_that_is_gone_reads_none():
    assert read_ticks(2**22 + 12345) is None


def test_the_meter_sees_cpu_burnt_and_not_time_slept():
    meter = CpuMeter()
    meter.watch("me", os.getpid())
    time.sleep(0.3)
    meter.sample(mark="slept")
    burn_until = time.process_time() + 0.3
    while time.process_time() < burn_until:
        pass
    meter.sample(mark="burnt")
    meter.pids["gone"] = 2**22 + 12345  # never readable: reported as null, not a crash
    summary = meter.summary("slept", "burnt")
    assert 0.25 <= summary["me"]["cpu_s"] <= 0.45, summary
    assert summary["me"]["share"] < summary["me"]["share_slept_burnt"], summary
    assert summary["gone"] is None


def test_a_process_read_with_its_children_counts_what_they_burn():
    """A car process is read with its command loop (fleet.car.velocity_loop): a child that
    burns 0.3 s of CPU shows in its parent's tree, not in the parent alone."""
    import subprocess
    import sys

    child = subprocess.Popen([sys.executable, "-c", "import sys, time\nt = time.process_time() + 0.3\n"
                              "while time.process_time() < t: pass\nsys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 10.0
        while (read_ticks(child.pid) or 0) < 0.3 * CLOCK_TICKS_PER_S and time.monotonic() < deadline:
            time.sleep(0.05)
        alone, tree = read_ticks(os.getpid()), read_ticks(os.getpid(), children=True)
        assert tree - alone >= 0.25 * CLOCK_TICKS_PER_S
    finally:
        child.stdin.close()
        child.wait()


def test_sections_book_the_cpu_since_the_last_booking():
    readings = iter([1.0, 1.5, 1.75, 3.0])
    sections = Sections(clock=lambda: next(readings))
    sections.book("wait")  # the first booking starts the watch: nothing before it is booked
    sections.book("replan")
    sections.book("wait")
    sections.book("replan")
    assert sections.cpu_s == {"replan": 0.5 + 1.25, "wait": 0.25}


def test_a_thread_burning_cpu_shows_under_its_own_id():
    import threading

    ids = {}

    def burn():
        ids["tid"] = threading.get_native_id()
        until = time.thread_time() + 0.3
        while time.thread_time() < until:
            pass
        ids["ticks"] = read_thread_ticks(os.getpid())

    thread = threading.Thread(target=burn)
    thread.start()
    thread.join()
    assert ids["ticks"][ids["tid"]] >= 0.25 * CLOCK_TICKS_PER_S
    assert threading.get_native_id() in read_thread_ticks(os.getpid())
    assert read_thread_ticks(2**22 + 12345) == {}


def test_breakdown_splits_a_car_into_its_threads_and_its_command_loop():
    hz = CLOCK_TICKS_PER_S
    # car process: main thread 10, NatNet 11, a Zenoh thread 12, a thread born within the window 13
    a = Snapshot(100.0, {"replan": 1.0, "wait": 0.1}, {10: 5 * hz, 11: hz, 12: hz}, 20, {20: hz, 21: hz})
    b = Snapshot(110.0, {"replan": 1.8, "wait": 0.2, "evidence": 0.3},
                 {10: 6 * hz, 11: hz + hz // 2, 12: hz + hz // 4, 13: hz // 4}, 20, {20: 2 * hz, 21: hz + hz // 2})
    out = breakdown(a, b, main_tid=10, natnet_tid=11)
    assert out["wall_s"] == 10.0
    assert out["sections"] == {"evidence": 0.3, "replan": 0.8, "wait": 0.1}
    assert out["threads"] == {"main": 1.0, "natnet": 0.5, "other": 0.5}
    assert out["command_loop"] == {"main": 1.0, "other": 0.5}
    restarted = Snapshot(110.0, b.sections, b.threads, 30, {30: hz})  # the loop died and came back
    assert breakdown(a, restarted, 10, 11)["command_loop"] == {"main": 0.0, "other": 0.0}
    assert breakdown(a, b, 10, None)["threads"] == {"main": 1.0, "natnet": 0.0, "other": 1.0}


def test_a_run_that_fills_the_cores_is_called_saturated():
    from trustfg.fleet.cpu import machine_load, usable_cores

    cpu = {"launcher": {"share_go_first_arrival": 0.05}, "mocap-sim": {"share_go_first_arrival": 0.1},
           **{f"car {i}": {"share_go_first_arrival": 0.22} for i in range(1, 9)}, "car 9": None}
    assert machine_load(cpu, 2) == {"busy_cores": 1.91, "cores": 2, "saturated": True, "until": "first_arrival"}
    assert machine_load(cpu, 4)["saturated"] is False
    assert machine_load({"car 1": {"share_go_first_arrival": None}}, 2)["busy_cores"] == 0.0  # no go: no window
    # No car arrived: the window runs from the go to the end, and sixteen starved cars are
    # saturated (a window that never closes would count them as an idle machine).
    starved = {f"car {i}": {"share_go_first_arrival": None, "share_go_end": 0.115} for i in range(1, 17)}
    assert machine_load(starved, 2)["busy_cores"] == 0.0
    assert machine_load(starved, 2, "end") == {"busy_cores": 1.84, "cores": 2, "saturated": True, "until": "end"}
    assert 1 <= usable_cores() <= (os.cpu_count() or 1)


def test_a_fleet_that_fits_the_cores_gets_no_capacity_note():
    assert capacity_note(4, 2) is None
    fits = int((2 - FLEET_SHARE) // CAR_SHARE)  # the most cars two cores hold by the estimate
    assert capacity_note(fits, 2) is None
    assert capacity_note(fits + 1, 2) is not None
    assert capacity_note(fits + 1, 4) is None


def test_the_capacity_note_says_how_many_cores_the_fleet_needs_and_has():
    note = capacity_note(16, 2)
    assert note.startswith("16 car processes need about 3.4 cores")
    assert "gives them 2" in note and "wait for the CPU" in note

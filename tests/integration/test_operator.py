"""The operator's protocol on a real fleet of processes: mocap-sim, four car processes, the
test as the operator (fleet.testbed), and the real ``trustfg check``, ``stop`` and ``go``.

One fleet for the module, the deadman on (0.5 s); each test leaves the cars waiting and
carries them back to their starts (mocap-sim's reset) for the next.
"""

import signal
import subprocess
import sys
import time

import pytest

from tests.conftest import wait_for
from trustfg.fleet.testbed import LoopbackFleet

DEADMAN_S = 0.5


@pytest.fixture(scope="module")
def fleet(intersection, tmp_path_factory):
    with LoopbackFleet(intersection, tmp_path_factory.mktemp("operator"), deadman_s=DEADMAN_S) as f:
        assert f.wait_states({"waiting"}, timeout_s=60.0), f.states()
        yield f


@pytest.fixture
def fresh(fleet):
    """Every car waiting at its start, heard by the operator; the same after the test."""
    yield fleet
    fleet.heartbeat.set()
    fleet.session.release()  # whatever the test left latched
    assert fleet.wait_states({"waiting", "arrived"}, timeout_s=10.0), fleet.states()
    fleet.control({"reset": True})
    time.sleep(0.3)


def trustfg(*argv, timeout=30):
    return subprocess.run([sys.executable, "-m", "trustfg", *argv], capture_output=True, text=True, timeout=timeout)


def start_and_wait_moving(fleet, cars=None, lead=0.5):
    cars = fleet.ids if cars is None else cars
    now = time.time()
    trial = fleet.session.start({car: (now + lead, 0.4) for car in cars})
    assert wait_for(lambda: fleet.moving() >= set(cars), 15.0), (fleet.moving(), fleet.states())
    return trial


def test_check_reports_every_cars_pose_link_bus_and_clock(fleet):
    result = trustfg("check", "--config", str(fleet.config), "--wait", "2")
    rows = {line.split()[0]: line for line in result.stdout.splitlines() if line[:1].isdigit()}
    assert set(rows) == {"1", "2", "3", "4"}, result.stdout + result.stderr
    for car in fleet.fleet.cars:
        row = rows[str(car.id)]
        assert f"{car.start[0]:6.2f} {car.start[1]:6.2f}" in row, row  # its map pose: at its start
        assert "answers" in row and "waiting, trial" in row and " ms" in row.split("trial")[-1], row
    assert "nothing missing" in result.stdout and result.returncode == 0, result.stdout + result.stderr


def test_two_trials_in_a_row_without_restarting_a_car_process(fresh):
    fleet = fresh
    first = start_and_wait_moving(fleet)
    fleet.session.abort(trial=first)
    assert fleet.wait_states({"waiting"}, timeout_s=5.0), fleet.states()
    assert wait_for(lambda: not fleet.moving(), 2.0)
    held = time.time()
    time.sleep(1.0)
    assert not fleet.moved_after(held)  # aborted: they hold
    second = start_and_wait_moving(fleet)
    assert second == first + 1
    assert fleet.wait_states({"arrived"}, timeout_s=40.0), fleet.states()
    assert all(seen.trial == second for seen in fleet.session.cars.values())
    pids = {name: p.pid for name, p in fleet.processes.children.items()}
    assert all(fleet.processes.children[name].poll() is None for name in pids)  # the same processes


def test_e_stop_without_any_car_process_and_the_car_stays_stopped_until_released(fresh):
    """SIGSTOP every car process, e-stop straight on the links; the processes, resumed,
    never heard of it and command motion again: the cars must stay stopped."""
    fleet = fresh
    start_and_wait_moving(fleet)
    fleet.pause_cars()
    issued = time.time()
    result = trustfg("stop", "--config", str(fleet.config), "--path", "link", "--wait", "1")
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.count("e-stop latched") == 4, result.stdout
    zero = fleet.zero_at(issued, set(fleet.ids))
    assert all(t is not None for t in zero.values()), zero
    fleet.resume_cars()
    resumed = time.time()
    time.sleep(1.5)
    assert fleet.moved_after(issued) == set(), fleet.commands()[-8:]
    assert all(fleet.processes.children[f"car {car}"].poll() is None for car in fleet.ids)
    assert all(seen.state in ("driving", "stuck", "e_stopped") for seen in fleet.session.cars.values())
    # The car processes learn the latch from their cars' answers, and say so.
    assert fleet.wait_states({"e_stopped"}, timeout_s=3.0), fleet.states()
    assert not fleet.moved_after(resumed)
    released = time.time()
    result = trustfg("stop", "--config", str(fleet.config), "--release")
    assert result.returncode == 0 and result.stdout.count("not latched") == 4, result.stdout + result.stderr
    assert fleet.wait_states({"waiting"}, timeout_s=3.0), fleet.states()
    time.sleep(1.0)
    assert not fleet.moved_after(released)  # released cars wait for a new start


def test_e_stop_on_both_paths_while_driving(fresh):
    fleet = fresh
    start_and_wait_moving(fleet)
    moving = fleet.moving()
    issued = time.time()
    result = trustfg("stop", "--config", str(fleet.config), "--cars", *map(str, sorted(moving)))
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.count("e_stopped") == len(moving), result.stdout  # the bus path confirmed too
    zero = fleet.zero_at(issued, moving)
    assert all(t is not None and t - issued < 1.0 for t in zero.values()), zero
    time.sleep(1.0)
    assert not fleet.moved_after(issued)


def test_killing_the_operators_heartbeat_stops_every_car_within_the_deadman(fresh):
    fleet = fresh
    fleet.heartbeat.clear()  # the test's own session goes quiet: trustfg go is the operator
    go = subprocess.Popen([sys.executable, "-m", "trustfg", "go", "--config", str(fleet.config), "--lead", "0.5"],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        assert wait_for(lambda: fleet.moving() == set(fleet.ids), 20.0), fleet.states()
        time.sleep(0.5)
        killed = time.time()
        go.send_signal(signal.SIGKILL)
        go.wait(5)
        zero = fleet.zero_at(killed, set(fleet.ids))
        assert wait_for(lambda: all(t is not None for t in fleet.zero_at(killed, set(fleet.ids)).values()), 3.0)
        zero = fleet.zero_at(killed, set(fleet.ids))
        assert max(zero.values()) - killed <= DEADMAN_S + 0.1, {c: t - killed for c, t in zero.items()}
        assert fleet.wait_states({"waiting"}, timeout_s=2.0), fleet.states()  # the trial ended
        stopped = max(zero.values())
        fleet.heartbeat.set()  # the operator is back: nobody drives off by that alone
        time.sleep(1.0)
        assert not fleet.moved_after(stopped)
    finally:
        if go.poll() is None:
            go.kill()
        go.communicate()


def test_a_car_process_restarted_by_its_supervisor_does_not_drive_off_by_itself(fresh):
    fleet = fresh
    trial = start_and_wait_moving(fleet)
    fleet.kill_car(2)
    killed = time.time()
    fleet.start_car(2)
    assert wait_for(lambda: fleet.session.cars[2].heard_at > killed and fleet.session.cars[2].trial == 0, 20.0)
    said = f"start of trial {trial} ignored: its departure passed"  # the operator's cached start came
    assert wait_for(lambda: said in (fleet.out / "car_2.log").read_text(), 5.0)
    stopped = fleet.zero_at(killed, {2})[2]
    assert stopped is not None
    time.sleep(2.0)
    assert 2 not in fleet.moved_after(stopped), fleet.commands()[-8:]
    assert fleet.session.cars[2].state == "waiting"

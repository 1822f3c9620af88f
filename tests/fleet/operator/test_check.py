"""trustfg check's table and clock arithmetic (pure): what it reports missing and warns of."""

import pytest

from trustfg.agent import messages
from trustfg.bridge.carlink import Answer, CarState
from trustfg.fleet.launch.launcher import loopback_fleet
from trustfg.fleet.operator.check import Seen, best_offset, report

pytestmark = pytest.mark.realtime


@pytest.fixture
def fleet(intersection):
    return loopback_fleet(intersection, None, None, 0.0)


def all_seen(fleet):
    seen = {}
    for car in fleet.cars:
        status = messages.StatusMessage(car.id, 1, 0.0, "waiting", 0.0, 0, False, {}, 0)
        seen[car.id] = Seen(pose=(car.start[0], car.start[1], car.start_heading), tracked=True,
                            answer=Answer(car.id, 1, 0.0), rtt_ms=0.4, alive=True, status=status,
                            clock=(0.001, 0.0005))
    return seen


def test_a_fleet_that_is_all_there_misses_nothing(fleet):
    out = report(fleet, all_seen(fleet), None, [])
    assert out.missing == [] and out.warnings == []
    assert [row[0] for row in out.rows[1:]] == ["1", "2", "3", "4"]
    assert "answers 0.4 ms" in out.rows[1][4] and out.rows[1][5] == "waiting, trial 0"


def test_what_is_missing_and_what_is_warned_of(fleet):
    seen = all_seen(fleet)
    seen[1].pose, seen[1].tracked = None, False
    seen[2].answer = None
    seen[3].alive, seen[3].status, seen[3].clock = False, None, None
    seen[4].clock = (0.5, 0.001)  # half a second off
    seen[4].answer = Answer(4, 1, 0.0, CarState.E_STOP_LATCHED | CarState.STOPPED)
    car2 = fleet.car(2)
    seen[2].pose = (car2.start[0] + 0.5, car2.start[1], car2.start_heading)
    out = report(fleet, seen, None, [9])
    text = "\n".join(out.missing + out.warnings)
    assert "car 1: rigid body 1 not in the stream" in text
    assert "car 2: no answer on its link" in text and "car 2: 0.50 m from its start" in text
    assert "car 3: its car process is not on the bus" in text
    assert "car 4: its clock is +500 ms off" in text and "E-STOP" in out.rows[4][4] and "WARN" in out.rows[4][6]
    assert "rigid bodies 9 stream but belong to no car" in text
    motive_down = report(fleet, all_seen(fleet), "no SERVERINFO", [])
    assert motive_down.missing == ["Motive: no SERVERINFO"]


def test_the_clock_offset_is_taken_from_the_shortest_round_trip():
    # their clock 0.25 s ahead; the second query had the shortest round trip
    samples = [(10.0, 10.26, 10.02), (11.0, 11.2505, 11.001), (12.0, 12.24, 12.03)]
    offset, spread = best_offset(samples)
    assert offset == pytest.approx(0.25) and spread == pytest.approx(0.0005)
    assert best_offset([]) is None


def test_a_clock_within_its_uncertainty_of_the_tolerance_is_not_warned_of(fleet):
    seen = all_seen(fleet)
    seen[1].clock = (fleet.operator.clock_tolerance_s + 0.004, 0.005)  # could be within
    assert report(fleet, seen, None, []).warnings == []
    seen[1].clock = (-(fleet.operator.clock_tolerance_s + 0.006), 0.005)
    assert len(report(fleet, seen, None, []).warnings) == 1

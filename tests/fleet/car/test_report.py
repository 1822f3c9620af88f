"""What a car process says it waits for (fleet.car.report), in one line."""

import logging

from trustfg.agent.operator_state import Mode
from trustfg.fleet.car.report import WaitingLog, waiting_for


def test_what_a_starting_car_waits_for():
    waiting = waiting_for(motive="10.0.0.2:1510 (no SERVERINFO)", body=None, link="udp://10.0.0.11:9000",
                          absent_peers=[2, 4], mode=Mode.WAITING, hears_operator=False)
    assert waiting == ("Motive at 10.0.0.2:1510 (no SERVERINFO)", "its car to answer on udp://10.0.0.11:9000",
                       "peers 2 4 on the bus", "the operator's start", "the operator's heartbeat")
    assert waiting_for(motive=None, body=3, link=None, absent_peers=[], mode=Mode.E_STOPPED,
                       hears_operator=True) == ("its rigid body 3 tracked in Motive's stream", "the operator's release")
    assert waiting_for(motive=None, body=None, link=None, absent_peers=[], mode=Mode.DRIVING,
                       hears_operator=True) == ()


def test_it_is_said_once_per_change_and_then_as_a_reminder(caplog):
    said = WaitingLog(1, reminder_s=30.0)
    with caplog.at_level(logging.INFO):
        for t in range(10):
            said.say("waiting", ("Motive at x",), float(t))
        said.say("waiting", ("the operator's start",), 10.0)
        said.say("waiting", ("the operator's start",), 41.0)
        said.say("driving", (), 42.0)
    lines = [r.getMessage() for r in caplog.records]
    assert lines == ["car 1 (waiting): waiting for Motive at x", "car 1 (waiting): waiting for the operator's start",
                     "car 1 (waiting): waiting for the operator's start", "car 1 (driving): everything is up"]
    assert all("\n" not in line for line in lines)

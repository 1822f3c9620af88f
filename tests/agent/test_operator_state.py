"""The car's side of the operator's protocol (agent.operator_state): trials, e-stop, deadman."""

import math

import pytest

from trustfg.agent.config import OperatorConfig
from trustfg.agent.messages import StartMessage, StopMessage
from trustfg.agent.operator_state import LATCH_REPORT_GRACE_S, Mode, Operation

CAR = 2


def start(trial, depart, cars=(CAR,), stamp=0.0):
    return StartMessage(trial, stamp, trial, {car: (depart, 0.4) for car in cars})


def stop(action, cars=(), trial=0):
    return StopMessage(1, 0.0, action, tuple(cars), trial)


def driving(config=OperatorConfig(), trial=1, now=10.0):
    op = Operation(CAR, config)
    op.heard_operator(now)
    assert op.take_start(start(trial, now + 1.0), now)
    return op


def test_a_start_drives_from_its_departure_once_per_trial():
    op = Operation(CAR, OperatorConfig())
    assert not op.may_drive(0.0) and op.mode == Mode.WAITING
    assert not op.take_start(start(1, 5.0, cars=(1, 3)), 0.0)  # not for us
    assert op.take_start(start(1, 5.0), 0.0)
    assert (op.mode, op.trial, op.depart_at, op.cruise_mps) == (Mode.DRIVING, 1, 5.0, 0.4)
    assert not op.may_drive(4.9) and op.may_drive(5.0)
    op.arrived()
    assert op.mode == Mode.ARRIVED and not op.may_drive(6.0)
    assert not op.take_start(start(1, 8.0), 6.0)  # the same trial again (a repeat, a cache)
    assert op.take_start(start(2, 8.0), 6.0) and op.may_drive(8.0)  # the next trial


def test_no_start_while_driving_or_e_stopped():
    op = driving()
    assert not op.take_start(start(2, 12.0), 10.5) and op.trial == 1
    assert "abort it first" in op.reason
    op.take_stop(stop("estop"), 10.6)
    assert not op.take_start(start(3, 12.0), 10.7) and "release first" in op.reason


def test_a_start_whose_departure_passed_is_not_taken_unless_rejoining():
    """A car process restarted mid-trial gets the operator's cached start: it must wait."""
    op = Operation(CAR, OperatorConfig())
    assert not op.take_start(start(4, 5.0), 7.0)
    assert op.mode == Mode.WAITING and "restarted car waits" in op.reason
    rejoining = Operation(CAR, OperatorConfig(rejoin_trial=True))
    assert rejoining.take_start(start(4, 5.0), 7.0) and rejoining.may_drive(7.0)


def test_abort_ends_the_named_trial_only():
    op = driving(trial=3)
    assert not op.take_stop(stop("abort", trial=2), 11.0) and op.mode == Mode.DRIVING
    assert not op.take_stop(stop("abort", cars=(1,)), 11.0) and op.mode == Mode.DRIVING
    assert op.take_stop(stop("abort", trial=3), 11.0) and op.mode == Mode.WAITING
    assert not op.may_drive(12.0)
    op = driving(trial=3)
    assert op.take_stop(stop("abort"), 11.0) and op.mode == Mode.WAITING  # trial 0: any


def test_e_stop_latches_every_datagram_until_released_and_release_never_resumes():
    op = driving()
    assert op.take_stop(stop("estop", cars=(1, CAR)), 11.5)
    assert op.mode == Mode.E_STOPPED and not op.may_drive(12.0) and math.isinf(op.depart_at)
    assert all(op.next_flags(12.0).e_stop for _ in range(100))
    op.take_stop(stop("release", cars=(1,)), 13.0)  # another car's release
    assert op.mode == Mode.E_STOPPED
    assert op.take_stop(stop("release"), 13.0) and op.mode == Mode.WAITING
    flags = [op.next_flags(13.0 + 0.02 * k) for k in range(50)]
    assert [f.release for f in flags] == [True] * 40 + [False] * 10  # release_s = 0.8
    assert not any(f.e_stop for f in flags)
    assert not op.may_drive(20.0)  # waits for a new start


def test_no_release_while_driving_so_a_direct_e_stop_holds():
    op = Operation(CAR, OperatorConfig())
    op.take_stop(stop("release"), 1.0)
    assert op.next_flags(1.02).release
    op.heard_operator(1.05)
    assert op.take_start(start(1, 2.0), 1.1)
    assert not any(op.next_flags(1.1 + 0.02 * k).release for k in range(50))


def test_a_release_also_releases_a_latch_it_never_heard_of_and_ends_the_trial():
    op = driving()
    assert op.take_stop(stop("release"), 11.5) and op.mode == Mode.WAITING
    assert op.next_flags(11.52).release


def test_deadman_ends_a_trial_and_blocks_starts_while_the_operator_is_silent():
    op = driving(OperatorConfig(deadman_s=2.0), now=10.0)  # heard at 10.0, departs at 11.0
    assert op.may_drive(11.5) and not op.check_deadman(12.0)
    assert not op.may_drive(12.01)  # already, before the check runs
    assert op.check_deadman(12.01) and op.mode == Mode.WAITING and "deadman" in op.reason
    assert not op.take_start(start(2, 14.0), 12.5) and "heartbeat" in op.reason
    again = op.heard_operator(12.6)  # the start that waited for the operator comes back
    assert again == start(2, 14.0) and op.heard_operator(12.61) is None
    assert op.take_start(again, 12.7)
    off = driving(OperatorConfig(deadman_s=0.0))
    assert not off.check_deadman(1e9) and off.may_drive(1e9)


def test_a_latched_car_makes_the_process_e_stopped_but_not_just_after_a_release():
    op = Operation(CAR, OperatorConfig())
    assert not op.car_reports_latch(False, 0.0)
    assert op.car_reports_latch(True, 0.0) and op.mode == Mode.E_STOPPED
    op.take_stop(stop("release"), 1.0)
    for k in range(40):  # answers from before the RELEASE got through
        op.next_flags(1.0 + 0.02 * k)
        assert not op.car_reports_latch(True, 1.0 + 0.02 * k)
    assert not op.car_reports_latch(True, 1.8 + LATCH_REPORT_GRACE_S - 0.01)
    assert op.car_reports_latch(True, 1.8 + LATCH_REPORT_GRACE_S + 0.01)  # still latched: say so


def test_an_arrived_car_steps_aside_in_its_trial_but_not_unheard_or_e_stopped():
    op = driving(OperatorConfig(deadman_s=2.0), now=10.0)
    op.arrived()
    assert op.step_aside(11.5, peer=3) and op.mode == Mode.DRIVING and op.trial == 1
    assert op.may_drive(11.5) and "car 3" in op.reason
    assert not op.step_aside(11.6, peer=3)  # driving already
    op.arrived()
    assert not op.step_aside(12.5, peer=3) and op.mode == Mode.ARRIVED  # the operator unheard for 2.5 s
    stopped = driving()
    stopped.take_stop(stop("estop"), 11.0)
    assert not stopped.step_aside(11.5, peer=3) and stopped.mode == Mode.E_STOPPED
    waiting = Operation(CAR, OperatorConfig())
    assert not waiting.step_aside(0.0, peer=3) and waiting.mode == Mode.WAITING


def test_start_timeout_drives_without_the_operator():
    op = Operation(CAR, OperatorConfig())
    op.take_start_without_operator(3.0, 0.3)
    assert op.may_drive(3.0) and op.cruise_mps == 0.3


@pytest.mark.parametrize("field, value", [("deadman_s", -1.0), ("deadman_s", 0.1), ("heartbeat_period_s", 0.0),
                                          ("release_s", 0.0), ("clock_tolerance_s", 0.0)])
def test_operator_config_is_checked(field, value):
    from trustfg.agent.config import ConfigError
    with pytest.raises(ConfigError, match=field):
        OperatorConfig(**{field: value}).validate("operator")

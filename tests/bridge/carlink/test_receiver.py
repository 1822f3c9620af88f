"""Car-link receiver rules: sequence numbers, restarts, watchdog, E_STOP and STOP, counters."""

import pytest

from tests.bridge.carlink_helpers import CAR, datagram, forge
from trustfg.bridge.carlink import CarLinkError, CommandFilter, Flags


def test_first_datagram_accepted_whatever_its_seq():
    f = CommandFilter(CAR)
    assert f.active_command(0.0) == (0.0, 0.0)
    assert f.accept(datagram(123456), 0.0) is not None
    assert f.counters.accepted == 1 and f.counters.rejected == 0


def test_in_order_and_gaps_accepted_repeats_and_old_dropped():
    f = CommandFilter(CAR)
    for seq in (10, 11, 15, 1000):
        assert f.accept(datagram(seq), 0.0) is not None
    assert f.accept(datagram(1000), 0.01) is None  # repeat
    assert f.accept(datagram(999), 0.02) is None  # overtaken / replayed
    assert f.accept(datagram(11), 0.03) is None
    c = f.counters
    assert (c.accepted, c.repeated_seq, c.stale_seq) == (4, 1, 2)
    assert f.last_command.seq == 1000


def test_replayed_capture_dropped_and_counted():
    f = CommandFilter(CAR)
    capture = [datagram(seq, v=0.1 * (seq % 3)) for seq in range(100, 120)]
    for i, data in enumerate(capture):
        assert f.accept(data, 0.01 * i) is not None
    for i, data in enumerate(capture):
        assert f.accept(data, 0.2 + 0.01 * i) is None
    assert f.counters.accepted == 20
    assert f.counters.repeated_seq + f.counters.stale_seq == 20
    assert f.last_command.seq == 119


def test_sequence_wraps_around():
    f = CommandFilter(CAR)
    seqs = [0xFFFFFFFD, 0xFFFFFFFE, 0xFFFFFFFF, 0, 1, 2]
    for i, seq in enumerate(seqs):
        assert f.accept(datagram(seq), 0.01 * i) is not None, seq
    assert f.accept(datagram(0xFFFFFFFF), 0.1) is None
    assert f.accept(datagram(0xFFFFFFF0), 0.1) is None
    assert f.counters.stale_seq == 2 and f.counters.accepted == len(seqs)


def test_spoofed_car_id_dropped_and_counted():
    f = CommandFilter(CAR)
    f.accept(datagram(5, v=0.2), 0.0)
    assert f.accept(datagram(6, car_id=CAR + 1, v=1.0), 0.01) is None
    assert f.accept(datagram(6, car_id=CAR + 1, flags=Flags.E_STOP), 0.02) is None
    assert f.counters.wrong_car == 2
    assert not f.e_stop_latched and f.last_command.seq == 5
    assert f.accept(datagram(6, v=0.3), 0.03).v_mps == pytest.approx(0.3)


def test_decode_errors_counted_by_reason_and_never_raised():
    f = CommandFilter(CAR)
    for data in (b"", forge(magic=b"XX"), forge(version=9), forge(crc=0), forge(car_id=0),
                 forge(v=float("nan")), forge(flags=0x10), "not bytes", None):
        assert f.accept(data, 0.0) is None  # type: ignore[arg-type]
    c = f.counters
    assert c.decode_errors == {"length": 1, "magic": 1, "version": 1, "crc": 1, "car_id": 1,
                               "non_finite": 1, "flags": 1, "type": 2}
    assert c.decode_error == c.rejected == 9 and c.accepted == 0


def test_watchdog_stops_exactly_after_250_ms():
    f = CommandFilter(CAR)
    f.accept(datagram(1, v=0.5, omega=-0.25), 1.0)
    assert f.active_command(1.0) == (0.5, -0.25)
    assert f.active_command(1.2499) == (0.5, -0.25)
    assert f.active_command(1.25) == (0.0, 0.0)
    assert f.active_command(7.0) == (0.0, 0.0)
    f.accept(datagram(2, v=0.5, omega=-0.25), 1.5)
    assert f.active_command(1.5) == (0.5, -0.25)
    assert f.active_command(1.75) == (0.0, 0.0)


def test_watchdog_counts_only_accepted_commands():
    f = CommandFilter(CAR)
    f.accept(datagram(10, v=0.5), 1.0)
    for i in range(1, 20):  # replays, other cars and noise keep arriving
        now = 1.0 + 0.02 * i
        f.accept(datagram(10, v=0.5), now)
        f.accept(datagram(11, car_id=9, v=0.5), now)
        f.accept(b"\x00" * 30, now)
    assert f.active_command(1.25) == (0.0, 0.0)


def test_watchdog_timeout_is_a_parameter():
    f = CommandFilter(CAR, watchdog_timeout_s=0.5, resync_after_s=2.0)
    f.accept(datagram(1, v=0.5), 0.0)
    assert f.active_command(0.4375) == (0.5, 0.25) and f.active_command(0.5) == (0.0, 0.0)


def test_stop_holds_still_without_latching():
    f = CommandFilter(CAR)
    f.accept(datagram(1, v=0.5, flags=Flags.STOP), 0.0)
    assert f.active_command(0.01) == (0.0, 0.0) and not f.e_stop_latched
    f.accept(datagram(2, v=0.5), 0.02)
    assert f.active_command(0.03) == (0.5, 0.25)


def test_e_stop_latches_until_a_release():
    f = CommandFilter(CAR)
    f.accept(datagram(1, v=0.5), 0.0)
    f.accept(datagram(2, v=0.5, flags=Flags.E_STOP), 0.02)
    assert f.e_stop_latched and f.active_command(0.03) == (0.0, 0.0)
    f.accept(datagram(3, v=0.5, flags=Flags.E_STOP), 0.04)
    assert f.active_command(0.05) == (0.0, 0.0)
    # nothing short of an accepted RELEASE releases it: not ordinary commands in sequence
    # (a car process that never heard of the e-stop keeps driving), not stale, foreign or
    # corrupted releases, not silence
    for seq in range(2, 60):
        assert f.accept(datagram(seq, v=0.5), 0.06 + 0.02 * seq) is not None
    f.accept(datagram(40, v=0.5, flags=Flags.RELEASE), 1.3)  # stale
    f.accept(datagram(60, car_id=CAR + 1, v=0.5, flags=Flags.RELEASE), 1.3)  # other car
    f.accept(forge(seq=60, flags=int(Flags.RELEASE), crc=0), 1.3)  # corrupted
    assert f.e_stop_latched and f.active_command(1.31) == (0.0, 0.0)
    assert f.active_command(100.0) == (0.0, 0.0) and f.e_stop_latched
    # released by RELEASE|STOP in sequence, but STOP still holds the car
    f.accept(datagram(60, v=0.5, flags=Flags.RELEASE | Flags.STOP), 100.0)
    assert not f.e_stop_latched and f.active_command(100.01) == (0.0, 0.0)
    f.accept(datagram(61, v=0.5), 100.02)
    assert f.active_command(100.03) == (0.5, 0.25)


def test_an_e_stop_from_a_second_sender_latches_out_of_sequence_and_leaves_the_stream_alone():
    """The operator's e-stop, straight to the car: its numbers are not the car process's."""
    f = CommandFilter(CAR)
    for seq in range(1000, 1010):
        f.accept(datagram(seq, v=0.5), 0.02 * (seq - 1000))
    operator = datagram(7, v=0.0, flags=Flags.E_STOP | Flags.STOP | Flags.PING)  # 'old' number
    assert f.accept(operator, 0.2) is not None
    assert f.e_stop_latched and f.active_command(0.2) == (0.0, 0.0)
    assert f.counters.e_stops == 1 and f.counters.stale_seq == 0
    # the car process's stream goes on in sequence (no resync hiccup), and the car holds
    assert f.accept(datagram(1010, v=0.5), 0.22) is not None
    assert f.last_command.seq == 1010 and f.active_command(0.23) == (0.0, 0.0)
    # an operator's e-stop numbered 'ahead' of the stream does not move the reference either
    f.accept(datagram(1010 + 2**20, v=0.0, flags=Flags.E_STOP), 0.24)
    assert f.accept(datagram(1011, v=0.5, flags=Flags.RELEASE), 0.26) is not None
    assert not f.e_stop_latched and f.active_command(0.27) == (0.5, 0.25)


def test_a_ping_is_answered_and_never_applied():
    f = CommandFilter(CAR)
    f.accept(datagram(100, v=0.5), 0.0)
    ping = f.accept(datagram(5, v=0.9, flags=Flags.PING, stamp_s=12.5), 0.01)
    assert ping is not None and ping.ping
    assert f.active_command(0.02) == (0.5, 0.25) and f.last_command.seq == 100
    answer = f.answer(ping, 0.02)
    assert (answer.car_id, answer.seq, answer.stamp_s) == (CAR, 5, 12.5)
    assert not answer.e_stop_latched and not answer.stopped
    assert f.answer(ping, 0.3).stopped  # the watchdog has stopped it by then
    f.accept(datagram(6, flags=Flags.E_STOP | Flags.PING), 0.31)
    assert f.answer(ping, 0.31).e_stop_latched
    assert f.counters.pings == 2 and f.counters.accepted == 1


def test_restarted_sender_is_resynced_after_silence():
    f = CommandFilter(CAR)  # watchdog 0.25 s, resync 1.0 s
    f.accept(datagram(5000, v=0.5), 10.0)
    # the car process restarts 0.1 s later and starts over at seq 0, streaming at 50 Hz
    for seq in range(45):
        t = 10.1 + 0.02 * seq  # up to 10.98
        assert f.accept(datagram(seq, v=0.3), t) is None
        assert f.active_command(t) == ((0.5, 0.25) if t < 10.25 else (0.0, 0.0))
    seq = 45
    assert f.counters.stale_seq == seq and f.counters.resynced == 0
    # one second after the last accepted command: the car has stood still for 0.75 s
    assert f.active_command(11.0) == (0.0, 0.0)
    assert f.accept(datagram(seq, v=0.3), 11.0) is not None
    assert f.counters.resynced == 1
    assert f.accept(datagram(seq + 1, v=0.3), 11.02) is not None
    assert f.active_command(11.05)[0] == pytest.approx(0.3)


def test_no_resync_before_the_silence():
    f = CommandFilter(CAR, watchdog_timeout_s=0.25, resync_after_s=1.0)
    f.accept(datagram(100), 0.0)
    assert f.accept(datagram(3), 0.999) is None
    assert f.accept(datagram(3), 1.0) is not None
    assert f.counters.resynced == 1 and f.counters.repeated_seq == 0 and f.counters.stale_seq == 1


def test_filter_parameters_are_checked():
    with pytest.raises(ValueError, match="resync_after_s"):
        CommandFilter(CAR, watchdog_timeout_s=0.25, resync_after_s=0.2)
    with pytest.raises(ValueError, match="watchdog_timeout_s"):
        CommandFilter(CAR, watchdog_timeout_s=0.0)
    with pytest.raises(CarLinkError):
        CommandFilter(0)

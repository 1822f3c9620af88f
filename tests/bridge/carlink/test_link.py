"""Car-link sockets: the sender's numbering, stamps and STOPs, and loopback through the receiver."""

import socket
import struct
import threading
import time

import pytest

from tests.bridge.carlink_helpers import CAR, datagram, forge
from trustfg.bridge.carlink import (
    CarLinkError,
    CommandFilter,
    CommandReceiver,
    CommandSender,
    Flags,
    decode_command,
    encode_command,
)

pytestmark = pytest.mark.realtime

# --------------------------------------------------------------------------- sender


@pytest.fixture
def udp_sink():
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(2.0)
    yield sock
    sock.close()


def drain(sock, count):
    return [decode_command(sock.recvfrom(2048)[0]) for _ in range(count)]


def test_sender_stamps_numbers_and_wraps(udp_sink):
    stamps = iter([100.0, 100.02, 100.04, 100.06, 100.08, 100.1])
    with CommandSender(CAR, udp_sink.getsockname(), stamp_clock=lambda: next(stamps),
                       first_seq=0xFFFFFFFE, stop_repeats=0) as tx:
        for _ in range(3):
            tx.send(0.25, -0.5)
    got = drain(udp_sink, 3)
    assert [c.seq for c in got] == [0xFFFFFFFE, 0xFFFFFFFF, 0]
    assert [c.stamp_s for c in got] == [100.0, 100.02, 100.04]
    assert all((c.car_id, c.v_mps, c.omega_radps, c.flags) == (CAR, 0.25, -0.5, 0) for c in got)
    assert tx.stats.sent == 3 and tx.stats.send_errors == 0


def test_sender_stop_sends_stop_and_close_is_idempotent(udp_sink):
    tx = CommandSender(CAR, udp_sink.getsockname(), stop_repeats=3, stop_spacing_s=0.0)
    tx.send(0.3, 0.0)
    tx.close()
    tx.close()
    got = drain(udp_sink, 4)
    assert [c.flags for c in got[1:]] == [Flags.STOP] * 3
    assert [c.seq for c in got] == [0, 1, 2, 3]
    with pytest.raises(RuntimeError):
        tx.send(0.1, 0.0)


def test_shutdown_keeps_an_e_stop_on(udp_sink):
    with CommandSender(CAR, udp_sink.getsockname(), stop_repeats=2, stop_spacing_s=0.0) as tx:
        tx.send(0.0, 0.0, Flags.E_STOP)
    got = drain(udp_sink, 3)
    assert [c.flags for c in got] == [Flags.E_STOP, Flags.E_STOP | Flags.STOP, Flags.E_STOP | Flags.STOP]
    f = CommandFilter(CAR)
    for i, c in enumerate(got):
        f.accept(encode_command(c), 0.01 * i)
    assert f.e_stop_latched


def test_shutdown_after_an_e_stop_released_sends_plain_stop(udp_sink):
    with CommandSender(CAR, udp_sink.getsockname(), stop_repeats=1) as tx:
        tx.send(0.0, 0.0, Flags.E_STOP)
        tx.send(0.2, 0.0)  # the last command decides: the e-stop was released
    assert [c.flags for c in drain(udp_sink, 3)] == [Flags.E_STOP, Flags.NONE, Flags.STOP]


def test_sender_rejects_invalid_commands(udp_sink):
    with CommandSender(CAR, udp_sink.getsockname(), stop_repeats=0) as tx:
        with pytest.raises(CarLinkError):
            tx.send(float("nan"), 0.0)
        with pytest.raises(CarLinkError):
            tx.send(0.0, 0.0, flags=0x80)
        assert tx.stats.sent == 0
        tx.send(0.1, 0.0)
    assert drain(udp_sink, 1)[0].seq == 0  # a rejected command uses up no sequence number


def test_sender_parameters_are_checked(udp_sink):
    with pytest.raises(CarLinkError):
        CommandSender(0, udp_sink.getsockname())
    with pytest.raises(CarLinkError):
        CommandSender(CAR, udp_sink.getsockname(), first_seq=2**32)


# ---------------------------------------------------------------- loopback integration


@pytest.fixture
def no_threads_left():
    yield
    left = [t.name for t in threading.enumerate() if t.name.startswith("carlink-")]
    assert not left, f"threads left behind: {left}"


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def test_loopback_50_hz_all_accepted_then_stopped(no_threads_left):
    with CommandReceiver(CAR, ("127.0.0.1", 0)) as rx:
        with CommandSender(CAR, rx.address) as tx:
            for _ in range(51):  # one second at 50 Hz, as the car process's control loop sends
                tx.send(0.3, 0.1)
                time.sleep(0.02)
            assert rx.wait_until(lambda c: c.accepted >= 51, timeout_s=5.0)
            assert rx.active_command() == (f32(0.3), f32(0.1))
            tx.stop()
            stats = tx.stats
            assert stats.sent == 51 + 3
            assert rx.wait_until(lambda c: c.accepted >= stats.sent, timeout_s=2.0)
            assert rx.active_command() == (0.0, 0.0)  # the STOP datagrams
            assert rx.last_command.stop
        assert stats.send_errors == 0
        total = tx.stats.sent  # close() sent its STOPs as well
        assert total == stats.sent + 3
        assert rx.wait_until(lambda c: c.accepted >= total, timeout_s=2.0)
        counters = rx.counters
        assert counters.accepted == total
        assert counters.rejected == 0 and rx.receive_errors == 0


def test_loopback_watchdog_after_sender_goes_silent(no_threads_left):
    with CommandReceiver(CAR, ("127.0.0.1", 0)) as rx:
        tx = CommandSender(CAR, rx.address, stop_repeats=0)
        for _ in range(5):
            tx.send(0.2, 0.0)
            time.sleep(0.01)
        tx.close()  # no STOP datagrams: the sender just goes silent
        sent = tx.stats.sent
        assert rx.wait_until(lambda c: c.accepted >= sent, timeout_s=2.0)
        assert rx.last_command.v_mps == pytest.approx(0.2) and not rx.last_command.stop
        assert rx.active_command(time.monotonic() + 0.25) == (0.0, 0.0)


def test_receiver_thread_counts_foreign_and_garbage(no_threads_left):
    with CommandReceiver(CAR, ("127.0.0.1", 0)) as rx, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as raw:
        raw.sendto(datagram(1, car_id=CAR + 1), rx.address)
        raw.sendto(b"hello", rx.address)
        raw.sendto(forge() * 3, rx.address)  # oversized: not truncated to a valid one
        raw.sendto(datagram(1, v=0.4), rx.address)
        assert rx.wait_until(lambda c: c.accepted + c.rejected >= 4, timeout_s=2.0)
        c = rx.counters
        assert (c.accepted, c.wrong_car, c.decode_errors) == (1, 1, {"length": 2})


def test_close_is_bounded_and_joins(no_threads_left):
    rx = CommandReceiver(CAR, ("127.0.0.1", 0), recv_timeout_s=0.1)
    rx.start()
    tx = CommandSender(CAR, rx.address, stop_repeats=1)
    tx.send(0.1, 0.0)
    started = time.monotonic()
    tx.close()
    rx.close()
    rx.close()
    assert time.monotonic() - started < 1.0

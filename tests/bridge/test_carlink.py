"""Car link: codec golden bytes and rejections, receiver rules, sender, loopback I/O."""

import re
import socket
import struct
import threading
import time
import zlib

import pytest

from trustfg.bridge.carlink import (
    DATAGRAM_SIZE,
    CarLinkError,
    Command,
    CommandFilter,
    CommandReceiver,
    CommandSender,
    Flags,
    codec,
    decode_command,
    encode_command,
    seq_after,
)

CAR = 3
GOLDEN = Command(CAR, 0x01020304, 12.5, 0.25, -0.5)
GOLDEN_HEX = ("54 46 01 03 04 03 02 01 00 00 00 00 00 00 29 40 "
              "00 00 80 3e 00 00 00 bf 00 00 bb 42 e0 c0")
GOLDEN_E_STOP = Command(7, 0xFFFFFFFF, 1234.0625, 0.0, 0.0, Flags.E_STOP)
GOLDEN_E_STOP_HEX = ("54 46 01 07 ff ff ff ff 00 00 00 00 40 48 93 40 "
                     "00 00 00 00 00 00 00 00 01 00 0b 9d 69 e9")


def forge(magic=b"TF", version=1, car_id=CAR, seq=1, stamp_s=1.0, v=0.5, omega=0.25, flags=0,
          crc=None):
    """Raw datagram with any field values (the codec would refuse to build some of them)."""
    body = struct.pack("<2sBBIdffH", magic, version, car_id, seq, stamp_s, v, omega, flags)
    return body + struct.pack("<I", zlib.crc32(body) if crc is None else crc)


def datagram(seq, car_id=CAR, v=0.5, omega=0.25, flags=Flags.NONE, stamp_s=0.0):
    return encode_command(Command(car_id, seq, stamp_s, v, omega, flags))


# ------------------------------------------------------------------------------ codec


def test_golden_bytes():
    assert encode_command(GOLDEN) == bytes.fromhex(GOLDEN_HEX)
    assert decode_command(bytes.fromhex(GOLDEN_HEX)) == GOLDEN
    assert encode_command(GOLDEN_E_STOP) == bytes.fromhex(GOLDEN_E_STOP_HEX)
    assert decode_command(bytes.fromhex(GOLDEN_E_STOP_HEX)) == GOLDEN_E_STOP


def test_worked_example_in_docstring_is_the_golden_datagram():
    doc = codec.__doc__
    example = doc[doc.index("Worked example"):]
    hex_lines = re.findall(r"^ {4}((?:[0-9a-f]{2} ?)+)$", example, flags=re.MULTILINE)
    assert bytes.fromhex(" ".join(hex_lines)) == encode_command(GOLDEN)
    assert "0xC0E042BB" in example and zlib.crc32(encode_command(GOLDEN)[:26]) == 0xC0E042BB


def crc32_bitwise(data: bytes) -> int:
    """The CRC as the module docstring tells a firmware writer to compute it."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0xEDB88320 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def test_documented_crc_parameters_are_zlib():
    assert crc32_bitwise(b"123456789") == zlib.crc32(b"123456789") == 0xCBF43926
    body = encode_command(GOLDEN)[:26]
    assert crc32_bitwise(body) == struct.unpack("<I", encode_command(GOLDEN)[26:])[0]


def test_layout_offsets():
    data = encode_command(Command(200, 0xA1B2C3D4, -3.0, 1.5, -2.0, Flags.STOP | Flags.E_STOP))
    assert len(data) == DATAGRAM_SIZE == 30
    assert data[0:2] == b"TF" and data[2] == 1 and data[3] == 200
    assert struct.unpack_from("<I", data, 4)[0] == 0xA1B2C3D4
    assert struct.unpack_from("<d", data, 8)[0] == -3.0
    assert struct.unpack_from("<ff", data, 16) == (1.5, -2.0)
    assert struct.unpack_from("<H", data, 24)[0] == 0x0003


@pytest.mark.parametrize("data, reason", [
    (b"", "length"),
    (forge()[:-1], "length"),
    (forge() + b"\x00", "length"),
    (forge(magic=b"FT"), "magic"),
    (forge(version=0), "version"),
    (forge(version=2), "version"),
    (forge(crc=zlib.crc32(forge()[:26]) ^ 1), "crc"),
    (forge()[:10] + b"\x01" + forge()[11:], "crc"),
    (forge(car_id=0), "car_id"),
    (forge(v=float("nan")), "non_finite"),
    (forge(v=float("inf")), "non_finite"),
    (forge(omega=float("-inf")), "non_finite"),
    (forge(omega=float("nan")), "non_finite"),
    (forge(stamp_s=float("nan")), "non_finite"),
    (forge(flags=0x0004), "flags"),
    (forge(flags=0x8001), "flags"),
], ids=lambda x: x if isinstance(x, str) else None)
def test_decode_rejects_with_reason(data, reason):
    with pytest.raises(CarLinkError) as err:
        decode_command(data)
    assert err.value.reason == reason
    assert isinstance(err.value, ValueError)
    assert reason in str(err.value)


def test_decode_rejects_non_bytes_with_carlink_error():
    with pytest.raises(CarLinkError, match="type"):
        decode_command("TF" * 15)  # type: ignore[arg-type]


def test_decode_accepts_bytearray_and_memoryview():
    data = encode_command(GOLDEN)
    assert decode_command(bytearray(data)) == decode_command(memoryview(data)) == GOLDEN


@pytest.mark.parametrize("fields, reason", [
    (dict(car_id=0), "car_id"),
    (dict(car_id=256), "car_id"),
    (dict(seq=-1), "range"),
    (dict(seq=2**32), "range"),
    (dict(v_mps=float("nan")), "non_finite"),
    (dict(omega_radps=1e39), "range"),
    (dict(stamp_s=float("inf")), "non_finite"),
    (dict(flags=4), "flags"),
    (dict(car_id=1.5), "type"),
    (dict(v_mps="fast"), "type"),
])
def test_command_validates_fields(fields, reason):
    base = dict(car_id=1, seq=0, stamp_s=0.0, v_mps=0.0, omega_radps=0.0, flags=0)
    with pytest.raises(CarLinkError) as err:
        Command(**{**base, **fields})
    assert err.value.reason == reason


def test_command_flags_become_flags():
    cmd = Command(1, 0, 0.0, 0.0, 0.0, 3)
    assert isinstance(cmd.flags, Flags) and cmd.flags == Flags.E_STOP | Flags.STOP
    assert cmd.e_stop and cmd.stop


def test_encode_rounds_to_f32():
    cmd = decode_command(encode_command(Command(1, 0, 0.1, 0.1, 0.1)))
    assert cmd.stamp_s == 0.1  # f64 kept exactly
    assert cmd.v_mps == struct.unpack("<f", struct.pack("<f", 0.1))[0] != 0.1


# --------------------------------------------------------------- sequence arithmetic


@pytest.mark.parametrize("seq, last, after", [
    (1, 0, True), (0, 1, False), (5, 5, False),
    (0, 0xFFFFFFFF, True), (0xFFFFFFFF, 0, False), (10, 0xFFFFFFF0, True),
    (2**31 - 1, 0, True), (2**31, 0, False), (0, 2**31, False),
])
def test_seq_after(seq, last, after):
    assert seq_after(seq, last) is after


# --------------------------------------------------------------------- receiver logic


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


def test_e_stop_latches_until_a_command_without_it():
    f = CommandFilter(CAR)
    f.accept(datagram(1, v=0.5), 0.0)
    f.accept(datagram(2, v=0.5, flags=Flags.E_STOP), 0.02)
    assert f.e_stop_latched and f.active_command(0.03) == (0.0, 0.0)
    f.accept(datagram(3, v=0.5, flags=Flags.E_STOP), 0.04)
    assert f.active_command(0.05) == (0.0, 0.0)
    # nothing short of an accepted command without E_STOP releases it
    f.accept(datagram(2, v=0.5), 0.06)  # stale
    f.accept(datagram(4, car_id=CAR + 1, v=0.5), 0.07)  # other car
    f.accept(forge(seq=4, flags=0, crc=0), 0.08)  # corrupted
    assert f.e_stop_latched and f.active_command(0.09) == (0.0, 0.0)
    assert f.active_command(100.0) == (0.0, 0.0) and f.e_stop_latched  # silence neither
    # released by STOP without E_STOP, but STOP still holds the car
    f.accept(datagram(4, v=0.5, flags=Flags.STOP), 100.0)
    assert not f.e_stop_latched and f.active_command(100.01) == (0.0, 0.0)
    f.accept(datagram(5, v=0.5), 100.02)
    assert f.active_command(100.03) == (0.5, 0.25)


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

"""The C reference of the car link (firmware/carlink/) against the Python one: SHA-256 and
HMAC (RFC 4231), the golden datagrams and answers, random datagram streams fed to both
(every verdict, decoded field, answer byte, motor command and counter the same), the MCU
example on a simulated board, the POSIX car, and a sanitizer build under mutation fuzzing."""

from __future__ import annotations

import ctypes
import hashlib
import hmac
import math
import random
import re
import socket
import struct
import subprocess
import zlib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.bridge.carlink.test_answer import GOLDEN as GOLDEN_ANSWER
from tests.bridge.carlink.test_codec import GOLDEN, GOLDEN_E_STOP, GOLDEN_E_STOP_HEX, GOLDEN_HEX
from tests.bridge.carlink.test_codec_v2 import DOC_KEY, SESSION, by_hand
from tests.bridge.carlink_helpers import forge
from tests.conftest import wait_for
from tests.firmware.carlink_reference import (
    FIRMWARE,
    HERE,
    SANITIZE,
    VERDICTS,
    CCar,
    build,
    build_posix,
    load_harness,
    posix_car,
)
from trustfg.bridge.carlink import (
    Answer,
    CarState,
    Command,
    CommandFilter,
    CommandSender,
    FilterCounters,
    Flags,
    answer,
    codec,
    decode_answer,
    encode_answer,
    encode_command,
    encode_command_v2,
    write_key_file,
)

pytestmark = pytest.mark.realtime  # the POSIX car on loopback, and C programs run as processes

CAR = 3
KEY = bytes(range(100, 132))
OTHER_KEY = bytes(range(1, 33))


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return load_harness(tmp_path_factory.mktemp("carlink") / "carlink_harness.so")


def documented(doc: str, start: str, end: str | None = None) -> bytes:
    """The hex lines of a worked example in a module docstring."""
    part = doc[doc.index(start):]
    part = part[part.index("Worked example"):]
    if end:
        part = part[:part.index(end)]
    return bytes.fromhex(" ".join(re.findall(r"^ {4}((?:[0-9a-f]{2} ?)+)$", part, flags=re.M)))


# ----------------------------------------------------------------- primitives


RFC_4231 = [  # (key, data, HMAC-SHA-256) of RFC 4231 section 4; case 5 truncated to 128 bits
    (b"\x0b" * 20, b"Hi There", "b0344c61d8db38535ca8afceaf0bf12b881dc200c9833da726e9376c2e32cff7"),
    (b"Jefe", b"what do ya want for nothing?", "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"),
    (b"\xaa" * 20, b"\xdd" * 50, "773ea91e36800e46854db8ebd09181a72959098b3ef8c122d9635514ced565fe"),
    (bytes(range(1, 26)), b"\xcd" * 50, "82558a389a443c0ea4cc819899f2083a85f0faa3e578f8077a2e3ff46729665b"),
    (b"\x0c" * 20, b"Test With Truncation", "a3b6167473100ee06e0c796c2955552b"),
    (b"\xaa" * 131, b"Test Using Larger Than Block-Size Key - Hash Key First",
     "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54"),
    (b"\xaa" * 131, b"This is a test using a larger than block-size key and a larger than block-size data. The "
                    b"key needs to be hashed before being used by the HMAC algorithm.",
     "9b09ffa71b942fcb27635fbcd5b0e944bfdc63644f0713938a7f51535c3a35e2"),
]


def c_hmac(lib, key: bytes, data: bytes) -> bytes:
    out = ctypes.create_string_buffer(32)
    lib.carlink_hmac_sha256(key, len(key), data, len(data), out)
    return out.raw


@pytest.mark.parametrize("case", range(1, 8))
def test_hmac_sha256_gives_the_rfc_4231_vectors(lib, case):
    key, data, expected = RFC_4231[case - 1]
    mac = c_hmac(lib, key, data)
    assert mac[:len(expected) // 2].hex() == expected
    assert mac == hmac.new(key, data, hashlib.sha256).digest()


def test_sha256_agrees_with_hashlib_at_every_length_around_the_blocks(lib):
    out = ctypes.create_string_buffer(32)
    for n in [*range(0, 130), 1000, 4097]:
        data = bytes((i * 131 + n) & 0xFF for i in range(n))
        lib.carlink_sha256(data, n, out)
        assert out.raw == hashlib.sha256(data).digest(), n
    lib.carlink_sha256(b"abc", 3, out)
    assert out.raw.hex() == "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"  # FIPS 180-4


def test_crc32_is_zlibs(lib):
    assert lib.carlink_crc32(b"123456789", 9) == 0xCBF43926
    for n in range(0, 70, 7):
        data = bytes(range(n))
        assert lib.carlink_crc32(data, n) == zlib.crc32(data)


# ---------------------------------------------------------------- golden vectors


def fields(got: dict) -> Command:
    """The C car's decoded command as a Python Command."""
    stamp, = struct.unpack("<d", struct.pack("<Q", got["stamp_bits"]))
    v, omega = struct.unpack("<ff", struct.pack("<II", got["v_bits"], got["omega_bits"]))
    return Command(got["car_id"], got["seq"], stamp, v, omega, Flags(got["flags"]), got["session"], got["source"])


def test_the_golden_datagrams_decode_to_the_same_commands(lib):
    v1_example = documented(codec.__doc__, "Datagram (version 1", "Datagram (version 2")
    assert v1_example == bytes.fromhex(GOLDEN_HEX)
    v2_example = documented(codec.__doc__, "Datagram (version 2", "(the MAC is the last 16 bytes)")
    assert v2_example == by_hand(DOC_KEY)
    cases = [
        (v1_example, None, GOLDEN, "accepted"),
        (bytes.fromhex(GOLDEN_E_STOP_HEX), None, GOLDEN_E_STOP, "e_stop"),
        (v2_example, DOC_KEY, Command(CAR, 7, 12.5, 0.25, -0.5, session=SESSION), "accepted"),
    ]
    for data, key, command, verdict in cases:
        car = CCar(lib, command.car_id, key)
        got = car.receive(data, 0)
        assert got["verdict"] == verdict and fields(got) == command
        assert got["version"] == (2 if key else 1)
        assert CommandFilter(command.car_id, key=key).accept(data, 0.0) == command
        if verdict == "accepted":
            assert car.motors(0) == (0.25, -0.5, False)


def test_the_golden_answers_are_built_byte_for_byte(lib):
    """answer.py's worked example (version 1, e-stop latched), and its version 2 by hand."""
    expected = documented(answer.__doc__, "Answer (version 1")
    assert expected == encode_answer(GOLDEN_ANSWER)
    ping = encode_command(Command(CAR, 7, 12.5, 0.0, 0.0, Flags.E_STOP | Flags.PING))
    assert CCar(lib, CAR).receive(ping, 0)["answer"] == expected
    ping = by_hand(DOC_KEY, source=1, flags=int(Flags.E_STOP | Flags.PING), v=0.0, omega=0.0)
    body = b"TA" + bytes([2, CAR, 1, 0]) + struct.pack("<HQId", 3, SESSION, 7, 12.5)
    assert CCar(lib, CAR, DOC_KEY).receive(ping, 0)["answer"] == body + hmac.new(DOC_KEY, body, "sha256").digest()[:16]


V1_REJECTIONS = [b"", forge()[:-1], forge() + b"\0", forge(magic=b"FT"), forge(version=0), forge(version=2),
                 forge(crc=zlib.crc32(forge()[:26]) ^ 1), forge(car_id=0), forge(v=float("nan")),
                 forge(omega=float("-inf")), forge(stamp_s=float("nan")), forge(flags=0x0010), forge(flags=0x0005),
                 forge(flags=0x8001), forge(flags=0x0010, v=float("nan")), forge(car_id=0, flags=0x10)]
V2_REJECTIONS = [by_hand(KEY)[:51], by_hand(KEY) + b"\0", b"XX" + by_hand(KEY)[2:], by_hand(KEY)[:2] + b"\x01" +
                 by_hand(KEY)[3:], by_hand(OTHER_KEY), by_hand(KEY)[:-1] + b"\0", by_hand(KEY, reserved=1),
                 by_hand(KEY, car_id=0), by_hand(KEY, flags=0x20), by_hand(KEY, flags=0x05),
                 by_hand(KEY, v=float("inf")), by_hand(KEY, stamp=float("nan")), by_hand(KEY, reserved=1, car_id=0),
                 by_hand(KEY, flags=0x10, v=float("nan")), encode_command(GOLDEN)]


@pytest.mark.parametrize("key, data", [(None, d) for d in V1_REJECTIONS] + [(KEY, d) for d in V2_REJECTIONS])
def test_every_rejection_has_pythons_reason(lib, key, data):
    """The checks in codec.py's order: the first failed one is the reason, in C as in Python."""
    python = CommandFilter(CAR, key=key)
    assert python.accept(data, 0.0) is None
    (reason,) = python.counters.decode_errors
    got = CCar(lib, CAR, key).receive(data, 0)
    assert got["verdict"] == reason and got["answer"] == b""


def test_parameters_are_checked_as_the_python_filter_checks_them(lib):
    assert CCar(lib, CAR).init_result == 0
    for car_id, watchdog, resync in ((0, 250, 1000), (CAR, 0, 1000), (CAR, 250, 250), (CAR, 250, 200)):
        assert CCar(lib, car_id, None, watchdog, resync).init_result == -1
        with pytest.raises(ValueError):
            CommandFilter(car_id, watchdog_timeout_s=watchdog / 1000, resync_after_s=resync / 1000)


def test_the_watchdog_stops_at_exactly_250_ms_also_across_the_clocks_wrap(lib):
    for start in (1000, 0xFFFFFF80):
        car = CCar(lib, CAR)
        assert car.receive(encode_command(Command(CAR, 1, 0.0, 0.5, -0.25)), start)["verdict"] == "accepted"
        assert car.motors(start + 249) == (0.5, -0.25, False)
        assert car.motors(start + 250) == (0.0, 0.0, True)


# ------------------------------------------------- random streams: C and Python agree


def python_verdict(before: FilterCounters, after: FilterCounters) -> str:
    reasons = [r for r, n in after.decode_errors.items() if n != before.decode_errors.get(r, 0)]
    if reasons:
        return reasons[0]
    for counter, verdict in (("e_stops", "e_stop"), ("pings", "ping"), ("accepted", "accepted"),
                             ("wrong_car", "wrong_car"), ("repeated_seq", "repeated_seq"),
                             ("stale_seq", "stale_seq"), ("old_session", "old_session")):
        if getattr(after, counter) != getattr(before, counter):
            return verdict
    raise AssertionError("no counter moved")


def counters(c: FilterCounters) -> dict:
    names = ("accepted", "resynced", "e_stops", "pings", "wrong_car", "stale_seq", "repeated_seq", "new_session",
             "old_session")
    return {**{name: getattr(c, name) for name in names}, "decode_errors": dict(c.decode_errors)}


def motors_of(python: CommandFilter, now_ms: int) -> tuple[float, float, bool]:
    v, omega = python.active_command(float(now_ms))
    return v, omega, (v, omega) == (0.0, 0.0)


def feed_both(lib, key: bytes | None, steps: list[tuple[bytes, int]]) -> list[str]:
    """Every datagram to the Python filter (times in ms: watchdog 250, resync 1000) and to
    the C core; after each, the same verdict, command, answer, motors and counters."""
    python = CommandFilter(CAR, key=key, watchdog_timeout_s=250.0, resync_after_s=1000.0)
    car = CCar(lib, CAR, key)
    now, verdicts = 0, []
    for data, dt in steps:
        now += dt
        before = python.counters
        cmd = python.accept(data, float(now))
        got = car.receive(data, now)
        after = python.counters
        verdict = python_verdict(before, after)
        assert got["verdict"] == verdict, (data.hex(), now)
        if cmd is not None:
            assert fields(got) == cmd and got["version"] == python.version
            assert struct.pack("<dff", cmd.stamp_s, cmd.v_mps, cmd.omega_radps) == struct.pack(
                "<QII", got["stamp_bits"], got["v_bits"], got["omega_bits"])
        expected = encode_answer(python.answer(cmd, float(now)), key) if cmd is not None and cmd.ping else b""
        assert got["answer"] == expected
        assert got["resynced"] == after.resynced - before.resynced
        assert got["new_session"] == after.new_session - before.new_session
        for later in (0, 1, 249, 250, 1000):
            c_motors, py_motors = car.motors(now + later), motors_of(python, now + later)
            assert struct.pack("<ff?", *c_motors) == struct.pack("<ff?", *py_motors), (later, c_motors, py_motors)
        assert car.counters() == counters(python.counters)
        verdicts.append(verdict)
    return verdicts


f32s = st.one_of(st.floats(width=32), st.sampled_from([0.0, -0.0, 0.25, -0.5]))
stamps = st.one_of(st.floats(), st.just(12.5))
flag_values = st.one_of(st.integers(0, 15), st.integers(0, 15), st.integers(0, 0xFFFF))
gaps_ms = st.one_of(st.integers(0, 30), st.integers(0, 400), st.sampled_from([249, 250, 251, 999, 1000, 1001]),
                    st.integers(0, 5000))
v2_bodies = st.builds(
    lambda car_id, source, reserved, flags, session, seq, stamp, v, omega: struct.pack(
        "<2sBBBBHQIdff", b"TF", 2, car_id, source, reserved, flags, session, seq, stamp, v, omega),
    st.sampled_from([CAR] * 6 + [0, CAR + 1]), st.sampled_from([0, 0, 0, 1, 1, 2, 255]),
    st.sampled_from([0] * 15 + [1]), flag_values, st.sampled_from([0, 10, 20, 30, 2**64 - 1]),
    st.one_of(st.integers(0, 8), st.just(2**32 - 1)), stamps, f32s, f32s)
v1_bodies = st.builds(
    lambda car_id, seq, stamp, v, omega, flags: struct.pack("<2sBBIdffH", b"TF", 1, car_id, seq, stamp, v, omega,
                                                             flags),
    st.sampled_from([CAR] * 6 + [0, CAR + 1]),
    st.one_of(st.integers(0, 8), st.integers(2**32 - 4, 2**32 - 1), st.integers(2**31 - 2, 2**31 + 2),
              st.integers(0, 2**32 - 1)), stamps, f32s, f32s, flag_values)


def sealed(body: bytes, how: str, key: bytes | None) -> bytes:
    """``body`` sealed (CRC, or MAC with ``key``), then spoilt as ``how`` says."""
    body = {"version": body[:2] + b"\x03" + body[3:], "magic": b"XF" + body[2:]}.get(how, body)
    if key is None:
        good = body + struct.pack("<I", zlib.crc32(body))
    else:
        good = body + hmac.new(key if how != "other_key" else OTHER_KEY, body, "sha256").digest()[:16]
    return {"flip": good[:-1] + bytes([good[-1] ^ 0x40]), "cut": good[:-1], "extend": good + b"\0"}.get(how, good)


def streams(bodies, key: bytes | None):
    how = st.sampled_from(["good"] * 10 + ["other_key", "flip", "cut", "extend", "version", "magic"])
    datagram = st.one_of(st.builds(sealed, bodies, how, st.just(key)), st.builds(sealed, bodies, how, st.just(key)),
                         st.builds(sealed, bodies, how, st.just(key)), st.binary(max_size=60))
    return st.lists(st.tuples(datagram, gaps_ms), max_size=40)


RANDOM_STREAMS = settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@RANDOM_STREAMS
@given(streams(v2_bodies, KEY))
def test_random_version_2_streams_give_the_same_everything_in_c_and_python(lib, steps):
    feed_both(lib, KEY, steps)


@RANDOM_STREAMS
@given(streams(v1_bodies, None))
def test_random_version_1_streams_give_the_same_everything_in_c_and_python(lib, steps):
    feed_both(lib, None, steps)


def seeded_steps(rng: random.Random, key: bytes | None, length: int) -> list[tuple[bytes, int]]:
    """A stream as the strategies above draw it, from a seeded generator."""
    floats = [0.0, -0.0, 0.25, -0.5, 1e-45, 3.4e38, math.nan, math.inf, -math.inf]
    steps = []
    for _ in range(length):
        f32 = [rng.choice(floats) if rng.random() < 0.2 else rng.uniform(-2.0, 2.0) for _ in range(3)]
        car_id = rng.choice([CAR] * 6 + [0, CAR + 1])
        flags = rng.randrange(16) if rng.random() < 0.9 else rng.randrange(0x10000)
        if key is None:
            seq = rng.choice([rng.randrange(9), rng.randrange(2**32 - 4, 2**32), rng.randrange(2**32)])
            body = struct.pack("<2sBBIdffH", b"TF", 1, car_id, seq, *f32, flags)
        else:
            body = struct.pack("<2sBBBBHQIdff", b"TF", 2, car_id, rng.choice([0, 0, 0, 1, 1, 2, 255]),
                               int(rng.random() < 0.06), flags, rng.choice([0, 10, 20, 30, 2**64 - 1]),
                               rng.randrange(9), *f32)
        how = rng.choice(["good"] * 10 + ["other_key", "flip", "cut", "extend", "version", "magic"])
        data = sealed(body, how, key) if rng.random() < 0.9 else rng.randbytes(rng.randrange(61))
        steps.append((data, rng.choice([rng.randrange(31), rng.randrange(401), 249, 250, 251, 999, 1000, 1001,
                                        rng.randrange(5001)])))
    return steps


@pytest.mark.parametrize("version", [1, 2])
def test_seeded_random_streams_agree_and_reach_every_verdict(lib, version):
    """300 streams of 40 datagrams (12,000) to both, from a fixed seed: the same outcome
    every time, and every verdict a car of this version can give among them."""
    rng = random.Random(version)
    key = KEY if version == 2 else None
    seen: set[str] = set()
    for _ in range(300):
        seen.update(feed_both(lib, key, seeded_steps(rng, key, 40)))
    impossible = {"crc"} if version == 2 else {"mac", "reserved", "old_session"}
    assert seen == set(VERDICTS) - impossible


def test_a_scripted_stream_of_the_receivers_rules_agrees(lib):
    """The rules' cases in one stream: sessions, a restart, replays, e-stops of two
    sources, releases, PINGs, the watchdog (hand-picked, beside the random ones)."""

    def d(seq, session=100, source=0, flags=0, v=0.5):
        return by_hand(KEY, seq=seq, session=session, source=source, flags=int(flags), v=v)

    steps = [(d(0), 0), (d(1), 20), (d(1), 20), (d(0), 20), (d(0, session=200), 20), (d(9), 20),
             (d(0, session=50, source=1, flags=Flags.E_STOP), 10), (d(2, session=200), 20),
             (d(3, session=200, flags=Flags.STOP | Flags.RELEASE), 20),
             (d(1, session=50, source=1, flags=Flags.PING | Flags.RELEASE), 5),
             (d(2, session=50, source=1, flags=Flags.STOP | Flags.RELEASE), 5), (d(4, session=200), 300),
             (d(5, session=200, flags=Flags.PING), 100), (d(6, session=200, flags=Flags.PING), 200),
             (d(0, session=40, source=1, flags=Flags.E_STOP | Flags.PING), 10)]
    assert feed_both(lib, KEY, steps) == [
        "accepted", "accepted", "repeated_seq", "stale_seq", "accepted", "old_session", "e_stop", "accepted",
        "accepted", "ping", "accepted", "accepted", "ping", "ping", "e_stop"]


# ---------------------------------------------------------------- the example and main


def test_the_mcu_example_drives_answers_and_stops_on_a_simulated_board(tmp_path):
    board = build(tmp_path / "board", [FIRMWARE / "mcu_example.c", FIRMWARE / "carlink.c", HERE / "board_stub.c"],
                  "-O2")
    ping = encode_command_v2(Command(CAR, 8, 1.0, 0.0, 0.0, Flags.PING, SESSION + 1, 1), DOC_KEY)
    e_stop = encode_command_v2(Command(CAR, 0, 2.0, 0.0, 0.0, Flags.E_STOP | Flags.STOP, SESSION + 2, 1), DOC_KEY)
    script = f"0 {by_hand(DOC_KEY).hex()}\n10 {ping.hex()}\n249\n250\n260 {e_stop.hex()}\n300 {'00' * 100}\n"
    done = subprocess.run([str(board)], input=script, capture_output=True, text=True, timeout=10)
    assert done.returncode == 0, done.stderr
    moving = encode_answer(Answer(CAR, 8, 1.0, CarState.NONE, SESSION + 1, 1), DOC_KEY)
    assert done.stdout.splitlines() == ["motors 0 0", "motors 0.25 -0.5", f"answer {moving.hex()}", "motors 0 0",
                                        "log e-stop latched by source 1"]


@pytest.fixture(scope="module")
def posix(tmp_path_factory):
    return build_posix(tmp_path_factory.mktemp("posix") / "carlink_posix")


def test_the_posix_car_drives_answers_and_prints_what_its_motors_do(posix, tmp_path):
    key_file = write_key_file(tmp_path / "car.key", KEY)
    with posix_car(posix, CAR, key_file) as (address, output), \
            CommandSender(CAR, address, key=KEY, source=1, stop_repeats=0) as operator, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.sendto(by_hand(KEY, seq=1, session=operator.session - 1), address)
        operator.send(0.0, 0.0, Flags.PING)
        got: list[Answer] = []
        assert wait_for(lambda: got.extend(operator.answers()) or got, 2.0)
        assert got[0].state == CarState.NONE  # driving at 0.25 m/s
    assert "motors v 0.250 m/s omega -0.500 rad/s" in "".join(output)
    assert output[-1].startswith("carlink: accepted 1, ") and "pings 1" in output[-1]


def test_the_posix_car_speaks_version_1_without_a_key(posix):
    with posix_car(posix, CAR, None) as (address, output), \
            CommandSender(CAR, address, stop_repeats=0) as operator:
        operator.send(0.0, 0.0, Flags.E_STOP | Flags.STOP | Flags.PING)
        got: list[Answer] = []
        assert wait_for(lambda: got.extend(operator.answers()) or got, 2.0)
        assert got[0].e_stop_latched and got[0].stopped
    assert "version 1" in output[0] and any("e-stop latched by source 0" in line for line in output)


@pytest.mark.parametrize("text, message", [("00" * 31, "32 bytes"), ("zz" * 32, "hexadecimal"),
                                           ("00" * 33, "hexadecimal")])
def test_the_posix_car_refuses_a_bad_key_file_as_keys_py_does(posix, tmp_path, text, message):
    path = tmp_path / "bad.key"
    path.write_text(text)
    done = subprocess.run([str(posix), "--car", "3", "--bind", "127.0.0.1:0", "--key", str(path)],
                          capture_output=True, text=True, timeout=10)
    assert done.returncode == 2 and message in done.stderr and "readable by others" in done.stderr


def test_a_key_file_with_whitespace_is_read_as_keys_py_reads_it(posix, tmp_path):
    path = tmp_path / "spaced.key"
    path.write_text(" ".join(KEY[i:i + 4].hex().upper() for i in range(0, 32, 4)) + "\n\n")
    path.chmod(0o600)
    with posix_car(posix, CAR, path) as (address, output), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.settimeout(2.0)
        sock.sendto(by_hand(KEY, flags=int(Flags.PING)), address)
        assert decode_answer(sock.recv(64), KEY).seq == 7


# ------------------------------------------------------------ sanitizers and fuzzing


FUZZ_INPUTS = 300_000


def test_a_sanitizer_build_survives_mutation_fuzzing(tmp_path):
    """carlink_fuzz.c: 300k mutated datagrams (half sealed again with a valid MAC or CRC) to
    a version-2 and a version-1 car under AddressSanitizer and UBSan; every input's
    invariants checked in C. The run must reach every verdict a car of its version has."""
    fuzz = build(tmp_path / "carlink_fuzz", [HERE / "carlink_fuzz.c", FIRMWARE / "carlink.c"], *SANITIZE)
    seeds = []
    for source in (0, 1, 2):
        for session in (10, 20):
            for seq in (0, 1, 5):
                for flags in (0, 1, 2, 3, 4, 6, 8, 9, 10, 11, 12, 14):
                    seeds.append(encode_command_v2(Command(CAR, seq, 1.5, 0.25, -0.5, Flags(flags), session, source),
                                                   KEY))
    for seq in (0, 1, 2, 2**32 - 1):
        for flags in (0, 1, 2, 4, 8, 9, 6):
            seeds.append(encode_command(Command(CAR, seq, 1.5, 0.25, -0.5, Flags(flags))))
    seeds += [bytes.fromhex(GOLDEN_HEX), bytes.fromhex(GOLDEN_E_STOP_HEX), by_hand(KEY)]
    assert len(seeds) <= 256
    (tmp_path / "seeds.txt").write_text("".join(s.hex() + "\n" for s in seeds))
    done = subprocess.run([str(fuzz), str(tmp_path / "seeds.txt"), KEY.hex(), str(FUZZ_INPUTS), "1"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and not done.stderr, done.stderr[-3000:]
    lines = done.stdout.splitlines()
    assert lines[0] == f"inputs {FUZZ_INPUTS}"
    tally = {(version, verdict): int(n) for version, verdict, n in (line.split() for line in lines[1:])}
    for verdict in VERDICTS:
        if verdict != "crc":
            assert tally["v2", verdict] > 0, verdict
        if verdict not in ("mac", "reserved", "old_session"):
            assert tally["v1", verdict] > 0, verdict

"""Car link version 2: the authenticated datagram (bytes built by hand from the documented
layout and HMAC-SHA256, not by our encoder), the car's session rules against replays and
restarts, and the per-source e-stop."""

import hashlib
import hmac
import re
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.bridge.carlink_helpers import CAR, datagram
from trustfg.bridge.carlink import (
    DATAGRAM_V2_SIZE,
    SOURCE_OPERATOR,
    CarLinkError,
    Command,
    CommandFilter,
    Flags,
    codec,
    decode_command_v2,
    encode_command_v2,
    new_key,
)

DOC_KEY = bytes(range(32))
SESSION = 1_700_000_000_000_000


def by_hand(key, car_id=CAR, source=0, reserved=0, flags=0, session=SESSION, seq=7, stamp=12.5, v=0.25,
            omega=-0.5) -> bytes:
    """The documented layout with struct, the MAC with the standard library's HMAC."""
    body = (b"TF" + bytes([2, car_id, source, reserved]) + struct.pack("<H", flags)
            + struct.pack("<Q", session) + struct.pack("<I", seq) + struct.pack("<d", stamp)
            + struct.pack("<f", v) + struct.pack("<f", omega))
    assert len(body) == 36
    return body + hmac.new(key, body, hashlib.sha256).digest()[:16]


def test_the_documented_worked_example_is_the_datagram_and_verifies():
    doc = codec.__doc__
    example = doc[doc.index("Datagram (version 2"):]
    example = example[example.index("Worked example"):example.index("(the MAC is the last 16 bytes)")]
    documented = bytes.fromhex(" ".join(re.findall(r"^ {4}((?:[0-9a-f]{2} ?)+)$", example, flags=re.M)))
    assert documented == by_hand(DOC_KEY)
    assert documented.hex().endswith("f9d72d990d008f4daffb2695e14c98dd")  # openssl dgst -sha256 -mac HMAC
    assert decode_command_v2(documented, DOC_KEY) == Command(CAR, 7, 12.5, 0.25, -0.5, session=SESSION)


def test_encoder_matches_the_hand_built_bytes():
    key = new_key()
    cmd = Command(200, 0xFFFFFFFE, -3.0, 1.5, -2.0, Flags.STOP | Flags.E_STOP, 2**64 - 1, SOURCE_OPERATOR)
    assert encode_command_v2(cmd, key) == by_hand(key, 200, SOURCE_OPERATOR, 0, 3, 2**64 - 1, 0xFFFFFFFE,
                                                  -3.0, 1.5, -2.0)
    assert len(encode_command_v2(cmd, key)) == DATAGRAM_V2_SIZE


@pytest.mark.parametrize("mutate, reason", [
    (lambda d: d[:-1] + bytes([d[-1] ^ 1]), "mac"),          # a flipped MAC bit
    (lambda d: d[:20] + bytes([d[20] ^ 0x80]) + d[21:], "mac"),  # a flipped payload bit
    (lambda d: d[:51], "length"),
    (lambda d: b"XX" + d[2:], "magic"),
    (lambda d: d[:2] + b"\x01" + d[3:], "version"),
])
def test_altered_datagrams_are_refused_with_a_reason(mutate, reason):
    with pytest.raises(CarLinkError) as err:
        decode_command_v2(mutate(by_hand(DOC_KEY)), DOC_KEY)
    assert err.value.reason == reason


def test_a_datagram_under_another_key_or_a_nonzero_reserved_byte_is_refused():
    with pytest.raises(CarLinkError, match="mac"):
        decode_command_v2(by_hand(new_key()), DOC_KEY)
    with pytest.raises(CarLinkError, match="reserved"):
        decode_command_v2(by_hand(DOC_KEY, reserved=1), DOC_KEY)


def v2(key, seq, session=SESSION, source=0, flags=0, v=0.5):
    return by_hand(key, source=source, flags=flags, session=session, seq=seq, v=v)


def test_a_wrong_mac_a_replay_and_a_datagram_from_before_a_restart_are_dropped_and_counted():
    key = new_key()
    car = CommandFilter(CAR, key=key)
    assert car.accept(v2(key, 0), 0.00) and car.accept(v2(key, 1), 0.02)
    # wrong MAC: signed with another key
    assert car.accept(v2(new_key(), 2), 0.04) is None
    # replayed: the same datagram again, and an older one
    assert car.accept(v2(key, 1), 0.06) is None and car.accept(v2(key, 0), 0.08) is None
    # the sender restarts: a new (later) session is taken at once, whatever its seq
    assert car.accept(v2(key, 0, session=SESSION + 5_000_000), 0.10)
    # a datagram of the session before the restart is refused -- even after a long silence,
    # and even one the car never saw (seq 9 was never sent to it)
    assert car.accept(v2(key, 9), 60.0) is None
    c = car.counters
    assert c.decode_errors == {"mac": 1}
    assert (c.repeated_seq, c.stale_seq, c.old_session) == (1, 1, 1)
    assert (c.accepted, c.new_session) == (3, 2)


def test_without_sessions_version_1_takes_a_replay_after_a_silence():
    """The control: why version 2 exists. Version 1 adopts any sequence after 1 s of silence."""
    car = CommandFilter(CAR)
    captured = datagram(5)
    assert car.accept(datagram(5), 0.0) and car.accept(datagram(6), 0.02)
    assert car.accept(captured, 0.04) is None
    assert car.accept(captured, 2.0) is not None  # replayed after a silence: accepted


def test_a_version_2_car_refuses_version_1_datagrams():
    car = CommandFilter(CAR, key=new_key())
    assert car.accept(datagram(1), 0.0) is None
    assert car.counters.decode_errors == {"length": 1}


def test_sources_have_sessions_of_their_own_and_only_the_setters_release_clears_its_e_stop():
    key = new_key()
    car = CommandFilter(CAR, key=key)
    assert car.accept(v2(key, 0, session=100, v=0.4), 0.00)
    # the operator latches an e-stop
    assert car.accept(v2(key, 0, session=50, source=SOURCE_OPERATOR, flags=Flags.E_STOP), 0.01)
    assert car.e_stop_latched and car.active_command(0.02) == (0.0, 0.0)
    # the car process goes on commanding, even with RELEASE: it cannot release the operator's e-stop
    assert car.accept(v2(key, 1, session=100, v=0.4), 0.03)
    assert car.accept(v2(key, 2, session=100, flags=Flags.STOP | Flags.RELEASE, v=0.0), 0.035)
    assert car.e_stop_latched and car.active_command(0.04) == (0.0, 0.0)
    # nor does the operator's own ordinary datagram or PING: only its RELEASE
    assert car.accept(v2(key, 1, session=50, source=SOURCE_OPERATOR, flags=Flags.STOP, v=0.0), 0.045)
    assert car.accept(v2(key, 2, session=50, source=SOURCE_OPERATOR, flags=Flags.PING, v=0.0), 0.046)
    assert car.e_stop_latched
    assert car.accept(v2(key, 3, session=50, source=SOURCE_OPERATOR, flags=Flags.STOP | Flags.RELEASE, v=0.0), 0.05)
    assert car.accept(v2(key, 3, session=100, v=0.4), 0.06)
    assert not car.e_stop_latched and car.active_command(0.07) == pytest.approx((0.4, -0.5))


def test_an_e_stop_latches_from_an_older_session_but_a_release_must_be_in_the_newest():
    """Rule 2 against rule 4: two tools of the operator's (the dashboard started first,
    trustfg stop later) -- the older one's e-stop still stops the car; a RELEASE of an old
    session (a replay, or the older tool) does not release it."""
    key = new_key()
    car = CommandFilter(CAR, key=key)
    assert car.accept(v2(key, 0, session=100, v=0.4), 0.00)
    assert car.accept(v2(key, 0, session=70, source=SOURCE_OPERATOR, flags=Flags.STOP | Flags.PING), 0.01)
    assert car.accept(v2(key, 1, session=70, source=SOURCE_OPERATOR, flags=Flags.STOP), 0.01)  # session 70 is newest
    assert car.accept(v2(key, 5, session=60, source=SOURCE_OPERATOR, flags=Flags.E_STOP), 0.02)  # older: still latches
    assert car.e_stop_latched and car.counters.e_stops == 1
    assert car.accept(v2(key, 6, session=60, source=SOURCE_OPERATOR, flags=Flags.RELEASE, v=0.0), 0.03) is None
    assert car.e_stop_latched and car.counters.old_session == 1
    assert car.accept(v2(key, 0, session=80, source=SOURCE_OPERATOR, flags=Flags.STOP | Flags.RELEASE, v=0.0), 0.04)
    assert not car.e_stop_latched


KEY = bytes(range(100, 132))


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.binary(max_size=80), st.builds(
    lambda i, bit: (lambda d: d[:i] + bytes([d[i] ^ (1 << bit)]) + d[i + 1:])(by_hand(KEY)),
    st.integers(0, 51), st.integers(0, 7))))
def test_random_and_bit_flipped_datagrams_are_dropped_never_raised(data):
    """Random bytes and every single-bit error of a valid datagram: counted, never accepted."""
    car = CommandFilter(CAR, key=KEY)
    assert car.accept(data, 0.0) is None
    assert car.counters.rejected == 1

"""Car-link answers to PING datagrams: the bytes (golden, the docstring's example), the
decoder's rejections, and a car on loopback answering the sender that pinged it."""

import hashlib
import hmac
import re
import socket
import struct
import zlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.bridge.carlink_helpers import CAR, datagram
from tests.conftest import wait_for
from trustfg.bridge.carlink import (
    ANSWER_SIZE,
    ANSWER_V2_SIZE,
    Answer,
    CarLinkError,
    CarState,
    CommandReceiver,
    CommandSender,
    Flags,
    decode_answer,
    encode_answer,
    new_key,
)
from trustfg.bridge.carlink import answer as answer_module

pytestmark = pytest.mark.realtime

GOLDEN = Answer(3, 7, 12.5, CarState.E_STOP_LATCHED | CarState.STOPPED)


def test_worked_example_in_docstring_is_the_golden_answer():
    doc = answer_module.__doc__
    example = doc[doc.index("Worked example"):]
    hex_lines = re.findall(r"^ {4}((?:[0-9a-f]{2} ?)+)$", example, flags=re.MULTILINE)
    data = bytes.fromhex(" ".join(hex_lines))
    assert data == encode_answer(GOLDEN) and len(data) == ANSWER_SIZE
    assert decode_answer(data) == GOLDEN
    assert "0x7E28F51B" in example and zlib.crc32(data[:18]) == 0x7E28F51B


def forge(magic=b"TA", version=1, car_id=3, seq=7, stamp=1.0, state=0, crc=None):
    body = struct.pack("<2sBBIdH", magic, version, car_id, seq, stamp, state)
    return body + struct.pack("<I", zlib.crc32(body) if crc is None else crc)


@pytest.mark.parametrize("data, reason", [
    (forge()[:-1], "length"), (forge() + b"\0", "length"), (forge(magic=b"TF"), "magic"),
    (forge(version=2), "version"), (forge(crc=0), "crc"), (forge(car_id=0), "car_id"),
    (forge(state=4), "flags"), (b"", "length"),
])
def test_decode_rejects_with_reason(data, reason):
    with pytest.raises(CarLinkError) as err:
        decode_answer(data)
    assert err.value.reason == reason


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=30))
def test_random_bytes_never_raise_anything_else(data):
    try:
        decode_answer(data)
    except CarLinkError:
        pass


def test_a_car_answers_a_ping_to_its_sender_and_the_sender_reads_it():
    with CommandReceiver(CAR, ("127.0.0.1", 0)) as car, \
            CommandSender(CAR, car.address, stamp_clock=lambda: 42.0, stop_repeats=0) as operator:
        operator.send(0.0, 0.0, Flags.PING)
        got = []
        assert wait_for(lambda: got.extend(operator.answers()) or got, 2.0)
        assert (got[0].seq, got[0].stamp_s) == (0, 42.0)
        assert got[0].stopped and not got[0].e_stop_latched  # nothing ever drove it
        # an e-stop with a ping: the answer says it latched
        operator.send(0.0, 0.0, Flags.E_STOP | Flags.STOP | Flags.PING)
        got = []
        assert wait_for(lambda: got.extend(operator.answers()) or got, 2.0)
        assert got[-1].e_stop_latched
        assert operator.stats.answers == 2 and car.counters.accepted == 0


def test_the_sender_drops_answers_from_another_car_or_garbage():
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as fake_car:
        fake_car.bind(("127.0.0.1", 0))
        fake_car.settimeout(2.0)
        with CommandSender(CAR, fake_car.getsockname(), stop_repeats=0) as sender:
            sender.send(0.0, 0.0, Flags.PING)
            _, source = fake_car.recvfrom(64)
            fake_car.sendto(encode_answer(Answer(CAR + 1, 0, 0.0)), source)
            fake_car.sendto(b"garbage", source)
            fake_car.sendto(encode_answer(Answer(CAR, 0, 0.0)), source)
            fake_car.sendto(datagram(1), source)
            got = []
            assert wait_for(lambda: got.extend(sender.answers()) or len(got) + sender.stats.bad_answers >= 4, 2.0)
            assert [a.car_id for a in got] == [CAR]
            assert sender.stats.bad_answers == 3


def test_a_version_2_answer_is_the_documented_layout_with_the_cars_mac():
    """Built by hand from answer.py's table and the standard library's HMAC."""
    key = bytes(range(32))
    answer = Answer(3, 7, 12.5, CarState.E_STOP_LATCHED, session=1_700_000_000_000_000, source=1)
    body = (b"TA" + bytes([2, 3, 1, 0]) + struct.pack("<HQId", 1, 1_700_000_000_000_000, 7, 12.5))
    data = body + hmac.new(key, body, hashlib.sha256).digest()[:16]
    assert encode_answer(answer, key) == data and len(data) == ANSWER_V2_SIZE
    assert decode_answer(data, key) == answer
    with pytest.raises(CarLinkError) as wrong_key:
        decode_answer(data, new_key())
    assert wrong_key.value.reason == "mac"
    with pytest.raises(CarLinkError):
        decode_answer(data)  # a version-1 reader: wrong length


def test_a_version_2_car_answers_its_sender_only_in_that_senders_session():
    key = new_key()
    with CommandReceiver(CAR, ("127.0.0.1", 0), key=key) as car, \
            CommandSender(CAR, car.address, key=key, source=1, stamp_clock=lambda: 42.0, stop_repeats=0) as operator, \
            CommandSender(CAR, car.address, key=new_key(), source=1, stop_repeats=0) as impostor:
        operator.send(0.0, 0.0, Flags.E_STOP | Flags.STOP | Flags.PING)
        got = []
        assert wait_for(lambda: got.extend(operator.answers()) or got, 2.0)
        assert got[0].e_stop_latched and (got[0].session, got[0].source) == (operator.session, 1)
        impostor.send(0.0, 0.0, Flags.PING)  # a forged PING: dropped by the car, never answered
        assert car.wait_until(lambda c: c.decode_errors.get("mac", 0) == 1, 2.0)
        operator.renew_session()  # an answer to the old session is no longer ours
        operator.send(0.0, 0.0, Flags.STOP | Flags.RELEASE)
        operator.send(0.0, 0.0, Flags.PING)
        got = []
        assert wait_for(lambda: got.extend(operator.answers()) or got, 2.0)
        assert not got[0].e_stop_latched and got[0].session == operator.session
        assert impostor.answers() == [] and operator.stats.bad_answers == 0

"""Car-link answer: what a car sends back to a PING datagram (pure, no I/O).

A car answers every valid datagram for it that carries the PING flag (:mod:`.codec`),
after handling it, with one datagram to the address and port the PING came from. The
operator's tools use the answers to see that a car link is up before a run (``trustfg
check``, with motors held: a PING is never applied) and that an e-stop latched
(``trustfg stop``). The answer echoes the PING's sequence number and stamp, so the asker
matches it and measures the round trip on its own clock.

Answers are framed as the commands are (:func:`.frame.seal`): a car that speaks version 2
answers in version 2, authenticated with its key (so an answer also proves that the car
holds the key the operator has), a version-1 car in version 1, with a CRC.

Answer (version 1)
------------------
Exactly 22 bytes, little-endian, no padding::

    offset size type  field
    0      2    bytes magic    b"TA" (0x54 0x41)
    2      1    u8    version  1
    3      1    u8    car_id   the answering car, 1..255
    4      4    u32   seq      the seq of the PING datagram answered
    8      8    f64   stamp_s  the stamp of the PING datagram answered, unchanged
    16     2    u16   state    bit 0 E_STOP_LATCHED (any sender's), bit 1 STOPPED (the
                               command applied now is zero: STOP, the watchdog or a
                               latched E_STOP), bits 2..15 0
    18     4    u32   crc32    CRC-32 (the command datagram's, zlib) over bytes 0..17

Worked example: car 3 answers PING seq 7, stamp 12.5 s, its e-stop latched (state 0x0003,
CRC 0x7E28F51B)::

    54 41 01 03 07 00 00 00 00 00 00 00 00 00 29 40
    03 00 1b f5 28 7e

Answer (version 2, authenticated)
---------------------------------
Exactly 44 bytes, little-endian, no padding::

    offset size type  field
    0      2    bytes magic    b"TA"
    2      1    u8    version  2
    3      1    u8    car_id   the answering car, 1..255
    4      1    u8    source   the source of the PING answered
    5      1    u8    reserved 0
    6      2    u16   state    as in version 1
    8      8    u64   session  the session of the PING answered
    16     4    u32   seq      the seq of the PING answered
    20     8    f64   stamp_s  the stamp of the PING answered, unchanged
    28     16   bytes mac      HMAC-SHA256(car key, bytes 0..27), its first 16 bytes

The asker takes only answers that echo its own session (a replayed answer of an earlier
session tells it nothing). Answers only inform: nothing relies on them for safety
(``trustfg stop`` sends its E_STOP datagrams whatever the answers say).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

from .codec import _check_int
from .frame import SEQ_MODULUS, SESSION_MODULUS, CarLinkError, check_key, open_frame, seal

ANSWER_MAGIC = b"TA"
ANSWER_SIZE = 22
ANSWER_V2_SIZE = 44
_BODY = struct.Struct("<2sBBIdH")
_BODY_V2 = struct.Struct("<2sBBBBHQId")


class CarState(enum.IntFlag):
    """State bits of an answer (u16 at offset 16)."""

    NONE = 0
    E_STOP_LATCHED = 0x0001
    STOPPED = 0x0002


@dataclass(frozen=True)
class Answer:
    """A car's answer to a PING datagram."""

    car_id: int
    seq: int
    stamp_s: float
    state: CarState = CarState.NONE
    session: int = 0
    source: int = 0
    """``session`` and ``source`` travel in version 2 only (version 1 decodes them as 0)."""

    def __post_init__(self) -> None:
        _check_int("car_id", self.car_id, 1, 255)
        _check_int("seq", self.seq, 0, SEQ_MODULUS - 1)
        _check_int("session", self.session, 0, SESSION_MODULUS - 1)
        _check_int("source", self.source, 0, 255)
        _check_int("state", self.state, 0, int(CarState.E_STOP_LATCHED | CarState.STOPPED))
        object.__setattr__(self, "state", CarState(int(self.state)))

    @property
    def e_stop_latched(self) -> bool:
        return bool(self.state & CarState.E_STOP_LATCHED)

    @property
    def stopped(self) -> bool:
        return bool(self.state & CarState.STOPPED)


def encode_answer(answer: Answer, key: bytes | None = None) -> bytes:
    """The answer's datagram: version 2 with the car's ``key``, else version 1."""
    if key is None:
        return seal(_BODY.pack(ANSWER_MAGIC, 1, answer.car_id, answer.seq, answer.stamp_s, int(answer.state)))
    return seal(_BODY_V2.pack(ANSWER_MAGIC, 2, answer.car_id, answer.source, 0, int(answer.state), answer.session,
                              answer.seq, answer.stamp_s), check_key(key))


def decode_answer(data: bytes | bytearray | memoryview, key: bytes | None = None) -> Answer:
    """The answer in a datagram (version 2 with ``key``, else version 1); raises
    :class:`CarLinkError` (and nothing else) if invalid or, in version 2, not authentic."""
    if key is None:
        _, _, car_id, seq, stamp_s, state = open_frame(data, _BODY, ANSWER_MAGIC, 1)
        session = source = 0
    else:
        _, _, car_id, source, reserved, state, session, seq, stamp_s = open_frame(
            data, _BODY_V2, ANSWER_MAGIC, 2, key)
        if reserved != 0:
            raise CarLinkError("reserved", f"reserved byte is 0x{reserved:02x}, must be 0")
    if state & ~int(CarState.E_STOP_LATCHED | CarState.STOPPED):
        raise CarLinkError("flags", f"reserved state bits set: 0x{state:04x}")
    return Answer(car_id, seq, stamp_s, CarState(state), session, source)

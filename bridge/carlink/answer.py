"""Car-link answer: what a car sends back to a PING datagram (pure, no I/O).

A car answers every valid datagram for it that carries the PING flag (:mod:`.codec`),
after handling it, with one datagram to the address and port the PING came from. The
operator's tools use the answers to see that a car link is up before a run (``trustfg
check``, with motors held: a PING is never applied) and that an e-stop latched
(``trustfg stop``). The answer echoes the PING's sequence number and stamp, so the asker
matches it and measures the round trip on its own clock.

Answer (version 1)
------------------
Exactly 22 bytes, little-endian, no padding::

    offset size type  field
    0      2    bytes magic    b"TA" (0x54 0x41)
    2      1    u8    version  1
    3      1    u8    car_id   the answering car, 1..255
    4      4    u32   seq      the seq of the PING datagram answered
    8      8    f64   stamp_s  the stamp of the PING datagram answered, unchanged
    16     2    u16   state    bit 0 E_STOP_LATCHED, bit 1 STOPPED (the command applied
                               now is zero: STOP, the watchdog or a latched E_STOP),
                               bits 2..15 0
    18     4    u32   crc32    CRC-32 (the command datagram's, zlib) over bytes 0..17

Worked example: car 3 answers PING seq 7, stamp 12.5 s, its e-stop latched (state 0x0003,
CRC 0x7E28F51B)::

    54 41 01 03 07 00 00 00 00 00 00 00 00 00 29 40
    03 00 1b f5 28 7e

Answers are not authenticated: they inform the operator, nothing relies on them for
safety (``trustfg stop`` sends its E_STOP datagrams whatever the answers say).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

from .codec import CarLinkError, _check_int, open_frame, seal

ANSWER_MAGIC = b"TA"
ANSWER_VERSION = 1
ANSWER_SIZE = 22
_BODY = struct.Struct("<2sBBIdH")


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

    def __post_init__(self) -> None:
        _check_int("car_id", self.car_id, 1, 255)
        _check_int("seq", self.seq, 0, 2**32 - 1)
        _check_int("state", self.state, 0, int(CarState.E_STOP_LATCHED | CarState.STOPPED))
        object.__setattr__(self, "state", CarState(int(self.state)))

    @property
    def e_stop_latched(self) -> bool:
        return bool(self.state & CarState.E_STOP_LATCHED)

    @property
    def stopped(self) -> bool:
        return bool(self.state & CarState.STOPPED)


def encode_answer(answer: Answer) -> bytes:
    return seal(_BODY.pack(ANSWER_MAGIC, ANSWER_VERSION, answer.car_id, answer.seq, answer.stamp_s, int(answer.state)))


def decode_answer(data: bytes | bytearray | memoryview) -> Answer:
    """The answer in a datagram; raises :class:`CarLinkError` (and nothing else) if invalid."""
    _, _, car_id, seq, stamp_s, state = open_frame(data, _BODY, ANSWER_MAGIC, ANSWER_VERSION)
    if state & ~int(CarState.E_STOP_LATCHED | CarState.STOPPED):
        raise CarLinkError("flags", f"reserved state bits set: 0x{state:04x}")
    return Answer(car_id, seq, stamp_s, CarState(state))

"""Car-link framing: the constants, body layouts, flags and checks of the datagrams that
:mod:`.codec` documents byte by byte -- only what is quick to import.

It is apart from :mod:`.codec` (the validated :class:`~.codec.Command` and its decoding)
so that the operator's first E_STOP (:mod:`.direct`, ``trustfg stop``) needs nothing but
struct, zlib, hmac and enum: no dataclasses, no receiving rules, no sockets' threads. Every
datagram a car link carries is built by :func:`command_datagram` or (answers) sealed by
:func:`seal` here.
"""

from __future__ import annotations

import enum
import hashlib
import hmac
import struct
import threading
import time
import zlib

MAGIC = b"TF"
VERSION = 1
DATAGRAM_SIZE = 30
VERSION_2 = 2
DATAGRAM_V2_SIZE = 52
MAC_BYTES = 16
KEY_BYTES = 32
SOURCE_CAR_PROCESS = 0
SOURCE_OPERATOR = 1
SEQ_MODULUS = 2**32
SESSION_MODULUS = 2**64
COMMAND_BODY = struct.Struct("<2sBBIdffH")  # version 1, bytes 0..25, covered by the CRC
COMMAND_BODY_V2 = struct.Struct("<2sBBBBHQIdff")  # version 2, bytes 0..35, covered by the MAC
_CRC = struct.Struct("<I")


class CarLinkError(ValueError):
    """A car-link datagram or command field is invalid.

    ``reason`` is a short machine-readable tag (``"length"``, ``"magic"``, ``"version"``,
    ``"crc"``, ``"mac"``, ``"reserved"``, ``"car_id"``, ``"non_finite"``, ``"flags"``,
    ``"range"``, ``"type"``, ``"key"``) by which rejections are counted; ``"range"`` and
    ``"type"`` come only from building a :class:`~.codec.Command`, ``"key"`` from a bad key.
    """

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


class Flags(enum.IntFlag):
    """Command flag bits (what a car does with each: :mod:`.codec`, :mod:`.receiver`)."""

    NONE = 0
    E_STOP = 0x0001
    STOP = 0x0002
    RELEASE = 0x0004
    PING = 0x0008


def command_datagram(key: bytes | None, car_id: int, seq: int, stamp_s: float, v_mps: float, omega_radps: float,
                     flags: int, session: int = 0, source: int = SOURCE_CAR_PROCESS) -> bytes:
    """The datagram of one command: version 2 (52 bytes, MAC) with the car's ``key``,
    version 1 (30 bytes, CRC; no session or source) without. The fields are packed as
    given: :class:`~.codec.Command` validates them (struct still refuses what does not fit)."""
    if key is None:
        return seal(COMMAND_BODY.pack(MAGIC, VERSION, car_id, seq, stamp_s, v_mps, omega_radps, int(flags)))
    return seal(COMMAND_BODY_V2.pack(MAGIC, VERSION_2, car_id, source, 0, int(flags), session, seq, stamp_s,
                                     v_mps, omega_radps), key)


def seal(body: bytes, key: bytes | None = None) -> bytes:
    """A datagram: its body, then its check -- version 1 the CRC-32 of the body (u32,
    little-endian), version 2 (with the car's ``key``) the MAC of the body. Commands and
    answers (:mod:`.answer`) share this framing."""
    return body + (_CRC.pack(zlib.crc32(body)) if key is None else mac(check_key(key), body))


def open_frame(data: object, layout: struct.Struct, magic: bytes, version: int,
               key: bytes | None = None) -> tuple:
    """The body fields of a sealed datagram whose body is ``layout`` (starting with the
    magic and the version), after checking, in this order, type, length, magic, version
    and the CRC (without ``key``) or the MAC (with it); :class:`CarLinkError` otherwise."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise CarLinkError("type", f"expected bytes, got {type(data).__name__}")
    data = bytes(data)
    check = _CRC.size if key is None else MAC_BYTES
    if len(data) != layout.size + check:
        raise CarLinkError("length", f"{len(data)} bytes, expected {layout.size + check}")
    fields = layout.unpack_from(data)
    if fields[0] != magic:
        raise CarLinkError("magic", f"magic {fields[0]!r}, expected {magic!r}")
    if fields[1] != version:
        raise CarLinkError("version", f"version {fields[1]}, this end speaks {version}")
    body = data[:layout.size]
    if key is None:
        (crc,) = _CRC.unpack_from(data, layout.size)
        if crc != zlib.crc32(body):
            raise CarLinkError("crc", f"crc 0x{crc:08x}, computed 0x{zlib.crc32(body):08x}")
    elif not hmac.compare_digest(data[layout.size:], mac(key, body)):
        raise CarLinkError("mac", "the MAC does not verify: wrong key, or altered or forged")
    return fields


def check_key(key: object) -> bytes:
    """A car's link key: exactly KEY_BYTES bytes (else :class:`CarLinkError`, reason "key")."""
    if not isinstance(key, (bytes, bytearray)) or len(key) != KEY_BYTES:
        raise CarLinkError("key", f"a car-link key is {KEY_BYTES} bytes, got "
                           f"{len(key) if isinstance(key, (bytes, bytearray)) else type(key).__name__}")
    return bytes(key)


def mac(key: bytes, body: bytes) -> bytes:
    """The version-2 tag: HMAC-SHA256(key, body) truncated to MAC_BYTES."""
    return hmac.new(key, body, hashlib.sha256).digest()[:MAC_BYTES]


_session_lock = threading.Lock()
_last_session = 0


def new_session() -> int:
    """A version-2 session id: the wall clock in microseconds, strictly increasing within
    this process (two senders started in the same microsecond still differ)."""
    global _last_session
    with _session_lock:
        _last_session = max(time.time_ns() // 1000, _last_session + 1) % SESSION_MODULUS
        return _last_session

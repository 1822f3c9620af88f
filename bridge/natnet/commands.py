"""The small command-channel messages, each a dataclass; :mod:`.packet` reads and writes
their bytes::

    REQUEST (2), MESSAGESTRING (8)   one NUL-terminated string
    RESPONSE (3)                     4 bytes (an int32 or float32, depending on the
                                     request) or a NUL-terminated string
    REQUEST_MODELDEF (4), REQUEST_FRAMEOFDATA (6), DISCONNECT (9), KEEPALIVE (10)
                                     empty
    ECHO_REQUEST (12)                uint64 client stamp
    ECHO_RESPONSE (13)               uint64 echoed client stamp, uint64 server stamp
                                     (server high-resolution clock ticks at reception)

UNRECOGNIZED_REQUEST (100) carries the sender block and lives in :mod:`.handshake`.
"""

from __future__ import annotations

from dataclasses import dataclass

from .common import _F32, _I32, NatNetError


@dataclass(frozen=True)
class Request:
    command: str


@dataclass(frozen=True)
class Response:
    """RESPONSE: raw payload; its meaning depends on the request it answers."""

    payload: bytes

    def as_int(self) -> int:
        if len(self.payload) != 4:
            raise NatNetError(f"RESPONSE of {len(self.payload)} bytes is not an int32")
        return _I32.unpack(self.payload)[0]

    def as_float(self) -> float:
        if len(self.payload) != 4:
            raise NatNetError(f"RESPONSE of {len(self.payload)} bytes is not a float32")
        return _F32.unpack(self.payload)[0]

    def as_text(self) -> str:
        return self.payload.split(b"\0", 1)[0].decode("utf-8", "replace")


@dataclass(frozen=True)
class MessageString:
    text: str


@dataclass(frozen=True)
class KeepAlive:
    pass


@dataclass(frozen=True)
class Disconnect:
    pass


@dataclass(frozen=True)
class RequestModelDef:
    pass


@dataclass(frozen=True)
class RequestFrame:
    pass


@dataclass(frozen=True)
class EchoRequest:
    timestamp: int


@dataclass(frozen=True)
class EchoResponse:
    request_timestamp: int
    received_timestamp: int

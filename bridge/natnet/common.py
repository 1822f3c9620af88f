"""What every NatNet message shares: the packet header, message ids, versions, the frame
layout of each version, errors (:class:`NatNetError`, a ``ValueError`` with a ``reason``
for counters; nothing else escapes a decoder) and the buffer readers the decoders use.

Every datagram is a 4-byte header and a payload, little-endian throughout::

    off  type    field
    0    uint16  message id (MessageId)
    2    uint16  payload size in bytes; must equal len(datagram) - 4
    4    ...     payload

Message ids are :class:`MessageId`'s. Strings on the wire (``cstring``) are UTF-8 and
NUL-terminated; ``vec3`` is 3 float32 (m), ``quat`` 4 float32 (qx, qy, qz, qw); counts are
int32.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from functools import lru_cache

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

MAX_PAYLOAD_BYTES = 0xFFFF  # the header's size field is a uint16


class NatNetError(ValueError):
    """A NatNet datagram that cannot be decoded (or a message that cannot be encoded).

    ``reason`` is a short machine-readable tag for counters: ``truncated``,
    ``size_mismatch``, ``bad_count``, ``section_size``, ``trailing_bytes``, ``non_finite``,
    ``unknown_message``, ``unsupported_version``, ``malformed`` or ``encode``.
    """

    def __init__(self, message: str, reason: str = "malformed") -> None:
        super().__init__(message)
        self.reason = reason


class MessageId(enum.IntEnum):
    CONNECT = 0
    SERVERINFO = 1
    REQUEST = 2
    RESPONSE = 3
    REQUEST_MODELDEF = 4
    MODELDEF = 5
    REQUEST_FRAMEOFDATA = 6
    FRAMEOFDATA = 7
    MESSAGESTRING = 8
    DISCONNECT = 9
    KEEPALIVE = 10
    ECHO_REQUEST = 12
    ECHO_RESPONSE = 13
    DISCOVERY = 14
    UNRECOGNIZED_REQUEST = 100


@dataclass(frozen=True, order=True)
class Version:
    """A NatNet or application version, major.minor.build.revision (each 0..255)."""

    major: int
    minor: int = 0
    build: int = 0
    revision: int = 0

    def __str__(self) -> str:
        return f"{self.major}.{self.minor}.{self.build}.{self.revision}"

    @classmethod
    def parse(cls, text: str) -> "Version":
        """``"4.1"`` or ``"3.0.0.0"`` -> Version."""
        try:
            parts = [int(p) for p in text.strip().split(".")]
        except ValueError:
            raise ValueError(f"not a version: {text!r}") from None
        if not 1 <= len(parts) <= 4 or not all(0 <= p <= 255 for p in parts):
            raise ValueError(f"not a version: {text!r}")
        return cls(*parts)

    def to_bytes(self) -> bytes:
        return bytes((self.major, self.minor, self.build, self.revision))

    @property
    def is_zero(self) -> bool:
        return self == _ZERO_VERSION


_ZERO_VERSION = Version(0, 0, 0, 0)
V2_5, V2_7, V2_9 = Version(2, 5), Version(2, 7), Version(2, 9)
V3_0, V3_1, V4_0, V4_1 = Version(3, 0), Version(3, 1), Version(4, 0), Version(4, 1)
V4_2 = Version(4, 2)
FRAME_VERSIONS = (V3_0, V3_1, V4_0, V4_1, V4_2)  # decoded and encoded; 2.x is decoded only
NEWEST_LAYOUT = V4_2
"""The last layout change the SDK documents: NatNet 4.2 (Motive 3.2) added a rotation to
the rigid-body description. The SDK's own 2025 depacketizer (NatNetClient.py) reads every
4.x from 4.2 on with this layout ("4_2_to_current"); so does this codec, up to
LATEST_DECODED."""
LATEST_DECODED = Version(4, 4)
"""The newest version decoded (with the 4.2 layout): OptiTrack's documentation lists 4.4.
A later one is refused rather than guessed at."""
STREAM_VERSIONS = tuple(f"{v.major}.{v.minor}" for v in FRAME_VERSIONS)
"""The versions a stream may be configured as, "3.0" ... (command-line choices)."""
DEFAULT_VERSION = V3_1
"""What mocap-sim streams unless told otherwise."""
DEFAULT_STREAM_VERSION = f"{DEFAULT_VERSION.major}.{DEFAULT_VERSION.minor}"

# ---------------------------------------------------------------------------------------
# Precompiled structs shared by the message modules
# ---------------------------------------------------------------------------------------
_HEADER = struct.Struct("<HH")
_I32 = struct.Struct("<i")
_I32x2 = struct.Struct("<ii")
_U16 = struct.Struct("<H")
_F32 = struct.Struct("<f")
_VEC3 = struct.Struct("<3f")
_QUAT = struct.Struct("<4f")
_RB = struct.Struct("<i8fH")  # id, x, y, z, qx, qy, qz, qw, mean error, params: 38 bytes
_RB_BYTES = _RB.size

# ---------------------------------------------------------------------------------------
# Header
# ---------------------------------------------------------------------------------------


def pack_header(message_id: int, payload: bytes) -> bytes:
    """Header + payload: a datagram ready to send."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise NatNetError(f"payload of {len(payload)} bytes exceeds the uint16 size field",
                          "encode")
    return _HEADER.pack(message_id, len(payload)) + payload


def unpack_header(packet: bytes) -> tuple[int, memoryview]:
    """(message id, payload view) of a datagram, checking the size field against its length."""
    if len(packet) < 4:
        raise NatNetError(f"truncated packet: {len(packet)} bytes, the header needs 4",
                          "truncated")
    message_id, size = _HEADER.unpack_from(packet, 0)
    if size != len(packet) - 4:
        raise NatNetError(f"header says {size} payload bytes but the datagram carries "
                          f"{len(packet) - 4}", "size_mismatch")
    return message_id, memoryview(packet)[4:]


def peek_message_id(packet: bytes) -> int | None:
    """The message id of a datagram, without validating it (None if under 2 bytes)."""
    return _U16.unpack_from(packet, 0)[0] if len(packet) >= 2 else None


# ---------------------------------------------------------------------------------------
# Small readers (and the one writer every encoder needs)
# ---------------------------------------------------------------------------------------


def _as_bytes(payload: bytes | bytearray | memoryview) -> bytes:
    return payload if type(payload) is bytes else bytes(payload)


def _cstring(buf: bytes, off: int, end: int, what: str) -> tuple[str, int]:
    nul = buf.find(b"\0", off, end)
    if nul < 0:
        raise NatNetError(f"unterminated {what} string at byte {off}", "truncated")
    return buf[off:nul].decode("utf-8", "replace"), nul + 1


def _skip_cstring(buf: bytes, off: int, end: int, what: str) -> int:
    nul = buf.find(b"\0", off, end)
    if nul < 0:
        raise NatNetError(f"unterminated {what} string at byte {off}", "truncated")
    return nul + 1


def _count(buf: bytes, off: int, end: int, min_item: int, what: str) -> tuple[int, int]:
    """An int32 count that must fit (at ``min_item`` bytes per item) in the bytes left."""
    if off + 4 > end:
        raise NatNetError(f"truncated before the {what} count (byte {off} of {end})",
                          "truncated")
    (n,) = _I32.unpack_from(buf, off)
    off += 4
    if n < 0 or n * min_item > end - off:
        raise NatNetError(f"{what} count {n} cannot fit in the {end - off} bytes left",
                          "bad_count")
    return n, off


def _section_end(buf: bytes, off: int, end: int, n: int, min_item: int,
                 what: str) -> tuple[int, int]:
    """The 4.1 ``int32 nbytes`` after a section count: (offset after it, section end)."""
    if off + 4 > end:
        raise NatNetError(f"truncated before the {what} byte size", "truncated")
    (nbytes,) = _I32.unpack_from(buf, off)
    off += 4
    if nbytes < 0 or nbytes > end - off:
        raise NatNetError(f"{what} section claims {nbytes} bytes but {end - off} remain",
                          "section_size")
    if n * min_item > nbytes:
        raise NatNetError(f"{what} section of {nbytes} bytes cannot hold {n} items",
                          "section_size")
    return off, off + nbytes


def _check_section(off: int, stop: int, what: str) -> None:
    if off != stop:
        raise NatNetError(f"{what} section size field disagrees with its content "
                          f"(content ends at byte {off}, size says {stop})", "section_size")


def _name_bytes(name: str, what: str) -> bytes:
    raw = name.encode("utf-8")
    if b"\0" in raw:
        raise NatNetError(f"{what} {name!r} contains a NUL", "encode")
    return raw + b"\0"


# ---------------------------------------------------------------------------------------
# Frame layout of each version (also the version gate of MODELDEF)
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Layout:
    """Which optional fields a NatNet version's frame carries (see the FRAMEOFDATA table in
    :mod:`.frame`)."""

    sizes: bool  # 4.1+: int32 nbytes after each section count
    rb_markers: bool  # < 3.0: per rigid body marker lists
    rb_marker_ids: bool  # 2.0+: ... with ids and sizes
    rb_params: bool  # 2.6+
    skeletons: bool  # 2.1+
    assets: bool  # 4.1+
    labeled: bool  # 2.3+
    labeled_params: bool  # 2.6+
    residual: bool  # 3.0+
    force_plates: bool  # 2.9+
    devices: bool  # 2.11+
    latency: bool  # < 3.0: float32 latency before the timecode
    timestamp: str  # "", "f" (2.6) or "d" (2.7+)
    hires: bool  # 3.0+: three uint64 stamps
    precision: bool  # 4.1+: PTP seconds and fraction
    frame_params: bool  # 2.6+
    rb_description_rotation: bool  # 4.2+ (MODELDEF): quat after the rigid body's offset

    @property
    def rb_min_bytes(self) -> int:
        if not self.rb_markers:
            return _RB_BYTES
        return 4 + 28 + 4 + (4 if self.rb_marker_ids else 0) + (2 if self.rb_params else 0)

    @property
    def labeled_bytes(self) -> int:
        return 20 + (2 if self.labeled_params else 0) + (4 if self.residual else 0)


@lru_cache(maxsize=None)
def _layout(major: int, minor: int) -> _Layout:
    if not (major == 2 and 0 <= minor <= 11 or major == 3 and minor in (0, 1)
            or major == 4 and 0 <= minor <= LATEST_DECODED.minor):
        raise NatNetError(f"unsupported NatNet version {major}.{minor} (frames of 2.x, "
                          f"3.0, 3.1 and 4.0 to {LATEST_DECODED.major}.{LATEST_DECODED.minor} are supported)",
                          "unsupported_version")
    v = (major, minor)
    return _Layout(
        sizes=v >= (4, 1), rb_markers=v < (3, 0), rb_marker_ids=v >= (2, 0),
        rb_params=v >= (2, 6), skeletons=v >= (2, 1), assets=v >= (4, 1),
        labeled=v >= (2, 3), labeled_params=v >= (2, 6), residual=v >= (3, 0),
        force_plates=v >= (2, 9), devices=v >= (2, 11), latency=v < (3, 0),
        timestamp="d" if v >= (2, 7) else ("f" if v >= (2, 6) else ""),
        hires=v >= (3, 0), precision=v >= (4, 1), frame_params=v >= (2, 6),
        rb_description_rotation=v >= (4, 2))


def supports_frames(version: Version) -> bool:
    """Whether frames of NatNet ``version`` can be decoded (2.x, 3.0, 3.1, 4.0 to 4.4)."""
    try:
        _layout(version.major, version.minor)
    except NatNetError:
        return False
    return True


def _encode_layout(version: Version) -> _Layout:
    if Version(version.major, version.minor) not in FRAME_VERSIONS:
        raise NatNetError(f"encoding NatNet {version.major}.{version.minor} is not supported "
                          f"({', '.join(STREAM_VERSIONS)} are)", "unsupported_version")
    return _layout(version.major, version.minor)

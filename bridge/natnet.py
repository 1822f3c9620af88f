"""NatNet wire codec: datagrams <-> frozen dataclasses, no sockets.

NatNet is OptiTrack Motive's UDP streaming protocol. This module decodes and encodes its
messages exactly as laid out by the NatNet SDK (the ``PacketClient.cpp`` and
``NatNetClient.py`` direct-depacketization samples of SDK 3.x/4.x). Frames of NatNet 3.0,
3.1, 4.0 and 4.1 are decoded and encoded; frames of the legacy 2.x layouts (2.0 to 2.11,
tested on 2.5/2.7/2.9 captures) are decoded only. Every decoding problem raises
:class:`NatNetError` (a ``ValueError``) with a ``reason`` for counters; nothing else
escapes a decoder.

Packet
------
Every datagram is a 4-byte header and a payload, little-endian throughout::

    off  type    field
    0    uint16  message id (MessageId)
    2    uint16  payload size in bytes; must equal len(datagram) - 4
    4    ...     payload

Message ids: 0 CONNECT, 1 SERVERINFO, 2 REQUEST, 3 RESPONSE, 4 REQUEST_MODELDEF, 5 MODELDEF,
6 REQUEST_FRAMEOFDATA, 7 FRAMEOFDATA, 8 MESSAGESTRING, 9 DISCONNECT, 10 KEEPALIVE,
12 ECHO_REQUEST, 13 ECHO_RESPONSE, 14 DISCOVERY, 100 UNRECOGNIZED_REQUEST.

Sender block (sSender, 264 bytes; in CONNECT, DISCOVERY, SERVERINFO, UNRECOGNIZED_REQUEST)
------------------------------------------------------------------------------------------
::

    0    char[256]  application name, NUL-terminated; bytes after the NUL are garbage
                    (Motive leaves whatever was in its buffer) and are ignored
    256  uint8[4]   application version   major.minor.build.revision
    260  uint8[4]   NatNet version        major.minor.build.revision

CONNECT (0) and DISCOVERY (14) payloads -- a server accepts every variant
---------------------------------------------------------------------------
* empty (0 bytes) or a bare NUL-terminated string such as ``"Ping\\0"`` (5 bytes);
* NatNetLib: the 264-byte sender block (client name, client version, NatNet version);
* sender block + connection options (sConnectionOptions, 5 bytes)::

      264  uint8     subscribed-data-only flag
      265  uint8[4]  requested bitstream NatNet version (0.0.0.0 = server default)

  The official Python sample sends "Ping" in the name field, zero versions, the options
  with its requested version at offset 265, and one extra NUL: 271 bytes.

SERVERINFO (1)
--------------
::

    0    sender block (264 bytes)
    -- NatNet 3.0 and later (sSender_Server), absent from 2.x servers (payload 264 bytes):
    264  uint64    high-resolution clock frequency, ticks/s
    272  uint16    data port
    274  uint8     multicast flag (bool)
    275  uint8[4]  multicast group address
    279  (end)

REQUEST (2) / MESSAGESTRING (8): one NUL-terminated string. RESPONSE (3): 4 bytes (an
int32 or float32, depending on the request) or a NUL-terminated string. REQUEST_MODELDEF
(4), REQUEST_FRAMEOFDATA (6), DISCONNECT (9), KEEPALIVE (10): empty. ECHO_REQUEST (12):
uint64 client stamp. ECHO_RESPONSE (13): uint64 echoed client stamp, uint64 server stamp
(server high-resolution clock ticks at reception). UNRECOGNIZED_REQUEST (100): empty or the
server's sender block.

FRAMEOFDATA (7)
---------------
Sections in order; ``vec3`` is 3 float32 (m), ``quat`` 4 float32 (qx, qy, qz, qw). In
NatNet 4.1 and later every section count is followed by ``int32 nbytes``, the byte size
of the section's items (not counting the count and size fields); the decoder validates it
and skips by it. Counts are int32 and must fit in the bytes that remain.

====================  ======================================================================
section               layout
====================  ======================================================================
prefix                int32 frame number
marker sets           int32 n [, int32 nbytes]; n x (cstring name, int32 m, m x vec3)
legacy markers        int32 n [, int32 nbytes]; n x vec3   ("other"/unlabeled markers)
rigid bodies          int32 n [, int32 nbytes]; n x rigid body (below)
skeletons (>=2.1)     int32 n [, int32 nbytes]; n x (int32 id, int32 m, m x rigid body)
assets (>=4.1)        int32 n, int32 nbytes; n x (int32 id, int32 r, r x rigid body(3.0),
                      int32 m, m x (int32 id, vec3, float32 size, int16 params,
                      float32 residual))
labeled (>=2.3)       int32 n [, int32 nbytes]; n x (int32 id = model << 16 | marker,
                      vec3, float32 size, [>=2.6 int16 params], [>=3.0 float32 residual])
force plates (>=2.9)  int32 n [, int32 nbytes]; n x (int32 id, int32 c,
                      c x (int32 f, f x float32))
devices (>=2.11)      same layout as force plates
suffix                [<3.0 float32 latency], uint32 timecode, uint32 timecode subframe,
                      [2.6 float32 | >=2.7 float64 timestamp (s)],
                      [>=3.0 uint64 camera mid-exposure, uint64 camera data received,
                      uint64 transmit (high-resolution clock ticks)],
                      [>=4.1 uint32 precision timestamp s, uint32 precision fraction],
                      [>=2.6 uint16 frame params: 0x01 recording, 0x02 tracked models
                      changed], int32 end-of-data tag (0; Motive sends it, the SDK samples
                      do not read it, so it may be absent)
====================  ======================================================================

A rigid body is, for NatNet 3.0 and later, 38 bytes::

    0   int32    id (streaming id)
    4   vec3     position (m)
    16  quat     orientation qx, qy, qz, qw
    32  float32  mean marker error (m)
    36  uint16   params: 0x01 tracking valid (tracked in this frame)

NatNet 2.x inserts after the orientation ``int32 m, m x vec3 marker positions`` and (2.0
and later) ``m x int32 marker ids, m x float32 marker sizes``; mean error is there from 2.0,
params from 2.6.

A decoded frame must end exactly after the params (or after the end-of-data tag): other
trailing bytes mean the packet is not of the NatNet version it was decoded as.

MODELDEF (5)
------------
``int32 n``, then n descriptions of ``int32 kind`` [4.1 and later: ``int32 nbytes`` of the
description that follows] and the description:

====================  ======================================================================
kind                  layout
====================  ======================================================================
0 marker set          cstring name, int32 m, m x cstring marker name
1 rigid body          cstring name (2.0+), int32 id, int32 parent id, vec3 offset;
                      3.0+: int32 m, m x vec3 marker offsets, m x int32 active labels,
                      4.0+: m x cstring marker names
2 skeleton            cstring name, int32 id, int32 r, r x rigid body description
3 force plate (3.0+)  int32 id, cstring serial, float32 width, float32 length, vec3 origin,
                      12 x 12 float32 calibration matrix, 4 x vec3 corners, int32 plate
                      type, int32 channel data type, int32 c, c x cstring channel name
4 device (3.0+)       int32 id, cstring name, cstring serial, int32 device type,
                      int32 channel data type, int32 c, c x cstring channel name
5 camera              cstring name, vec3 position, quat orientation
6 asset               cstring name, int32 type, int32 id, int32 r, r x rigid body
                      description, int32 m, m x (cstring name, int32 id, vec3, float32
                      size, int16 params)
====================  ======================================================================

Marker sets and rigid bodies are decoded; the other kinds are walked by their layout (or
by their 4.1 byte size) and kept as :class:`OtherDescription` (kind and name).

Coordinates
-----------
Motive is right-handed and Y-up by default. :func:`to_ground_plane` maps a pose to the
planner's ground plane (x, y, yaw); see there.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal, Sequence, Union

__all__ = [
    "NatNetError", "MessageId", "Version", "V2_5", "V2_7", "V2_9", "V3_0", "V3_1", "V4_0",
    "V4_1", "FRAME_VERSIONS", "STREAM_VERSIONS", "DEFAULT_VERSION", "DEFAULT_STREAM_VERSION", "RigidBody", "MarkerSet", "LabeledMarker", "Skeleton", "Asset",
    "AnalogDevice", "Frame", "ConnectionInfo", "ServerInfo", "ConnectRequest",
    "DiscoveryRequest", "Request", "Response", "MessageString", "KeepAlive", "Disconnect",
    "RequestModelDef", "RequestFrame", "EchoRequest", "EchoResponse", "UnrecognizedRequest",
    "MarkerSetDescription", "RigidBodyMarker", "RigidBodyDescription", "OtherDescription",
    "ModelDef", "Message", "pack_header", "unpack_header", "peek_message_id",
    "decode_frame", "encode_frame", "decode_server_info", "encode_server_info",
    "decode_connect", "encode_connect", "decode_model_def", "encode_model_def",
    "serialize", "deserialize", "supports_frames", "to_ground_plane", "MAX_PAYLOAD_BYTES",
]

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
FRAME_VERSIONS = (V3_0, V3_1, V4_0, V4_1)  # decoded and encoded; 2.x is decoded only
STREAM_VERSIONS = tuple(f"{v.major}.{v.minor}" for v in FRAME_VERSIONS)
"""The versions a stream may be configured as, "3.0" ... (command-line choices)."""
DEFAULT_VERSION = V3_1
"""What mocap-sim streams unless told otherwise."""
DEFAULT_STREAM_VERSION = f"{DEFAULT_VERSION.major}.{DEFAULT_VERSION.minor}"

# ---------------------------------------------------------------------------------------
# Precompiled structs
# ---------------------------------------------------------------------------------------
_HEADER = struct.Struct("<HH")
_I32 = struct.Struct("<i")
_I32x2 = struct.Struct("<ii")
_U16 = struct.Struct("<H")
_F32 = struct.Struct("<f")
_F64 = struct.Struct("<d")
_U64 = struct.Struct("<Q")
_U64x2 = struct.Struct("<QQ")
_VEC3 = struct.Struct("<3f")
_QUAT = struct.Struct("<4f")
_RB = struct.Struct("<i8fH")  # id, x, y, z, qx, qy, qz, qw, mean error, params: 38 bytes
_LABELED = struct.Struct("<i3ffHf")  # id, x, y, z, size, params, residual: 26 bytes
_ASSET_MARKER = _LABELED
_SUFFIX_30 = struct.Struct("<IIdQQQH")  # timecode .. params (3.0 - 4.0): 42 bytes
_SUFFIX_41 = struct.Struct("<IIdQQQIIH")  # + precision timestamp (4.1): 50 bytes
_CONN_INFO = struct.Struct("<QHB4s")  # SERVERINFO connection info: 15 bytes
_SENDER_BYTES = 264
_SERVERINFO_BYTES = _SENDER_BYTES + _CONN_INFO.size
_NAME_BYTES = 256
_RB_BYTES = _RB.size

# ---------------------------------------------------------------------------------------
# Frame dataclasses
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RigidBody:
    """One rigid body of a frame: Motive coordinates, metres, quaternion xyzw."""

    id: int
    position: Vec3
    orientation: Quat
    mean_error: float = 0.0
    tracking_valid: bool = True


@dataclass(frozen=True, slots=True)
class MarkerSet:
    name: str
    markers: tuple[Vec3, ...] = ()


@dataclass(frozen=True, slots=True)
class LabeledMarker:
    """A labeled marker (or an asset marker). ``id`` packs model id << 16 | marker id."""

    id: int
    position: Vec3
    size: float = 0.0
    params: int = 0
    residual: float = 0.0

    @property
    def model_id(self) -> int:
        return self.id >> 16

    @property
    def marker_id(self) -> int:
        return self.id & 0xFFFF

    @property
    def occluded(self) -> bool:
        return bool(self.params & 0x01)


@dataclass(frozen=True, slots=True)
class Skeleton:
    id: int
    rigid_bodies: tuple[RigidBody, ...] = ()


@dataclass(frozen=True, slots=True)
class Asset:
    id: int
    rigid_bodies: tuple[RigidBody, ...] = ()
    markers: tuple[LabeledMarker, ...] = ()


@dataclass(frozen=True, slots=True)
class AnalogDevice:
    """A force plate or peripheral device: per channel, the samples of this frame."""

    id: int
    channels: tuple[tuple[float, ...], ...] = ()


@dataclass(frozen=True, slots=True)
class Frame:
    """A FRAMEOFDATA message.

    ``timestamp`` is Motive's software time in seconds (0.0 for NatNet < 2.6, which has
    none). The ``*_ticks`` stamps are in the server's high-resolution clock (frequency in
    SERVERINFO), 0 before NatNet 3.0; the precision timestamp (PTP) is NatNet 4.1 only.
    The marker, skeleton, asset and analog sections are filled only when decoded with
    ``full=True``; by default they are validated, skipped and left empty.
    """

    frame_number: int
    rigid_bodies: tuple[RigidBody, ...] = ()
    timestamp: float = 0.0
    timecode: int = 0
    timecode_subframe: int = 0
    camera_mid_exposure_ticks: int = 0
    camera_data_received_ticks: int = 0
    transmit_ticks: int = 0
    precision_timestamp_s: int = 0
    precision_timestamp_fraction: int = 0
    params: int = 0
    marker_sets: tuple[MarkerSet, ...] = ()
    legacy_markers: tuple[Vec3, ...] = ()
    skeletons: tuple[Skeleton, ...] = ()
    assets: tuple[Asset, ...] = ()
    labeled_markers: tuple[LabeledMarker, ...] = ()
    force_plates: tuple[AnalogDevice, ...] = ()
    devices: tuple[AnalogDevice, ...] = ()

    @property
    def is_recording(self) -> bool:
        return bool(self.params & 0x01)

    @property
    def tracked_models_changed(self) -> bool:
        return bool(self.params & 0x02)


# ---------------------------------------------------------------------------------------
# Other messages
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ConnectionInfo:
    """The NatNet 3.0+ tail of SERVERINFO."""

    clock_frequency_hz: int
    data_port: int
    multicast: bool
    multicast_address: str


@dataclass(frozen=True)
class ServerInfo:
    app_name: str
    app_version: Version
    natnet_version: Version
    connection: ConnectionInfo | None = None


@dataclass(frozen=True)
class ConnectRequest:
    """CONNECT, in any of its variants (see the module docstring).

    Fields the variant does not carry are empty/None. :attr:`stream_version` is the
    NatNet version the client asks for, if any.
    """

    client_name: str = ""
    client_version: Version | None = None
    natnet_version: Version | None = None
    subscribed_only: bool = False
    requested_version: Version | None = None

    @property
    def stream_version(self) -> Version | None:
        return self.requested_version or self.natnet_version


@dataclass(frozen=True)
class DiscoveryRequest(ConnectRequest):
    """DISCOVERY (14): a connect-shaped broadcast asking servers to announce themselves."""


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


@dataclass(frozen=True)
class UnrecognizedRequest:
    """UNRECOGNIZED_REQUEST; Motive attaches its sender block, others send nothing."""

    app_name: str = ""
    app_version: Version | None = None
    natnet_version: Version | None = None


@dataclass(frozen=True)
class MarkerSetDescription:
    name: str
    marker_names: tuple[str, ...] = ()


@dataclass(frozen=True)
class RigidBodyMarker:
    """A marker of a rigid body description; ``name`` is on the wire from NatNet 4.0."""

    offset: Vec3
    active_label: int = 0
    name: str = ""


@dataclass(frozen=True)
class RigidBodyDescription:
    name: str
    id: int
    parent_id: int = -1
    offset: Vec3 = (0.0, 0.0, 0.0)
    markers: tuple[RigidBodyMarker, ...] = ()


@dataclass(frozen=True)
class OtherDescription:
    """A description we walk but do not keep: skeleton, force plate, device, camera, asset."""

    kind: int
    name: str = ""


Description = Union[MarkerSetDescription, RigidBodyDescription, OtherDescription]


@dataclass(frozen=True)
class ModelDef:
    """MODELDEF: descriptions in wire order."""

    descriptions: tuple[Description, ...] = ()

    @property
    def rigid_bodies(self) -> tuple[RigidBodyDescription, ...]:
        return tuple(d for d in self.descriptions if isinstance(d, RigidBodyDescription))

    @property
    def marker_sets(self) -> tuple[MarkerSetDescription, ...]:
        return tuple(d for d in self.descriptions if isinstance(d, MarkerSetDescription))


Message = Union[Frame, ServerInfo, ConnectRequest, DiscoveryRequest, Request, Response,
                MessageString, KeepAlive, Disconnect, RequestModelDef, RequestFrame,
                EchoRequest, EchoResponse, UnrecognizedRequest, ModelDef]

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
# Small readers
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


# ---------------------------------------------------------------------------------------
# FRAMEOFDATA
# ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Layout:
    """Which optional fields a NatNet version's frame carries (see the module docstring)."""

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
            or major == 4 and minor in (0, 1)):
        raise NatNetError(f"unsupported NatNet version {major}.{minor} (frames of 2.x, "
                          "3.0, 3.1, 4.0 and 4.1 are supported)", "unsupported_version")
    v = (major, minor)
    return _Layout(
        sizes=v >= (4, 1), rb_markers=v < (3, 0), rb_marker_ids=v >= (2, 0),
        rb_params=v >= (2, 6), skeletons=v >= (2, 1), assets=v >= (4, 1),
        labeled=v >= (2, 3), labeled_params=v >= (2, 6), residual=v >= (3, 0),
        force_plates=v >= (2, 9), devices=v >= (2, 11), latency=v < (3, 0),
        timestamp="d" if v >= (2, 7) else ("f" if v >= (2, 6) else ""),
        hires=v >= (3, 0), precision=v >= (4, 1), frame_params=v >= (2, 6))


def supports_frames(version: Version) -> bool:
    """Whether frames of NatNet ``version`` can be decoded (2.x, 3.0, 3.1, 4.0, 4.1)."""
    try:
        _layout(version.major, version.minor)
    except NatNetError:
        return False
    return True


def _finite_or_raise(t: tuple, what: str) -> None:
    # Ints in t are finite; a non-finite float makes the sum inf or nan.
    if sum(t) * 0.0 != 0.0:
        raise NatNetError(f"{what} has a non-finite value: {t}", "non_finite")


def _rigid_bodies_v3(buf: bytes, off: int, n: int) -> tuple[tuple[RigidBody, ...], int]:
    bodies = []
    append = bodies.append
    for t in _RB.iter_unpack(buf[off:off + n * _RB_BYTES]):
        valid = bool(t[9] & 1)
        if valid and sum(t) * 0.0 != 0.0:
            raise NatNetError(f"tracked rigid body {t[0]} has a non-finite pose or error",
                              "non_finite")
        append(RigidBody(t[0], t[1:4], t[4:8], t[8], valid))
    return tuple(bodies), off + n * _RB_BYTES


def _rigid_body_v2(buf: bytes, off: int, end: int, lay: _Layout) -> tuple[RigidBody, int]:
    rb_id, x, y, z, qx, qy, qz, qw = struct.unpack_from("<i7f", buf, off)
    off += 32
    m, off = _count(buf, off, end, 12 + (8 if lay.rb_marker_ids else 0), "rigid body marker")
    off += m * (20 if lay.rb_marker_ids else 12)
    error = 0.0
    if lay.rb_marker_ids:
        (error,) = _F32.unpack_from(buf, off)
        off += 4
    valid = True
    if lay.rb_params:
        valid = bool(_U16.unpack_from(buf, off)[0] & 1)
        off += 2
    if valid:
        _finite_or_raise((x, y, z, qx, qy, qz, qw, error), f"tracked rigid body {rb_id}")
    return RigidBody(rb_id, (x, y, z), (qx, qy, qz, qw), error, valid), off


def _rigid_body_list(buf: bytes, off: int, end: int, n: int,
                     lay: _Layout) -> tuple[tuple[RigidBody, ...], int]:
    if not lay.rb_markers:
        return _rigid_bodies_v3(buf, off, n)
    bodies = []
    for _ in range(n):
        rb, off = _rigid_body_v2(buf, off, end, lay)
        bodies.append(rb)
    return tuple(bodies), off


def _marker_sets(buf: bytes, off: int, end: int, n: int,
                 full: bool) -> tuple[tuple[MarkerSet, ...], int]:
    sets = []
    for _ in range(n):
        if full:
            name, off = _cstring(buf, off, end, "marker set name")
        else:
            off = _skip_cstring(buf, off, end, "marker set name")
        m, off = _count(buf, off, end, 12, "marker set marker")
        if full:
            sets.append(MarkerSet(name, tuple(_VEC3.iter_unpack(buf[off:off + 12 * m]))))
        off += 12 * m
    return tuple(sets), off


def _labeled_markers(buf: bytes, off: int, n: int, lay: _Layout,
                     full: bool) -> tuple[tuple[LabeledMarker, ...], int]:
    size = lay.labeled_bytes
    if not full:
        return (), off + n * size
    markers = []
    for i in range(n):
        o = off + i * size
        mid, x, y, z, msize = struct.unpack_from("<i4f", buf, o)
        params = _U16.unpack_from(buf, o + 20)[0] if lay.labeled_params else 0
        residual = _F32.unpack_from(buf, o + size - 4)[0] if lay.residual else 0.0
        markers.append(LabeledMarker(mid, (x, y, z), msize, params, residual))
    return tuple(markers), off + n * size


def _skeletons(buf: bytes, off: int, end: int, n: int, lay: _Layout,
               full: bool) -> tuple[tuple[Skeleton, ...], int]:
    skeletons = []
    for _ in range(n):
        if off + 8 > end:
            raise NatNetError("truncated skeleton", "truncated")
        (sk_id,) = _I32.unpack_from(buf, off)
        r, off = _count(buf, off + 4, end, lay.rb_min_bytes, "skeleton rigid body")
        bodies, off = _rigid_body_list(buf, off, end, r, lay)
        if full:
            skeletons.append(Skeleton(sk_id, bodies))
    return tuple(skeletons), off


def _assets(buf: bytes, off: int, end: int, n: int,
            full: bool) -> tuple[tuple[Asset, ...], int]:
    assets = []
    for _ in range(n):
        if off + 4 > end:
            raise NatNetError("truncated asset", "truncated")
        (asset_id,) = _I32.unpack_from(buf, off)
        r, off = _count(buf, off + 4, end, _RB_BYTES, "asset rigid body")
        bodies, off = _rigid_bodies_v3(buf, off, r)
        m, off = _count(buf, off, end, _ASSET_MARKER.size, "asset marker")
        markers = tuple(LabeledMarker(t[0], t[1:4], t[4], t[5], t[6])
                        for t in _ASSET_MARKER.iter_unpack(buf[off:off + m * _ASSET_MARKER.size]))
        off += m * _ASSET_MARKER.size
        if full:
            assets.append(Asset(asset_id, bodies, markers))
    return tuple(assets), off


def _analog_section(buf: bytes, off: int, end: int, sizes: bool, full: bool,
                    what: str) -> tuple[tuple[AnalogDevice, ...], int]:
    """A force-plate or device section: its count, then (4.1) its byte size, then the
    devices -- decoded when ``full``, else skipped by their size."""
    n, off = _count(buf, off, end, 8, what)
    if not sizes:
        return _analog(buf, off, end, n, what, full)
    off, stop = _section_end(buf, off, end, n, 8, what)
    if not full:
        return (), stop
    items, off = _analog(buf, off, stop, n, what, True)
    _check_section(off, stop, what)
    return items, off


def _analog(buf: bytes, off: int, end: int, n: int, what: str,
            full: bool) -> tuple[tuple[AnalogDevice, ...], int]:
    devices = []
    for _ in range(n):
        if off + 4 > end:
            raise NatNetError(f"truncated {what}", "truncated")
        (dev_id,) = _I32.unpack_from(buf, off)
        c, off = _count(buf, off + 4, end, 4, f"{what} channel")
        channels = []
        for _ in range(c):
            f, off = _count(buf, off, end, 4, f"{what} sample")
            if full:
                channels.append(struct.unpack_from(f"<{f}f", buf, off))
            off += 4 * f
        if full:
            devices.append(AnalogDevice(dev_id, tuple(channels)))
    return tuple(devices), off


def decode_frame(payload: bytes | bytearray | memoryview, version: Version, *,
                 full: bool = False) -> Frame:
    """Decode a FRAMEOFDATA payload (the bytes after the header) of NatNet ``version``.

    With ``full=False`` (the fast path used by the client) only rigid bodies and the
    frame suffix are kept; every other section is still checked against the bytes
    available and skipped by its real size.
    """
    lay = _layout(version.major, version.minor)
    buf = _as_bytes(payload)
    end = len(buf)
    try:
        return _decode_frame(buf, end, lay, full)
    except struct.error as exc:  # a fixed-size read ran off the end
        raise NatNetError(f"truncated FRAMEOFDATA ({end} bytes): {exc}", "truncated") from None


def _decode_frame(buf: bytes, end: int, lay: _Layout, full: bool) -> Frame:
    sizes = lay.sizes
    if end < 4:
        raise NatNetError(f"truncated FRAMEOFDATA: {end} bytes", "truncated")
    (frame_number,) = _I32.unpack_from(buf, 0)

    # marker sets
    n, off = _count(buf, 4, end, 5, "marker set")
    if sizes:
        off, stop = _section_end(buf, off, end, n, 5, "marker set")
        if full:
            marker_sets, off = _marker_sets(buf, off, stop, n, True)
            _check_section(off, stop, "marker set")
        else:
            marker_sets, off = (), stop
    else:
        marker_sets, off = _marker_sets(buf, off, end, n, full)

    # legacy ("other") markers
    n, off = _count(buf, off, end, 12, "legacy marker")
    if sizes:
        off, stop = _section_end(buf, off, end, n, 12, "legacy marker")
        _check_section(off + 12 * n, stop, "legacy marker")
    legacy = tuple(_VEC3.iter_unpack(buf[off:off + 12 * n])) if full and n else ()
    off += 12 * n

    # rigid bodies (always decoded)
    n, off = _count(buf, off, end, lay.rb_min_bytes, "rigid body")
    if sizes:
        off, stop = _section_end(buf, off, end, n, _RB_BYTES, "rigid body")
        bodies, off = _rigid_bodies_v3(buf, off, n)
        _check_section(off, stop, "rigid body")
    else:
        bodies, off = _rigid_body_list(buf, off, end, n, lay)

    skeletons: tuple[Skeleton, ...] = ()
    if lay.skeletons:
        n, off = _count(buf, off, end, 8, "skeleton")
        if sizes:
            off, stop = _section_end(buf, off, end, n, 8, "skeleton")
            if full:
                skeletons, off = _skeletons(buf, off, stop, n, lay, True)
                _check_section(off, stop, "skeleton")
            else:
                off = stop
        else:
            skeletons, off = _skeletons(buf, off, end, n, lay, full)

    assets: tuple[Asset, ...] = ()
    if lay.assets:
        n, off = _count(buf, off, end, 12, "asset")
        off, stop = _section_end(buf, off, end, n, 12, "asset")
        if full:
            assets, off = _assets(buf, off, stop, n, True)
            _check_section(off, stop, "asset")
        else:
            off = stop

    labeled: tuple[LabeledMarker, ...] = ()
    if lay.labeled:
        size = lay.labeled_bytes
        n, off = _count(buf, off, end, size, "labeled marker")
        if sizes:
            off, stop = _section_end(buf, off, end, n, size, "labeled marker")
            _check_section(off + n * size, stop, "labeled marker")
        labeled, off = _labeled_markers(buf, off, n, lay, full)

    plates: tuple[AnalogDevice, ...] = ()
    if lay.force_plates:
        plates, off = _analog_section(buf, off, end, sizes, full, "force plate")

    devices: tuple[AnalogDevice, ...] = ()
    if lay.devices:
        devices, off = _analog_section(buf, off, end, sizes, full, "device")

    # suffix
    mid = received = transmit = prec_s = prec_frac = params = 0
    if lay.hires:
        if lay.precision:
            (timecode, subframe, timestamp, mid, received, transmit, prec_s, prec_frac,
             params) = _SUFFIX_41.unpack_from(buf, off)
            off += _SUFFIX_41.size
        else:
            timecode, subframe, timestamp, mid, received, transmit, params = \
                _SUFFIX_30.unpack_from(buf, off)
            off += _SUFFIX_30.size
    else:
        timestamp, params, off = 0.0, 0, off + (4 if lay.latency else 0)  # latency dropped
        timecode, subframe = struct.unpack_from("<II", buf, off)
        off += 8
        if lay.timestamp == "d":
            (timestamp,) = _F64.unpack_from(buf, off)
            off += 8
        elif lay.timestamp == "f":
            (timestamp,) = _F32.unpack_from(buf, off)
            off += 4
        if lay.frame_params:
            (params,) = _U16.unpack_from(buf, off)
            off += 2
    if timestamp * 0.0 != 0.0:
        raise NatNetError(f"frame {frame_number} has a non-finite timestamp", "non_finite")
    rest = end - off
    if rest != 0 and rest != 4:  # 4: Motive's end-of-data tag
        raise NatNetError(f"{rest} unexpected bytes after the frame suffix (is this really "
                          "the stream's NatNet version?)", "trailing_bytes")
    return Frame(frame_number, bodies, timestamp, timecode, subframe, mid, received, transmit,
                 prec_s, prec_frac, params, marker_sets, legacy, skeletons, assets, labeled,
                 plates, devices)


def _encode_layout(version: Version) -> _Layout:
    if (version.major, version.minor) not in ((3, 0), (3, 1), (4, 0), (4, 1)):
        raise NatNetError(f"encoding NatNet {version.major}.{version.minor} is not supported "
                          "(3.0, 3.1, 4.0, 4.1 are)", "unsupported_version")
    return _layout(version.major, version.minor)


def _name_bytes(name: str, what: str) -> bytes:
    raw = name.encode("utf-8")
    if b"\0" in raw:
        raise NatNetError(f"{what} {name!r} contains a NUL", "encode")
    return raw + b"\0"


def _encode_rigid_bodies(bodies: Sequence[RigidBody]) -> bytes:
    pack = _RB.pack
    return b"".join(pack(b.id, *b.position, *b.orientation, b.mean_error,
                         1 if b.tracking_valid else 0) for b in bodies)


def _encode_marker(m: LabeledMarker) -> bytes:
    return _LABELED.pack(m.id, *m.position, m.size, m.params, m.residual)


def _encode_analog(devices: Sequence[AnalogDevice]) -> bytes:
    parts = []
    for d in devices:
        parts.append(_I32x2.pack(d.id, len(d.channels)))
        for ch in d.channels:
            parts.append(_I32.pack(len(ch)) + struct.pack(f"<{len(ch)}f", *ch))
    return b"".join(parts)


def encode_frame(frame: Frame, version: Version) -> bytes:
    """The FRAMEOFDATA payload of ``frame`` in NatNet ``version`` (3.0, 3.1, 4.0, 4.1)."""
    lay = _encode_layout(version)
    try:
        sections = [
            (len(frame.marker_sets), b"".join(
                _name_bytes(s.name, "marker set name") + _I32.pack(len(s.markers))
                + b"".join(_VEC3.pack(*p) for p in s.markers) for s in frame.marker_sets)),
            (len(frame.legacy_markers), b"".join(_VEC3.pack(*p) for p in frame.legacy_markers)),
            (len(frame.rigid_bodies), _encode_rigid_bodies(frame.rigid_bodies)),
            (len(frame.skeletons), b"".join(
                _I32x2.pack(s.id, len(s.rigid_bodies)) + _encode_rigid_bodies(s.rigid_bodies)
                for s in frame.skeletons)),
        ]
        if lay.assets:
            sections.append((len(frame.assets), b"".join(
                _I32x2.pack(a.id, len(a.rigid_bodies)) + _encode_rigid_bodies(a.rigid_bodies)
                + _I32.pack(len(a.markers)) + b"".join(_encode_marker(m) for m in a.markers)
                for a in frame.assets)))
        elif frame.assets:
            raise NatNetError(f"assets need NatNet 4.1, not {version}", "encode")
        sections += [
            (len(frame.labeled_markers), b"".join(_encode_marker(m)
                                                  for m in frame.labeled_markers)),
            (len(frame.force_plates), _encode_analog(frame.force_plates)),
            (len(frame.devices), _encode_analog(frame.devices)),
        ]
        parts = [_I32.pack(frame.frame_number)]
        for n, body in sections:
            parts.append(_I32x2.pack(n, len(body)) if lay.sizes else _I32.pack(n))
            parts.append(body)
        if lay.precision:
            parts.append(_SUFFIX_41.pack(
                frame.timecode, frame.timecode_subframe, frame.timestamp,
                frame.camera_mid_exposure_ticks, frame.camera_data_received_ticks,
                frame.transmit_ticks, frame.precision_timestamp_s,
                frame.precision_timestamp_fraction, frame.params))
        else:
            parts.append(_SUFFIX_30.pack(
                frame.timecode, frame.timecode_subframe, frame.timestamp,
                frame.camera_mid_exposure_ticks, frame.camera_data_received_ticks,
                frame.transmit_ticks, frame.params))
        parts.append(_I32.pack(0))  # end-of-data tag, as Motive sends it
    except struct.error as exc:
        raise NatNetError(f"cannot encode frame {frame.frame_number}: {exc}", "encode") from None
    return b"".join(parts)


# ---------------------------------------------------------------------------------------
# Sender block, SERVERINFO, CONNECT
# ---------------------------------------------------------------------------------------


def _decode_sender(buf: bytes) -> tuple[str, Version, Version]:
    name = buf[:_NAME_BYTES].split(b"\0", 1)[0].decode("utf-8", "replace")
    return name, Version(*buf[256:260]), Version(*buf[260:264])


def _encode_sender(name: str, app_version: Version | None,
                   natnet_version: Version | None) -> bytes:
    raw = _name_bytes(name, "application name")
    if len(raw) > _NAME_BYTES:
        raise NatNetError(f"application name {name!r} is longer than 255 bytes", "encode")
    try:
        return (raw.ljust(_NAME_BYTES, b"\0") + (app_version or _ZERO_VERSION).to_bytes()
                + (natnet_version or _ZERO_VERSION).to_bytes())
    except ValueError as exc:
        raise NatNetError(f"version out of range: {exc}", "encode") from None


def decode_server_info(payload: bytes | memoryview) -> ServerInfo:
    """SERVERINFO payload: 264 bytes (NatNet 2.x) or 279 bytes (3.0+)."""
    buf = _as_bytes(payload)
    n = len(buf)
    if n < _SENDER_BYTES or _SENDER_BYTES < n < _SERVERINFO_BYTES:
        raise NatNetError(f"SERVERINFO of {n} bytes: expected {_SENDER_BYTES} (NatNet 2.x) "
                          f"or {_SERVERINFO_BYTES}", "truncated")
    name, app_version, natnet_version = _decode_sender(buf)
    connection = None
    if n >= _SERVERINFO_BYTES:
        clock, port, multicast, group = _CONN_INFO.unpack_from(buf, _SENDER_BYTES)
        connection = ConnectionInfo(clock, port, bool(multicast), ".".join(map(str, group)))
    return ServerInfo(name, app_version, natnet_version, connection)


def encode_server_info(info: ServerInfo) -> bytes:
    out = _encode_sender(info.app_name, info.app_version, info.natnet_version)
    c = info.connection
    if c is not None:
        try:
            group = bytes(int(p) for p in c.multicast_address.split("."))
            if len(group) != 4:
                raise ValueError(c.multicast_address)
            out += _CONN_INFO.pack(c.clock_frequency_hz, c.data_port, int(c.multicast), group)
        except (ValueError, struct.error) as exc:
            raise NatNetError(f"cannot encode connection info {c}: {exc}", "encode") from None
    return out


def _nonzero(v: Version) -> Version | None:
    return None if v.is_zero else v


def decode_connect(payload: bytes | memoryview, cls: type = ConnectRequest) -> ConnectRequest:
    """CONNECT (or DISCOVERY) payload, any variant; never fails on a short payload."""
    buf = _as_bytes(payload)
    if len(buf) < _SENDER_BYTES:
        name = buf.split(b"\0", 1)[0].decode("utf-8", "replace")
        return cls(name)
    name, client_version, natnet_version = _decode_sender(buf)
    subscribed, requested = False, None
    if len(buf) >= _SENDER_BYTES + 5:
        subscribed = bool(buf[_SENDER_BYTES])
        requested = _nonzero(Version(*buf[265:269]))
    return cls(name, _nonzero(client_version), _nonzero(natnet_version), subscribed, requested)


def encode_connect(request: ConnectRequest) -> bytes:
    """Mirror of :func:`decode_connect`: the shortest variant that carries the fields."""
    r = request
    if r.client_version is None and r.natnet_version is None and r.requested_version is None \
            and not r.subscribed_only:
        return _name_bytes(r.client_name, "client name") if r.client_name else b""
    out = _encode_sender(r.client_name, r.client_version, r.natnet_version)
    if r.requested_version is not None or r.subscribed_only:
        out += bytes((1 if r.subscribed_only else 0,)) + (
            r.requested_version or _ZERO_VERSION).to_bytes()
    return out


# ---------------------------------------------------------------------------------------
# MODELDEF
# ---------------------------------------------------------------------------------------


def _rb_description(buf: bytes, off: int, end: int,
                    version: Version) -> tuple[RigidBodyDescription, int]:
    name = ""
    if version.major >= 2:
        name, off = _cstring(buf, off, end, "rigid body name")
    if off + 20 > end:
        raise NatNetError("truncated rigid body description", "truncated")
    rb_id, parent, ox, oy, oz = struct.unpack_from("<ii3f", buf, off)
    off += 20
    markers: tuple[RigidBodyMarker, ...] = ()
    if version.major >= 3:
        m, off = _count(buf, off, end, 16 + (1 if version.major >= 4 else 0),
                        "rigid body marker")
        offsets = list(_VEC3.iter_unpack(buf[off:off + 12 * m]))
        labels = struct.unpack_from(f"<{m}i", buf, off + 12 * m)
        off += 16 * m
        names = [""] * m
        if version.major >= 4:
            for i in range(m):
                names[i], off = _cstring(buf, off, end, "rigid body marker name")
        markers = tuple(RigidBodyMarker(o, lab, nm) for o, lab, nm in zip(offsets, labels, names))
    return RigidBodyDescription(name, rb_id, parent, (ox, oy, oz), markers), off


def _marker_set_description(buf: bytes, off: int, end: int) -> tuple[MarkerSetDescription, int]:
    name, off = _cstring(buf, off, end, "marker set name")
    m, off = _count(buf, off, end, 1, "marker set marker name")
    names = []
    for _ in range(m):
        nm, off = _cstring(buf, off, end, "marker name")
        names.append(nm)
    return MarkerSetDescription(name, tuple(names)), off


def _skip_names(buf: bytes, off: int, end: int, what: str) -> int:
    c, off = _count(buf, off, end, 1, what)
    for _ in range(c):
        off = _skip_cstring(buf, off, end, what)
    return off


def _other_description(kind: int, buf: bytes, off: int, end: int,
                       version: Version) -> tuple[OtherDescription, int]:
    """Walk a skeleton/force plate/device/camera/asset description by its layout."""
    name = ""
    if kind == 2:  # skeleton
        name, off = _cstring(buf, off, end, "skeleton name")
        r, off = _count(buf, off + 4, end, 20, "skeleton bone")
        for _ in range(r):
            _, off = _rb_description(buf, off, end, version)
    elif kind == 3 and version.major >= 3:  # force plate
        off += 4
        name, off = _cstring(buf, off, end, "force plate serial")
        off += 8 + 12 + 12 * 12 * 4 + 4 * 12 + 8
        off = _skip_names(buf, off, end, "force plate channel name")
    elif kind == 4 and version.major >= 3:  # device
        off += 4
        name, off = _cstring(buf, off, end, "device name")
        off = _skip_cstring(buf, off, end, "device serial") + 8
        off = _skip_names(buf, off, end, "device channel name")
    elif kind == 5:  # camera
        name, off = _cstring(buf, off, end, "camera name")
        off += 28
    elif kind == 6:  # asset
        name, off = _cstring(buf, off, end, "asset name")
        r, off = _count(buf, off + 8, end, 20, "asset rigid body")
        for _ in range(r):
            _, off = _rb_description(buf, off, end, version)
        m, off = _count(buf, off, end, 23, "asset marker")
        for _ in range(m):  # cstring name, int32 id, vec3, float32 size, int16 params
            off = _skip_cstring(buf, off, end, "asset marker name") + 22
    elif kind not in (3, 4):
        raise NatNetError(f"unknown model description kind {kind}", "malformed")
    if off > end:
        raise NatNetError(f"truncated model description of kind {kind}", "truncated")
    return OtherDescription(kind, name), off


def decode_model_def(payload: bytes | memoryview, version: Version) -> ModelDef:
    """MODELDEF payload of NatNet ``version`` (2.x, 3.0, 3.1, 4.0, 4.1)."""
    _layout(version.major, version.minor)  # rejects versions whose layout we do not know
    buf = _as_bytes(payload)
    end = len(buf)
    sized = (version.major, version.minor) >= (4, 1)
    try:
        n, off = _count(buf, 0, end, 8 if sized else 4, "model description")
        descriptions: list[Description] = []
        for _ in range(n):
            (kind,) = _I32.unpack_from(buf, off)
            off += 4
            stop = end
            if sized:
                (nbytes,) = _I32.unpack_from(buf, off)
                off += 4
                if not 0 <= nbytes <= end - off:
                    raise NatNetError(f"model description claims {nbytes} bytes but "
                                      f"{end - off} remain", "section_size")
                stop = off + nbytes
            start = off
            if kind == 0:
                d, off = _marker_set_description(buf, off, stop)
            elif kind == 1:
                d, off = _rb_description(buf, off, stop, version)
            elif sized and kind not in range(7):
                d, off = OtherDescription(kind), stop  # unknown kind: skip by its size
            else:
                d, off = _other_description(kind, buf, off, stop, version)
            if off > stop or sized and off != stop:
                raise NatNetError(f"model description of kind {kind} takes {off - start} "
                                  f"bytes, its size says {stop - start}", "section_size")
            descriptions.append(d)
    except struct.error as exc:
        raise NatNetError(f"truncated MODELDEF ({end} bytes): {exc}", "truncated") from None
    if off != end:
        raise NatNetError(f"{end - off} unexpected bytes after MODELDEF", "trailing_bytes")
    return ModelDef(tuple(descriptions))


def _encode_description(d: Description, version: Version) -> tuple[int, bytes]:
    if isinstance(d, MarkerSetDescription):
        return 0, (_name_bytes(d.name, "marker set name") + _I32.pack(len(d.marker_names))
                   + b"".join(_name_bytes(m, "marker name") for m in d.marker_names))
    if isinstance(d, RigidBodyDescription):
        out = _name_bytes(d.name, "rigid body name") + struct.pack(
            "<ii3f", d.id, d.parent_id, *d.offset)
        out += _I32.pack(len(d.markers))
        out += b"".join(_VEC3.pack(*m.offset) for m in d.markers)
        out += b"".join(_I32.pack(m.active_label) for m in d.markers)
        if version.major >= 4:
            out += b"".join(_name_bytes(m.name, "marker name") for m in d.markers)
        return 1, out
    raise NatNetError(f"cannot encode {type(d).__name__} (kind {getattr(d, 'kind', '?')})",
                      "encode")


def encode_model_def(model: ModelDef, version: Version) -> bytes:
    """MODELDEF payload (marker sets and rigid bodies) in NatNet 3.0, 3.1, 4.0 or 4.1."""
    lay = _encode_layout(version)
    parts = [_I32.pack(len(model.descriptions))]
    try:
        for d in model.descriptions:
            kind, body = _encode_description(d, version)
            parts.append(_I32x2.pack(kind, len(body)) if lay.sizes else _I32.pack(kind))
            parts.append(body)
    except struct.error as exc:
        raise NatNetError(f"cannot encode MODELDEF: {exc}", "encode") from None
    return b"".join(parts)


# ---------------------------------------------------------------------------------------
# Whole datagrams
# ---------------------------------------------------------------------------------------


def _text(buf: bytes) -> str:
    return buf.split(b"\0", 1)[0].decode("utf-8", "replace")


def _fixed(buf: bytes, s: struct.Struct, what: str) -> tuple:
    if len(buf) != s.size:
        raise NatNetError(f"{what} of {len(buf)} bytes, expected {s.size}",
                          "truncated" if len(buf) < s.size else "trailing_bytes")
    return s.unpack(buf)


def _decode_unrecognized(buf: bytes) -> UnrecognizedRequest:
    if len(buf) < _SENDER_BYTES:
        return UnrecognizedRequest()
    name, app, natnet = _decode_sender(buf)
    return UnrecognizedRequest(name, app, natnet)


_EMPTY = {MessageId.KEEPALIVE: KeepAlive(), MessageId.DISCONNECT: Disconnect(),
          MessageId.REQUEST_MODELDEF: RequestModelDef(),
          MessageId.REQUEST_FRAMEOFDATA: RequestFrame()}


def deserialize(packet: bytes | bytearray | memoryview, version: Version, *,
                full: bool = False) -> Message:
    """Decode one datagram; ``version`` is the stream's NatNet version (frames, MODELDEF)."""
    message_id, view = unpack_header(_as_bytes(packet))
    if message_id == MessageId.FRAMEOFDATA:
        return decode_frame(view, version, full=full)
    buf = bytes(view)
    if message_id in _EMPTY:
        return _EMPTY[MessageId(message_id)]  # extra payload bytes are tolerated
    if message_id == MessageId.SERVERINFO:
        return decode_server_info(buf)
    if message_id == MessageId.CONNECT:
        return decode_connect(buf)
    if message_id == MessageId.DISCOVERY:
        return decode_connect(buf, DiscoveryRequest)
    if message_id == MessageId.MODELDEF:
        return decode_model_def(buf, version)
    if message_id == MessageId.REQUEST:
        return Request(_text(buf))
    if message_id == MessageId.RESPONSE:
        return Response(buf)
    if message_id == MessageId.MESSAGESTRING:
        return MessageString(_text(buf))
    if message_id == MessageId.ECHO_REQUEST:
        return EchoRequest(*_fixed(buf, _U64, "ECHO_REQUEST"))
    if message_id == MessageId.ECHO_RESPONSE:
        return EchoResponse(*_fixed(buf, _U64x2, "ECHO_RESPONSE"))
    if message_id == MessageId.UNRECOGNIZED_REQUEST:
        return _decode_unrecognized(buf)
    raise NatNetError(f"unknown message id {message_id}", "unknown_message")


def serialize(message: Message, version: Version = V3_0) -> bytes:
    """Encode one message as a datagram (header included)."""
    m = message
    if isinstance(m, Frame):
        return pack_header(MessageId.FRAMEOFDATA, encode_frame(m, version))
    if isinstance(m, ServerInfo):
        return pack_header(MessageId.SERVERINFO, encode_server_info(m))
    if isinstance(m, DiscoveryRequest):
        return pack_header(MessageId.DISCOVERY, encode_connect(m))
    if isinstance(m, ConnectRequest):
        return pack_header(MessageId.CONNECT, encode_connect(m))
    if isinstance(m, ModelDef):
        return pack_header(MessageId.MODELDEF, encode_model_def(m, version))
    if isinstance(m, Request):
        return pack_header(MessageId.REQUEST, _name_bytes(m.command, "request"))
    if isinstance(m, Response):
        return pack_header(MessageId.RESPONSE, m.payload)
    if isinstance(m, MessageString):
        return pack_header(MessageId.MESSAGESTRING, _name_bytes(m.text, "message"))
    if isinstance(m, EchoRequest):
        return pack_header(MessageId.ECHO_REQUEST, _U64.pack(m.timestamp))
    if isinstance(m, EchoResponse):
        return pack_header(MessageId.ECHO_RESPONSE,
                           _U64x2.pack(m.request_timestamp, m.received_timestamp))
    if isinstance(m, UnrecognizedRequest):
        body = b"" if m.app_version is None and m.natnet_version is None and not m.app_name \
            else _encode_sender(m.app_name, m.app_version, m.natnet_version)
        return pack_header(MessageId.UNRECOGNIZED_REQUEST, body)
    for message_id, empty in _EMPTY.items():
        if m == empty:
            return pack_header(message_id, b"")
    raise NatNetError(f"cannot serialize {type(m).__name__}", "encode")


# ---------------------------------------------------------------------------------------
# Coordinates
# ---------------------------------------------------------------------------------------


def to_ground_plane(position: Sequence[float], orientation: Sequence[float],
                    up_axis: Literal["y", "z"] = "y") -> tuple[float, float, float]:
    """Map a Motive pose to the ground plane: (x, y, yaw), metres and radians.

    Motive is right-handed. With ``up_axis="y"`` (Motive's default) the ground frame is
    X = x, Y = -z, Z(up) = y, a proper rotation (+90 deg about x) of Motive's axes, so
    counter-clockwise seen from above stays counter-clockwise. With ``"z"`` the ground
    frame is Motive's own x, y.

    Yaw is the heading of the body's +x axis projected on the ground plane (a rigid body
    created in Motive with the car facing +x has yaw 0), measured counter-clockwise from
    ground X. With q = (qx, qy, qz, qw) of any norm, the body x axis in Motive coordinates
    is ``(w^2 + x^2 - y^2 - z^2, 2(xy + wz), 2(xz - wy))`` (times |q|^2), hence

        Y-up: yaw = atan2(2(wy - xz), w^2 + x^2 - y^2 - z^2)   (ground Y = -z)
        Z-up: yaw = atan2(2(wz + xy), w^2 + x^2 - y^2 - z^2)

    so a rotation by +theta about the up axis gives yaw = +theta in both cases.
    """
    x, y, z = position
    qx, qy, qz, qw = orientation
    heading_x = qw * qw + qx * qx - qy * qy - qz * qz
    if up_axis == "y":
        return float(x), float(-z), math.atan2(2.0 * (qw * qy - qx * qz), heading_x)
    if up_axis == "z":
        return float(x), float(y), math.atan2(2.0 * (qw * qz + qx * qy), heading_x)
    raise ValueError(f"up_axis must be 'y' or 'z', not {up_axis!r}")


def from_ground_plane(x: float, y: float, yaw: float, height: float = 0.0,
                      up_axis: str = "y") -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """The inverse of :func:`to_ground_plane`: a Motive position and quaternion (xyzw)
    for a body at (x, y) on the ground, ``height`` above it, turned ``yaw`` about up."""
    s, c = math.sin(yaw / 2.0), math.cos(yaw / 2.0)
    if up_axis == "y":
        return (float(x), float(height), float(-y)), (0.0, s, 0.0, c)
    if up_axis == "z":
        return (float(x), float(y), float(height)), (0.0, 0.0, s, c)
    raise ValueError(f"up_axis must be 'y' or 'z', not {up_axis!r}")

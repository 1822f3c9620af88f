"""The messages built on the sender block: CONNECT (0) and DISCOVERY (14), with which a
client introduces itself, SERVERINFO (1), the server's answer, and UNRECOGNIZED_REQUEST
(100). Decoded and encoded.

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

UNRECOGNIZED_REQUEST (100)
--------------------------
Empty, or the server's sender block (Motive attaches it).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from .common import _ZERO_VERSION, NatNetError, Version, _as_bytes, _name_bytes

_CONN_INFO = struct.Struct("<QHB4s")  # SERVERINFO connection info: 15 bytes
_SENDER_BYTES = 264
_SERVERINFO_BYTES = _SENDER_BYTES + _CONN_INFO.size
_NAME_BYTES = 256


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
class UnrecognizedRequest:
    """UNRECOGNIZED_REQUEST; Motive attaches its sender block, others send nothing."""

    app_name: str = ""
    app_version: Version | None = None
    natnet_version: Version | None = None


# ---------------------------------------------------------------------------------------
# Sender block, SERVERINFO, CONNECT, UNRECOGNIZED_REQUEST
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


def _decode_unrecognized(buf: bytes) -> UnrecognizedRequest:
    if len(buf) < _SENDER_BYTES:
        return UnrecognizedRequest()
    name, app, natnet = _decode_sender(buf)
    return UnrecognizedRequest(name, app, natnet)

"""Whole datagrams: :func:`deserialize` checks the header (:mod:`.common`) and hands the
payload to the decoder of its message id; :func:`serialize` encodes any message with its
header. The byte layouts are in the message modules: :mod:`.frame`, :mod:`.model`,
:mod:`.handshake` and :mod:`.commands`.
"""

from __future__ import annotations

import struct
from typing import Union

from .commands import (
    Disconnect,
    EchoRequest,
    EchoResponse,
    KeepAlive,
    MessageString,
    Request,
    RequestFrame,
    RequestModelDef,
    Response,
)
from .common import V3_0, MessageId, NatNetError, Version, _as_bytes, _name_bytes, pack_header, unpack_header
from .frame import Frame, decode_frame, encode_frame
from .handshake import (
    ConnectRequest,
    DiscoveryRequest,
    ServerInfo,
    UnrecognizedRequest,
    _decode_unrecognized,
    _encode_sender,
    decode_connect,
    decode_server_info,
    encode_connect,
    encode_server_info,
)
from .model import ModelDef, decode_model_def, encode_model_def

Message = Union[Frame, ServerInfo, ConnectRequest, DiscoveryRequest, Request, Response,
                MessageString, KeepAlive, Disconnect, RequestModelDef, RequestFrame,
                EchoRequest, EchoResponse, UnrecognizedRequest, ModelDef]

_U64 = struct.Struct("<Q")
_U64x2 = struct.Struct("<QQ")


def _text(buf: bytes) -> str:
    return buf.split(b"\0", 1)[0].decode("utf-8", "replace")


def _fixed(buf: bytes, s: struct.Struct, what: str) -> tuple:
    if len(buf) != s.size:
        raise NatNetError(f"{what} of {len(buf)} bytes, expected {s.size}",
                          "truncated" if len(buf) < s.size else "trailing_bytes")
    return s.unpack(buf)


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

"""NatNet wire codec: datagrams <-> frozen dataclasses, no sockets.

NatNet is OptiTrack Motive's UDP streaming protocol. This package decodes and encodes its
messages exactly as laid out by the NatNet SDK (the ``PacketClient.cpp`` and
``NatNetClient.py`` direct-depacketization samples of SDK 3.x/4.x). Frames and model
definitions of NatNet 3.0, 3.1, 4.0, 4.1 and 4.2 are decoded and encoded; 4.3 and 4.4 are
decoded with the 4.2 layout (as the SDK's 2025 sample reads them); frames of the legacy
2.x layouts (2.0 to 2.11, tested on 2.5/2.7/2.9 captures) are decoded only. Every decoding problem raises
:class:`NatNetError` (a ``ValueError``) with a ``reason`` for counters; nothing else
escapes a decoder.

One module per message, each with the byte layout it reads and writes:

* :mod:`.common` -- the packet header and message ids, versions and which fields each
  version's frame carries, :class:`NatNetError`, the shared buffer readers;
* :mod:`.frame` -- FRAMEOFDATA: the section table and the suffix;
  :mod:`.sections` -- the items in those sections (the rigid body's 38 bytes, ...);
* :mod:`.model` -- MODELDEF and its description kinds;
* :mod:`.handshake` -- the sender block, CONNECT, DISCOVERY, SERVERINFO,
  UNRECOGNIZED_REQUEST;
* :mod:`.commands` -- REQUEST, RESPONSE, MESSAGESTRING, KEEPALIVE, DISCONNECT, ECHO, ...;
* :mod:`.packet` -- :func:`serialize` and :func:`deserialize` over all of them;
* :mod:`.coordinates` -- Motive poses on the planner's ground plane.

Imports point one way only: common <- sections <- frame; common <- model, handshake,
commands; all of them <- packet <- this package. Everything public is re-exported here:
callers write ``from trustfg.bridge import natnet`` and ``natnet.decode_frame(...)``.
"""

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
from .common import (
    DEFAULT_STREAM_VERSION,
    DEFAULT_VERSION,
    FRAME_VERSIONS,
    LATEST_DECODED,
    MAX_PAYLOAD_BYTES,
    NEWEST_LAYOUT,
    STREAM_VERSIONS,
    V2_5,
    V2_7,
    V2_9,
    V3_0,
    V3_1,
    V4_0,
    V4_1,
    V4_2,
    MessageId,
    NatNetError,
    Version,
    pack_header,
    peek_message_id,
    supports_frames,
    unpack_header,
)
from .coordinates import from_ground_plane as from_ground_plane
from .coordinates import to_ground_plane
from .frame import Frame, decode_frame, encode_frame
from .handshake import (
    ConnectionInfo,
    ConnectRequest,
    DiscoveryRequest,
    ServerInfo,
    UnrecognizedRequest,
    decode_connect,
    decode_server_info,
    encode_connect,
    encode_server_info,
)
from .model import (
    MarkerSetDescription,
    ModelDef,
    OtherDescription,
    RigidBodyDescription,
    RigidBodyMarker,
    decode_model_def,
    encode_model_def,
)
from .packet import Message, deserialize, serialize
from .sections import AnalogDevice, Asset, LabeledMarker, MarkerSet, RigidBody, Skeleton

__all__ = [
    "NatNetError", "MessageId", "Version", "V2_5", "V2_7", "V2_9", "V3_0", "V3_1", "V4_0",
    "V4_1", "V4_2", "NEWEST_LAYOUT", "LATEST_DECODED", "FRAME_VERSIONS", "STREAM_VERSIONS", "DEFAULT_VERSION", "DEFAULT_STREAM_VERSION", "RigidBody", "MarkerSet", "LabeledMarker", "Skeleton", "Asset",
    "AnalogDevice", "Frame", "ConnectionInfo", "ServerInfo", "ConnectRequest",
    "DiscoveryRequest", "Request", "Response", "MessageString", "KeepAlive", "Disconnect",
    "RequestModelDef", "RequestFrame", "EchoRequest", "EchoResponse", "UnrecognizedRequest",
    "MarkerSetDescription", "RigidBodyMarker", "RigidBodyDescription", "OtherDescription",
    "ModelDef", "Message", "pack_header", "unpack_header", "peek_message_id",
    "decode_frame", "encode_frame", "decode_server_info", "encode_server_info",
    "decode_connect", "encode_connect", "decode_model_def", "encode_model_def",
    "serialize", "deserialize", "supports_frames", "to_ground_plane", "MAX_PAYLOAD_BYTES",
]

"""NatNet wire codec: datagrams <-> frozen dataclasses, no sockets.

NatNet is OptiTrack Motive's UDP streaming protocol; this package reads and writes its
messages as the NatNet SDK's depacketization samples lay them out. Frames and model
definitions of 3.0 to 4.2 are decoded and encoded, 4.3 and 4.4 decoded with the 4.2 layout,
frames of the legacy 2.x layouts decoded only. Every decoding problem raises
:class:`NatNetError` (a ``ValueError``) with a ``reason`` for counters; nothing else escapes.

One module per message, each with the byte layout it reads and writes: :mod:`.common`
(header, ids, versions, each version's layout), :mod:`.frame` and :mod:`.sections`
(FRAMEOFDATA), :mod:`.model` (MODELDEF), :mod:`.handshake` (CONNECT, SERVERINFO, ...),
:mod:`.commands` (the small requests), :mod:`.packet` (:func:`serialize`,
:func:`deserialize`) and :mod:`.coordinates` (Motive poses on the ground plane). Imports
point one way, ``common`` first and ``packet`` last; everything public is re-exported here.
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

"""The handshake messages: SERVERINFO and CONNECT/DISCOVERY from Motive captures, every
CONNECT variant a server must accept, and their round trips."""

from __future__ import annotations

import pytest

from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0, V3_1, V4_1, MessageId, Version

# ---------------------------------------------------------------------------------------
# SERVERINFO
# ---------------------------------------------------------------------------------------


def test_server_info_capture(capture):
    info = nn.deserialize(capture("serverinfo_packet_v3.bin"), V3_0)
    assert info == nn.ServerInfo("Motive", Version(2, 1, 0, 0), Version(3, 0, 0, 0),
                                 nn.ConnectionInfo(3312787, 1511, True, "239.255.42.99"))


def test_server_info_reencodes_except_the_garbage_after_the_name(capture):
    packet = capture("serverinfo_packet_v3.bin")
    again = nn.serialize(nn.deserialize(packet, V3_0))
    assert len(again) == len(packet) == 4 + 279
    assert again[:4 + 7] == packet[:4 + 7]  # header and "Motive\0"
    assert again[4 + 256:] == packet[4 + 256:]
    assert packet[4 + 7:4 + 256] != bytes(249)  # Motive really sends garbage there


# ---------------------------------------------------------------------------------------
# CONNECT and DISCOVERY variants
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name, cls", [("connect_packet_v3.bin", nn.ConnectRequest),
                                       ("discovery_packet_v3.bin", nn.DiscoveryRequest)])
def test_natnetlib_connect_and_discovery(capture, name, cls):
    packet = capture(name)
    request = nn.deserialize(packet, V3_0)
    assert type(request) is cls
    assert request == cls("NatNetLib", Version(3, 0, 0, 0), Version(3, 0, 0, 0))
    assert len(packet) == 4 + 264 and nn.serialize(request) == packet


def python_sample_connect(version: Version) -> bytes:
    """What the official SDK Python sample sends: 270 bytes, "Ping", version at 265, + NUL."""
    body = bytearray(270)
    body[0:4] = b"Ping"
    body[265:269] = version.to_bytes()
    return nn.pack_header(MessageId.CONNECT, bytes(body) + b"\0")


def test_every_connect_variant_decodes(capture):
    assert nn.deserialize(nn.pack_header(0, b""), V3_0) == nn.ConnectRequest()
    assert nn.deserialize(nn.pack_header(0, b"Ping\0"), V3_0) == nn.ConnectRequest("Ping")
    natnetlib = nn.deserialize(capture("connect_packet_v3.bin"), V3_0)
    assert natnetlib.stream_version == Version(3, 0)
    sample = nn.deserialize(python_sample_connect(Version(4, 2)), V3_0)
    assert len(python_sample_connect(Version(4, 2))) == 4 + 271
    assert sample == nn.ConnectRequest("Ping", requested_version=Version(4, 2))
    assert sample.stream_version == Version(4, 2)


@pytest.mark.parametrize("request_", [
    nn.ConnectRequest(), nn.ConnectRequest("Ping"),
    nn.ConnectRequest("trustfg", Version(0, 1), V4_1),
    nn.ConnectRequest("trustfg", Version(0, 1), V4_1, True, V3_1),
    nn.DiscoveryRequest("NatNetLib", Version(3), Version(3)),
])
def test_connect_round_trips(request_):
    assert nn.deserialize(nn.serialize(request_), V3_0) == request_

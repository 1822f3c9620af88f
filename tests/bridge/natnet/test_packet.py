"""The NatNet packet layer: the header, message ids, versions, and deserialize over every
datagram of a recorded Motive session."""

from __future__ import annotations

import hashlib

import pytest

from tests.bridge.conftest import reason_of
from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0, V3_1, V4_0, V4_1, MessageId, NatNetError, Version

# ---------------------------------------------------------------------------------------
# Captures and the whole recorded session
# ---------------------------------------------------------------------------------------


def test_capture_files_match_their_checksums(captures):
    for line in (captures / "SHA256SUMS").read_text().splitlines():
        digest, name = line.split(maxsplit=1)
        assert hashlib.sha256((captures / name).read_bytes()).hexdigest() == digest, name


def test_every_datagram_of_the_session_decodes(traffic):
    assert len(traffic) == 550
    kinds = [type(nn.deserialize(d.payload, V3_0)).__name__ for d in traffic]
    assert kinds.count("Frame") == 518
    for name in ("DiscoveryRequest", "ConnectRequest", "ServerInfo", "Request", "Response",
                 "EchoRequest", "EchoResponse", "RequestModelDef", "ModelDef",
                 "UnrecognizedRequest"):
        assert name in kinds


# ---------------------------------------------------------------------------------------
# Header, message ids, versions
# ---------------------------------------------------------------------------------------


def test_header_errors():
    assert reason_of(b"\x07") == "truncated"
    assert reason_of(b"\x07\x00\x10\x00" + bytes(8)) == "size_mismatch"
    assert reason_of(nn.pack_header(55, b"")) == "unknown_message"
    assert issubclass(NatNetError, ValueError)


def test_message_ids_are_the_sdk_numbers():
    assert [int(m) for m in MessageId] == [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 12, 13, 14, 100]
    assert nn.peek_message_id(b"\x07\x00") == 7 and nn.peek_message_id(b"\x07") is None


def test_version_parse_and_order():
    assert Version.parse("4.1") == Version(4, 1, 0, 0) == V4_1
    assert str(Version.parse("3.0.0.0")) == "3.0.0.0"
    assert nn.V2_9 < V3_0 < V3_1 < V4_0 < V4_1
    for bad in ("", "4.x", "256.0", "1.2.3.4.5"):
        with pytest.raises(ValueError):
            Version.parse(bad)

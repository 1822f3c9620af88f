"""The small command-channel messages: captured requests, responses and echoes, round
trips of every simple message, and fixed sizes enforced."""

from __future__ import annotations

import pytest

from tests.bridge.conftest import reason_of
from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0, V4_1, MessageId, NatNetError, Version


def test_echo_request_and_response(capture):
    request = nn.deserialize(capture("echorequest_packet_v3.bin"), V3_0)
    response = nn.deserialize(capture("echoresponse_packet_v3.bin"), V3_0)
    assert request == nn.EchoRequest(278554190)
    assert response.request_timestamp == 278554190
    assert nn.serialize(request) == capture("echorequest_packet_v3.bin")
    assert nn.serialize(response) == capture("echoresponse_packet_v3.bin")


def test_requests_responses_and_unrecognized_request(capture):
    assert nn.deserialize(capture("requestmodeldef_packet_v3.bin"), V3_0) == nn.RequestModelDef()
    assert nn.deserialize(capture("request_FrameRate_v3.bin"), V3_0) == nn.Request("FrameRate")
    assert nn.serialize(nn.Request("FrameRate")) == capture("request_FrameRate_v3.bin")
    rate = nn.deserialize(capture("response_FrameRate_120Hz_v3.bin"), V3_0)
    assert rate.as_float() == 120.0
    assert nn.deserialize(capture("response_AnalogSamplesPerMocapFrame_v3.bin"), V3_0).as_int() == 0
    unrecognized_packet = capture("unrecognized_request_id100_v3.bin")
    assert unrecognized_packet[:2] == b"\x64\x00"  # 100 decimal on the wire
    unrecognized = nn.deserialize(unrecognized_packet, V3_0)
    assert unrecognized == nn.UnrecognizedRequest("NatNetLib", Version(3), Version(3))


@pytest.mark.parametrize("message", [
    nn.KeepAlive(), nn.Disconnect(), nn.RequestModelDef(), nn.RequestFrame(),
    nn.Request("FrameRate"), nn.Response(b"\x01\x02\x03\x04"), nn.MessageString("hello"),
    nn.EchoRequest(2 ** 63), nn.EchoResponse(1, 2), nn.UnrecognizedRequest(),
    nn.UnrecognizedRequest("mocap_sim", Version(0, 1), V4_1),
    nn.ServerInfo("mocap_sim", Version(0, 1, 2, 3), V4_1,
                  nn.ConnectionInfo(10_000_000, 1511, False, "239.255.42.99")),
    nn.ServerInfo("old", Version(1, 5), Version(2, 5), None),
])
def test_simple_messages_round_trip(message):
    assert nn.deserialize(nn.serialize(message), V4_1) == message


def test_empty_messages_tolerate_the_python_sample_trailing_nul():
    # the SDK Python sample sends KEEPALIVE and REQUEST_MODELDEF with a 1-byte payload "\0"
    assert nn.deserialize(nn.pack_header(MessageId.KEEPALIVE, b"\0"), V3_0) == nn.KeepAlive()
    assert nn.deserialize(nn.pack_header(MessageId.REQUEST_MODELDEF, b"\0"), V3_0) == \
        nn.RequestModelDef()


def test_fixed_size_messages_reject_wrong_sizes():
    assert reason_of(nn.pack_header(MessageId.ECHO_REQUEST, bytes(7))) == "truncated"
    assert reason_of(nn.pack_header(MessageId.ECHO_RESPONSE, bytes(17))) == "trailing_bytes"
    assert reason_of(nn.pack_header(MessageId.SERVERINFO, bytes(270))) == "truncated"
    with pytest.raises(NatNetError):
        nn.Response(b"\0\0").as_float()

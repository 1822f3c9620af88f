"""NatNet 4.2 (Motive 3.2 and later): byte vectors written by hand from the SDK's documented
layout, not by our encoder.

Source of the layout: the NatNet SDK's direct-depacketization samples. NatNetClient.py
(SDK 4.2+, ``__unpack_rigid_body_descript_4_2_to_current``): a rigid-body description is
name, id, parent id, offset vec3, then -- new in 4.2 -- a rotation quaternion (4 float32,
x y z w), then the marker count, offsets, active labels and names; descriptions carry
their byte size from 4.1 on (``__unpack_data_descriptions``). Frames keep the 4.1 layout
(``__unpack_mocap_data``: section byte counts for 4.1+, assets from 4.1, the precision
timestamp in the suffix). The SDK reads every 4.x from 4.2 on with this layout.
"""

from __future__ import annotations

import struct

import pytest

from tests.bridge.test_natnet_client import FakeServer, server_info, unicast_options
from tests.conftest import wait_for
from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V4_1, V4_2, MessageId, NatNetError, Version
from trustfg.bridge.natnet_client import NatNetClient, NatNetClientOptions
from trustfg.mocap_sim.natnet_server import NatNetServer, NatNetServerOptions

pytestmark = pytest.mark.realtime

ROTATION = (0.0, 0.70710677, 0.0, 0.70710677)  # 90 degrees about Motive's y (up)


def cstr(text: str) -> bytes:
    return text.encode() + b"\0"


def rigid_body_description_42() -> bytes:
    """car7 (id 7, parent -1), offset (0.1, 0.2, 0.3), ROTATION, two markers."""
    return (cstr("car7") + struct.pack("<i", 7) + struct.pack("<i", -1) + struct.pack("<3f", 0.1, 0.2, 0.3)
            + struct.pack("<4f", *ROTATION)
            + struct.pack("<i", 2)
            + struct.pack("<3f", 0.05, 0.0, 0.0) + struct.pack("<3f", -0.05, 0.0, 0.02)
            + struct.pack("<i", 11) + struct.pack("<i", 12)
            + cstr("front") + cstr("back"))


def marker_set_description() -> bytes:
    return cstr("car7") + struct.pack("<i", 2) + cstr("front") + cstr("back")


def modeldef_42_payload() -> bytes:
    """Two descriptions, each: int32 kind, int32 byte size (4.1+), the description."""
    rb, ms = rigid_body_description_42(), marker_set_description()
    return (struct.pack("<i", 2)
            + struct.pack("<i", 0) + struct.pack("<i", len(ms)) + ms
            + struct.pack("<i", 1) + struct.pack("<i", len(rb)) + rb)


def frame_42_payload() -> bytes:
    """Frame 4242 with one tracked rigid body (id 7); every other section empty."""
    body = (struct.pack("<i", 7) + struct.pack("<3f", 1.0, 0.05, -2.0) + struct.pack("<4f", *ROTATION)
            + struct.pack("<f", 0.0005) + struct.pack("<h", 1))  # mean error, params: tracked
    assert len(body) == 38
    empty = struct.pack("<i", 0) + struct.pack("<i", 0)  # count 0, byte size 0
    return (struct.pack("<i", 4242)
            + empty                                     # marker sets
            + empty                                     # legacy markers
            + struct.pack("<i", 1) + struct.pack("<i", len(body)) + body  # rigid bodies
            + empty                                     # skeletons
            + empty                                     # assets (4.1+)
            + empty                                     # labeled markers
            + empty                                     # force plates
            + empty                                     # devices
            + struct.pack("<I", 0x01020304) + struct.pack("<I", 5)  # timecode, subframe
            + struct.pack("<d", 35.25)                  # timestamp, s
            + struct.pack("<QQQ", 1000, 2000, 3000)     # mid-exposure, received, transmit ticks
            + struct.pack("<II", 1_700_000_000, 123)    # precision timestamp s, fraction (4.1+)
            + struct.pack("<h", 0)                      # params
            + struct.pack("<i", 0))                     # end of data


def test_a_4_2_model_definition_by_hand_decodes_with_the_rotation():
    model = nn.decode_model_def(modeldef_42_payload(), V4_2)
    (rb,) = model.rigid_bodies
    assert (rb.name, rb.id, rb.parent_id) == ("car7", 7, -1)
    assert rb.offset == pytest.approx((0.1, 0.2, 0.3))
    assert rb.rotation == pytest.approx(ROTATION)
    assert [(m.name, m.active_label) for m in rb.markers] == [("front", 11), ("back", 12)]
    assert rb.markers[1].offset == pytest.approx((-0.05, 0.0, 0.02))
    assert model.marker_sets[0].marker_names == ("front", "back")


def test_the_encoder_writes_the_hand_built_bytes():
    model = nn.decode_model_def(modeldef_42_payload(), V4_2)
    assert nn.encode_model_def(model, V4_2) == modeldef_42_payload()
    packet = nn.serialize(model, V4_2)
    assert packet[:4] == struct.pack("<HH", MessageId.MODELDEF, len(modeldef_42_payload()))


def test_a_4_1_parser_misreads_the_4_2_description():
    """The mechanism: without the rotation the quaternion's bytes are read as the marker
    count, and the description's byte size (4.1+) no longer adds up."""
    with pytest.raises(NatNetError):
        nn.decode_model_def(modeldef_42_payload(), V4_1)


@pytest.mark.parametrize("version", [V4_2, Version(4, 3), Version(4, 4)])
def test_4_2_and_later_frames_by_hand_decode(version):
    frame = nn.decode_frame(frame_42_payload(), version)
    assert frame.frame_number == 4242
    (body,) = frame.rigid_bodies
    assert body.id == 7 and body.tracking_valid
    assert body.position == pytest.approx((1.0, 0.05, -2.0)) and body.orientation == pytest.approx(ROTATION)
    assert (frame.timecode, frame.timecode_subframe, frame.timestamp) == (0x01020304, 5, 35.25)
    assert (frame.precision_timestamp_s, frame.precision_timestamp_fraction) == (1_700_000_000, 123)
    assert nn.decode_model_def(modeldef_42_payload(), version).rigid_bodies[0].rotation == pytest.approx(ROTATION)


def test_newer_versions_than_documented_are_refused_not_guessed():
    with pytest.raises(NatNetError) as err:
        nn.decode_frame(frame_42_payload(), Version(4, 5))
    assert err.value.reason == "unsupported_version"


def test_mocap_sim_serves_4_2_and_the_client_learns_names_and_ids():
    bodies = [(7, "car7", (1.0, 0.05, -2.0), ROTATION, True), (9, "car9", (0.0, 0.05, 0.0), (0, 0, 0, 1), True)]
    options = NatNetServerOptions(natnet_version=V4_2, address="127.0.0.1", command_port=0, multicast=False,
                                  data_port=0)
    with NatNetServer(options, lambda t: bodies) as server:
        client_options = NatNetClientOptions(server_address="127.0.0.1", command_port=server.command_address[1],
                                             multicast=False, local_address="127.0.0.1")
        with NatNetClient(client_options) as client:
            assert client.version == V4_2
            assert client.wait_for_frames(5, timeout_s=5.0)
            assert client.latest(7).body.orientation == pytest.approx(ROTATION)
            assert wait_for(lambda: client.body_ids() == {"car7": 7, "car9": 9}, 5.0), client.body_ids()
            assert client.stats().rejected_total == 0


def test_a_server_announcing_4_4_is_read_with_the_4_2_layout_and_its_model_kept():
    """Negotiation: the client announces 4.2, takes the server's 4.4 (the SDK's "4.2 to
    current"), decodes its frames and its model definitions with the 4.2 layout."""
    def reply(packet, sender):
        message = nn.peek_message_id(packet)
        if message == MessageId.CONNECT:
            assert nn.decode_connect(nn.unpack_header(packet)[1]).natnet_version == V4_2
            return [server_info(Version(4, 4))]
        if message == MessageId.REQUEST_MODELDEF:
            return [nn.pack_header(MessageId.MODELDEF, modeldef_42_payload())]
        return []

    with FakeServer(reply) as server:
        with NatNetClient(unicast_options(server)) as client:
            assert client.version == Version(4, 4)
            assert wait_for(lambda: client.body_ids() == {"car7": 7}, 5.0)
            server.send(nn.pack_header(MessageId.FRAMEOFDATA, frame_42_payload()), client.local_address)
            assert client.wait_for_frames(1, timeout_s=5.0)
            assert client.latest(7).body.position == pytest.approx((1.0, 0.05, -2.0))

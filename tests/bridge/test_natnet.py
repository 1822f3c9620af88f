"""The NatNet codec against real Motive captures, golden bytes and the SDK layouts."""

from __future__ import annotations

import hashlib
import math
import re
import struct
from decimal import ROUND_HALF_UP, Decimal

import pytest

from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0, V3_1, V4_0, V4_1, Frame, MessageId, NatNetError, RigidBody, Version

V3_FRAME = "mocapframe_packet_v3.bin"
CLOCK_HZ = 3312787  # from the SERVERINFO of the same session


def approx(values, rel=0, abs=5e-7):
    return pytest.approx(tuple(values), rel=rel, abs=abs)


# ---------------------------------------------------------------------------------------
# Captures: the values the captures README lists
# ---------------------------------------------------------------------------------------


def test_capture_files_match_their_checksums(captures):
    for line in (captures / "SHA256SUMS").read_text().splitlines():
        digest, name = line.split(maxsplit=1)
        assert hashlib.sha256((captures / name).read_bytes()).hexdigest() == digest, name


def test_motive_3_0_frame_decodes_to_the_documented_values(capture):
    packet = capture(V3_FRAME)
    frame = nn.deserialize(packet, V3_0)
    assert isinstance(frame, Frame)
    assert frame.frame_number == 162734
    (body,) = frame.rigid_bodies
    assert body.id == 2
    assert body.position == approx((0.1744466, 1.4471314, -0.7343040))
    assert body.orientation == approx((-0.05459423, 0.5099482, 0.04370357, -0.8573577))
    assert body.mean_error == pytest.approx(0.00051522, abs=5e-9)
    assert body.tracking_valid
    assert frame.timestamp == pytest.approx(1356.1166667, abs=1e-6)
    assert frame.timestamp == pytest.approx(frame.frame_number / 120, abs=1e-9)
    assert frame.params == 0 and not frame.is_recording and not frame.tracked_models_changed
    full = nn.deserialize(packet, V3_0, full=True)
    assert len(full.legacy_markers) == 5 and len(full.labeled_markers) == 6
    assert [(m.model_id, m.marker_id) for m in full.labeled_markers] == \
        [(2, 1), (2, 2), (2, 3), (2, 4), (2, 5), (0, 50007)]
    # the rigid body params word on the wire is exactly 1 (tracking valid)
    assert packet[4 + 72 + 4 + 36:4 + 72 + 4 + 38] == b"\x01\x00"


def test_occluded_capture_has_two_marker_sets_and_one_occluded_marker(capture):
    frame = nn.deserialize(capture("mocapframe_packet_occluded_v3.bin"), V3_0, full=True)
    assert frame.frame_number == 269007
    assert frame.timestamp == pytest.approx(269007 / 30)  # streamed at 30 Hz
    assert [s.name for s in frame.marker_sets] == ["FakeTree", "all"]
    (body,) = frame.rigid_bodies
    assert body.id == 7 and body.tracking_valid
    assert body.position == approx((-0.15413, 0.28294, 0.47066), abs=5e-6)
    assert body.orientation == approx((-0.000334, -0.000148, 0.005249, -0.999986), abs=5e-7)
    assert [m.occluded for m in frame.labeled_markers].count(True) == 1


def test_last_frame_of_the_session(capture):
    frame = nn.deserialize(capture("mocapframe_last_frame163251_v3.bin"), V3_0)
    assert frame.frame_number == 163251
    assert frame.rigid_bodies[0].id == 2
    assert frame.rigid_bodies[0].position == approx((0.17444, 1.44713, -0.73431), abs=5e-6)


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


def test_model_def_capture_and_golden_bytes(capture):
    packet = capture("modeldef_packet_v3.bin")
    model = nn.deserialize(packet, V3_0)
    (quad,) = model.rigid_bodies
    assert (quad.name, quad.id, quad.parent_id, quad.offset) == ("RaceQuad", 2, -1, (0, 0, 0))
    assert len(quad.markers) == 5
    assert quad.markers[0].offset == approx((0.161159, 0.0350516, -0.0321813), abs=5e-7)
    assert [m.name for m in quad.markers] == [""] * 5  # names are on the wire from 4.0
    assert [s.name for s in model.marker_sets] == ["RaceQuad", "all"]
    assert model.marker_sets[0].marker_names == tuple(f"Marker{i}" for i in range(1, 6))
    assert model.marker_sets[1].marker_names == tuple(f"RaceQuad_{i}" for i in range(1, 6))
    assert nn.serialize(model, V3_0) == packet


@pytest.mark.parametrize("name, cls", [("connect_packet_v3.bin", nn.ConnectRequest),
                                       ("discovery_packet_v3.bin", nn.DiscoveryRequest)])
def test_natnetlib_connect_and_discovery(capture, name, cls):
    packet = capture(name)
    request = nn.deserialize(packet, V3_0)
    assert type(request) is cls
    assert request == cls("NatNetLib", Version(3, 0, 0, 0), Version(3, 0, 0, 0))
    assert len(packet) == 4 + 264 and nn.serialize(request) == packet


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


# ---------------------------------------------------------------------------------------
# The whole recorded session
# ---------------------------------------------------------------------------------------


def test_every_datagram_of_the_session_decodes(traffic):
    assert len(traffic) == 550
    kinds = [type(nn.deserialize(d.payload, V3_0)).__name__ for d in traffic]
    assert kinds.count("Frame") == 518
    for name in ("DiscoveryRequest", "ConnectRequest", "ServerInfo", "Request", "Response",
                 "EchoRequest", "EchoResponse", "RequestModelDef", "ModelDef",
                 "UnrecognizedRequest"):
        assert name in kinds


def test_all_518_frames_are_consecutive_and_reencode_exactly(traffic):
    frames = [d for d in traffic if d.dst_port == 1511]
    assert len(frames) == 518
    assert {(d.dst, len(d.payload)) for d in frames} == {("239.255.42.99", 336)}
    decoded = [nn.deserialize(d.payload, V3_0) for d in frames]
    assert [f.frame_number for f in decoded] == list(range(162734, 163252))
    for d, frame in zip(frames, decoded):
        (body,) = frame.rigid_bodies
        assert body.id == 2 and body.tracking_valid
        assert body.position == approx((0.17444, 1.44713, -0.73430), abs=2e-4)
        assert frame.timestamp == pytest.approx(frame.frame_number / 120, abs=1e-6)
        assert frame.camera_mid_exposure_ticks < frame.camera_data_received_ticks \
            < frame.transmit_ticks
        assert nn.serialize(nn.deserialize(d.payload, V3_0, full=True), V3_0) == d.payload


def _sample_client_frames(log: str) -> dict[int, dict]:
    """FrameID -> timestamp, latencies and rigid body line of the SDK SampleClient log."""
    frames: dict[int, dict] = {}
    current = None
    expect_pose = False
    for line in log.splitlines():
        if m := re.match(r"FrameID : (\d+)", line):
            current = frames.setdefault(int(m[1]), {})
        elif current is None:
            continue
        elif m := re.match(r"Timestamp : ([\d.]+)", line):
            current["timestamp"] = m[1]
        elif m := re.match(r"(Software|System) latency : ([\d.]+) milliseconds", line):
            current[m[1].lower()] = m[2]
        elif m := re.match(r"Rigid Body \[ID=(\d+)\s+Error=([\d.]+)\s+Valid=(\d)\]", line):
            current["body"] = (int(m[1]), m[2], int(m[3]))
        elif re.match(r"\s*x\s+y\s+z\s+qx", line):
            expect_pose = True
        elif expect_pose and re.match(r"\s*-?\d", line):
            current["pose"] = line.split()
            expect_pose = False
    return frames


def msvc_2f(value: float) -> str:
    """printf("%.2f") as the SampleClient's (Windows, pre-UCRT) C runtime does it: the double
    is first cut to 17 significant digits, then rounded half away from zero. Python's
    exact round-half-even differs on ties: 1356.125 -> "1356.13" and 1356.175 (really
    1356.17499999999995...) -> "1356.18" in the log."""
    return str(Decimal(f"{value:.17g}").quantize(Decimal("0.01"), rounding=ROUND_HALF_UP))


def test_frames_agree_with_the_sdk_sample_client_log(traffic, sample_client_log):
    logged = _sample_client_frames(sample_client_log)
    assert len(logged) == 251
    decoded = {f.frame_number: f for f in (nn.deserialize(d.payload, V3_0) for d in traffic
                                           if d.dst_port == 1511)}
    for number, entry in logged.items():
        frame = decoded[number]
        body = frame.rigid_bodies[0]
        assert msvc_2f(frame.timestamp) == entry["timestamp"]
        software = (frame.transmit_ticks - frame.camera_data_received_ticks) * 1000.0 / CLOCK_HZ
        system = (frame.transmit_ticks - frame.camera_mid_exposure_ticks) * 1000.0 / CLOCK_HZ
        assert msvc_2f(software) == entry["software"]
        assert msvc_2f(system) == entry["system"]
        assert entry["body"] == (body.id, msvc_2f(body.mean_error), int(body.tracking_valid))
        assert entry["pose"] == [msvc_2f(v) for v in body.position + body.orientation]


# ---------------------------------------------------------------------------------------
# Golden bytes: what the fast path keeps re-encodes to the capture's bytes
# ---------------------------------------------------------------------------------------


def test_rigid_body_section_and_suffix_reencode_to_the_capture_bytes(capture):
    payload = capture(V3_FRAME)[4:]
    frame = nn.decode_frame(payload, V3_0)  # fast path: markers skipped
    ours = nn.encode_frame(frame, V3_0)
    # capture: frame(4) marker sets 0 (4) legacy 5 (4 + 60) | rigid bodies at 72 (4 + 38)
    # ours:    frame(4) marker sets 0 (4) legacy 0 (4)      | rigid bodies at 12
    assert ours[12:12 + 42] == payload[72:72 + 42]
    # suffix: timecode .. params (42 bytes) and the end-of-data tag
    assert ours[-46:] == payload[-46:]
    assert ours[:4] == payload[:4]


def test_whole_v3_packets_reencode_exactly(capture):
    for name in (V3_FRAME, "mocapframe_packet_occluded_v3.bin",
                 "mocapframe_last_frame163251_v3.bin"):
        packet = capture(name)
        assert nn.serialize(nn.deserialize(packet, V3_0, full=True), V3_0) == packet


# ---------------------------------------------------------------------------------------
# NatNet 2.x (Motive 1.x) captures
# ---------------------------------------------------------------------------------------

V2_CASES = [
    (nn.V2_5, "1.5.0", (92881, 92882), "Rigid Body 1", 1, (-0.26316, 0.03913, 1.12352), 2),
    (nn.V2_7, "1.7.2", (411213, 411214), "Rigid Body 1", 1, (0.00602, 0.09581, -1.40760), 2),
    (nn.V2_9, "1.9.0", (11823217, 11823218), "Triangle", 2, (0.24534, 0.01696, 0.22016), 0),
]


@pytest.mark.parametrize("version, motive, numbers, set_name, body_id, position, legacy",
                         V2_CASES)
def test_natnet_2x_captures(capture, version, motive, numbers, set_name, body_id, position,
                            legacy):
    folder = "natnet2x_motive1.x_natnet-decode"
    info = nn.deserialize(capture(f"{folder}/frame-motive-{motive}-000.bin"), version)
    assert info == nn.ServerInfo("NatNetLib", version, version, None)
    for i, number in enumerate(numbers, start=1):
        frame = nn.deserialize(capture(f"{folder}/frame-motive-{motive}-00{i}.bin"), version,
                               full=True)
        assert frame.frame_number == number
        assert {s.name for s in frame.marker_sets} == {set_name, "all"}
        assert len(frame.legacy_markers) == legacy and len(frame.labeled_markers) == 3
        (body,) = frame.rigid_bodies
        assert body.id == body_id and body.tracking_valid
        assert body.position == approx(position, abs=5e-5)
        assert math.isclose(sum(q * q for q in body.orientation), 1.0, abs_tol=1e-5)
        if version >= nn.V2_7:
            assert frame.timestamp > 0
        with pytest.raises(NatNetError):
            nn.encode_frame(frame, version)  # 2.x is decoded only


def test_natnet_2_5_marker_set_positions_match_optirx(capture):
    frame = nn.deserialize(capture("natnet2x_motive1.x_natnet-decode/frame-motive-1.5.0-001.bin"),
                           nn.V2_5, full=True)
    markers = {s.name: s.markers for s in frame.marker_sets}["Rigid Body 1"]
    assert markers[0] == approx((-0.3015673756599426, 0.08478303998708725, 1.1143304109573364),
                                abs=1e-7)


# ---------------------------------------------------------------------------------------
# Round trips of every section for 3.0, 3.1, 4.0, 4.1
# ---------------------------------------------------------------------------------------


def rich_frame(version: Version) -> Frame:
    """Every section filled, with float32-exact values so equality is exact."""
    body = RigidBody(3, (0.5, -1.25, 2.0), (0.0, 0.5, 0.0, 0.75), 0.015625, True)
    lost = RigidBody(4, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 0.0, False)
    marker = nn.LabeledMarker(3 << 16 | 2, (0.25, 0.5, 0.75), 0.0234375, 0x0A, 0.00048828125)
    is41 = version >= V4_1
    return Frame(
        frame_number=123456, rigid_bodies=(body, lost), timestamp=1028.8,
        timecode=0x01020304, timecode_subframe=7, camera_mid_exposure_ticks=10 ** 12,
        camera_data_received_ticks=10 ** 12 + 50, transmit_ticks=10 ** 12 + 90,
        precision_timestamp_s=1_700_000_000 if is41 else 0,
        precision_timestamp_fraction=123456789 if is41 else 0, params=0x02,
        marker_sets=(nn.MarkerSet("car3", ((0.25, 0.5, 0.75), (1.0, 2.0, 3.0))),
                     nn.MarkerSet("all", ())),
        legacy_markers=((9.0, 8.0, 7.0),),
        skeletons=(nn.Skeleton(1, (RigidBody(65537, (1.0, 1.0, 1.0), (0.0, 0.0, 0.0, 1.0),
                                             0.5, True),)),),
        assets=((nn.Asset(9, (body,), (marker,)),) if is41 else ()),
        labeled_markers=(marker, nn.LabeledMarker(50007, (0.0, 0.0, 0.0), 0.5, 0x10, 0.0)),
        force_plates=(nn.AnalogDevice(1, ((1.0, 2.0, 3.0), ())),),
        devices=(nn.AnalogDevice(5, ((0.5,),)),))


@pytest.mark.parametrize("version", nn.FRAME_VERSIONS)
def test_every_section_round_trips(version):
    frame = rich_frame(version)
    packet = nn.serialize(frame, version)
    assert nn.deserialize(packet, version, full=True) == frame
    fast = nn.deserialize(packet, version)
    assert fast.rigid_bodies == frame.rigid_bodies
    assert fast == Frame(**{f: getattr(frame, f) for f in (
        "frame_number", "rigid_bodies", "timestamp", "timecode", "timecode_subframe",
        "camera_mid_exposure_ticks", "camera_data_received_ticks", "transmit_ticks",
        "precision_timestamp_s", "precision_timestamp_fraction", "params")})
    assert nn.serialize(nn.deserialize(packet, version, full=True), version) == packet


def test_3_0_3_1_and_4_0_frames_share_one_layout_and_4_1_adds_sizes_and_assets():
    frame = rich_frame(V3_0)
    assert nn.encode_frame(frame, V3_0) == nn.encode_frame(frame, V3_1) == \
        nn.encode_frame(frame, V4_0)
    simple = Frame(7, (RigidBody(1, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0)),
                       RigidBody(2, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0))), 1.0)
    p30, p41 = nn.encode_frame(simple, V3_0), nn.encode_frame(simple, V4_1)
    assert len(p30) == 4 + 4 + 4 + (4 + 76) + 4 + 4 + 4 + 4 + 42 + 4
    # 4.1: every count is followed by its section's byte size, assets come after skeletons,
    # and the suffix carries the two precision timestamp fields.
    assert len(p41) == 4 + 8 + 8 + (8 + 76) + 8 + 8 + 8 + 8 + 8 + 50 + 4
    assert struct.unpack_from("<ii", p41, 20) == (2, 76)


@pytest.mark.parametrize("encoded, decoded", [(V4_1, V4_0), (V4_0, V4_1), (V3_0, V4_1)])
def test_a_frame_decoded_with_the_wrong_version_is_rejected(encoded, decoded):
    payload = nn.encode_frame(rich_frame(encoded), encoded)
    with pytest.raises(NatNetError):
        nn.decode_frame(payload, decoded, full=True)


def test_frame_without_the_end_of_data_tag_is_accepted():
    payload = nn.encode_frame(rich_frame(V4_1), V4_1)
    assert nn.decode_frame(payload[:-4], V4_1, full=True) == rich_frame(V4_1)


# ---------------------------------------------------------------------------------------
# Errors
# ---------------------------------------------------------------------------------------


def _reason(packet: bytes, version: Version = V3_0, **kw) -> str:
    with pytest.raises(NatNetError) as info:
        nn.deserialize(packet, version, **kw)
    assert str(info.value)
    return info.value.reason


def test_header_errors():
    assert _reason(b"\x07") == "truncated"
    assert _reason(b"\x07\x00\x10\x00" + bytes(8)) == "size_mismatch"
    assert _reason(nn.pack_header(55, b"")) == "unknown_message"
    assert issubclass(NatNetError, ValueError)


def test_huge_and_negative_counts_are_rejected_before_allocating():
    simple = nn.encode_frame(Frame(1, (RigidBody(1, (0, 0, 0), (0, 0, 0, 1)),), 0.0), V3_0)
    for count in (0x7FFFFFFF, 3, -1):
        bad = simple[:12] + struct.pack("<i", count) + simple[16:]
        assert _reason(nn.pack_header(7, bad)) == "bad_count"
    bad_sets = struct.pack("<ii", 1, 0x7FFFFFFF) + simple[8:]
    assert _reason(nn.pack_header(7, bad_sets)) == "bad_count"


def test_section_size_that_disagrees_is_rejected():
    payload = bytearray(nn.encode_frame(rich_frame(V4_1), V4_1))
    (n_sets, size) = struct.unpack_from("<ii", payload, 4)
    struct.pack_into("<i", payload, 8, size + 1)
    assert _reason(nn.pack_header(7, bytes(payload)), V4_1) in ("section_size", "bad_count",
                                                                "truncated")
    payload = bytearray(nn.encode_frame(rich_frame(V4_1), V4_1))
    off = 8 + 4 + size  # legacy marker count
    struct.pack_into("<i", payload, off + 4, 11)  # one legacy marker is 12 bytes
    assert _reason(nn.pack_header(7, bytes(payload)), V4_1) == "section_size"


def test_non_finite_values_where_they_matter():
    good = RigidBody(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    for bad in (RigidBody(1, (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
                RigidBody(1, (0.0, 0.0, 0.0), (0.0, math.inf, 0.0, 1.0)),
                RigidBody(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), -math.inf)):
        assert _reason(nn.serialize(Frame(1, (good, bad), 0.0), V3_0)) == "non_finite"
    assert _reason(nn.serialize(Frame(1, (good,), math.nan), V3_0)) == "non_finite"
    # an untracked body's pose does not matter: accepted as sent
    lost = RigidBody(2, (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 0.0, False)
    frame = nn.deserialize(nn.serialize(Frame(1, (good, lost), 0.0), V3_0), V3_0)
    assert not frame.rigid_bodies[1].tracking_valid


def test_trailing_bytes_and_unsupported_versions():
    packet = nn.serialize(Frame(1, (), 0.0), V3_0)
    assert _reason(nn.pack_header(7, packet[4:] + b"\0\0")) == "trailing_bytes"
    for version in (Version(4, 2), Version(1, 0), Version(5, 0)):
        assert _reason(packet, version) == "unsupported_version"
        assert not nn.supports_frames(version)
        with pytest.raises(NatNetError):
            nn.encode_frame(Frame(1), version)
    assert all(nn.supports_frames(v) for v in nn.FRAME_VERSIONS + (nn.V2_5, nn.V2_9))


def test_fixed_size_messages_reject_wrong_sizes():
    assert _reason(nn.pack_header(MessageId.ECHO_REQUEST, bytes(7))) == "truncated"
    assert _reason(nn.pack_header(MessageId.ECHO_RESPONSE, bytes(17))) == "trailing_bytes"
    assert _reason(nn.pack_header(MessageId.SERVERINFO, bytes(270))) == "truncated"
    with pytest.raises(NatNetError):
        nn.Response(b"\0\0").as_float()


def test_encoder_errors_are_natnet_errors():
    with pytest.raises(NatNetError):
        nn.encode_frame(Frame(1, (RigidBody(2 ** 40, (0, 0, 0), (0, 0, 0, 1)),)), V3_0)
    with pytest.raises(NatNetError):
        nn.encode_frame(Frame(1, marker_sets=(nn.MarkerSet("a\0b"),)), V3_0)
    with pytest.raises(NatNetError):
        nn.encode_frame(rich_frame(V4_1), V4_0)  # assets need 4.1
    with pytest.raises(NatNetError):
        nn.pack_header(7, bytes(70000))


# ---------------------------------------------------------------------------------------
# CONNECT variants, SERVERINFO, simple messages
# ---------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------
# MODELDEF
# ---------------------------------------------------------------------------------------


def model(names: bool) -> nn.ModelDef:
    markers = tuple(nn.RigidBodyMarker((0.125 * i, -0.25, 0.5), i, f"M{i}" if names else "")
                    for i in range(3))
    return nn.ModelDef((nn.MarkerSetDescription("car1", ("M0", "M1", "M2")),
                        nn.RigidBodyDescription("car1", 1, -1, (0.0, 0.5, 0.0), markers),
                        nn.RigidBodyDescription("car2", 2),
                        nn.MarkerSetDescription("all")))


@pytest.mark.parametrize("version, names", [(V3_0, False), (V3_1, False), (V4_0, True),
                                            (V4_1, True)])
def test_model_def_round_trips(version, names):
    m = model(names)
    assert nn.deserialize(nn.serialize(m, version), version) == m


def test_model_def_4_1_sizes_and_other_kinds_are_walked():
    # NatNet 4.1: kind, byte size, description; unknown kinds are skipped by their size
    camera = b"cam1\0" + struct.pack("<3f4f", 1, 2, 3, 0, 0, 0, 1)
    skeleton = (b"skel\0" + struct.pack("<ii", 4, 1) + b"bone\0"
                + struct.pack("<ii3fi", 65537, -1, 0, 0, 0, 0))
    asset = (b"asset\0" + struct.pack("<iii", 1, 6, 1) + b"rb\0"
             + struct.pack("<ii3fi", 7, -1, 0, 0, 0, 0) + struct.pack("<i", 1) + b"m1\0"
             + struct.pack("<i3ffh", 3, 0, 0, 0, 0.02, 0))
    device = struct.pack("<i", 3) + b"dev\0" + b"SN1\0" + struct.pack("<iii", 1, 2, 1) + b"ch0\0"
    plate = (struct.pack("<i", 2) + b"FP\0" + struct.pack("<2f3f", 1, 1, 0, 0, 0)
             + bytes(144 * 4 + 12 * 4) + struct.pack("<iii", 1, 1, 2) + b"Fx\0Fy\0")
    parts = [(5, camera), (2, skeleton), (6, asset), (4, device), (3, plate), (99, b"future")]
    payload = struct.pack("<i", len(parts)) + b"".join(struct.pack("<ii", k, len(b)) + b
                                                       for k, b in parts)
    decoded = nn.decode_model_def(payload, V4_1)
    assert [(d.kind, d.name) for d in decoded.descriptions] == [
        (5, "cam1"), (2, "skel"), (6, "asset"), (4, "dev"), (3, "FP"), (99, "")]
    # the same without the sizes (4.0), minus the unknown kind
    payload40 = struct.pack("<i", 5) + b"".join(struct.pack("<i", k) + b for k, b in parts[:5])
    assert len(nn.decode_model_def(payload40, V4_0).descriptions) == 5
    with pytest.raises(NatNetError):
        nn.decode_model_def(struct.pack("<i", 1) + struct.pack("<i", 99) + b"future", V4_0)
    bad_size = bytearray(payload)
    struct.pack_into("<i", bad_size, 8, len(camera) + 1)
    with pytest.raises(NatNetError):
        nn.decode_model_def(bytes(bad_size), V4_1)


# ---------------------------------------------------------------------------------------
# Ground plane
# ---------------------------------------------------------------------------------------


def about(axis: str, angle: float) -> tuple[float, float, float, float]:
    s, c = math.sin(angle / 2), math.cos(angle / 2)
    return {"x": (s, 0.0, 0.0, c), "y": (0.0, s, 0.0, c), "z": (0.0, 0.0, s, c)}[axis]


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


@pytest.mark.parametrize("angle", [0.0, 0.3, math.pi / 2, 2.5, -1.0, -math.pi / 2])
def test_yaw_of_known_rotations(angle):
    # Y-up: +angle about Motive's +y (up) is counter-clockwise seen from above
    x, y, yaw = nn.to_ground_plane((1.0, 0.2, 3.0), about("y", angle), "y")
    assert (x, y) == (1.0, -3.0)
    assert yaw == pytest.approx(angle, abs=1e-12)
    x, y, yaw = nn.to_ground_plane((1.0, 2.0, 0.2), about("z", angle), "z")
    assert (x, y) == (1.0, 2.0) and yaw == pytest.approx(angle, abs=1e-12)
    # scale does not matter, and neither does a roll about the body's own x axis
    q = tuple(2.0 * v for v in quat_mul(about("y", angle), about("x", 0.4)))
    assert nn.to_ground_plane((0, 0, 0), q, "y")[2] == pytest.approx(angle, abs=1e-12)


def test_yaw_sign_matches_the_ground_frame_by_construction():
    # Y-up: a body whose x axis points along Motive -z points along ground +y: yaw +90 deg.
    # That is a rotation of +90 deg about +y: x -> (cos, 0, -sin) = -z.
    assert nn.to_ground_plane((0, 0, 0), about("y", math.pi / 2))[2] == \
        pytest.approx(math.pi / 2)
    # Motive +x stays ground +x, Motive -z becomes ground +y (right-handed, z up)
    assert nn.to_ground_plane((0.0, 5.0, -2.0), (0, 0, 0, 1))[:2] == (0.0, 2.0)
    with pytest.raises(ValueError):
        nn.to_ground_plane((0, 0, 0), (0, 0, 0, 1), "x")


def test_yaw_of_the_captured_quad(capture):
    body = nn.deserialize(capture(V3_FRAME), V3_0).rigid_bodies[0]
    x, y, yaw = nn.to_ground_plane(body.position, body.orientation, "y")
    assert (x, y) == pytest.approx((0.1744466, 0.7343040), abs=1e-6)
    # q is nearly a rotation about +y (qy = 0.51, qw = -0.857): angle = 2 atan2(qy, qw)
    qx, qy, qz, qw = body.orientation
    expected = math.atan2(math.sin(2 * math.atan2(qy, qw)), math.cos(2 * math.atan2(qy, qw)))
    assert yaw == pytest.approx(expected, abs=0.15)


@pytest.mark.parametrize("up", ["y", "z"])
def test_ground_plane_mapping_round_trips(up):
    import math
    for x, y, yaw in [(0.4, -2.15, 1.57), (-1.0, 0.3, -3.0), (2.0, 2.0, 0.0), (0.0, 0.0, 3.1)]:
        position, orientation = nn.from_ground_plane(x, y, yaw, 0.05, up)
        gx, gy, gyaw = nn.to_ground_plane(position, orientation, up)
        assert (gx, gy) == pytest.approx((x, y))
        assert math.isclose(math.remainder(gyaw - yaw, 2 * math.pi), 0.0, abs_tol=1e-9)

"""FRAMEOFDATA against real Motive captures (3.0 and 2.x), the SDK sample client's log,
golden bytes, round trips of every section in 3.0-4.1, and rejected frames."""

from __future__ import annotations

import math
import re
import struct
from decimal import ROUND_HALF_UP, Decimal

import pytest

from tests.bridge.conftest import V3_FRAME, approx, reason_of
from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0, V3_1, V4_0, V4_1, Frame, NatNetError, RigidBody, Version

CLOCK_HZ = 3312787  # from the SERVERINFO of the same session


# ---------------------------------------------------------------------------------------
# Captures: the values the captures README lists
# ---------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------
# The whole recorded session
# ---------------------------------------------------------------------------------------


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


def test_huge_and_negative_counts_are_rejected_before_allocating():
    simple = nn.encode_frame(Frame(1, (RigidBody(1, (0, 0, 0), (0, 0, 0, 1)),), 0.0), V3_0)
    for count in (0x7FFFFFFF, 3, -1):
        bad = simple[:12] + struct.pack("<i", count) + simple[16:]
        assert reason_of(nn.pack_header(7, bad)) == "bad_count"
    bad_sets = struct.pack("<ii", 1, 0x7FFFFFFF) + simple[8:]
    assert reason_of(nn.pack_header(7, bad_sets)) == "bad_count"


def test_section_size_that_disagrees_is_rejected():
    payload = bytearray(nn.encode_frame(rich_frame(V4_1), V4_1))
    (n_sets, size) = struct.unpack_from("<ii", payload, 4)
    struct.pack_into("<i", payload, 8, size + 1)
    assert reason_of(nn.pack_header(7, bytes(payload)), V4_1) in ("section_size", "bad_count",
                                                                "truncated")
    payload = bytearray(nn.encode_frame(rich_frame(V4_1), V4_1))
    off = 8 + 4 + size  # legacy marker count
    struct.pack_into("<i", payload, off + 4, 11)  # one legacy marker is 12 bytes
    assert reason_of(nn.pack_header(7, bytes(payload)), V4_1) == "section_size"


def test_non_finite_values_where_they_matter():
    good = RigidBody(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))
    for bad in (RigidBody(1, (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
                RigidBody(1, (0.0, 0.0, 0.0), (0.0, math.inf, 0.0, 1.0)),
                RigidBody(1, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), -math.inf)):
        assert reason_of(nn.serialize(Frame(1, (good, bad), 0.0), V3_0)) == "non_finite"
    assert reason_of(nn.serialize(Frame(1, (good,), math.nan), V3_0)) == "non_finite"
    # an untracked body's pose does not matter: accepted as sent
    lost = RigidBody(2, (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), 0.0, False)
    frame = nn.deserialize(nn.serialize(Frame(1, (good, lost), 0.0), V3_0), V3_0)
    assert not frame.rigid_bodies[1].tracking_valid


def test_trailing_bytes_and_unsupported_versions():
    packet = nn.serialize(Frame(1, (), 0.0), V3_0)
    assert reason_of(nn.pack_header(7, packet[4:] + b"\0\0")) == "trailing_bytes"
    for version in (Version(4, 5), Version(1, 0), Version(5, 0)):
        assert reason_of(packet, version) == "unsupported_version"
        assert not nn.supports_frames(version)
        with pytest.raises(NatNetError):
            nn.encode_frame(Frame(1), version)
    assert all(nn.supports_frames(v) for v in nn.FRAME_VERSIONS + (nn.V2_5, nn.V2_9, Version(4, 3), Version(4, 4)))
    with pytest.raises(NatNetError):  # decoded with the 4.2 layout, never encoded
        nn.encode_frame(Frame(1), Version(4, 4))


def test_encoder_errors_are_natnet_errors():
    with pytest.raises(NatNetError):
        nn.encode_frame(Frame(1, (RigidBody(2 ** 40, (0, 0, 0), (0, 0, 0, 1)),)), V3_0)
    with pytest.raises(NatNetError):
        nn.encode_frame(Frame(1, marker_sets=(nn.MarkerSet("a\0b"),)), V3_0)
    with pytest.raises(NatNetError):
        nn.encode_frame(rich_frame(V4_1), V4_0)  # assets need 4.1
    with pytest.raises(NatNetError):
        nn.pack_header(7, bytes(70000))

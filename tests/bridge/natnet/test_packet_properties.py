"""Property tests of the NatNet codec: round trips, and hostile bytes never escape as
anything but NatNetError, never hang and never allocate beyond what the bytes can hold."""

from __future__ import annotations

import struct
import tracemalloc
from datetime import timedelta

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V4_1, Frame, NatNetError, RigidBody

DECODABLE = nn.FRAME_VERSIONS + (nn.V2_5, nn.V2_7, nn.V2_9)
SETTINGS = settings(max_examples=150, deadline=timedelta(seconds=2),
                    suppress_health_check=[HealthCheck.too_slow])

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
f64 = st.floats(allow_nan=False, allow_infinity=False)
i32 = st.integers(-2 ** 31, 2 ** 31 - 1)
u16 = st.integers(0, 2 ** 16 - 1)
u32 = st.integers(0, 2 ** 32 - 1)
u64 = st.integers(0, 2 ** 64 - 1)
vec3 = st.tuples(f32, f32, f32)
quat = st.tuples(f32, f32, f32, f32)
name = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\0"),
               max_size=12)
small = {"max_size": 3}

rigid_bodies = st.builds(RigidBody, i32, vec3, quat, f32, st.booleans())
labeled = st.builds(nn.LabeledMarker, i32, vec3, f32, u16, f32)
analog = st.builds(nn.AnalogDevice, i32, st.lists(st.lists(f32, **small).map(tuple),
                                                  **small).map(tuple))


@st.composite
def frames(draw, version):
    is41 = version >= V4_1
    tup = lambda s: st.lists(s, **small).map(tuple)  # noqa: E731
    return Frame(
        frame_number=draw(i32), rigid_bodies=draw(tup(rigid_bodies)), timestamp=draw(f64),
        timecode=draw(u32), timecode_subframe=draw(u32), camera_mid_exposure_ticks=draw(u64),
        camera_data_received_ticks=draw(u64), transmit_ticks=draw(u64),
        precision_timestamp_s=draw(u32) if is41 else 0,
        precision_timestamp_fraction=draw(u32) if is41 else 0, params=draw(u16),
        marker_sets=draw(tup(st.builds(nn.MarkerSet, name, tup(vec3)))),
        legacy_markers=draw(tup(vec3)),
        skeletons=draw(tup(st.builds(nn.Skeleton, i32, tup(rigid_bodies)))),
        assets=draw(tup(st.builds(nn.Asset, i32, tup(rigid_bodies), tup(labeled))))
        if is41 else (),
        labeled_markers=draw(tup(labeled)), force_plates=draw(tup(analog)),
        devices=draw(tup(analog)))


any_frame = st.sampled_from(nn.FRAME_VERSIONS).flatmap(
    lambda v: st.tuples(st.just(v), frames(v)))


@SETTINGS
@given(any_frame)
def test_encode_decode_round_trip(version_frame):
    version, frame = version_frame
    payload = nn.encode_frame(frame, version)
    assert nn.decode_frame(payload, version, full=True) == frame
    fast = nn.decode_frame(payload, version)
    assert fast.rigid_bodies == frame.rigid_bodies and fast.params == frame.params
    assert nn.encode_frame(nn.decode_frame(payload, version, full=True), version) == payload


descriptions = st.one_of(
    st.builds(nn.MarkerSetDescription, name, st.lists(name, **small).map(tuple)),
    st.builds(nn.RigidBodyDescription, name, i32, i32, vec3,
              st.lists(st.builds(nn.RigidBodyMarker, vec3, i32, name), **small).map(tuple)))


@SETTINGS
@given(st.sampled_from(nn.FRAME_VERSIONS), st.lists(descriptions, max_size=4))
def test_model_def_round_trip(version, items):
    if version.major < 4:  # marker names are on the wire from 4.0
        items = [nn.RigidBodyDescription(d.name, d.id, d.parent_id, d.offset,
                                         tuple(nn.RigidBodyMarker(m.offset, m.active_label)
                                               for m in d.markers))
                 if isinstance(d, nn.RigidBodyDescription) else d for d in items]
    model = nn.ModelDef(tuple(items))
    assert nn.decode_model_def(nn.encode_model_def(model, version), version) == model


versions = st.builds(nn.Version, *[st.integers(0, 255)] * 4).filter(lambda v: not v.is_zero)


@SETTINGS
@given(st.builds(nn.ConnectRequest, name, st.none() | versions, st.none() | versions,
                 st.booleans(), st.none() | versions), st.booleans())
def test_connect_round_trip(request_, discovery):
    if discovery:
        request_ = nn.DiscoveryRequest(**request_.__dict__)
    assert nn.deserialize(nn.serialize(request_), nn.V3_0) == request_


def decode_all_ways(packet: bytes) -> None:
    """Every decoder, every version: a result or NatNetError, nothing else."""
    for version in DECODABLE:
        for full in (False, True):
            try:
                nn.deserialize(packet, version, full=full)
            except NatNetError as exc:
                assert exc.reason and str(exc)
            try:
                nn.decode_frame(packet, version, full=full)
            except NatNetError:
                pass
        try:
            nn.decode_model_def(packet, version)
        except NatNetError:
            pass
    for decoder in (nn.decode_server_info, nn.decode_connect):
        try:
            decoder(packet)
        except NatNetError:
            pass


@SETTINGS
@given(st.binary(max_size=600))
def test_random_bytes_only_raise_natnet_error(data):
    decode_all_ways(data)


@SETTINGS
@given(st.sampled_from([int(m) for m in nn.MessageId] + [11, 99, 0xFFFF]), st.binary(max_size=600))
def test_random_payloads_behind_a_valid_header(message_id, payload):
    decode_all_ways(nn.pack_header(message_id, payload))


def _seeds(capture) -> list[tuple[nn.Version, bytes]]:
    seeds = [(nn.V3_0, capture(n)) for n in ("mocapframe_packet_v3.bin",
                                             "mocapframe_packet_occluded_v3.bin")]
    rich = Frame(5, (RigidBody(1, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0)),),
                 1.0, marker_sets=(nn.MarkerSet("a", ((1.0, 1.0, 1.0),)),),
                 legacy_markers=((2.0, 2.0, 2.0),),
                 skeletons=(nn.Skeleton(1, (RigidBody(2, (0, 0, 0), (0, 0, 0, 1.0)),)),),
                 labeled_markers=(nn.LabeledMarker(1, (0.0, 0.0, 0.0), 0.5),),
                 force_plates=(nn.AnalogDevice(1, ((1.0, 2.0),)),),
                 devices=(nn.AnalogDevice(2, ((3.0,),)),))
    for version in nn.FRAME_VERSIONS:
        frame = rich if version < V4_1 else Frame(
            **{**{f: getattr(rich, f) for f in rich.__dataclass_fields__},
               "assets": (nn.Asset(3, rich.rigid_bodies, rich.labeled_markers),)})
        seeds.append((version, nn.serialize(frame, version)))
    return seeds


def test_every_truncation_is_rejected(capture):
    for version, packet in _seeds(capture):
        payload = packet[4:]
        for cut in range(len(payload)):
            if cut == len(payload) - 4:  # only the optional end-of-data tag is missing
                nn.decode_frame(payload[:cut], version, full=True)
                continue
            for full in (False, True):
                with pytest.raises(NatNetError):
                    nn.decode_frame(payload[:cut], version, full=full)
            with pytest.raises(NatNetError) as info:  # the header still claims the old size
                nn.deserialize(packet[:4 + cut], version)
            assert info.value.reason == "size_mismatch"


@pytest.fixture(scope="module")
def seeds(capture):
    return _seeds(capture)


@SETTINGS
@given(st.data())
def test_byte_flips_never_escape_and_stay_bounded(seeds, data):
    version, packet = data.draw(st.sampled_from(seeds))
    payload = bytearray(packet[4:])
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(payload) - 1))
        if data.draw(st.booleans()):  # smash an aligned int32 (counts live there)
            at -= at % 4
            value = data.draw(st.sampled_from([-1, 0, 1, 255, 2 ** 16, 2 ** 31 - 1, -2 ** 31]))
            payload[at:at + 4] = struct.pack("<i", value)[:len(payload) - at]
        else:
            payload[at] = data.draw(st.integers(0, 255))
    mutated = bytes(payload)
    tracemalloc.start()
    try:
        for full in (False, True):
            try:
                nn.decode_frame(mutated, version, full=full)
            except NatNetError:
                pass
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # Decoded objects cost a bounded multiple of the bytes they come from; a count taken on
    # trust (2**31 - 1 rigid bodies...) would cost gigabytes.
    assert peak < 64 * len(mutated) + 256 * 1024

"""MODELDEF: the Motive capture and its golden bytes, round trips in 3.0-4.1, and the
description kinds that are walked rather than kept."""

from __future__ import annotations

import struct

import pytest

from tests.bridge.conftest import approx
from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0, V3_1, V4_0, V4_1, NatNetError


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


def model(names: bool) -> nn.ModelDef:
    markers = tuple(nn.RigidBodyMarker((0.125 * i, -0.25, 0.5), i, f"M{i}" if names else "")
                    for i in range(3))
    return nn.ModelDef((nn.MarkerSetDescription("car1", ("M0", "M1", "M2")),
                        nn.RigidBodyDescription("car1", 1, -1, (0.0, 0.5, 0.0), markers),
                        nn.RigidBodyDescription("car2", 2),
                        nn.MarkerSetDescription("all")))


@pytest.mark.parametrize("version, names", [(V3_0, False), (V3_1, False), (V4_0, True), (nn.V4_2, True),
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

"""Motive poses on the planner's ground plane: yaw of known rotations, the sign
convention, the captured quad, and the inverse mapping."""

from __future__ import annotations

import math

import pytest

from tests.bridge.conftest import V3_FRAME
from trustfg.bridge import natnet as nn
from trustfg.bridge.natnet import V3_0


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

"""Motive poses on the planner's ground plane, and back.

Motive is right-handed and Y-up by default. :func:`to_ground_plane` maps a pose to the
planner's ground plane (x, y, yaw); see there. :func:`from_ground_plane` is its inverse
(mocap-sim places its bodies with it).
"""

from __future__ import annotations

import math
from typing import Literal, Sequence


def to_ground_plane(position: Sequence[float], orientation: Sequence[float],
                    up_axis: Literal["y", "z"] = "y") -> tuple[float, float, float]:
    """Map a Motive pose to the ground plane: (x, y, yaw), metres and radians.

    Motive is right-handed. With ``up_axis="y"`` (Motive's default) the ground frame is
    X = x, Y = -z, Z(up) = y, a proper rotation (+90 deg about x) of Motive's axes, so
    counter-clockwise seen from above stays counter-clockwise. With ``"z"`` the ground
    frame is Motive's own x, y.

    Yaw is the heading of the body's +x axis projected on the ground plane (a rigid body
    created in Motive with the car facing +x has yaw 0), measured counter-clockwise from
    ground X. With q = (qx, qy, qz, qw) of any norm, the body x axis in Motive coordinates
    is ``(w^2 + x^2 - y^2 - z^2, 2(xy + wz), 2(xz - wy))`` (times |q|^2), hence

        Y-up: yaw = atan2(2(wy - xz), w^2 + x^2 - y^2 - z^2)   (ground Y = -z)
        Z-up: yaw = atan2(2(wz + xy), w^2 + x^2 - y^2 - z^2)

    so a rotation by +theta about the up axis gives yaw = +theta in both cases.
    """
    x, y, z = position
    qx, qy, qz, qw = orientation
    heading_x = qw * qw + qx * qx - qy * qy - qz * qz
    if up_axis == "y":
        return float(x), float(-z), math.atan2(2.0 * (qw * qy - qx * qz), heading_x)
    if up_axis == "z":
        return float(x), float(y), math.atan2(2.0 * (qw * qz + qx * qy), heading_x)
    raise ValueError(f"up_axis must be 'y' or 'z', not {up_axis!r}")


def from_ground_plane(x: float, y: float, yaw: float, height: float = 0.0,
                      up_axis: str = "y") -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """The inverse of :func:`to_ground_plane`: a Motive position and quaternion (xyzw)
    for a body at (x, y) on the ground, ``height`` above it, turned ``yaw`` about up."""
    s, c = math.sin(yaw / 2.0), math.cos(yaw / 2.0)
    if up_axis == "y":
        return (float(x), float(height), float(-y)), (0.0, s, 0.0, c)
    if up_axis == "z":
        return (float(x), float(y), float(height)), (0.0, 0.0, s, c)
    raise ValueError(f"up_axis must be 'y' or 'z', not {up_axis!r}")

"""The items inside a FRAMEOFDATA's sections (rigid bodies, marker sets, labeled markers,
skeletons, assets, force plates, devices): their dataclasses, and how one section's items
are read (or checked and skipped) and written. :mod:`.frame` holds the section table.

A rigid body is, for NatNet 3.0 and later, 38 bytes::

    0   int32    id (streaming id)
    4   vec3     position (m)
    16  quat     orientation qx, qy, qz, qw
    32  float32  mean marker error (m)
    36  uint16   params: 0x01 tracking valid (tracked in this frame)

NatNet 2.x inserts after the orientation ``int32 m, m x vec3 marker positions`` and (2.0 and
later) ``m x int32 marker ids, m x float32 marker sizes``; mean error from 2.0, params from 2.6.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Sequence

from .common import (
    _F32,
    _I32,
    _RB,
    _RB_BYTES,
    _U16,
    _VEC3,
    NatNetError,
    Quat,
    Vec3,
    _check_section,
    _count,
    _cstring,
    _I32x2,
    _Layout,
    _section_end,
    _skip_cstring,
)

_LABELED = struct.Struct("<i3ffHf")  # id, x, y, z, size, params, residual: 26 bytes
_ASSET_MARKER = _LABELED


@dataclass(frozen=True, slots=True)
class RigidBody:
    """One rigid body of a frame: Motive coordinates, metres, quaternion xyzw."""

    id: int
    position: Vec3
    orientation: Quat
    mean_error: float = 0.0
    tracking_valid: bool = True


@dataclass(frozen=True, slots=True)
class MarkerSet:
    name: str
    markers: tuple[Vec3, ...] = ()


@dataclass(frozen=True, slots=True)
class LabeledMarker:
    """A labeled marker (or an asset marker). ``id`` packs model id << 16 | marker id."""

    id: int
    position: Vec3
    size: float = 0.0
    params: int = 0
    residual: float = 0.0

    @property
    def model_id(self) -> int:
        return self.id >> 16

    @property
    def marker_id(self) -> int:
        return self.id & 0xFFFF

    @property
    def occluded(self) -> bool:
        return bool(self.params & 0x01)


@dataclass(frozen=True, slots=True)
class Skeleton:
    id: int
    rigid_bodies: tuple[RigidBody, ...] = ()


@dataclass(frozen=True, slots=True)
class Asset:
    id: int
    rigid_bodies: tuple[RigidBody, ...] = ()
    markers: tuple[LabeledMarker, ...] = ()


@dataclass(frozen=True, slots=True)
class AnalogDevice:
    """A force plate or peripheral device: per channel, the samples of this frame."""

    id: int
    channels: tuple[tuple[float, ...], ...] = ()


# ---------------------------------------------------------------------------------------
# Readers: (items, offset after them); with full=False most are checked and skipped
# ---------------------------------------------------------------------------------------


def _finite_or_raise(t: tuple, what: str) -> None:
    # Ints in t are finite; a non-finite float makes the sum inf or nan.
    if sum(t) * 0.0 != 0.0:
        raise NatNetError(f"{what} has a non-finite value: {t}", "non_finite")


def _rigid_bodies_v3(buf: bytes, off: int, n: int) -> tuple[tuple[RigidBody, ...], int]:
    bodies = []
    append = bodies.append
    for t in _RB.iter_unpack(buf[off:off + n * _RB_BYTES]):
        valid = bool(t[9] & 1)
        if valid and sum(t) * 0.0 != 0.0:
            raise NatNetError(f"tracked rigid body {t[0]} has a non-finite pose or error",
                              "non_finite")
        append(RigidBody(t[0], t[1:4], t[4:8], t[8], valid))
    return tuple(bodies), off + n * _RB_BYTES


def _rigid_body_v2(buf: bytes, off: int, end: int, lay: _Layout) -> tuple[RigidBody, int]:
    rb_id, x, y, z, qx, qy, qz, qw = struct.unpack_from("<i7f", buf, off)
    off += 32
    m, off = _count(buf, off, end, 12 + (8 if lay.rb_marker_ids else 0), "rigid body marker")
    off += m * (20 if lay.rb_marker_ids else 12)
    error = 0.0
    if lay.rb_marker_ids:
        (error,) = _F32.unpack_from(buf, off)
        off += 4
    valid = True
    if lay.rb_params:
        valid = bool(_U16.unpack_from(buf, off)[0] & 1)
        off += 2
    if valid:
        _finite_or_raise((x, y, z, qx, qy, qz, qw, error), f"tracked rigid body {rb_id}")
    return RigidBody(rb_id, (x, y, z), (qx, qy, qz, qw), error, valid), off


def _rigid_body_list(buf: bytes, off: int, end: int, n: int,
                     lay: _Layout) -> tuple[tuple[RigidBody, ...], int]:
    if not lay.rb_markers:
        return _rigid_bodies_v3(buf, off, n)
    bodies = []
    for _ in range(n):
        rb, off = _rigid_body_v2(buf, off, end, lay)
        bodies.append(rb)
    return tuple(bodies), off


def _marker_sets(buf: bytes, off: int, end: int, n: int,
                 full: bool) -> tuple[tuple[MarkerSet, ...], int]:
    sets = []
    for _ in range(n):
        if full:
            name, off = _cstring(buf, off, end, "marker set name")
        else:
            off = _skip_cstring(buf, off, end, "marker set name")
        m, off = _count(buf, off, end, 12, "marker set marker")
        if full:
            sets.append(MarkerSet(name, tuple(_VEC3.iter_unpack(buf[off:off + 12 * m]))))
        off += 12 * m
    return tuple(sets), off


def _labeled_markers(buf: bytes, off: int, n: int, lay: _Layout,
                     full: bool) -> tuple[tuple[LabeledMarker, ...], int]:
    size = lay.labeled_bytes
    if not full:
        return (), off + n * size
    markers = []
    for i in range(n):
        o = off + i * size
        mid, x, y, z, msize = struct.unpack_from("<i4f", buf, o)
        params = _U16.unpack_from(buf, o + 20)[0] if lay.labeled_params else 0
        residual = _F32.unpack_from(buf, o + size - 4)[0] if lay.residual else 0.0
        markers.append(LabeledMarker(mid, (x, y, z), msize, params, residual))
    return tuple(markers), off + n * size


def _skeletons(buf: bytes, off: int, end: int, n: int, lay: _Layout,
               full: bool) -> tuple[tuple[Skeleton, ...], int]:
    skeletons = []
    for _ in range(n):
        if off + 8 > end:
            raise NatNetError("truncated skeleton", "truncated")
        (sk_id,) = _I32.unpack_from(buf, off)
        r, off = _count(buf, off + 4, end, lay.rb_min_bytes, "skeleton rigid body")
        bodies, off = _rigid_body_list(buf, off, end, r, lay)
        if full:
            skeletons.append(Skeleton(sk_id, bodies))
    return tuple(skeletons), off


def _assets(buf: bytes, off: int, end: int, n: int,
            full: bool) -> tuple[tuple[Asset, ...], int]:
    assets = []
    for _ in range(n):
        if off + 4 > end:
            raise NatNetError("truncated asset", "truncated")
        (asset_id,) = _I32.unpack_from(buf, off)
        r, off = _count(buf, off + 4, end, _RB_BYTES, "asset rigid body")
        bodies, off = _rigid_bodies_v3(buf, off, r)
        m, off = _count(buf, off, end, _ASSET_MARKER.size, "asset marker")
        markers = tuple(LabeledMarker(t[0], t[1:4], t[4], t[5], t[6])
                        for t in _ASSET_MARKER.iter_unpack(buf[off:off + m * _ASSET_MARKER.size]))
        off += m * _ASSET_MARKER.size
        if full:
            assets.append(Asset(asset_id, bodies, markers))
    return tuple(assets), off


def _analog_section(buf: bytes, off: int, end: int, sizes: bool, full: bool,
                    what: str) -> tuple[tuple[AnalogDevice, ...], int]:
    """A force-plate or device section: its count, then (4.1) its byte size, then the
    devices -- decoded when ``full``, else skipped by their size."""
    n, off = _count(buf, off, end, 8, what)
    if not sizes:
        return _analog(buf, off, end, n, what, full)
    off, stop = _section_end(buf, off, end, n, 8, what)
    if not full:
        return (), stop
    items, off = _analog(buf, off, stop, n, what, True)
    _check_section(off, stop, what)
    return items, off


def _analog(buf: bytes, off: int, end: int, n: int, what: str,
            full: bool) -> tuple[tuple[AnalogDevice, ...], int]:
    devices = []
    for _ in range(n):
        if off + 4 > end:
            raise NatNetError(f"truncated {what}", "truncated")
        (dev_id,) = _I32.unpack_from(buf, off)
        c, off = _count(buf, off + 4, end, 4, f"{what} channel")
        channels = []
        for _ in range(c):
            f, off = _count(buf, off, end, 4, f"{what} sample")
            if full:
                channels.append(struct.unpack_from(f"<{f}f", buf, off))
            off += 4 * f
        if full:
            devices.append(AnalogDevice(dev_id, tuple(channels)))
    return tuple(devices), off


# ---------------------------------------------------------------------------------------
# Writers (NatNet 3.0 and later)
# ---------------------------------------------------------------------------------------


def _encode_rigid_bodies(bodies: Sequence[RigidBody]) -> bytes:
    pack = _RB.pack
    return b"".join(pack(b.id, *b.position, *b.orientation, b.mean_error,
                         1 if b.tracking_valid else 0) for b in bodies)


def _encode_marker(m: LabeledMarker) -> bytes:
    return _LABELED.pack(m.id, *m.position, m.size, m.params, m.residual)


def _encode_analog(devices: Sequence[AnalogDevice]) -> bytes:
    parts = []
    for d in devices:
        parts.append(_I32x2.pack(d.id, len(d.channels)))
        for ch in d.channels:
            parts.append(_I32.pack(len(ch)) + struct.pack(f"<{len(ch)}f", *ch))
    return b"".join(parts)

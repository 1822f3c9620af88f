"""MODELDEF (5): the model descriptions (marker sets, rigid bodies, ...), decoded and
encoded. REQUEST_MODELDEF (4), the empty request for it, is in :mod:`.commands`.

``int32 n``, then n descriptions of ``int32 kind`` [4.1 and later: ``int32 nbytes`` of the
description that follows] and the description:

====================  ======================================================================
kind                  layout
====================  ======================================================================
0 marker set          cstring name, int32 m, m x cstring marker name
1 rigid body          cstring name (2.0+), int32 id, int32 parent id, vec3 offset,
                      [4.2+: quat rotation (qx, qy, qz, qw): the pivot's orientation];
                      3.0+: int32 m, m x vec3 marker offsets, m x int32 active labels,
                      4.0+: m x cstring marker names
2 skeleton            cstring name, int32 id, int32 r, r x rigid body description
3 force plate (3.0+)  int32 id, cstring serial, float32 width, float32 length, vec3 origin,
                      12 x 12 float32 calibration matrix, 4 x vec3 corners, int32 plate
                      type, int32 channel data type, int32 c, c x cstring channel name
4 device (3.0+)       int32 id, cstring name, cstring serial, int32 device type,
                      int32 channel data type, int32 c, c x cstring channel name
5 camera              cstring name, vec3 position, quat orientation
6 asset               cstring name, int32 type, int32 id, int32 r, r x rigid body
                      description, int32 m, m x (cstring name, int32 id, vec3, float32
                      size, int16 params)
====================  ======================================================================

Marker sets and rigid bodies are decoded; the other kinds are walked by their layout (or
by their 4.1 byte size) and kept as :class:`OtherDescription` (kind and name).

The 4.2 rotation is the one change of the rigid-body description since 4.0; the SDK's
NatNetClient.py (``__unpack_rigid_body_descript_4_2_to_current``) and PacketClient.cpp
read it there, and a parser that does not reads the following marker count from the
quaternion's bytes. A NatNet version whose frame layout is unknown (see ``_layout`` in
:mod:`.common`) is rejected here too; MODELDEF is encoded in NatNet 3.0 to 4.2.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Union

from .common import (
    _I32,
    _QUAT,
    _VEC3,
    NatNetError,
    Quat,
    Vec3,
    Version,
    _as_bytes,
    _count,
    _cstring,
    _encode_layout,
    _I32x2,
    _layout,
    _name_bytes,
    _skip_cstring,
)


@dataclass(frozen=True)
class MarkerSetDescription:
    name: str
    marker_names: tuple[str, ...] = ()


@dataclass(frozen=True)
class RigidBodyMarker:
    """A marker of a rigid body description; ``name`` is on the wire from NatNet 4.0."""

    offset: Vec3
    active_label: int = 0
    name: str = ""


@dataclass(frozen=True)
class RigidBodyDescription:
    """A rigid body as Motive describes it; ``rotation`` is on the wire from NatNet 4.2."""

    name: str
    id: int
    parent_id: int = -1
    offset: Vec3 = (0.0, 0.0, 0.0)
    markers: tuple[RigidBodyMarker, ...] = ()
    rotation: Quat = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class OtherDescription:
    """A description we walk but do not keep: skeleton, force plate, device, camera, asset."""

    kind: int
    name: str = ""


Description = Union[MarkerSetDescription, RigidBodyDescription, OtherDescription]


@dataclass(frozen=True)
class ModelDef:
    """MODELDEF: descriptions in wire order."""

    descriptions: tuple[Description, ...] = ()

    @property
    def rigid_bodies(self) -> tuple[RigidBodyDescription, ...]:
        return tuple(d for d in self.descriptions if isinstance(d, RigidBodyDescription))

    @property
    def marker_sets(self) -> tuple[MarkerSetDescription, ...]:
        return tuple(d for d in self.descriptions if isinstance(d, MarkerSetDescription))


def _rb_description(buf: bytes, off: int, end: int,
                    version: Version) -> tuple[RigidBodyDescription, int]:
    name = ""
    if version.major >= 2:
        name, off = _cstring(buf, off, end, "rigid body name")
    if off + 20 > end:
        raise NatNetError("truncated rigid body description", "truncated")
    rb_id, parent, ox, oy, oz = struct.unpack_from("<ii3f", buf, off)
    off += 20
    rotation: Quat = (0.0, 0.0, 0.0, 1.0)
    if _layout(version.major, version.minor).rb_description_rotation:
        if off + 16 > end:
            raise NatNetError("truncated rigid body description rotation", "truncated")
        rotation = _QUAT.unpack_from(buf, off)
        off += 16
    markers: tuple[RigidBodyMarker, ...] = ()
    if version.major >= 3:
        m, off = _count(buf, off, end, 16 + (1 if version.major >= 4 else 0),
                        "rigid body marker")
        offsets = list(_VEC3.iter_unpack(buf[off:off + 12 * m]))
        labels = struct.unpack_from(f"<{m}i", buf, off + 12 * m)
        off += 16 * m
        names = [""] * m
        if version.major >= 4:
            for i in range(m):
                names[i], off = _cstring(buf, off, end, "rigid body marker name")
        markers = tuple(RigidBodyMarker(o, lab, nm) for o, lab, nm in zip(offsets, labels, names))
    return RigidBodyDescription(name, rb_id, parent, (ox, oy, oz), markers, rotation), off


def _marker_set_description(buf: bytes, off: int, end: int) -> tuple[MarkerSetDescription, int]:
    name, off = _cstring(buf, off, end, "marker set name")
    m, off = _count(buf, off, end, 1, "marker set marker name")
    names = []
    for _ in range(m):
        nm, off = _cstring(buf, off, end, "marker name")
        names.append(nm)
    return MarkerSetDescription(name, tuple(names)), off


def _skip_names(buf: bytes, off: int, end: int, what: str) -> int:
    c, off = _count(buf, off, end, 1, what)
    for _ in range(c):
        off = _skip_cstring(buf, off, end, what)
    return off


def _other_description(kind: int, buf: bytes, off: int, end: int,
                       version: Version) -> tuple[OtherDescription, int]:
    """Walk a skeleton/force plate/device/camera/asset description by its layout."""
    name = ""
    if kind == 2:  # skeleton
        name, off = _cstring(buf, off, end, "skeleton name")
        r, off = _count(buf, off + 4, end, 20, "skeleton bone")
        for _ in range(r):
            _, off = _rb_description(buf, off, end, version)
    elif kind == 3 and version.major >= 3:  # force plate
        off += 4
        name, off = _cstring(buf, off, end, "force plate serial")
        off += 8 + 12 + 12 * 12 * 4 + 4 * 12 + 8
        off = _skip_names(buf, off, end, "force plate channel name")
    elif kind == 4 and version.major >= 3:  # device
        off += 4
        name, off = _cstring(buf, off, end, "device name")
        off = _skip_cstring(buf, off, end, "device serial") + 8
        off = _skip_names(buf, off, end, "device channel name")
    elif kind == 5:  # camera
        name, off = _cstring(buf, off, end, "camera name")
        off += 28
    elif kind == 6:  # asset
        name, off = _cstring(buf, off, end, "asset name")
        r, off = _count(buf, off + 8, end, 20, "asset rigid body")
        for _ in range(r):
            _, off = _rb_description(buf, off, end, version)
        m, off = _count(buf, off, end, 23, "asset marker")
        for _ in range(m):  # cstring name, int32 id, vec3, float32 size, int16 params
            off = _skip_cstring(buf, off, end, "asset marker name") + 22
    elif kind not in (3, 4):
        raise NatNetError(f"unknown model description kind {kind}", "malformed")
    if off > end:
        raise NatNetError(f"truncated model description of kind {kind}", "truncated")
    return OtherDescription(kind, name), off


def decode_model_def(payload: bytes | memoryview, version: Version) -> ModelDef:
    """MODELDEF payload of NatNet ``version`` (2.x, 3.0, 3.1, 4.0 to 4.4)."""
    _layout(version.major, version.minor)  # rejects versions whose layout we do not know
    buf = _as_bytes(payload)
    end = len(buf)
    sized = (version.major, version.minor) >= (4, 1)
    try:
        n, off = _count(buf, 0, end, 8 if sized else 4, "model description")
        descriptions: list[Description] = []
        for _ in range(n):
            (kind,) = _I32.unpack_from(buf, off)
            off += 4
            stop = end
            if sized:
                (nbytes,) = _I32.unpack_from(buf, off)
                off += 4
                if not 0 <= nbytes <= end - off:
                    raise NatNetError(f"model description claims {nbytes} bytes but "
                                      f"{end - off} remain", "section_size")
                stop = off + nbytes
            start = off
            if kind == 0:
                d, off = _marker_set_description(buf, off, stop)
            elif kind == 1:
                d, off = _rb_description(buf, off, stop, version)
            elif sized and kind not in range(7):
                d, off = OtherDescription(kind), stop  # unknown kind: skip by its size
            else:
                d, off = _other_description(kind, buf, off, stop, version)
            if off > stop or sized and off != stop:
                raise NatNetError(f"model description of kind {kind} takes {off - start} "
                                  f"bytes, its size says {stop - start}", "section_size")
            descriptions.append(d)
    except struct.error as exc:
        raise NatNetError(f"truncated MODELDEF ({end} bytes): {exc}", "truncated") from None
    if off != end:
        raise NatNetError(f"{end - off} unexpected bytes after MODELDEF", "trailing_bytes")
    return ModelDef(tuple(descriptions))


def _encode_description(d: Description, version: Version) -> tuple[int, bytes]:
    if isinstance(d, MarkerSetDescription):
        return 0, (_name_bytes(d.name, "marker set name") + _I32.pack(len(d.marker_names))
                   + b"".join(_name_bytes(m, "marker name") for m in d.marker_names))
    if isinstance(d, RigidBodyDescription):
        out = _name_bytes(d.name, "rigid body name") + struct.pack(
            "<ii3f", d.id, d.parent_id, *d.offset)
        if _layout(version.major, version.minor).rb_description_rotation:
            out += _QUAT.pack(*d.rotation)
        out += _I32.pack(len(d.markers))
        out += b"".join(_VEC3.pack(*m.offset) for m in d.markers)
        out += b"".join(_I32.pack(m.active_label) for m in d.markers)
        if version.major >= 4:
            out += b"".join(_name_bytes(m.name, "marker name") for m in d.markers)
        return 1, out
    raise NatNetError(f"cannot encode {type(d).__name__} (kind {getattr(d, 'kind', '?')})",
                      "encode")


def encode_model_def(model: ModelDef, version: Version) -> bytes:
    """MODELDEF payload (marker sets and rigid bodies) in NatNet 3.0, 3.1, 4.0, 4.1 or 4.2."""
    lay = _encode_layout(version)
    parts = [_I32.pack(len(model.descriptions))]
    try:
        for d in model.descriptions:
            kind, body = _encode_description(d, version)
            parts.append(_I32x2.pack(kind, len(body)) if lay.sizes else _I32.pack(kind))
            parts.append(body)
    except struct.error as exc:
        raise NatNetError(f"cannot encode MODELDEF: {exc}", "encode") from None
    return b"".join(parts)

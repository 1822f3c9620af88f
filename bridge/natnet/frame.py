"""FRAMEOFDATA (7): one frame of the stream, decoded and encoded.

Frames of NatNet 3.0, 3.1, 4.0, 4.1 and 4.2 are decoded and encoded (4.2 frames are laid
out as 4.1's: its change is in MODELDEF; 4.3 and 4.4 decode the same); frames of the legacy 2.x
layouts (2.0 to 2.11, tested on 2.5/2.7/2.9 captures) are decoded only. Which optional
fields each version carries is ``_layout`` in :mod:`.common`; the items of each section
(and the rigid body's bytes) are in :mod:`.sections`.

Sections in order; ``vec3`` is 3 float32 (m), ``quat`` 4 float32 (qx, qy, qz, qw). In
NatNet 4.1 and later every section count is followed by ``int32 nbytes``, the byte size
of the section's items (not counting the count and size fields); the decoder validates it
and skips by it. Counts are int32 and must fit in the bytes that remain.

====================  ======================================================================
section               layout
====================  ======================================================================
prefix                int32 frame number
marker sets           int32 n [, int32 nbytes]; n x (cstring name, int32 m, m x vec3)
legacy markers        int32 n [, int32 nbytes]; n x vec3   ("other"/unlabeled markers)
rigid bodies          int32 n [, int32 nbytes]; n x rigid body (see .sections)
skeletons (>=2.1)     int32 n [, int32 nbytes]; n x (int32 id, int32 m, m x rigid body)
assets (>=4.1)        int32 n, int32 nbytes; n x (int32 id, int32 r, r x rigid body(3.0),
                      int32 m, m x (int32 id, vec3, float32 size, int16 params,
                      float32 residual))
labeled (>=2.3)       int32 n [, int32 nbytes]; n x (int32 id = model << 16 | marker,
                      vec3, float32 size, [>=2.6 int16 params], [>=3.0 float32 residual])
force plates (>=2.9)  int32 n [, int32 nbytes]; n x (int32 id, int32 c,
                      c x (int32 f, f x float32))
devices (>=2.11)      same layout as force plates
suffix                [<3.0 float32 latency], uint32 timecode, uint32 timecode subframe,
                      [2.6 float32 | >=2.7 float64 timestamp (s)],
                      [>=3.0 uint64 camera mid-exposure, uint64 camera data received,
                      uint64 transmit (high-resolution clock ticks)],
                      [>=4.1 uint32 precision timestamp s, uint32 precision fraction],
                      [>=2.6 uint16 frame params: 0x01 recording, 0x02 tracked models
                      changed], int32 end-of-data tag (0; Motive sends it, the SDK samples
                      do not read it, so it may be absent)
====================  ======================================================================

A decoded frame must end exactly after the params (or after the end-of-data tag): other
trailing bytes mean the packet is not of the NatNet version it was decoded as.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from .common import (
    _F32,
    _I32,
    _RB_BYTES,
    _U16,
    _VEC3,
    NatNetError,
    Vec3,
    Version,
    _as_bytes,
    _check_section,
    _count,
    _encode_layout,
    _I32x2,
    _Layout,
    _layout,
    _name_bytes,
    _section_end,
)
from .sections import (
    AnalogDevice,
    Asset,
    LabeledMarker,
    MarkerSet,
    RigidBody,
    Skeleton,
    _analog_section,
    _assets,
    _encode_analog,
    _encode_marker,
    _encode_rigid_bodies,
    _labeled_markers,
    _marker_sets,
    _rigid_bodies_v3,
    _rigid_body_list,
    _skeletons,
)

_F64 = struct.Struct("<d")
_SUFFIX_30 = struct.Struct("<IIdQQQH")  # timecode .. params (3.0 - 4.0): 42 bytes
_SUFFIX_41 = struct.Struct("<IIdQQQIIH")  # + precision timestamp (4.1): 50 bytes


@dataclass(frozen=True, slots=True)
class Frame:
    """A FRAMEOFDATA message.

    ``timestamp`` is Motive's software time in seconds (0.0 for NatNet < 2.6, which has
    none). The ``*_ticks`` stamps are in the server's high-resolution clock (frequency in
    SERVERINFO), 0 before NatNet 3.0; the precision timestamp (PTP) is NatNet 4.1 only.
    The marker, skeleton, asset and analog sections are filled only when decoded with
    ``full=True``; by default they are validated, skipped and left empty.
    """

    frame_number: int
    rigid_bodies: tuple[RigidBody, ...] = ()
    timestamp: float = 0.0
    timecode: int = 0
    timecode_subframe: int = 0
    camera_mid_exposure_ticks: int = 0
    camera_data_received_ticks: int = 0
    transmit_ticks: int = 0
    precision_timestamp_s: int = 0
    precision_timestamp_fraction: int = 0
    params: int = 0
    marker_sets: tuple[MarkerSet, ...] = ()
    legacy_markers: tuple[Vec3, ...] = ()
    skeletons: tuple[Skeleton, ...] = ()
    assets: tuple[Asset, ...] = ()
    labeled_markers: tuple[LabeledMarker, ...] = ()
    force_plates: tuple[AnalogDevice, ...] = ()
    devices: tuple[AnalogDevice, ...] = ()

    @property
    def is_recording(self) -> bool:
        return bool(self.params & 0x01)

    @property
    def tracked_models_changed(self) -> bool:
        return bool(self.params & 0x02)


def decode_frame(payload: bytes | bytearray | memoryview, version: Version, *,
                 full: bool = False) -> Frame:
    """Decode a FRAMEOFDATA payload (the bytes after the header) of NatNet ``version``.

    With ``full=False`` (the fast path used by the client) only rigid bodies and the
    frame suffix are kept; every other section is still checked against the bytes
    available and skipped by its real size.
    """
    lay = _layout(version.major, version.minor)
    buf = _as_bytes(payload)
    end = len(buf)
    try:
        return _decode_frame(buf, end, lay, full)
    except struct.error as exc:  # a fixed-size read ran off the end
        raise NatNetError(f"truncated FRAMEOFDATA ({end} bytes): {exc}", "truncated") from None


def _decode_frame(buf: bytes, end: int, lay: _Layout, full: bool) -> Frame:
    """The sections in the order the module docstring lists them, each read by its own step."""
    if end < 4:
        raise NatNetError(f"truncated FRAMEOFDATA: {end} bytes", "truncated")
    (frame_number,) = _I32.unpack_from(buf, 0)
    marker_sets, off = _marker_set_section(buf, 4, end, lay, full)
    legacy, off = _legacy_marker_section(buf, off, end, lay, full)
    bodies, off = _rigid_body_section(buf, off, end, lay)
    skeletons: tuple[Skeleton, ...] = ()
    if lay.skeletons:
        skeletons, off = _skeleton_section(buf, off, end, lay, full)
    assets: tuple[Asset, ...] = ()
    if lay.assets:
        assets, off = _asset_section(buf, off, end, full)
    labeled: tuple[LabeledMarker, ...] = ()
    if lay.labeled:
        labeled, off = _labeled_marker_section(buf, off, end, lay, full)
    plates: tuple[AnalogDevice, ...] = ()
    if lay.force_plates:
        plates, off = _analog_section(buf, off, end, lay.sizes, full, "force plate")
    devices: tuple[AnalogDevice, ...] = ()
    if lay.devices:
        devices, off = _analog_section(buf, off, end, lay.sizes, full, "device")
    (timecode, subframe, timestamp, mid, received, transmit, prec_s, prec_frac, params), off = \
        _suffix(buf, off, lay)
    if timestamp * 0.0 != 0.0:
        raise NatNetError(f"frame {frame_number} has a non-finite timestamp", "non_finite")
    rest = end - off
    if rest != 0 and rest != 4:  # 4: Motive's end-of-data tag
        raise NatNetError(f"{rest} unexpected bytes after the frame suffix (is this really "
                          "the stream's NatNet version?)", "trailing_bytes")
    return Frame(frame_number, bodies, timestamp, timecode, subframe, mid, received, transmit,
                 prec_s, prec_frac, params, marker_sets, legacy, skeletons, assets, labeled,
                 plates, devices)


# Each section step takes the offset of the section's count and returns what it kept (empty
# unless ``full``) and the offset after the section. With ``lay.sizes`` (NatNet >= 4.1) the
# section's byte size is checked against what its items take, and a skipped section is
# skipped by that size.


def _marker_set_section(buf: bytes, off: int, end: int, lay: _Layout,
                        full: bool) -> tuple[tuple[MarkerSet, ...], int]:
    n, off = _count(buf, off, end, 5, "marker set")
    if not lay.sizes:
        return _marker_sets(buf, off, end, n, full)
    off, stop = _section_end(buf, off, end, n, 5, "marker set")
    if not full:
        return (), stop
    marker_sets, off = _marker_sets(buf, off, stop, n, True)
    _check_section(off, stop, "marker set")
    return marker_sets, off


def _legacy_marker_section(buf: bytes, off: int, end: int, lay: _Layout,
                           full: bool) -> tuple[tuple[Vec3, ...], int]:
    """The "other" (unlabeled) markers: ``n`` vec3 of 12 bytes."""
    n, off = _count(buf, off, end, 12, "legacy marker")
    if lay.sizes:
        off, stop = _section_end(buf, off, end, n, 12, "legacy marker")
        _check_section(off + 12 * n, stop, "legacy marker")
    legacy = tuple(_VEC3.iter_unpack(buf[off:off + 12 * n])) if full and n else ()
    return legacy, off + 12 * n


def _rigid_body_section(buf: bytes, off: int, end: int,
                        lay: _Layout) -> tuple[tuple[RigidBody, ...], int]:
    """The rigid bodies, always decoded (the client's one use of a frame)."""
    n, off = _count(buf, off, end, lay.rb_min_bytes, "rigid body")
    if not lay.sizes:
        return _rigid_body_list(buf, off, end, n, lay)
    off, stop = _section_end(buf, off, end, n, _RB_BYTES, "rigid body")
    bodies, off = _rigid_bodies_v3(buf, off, n)
    _check_section(off, stop, "rigid body")
    return bodies, off


def _skeleton_section(buf: bytes, off: int, end: int, lay: _Layout,
                      full: bool) -> tuple[tuple[Skeleton, ...], int]:
    n, off = _count(buf, off, end, 8, "skeleton")
    if not lay.sizes:
        return _skeletons(buf, off, end, n, lay, full)
    off, stop = _section_end(buf, off, end, n, 8, "skeleton")
    if not full:
        return (), stop
    skeletons, off = _skeletons(buf, off, stop, n, lay, True)
    _check_section(off, stop, "skeleton")
    return skeletons, off


def _asset_section(buf: bytes, off: int, end: int, full: bool) -> tuple[tuple[Asset, ...], int]:
    """Assets exist from NatNet 4.1 only, so their section always carries its byte size."""
    n, off = _count(buf, off, end, 12, "asset")
    off, stop = _section_end(buf, off, end, n, 12, "asset")
    if not full:
        return (), stop
    assets, off = _assets(buf, off, stop, n, True)
    _check_section(off, stop, "asset")
    return assets, off


def _labeled_marker_section(buf: bytes, off: int, end: int, lay: _Layout,
                            full: bool) -> tuple[tuple[LabeledMarker, ...], int]:
    """Labeled markers: ``n`` items of ``lay.labeled_bytes`` each (the size depends on the version)."""
    size = lay.labeled_bytes
    n, off = _count(buf, off, end, size, "labeled marker")
    if lay.sizes:
        off, stop = _section_end(buf, off, end, n, size, "labeled marker")
        _check_section(off + n * size, stop, "labeled marker")
    return _labeled_markers(buf, off, n, lay, full)


def _suffix(buf: bytes, off: int, lay: _Layout) -> tuple[tuple, int]:
    """The fields after the sections, as the Frame orders them: (timecode, subframe,
    timestamp, mid-exposure, data received, transmit, precision s, precision fraction,
    params), each 0 where the version has none; and the offset after them. A short
    buffer raises ``struct.error`` (decode_frame reports it as truncated)."""
    mid = received = transmit = prec_s = prec_frac = params = 0
    if lay.hires:
        if lay.precision:
            (timecode, subframe, timestamp, mid, received, transmit, prec_s, prec_frac,
             params) = _SUFFIX_41.unpack_from(buf, off)
            off += _SUFFIX_41.size
        else:
            timecode, subframe, timestamp, mid, received, transmit, params = \
                _SUFFIX_30.unpack_from(buf, off)
            off += _SUFFIX_30.size
    else:
        timestamp, params, off = 0.0, 0, off + (4 if lay.latency else 0)  # latency dropped
        timecode, subframe = struct.unpack_from("<II", buf, off)
        off += 8
        if lay.timestamp == "d":
            (timestamp,) = _F64.unpack_from(buf, off)
            off += 8
        elif lay.timestamp == "f":
            (timestamp,) = _F32.unpack_from(buf, off)
            off += 4
        if lay.frame_params:
            (params,) = _U16.unpack_from(buf, off)
            off += 2
    return (timecode, subframe, timestamp, mid, received, transmit, prec_s, prec_frac, params), off


def encode_frame(frame: Frame, version: Version) -> bytes:
    """The FRAMEOFDATA payload of ``frame`` in NatNet ``version`` (3.0, 3.1, 4.0, 4.1, 4.2)."""
    lay = _encode_layout(version)
    try:
        sections = [
            (len(frame.marker_sets), b"".join(
                _name_bytes(s.name, "marker set name") + _I32.pack(len(s.markers))
                + b"".join(_VEC3.pack(*p) for p in s.markers) for s in frame.marker_sets)),
            (len(frame.legacy_markers), b"".join(_VEC3.pack(*p) for p in frame.legacy_markers)),
            (len(frame.rigid_bodies), _encode_rigid_bodies(frame.rigid_bodies)),
            (len(frame.skeletons), b"".join(
                _I32x2.pack(s.id, len(s.rigid_bodies)) + _encode_rigid_bodies(s.rigid_bodies)
                for s in frame.skeletons)),
        ]
        if lay.assets:
            sections.append((len(frame.assets), b"".join(
                _I32x2.pack(a.id, len(a.rigid_bodies)) + _encode_rigid_bodies(a.rigid_bodies)
                + _I32.pack(len(a.markers)) + b"".join(_encode_marker(m) for m in a.markers)
                for a in frame.assets)))
        elif frame.assets:
            raise NatNetError(f"assets need NatNet 4.1, not {version}", "encode")
        sections += [
            (len(frame.labeled_markers), b"".join(_encode_marker(m)
                                                  for m in frame.labeled_markers)),
            (len(frame.force_plates), _encode_analog(frame.force_plates)),
            (len(frame.devices), _encode_analog(frame.devices)),
        ]
        parts = [_I32.pack(frame.frame_number)]
        for n, body in sections:
            parts.append(_I32x2.pack(n, len(body)) if lay.sizes else _I32.pack(n))
            parts.append(body)
        if lay.precision:
            parts.append(_SUFFIX_41.pack(
                frame.timecode, frame.timecode_subframe, frame.timestamp,
                frame.camera_mid_exposure_ticks, frame.camera_data_received_ticks,
                frame.transmit_ticks, frame.precision_timestamp_s,
                frame.precision_timestamp_fraction, frame.params))
        else:
            parts.append(_SUFFIX_30.pack(
                frame.timecode, frame.timecode_subframe, frame.timestamp,
                frame.camera_mid_exposure_ticks, frame.camera_data_received_ticks,
                frame.transmit_ticks, frame.params))
        parts.append(_I32.pack(0))  # end-of-data tag, as Motive sends it
    except struct.error as exc:
        raise NatNetError(f"cannot encode frame {frame.frame_number}: {exc}", "encode") from None
    return b"".join(parts)

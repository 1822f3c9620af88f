"""Car-link codec: the bytes of one velocity command, and nothing else (pure, no I/O).

Two versions. Version 2 is authenticated (a MAC with a per-car key) and is what a car
process speaks whenever its car has a key; version 1 (a CRC, no authentication: anyone on
the network can drive the car) remains for old firmware, only where a car's config asks for
it (``link_version = 1``). A receiver speaks one version, never both: a car with a key
refuses version-1 datagrams, so an attacker cannot downgrade it.

Datagram (version 1)
--------------------
Exactly 30 bytes, little-endian, no padding, IEEE 754 floats::

    offset size type  field
    0      2    bytes magic        b"TF" (0x54 0x46)
    2      1    u8    version      1
    3      1    u8    car_id       1..255 (0 is invalid)
    4      4    u32   seq          sequence number, +1 per datagram, wraps 0xFFFFFFFF -> 0
    8      8    f64   stamp_s      sender's fleet clock, seconds (finite)
    16     4    f32   v_mps        linear velocity, m/s (finite)
    20     4    f32   omega_radps  angular velocity, rad/s, counter-clockwise positive (finite)
    24     2    u16   flags        bit 0 E_STOP, bit 1 STOP, bit 2 RELEASE, bit 3 PING,
                                   bits 4..15 must be 0
    26     4    u32   crc32        CRC-32 over bytes 0..25

Flags (what a car does with each is in :mod:`.receiver`):

* ``E_STOP`` (0x0001): stop now and stay stopped (latched) until a datagram with RELEASE
  from the same sender (version 2: the same ``source``) arrives. Taken whatever its
  sequence number or session: the operator sends it straight to the car, next to the car
  process's own stream.
* ``STOP`` (0x0002): hold still while this is the latest command (not latched); v and
  omega are ignored. Sent while a car waits, on shutdown and when its pose is lost.
* ``RELEASE`` (0x0004): clears the E_STOP its sender latched (in sequence: the car process
  after the operator released the car; version 2, the operator's own tools for the e-stops
  they sent straight to the car). Never together with E_STOP.
* ``PING`` (0x0008): answer this datagram (:mod:`.answer`) and otherwise ignore it, except
  that an E_STOP in it still latches. The operator's tools use it to see that a car link
  answers (``trustfg check``) and that an e-stop latched (``trustfg stop``).

CRC: CRC-32/ISO-HDLC, the one of zlib, Ethernet and PNG -- width 32, polynomial
0x04C11DB7 (0xEDB88320 bit-reflected), init 0xFFFFFFFF, input and output reflected,
xorout 0xFFFFFFFF; check value CRC("123456789") = 0xCBF43926. In Python
``zlib.crc32(datagram[:26])``; bitwise in C::

    uint32_t crc = 0xFFFFFFFF;
    for (i = 0; i < 26; i++) {
        crc ^= d[i];
        for (k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xEDB88320 & -(crc & 1));
    }
    crc ^= 0xFFFFFFFF;      /* compare with the u32 at offset 26 (little-endian) */

Worked example: car 3, seq 0x01020304, stamp 12.5 s, v 0.25 m/s, omega -0.5 rad/s, no
flags (CRC 0xC0E042BB)::

    54 46 01 03 04 03 02 01 00 00 00 00 00 00 29 40
    00 00 80 3e 00 00 00 bf 00 00 bb 42 e0 c0

A receiver rejects, in this order: wrong length, bad magic, unknown version, bad CRC,
car id 0, reserved flag bits set or E_STOP with RELEASE, non-finite stamp/v/omega (NaN or
infinity). Encoding rounds v and omega to the nearest f32 (a value beyond the f32 range
is an error).

Datagram (version 2, authenticated)
-----------------------------------
Exactly 52 bytes, little-endian, no padding, IEEE 754 floats::

    offset size type  field
    0      2    bytes magic        b"TF" (0x54 0x46)
    2      1    u8    version      2
    3      1    u8    car_id       1..255 (0 is invalid)
    4      1    u8    source       which sender: 0 the car process, 1 the operator, ...
    5      1    u8    reserved     0
    6      2    u16   flags        as in version 1 (E_STOP, STOP, RELEASE, PING)
    8      8    u64   session      the sender's session: its wall clock when it started,
                                   microseconds since the Unix epoch (a restarted sender
                                   has a larger one)
    16     4    u32   seq          0, 1, 2, ... within the session (never wraps: a sender
                                   starts a new session first)
    20     8    f64   stamp_s      sender's fleet clock, seconds (finite)
    28     4    f32   v_mps        linear velocity, m/s (finite)
    32     4    f32   omega_radps  angular velocity, rad/s, counter-clockwise positive (finite)
    36     16   bytes mac          HMAC-SHA256(key, bytes 0..35), its first 16 bytes

MAC: HMAC (RFC 2104) with SHA-256 (FIPS 180-4) keyed with the car's 32-byte key, over
bytes 0..35; the tag is the first 16 bytes of the 32-byte HMAC (truncation as RFC 2104
section 5 allows; 128 bits). Compare in constant time. Any HMAC-SHA256 of a firmware's
crypto library will do (mbedTLS ``mbedtls_md_hmac``, ...); Python
``hmac.new(key, d[:36], "sha256").digest()[:16]``.

Worked example: key 00 01 02 .. 1f (the bytes 0 to 31; an example, never a real key),
car 3, source 0, session 1700000000000000 (0x00060A24181E4000), seq 7, stamp 12.5 s,
v 0.25 m/s, omega -0.5 rad/s, no flags::

    54 46 02 03 00 00 00 00 00 40 1e 18 24 0a 06 00
    07 00 00 00 00 00 00 00 00 00 29 40 00 00 80 3e
    00 00 00 bf f9 d7 2d 99 0d 00 8f 4d af fb 26 95
    e1 4c 98 dd

(the MAC is the last 16 bytes). A receiver rejects, in this order: wrong length, bad
magic, other version, bad MAC, reserved byte not 0, car id 0, reserved flag bits or E_STOP
with RELEASE, non-finite numbers. Which sessions and sequence numbers it accepts (replays,
restarts) is in :mod:`.receiver`.

What a car does with the commands it decodes is in :mod:`.receiver`. The constants, the
layouts, the flags and the framing (CRC, MAC) are code in :mod:`.frame`, quick to import;
this module adds the validated :class:`Command` and the decoders.
"""

from __future__ import annotations

import math
import operator
import struct
from dataclasses import dataclass

from .frame import (
    COMMAND_BODY,
    COMMAND_BODY_V2,
    MAGIC,
    SEQ_MODULUS,
    SESSION_MODULUS,
    SOURCE_CAR_PROCESS,
    VERSION,
    VERSION_2,
    CarLinkError,
    Flags,
    check_key,
    command_datagram,
    open_frame,
)

_HALF_SEQ = 2**31
_F32 = struct.Struct("<f")
_KNOWN_FLAGS = int(Flags.E_STOP | Flags.STOP | Flags.RELEASE | Flags.PING)


@dataclass(frozen=True)
class Command:
    """One velocity command, validated on construction (raises :class:`CarLinkError`).

    ``session`` and ``source`` travel in version 2 only (version 1 decodes them as 0)."""

    car_id: int
    seq: int
    stamp_s: float
    v_mps: float
    omega_radps: float
    flags: Flags = Flags.NONE
    session: int = 0
    source: int = SOURCE_CAR_PROCESS

    def __post_init__(self) -> None:
        _check_int("car_id", self.car_id, 1, 255)
        _check_int("seq", self.seq, 0, SEQ_MODULUS - 1)
        _check_int("session", self.session, 0, SESSION_MODULUS - 1)
        _check_int("source", self.source, 0, 255)
        _check_int("flags", self.flags, 0, 0xFFFF)
        if int(self.flags) & ~_KNOWN_FLAGS:
            raise CarLinkError("flags", f"reserved flag bits set: 0x{int(self.flags):04x}")
        if int(self.flags) & Flags.E_STOP and int(self.flags) & Flags.RELEASE:
            raise CarLinkError("flags", "E_STOP and RELEASE together")
        object.__setattr__(self, "flags", Flags(int(self.flags)))
        _check_float("stamp_s", self.stamp_s)
        _check_float("v_mps", self.v_mps, f32=True)
        _check_float("omega_radps", self.omega_radps, f32=True)

    @property
    def e_stop(self) -> bool:
        return bool(self.flags & Flags.E_STOP)

    @property
    def stop(self) -> bool:
        return bool(self.flags & Flags.STOP)

    @property
    def release(self) -> bool:
        return bool(self.flags & Flags.RELEASE)

    @property
    def ping(self) -> bool:
        return bool(self.flags & Flags.PING)


def _check_int(name: str, value: object, low: int, high: int) -> None:
    try:
        number = operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise CarLinkError("type", f"{name} must be an integer, got {value!r}") from None
    if not low <= number <= high:
        reason = "car_id" if name == "car_id" else "range"
        raise CarLinkError(reason, f"{name} = {number} is outside {low}..{high}")


def _check_float(name: str, value: object, f32: bool = False) -> None:
    try:
        finite = math.isfinite(value)  # type: ignore[arg-type]
    except TypeError:
        raise CarLinkError("type", f"{name} must be a number, got {value!r}") from None
    if not finite:
        raise CarLinkError("non_finite", f"{name} = {value!r}")
    if f32:
        try:
            _F32.pack(value)
        except (OverflowError, struct.error):
            raise CarLinkError("range", f"{name} = {value!r} does not fit an f32") from None


def encode_command(cmd: Command) -> bytes:
    """The 30-byte datagram of ``cmd`` (v and omega rounded to f32)."""
    return command_datagram(None, cmd.car_id, cmd.seq, cmd.stamp_s, cmd.v_mps, cmd.omega_radps, cmd.flags)


def decode_command(data: bytes | bytearray | memoryview) -> Command:
    """The command in a datagram; raises :class:`CarLinkError` (and nothing else) if invalid."""
    _, _, car_id, seq, stamp_s, v_mps, omega_radps, flags = open_frame(data, COMMAND_BODY, MAGIC, VERSION)
    return Command(car_id, seq, stamp_s, v_mps, omega_radps, flags)


def encode_command_v2(cmd: Command, key: bytes) -> bytes:
    """The 52-byte authenticated datagram of ``cmd`` (v and omega rounded to f32)."""
    return command_datagram(check_key(key), cmd.car_id, cmd.seq, cmd.stamp_s, cmd.v_mps, cmd.omega_radps,
                            cmd.flags, cmd.session, cmd.source)


def decode_command_v2(data: bytes | bytearray | memoryview, key: bytes) -> Command:
    """The command in an authenticated datagram; raises :class:`CarLinkError` (and nothing
    else) if it is invalid or its MAC does not verify with ``key``."""
    (_, _, car_id, source, reserved, flags, session, seq, stamp_s, v_mps,
     omega_radps) = open_frame(data, COMMAND_BODY_V2, MAGIC, VERSION_2, key)
    if reserved != 0:
        raise CarLinkError("reserved", f"reserved byte is 0x{reserved:02x}, must be 0")
    return Command(car_id, seq, stamp_s, v_mps, omega_radps, flags, session, source)


def seq_after(seq: int, last: int) -> bool:
    """True if 32-bit sequence number ``seq`` comes after ``last`` (RFC 1982).

    The distance 2**31 is undefined in RFC 1982; it counts as "not after" here.
    """
    distance = (seq - last) % SEQ_MODULUS
    return 0 < distance < _HALF_SEQ

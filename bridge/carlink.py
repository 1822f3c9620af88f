"""Car link: velocity commands from a car process to its car, one UDP datagram each.

Three layers (STYLE.md): a pure codec (:func:`encode_command` / :func:`decode_command`),
the pure receiver logic that a car runs (:class:`CommandFilter`; mocap_sim's simulated
car uses this very class), and thin socket wrappers (:class:`CommandSender`,
:class:`CommandReceiver`).

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
    24     2    u16   flags        bit 0 E_STOP, bit 1 STOP, bits 2..15 must be 0
    26     4    u32   crc32        CRC-32 over bytes 0..25

Flags:

* ``E_STOP`` (0x0001): stop now and stay stopped (latched) until a valid command arrives
  *without* this bit. The sender keeps E_STOP in every datagram while an e-stop is on,
  including the STOP datagrams it sends when it shuts down.
* ``STOP`` (0x0002): hold still while this is the latest command (not latched); v and
  omega are ignored. Sent on shutdown and when the car process loses its pose.

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
car id 0, non-finite stamp/v/omega (NaN or infinity), reserved flag bits set. Encoding
rounds v and omega to the nearest f32 (a value beyond the f32 range is an error).

Receiver rules (what the car firmware does; :class:`CommandFilter`)
---------------------------------------------------------------------
1. Decode; drop invalid datagrams and datagrams for another car id.
2. Sequence numbers compare with serial-number arithmetic (RFC 1982, 32 bits): ``s`` is
   after ``last`` iff ``0 < (s - last) mod 2**32 < 2**31``. Only a datagram after the
   last accepted one is accepted: repeats, replays and datagrams overtaken on the air
   are dropped. The first datagram ever is accepted whatever its seq.
3. Restarted sender: a restarted car process starts a new sequence, which usually looks
   "old". If no datagram has been *accepted* for ``resync_after_s`` (default 1.0 s), the
   next valid datagram is accepted whatever its seq and becomes the new reference.
   This is safe because ``resync_after_s`` is longer than the watchdog, so the car has
   been standing still for a while when a new sequence is adopted, and whatever comes
   next is again watched by the watchdog. Silence is measured from the last accepted
   datagram, so a new sender's stream of "old" numbers cannot postpone the resync
   forever. (The CRC detects corruption, not forgery: the link is not authenticated,
   and after a silence a replayed capture looks like a restarted sender.)
4. Watchdog: the command to apply is (0, 0) once the last accepted command is
   ``watchdog_timeout_s`` (default 0.250 s) old, measured on the receiver's clock (the
   sender's stamp is for logs and latency only; the clocks need not agree).
5. (0, 0) also while E_STOP is latched, or while the latest command has STOP.

Sender (:class:`CommandSender`): sends the latest (v, omega, flags) at a fixed rate
(default 50 Hz) on absolute deadlines ``start + k * period``; a late sender sends one
datagram for the missed slots and carries on with the schedule (no bursts).
"""

from __future__ import annotations

import enum
import logging
import math
import operator
import socket
import struct
import threading
import time
import zlib
from collections import Counter
from dataclasses import dataclass, field
from typing import Callable, Mapping

log = logging.getLogger(__name__)

MAGIC = b"TF"
VERSION = 1
DATAGRAM_SIZE = 30
SEQ_MODULUS = 2**32
_HALF_SEQ = 2**31
_BODY = struct.Struct("<2sBBIdffH")  # bytes 0..25, covered by the CRC
_CRC = struct.Struct("<I")
_F32 = struct.Struct("<f")
# recv buffer larger than a datagram, so an oversized datagram is seen (wrong length)
# rather than silently truncated to 30 bytes.
_RECV_BUFFER_BYTES = 2048

DEFAULT_RATE_HZ = 50.0
DEFAULT_WATCHDOG_TIMEOUT_S = 0.250
DEFAULT_RESYNC_AFTER_S = 1.0

Clock = Callable[[], float]


class CarLinkError(ValueError):
    """A car-link datagram or command field is invalid.

    ``reason`` is a short machine-readable tag (``"length"``, ``"magic"``, ``"version"``,
    ``"crc"``, ``"car_id"``, ``"non_finite"``, ``"flags"``, ``"range"``, ``"type"``) used
    to count rejections; the last two come only from building a :class:`Command`.
    """

    def __init__(self, reason: str, detail: str):
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


class Flags(enum.IntFlag):
    """Command flag bits (u16 at offset 24)."""

    NONE = 0
    E_STOP = 0x0001
    STOP = 0x0002


_KNOWN_FLAGS = int(Flags.E_STOP | Flags.STOP)


# ----------------------------------------------------------------------------- codec


@dataclass(frozen=True)
class Command:
    """One velocity command, validated on construction (raises :class:`CarLinkError`)."""

    car_id: int
    seq: int
    stamp_s: float
    v_mps: float
    omega_radps: float
    flags: Flags = Flags.NONE

    def __post_init__(self) -> None:
        _check_int("car_id", self.car_id, 1, 255)
        _check_int("seq", self.seq, 0, SEQ_MODULUS - 1)
        _check_int("flags", self.flags, 0, 0xFFFF)
        if int(self.flags) & ~_KNOWN_FLAGS:
            raise CarLinkError("flags", f"reserved flag bits set: 0x{int(self.flags):04x}")
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
    body = _BODY.pack(MAGIC, VERSION, cmd.car_id, cmd.seq, cmd.stamp_s, cmd.v_mps,
                      cmd.omega_radps, int(cmd.flags))
    return body + _CRC.pack(zlib.crc32(body))


def decode_command(data: bytes | bytearray | memoryview) -> Command:
    """The command in a datagram; raises :class:`CarLinkError` (and nothing else) if invalid."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise CarLinkError("type", f"expected bytes, got {type(data).__name__}")
    data = bytes(data)
    if len(data) != DATAGRAM_SIZE:
        raise CarLinkError("length", f"{len(data)} bytes, expected {DATAGRAM_SIZE}")
    magic, version, car_id, seq, stamp_s, v_mps, omega_radps, flags = _BODY.unpack_from(data)
    if magic != MAGIC:
        raise CarLinkError("magic", f"magic {magic!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise CarLinkError("version", f"version {version}, this end speaks {VERSION}")
    (crc,) = _CRC.unpack_from(data, _BODY.size)
    expected = zlib.crc32(data[:_BODY.size])
    if crc != expected:
        raise CarLinkError("crc", f"crc 0x{crc:08x}, computed 0x{expected:08x}")
    return Command(car_id, seq, stamp_s, v_mps, omega_radps, flags)


def seq_after(seq: int, last: int) -> bool:
    """True if 32-bit sequence number ``seq`` comes after ``last`` (RFC 1982).

    The distance 2**31 is undefined in RFC 1982; it counts as "not after" here.
    """
    distance = (seq - last) % SEQ_MODULUS
    return 0 < distance < _HALF_SEQ


# ----------------------------------------------------------------------- receiver logic


@dataclass(frozen=True)
class FilterCounters:
    """A snapshot of what a :class:`CommandFilter` accepted and rejected.

    ``resynced`` counts accepted datagrams whose seq was not after the last one and that
    were taken under the restart rule (they are also in ``accepted``).
    ``decode_errors`` maps a :class:`CarLinkError` reason to its count.
    """

    accepted: int = 0
    resynced: int = 0
    wrong_car: int = 0
    stale_seq: int = 0
    repeated_seq: int = 0
    decode_errors: Mapping[str, int] = field(default_factory=dict)

    @property
    def decode_error(self) -> int:
        return sum(self.decode_errors.values())

    @property
    def rejected(self) -> int:
        return self.decode_error + self.wrong_car + self.stale_seq + self.repeated_seq


class CommandFilter:
    """The car's side of the link: which datagrams to accept and what to apply now.

    Pure and single-threaded; times are seconds on the receiver's clock. See the module
    docstring, "Receiver rules", for the rules and why the restart rule is safe.
    """

    def __init__(self, car_id: int, *, watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
                 resync_after_s: float = DEFAULT_RESYNC_AFTER_S):
        _check_int("car_id", car_id, 1, 255)
        if not watchdog_timeout_s > 0.0:
            raise ValueError(f"watchdog_timeout_s must be > 0, got {watchdog_timeout_s}")
        if not resync_after_s > watchdog_timeout_s:
            raise ValueError(f"resync_after_s ({resync_after_s}) must exceed watchdog_timeout_s "
                             f"({watchdog_timeout_s}) so a new sequence is adopted only at a standstill")
        self.car_id = car_id
        self.watchdog_timeout_s = watchdog_timeout_s
        self.resync_after_s = resync_after_s
        self._last: Command | None = None
        self._last_time_s = 0.0
        self._e_stop_latched = False
        self._counts: Counter[str] = Counter()
        self._decode_errors: Counter[str] = Counter()

    @property
    def last_command(self) -> Command | None:
        """The last accepted command, or None before the first."""
        return self._last

    @property
    def e_stop_latched(self) -> bool:
        return self._e_stop_latched

    @property
    def counters(self) -> FilterCounters:
        return FilterCounters(accepted=self._counts["accepted"], resynced=self._counts["resynced"],
                              wrong_car=self._counts["wrong_car"], stale_seq=self._counts["stale_seq"],
                              repeated_seq=self._counts["repeated_seq"],
                              decode_errors=dict(self._decode_errors))

    def accept(self, data: bytes, now_s: float) -> Command | None:
        """Decode and filter one datagram received at ``now_s``; None (counted) if dropped.

        Never raises for any bytes-like input.
        """
        try:
            cmd = decode_command(data)
        except CarLinkError as exc:
            self._decode_errors[exc.reason] += 1
            log.debug("car %d: dropped invalid datagram (%s)", self.car_id, exc)
            return None
        if cmd.car_id != self.car_id:
            self._counts["wrong_car"] += 1
            log.debug("car %d: dropped datagram for car %d", self.car_id, cmd.car_id)
            return None
        if not self._sequence_ok(cmd, now_s):
            return None
        self._take(cmd, now_s)
        return cmd

    def active_command(self, now_s: float) -> tuple[float, float]:
        """The (v_mps, omega_radps) to apply at ``now_s``: (0, 0) when stopped for any reason."""
        cmd = self._last
        if cmd is None or self._e_stop_latched or cmd.stop:
            return 0.0, 0.0
        if now_s - self._last_time_s >= self.watchdog_timeout_s:
            return 0.0, 0.0
        return cmd.v_mps, cmd.omega_radps

    def _sequence_ok(self, cmd: Command, now_s: float) -> bool:
        last = self._last
        if last is None or seq_after(cmd.seq, last.seq):
            return True
        if now_s - self._last_time_s >= self.resync_after_s:
            self._counts["resynced"] += 1
            log.info("car %d: silent for %.3f s, adopting new sequence at seq %d (was %d)",
                     self.car_id, now_s - self._last_time_s, cmd.seq, last.seq)
            return True
        key = "repeated_seq" if cmd.seq == last.seq else "stale_seq"
        self._counts[key] += 1
        log.debug("car %d: dropped seq %d (%s, last %d)", self.car_id, cmd.seq, key, last.seq)
        return False

    def _take(self, cmd: Command, now_s: float) -> None:
        if cmd.e_stop and not self._e_stop_latched:
            log.warning("car %d: E-STOP latched (seq %d)", self.car_id, cmd.seq)
        elif self._e_stop_latched and not cmd.e_stop:
            log.warning("car %d: E-STOP released (seq %d)", self.car_id, cmd.seq)
        self._e_stop_latched = cmd.e_stop
        self._last = cmd
        self._last_time_s = now_s
        self._counts["accepted"] += 1


# --------------------------------------------------------------------------- sending


def next_slot(last_slot: int, start_s: float, period_s: float, now_s: float) -> int:
    """The schedule slot to send next, after ``last_slot`` was sent and it is ``now_s``.

    Slot k is due at ``start_s + k * period_s``. On time, that is ``last_slot + 1``; when
    late, the latest slot already due, so the missed ones in between are skipped and one
    datagram is sent for all of them.
    """
    due = math.floor((now_s - start_s) / period_s)
    return max(last_slot + 1, due)


@dataclass(frozen=True)
class SenderStats:
    """Counts of a :class:`CommandSender`.

    ``sent`` counts every datagram handed to the socket (periodic, direct and STOP);
    ``periodic_sent`` those of the fixed-rate thread, whose rate over its run is
    ``achieved_rate_hz`` (0 before two periodic sends).
    """

    sent: int = 0
    send_errors: int = 0
    periodic_sent: int = 0
    skipped_slots: int = 0
    achieved_rate_hz: float = 0.0


def _resolve(address: tuple[str, int], passive: bool) -> tuple[socket.AddressFamily, tuple]:
    """Resolve once (not per datagram), preferring IPv4 so that "localhost" means the same
    address to a sender and a receiver."""
    flags = socket.AI_PASSIVE if passive else 0
    host = address[0] or None
    try:
        infos = socket.getaddrinfo(host, address[1], socket.AF_INET, socket.SOCK_DGRAM, flags=flags)
    except socket.gaierror:
        infos = socket.getaddrinfo(host, address[1], socket.AF_UNSPEC, socket.SOCK_DGRAM, flags=flags)
    family, _, _, _, sockaddr = infos[0]
    return family, sockaddr


class CommandSender:
    """Sends one car's commands over UDP; owns one socket and (after :meth:`start`) one thread.

    ``set()`` updates what the fixed-rate thread sends (use it while the thread runs: its
    next datagram replaces anything sent directly); ``send()`` sends one datagram now.
    ``stop()`` ends the thread and sends ``stop_repeats`` STOP datagrams, keeping E_STOP
    if the latest ``set()`` or the last datagram sent had it, so shutting down never
    releases a car's e-stop; ``close()`` (also on leaving a ``with`` block) stops and
    closes the socket. Sequence numbers start at ``first_seq`` and wrap.
    ``clock`` drives the schedule (it must follow real time while the thread runs);
    ``stamp_clock`` (default ``clock``) stamps datagrams -- pass the fleet clock.
    """

    def __init__(self, car_id: int, address: tuple[str, int], *, rate_hz: float = DEFAULT_RATE_HZ,
                 clock: Clock = time.monotonic, stamp_clock: Clock | None = None, first_seq: int = 0,
                 stop_repeats: int = 3, stop_spacing_s: float = 0.005, send_timeout_s: float = 0.1,
                 join_timeout_s: float = 1.0):
        _check_int("car_id", car_id, 1, 255)
        _check_int("seq", first_seq, 0, SEQ_MODULUS - 1)
        if not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be > 0, got {rate_hz}")
        self.car_id = car_id
        self.period_s = 1.0 / rate_hz
        self._clock = clock
        self._stamp_clock = stamp_clock or clock
        self._seq = first_seq
        self._stop_repeats = stop_repeats
        self._stop_spacing_s = stop_spacing_s
        self._join_timeout_s = join_timeout_s
        family, self._sockaddr = _resolve(address, passive=False)
        self._sock: socket.socket | None = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.settimeout(send_timeout_s)
        self._send_lock = threading.Lock()  # seq and socket: direct sends vs. the thread
        self._latest_lock = threading.Lock()
        self._latest = (0.0, 0.0, Flags.NONE)
        self._last_sent_flags = Flags.NONE
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None
        self._counts: Counter[str] = Counter()
        self._first_periodic_s: float | None = None
        self._last_periodic_s: float | None = None

    def __enter__(self) -> CommandSender:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def stats(self) -> SenderStats:
        with self._send_lock:
            first, last, periodic = self._first_periodic_s, self._last_periodic_s, self._counts["periodic"]
            rate = (periodic - 1) / (last - first) if periodic >= 2 and last > first else 0.0
            return SenderStats(sent=self._counts["sent"], send_errors=self._counts["errors"],
                               periodic_sent=periodic, skipped_slots=self._counts["skipped"],
                               achieved_rate_hz=rate)

    def set(self, v_mps: float, omega_radps: float, flags: Flags | int = Flags.NONE) -> None:
        """Set what the fixed-rate thread sends from now on (validated here)."""
        _check_fields(v_mps, omega_radps, flags)
        with self._latest_lock:
            self._latest = (v_mps, omega_radps, Flags(int(flags)))

    def send(self, v_mps: float, omega_radps: float, flags: Flags | int = Flags.NONE) -> Command | None:
        """Send one datagram now, stamped and numbered; the command, or None if the socket failed.

        Invalid fields raise :class:`CarLinkError`. A failed send is logged and counted:
        to the car it is a lost datagram.
        """
        return self._send(v_mps, omega_radps, flags, periodic=False)

    def start(self) -> None:
        """Start sending the latest ``set()`` command at the fixed rate."""
        if self._sock is None:
            raise RuntimeError(f"car {self.car_id}: sender is closed")
        if self.running:
            return
        self._halt.clear()
        self._thread = threading.Thread(target=self._run, name=f"carlink-tx-{self.car_id}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop the fixed-rate thread and send STOP datagrams (E_STOP kept if it is on)."""
        self._join()
        if self._sock is None:
            return
        with self._latest_lock, self._send_lock:
            e_stop = (self._latest[2] | self._last_sent_flags) & Flags.E_STOP
        flags = Flags.STOP | e_stop
        for i in range(self._stop_repeats):
            if i:
                time.sleep(self._stop_spacing_s)  # spread out: Wi-Fi loses bursts together
            self._send(0.0, 0.0, flags, periodic=False)

    def close(self) -> None:
        """Stop (sending STOP) and close the socket; safe to call twice."""
        if self._sock is None:
            return
        self.stop()
        with self._send_lock:
            self._sock.close()
            self._sock = None

    def _join(self) -> None:
        thread = self._thread
        if thread is None:
            return
        self._halt.set()
        thread.join(self._join_timeout_s)
        if thread.is_alive():
            log.error("car %d: sender thread did not stop within %.1f s", self.car_id, self._join_timeout_s)
        self._thread = None

    def _send(self, v_mps: float, omega_radps: float, flags: Flags | int, periodic: bool) -> Command | None:
        with self._send_lock:
            if self._sock is None:
                raise RuntimeError(f"car {self.car_id}: sender is closed")
            cmd = Command(self.car_id, self._seq, self._stamp_clock(), v_mps, omega_radps, flags)
            self._seq = (self._seq + 1) % SEQ_MODULUS
            try:
                self._sock.sendto(encode_command(cmd), self._sockaddr)
            except OSError as exc:
                self._counts["errors"] += 1
                log.warning("car %d: send of seq %d failed: %s", self.car_id, cmd.seq, exc)
                return None
            self._counts["sent"] += 1
            self._last_sent_flags = cmd.flags
            if periodic:
                self._note_periodic()
            return cmd

    def _note_periodic(self) -> None:
        now = self._clock()
        self._counts["periodic"] += 1
        if self._first_periodic_s is None:
            self._first_periodic_s = now
        self._last_periodic_s = now

    def _run(self) -> None:
        try:
            self._send_on_schedule()
        except Exception:  # the loop's edge: log it; the car's watchdog stops the car
            log.exception("car %d: sender thread failed; the car will stop by its watchdog", self.car_id)

    def _send_on_schedule(self) -> None:
        start = self._clock()
        slot = 0
        with self._send_lock:
            self._first_periodic_s = self._last_periodic_s = None
            self._counts["periodic"] = 0
        while not self._halt.is_set():
            with self._latest_lock:
                v, omega, flags = self._latest
            self._send(v, omega, flags, periodic=True)
            following = next_slot(slot, start, self.period_s, self._clock())
            with self._send_lock:
                self._counts["skipped"] += following - slot - 1
            slot = following
            deadline = start + slot * self.period_s
            while (remaining := deadline - self._clock()) > 0.0:
                if self._halt.wait(remaining):
                    return


def _check_fields(v_mps: float, omega_radps: float, flags: Flags | int) -> None:
    """Raise :class:`CarLinkError` now if a command with these fields could not be sent."""
    Command(1, 0, 0.0, v_mps, omega_radps, flags)


# ------------------------------------------------------------------------- receiving


class CommandReceiver:
    """Receives one car's commands: a bound UDP socket and a reader thread feeding a
    :class:`CommandFilter`.

    The socket is bound on construction (``address`` tells the port when 0 was asked
    for); the reader runs between :meth:`start` (or entering a ``with`` block) and
    :meth:`close`. ``clock`` stamps arrivals and is the default ``now`` of
    :meth:`active_command`.
    """

    def __init__(self, car_id: int, bind_address: tuple[str, int], *,
                 watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
                 resync_after_s: float = DEFAULT_RESYNC_AFTER_S, clock: Clock = time.monotonic,
                 recv_timeout_s: float = 0.1, join_timeout_s: float = 1.0):
        self._filter = CommandFilter(car_id, watchdog_timeout_s=watchdog_timeout_s,
                                     resync_after_s=resync_after_s)
        self.car_id = car_id
        self._clock = clock
        self._join_timeout_s = join_timeout_s
        family, sockaddr = _resolve(bind_address, passive=True)
        self._sock: socket.socket | None = socket.socket(family, socket.SOCK_DGRAM)
        try:
            self._sock.bind(sockaddr)
        except OSError:
            self._sock.close()
            raise
        self._sock.settimeout(recv_timeout_s)
        self.address: tuple = self._sock.getsockname()
        self._changed = threading.Condition()  # guards the filter; notified per datagram
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None
        self.receive_errors = 0
        self.deaf = threading.Event()
        """While set, arriving datagrams are discarded unread (a simulated cut link)."""
        self.discarded = 0

    def __enter__(self) -> CommandReceiver:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def counters(self) -> FilterCounters:
        with self._changed:
            return self._filter.counters

    @property
    def last_command(self) -> Command | None:
        with self._changed:
            return self._filter.last_command

    def active_command(self, now_s: float | None = None) -> tuple[float, float]:
        """The (v_mps, omega_radps) to apply at ``now_s`` (default: the clock's now)."""
        now = self._clock() if now_s is None else now_s
        with self._changed:
            return self._filter.active_command(now)

    def wait_until(self, predicate: Callable[[FilterCounters], bool], timeout_s: float) -> bool:
        """Block until ``predicate(counters)`` holds or ``timeout_s`` passes; whether it held."""
        with self._changed:
            return self._changed.wait_for(lambda: predicate(self._filter.counters), timeout_s)

    def start(self) -> None:
        if self._sock is None:
            raise RuntimeError(f"car {self.car_id}: receiver is closed")
        if self._thread is not None:
            return
        self._thread = threading.Thread(target=self._run, args=(self._sock,), name=f"carlink-rx-{self.car_id}",
                                        daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop and join the reader, then close the socket; safe to call twice."""
        if self._thread is not None:
            self._halt.set()
            self._thread.join(self._join_timeout_s)
            if self._thread.is_alive():
                log.error("car %d: receiver thread did not stop within %.1f s",
                          self.car_id, self._join_timeout_s)
            self._thread = None
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def _run(self, sock: socket.socket) -> None:
        try:
            while not self._halt.is_set():
                self._receive_one(sock)
        except Exception:  # the loop's edge: without commands the watchdog stops the car
            log.exception("car %d: receiver thread failed; commands stop, the watchdog stops the car",
                          self.car_id)

    def _receive_one(self, sock: socket.socket) -> None:
        try:
            data, _ = sock.recvfrom(_RECV_BUFFER_BYTES)
        except TimeoutError:
            return
        except OSError as exc:
            if self._halt.is_set():
                return  # closed under us after a join timeout
            self.receive_errors += 1
            log.warning("car %d: receive failed: %s", self.car_id, exc)
            self._halt.wait(0.05)  # back off rather than spin on a persistent error
            return
        if self.deaf.is_set():
            self.discarded += 1
            return
        now = self._clock()
        with self._changed:
            self._filter.accept(data, now)
            self._changed.notify_all()

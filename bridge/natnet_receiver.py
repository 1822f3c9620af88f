"""NatNet client logic without sockets: datagrams in, frames and the latest pose of every
rigid body out.

:class:`FrameReceiver` opens nothing: :class:`~trustfg.bridge.natnet_client.NatNetClient`
feeds it (from its socket thread, or from its readers' when they pull), and tests drive
it with captured bytes. It decodes (with
the pure codec in :mod:`bridge.natnet`), counts (received, decoded, rejected by reason,
frames dropped by gaps in frame numbers, stale/out-of-order), keeps a latest-value slot
per rigid body id, keeps the latest model definitions (MODELDEF: rigid bodies' names and
ids) and calls an optional ``on_frame(frame, received_s)`` callback.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Callable, Mapping

from . import natnet
from .natnet import Frame, MessageId, ModelDef, NatNetError, RigidBody, ServerInfo, Version, supports_frames

__all__ = ["FrameReceiver", "BodySample", "NatNetStats"]

# The whole NatNet client logs under one name, so one logger configures it.
log = logging.getLogger("trustfg.bridge.natnet_client")


@dataclass(frozen=True)
class BodySample:
    """The latest report of one rigid body. ``received_s`` is ``time.monotonic()``."""

    body: RigidBody
    frame_number: int
    timestamp: float
    received_s: float


@dataclass(frozen=True)
class NatNetStats:
    received: int = 0  # datagrams
    decoded: int = 0  # frames accepted
    rejected: Mapping[str, int] = field(default_factory=dict)  # datagrams, by reason
    dropped: int = 0  # frames missing from the sequence of frame numbers
    other: int = 0  # non-frame messages (SERVERINFO, responses, ...)
    callback_errors: int = 0
    last_frame_number: int | None = None
    skipped: int = 0  # frames left undecoded: over the rate cap, or newer ones came before a read

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())


class FrameReceiver:
    """Client logic: decode datagrams, count, keep the latest sample of each rigid body.

    ``handle`` is called by one thread (the socket's); the readers (``latest``, ``stats``,
    ``wait_for_frames``) may be called from any thread. A frame number lower than the last
    one is rejected as ``stale``, unless it is more than ``restart_threshold`` lower: then
    the server restarted and the sequence starts over.

    ``decode_on_read``: frames are kept undecoded as they come, the newest only, and decoded
    when a reader asks for the latest samples -- for a reader that wants the newest pose a
    few times a second of a stream many times faster (the command loop: 50 Hz of Motive's
    120-360). The samples it reads are those it would have read with every frame decoded
    (the newest received, with its own arrival time); the frames in between are counted as
    skipped. It takes no ``on_frame`` and no ``max_rate_hz``.
    """

    def __init__(self, version: Version | None, on_frame: Callable[[Frame, float], None] | None = None,
                 *, pinned: bool = False, restart_threshold: int = 600, max_rate_hz: float = 0.0,
                 decode_on_read: bool = False) -> None:
        if decode_on_read and (on_frame is not None or max_rate_hz > 0):
            raise ValueError("decode_on_read takes neither on_frame nor max_rate_hz")
        self._decode_on_read = decode_on_read
        self._held: tuple[memoryview, float] | None = None
        """The newest frame's payload and arrival, not decoded yet (decode_on_read)."""
        self._decoding = threading.Lock()
        """One reader decodes the held frame at a time (so none is taken for stale)."""
        self._version = version
        self._period = 1.0 / max_rate_hz if max_rate_hz > 0 else 0.0
        self._due = -math.inf
        self._skipped = 0
        self._skipped_since_accepted = 0
        """Frames left undecoded since the last accepted one: a gap they fill is no loss."""
        self._pinned = pinned
        self._on_frame = on_frame
        self._restart_threshold = restart_threshold
        self._cond = threading.Condition()
        self._latest: dict[int, BodySample] = {}
        self._rejected: Counter[str] = Counter()
        self._received = self._decoded = self._dropped = self._other = 0
        self._callback_errors = 0
        self._last_frame: int | None = None
        self.server_info: ServerInfo | None = None
        self.model: ModelDef | None = None
        """The latest MODELDEF (model definitions), None before one arrived."""
        self.models_changed = False
        """Set when a frame says Motive's tracked models changed (ask for MODELDEF again)."""

    @property
    def version(self) -> Version | None:
        return self._version

    def handle(self, packet: bytes, received_s: float) -> Frame | None:
        """Process one datagram; returns the frame if it was accepted."""
        with self._cond:
            self._received += 1
        try:
            message_id, payload = natnet.unpack_header(packet)
            if message_id != MessageId.FRAMEOFDATA:
                self._handle_other(message_id, payload)
                return None
            if self._version is None:
                raise NatNetError("frame before the NatNet version is known", "no_version")
            if self._decode_on_read:
                self._hold(payload, received_s)
                return None
            if self._over_rate(received_s):
                if _models_changed_hint(payload):
                    with self._cond:
                        self.models_changed = True
                return None
            frame = natnet.decode_frame(payload, self._version)
        except NatNetError as exc:
            self._reject(exc.reason, str(exc))
            return None
        if not self._accept(frame, received_s):
            return None
        if self._on_frame is not None:
            try:
                self._on_frame(frame, received_s)
            except Exception:  # the callback is user code; the socket thread must go on
                with self._cond:
                    self._callback_errors += 1
                log.exception("NatNet on_frame callback failed on frame %d", frame.frame_number)
        return frame

    def _hold(self, payload: memoryview, received_s: float) -> None:
        """Keep the newest frame for the next read; the one it replaces is skipped (but a
        change of Motive's models it tells is kept)."""
        with self._cond:
            if self._held is not None:
                self._skipped += 1
                self._skipped_since_accepted += 1
                if _models_changed_hint(self._held[0]):
                    self.models_changed = True
            self._held = (payload, received_s)
            self._cond.notify_all()

    def _settle(self) -> None:
        """Decode and accept the held frame, if any (decode_on_read): in the reader's thread."""
        if not self._decode_on_read:
            return
        with self._decoding:
            with self._cond:  # the frames skipped before it go with it: later ones may come meanwhile
                held, self._held = self._held, None
                skipped, self._skipped_since_accepted = self._skipped_since_accepted, 0
            if held is None:
                return
            payload, received_s = held
            try:
                frame = natnet.decode_frame(payload, self._version)
            except NatNetError as exc:
                with self._cond:  # the frames skipped before it go with the next one taken
                    self._skipped_since_accepted += skipped
                self._reject(exc.reason, str(exc))
                return
            self._accept(frame, received_s, skipped)

    def _over_rate(self, received_s: float) -> bool:
        """Whether a frame arriving at ``received_s`` is over ``max_rate_hz`` (then it is
        counted and left undecoded). Frames are taken at the first arrival at or after
        each due time, due times 1/max_rate_hz apart: the rate taken is the cap on average
        whatever the stream's rate (120 Hz capped at 50: every second or third frame); a
        stream slower than the cap, or a gap, resets the schedule."""
        if not self._period:
            return False
        if received_s < self._due:
            with self._cond:
                self._skipped += 1
                self._skipped_since_accepted += 1
            return True
        self._due += self._period
        if self._due < received_s:  # the first frame, a gap, or a stream slower than the cap
            self._due = received_s + self._period
        return False

    def _handle_other(self, message_id: int, payload: memoryview) -> None:
        with self._cond:
            self._other += 1
        if message_id == MessageId.MODELDEF:
            if self._version is None:
                raise NatNetError("MODELDEF before the NatNet version is known", "no_version")
            model = natnet.decode_model_def(payload, self._version)
            with self._cond:
                self.model = model
                self.models_changed = False
            log.info("NatNet model: rigid bodies %s",
                     ", ".join(f"{d.name!r}={d.id}" for d in model.rigid_bodies) or "none")
            return
        if message_id == MessageId.SERVERINFO:
            info = natnet.decode_server_info(payload)
            self.server_info = info
            if not self._pinned and info.natnet_version != self._version \
                    and supports_frames(info.natnet_version):
                log.warning("NatNet server now streams version %s (was %s)",
                            info.natnet_version, self._version)
                self._version = info.natnet_version

    def _reject(self, reason: str, message: str) -> None:
        with self._cond:
            self._rejected[reason] += 1
            first = self._rejected[reason] == 1
        log.log(logging.WARNING if first else logging.DEBUG,
                "NatNet datagram rejected (%s): %s", reason, message)

    def _accept(self, frame: Frame, received_s: float, skipped: int | None = None) -> bool:
        """Take a decoded frame; ``skipped``: frames left undecoded since the last one taken
        (None: the count kept for the socket thread, which skips and takes alike)."""
        number = frame.frame_number
        with self._cond:
            owed = self._skipped_since_accepted if skipped is None else skipped
            last = self._last_frame
            if last is not None:
                if number <= last and last - number <= self._restart_threshold:
                    if skipped is not None:  # handed over with this frame: they go with the next
                        self._skipped_since_accepted += skipped
                    self._rejected["stale"] += 1
                    return False
                if number > last + 1:  # a gap, less the frames we chose not to decode
                    self._dropped += max(number - last - 1 - owed, 0)
                elif number <= last:
                    log.info("NatNet frame numbers restarted (%d after %d)", number, last)
            if skipped is None:
                self._skipped_since_accepted = 0
            self._last_frame = number
            self._decoded += 1
            if frame.tracked_models_changed:
                self.models_changed = True
            for body in frame.rigid_bodies:
                self._latest[body.id] = BodySample(body, number, frame.timestamp, received_s)
            self._cond.notify_all()
        return True

    def body_ids(self) -> dict[str, int]:
        """Rigid-body name -> id, from the latest MODELDEF (empty before one arrived)."""
        with self._cond:
            model = self.model
        return {d.name: d.id for d in model.rigid_bodies} if model is not None else {}

    def latest(self, body_id: int) -> BodySample | None:
        self._settle()
        with self._cond:
            return self._latest.get(body_id)

    def latest_all(self) -> dict[int, BodySample]:
        self._settle()
        with self._cond:
            return dict(self._latest)

    def stats(self) -> NatNetStats:
        self._settle()
        with self._cond:
            return NatNetStats(self._received, self._decoded,
                               MappingProxyType(dict(self._rejected)), self._dropped,
                               self._other, self._callback_errors, self._last_frame, self._skipped)

    def wait_for_frames(self, count: int, timeout_s: float) -> bool:
        """Block until ``count`` frames in total have been accepted, or the timeout passes
        (with ``decode_on_read``, frames held and read count)."""
        deadline = time.monotonic() + timeout_s
        while True:
            self._settle()
            with self._cond:
                if self._decoded >= count:
                    return True
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)


def _models_changed_hint(payload: memoryview | bytes) -> bool:
    """Whether an undecoded frame may say that Motive's tracked models changed: its frame
    params (uint16, bit 0x02) end the frame, or come just before a zero end-of-data tag.
    A frame without the tag whose last four bytes are zero is read as having it: that may
    flag a change that was none (one MODELDEF asked for too many), never miss one."""
    tail = bytes(payload[-6:])
    if len(tail) < 6:
        return False
    params = tail[0:2] if tail[2:] == b"\0\0\0\0" else tail[4:6]
    return bool(int.from_bytes(params, "little") & 0x02)

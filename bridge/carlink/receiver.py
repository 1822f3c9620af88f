"""Car-link receiver: the rules the car's firmware runs on every datagram (pure, no I/O).

mocap_sim's simulated car runs this very class, so the simulation obeys the same rules as a
real car. The bytes themselves are in :mod:`.codec`; sockets and threads in :mod:`.link`.

Receiver rules (what the car firmware does; :class:`CommandFilter`)
---------------------------------------------------------------------
1. Decode; drop invalid datagrams and datagrams for another car id. A car with a key
   decodes version 2 only (a bad MAC is dropped as ``mac``); a car without one, version 1.
   Every version-2 datagram names its ``source`` (0 the car process, 1 the operator, ...);
   a version-1 datagram is always source 0.
2. E_STOP latches for its source at once, whatever the datagram's sequence number or
   session, and without touching the sequence reference or the watchdog's clock (rules
   4, 5 and 6). An e-stop may come from a second sender -- the operator, straight to the
   car (``trustfg stop``, go's key, the dashboard's button) -- whose numbers have nothing
   to do with the car process's, or from an older session of the operator's tools than the
   newest the car has seen; taking one can only make the car safer. (A replayed e-stop
   stops the car: a denial of service, which jamming the radio achieves as well; it can
   never make a car move. Version 2 still needs the car's key to make one.)
3. PING: the car answers (:mod:`.answer`, to the datagram's source address and port) after
   rule 2; a PING is otherwise not applied and does not touch the sequence, the sessions
   or the watchdog, so the operator's checks never disturb the car process's stream.
4. Version 2 -- sessions (replays are refused, also across a sender's restart). Per
   source the car keeps the newest session it has accepted and the last sequence number
   in it:

   * a datagram of that session is accepted only if its seq is larger than the last one
     (a repeat or an older one is a replay, or overtaken on the air: dropped);
   * a datagram of a *larger* session is a restarted sender: accepted, and from now on
     that source's older sessions are refused (``old_session``), however long it is quiet;
   * a datagram of a smaller session is refused (``old_session``).

   Session ids are the sender's start time in microseconds, so they grow across restarts
   (a sender whose clock was set back by more than its run time is refused until it passes
   -- it fails safe, standing). Limits: the car's memory of sessions is lost when the car
   itself reboots, after which the first authentic datagram of any session is taken (keep
   the newest session per source in non-volatile memory to close this); and a datagram
   held back by an attacker may still arrive late, within its session's order (the
   watchdog bounds what a withheld stream can do).
5. Version 1 -- sequence numbers compare with serial-number arithmetic (RFC 1982, 32 bits):
   ``s`` is after ``last`` iff ``0 < (s - last) mod 2**32 < 2**31``. Only a datagram after
   the last accepted one is accepted. The first datagram ever is accepted whatever its seq.
   Restarted sender: if no datagram has been *accepted* for ``resync_after_s`` (default
   1.0 s), the next valid datagram is accepted whatever its seq. This is why, in version 1,
   a second sender must send nothing but E_STOP and PING: an ordinary command accepted out
   of the car process's sequence would become the reference and the car would stand until
   the resync. (The CRC detects corruption, not forgery: after a silence a replayed capture
   looks like a restarted sender -- version 2 exists for that.)
6. Watchdog: the command to apply is (0, 0) once the last accepted command is
   ``watchdog_timeout_s`` (default 0.250 s) old, measured on the receiver's clock (the
   sender's stamp is for logs and latency only; the clocks need not agree).
7. RELEASE: only an accepted datagram (rules 4, 5) with RELEASE *from the source that set
   the e-stop* clears that source's latch. The car process sends RELEASE for a few
   datagrams after the operator released the car; the operator's tools send it (version 2,
   in a new session of their own) for the e-stops they sent straight to the car. Nothing
   else releases -- neither silence, nor ordinary commands, nor another source -- so an
   e-stop the operator sent straight to the car holds while a car process that never heard
   of it keeps driving. (Version 1 has one source: there the car process's RELEASE clears
   every e-stop, the operator's direct ones too.)
8. (0, 0) while any source's E_STOP is latched, or while the latest command has STOP.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, field
from typing import Mapping

from .answer import Answer, CarState
from .codec import Command, _check_int, decode_command, decode_command_v2, seq_after
from .frame import CarLinkError, check_key

log = logging.getLogger(__name__)

DEFAULT_WATCHDOG_TIMEOUT_S = 0.250
DEFAULT_RESYNC_AFTER_S = 1.0


@dataclass(frozen=True)
class FilterCounters:
    """A snapshot of what a :class:`CommandFilter` accepted and rejected.

    ``resynced`` counts accepted datagrams whose seq was not after the last one and that
    were taken under the version-1 restart rule; ``new_session`` accepted version-2
    datagrams that opened a newer session of their source (both are also in ``accepted``).
    ``old_session`` counts version-2 datagrams of a session older than their source's
    newest. ``decode_errors`` maps a :class:`CarLinkError` reason to its count (a bad MAC
    is ``"mac"``).
    """

    accepted: int = 0
    resynced: int = 0
    e_stops: int = 0
    """Datagrams with E_STOP taken (rule 2), in or out of sequence; not in ``accepted``."""
    pings: int = 0
    """PING datagrams answered (rule 3); not in ``accepted``."""
    wrong_car: int = 0
    stale_seq: int = 0
    repeated_seq: int = 0
    decode_errors: Mapping[str, int] = field(default_factory=dict)
    new_session: int = 0
    old_session: int = 0

    @property
    def decode_error(self) -> int:
        return sum(self.decode_errors.values())

    @property
    def rejected(self) -> int:
        return self.decode_error + self.wrong_car + self.stale_seq + self.repeated_seq + self.old_session


class CommandFilter:
    """The car's side of the link: which datagrams to accept and what to apply now.

    Pure and single-threaded; times are seconds on the receiver's clock. With ``key`` (the
    car's 32-byte link key) it speaks version 2, without one version 1. See this module's
    docstring, "Receiver rules", for the rules and why the restart rules are safe.
    """

    def __init__(self, car_id: int, *, key: bytes | None = None,
                 watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
                 resync_after_s: float = DEFAULT_RESYNC_AFTER_S):
        _check_int("car_id", car_id, 1, 255)
        self._key = check_key(key) if key is not None else None
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
        self._e_stop_sources: set[int] = set()
        self._sessions: dict[int, tuple[int, int]] = {}  # version 2: source -> (session, last seq)
        self._counts: Counter[str] = Counter()
        self._decode_errors: Counter[str] = Counter()

    @property
    def last_command(self) -> Command | None:
        """The last accepted command, or None before the first."""
        return self._last

    @property
    def version(self) -> int:
        return 1 if self._key is None else 2

    @property
    def e_stop_latched(self) -> bool:
        return bool(self._e_stop_sources)

    @property
    def counters(self) -> FilterCounters:
        return FilterCounters(accepted=self._counts["accepted"], resynced=self._counts["resynced"],
                              e_stops=self._counts["e_stops"], pings=self._counts["pings"],
                              wrong_car=self._counts["wrong_car"], stale_seq=self._counts["stale_seq"],
                              repeated_seq=self._counts["repeated_seq"],
                              decode_errors=dict(self._decode_errors), new_session=self._counts["new_session"],
                              old_session=self._counts["old_session"])

    def accept(self, data: bytes, now_s: float) -> Command | None:
        """Decode and filter one datagram received at ``now_s``; None (counted) if dropped.
        A PING comes back (it is to be answered: :meth:`answer`) but is not applied.

        Never raises for any bytes-like input.
        """
        try:
            cmd = decode_command(data) if self._key is None else decode_command_v2(data, self._key)
        except CarLinkError as exc:
            self._decode_errors[exc.reason] += 1
            log.debug("car %d: dropped invalid datagram (%s)", self.car_id, exc)
            return None
        if cmd.car_id != self.car_id:
            self._counts["wrong_car"] += 1
            log.debug("car %d: dropped datagram for car %d", self.car_id, cmd.car_id)
            return None
        if cmd.e_stop:  # rule 2: from any sender, in or out of sequence or session
            if cmd.source not in self._e_stop_sources:
                log.warning("car %d: E-STOP latched by source %d (seq %d)", self.car_id, cmd.source, cmd.seq)
            self._e_stop_sources.add(cmd.source)
            self._counts["e_stops"] += 1
            if cmd.ping:
                self._counts["pings"] += 1
            return cmd
        if cmd.ping:  # rule 3: answered, not applied
            self._counts["pings"] += 1
            return cmd
        if not (self._sequence_ok(cmd, now_s) if self._key is None else self._session_ok(cmd)):
            return None
        self._take(cmd, now_s)
        return cmd

    def answer(self, ping: Command, now_s: float) -> Answer:
        """The answer to a PING datagram (rule 3): the car's state after handling it, and
        the PING's source, session, seq and stamp, so its sender knows it for its own."""
        state = CarState.E_STOP_LATCHED if self._e_stop_sources else CarState.NONE
        if self.active_command(now_s) == (0.0, 0.0):
            state |= CarState.STOPPED
        return Answer(self.car_id, ping.seq, ping.stamp_s, state, ping.session, ping.source)

    def active_command(self, now_s: float) -> tuple[float, float]:
        """The (v_mps, omega_radps) to apply at ``now_s``: (0, 0) when stopped for any reason."""
        cmd = self._last
        if cmd is None or self._e_stop_sources or cmd.stop:
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

    def _session_ok(self, cmd: Command) -> bool:
        """Version 2: per source, only the newest session, and in it only a larger seq."""
        current = self._sessions.get(cmd.source)
        if current is None or cmd.session > current[0]:
            if current is not None:
                log.info("car %d: source %d started session %d (was %d)", self.car_id, cmd.source,
                         cmd.session, current[0])
            self._counts["new_session"] += 1
            self._sessions[cmd.source] = (cmd.session, cmd.seq)
            return True
        session, last_seq = current
        if cmd.session < session:
            self._counts["old_session"] += 1
            log.debug("car %d: dropped datagram of old session %d (source %d is at %d)", self.car_id,
                      cmd.session, cmd.source, session)
            return False
        if cmd.seq <= last_seq:
            key = "repeated_seq" if cmd.seq == last_seq else "stale_seq"
            self._counts[key] += 1
            log.debug("car %d: dropped seq %d (%s, last %d)", self.car_id, cmd.seq, key, last_seq)
            return False
        self._sessions[cmd.source] = (session, cmd.seq)
        return True

    def _take(self, cmd: Command, now_s: float) -> None:
        if cmd.release and cmd.source in self._e_stop_sources:  # rule 7
            log.warning("car %d: E-STOP released by source %d (seq %d)", self.car_id, cmd.source, cmd.seq)
            self._e_stop_sources.discard(cmd.source)
        self._last = cmd
        self._last_time_s = now_s
        self._counts["accepted"] += 1

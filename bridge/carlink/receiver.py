"""Car-link receiver: the rules the car's firmware runs on every datagram (pure, no I/O).

mocap_sim's simulated car runs this very class, so the simulation obeys the same rules as a
real car. The bytes themselves are in :mod:`.codec`; sockets and threads in :mod:`.link`.

Receiver rules (what the car firmware does; :class:`CommandFilter`)
---------------------------------------------------------------------
1. Decode; drop invalid datagrams and datagrams for another car id.
2. E_STOP latches at once, whatever the datagram's sequence number, and without touching
   the sequence reference or the watchdog's clock (rules 4 and 6). An e-stop may come from
   a second sender -- the operator, straight to the car (``trustfg stop``) -- whose
   numbers have nothing to do with the car process's, and taking one can only make the
   car safer. (A replayed e-stop stops the car: a denial of service, which jamming the
   radio achieves as well; it can never make a car move.)
3. PING: the car answers (:mod:`.answer`, to the datagram's source address and port) after
   rule 2; a PING is otherwise not applied and does not touch the sequence or the
   watchdog, so the operator's checks never disturb the car process's stream.
4. Sequence numbers compare with serial-number arithmetic (RFC 1982, 32 bits): ``s`` is
   after ``last`` iff ``0 < (s - last) mod 2**32 < 2**31``. Only a datagram after the
   last accepted one is accepted: repeats, replays and datagrams overtaken on the air
   are dropped. The first datagram ever is accepted whatever its seq.
   This is why a second sender must not send ordinary commands: one accepted out of the
   car process's sequence becomes the reference, the car process's next datagrams look
   old and are dropped until rule 5 adopts them again after 1 s, and the car stands
   meanwhile (rule 6). The operator sends nothing but E_STOP and PING.
5. Restarted sender: a restarted car process starts a new sequence, which usually looks
   "old". If no datagram has been *accepted* for ``resync_after_s`` (default 1.0 s), the
   next valid datagram is accepted whatever its seq and becomes the new reference.
   This is safe because ``resync_after_s`` is longer than the watchdog, so the car has
   been standing still for a while when a new sequence is adopted, and whatever comes
   next is again watched by the watchdog. Silence is measured from the last accepted
   datagram, so a new sender's stream of "old" numbers cannot postpone the resync
   forever. (The CRC detects corruption, not forgery: the link is not authenticated,
   and after a silence a replayed capture looks like a restarted sender.)
6. Watchdog: the command to apply is (0, 0) once the last accepted command is
   ``watchdog_timeout_s`` (default 0.250 s) old, measured on the receiver's clock (the
   sender's stamp is for logs and latency only; the clocks need not agree).
7. RELEASE: only an accepted datagram (rule 4) with RELEASE clears a latched E_STOP; the
   car process sends it for a few datagrams after the operator released the car. Nothing
   else does -- neither silence nor ordinary commands, so an e-stop the operator sent
   straight to the car holds while a car process that never heard of it keeps driving.
8. (0, 0) while E_STOP is latched, or while the latest command has STOP.
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, field
from typing import Mapping

from .answer import Answer, CarState
from .codec import CarLinkError, Command, _check_int, decode_command, seq_after

log = logging.getLogger(__name__)

DEFAULT_WATCHDOG_TIMEOUT_S = 0.250
DEFAULT_RESYNC_AFTER_S = 1.0


@dataclass(frozen=True)
class FilterCounters:
    """A snapshot of what a :class:`CommandFilter` accepted and rejected.

    ``resynced`` counts accepted datagrams whose seq was not after the last one and that
    were taken under the restart rule (they are also in ``accepted``).
    ``decode_errors`` maps a :class:`CarLinkError` reason to its count.
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

    @property
    def decode_error(self) -> int:
        return sum(self.decode_errors.values())

    @property
    def rejected(self) -> int:
        return self.decode_error + self.wrong_car + self.stale_seq + self.repeated_seq


class CommandFilter:
    """The car's side of the link: which datagrams to accept and what to apply now.

    Pure and single-threaded; times are seconds on the receiver's clock. See this module's
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
                              e_stops=self._counts["e_stops"], pings=self._counts["pings"],
                              wrong_car=self._counts["wrong_car"], stale_seq=self._counts["stale_seq"],
                              repeated_seq=self._counts["repeated_seq"],
                              decode_errors=dict(self._decode_errors))

    def accept(self, data: bytes, now_s: float) -> Command | None:
        """Decode and filter one datagram received at ``now_s``; None (counted) if dropped.
        A PING comes back (it is to be answered: :meth:`answer`) but is not applied.

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
        if cmd.e_stop:  # rule 2: from any sender, in or out of sequence
            if not self._e_stop_latched:
                log.warning("car %d: E-STOP latched (seq %d)", self.car_id, cmd.seq)
            self._e_stop_latched = True
            self._counts["e_stops"] += 1
            if cmd.ping:
                self._counts["pings"] += 1
            return cmd
        if cmd.ping:  # rule 3: answered, not applied
            self._counts["pings"] += 1
            return cmd
        if not self._sequence_ok(cmd, now_s):
            return None
        self._take(cmd, now_s)
        return cmd

    def answer(self, ping: Command, now_s: float) -> Answer:
        """The answer to a PING datagram (rule 3): the car's state after handling it."""
        state = CarState.E_STOP_LATCHED if self._e_stop_latched else CarState.NONE
        if self.active_command(now_s) == (0.0, 0.0):
            state |= CarState.STOPPED
        return Answer(self.car_id, ping.seq, ping.stamp_s, state)

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
        if self._e_stop_latched and cmd.release:  # rule 7
            log.warning("car %d: E-STOP released (seq %d)", self.car_id, cmd.seq)
            self._e_stop_latched = False
        self._last = cmd
        self._last_time_s = now_s
        self._counts["accepted"] += 1

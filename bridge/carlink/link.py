"""Car-link sockets: the car process's sender and a car's receiver thread (thin I/O).

The bytes are in :mod:`.codec`, the receiving rules in :mod:`.receiver`; this module moves
datagrams between them and UDP sockets. :class:`CommandSender` sends one numbered, stamped
datagram per :meth:`~CommandSender.send` -- version 2 (a session of its own) with the car's
key, version 1 without; :meth:`CommandSender.for_car` builds it from a car's config -- reads
the car's answers to its PINGs without blocking, and on shutdown sends a few STOPs that
keep an E_STOP. It keeps no schedule: the caller's loop sets the pace
(``fleet/car/ticker.py``). :class:`CommandReceiver` is a bound socket and a reader thread
feeding a :class:`~.receiver.CommandFilter` and answering PINGs (mocap-sim's cars).
Design: docs/design/links.md, "The car link's sockets".
"""

from __future__ import annotations

import logging
import select
import socket
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

from .answer import Answer, decode_answer, encode_answer
from .codec import Command, _check_int, encode_command, encode_command_v2
from .direct import resolve
from .frame import SEQ_MODULUS, SOURCE_CAR_PROCESS, CarLinkError, Flags, check_key, new_session
from .keys import link_key
from .receiver import (
    DEFAULT_RESYNC_AFTER_S,
    DEFAULT_WATCHDOG_TIMEOUT_S,
    CommandFilter,
    FilterCounters,
)

if TYPE_CHECKING:
    from ...agent.config import CarConfig

log = logging.getLogger(__name__)

# recv buffer larger than a datagram, so an oversized datagram is seen (wrong length)
# rather than silently truncated to 30 (or 52) bytes.
_RECV_BUFFER_BYTES = 2048

Clock = Callable[[], float]


@dataclass(frozen=True)
class SenderStats:
    """Counts of a :class:`CommandSender`: ``sent`` datagrams handed to the socket (commands
    and STOP datagrams alike), ``send_errors``, datagrams the socket refused, ``answers``
    received and ``bad_answers`` (invalid, forged, from another car or of another session), dropped."""

    sent: int = 0
    send_errors: int = 0
    answers: int = 0
    bad_answers: int = 0


class CommandSender:
    """Sends one car's commands over UDP, one datagram per :meth:`send`; owns one socket.

    The caller sets the pace (the car process's control loop). ``stop()`` sends
    ``stop_repeats`` STOP datagrams, keeping E_STOP if the last command given to
    :meth:`send` had it, so shutting down never releases a car's e-stop; ``close()``
    (also on leaving a ``with`` block) stops and closes the socket. Sequence numbers start
    at ``first_seq`` and wrap (version 2: a new session instead). ``stamp_clock`` stamps
    datagrams -- pass the fleet clock. With ``key`` it sends version 2 as ``source``
    (codec.SOURCE_CAR_PROCESS, SOURCE_OPERATOR, ...) in a session of its own.
    Safe to call from two threads (a control thread sending, the main thread stopping).
    """

    def __init__(self, car_id: int, address: tuple[str, int], *, key: bytes | None = None,
                 source: int = SOURCE_CAR_PROCESS, stamp_clock: Clock = time.monotonic,
                 first_seq: int = 0, stop_repeats: int = 3, stop_spacing_s: float = 0.005,
                 send_timeout_s: float = 0.1):
        _check_int("car_id", car_id, 1, 255)
        _check_int("seq", first_seq, 0, SEQ_MODULUS - 1)
        _check_int("source", source, 0, 255)
        self.car_id = car_id
        self._key = check_key(key) if key is not None else None
        self.source = source
        self.session = new_session() if self._key is not None else 0
        self._stamp_clock = stamp_clock
        self._seq = first_seq
        self._stop_repeats = stop_repeats
        self._stop_spacing_s = stop_spacing_s
        family, self._sockaddr = resolve(address, passive=False)
        self._sock: socket.socket | None = socket.socket(family, socket.SOCK_DGRAM)
        self._sock.settimeout(send_timeout_s)
        self._lock = threading.Lock()  # seq, socket, last flags and counts
        self._last_flags = Flags.NONE
        self._sent = 0
        self._send_errors = 0
        self._answers = 0
        self._bad_answers = 0

    @classmethod
    def for_car(cls, car: "CarConfig", *, source: int = SOURCE_CAR_PROCESS, stamp_clock: Clock = time.time,
                **options) -> "CommandSender":
        """The one place that turns a car's config into a sender to it -- the car process's
        and the operator's tools' (``source=SOURCE_OPERATOR``: trustfg stop, check, go, the
        dashboard) alike: its ``link`` address, and version 2 with its key unless it asks
        for version 1. ConfigError for a bad address or a missing or bad key."""
        from ...agent.config import parse_udp_address  # not at import: trustfg stop's first datagrams go first

        host, port = parse_udp_address(car.link, f"cars[id={car.id}].link")
        return cls(car.id, (host, port), key=link_key(car), source=source, stamp_clock=stamp_clock, **options)

    @property
    def version(self) -> int:
        return 1 if self._key is None else 2

    def renew_session(self) -> None:
        """Version 2: go on in a new session (seq from 0). An operator's tool does this
        before a RELEASE, which the car takes only in its source's newest session
        (receiver, rules 4 and 7): another tool of the operator may have sent since."""
        with self._lock:
            if self._key is not None:
                self.session, self._seq = new_session(), 0

    def __enter__(self) -> CommandSender:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def stats(self) -> SenderStats:
        with self._lock:
            return SenderStats(sent=self._sent, send_errors=self._send_errors, answers=self._answers,
                               bad_answers=self._bad_answers)

    def send(self, v_mps: float, omega_radps: float, flags: Flags | int = Flags.NONE) -> Command | None:
        """Send one datagram now, stamped and numbered; the command, or None if the socket failed.

        Invalid fields raise :class:`CarLinkError`. A failed send is logged and counted:
        to the car it is a lost datagram.
        """
        with self._lock:
            if self._sock is None:
                raise RuntimeError(f"car {self.car_id}: sender is closed")
            cmd = Command(self.car_id, self._seq, self._stamp_clock(), v_mps, omega_radps, flags,
                          self.session, self.source)
            self._seq = (self._seq + 1) % SEQ_MODULUS
            if self._seq == 0 and self._key is not None:  # version 2 never wraps: a new session
                self.session = new_session()
            # What the caller asked for, even if the socket fails: stop() keeps an e-stop
            # whose own datagram was lost. A PING is not a command.
            if not cmd.ping:
                self._last_flags = cmd.flags
            datagram = encode_command(cmd) if self._key is None else encode_command_v2(cmd, self._key)
            try:
                self._sock.sendto(datagram, self._sockaddr)
            except OSError as exc:
                self._send_errors += 1
                log.warning("car %d: send of seq %d failed: %s", self.car_id, cmd.seq, exc)
                return None
            self._sent += 1
            return cmd

    def answers(self) -> list[Answer]:
        """The car's answers to our PINGs that have arrived since the last call (never blocks):
        in the link's version, for this car and (version 2) this sender's session."""
        got = []
        with self._lock:
            # The socket has a (send) timeout, under which recv would wait: poll first.
            while self._sock is not None and select.select([self._sock], [], [], 0.0)[0]:
                try:
                    data = self._sock.recv(_RECV_BUFFER_BYTES)
                except OSError as exc:  # e.g. ICMP port unreachable on some systems: nobody answers
                    log.debug("car %d: reading answers: %s", self.car_id, exc)
                    break
                try:
                    answer = decode_answer(data, self._key)
                except CarLinkError:
                    self._bad_answers += 1
                    continue
                if answer.car_id != self.car_id or answer.session != self.session:
                    self._bad_answers += 1
                    continue
                self._answers += 1
                got.append(answer)
        return got

    def stop(self) -> None:
        """Send the STOP datagrams (E_STOP kept if the last command had it); a no-op once closed."""
        with self._lock:
            if self._sock is None:
                return
            flags = Flags.STOP | (self._last_flags & Flags.E_STOP)
        for i in range(self._stop_repeats):
            if i:
                time.sleep(self._stop_spacing_s)  # spread out: Wi-Fi loses bursts together
            self.send(0.0, 0.0, flags)

    def close(self) -> None:
        """Stop (sending STOP) and close the socket; safe to call twice."""
        if self._sock is None:
            return
        self.stop()
        with self._lock:
            if self._sock is not None:
                self._sock.close()
                self._sock = None


# ------------------------------------------------------------------------- receiving


class CommandReceiver:
    """Receives one car's commands: a bound UDP socket and a reader thread feeding a
    :class:`CommandFilter`.

    The socket is bound on construction (``address`` tells the port when 0 was asked
    for); the reader runs between :meth:`start` (or entering a ``with`` block) and
    :meth:`close`. ``clock`` stamps arrivals and is the default ``now`` of
    :meth:`active_command`. With ``key`` the car speaks version 2 (see :mod:`.receiver`).
    """

    def __init__(self, car_id: int, bind_address: tuple[str, int], *, key: bytes | None = None,
                 watchdog_timeout_s: float = DEFAULT_WATCHDOG_TIMEOUT_S,
                 resync_after_s: float = DEFAULT_RESYNC_AFTER_S, clock: Clock = time.monotonic,
                 recv_timeout_s: float = 0.1, join_timeout_s: float = 1.0):
        self._filter = CommandFilter(car_id, key=key, watchdog_timeout_s=watchdog_timeout_s,
                                     resync_after_s=resync_after_s)
        self._key = check_key(key) if key is not None else None
        self.car_id = car_id
        self._clock = clock
        self._join_timeout_s = join_timeout_s
        family, sockaddr = resolve(bind_address, passive=True)
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
            data, source = sock.recvfrom(_RECV_BUFFER_BYTES)
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
            cmd = self._filter.accept(data, now)
            answer = self._filter.answer(cmd, now) if cmd is not None and cmd.ping else None
            key = self._key
            self._changed.notify_all()
        if answer is not None:
            try:
                sock.sendto(encode_answer(answer, key), source)
            except OSError as exc:
                log.debug("car %d: answer to %s failed: %s", self.car_id, source, exc)

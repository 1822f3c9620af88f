"""Car-link sockets: the car process's sender and a car's receiver thread (thin I/O).

The bytes are in :mod:`.codec`, the receiving rules in :mod:`.receiver`; this module only
moves datagrams between them and UDP sockets.

Sender (:class:`CommandSender`): sends the latest (v, omega, flags) at a fixed rate
(default 50 Hz) on absolute deadlines ``start + k * period``; a late sender sends one
datagram for the missed slots and carries on with the schedule (no bursts).

Receiver (:class:`CommandReceiver`): a bound UDP socket and a reader thread that feeds
every datagram to a :class:`~.receiver.CommandFilter` (mocap_sim's simulated cars use it).
"""

from __future__ import annotations

import logging
import math
import socket
import threading
import time
from collections import Counter
from dataclasses import dataclass
from typing import Callable

from trustfg.bridge.carlink.codec import SEQ_MODULUS, Command, Flags, _check_int, encode_command
from trustfg.bridge.carlink.receiver import (
    DEFAULT_RESYNC_AFTER_S,
    DEFAULT_WATCHDOG_TIMEOUT_S,
    CommandFilter,
    FilterCounters,
)

log = logging.getLogger(__name__)

# recv buffer larger than a datagram, so an oversized datagram is seen (wrong length)
# rather than silently truncated to 30 bytes.
_RECV_BUFFER_BYTES = 2048

DEFAULT_RATE_HZ = 50.0

Clock = Callable[[], float]


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

"""The probes of ``trustfg carlink-test`` (:mod:`.conformance`): what each sends a car and
what it reads back.

A :class:`Tester` holds one UDP socket to the car (:class:`UdpProbe`, the thin I/O) and the
numbering of the senders it plays -- the car process (source 0), the operator (source 1)
and its PINGs -- and reads the car's state from its answers to PINGs (:mod:`.answer`:
e-stop latched; the command applied is zero). Each probe function starts from a released,
standing car and returns its checks as (what must hold, whether it held), or samples for a
verdict to judge (:mod:`.conformance`). :class:`Unobservable` says a probe could not see
what it needed to (a PING unanswered, a starting state not made).
"""

from __future__ import annotations

import math
import socket
import time
from dataclasses import dataclass

from .answer import Answer, CarState, decode_answer
from .direct import resolve
from .frame import (
    COMMAND_BODY_V2,
    MAGIC,
    SOURCE_CAR_PROCESS,
    SOURCE_OPERATOR,
    VERSION_2,
    CarLinkError,
    Flags,
    command_datagram,
    new_session,
    seal,
)
from .keys import new_key
from .receiver import DEFAULT_RESYNC_AFTER_S, DEFAULT_WATCHDOG_TIMEOUT_S

PING_BOUND_MS = 10.0
"""A car answers a PING within this, ms (docs/carlink.md, what else the firmware must do)."""


@dataclass(frozen=True)
class ConformanceOptions:
    """What the probes send and the bounds they hold a car to."""

    car_id: int
    key: bytes
    speed_mps: float = 0.1
    """The speed of the probes' commands (the car drives at it, briefly: wheels off the floor)."""
    pings: int = 20
    """PINGs whose round trip is measured."""
    ping_bound_ms: float = PING_BOUND_MS
    """A PING's answer within this (19 of 20 must be)."""
    watchdog_ms: float = DEFAULT_WATCHDOG_TIMEOUT_S * 1000.0
    """The car stands this long after its last accepted command (receiver.py, rule 6)."""
    watchdog_slack_ms: float = 25.0
    """Allowed beyond ``watchdog_ms`` for the link's delay and the sampling (a PING every 2 ms)."""
    answer_timeout_s: float = 0.25
    """How long an awaited answer may take before the PING counts as lost."""
    quiet_s: float = 0.05
    """How long to listen for an answer that must not come (5 PING bounds)."""
    resync_s: float = DEFAULT_RESYNC_AFTER_S
    """The silence after which a version-1 car takes any sequence; a version-2 car must not."""


class Unobservable(Exception):
    """The car did not answer a PING, or the probe's starting state could not be made:
    what it says about the rule is unknown (the rule fails, 'not tested')."""


# ------------------------------------------------------------------------ the socket


class UdpProbe:
    """One UDP socket to a car (thin I/O): datagrams out, the car's answers in, with the
    monotonic time of each."""

    def __init__(self, address: tuple[str, int]):
        family, self._sockaddr = resolve(address, passive=False)
        self._sock = socket.socket(family, socket.SOCK_DGRAM)

    def __enter__(self) -> UdpProbe:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._sock.close()

    def send(self, datagram: bytes) -> float:
        sent = time.monotonic()
        self._sock.sendto(datagram, self._sockaddr)
        return sent

    def receive(self, until: float) -> tuple[bytes, float] | None:
        """The next datagram that arrives before monotonic time ``until``, or None."""
        while True:
            wait = until - time.monotonic()
            if wait <= 0:
                return None
            self._sock.settimeout(wait)
            try:
                data = self._sock.recv(2048)
            except TimeoutError:
                return None
            except OSError:  # ICMP port unreachable: nobody listens there (yet)
                continue
            return data, time.monotonic()


# ------------------------------------------------------------------------ the probes


@dataclass
class Stream:
    """One sender's numbering: its session (new_session(): larger after every restart) and seq."""

    source: int
    session: int = 0
    seq: int = 0

    def restart(self) -> None:
        self.session, self.seq = new_session(), 0

    def take(self) -> int:
        self.seq += 1
        return self.seq - 1


class Tester:
    """Sends the probes' datagrams through a probe and reads the car's state from its answers."""

    def __init__(self, probe: UdpProbe, options: ConformanceOptions):
        self.probe, self.options = probe, options
        self.car = Stream(SOURCE_CAR_PROCESS)
        self.operator = Stream(SOURCE_OPERATOR)
        self.pings = Stream(SOURCE_OPERATOR)  # PINGs touch no session: one of their own
        for stream in (self.car, self.operator, self.pings):
            stream.restart()
        self.forger_key = new_key()
        self.answers = 0
        """Answers to this tester's PINGs received so far."""

    # -- datagrams

    def datagram(self, stream: Stream | None, flags: int, v: float = 0.0, *, omega: float = 0.0,
                 seq: int | None = None, session: int | None = None, source: int | None = None,
                 car_id: int | None = None, key: bytes | None = None, reserved: int = 0, stamp: float | None = None,
                 magic: bytes = MAGIC, version: int = VERSION_2) -> bytes:
        """A version-2 datagram with any field values, sealed with ``key`` (the car's by default)."""
        stream = stream or self.car
        body = COMMAND_BODY_V2.pack(magic, version, self.options.car_id if car_id is None else car_id,
                                    stream.source if source is None else source, reserved, flags,
                                    stream.session if session is None else session,
                                    stream.take() if seq is None else seq,
                                    time.time() if stamp is None else stamp, v, omega)
        return seal(body, key or self.options.key)

    def send(self, datagram: bytes) -> float:
        return self.probe.send(datagram)

    def drive(self) -> bytes:
        data = self.datagram(self.car, Flags.NONE, self.options.speed_mps)
        self.send(data)
        return data

    def stop(self, stream: Stream | None = None, flags: int = Flags.STOP) -> bytes:
        data = self.datagram(stream or self.car, flags)
        self.send(data)
        return data

    # -- answers

    def ping(self, flags: int = Flags.PING, *, stream: Stream | None = None, v: float = 0.0,
             seq: int | None = None, session: int | None = None) -> tuple[Answer | None, float, float]:
        """Send a PING (with ``flags``) as ``stream`` (default: the PINGs' own); its answer
        or None, the round trip in ms, and when it was sent. An answer counts only if it is
        authentic (the car's key) and echoes this PING's car, source, session, seq and stamp."""
        stream = stream or self.pings
        seq = stream.take() if seq is None else seq
        session = stream.session if session is None else session
        stamp = time.time()
        sent = self.send(self.datagram(stream, flags, v, seq=seq, session=session, stamp=stamp))
        echo = (self.options.car_id, stream.source, session, seq, stamp)
        until = sent + self.options.answer_timeout_s
        while (got := self.probe.receive(until)) is not None:
            data, arrived = got
            try:
                answer = decode_answer(data, self.options.key)
            except CarLinkError:
                continue  # not an authentic answer: as good as none
            if (answer.car_id, answer.source, answer.session, answer.seq, answer.stamp_s) == echo:
                self.answers += 1
                return answer, (arrived - sent) * 1000.0, sent
        return None, math.inf, sent

    def state(self) -> CarState:
        answer, _, _ = self.ping()
        if answer is None:
            raise Unobservable("a PING went unanswered")
        return answer.state

    def moving(self) -> bool:
        return not self.state() & CarState.STOPPED

    def latched(self) -> bool:
        return bool(self.state() & CarState.E_STOP_LATCHED)

    def quiet_after(self, datagram: bytes) -> bool:
        """Send ``datagram``; True if nothing comes back within ``quiet_s``."""
        sent = self.send(datagram)
        return self.probe.receive(sent + self.options.quiet_s) is None

    # -- starting states

    def reset(self) -> None:
        """Both sources' e-stops released (each in a new session), the car standing."""
        for stream in (self.car, self.operator):
            stream.restart()
            self.stop(stream, Flags.STOP | Flags.RELEASE)
        if self.state() & CarState.E_STOP_LATCHED:
            raise Unobservable("the car stays e-stopped after a RELEASE of sources 0 and 1")

    def need(self, holds: bool, what: str) -> None:
        if not holds:
            raise Unobservable(what)

    def sleep(self, seconds: float) -> None:
        time.sleep(seconds)


# ------------------------------------------------------------------- the rules' probes


def ping_answered(t: Tester) -> list[float | None]:
    """Round trips (ms) of ``pings`` PINGs, None for one unanswered (all the rest too
    once the first three went unanswered: a car that answers none is not waited for)."""
    round_trips: list[float | None] = []
    while len(round_trips) < t.options.pings:
        if round_trips[:3] == [None, None, None]:
            round_trips.append(None)
            continue
        answer, rtt, _ = t.ping()
        round_trips.append(None if answer is None else rtt)
        t.sleep(0.002)
    return round_trips


def commands_applied(t: Tester) -> list[tuple[str, bool]]:
    """Rule 8 and the basis of every probe: a command drives, STOP stops without latching."""
    t.drive()
    checks = [("a command drives the car", t.moving())]
    t.stop()
    state = t.state()
    checks.append(("STOP holds it still, unlatched",
                   bool(state & CarState.STOPPED) and not state & CarState.E_STOP_LATCHED))
    t.drive()
    checks.append(("the next command drives it again", t.moving()))
    return checks


def restart_taken(t: Tester) -> list[tuple[str, bool]]:
    """Rule 4: a larger session is a restarted sender, taken at once whatever its seq."""
    t.drive()
    t.need(t.moving(), "a command did not drive the car")
    t.car.restart()
    t.stop()
    checks = [("a newer session's STOP is taken", not t.moving())]
    t.drive()
    checks.append(("its next command drives the car", t.moving()))
    return checks


def bad_mac_ignored(t: Tester) -> list[tuple[str, bool]]:
    """Rule 1: a datagram whose MAC does not verify is dropped, whatever it says."""
    forged = t.forger_key
    checks = [("PING (another key) unanswered", t.quiet_after(t.datagram(t.pings, Flags.PING, key=forged)))]
    t.drive()
    t.need(t.moving(), "a command did not drive the car")
    t.send(t.datagram(t.car, Flags.STOP, key=forged))
    checks.append(("STOP (another key)", t.moving()))
    t.stop()
    data = bytearray(t.datagram(t.car, Flags.NONE, t.options.speed_mps))
    data[-1] ^= 0x01  # one bit of the MAC
    t.send(bytes(data))
    checks.append(("command (one MAC bit flipped)", not t.moving()))
    t.send(t.datagram(t.operator, Flags.E_STOP | Flags.STOP, key=forged))
    checks.append(("E_STOP (another key)", not t.latched()))
    return checks


def replay_ignored(t: Tester) -> list[tuple[str, bool]]:
    """Rule 4: in a session only a larger seq is taken -- an older one or a repeat is dropped."""
    older = t.drive()
    t.need(t.moving(), "a command did not drive the car")
    t.stop()
    t.need(not t.moving(), "STOP did not stop the car")
    t.send(older)
    checks = [("an older command sent again", not t.moving())]
    last = t.stop(flags=Flags.STOP | Flags.RELEASE)
    t.send(t.datagram(t.car, Flags.E_STOP | Flags.STOP))
    t.need(t.latched(), "an E_STOP did not latch")
    t.send(last)  # taken again, its RELEASE would clear the e-stop
    checks.append(("the last datagram (a RELEASE) sent again", t.latched()))
    return checks


def older_session_refused(t: Tester) -> list[tuple[str, bool]]:
    """Rule 4: after a restart the older sessions of the source are refused, however long it is quiet."""
    before = t.car.session
    t.drive()
    t.need(t.moving(), "a command did not drive the car")
    t.car.restart()
    t.stop()
    t.need(not t.moving(), "a restarted sender's STOP was not taken")
    speed = t.options.speed_mps
    t.send(t.datagram(t.car, Flags.NONE, speed, session=before, seq=1000))
    checks = [("the session before the restart, a new seq", not t.moving())]
    t.send(t.datagram(t.car, Flags.NONE, speed, session=before - 1, seq=0))
    checks.append(("an older session", not t.moving()))
    silence = t.options.resync_s + 0.1
    t.sleep(silence)
    t.send(t.datagram(t.car, Flags.NONE, speed, session=before, seq=1001))
    checks.append((f"the old session after {silence:.1f} s of silence", not t.moving()))
    return checks


def watchdog_samples(t: Tester) -> list[tuple[float, bool]]:
    """Rule 6: one command, then a PING every 2 ms: (ms since the command was sent, stopped),
    until the first stopped or 4 watchdog periods. PINGs must not feed the watchdog (rule 3)."""
    sent = t.send(t.datagram(t.car, Flags.NONE, t.options.speed_mps))
    samples: list[tuple[float, bool]] = []
    deadline = sent + 4 * t.options.watchdog_ms / 1000.0
    while time.monotonic() < deadline and not (samples and samples[-1][1]):
        answer, _, asked = t.ping()
        if answer is not None:
            samples.append(((asked - sent) * 1000.0, bool(answer.state & CarState.STOPPED)))
        t.sleep(0.002)
    if not samples:
        raise Unobservable("no PING answered")
    return samples


def e_stop_latched(t: Tester) -> list[tuple[str, bool]]:
    """Rules 2 and 7: the operator's E_STOP holds until the operator's own RELEASE."""
    t.drive()
    t.need(t.moving(), "a command did not drive the car")
    answer, _, _ = t.ping(Flags.E_STOP | Flags.STOP | Flags.PING, stream=t.operator)
    checks = [("the answer to the E_STOP says latched", answer is not None and answer.e_stop_latched)]
    for _ in range(5):
        t.drive()
    state = t.state()
    checks.append(("held through 5 commands of source 0",
                   bool(state & CarState.E_STOP_LATCHED and state & CarState.STOPPED)))
    t.stop(flags=Flags.STOP | Flags.RELEASE)
    t.drive()
    checks.append(("held through source 0's RELEASE", t.latched()))
    t.stop(t.operator)
    answer, _, _ = t.ping(Flags.PING | Flags.RELEASE, stream=t.operator)
    checks.append(("held through its source's STOP and PING|RELEASE", answer is not None and answer.e_stop_latched))
    silence = (t.options.watchdog_ms + 100.0) / 1000.0
    t.sleep(silence)
    checks.append((f"held through {silence:.2f} s of silence", t.latched()))
    t.operator.restart()
    t.stop(t.operator, Flags.STOP | Flags.RELEASE)
    checks.append(("released by its source's RELEASE", not t.latched()))
    t.drive()
    checks.append(("the car drives after it", t.moving()))
    return checks


def e_stop_any_session(t: Tester) -> list[tuple[str, bool]]:
    """Rule 2: an E_STOP latches whatever its session or seq."""
    older = t.operator.session
    t.operator.restart()
    t.stop(t.operator)  # the operator's newest session now
    t.send(t.datagram(t.operator, Flags.E_STOP | Flags.STOP, session=older, seq=0))
    checks = [("of an older session of its source", t.latched())]
    t.reset()
    for _ in range(3):
        t.drive()
    t.send(t.datagram(t.car, Flags.E_STOP | Flags.STOP, seq=0))
    checks.append(("with a seq long past", t.latched()))
    return checks


def ping_not_applied(t: Tester) -> list[tuple[str, bool]]:
    """Rule 3: a PING is answered and touches nothing: not the command, the seq, the session."""
    speed = t.options.speed_mps
    seq = t.car.take()
    answer, _, _ = t.ping(Flags.PING, stream=t.car, v=speed, seq=seq)
    t.need(answer is not None, "a PING went unanswered")
    checks = [("a PING with a speed does not drive the car", bool(answer.state & CarState.STOPPED))]
    t.send(t.datagram(t.car, Flags.NONE, speed, seq=seq))
    checks.append(("the PING's seq is still free for a command", t.moving()))
    t.stop()
    answer, _, _ = t.ping(Flags.PING, stream=t.car, session=new_session(), seq=0)
    t.need(answer is not None, "a PING went unanswered")
    t.drive()
    checks.append(("a PING of a newer session leaves the session", t.moving()))
    return checks


def other_car_ignored(t: Tester) -> list[tuple[str, bool]]:
    """Rule 1: datagrams for another car id are dropped (sealed with this car's key: only the id
    check can drop them)."""
    other = t.options.car_id % 255 + 1
    t.send(t.datagram(t.operator, Flags.E_STOP | Flags.STOP, car_id=other))
    checks = [(f"E_STOP for car {other}", not t.latched())]
    t.send(t.datagram(t.car, Flags.NONE, t.options.speed_mps, car_id=other))
    checks.append((f"command for car {other}", not t.moving()))
    checks.append((f"PING for car {other} unanswered", t.quiet_after(t.datagram(t.pings, Flags.PING, car_id=other))))
    return checks


def malformed_ignored(t: Tester) -> list[tuple[str, bool]]:
    """Rule 1 (codec.py): authentic but malformed datagrams, and version 1, are dropped."""
    checks: list[tuple[str, bool]] = []
    e_stop = Flags.E_STOP | Flags.STOP

    def not_latching(what: str, data: bytes) -> None:
        t.send(data)
        checks.append((what, not t.latched()))
        if not checks[-1][1]:
            t.reset()

    def not_driving(what: str, **fields: float) -> None:
        v = fields.pop("v", t.options.speed_mps)
        t.send(t.datagram(t.car, Flags.NONE, v, **fields))  # type: ignore[arg-type]
        checks.append((what, not t.moving()))
        if not checks[-1][1]:
            t.stop()

    not_latching("E_STOP, reserved byte 1", t.datagram(t.operator, e_stop, reserved=1))
    not_latching("E_STOP, a reserved flag bit", t.datagram(t.operator, e_stop | 0x0010))
    not_latching("E_STOP with RELEASE", t.datagram(t.operator, Flags.E_STOP | Flags.RELEASE))
    not_latching("E_STOP, car id 0", t.datagram(t.operator, e_stop, car_id=0))
    not_latching("E_STOP, magic TX", t.datagram(t.operator, e_stop, magic=b"TX"))
    not_latching("E_STOP, version 3", t.datagram(t.operator, e_stop, version=3))
    whole = t.datagram(t.operator, e_stop)
    not_latching("E_STOP, one byte longer", whole + b"\0")
    not_latching("E_STOP, one byte shorter", whole[:-1])
    car_id = t.options.car_id
    not_latching("E_STOP, version 1", command_datagram(None, car_id, 0, time.time(), 0.0, 0.0, e_stop))
    checks.append(("PING, version 1: unanswered",
                   t.quiet_after(command_datagram(None, car_id, 1, time.time(), 0.0, 0.0, Flags.PING))))
    not_driving("command, v NaN", v=math.nan)
    not_driving("command, omega infinite", omega=math.inf)
    not_driving("command, stamp infinite", stamp=math.inf)
    return checks

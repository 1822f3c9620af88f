"""The fleet bus: one Zenoh session per process, its publishers and subscribers, and queues.

What is published under which key, and how reliably, is fleet.bus.key_exprs' table; the
zenoh.Config the session opens with comes from fleet.bus.zenoh_setup.

Zenoh callbacks only hand ``(sender, kind, payload)`` to a bounded queue (the oldest is
dropped, and counted, when it is full) -- they never decode, block or call into the
agent. The owner drains the queue in its own loop and decodes there (agent.messages).
The sender id is taken from the key, so the decoder can refuse a message whose ``id``
disagrees with it. ``close()`` undeclares everything and closes the session; nothing in
here blocks on a Zenoh channel, so shutdown never hangs. ``drain()`` also watches: a kind
a live car is not heard on is subscribed again (:func:`silent_kinds`), and hearing no
live car at all for ``DEAF_S`` is told as a deaf spell.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass
from typing import Callable

import zenoh
import zenoh.ext as zext

from ...agent import messages
from ...agent.config import BusConfig
from .key_exprs import ALIVE, CLOCK, HEARTBEAT, KINDS, OPERATOR, START, STOP, every_car, fleet_key, key, parse_key
from .zenoh_setup import BusError, config_value, zenoh_config, zenoh_runtime_threads

log = logging.getLogger(__name__)

CLOSE_TIMEOUT_S = 2.0
WATCH_PERIOD_S = 0.5
SILENT_S = 3.0
"""With the control defaults a car publishes every kind at least every 0.5 s (status and
trust 0.5 s, plans 0.1 s, poses 0.05 s): three seconds without one is a lost subscription,
not a gap (a lab that sets slower periods pays a needless redeclaration now and then)."""
FREQUENT = ("plan", "pose")
BEHIND_S = 1.0
"""A car publishes plans every 0.1 s and poses every 0.05 s (control defaults), from its
first own pose on. One of them a second behind the car's other kinds is ten or more sent
and none heard: at 50 % loss, independent per packet, once in a thousand such seconds --
a lost subscription, not loss. (Trust reports and status come every 0.5 s: two missed
are common, so they wait for SILENT_S.)"""
RESUBSCRIBE_EVERY_S = 5.0
DEAF_S = 1.5
"""Nothing from any live car for this long is a deaf spell: every car publishes a pose
every 50 ms, so 1.5 s of nothing from all of them is the process, not the peers."""


def present(alive: dict[int, bool], heard: dict[tuple[int, str], float], now: float) -> dict[int, bool]:
    """Which cars are on the bus: those whose liveliness token is up, and those whose token
    never reached us but that were heard on some kind within ``SILENT_S``. Between two
    peers that both listen on TCP and UDP, Zenoh 1.10 now and then never delivers one's
    token to the other, though the other's samples arrive (docs/results/zenoh-liveliness.md);
    such a car is on the bus by what we hear of it, for as long as we hear it. A car whose
    token went down has left, whatever arrives late from it."""
    out = dict(alive)
    for (car, kind), at in heard.items():
        if kind in KINDS and car not in alive:  # a car's kinds: the operator (0) has no token
            out[car] = out.get(car, False) or now - at <= SILENT_S  # False: heard once, silent since
    return out


def silent_kinds(heard: dict[tuple[int, str], float], alive: dict[int, bool], kinds: tuple[str, ...],
                 now: float, opened: float, first: dict[int, float] | None = None,
                 frequent: tuple[str, ...] = FREQUENT) -> dict[str, list[int]]:
    """Per kind, the cars whose liveliness token is up but that were not heard on it for
    SILENT_S (counted from the session's opening for a car never heard on it), or -- a
    ``frequent`` kind -- that were heard on another kind BEHIND_S after they were last heard
    on it (or, never heard on it, after ``first[car]``: when they were first heard at all;
    a car only starting has no plan to send for its first few tenths of a second).

    The bus subscribes to such a kind again, at most every ``RESUBSCRIBE_EVERY_S``
    (counted: ``resubscribed_<kind>``). Peers that open their sessions to each other at
    once sometimes end with one of them never getting one kind from another, or nothing at
    all, though the other's liveliness token reached it and it reaches the other
    (benchmarks/bench_zenoh_start.py reproduces it). A frequent kind (plans, poses) is
    subscribed again sooner: at 50 % loss the redeclared subscription itself takes a second
    or two to reach the peer, which on top of SILENT_S would leave a car without a peer's
    plans for several seconds. A car that only stopped publishing K, or is cut off behind a
    partition, costs a redeclaration every few seconds, no more."""
    out: dict[str, list[int]] = {}
    first = first or {}
    for car, up in alive.items():
        if not up:
            continue
        latest = max((heard.get((car, kind), -math.inf) for kind in kinds), default=-math.inf)
        for kind in kinds:
            last = max(heard.get((car, kind), -math.inf), opened)
            silent = now - opened >= SILENT_S and now - last > SILENT_S
            behind = kind in frequent and latest - max(last, first.get(car, -math.inf)) > BEHIND_S
            if silent or behind:
                out.setdefault(kind, []).append(car)
    return out

@dataclass(frozen=True)
class Received:
    sender: int
    kind: str
    payload: bytes
    at: float
    """When it arrived (fleet clock)."""


LINKS_LISTED = 4
"""Up to this many links a warning lists one by one; more are counted by kind (a car of
a loopback fleet has two per peer, and a list of thirty addresses says nothing)."""


def links_said(links: list[tuple[str, str, bool]]) -> str:
    """The session's links, (local, remote, reliable), as a warning tells them."""
    if not links:
        return "none"
    said = [f"{dst}{'' if reliable else ' (best effort)'}" for _, dst, reliable in links]
    if len(said) <= LINKS_LISTED:
        return ", ".join(said)
    kinds = Counter(f"{dst.split('/', 1)[0]}{'' if reliable else ' best effort'}" for _, dst, reliable in links)
    return f"{len(links)} ({', '.join(f'{n} {kind}' for kind, n in sorted(kinds.items()))})"


class FleetBus:
    """One process's Zenoh presence. A car (``car_id``) publishes under its own keys and
    answers clock queries; an observer (``car_id=None``: dashboard, recorder, operator)
    listens, may send the operator's messages (start, stop, heartbeat) and query clocks.
    ``kinds`` are the car kinds received, ``operator_kinds`` the operator's."""

    def __init__(self, config: BusConfig, fleet: str, car_id: int | None = None, *,
                 listen: tuple[str, ...] = (), kinds: tuple[str, ...] = KINDS,
                 operator_kinds: tuple[str, ...] = OPERATOR, clock: Callable[[], float] = time.time):
        self.config = config
        self.fleet = fleet
        self.car_id = car_id
        self.kinds = kinds
        self.operator_kinds = operator_kinds
        self.clock = clock
        self._listen = listen
        self._queue: deque[Received] = deque()
        self._lock = threading.Lock()
        self._arrived = threading.Event()
        self.counters: Counter = Counter()
        self.alive: dict[int, bool] = {}
        """Liveliness of every car process seen: True while its token is up (see
        :meth:`on_bus` for the cars whose token never reached us)."""
        self._session: zenoh.Session | None = None
        self._publishers: dict[str, object] = {}
        self._reliable_plan = None
        self._entities: list = []
        self._subscribers: dict[str, object] = {}
        """The car kinds' subscribers, by kind (declared again when one goes silent)."""
        self._heard: dict[tuple[int, str], float] = {}
        self._first_heard: dict[int, float] = {}
        self._opened = math.inf
        self._next_watch = 0.0
        self._deaf_since: float | None = None
        self._resubscribed: dict[str, float] = {}

    # --- lifecycle -------------------------------------------------------------------------

    def __enter__(self) -> "FleetBus":
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def open(self) -> None:
        zenoh_runtime_threads()
        try:
            config = zenoh_config(self.config, self._listen)
            self._session = zenoh.open(config)
        except BusError:
            raise
        except Exception as exc:
            raise BusError(f"cannot open a Zenoh session: {exc}") from exc
        session = self._session
        fleet = self.fleet
        listening = config_value(config, "listen/endpoints")
        if isinstance(listening, list) and listening:
            log.info("%s: Zenoh listening on %s", f"car {self.car_id}" if self.car_id else "operator/observer",
                     ", ".join(listening))
        if self.car_id is not None:
            cid = self.car_id
            # Plans go two ways. Best effort (on a UDP link, ``?rel=0``, where the peers have
            # one), repeated every control.plan_period_s: a lost plan is replaced by the next
            # instead of retransmitted, which over TCP at heavy loss would hold every later plan
            # back for seconds. And reliable, each new plan once, through an advanced publisher
            # with a cache of 1: late joiners and peers back from a partition get the latest at
            # once, not seconds later. Whichever copy arrives first is taken; the other is
            # dropped by the Inbox as a repeat of its sequence number.
            self._publishers["plan"] = session.declare_publisher(
                key(fleet, cid, "plan"), reliability=zenoh.Reliability.BEST_EFFORT, express=True,
                congestion_control=zenoh.CongestionControl.DROP)
            self._reliable_plan = zext.declare_advanced_publisher(
                session, key(fleet, cid, "plan"), cache=zext.CacheConfig(max_samples=1),
                publisher_detection=True, sample_miss_detection=zext.MissDetectionConfig(heartbeat=0.5),
                reliability=zenoh.Reliability.RELIABLE, congestion_control=zenoh.CongestionControl.DROP)
            # Trust reports best effort too: each supersedes the last (every
            # control.trust_report_period_s), and at heavy loss a reliable report would wait
            # behind TCP retransmissions for seconds and arrive stale.
            self._publishers["trust"] = session.declare_publisher(
                key(fleet, cid, "trust"), reliability=zenoh.Reliability.BEST_EFFORT, express=True,
                congestion_control=zenoh.CongestionControl.DROP)
            self._publishers["pose"] = session.declare_publisher(
                key(fleet, cid, "pose"), reliability=zenoh.Reliability.BEST_EFFORT, express=True,
                congestion_control=zenoh.CongestionControl.DROP)
            self._publishers["status"] = session.declare_publisher(
                key(fleet, cid, "status"), reliability=zenoh.Reliability.BEST_EFFORT,
                congestion_control=zenoh.CongestionControl.DROP)
            self._entities.append(session.liveliness().declare_token(key(fleet, cid, ALIVE)))
            self._entities.append(session.declare_queryable(key(fleet, cid, CLOCK), self._on_clock_query))
        else:
            for name in (START, STOP):  # cached: a car process that joins late gets the latest
                self._publishers[name] = zext.declare_advanced_publisher(
                    session, fleet_key(fleet, name), cache=zext.CacheConfig(max_samples=1), publisher_detection=True,
                    sample_miss_detection=zext.MissDetectionConfig(heartbeat=0.5))
            self._publishers[HEARTBEAT] = session.declare_publisher(
                fleet_key(fleet, HEARTBEAT), congestion_control=zenoh.CongestionControl.DROP)
        for kind in self.kinds:
            self._subscribers[kind] = self._subscribe(kind)
        self._opened = self.clock()
        for name in self.operator_kinds:
            if name == HEARTBEAT:
                self._entities.append(session.declare_subscriber(fleet_key(fleet, name), self._on_sample))
            else:
                # The latest start or stop from the publisher's cache when it is found, and again
                # whenever its heartbeat (every 0.5 s) tells of one we missed: the start is put
                # once, and a car whose history query came before the put would otherwise never
                # get it.
                self._entities.append(zext.declare_advanced_subscriber(
                    session, fleet_key(fleet, name), self._on_sample,
                    history=zext.HistoryConfig(detect_late_publishers=True, max_samples=1),
                    recovery=zext.RecoveryConfig(heartbeat=True)))
        self._entities.append(session.liveliness().declare_subscriber(
            every_car(fleet, ALIVE), self._on_liveliness, history=True))

    def _subscribe(self, kind: str):
        pattern = every_car(self.fleet, kind)
        if kind == "plan":
            return zext.declare_advanced_subscriber(
                self._session, pattern, self._on_sample,
                history=zext.HistoryConfig(detect_late_publishers=True, max_samples=1),
                recovery=zext.RecoveryConfig(heartbeat=True), subscriber_detection=True)
        return self._session.declare_subscriber(pattern, self._on_sample)

    def _watch(self, now: float) -> None:
        """Declare again the subscription of a kind a live car is not heard on (see above)."""
        if now < self._next_watch or self._session is None:
            return
        self._next_watch = now + WATCH_PERIOD_S
        with self._lock:  # the callbacks' threads write them
            heard, tokens, first = dict(self._heard), dict(self.alive), dict(self._first_heard)
        alive = present(tokens, heard, now)
        self.counters["peers_without_token"] = sum(1 for car in alive if car not in tokens)
        if self.car_id is not None:
            alive[self.car_id] = False  # never watch ourselves
        self._watch_deafness(heard, alive, now)
        silent = silent_kinds(heard, alive, self.kinds, now, self._opened, first)
        for kind, cars in silent.items():
            if now - self._resubscribed.get(kind, -math.inf) < RESUBSCRIBE_EVERY_S:
                continue
            self._resubscribed[kind] = now
            # Lost (heard on K before) is worth a warning; never heard since the session
            # opened is most often a car still starting up. A car silent on every kind may
            # have no link to us at all, which no redeclaration mends: say our links.
            lost = [car for car in cars if (car, kind) in heard]
            quiet_s = max(now - max(heard.get((car, kind), -math.inf), self._opened) for car in cars)
            on_nothing = [car for car in cars if all(car in silent.get(k, ()) for k in self.kinds)]
            log.log(logging.WARNING if lost else logging.INFO,
                    "%s: no %s from car%s %s for %.1f s, though %s token is up: subscribing to %s again%s",
                    self._me, kind, "s" if len(cars) > 1 else "",
                    ", ".join(map(str, cars)), quiet_s, "their" if len(cars) > 1 else "its", kind,
                    f" (car{'s' if len(on_nothing) > 1 else ''} {', '.join(map(str, on_nothing))} heard on "
                    f"nothing; links: {self._links_said()})" if on_nothing else "")
            self.subscribe_again(kind)

    def subscribe_again(self, kind: str) -> None:
        """Declare the subscription of car kind ``kind`` anew (counted: ``resubscribed_<kind>``):
        the mend for a declaration Zenoh lost on the way to a peer (see :func:`silent_kinds`)."""
        try:
            self._subscribers[kind].undeclare()
        except Exception as exc:  # already gone: declare anew all the same
            log.debug("undeclare %s: %s", kind, exc)
        try:
            self._subscribers[kind] = self._subscribe(kind)
            self.counters[f"resubscribed_{kind}"] += 1
        except Exception as exc:  # a closing session: nothing to watch any more
            log.warning("subscribing to %s again failed: %s", kind, exc)

    def _watch_deafness(self, heard: dict[tuple[int, str], float], alive: dict[int, bool], now: float) -> None:
        """Nothing from any live car for DEAF_S: a deaf spell, counted (``deaf_spells``,
        ``deaf_ms_max``) and told with the session's links when it starts and ends. It is
        what stalls a whole process's receiving, not one subscription, as Zenoh's lingering
        TCP closes can (fleet.bus.zenoh_setup.RX_THREADS)."""
        last = max([self._opened, *(at for (car, _), at in heard.items() if car in alive)])  # cars, not the operator
        up = sum(alive.values())
        if up and now - last > DEAF_S and self._deaf_since is None:
            self._deaf_since = last
            self.counters["deaf_spells"] += 1
            log.warning("%s: heard nothing from any car for %.1f s, though %d token%s up; links: %s",
                        self._me, now - last, up, "s are" if up > 1 else " is", self._links_said())
        elif self._deaf_since is not None and now - last <= DEAF_S:
            spell_ms = round((last - self._deaf_since) * 1e3)
            self.counters["deaf_ms_max"] = max(self.counters["deaf_ms_max"], spell_ms)
            log.warning("%s: hears cars again after %.1f s of nothing; links: %s", self._me, spell_ms / 1e3,
                        self._links_said())
            self._deaf_since = None

    @property
    def _me(self) -> str:
        return f"car {self.car_id}" if self.car_id else "observer"

    def _links_said(self) -> str:
        try:
            return links_said(self.links())
        except Exception as exc:  # noqa: BLE001 -- a closing session
            return f"unknown ({exc})"

    def close(self, timeout_s: float = CLOSE_TIMEOUT_S) -> None:
        """Undeclare everything and close the session, giving up after ``timeout_s``:
        on a lossy network Zenoh may wait long for its peers, and a stopping car process
        must not hang on that (the OS closes the sockets when the process ends)."""
        session, self._session = self._session, None
        if session is None:
            return
        entities = [*self._subscribers.values(), *self._entities, *self._publishers.values(),
                    *([self._reliable_plan] if self._reliable_plan is not None else [])]
        self._subscribers.clear()
        self._entities.clear()
        self._publishers.clear()
        self._reliable_plan = None

        def close_all() -> None:
            for entity in entities:
                try:
                    entity.undeclare()
                except Exception as exc:  # already gone with the session: nothing to do
                    log.debug("undeclare: %s", exc)
            try:
                session.close()
            except Exception as exc:  # Zenoh gives up after 10 s of its own (a peer that stopped reading)
                self.counters["close_failed"] += 1
                log.warning("closing the Zenoh session: %s", exc)

        closer = threading.Thread(target=close_all, name="zenoh-close", daemon=True)
        closer.start()
        closer.join(timeout_s)
        if closer.is_alive():
            self.counters["close_timed_out"] += 1
            log.warning("the Zenoh session did not close within %.1f s; leaving it to the OS", timeout_s)

    def links(self) -> list[tuple[str, str, bool]]:
        """(local, remote, reliable) of every Zenoh link this session has now."""
        if self._session is None:
            return []
        return [(str(link.src), str(link.dst), link.reliability == zenoh.Reliability.RELIABLE)
                for link in self._session.info.links()]

    # --- sending ---------------------------------------------------------------------------

    def publish(self, kind: str, payload: bytes, *, repeat: bool = False) -> None:
        """Publish one of our own messages (kind in KINDS, or the operator's for an observer).
        A new plan goes best effort and reliably; a ``repeat`` of the latest, best effort only."""
        publisher = self._publishers.get(kind)
        if publisher is None:
            raise BusError(f"this bus cannot publish {kind!r} (car_id={self.car_id})")
        try:
            publisher.put(payload)
            if kind == "plan" and not repeat and self._reliable_plan is not None:
                self._reliable_plan.put(payload)
            self.counters[f"sent_{kind}"] += 1
        except Exception as exc:  # a closed session or a full queue must not kill the loop
            self.counters[f"send_failed_{kind}"] += 1
            log.warning("publishing %s failed: %s", kind, exc)

    # --- receiving (callbacks: never block) ----------------------------------------------------

    def _on_sample(self, sample: zenoh.Sample) -> None:
        parsed = parse_key(self.fleet, str(sample.key_expr))
        if parsed is None:
            self.counters["bad_key"] += 1
            return
        sender, kind = parsed
        if self.car_id is not None and sender == self.car_id:
            return  # our own message
        item = Received(sender, kind, sample.payload.to_bytes(), self.clock())
        with self._lock:
            if len(self._queue) >= self.config.queue_size:
                self._queue.popleft()
                self.counters["dropped_queue_full"] += 1
            self._queue.append(item)
            self._heard[(sender, kind)] = item.at
            self._first_heard.setdefault(sender, item.at)
            self.counters[f"received_{kind}"] += 1
        self._arrived.set()

    def _on_clock_query(self, query: zenoh.Query) -> None:
        """A car's clock, to the operator's query (never blocks: encode and reply)."""
        try:
            query.reply(query.key_expr, messages.encode(messages.ClockMessage(self.car_id, 0, self.clock())))
            self.counters["clock_queries"] += 1
        except Exception as exc:  # the asker may be gone already
            log.debug("clock reply failed: %s", exc)

    def query_clocks(self, car_id: int, timeout_s: float = 0.5) -> tuple[float, float, float] | None:
        """Ask car ``car_id``'s process for its clock: (sent, its clock, received) on our
        clock, or None if it did not answer in time. Blocks up to ``timeout_s``."""
        if self._session is None:
            raise BusError("the bus is not open")
        sent = self.clock()
        try:
            for reply in self._session.get(key(self.fleet, car_id, CLOCK), timeout=timeout_s):
                received = self.clock()
                if reply.ok is None:
                    continue
                answer = messages.decode(reply.ok.payload.to_bytes())
                if isinstance(answer, messages.ClockMessage) and answer.sender == car_id:
                    return sent, answer.stamp, received
        except messages.MessageError:
            self.counters["bad_clock_replies"] += 1
        except Exception as exc:  # a closed session, a refused query
            log.debug("clock query to car %d failed: %s", car_id, exc)
        return None

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        parsed = parse_key(self.fleet, str(sample.key_expr))
        if parsed is None or parsed[1] != ALIVE:
            return
        up = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            if up and self.alive.get(parsed[0]) is False:  # back, a new process: it starts its kinds anew
                self._first_heard.pop(parsed[0], None)
            self.alive[parsed[0]] = up
        self.counters["liveliness_up" if up else "liveliness_down"] += 1

    def on_bus(self) -> dict[int, bool]:
        """Every car seen: whether it is on the bus now (:func:`present`: its token is up,
        or, its token never having reached us, it was heard lately)."""
        with self._lock:
            return present(dict(self.alive), dict(self._heard), self.clock())

    def wait(self, timeout: float) -> bool:
        """Until something arrives or ``timeout`` passes; whether something is waiting."""
        arrived = self._arrived.wait(timeout)
        self._arrived.clear()
        return arrived or bool(self._queue)

    def drain(self, limit: int | None = None) -> list[Received]:
        """Everything received since the last drain (oldest first); and, every
        WATCH_PERIOD_S, a subscription lost to Zenoh declared again (see above)."""
        self._watch(self.clock())
        with self._lock:
            if limit is None or limit >= len(self._queue):
                items = list(self._queue)
                self._queue.clear()
            else:
                items = [self._queue.popleft() for _ in range(limit)]
        return items

"""The fleet bus: one Zenoh session per process, its publishers and subscribers, and queues.

What is published under which key, and how reliably, is fleet.keys' table.

Zenoh callbacks only hand ``(sender, kind, payload)`` to a bounded queue (the oldest is
dropped, and counted, when it is full) -- they never decode, block or call into the
agent. The owner drains the queue in its own loop and decodes there (agent.messages).
The sender id is taken from the key, so the decoder can refuse a message whose ``id``
disagrees with it. ``close()`` undeclares everything and closes the session; nothing in
here blocks on a Zenoh channel, so shutdown never hangs.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import zenoh
import zenoh.ext as zext

from ..agent.config import BusConfig
from .keys import ALIVE, KINDS, START, every_car, fleet_key, key, parse_key

log = logging.getLogger(__name__)

CLOSE_TIMEOUT_S = 2.0


class BusError(RuntimeError):
    """The Zenoh session could not be opened or configured."""


def zenoh_config(bus: BusConfig, extra_listen: tuple[str, ...] = ()) -> zenoh.Config:
    """A zenoh.Config from our BusConfig (on top of ``bus.zenoh_config`` if given)."""
    try:
        config = zenoh.Config.from_file(str(Path(bus.zenoh_config))) if bus.zenoh_config else zenoh.Config()
        config.insert_json5("mode", json.dumps(bus.mode))
        listen = [*bus.listen, *extra_listen]
        if listen:
            config.insert_json5("listen/endpoints", json.dumps(listen))
        connect = [e for e in bus.connect if e not in listen]  # a fleet-wide list may name us
        if connect:
            config.insert_json5("connect/endpoints", json.dumps(connect))
        config.insert_json5("scouting/multicast/enabled", json.dumps(bus.multicast_scouting))
        config.insert_json5("transport/unicast/max_links", json.dumps(bus.max_links))
        if bus.multicast_interface:
            config.insert_json5("scouting/multicast/interface", json.dumps(bus.multicast_interface))
    except Exception as exc:  # zenoh raises ZError and others for bad files or values
        raise BusError(f"bad Zenoh configuration: {exc}") from exc
    return config


@dataclass(frozen=True)
class Received:
    sender: int
    kind: str
    payload: bytes
    at: float
    """When it arrived (fleet clock)."""


class FleetBus:
    """One process's Zenoh presence. A car (``car_id``) publishes under its own keys; an
    observer (``car_id=None``: dashboard, recorder, operator) only listens and may send
    the start message."""

    def __init__(self, config: BusConfig, fleet: str, car_id: int | None = None, *,
                 listen: tuple[str, ...] = (), kinds: tuple[str, ...] = KINDS,
                 clock: Callable[[], float] = time.time):
        self.config = config
        self.fleet = fleet
        self.car_id = car_id
        self.kinds = kinds
        self.clock = clock
        self._listen = listen
        self._queue: deque[Received] = deque()
        self._lock = threading.Lock()
        self._arrived = threading.Event()
        self.counters: Counter = Counter()
        self.alive: dict[int, bool] = {}
        """Liveliness of every car process seen: True while its token is up."""
        self._session: zenoh.Session | None = None
        self._publishers: dict[str, object] = {}
        self._reliable_plan = None
        self._entities: list = []

    # --- lifecycle -------------------------------------------------------------------------

    def __enter__(self) -> "FleetBus":
        self.open()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def open(self) -> None:
        try:
            self._session = zenoh.open(zenoh_config(self.config, self._listen))
        except BusError:
            raise
        except Exception as exc:
            raise BusError(f"cannot open a Zenoh session: {exc}") from exc
        session = self._session
        fleet = self.fleet
        if self.car_id is not None:
            cid = self.car_id
            # Plans go two ways. Best effort (on a UDP link, ``?rel=0``, where the peers have
            # one), repeated every control.plan_period_s: a lost plan is replaced by the next
            # instead of retransmitted, which over TCP at heavy loss held every later plan back
            # for seconds. And reliable, each new plan once, through an advanced publisher with
            # a cache of 1: late joiners and peers back from a partition get the latest at once
            # (the best-effort path alone took seconds to resume). Whichever copy arrives first
            # is taken; the other is dropped by the Inbox as a repeat of its sequence number.
            self._publishers["plan"] = session.declare_publisher(
                key(fleet, cid, "plan"), reliability=zenoh.Reliability.BEST_EFFORT, express=True,
                congestion_control=zenoh.CongestionControl.DROP)
            self._reliable_plan = zext.declare_advanced_publisher(
                session, key(fleet, cid, "plan"), cache=zext.CacheConfig(max_samples=1),
                publisher_detection=True, sample_miss_detection=zext.MissDetectionConfig(heartbeat=0.5),
                reliability=zenoh.Reliability.RELIABLE, congestion_control=zenoh.CongestionControl.DROP)
            self._publishers["trust"] = session.declare_publisher(
                key(fleet, cid, "trust"), reliability=zenoh.Reliability.RELIABLE)
            self._publishers["pose"] = session.declare_publisher(
                key(fleet, cid, "pose"), reliability=zenoh.Reliability.BEST_EFFORT, express=True,
                congestion_control=zenoh.CongestionControl.DROP)
            self._publishers["status"] = session.declare_publisher(
                key(fleet, cid, "status"), reliability=zenoh.Reliability.BEST_EFFORT,
                congestion_control=zenoh.CongestionControl.DROP)
            self._entities.append(session.liveliness().declare_token(key(fleet, cid, ALIVE)))
        else:
            self._publishers[START] = zext.declare_advanced_publisher(
                session, fleet_key(fleet, START), cache=zext.CacheConfig(max_samples=1), publisher_detection=True,
                sample_miss_detection=zext.MissDetectionConfig(heartbeat=0.5))
        for kind in self.kinds:
            pattern = every_car(fleet, kind)
            if kind == "plan":
                subscriber = zext.declare_advanced_subscriber(
                    session, pattern, self._on_sample,
                    history=zext.HistoryConfig(detect_late_publishers=True, max_samples=1),
                    recovery=zext.RecoveryConfig(heartbeat=True), subscriber_detection=True)
            else:
                subscriber = session.declare_subscriber(pattern, self._on_sample)
            self._entities.append(subscriber)
        self._entities.append(zext.declare_advanced_subscriber(
            session, fleet_key(fleet, START), self._on_sample,
            history=zext.HistoryConfig(detect_late_publishers=True, max_samples=1)))
        self._entities.append(session.liveliness().declare_subscriber(
            every_car(fleet, ALIVE), self._on_liveliness, history=True))

    def close(self, timeout_s: float = CLOSE_TIMEOUT_S) -> None:
        """Undeclare everything and close the session, giving up after ``timeout_s``:
        on a lossy network Zenoh may wait long for its peers, and a stopping car process
        must not hang on that (the OS closes the sockets when the process ends)."""
        session, self._session = self._session, None
        if session is None:
            return
        entities = [*self._entities, *self._publishers.values(),
                    *([self._reliable_plan] if self._reliable_plan is not None else [])]
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
            except Exception as exc:
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
        """Publish one of our own messages (kind in KINDS, or "start" for an observer). A new
        plan goes best effort and reliably; a ``repeat`` of the latest, best effort only."""
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
            self.counters[f"received_{kind}"] += 1
        self._arrived.set()

    def _on_liveliness(self, sample: zenoh.Sample) -> None:
        parsed = parse_key(self.fleet, str(sample.key_expr))
        if parsed is None or parsed[1] != ALIVE:
            return
        up = sample.kind == zenoh.SampleKind.PUT
        self.alive[parsed[0]] = up
        self.counters["liveliness_up" if up else "liveliness_down"] += 1

    def wait(self, timeout: float) -> bool:
        """Until something arrives or ``timeout`` passes; whether something is waiting."""
        arrived = self._arrived.wait(timeout)
        self._arrived.clear()
        return arrived or bool(self._queue)

    def drain(self, limit: int | None = None) -> list[Received]:
        """Everything received since the last drain (oldest first)."""
        with self._lock:
            if limit is None or limit >= len(self._queue):
                items = list(self._queue)
                self._queue.clear()
            else:
                items = [self._queue.popleft() for _ in range(limit)]
        return items

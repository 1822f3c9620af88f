"""The operator's hold on a fleet: heartbeat, trials, and the stop on two independent paths.

Every operator's session (``trustfg go``, the dashboard in operator mode, the launcher of
``trustfg sim``) and the one-shot ``trustfg stop`` use these pieces:

* :class:`~.estop_direct.LinkStopper` -- the direct path: E_STOP datagrams straight to
  each car's ``link``, needing no car process (fleet.operator.estop_direct).
* :class:`OperatorSession` -- the bus path and the rest: the heartbeat the cars' deadman
  listens for, trials (the next id after every one the cars report), e-stops, releases and
  aborts on the bus beside the direct path; it learns the cars' states from the status
  messages its owner hands it (:meth:`OperatorSession.heard`).

A release ends this session's e-stop repeats first, then goes both ways. How releases and
another session's repeats meet: docs/design/architecture.md, "The operator's tools".
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Callable, Iterable

from ...agent import messages
from ...agent.config import Scenario
from ..bus.session import FleetBus
from .estop_direct import LinkStopper, named

log = logging.getLogger(__name__)

@dataclass
class CarSeen:
    """What the operator knows of a car process from its status messages."""

    state: str = ""
    trial: int = 0
    at_goal: bool = False
    heard_at: float = -math.inf
    counters: dict = field(default_factory=dict)


class OperatorSession:
    """The operator on the bus (and the links); see the module docstring. The owner drains
    ``bus`` and hands every decoded message to :meth:`heard`, and calls :meth:`step`
    often (at least every ``operator.heartbeat_period_s``)."""

    def __init__(self, fleet: Scenario, bus: FleetBus, *, direct: bool = True,
                 clock: Callable[[], float] = time.time):
        self.fleet = fleet
        self.bus = bus
        self.clock = clock
        self.stopper = LinkStopper(fleet, clock) if direct else None
        self.cars: dict[int, CarSeen] = {c.id: CarSeen() for c in fleet.cars}
        self._next_heartbeat = -math.inf
        self.log: list[tuple[float, str]] = []
        """What this session did: (time, what)."""

    # --- what it hears and keeps up -----------------------------------------------------

    def heard(self, message: messages.Message, at: float) -> None:
        if isinstance(message, messages.StatusMessage) and message.sender in self.cars:
            self.cars[message.sender] = CarSeen(message.state, message.trial, message.at_goal, at,
                                                dict(message.counters))

    def step(self, now: float | None = None) -> None:
        now = self.clock() if now is None else now
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + self.fleet.operator.heartbeat_period_s
            self.bus.publish("heartbeat", messages.encode(messages.HeartbeatMessage(messages.operator_seq(now), now)))
        if self.stopper is not None:
            self.stopper.step(now)

    def alive(self) -> list[int]:
        """Car processes on the bus now: their liveliness token is up, or it never reached
        us but we hear them (fleet.bus.session.present)."""
        return sorted(car for car, up in self.bus.on_bus().items() if up and car in self.cars)

    # --- what it says -------------------------------------------------------------------

    def next_trial(self) -> int:
        return 1 + max((seen.trial for seen in self.cars.values()), default=0)

    def start(self, departures: dict[int, tuple[float, float]], trial: int | None = None) -> int:
        """Publish the start of a trial (the next one unless given); its id."""
        now = self.clock()
        trial = self.next_trial() if trial is None else trial
        self.step(now)  # a heartbeat first: with the deadman on, a car takes no start without
        self.bus.publish("start", messages.encode(messages.StartMessage(messages.operator_seq(now), now, trial,
                                                                        departures)))
        self._did(now, f"start of trial {trial}: cars {' '.join(map(str, sorted(departures)))}")
        return trial

    def estop(self, cars: Iterable[int] = ()) -> None:
        """E-stop on both paths: straight to the links first, then the bus."""
        now = self.clock()
        chosen = named(self.fleet, cars)
        if self.stopper is not None:
            self.stopper.engage(chosen, now)
        self._publish_stop("estop", cars, now)

    def release(self, cars: Iterable[int] = ()) -> None:
        """Release on both paths: this session's e-stop repeats to those cars end, the
        operator's RELEASE goes to the links, and the release on the bus."""
        now = self.clock()
        if self.stopper is not None:
            self.stopper.release(named(self.fleet, cars), now)
        self._publish_stop("release", cars, now)

    def abort(self, cars: Iterable[int] = (), trial: int = 0) -> None:
        self._publish_stop("abort", cars, self.clock(), trial)

    def _publish_stop(self, action: str, cars: Iterable[int], now: float, trial: int = 0) -> None:
        cars = tuple(cars)
        named(self.fleet, cars)
        self.bus.publish("stop", messages.encode(messages.StopMessage(messages.operator_seq(now), now, action, cars,
                                                                      trial)))
        self._did(now, f"{action}: {'cars ' + ' '.join(map(str, cars)) if cars else 'every car'}")

    def _did(self, now: float, what: str) -> None:
        self.log.append((now, what))
        log.info("operator: %s", what)

    def close(self) -> None:
        if self.stopper is not None:
            self.stopper.close()

"""The e-stop's direct path: E_STOP datagrams straight to each car's link, no car process needed.

The operator's tools send as the operator's source (``SOURCE_OPERATOR``), with the car's
key on an authenticated (version 2) link. A car latches an E_STOP whatever its sequence
number or session (bridge.carlink.receiver, rule 2), so these datagrams work beside a car
process's own stream, without one, or with one that is hung. :class:`LinkStopper` repeats
the E_STOP for ``repeat_s`` (Wi-Fi loses datagrams), PINGs, and reads the answers, which
only inform. A car latches per source and only that source's in-session RELEASE clears
it (rule 7), so a release goes this way too, in a new session of its own. On a version-1
link the operator sends only E_STOP and PING (rule 5); the car process releases there.
This module imports nothing heavy: no Zenoh, no numpy, not even the typed config.
"""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING, Callable, Iterable

from ...bridge.carlink import E_STOP_FLAGS, SOURCE_OPERATOR, Answer, CommandSender, Flags, link_key
from ...bridge.carlink.direct import resolve
from .estop_first import DIRECT_REPEAT_S

if TYPE_CHECKING:
    from ...agent.config import Scenario

log = logging.getLogger(__name__)

def named(fleet: "Scenario", cars: Iterable[int] = ()) -> list[int]:
    """The car ids a command names (none: every car); ValueError for an unknown one."""
    ids = [c.id for c in fleet.cars]
    chosen = list(cars) or ids
    unknown = sorted(set(chosen) - set(ids))
    if unknown:
        raise ValueError(f"no car {' '.join(map(str, unknown))} in this fleet (cars: {' '.join(map(str, ids))})")
    return chosen


def missing_paths(fleet: "Scenario") -> dict[int, str]:
    """Cars the direct path cannot reach from this machine, and why: no ``link``, an
    address that does not resolve, a key that does not read. Checked without a socket;
    ``trustfg go`` starts no trial while any is missing."""
    from ...agent.config import ConfigError, parse_udp_address

    missing = {}
    for car in fleet.cars:
        where = f"cars[id={car.id}].link"
        if not car.link:
            missing[car.id] = f"{where}: no address"
            continue
        try:
            resolve(parse_udp_address(car.link, where), passive=False)
            link_key(car)
        except ConfigError as exc:
            missing[car.id] = str(exc)
        except OSError as exc:
            missing[car.id] = f"{where} {car.link}: {exc.strerror or exc}"
    return missing


class LinkStopper:
    """E_STOP (and PING) datagrams straight to cars' links; see the module docstring."""

    def __init__(self, fleet: "Scenario", clock: Callable[[], float] = time.time):
        from ...agent.config import ConfigError

        self.clock = clock
        self.release_s = fleet.operator.release_s
        self.senders: dict[int, CommandSender] = {}
        self.unreachable: dict[int, str] = {}
        """Cars without a direct path, and why (their key does not read on this machine, an
        address that does not resolve): the bus path still stops them."""
        for car in fleet.cars:
            if not car.link:
                continue
            try:
                self.senders[car.id] = CommandSender.for_car(car, source=SOURCE_OPERATOR, stamp_clock=clock,
                                                             stop_repeats=0)
            except (ConfigError, OSError) as exc:  # a key that does not read, an address that does not resolve
                why = str(exc) if isinstance(exc, ConfigError) else f"cars[id={car.id}].link {car.link}: {exc}"
                self.unreachable[car.id] = why
                log.warning("no direct e-stop path to car %d: %s", car.id, why)
        self._until: dict[int, float] = {}
        self._release_until: dict[int, float] = {}
        self.answers: dict[int, Answer] = {}
        """The latest answer of each car."""
        self.answered_at: dict[int, float] = {}

    def engage(self, cars: Iterable[int], now: float, repeat_s: float = DIRECT_REPEAT_S) -> None:
        """E_STOP to every named car now, and again at every :meth:`step` for ``repeat_s``."""
        for car in cars:
            if car in self.senders:
                self._until[car] = now + repeat_s
                self.senders[car].send(0.0, 0.0, E_STOP_FLAGS)

    def cancel(self, cars: Iterable[int]) -> None:
        """Stop repeating the e-stop to the named cars (the operator released them: a
        repeat arriving after their RELEASE would latch them again)."""
        for car in cars:
            self._until.pop(car, None)

    def release(self, cars: Iterable[int], now: float) -> None:
        """Release the e-stops the operator sent straight to the named cars: end the
        repeats, then RELEASE (with STOP) in a new session, now and at every :meth:`step`
        for ``[operator] release_s`` (0.8 s: longer than another session's e-stop repeats,
        so none still in flight latches the car again). Version-1 links get none (see the
        module docstring)."""
        cars = list(cars)
        self.cancel(cars)
        for car in cars:
            sender = self.senders.get(car)
            if sender is not None and sender.version == 2:
                sender.renew_session()
                self._release_until[car] = now + self.release_s
                sender.send(0.0, 0.0, Flags.STOP | Flags.RELEASE)

    def ping(self, cars: Iterable[int]) -> None:
        """Ask the named cars for their state (a PING is never applied)."""
        for car in cars:
            if car in self.senders:
                self.senders[car].send(0.0, 0.0, Flags.STOP | Flags.PING)

    def step(self, now: float) -> None:
        """Repeat pending e-stops; read answers."""
        for car, until in list(self._until.items()):
            if now < until:
                self.senders[car].send(0.0, 0.0, E_STOP_FLAGS)
            else:
                del self._until[car]
        for car, until in list(self._release_until.items()):
            if now < until:
                self.senders[car].send(0.0, 0.0, Flags.STOP | Flags.RELEASE)
            else:
                del self._release_until[car]
        for car, sender in self.senders.items():
            for answer in sender.answers():
                self.answers[car] = answer
                self.answered_at[car] = now

    @property
    def busy(self) -> bool:
        return bool(self._until or self._release_until)

    def close(self) -> None:
        for sender in self.senders.values():
            sender.close()  # stop_repeats=0: it sends nothing on the way out
        self.senders.clear()


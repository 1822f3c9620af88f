"""The e-stop's direct path: E_STOP datagrams straight to each car's link, no car process needed.

A car latches an E_STOP whatever its sequence number (bridge.carlink.receiver, rule 2), so
the operator's datagrams work next to a car process's own stream -- or without one, or
with one that is hung or never heard the stop. :class:`LinkStopper` sends nothing but
E_STOP and PING (never an ordinary command, which would break into the car process's
sequence: rule 4), repeats the E_STOP for ``repeat_s`` (Wi-Fi loses datagrams) and reads
the cars' answers, which tell whether the latch took. The answers only inform: the
E_STOPs go out whatever they say.

This module imports nothing heavy (no Zenoh, no numpy, not even the typed config, whose
dataclasses take tens of milliseconds to build): ``trustfg stop`` reads the cars' links
straight from the config file (:func:`first_e_stop`) and sends its first E_STOPs before
anything else loads; the typed config follows and is the authority.
"""

from __future__ import annotations

import time
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterable

from ..bridge.carlink import Answer, CommandSender, Flags, open_sender

if TYPE_CHECKING:
    from ..agent.config import Scenario

DIRECT_PERIOD_S = 0.02
"""The direct path repeats its E_STOP at the command rate of a car process (50 Hz)."""
DIRECT_REPEAT_S = 0.5
"""... for this long after the stop (25 datagrams: losing a few does not matter)."""


def named(fleet: "Scenario", cars: Iterable[int] = ()) -> list[int]:
    """The car ids a command names (none: every car); ValueError for an unknown one."""
    ids = [c.id for c in fleet.cars]
    chosen = list(cars) or ids
    unknown = sorted(set(chosen) - set(ids))
    if unknown:
        raise ValueError(f"no car {' '.join(map(str, unknown))} in this fleet (cars: {' '.join(map(str, ids))})")
    return chosen


class LinkStopper:
    """E_STOP (and PING) datagrams straight to cars' links; see the module docstring."""

    def __init__(self, fleet: "Scenario", clock: Callable[[], float] = time.time):
        self.clock = clock
        self.senders: dict[int, CommandSender] = {
            car.id: open_sender(car, stamp_clock=clock, stop_repeats=0) for car in fleet.cars if car.link}
        self._until: dict[int, float] = {}
        self.answers: dict[int, Answer] = {}
        """The latest answer of each car."""
        self.answered_at: dict[int, float] = {}

    def engage(self, cars: Iterable[int], now: float, repeat_s: float = DIRECT_REPEAT_S) -> None:
        """E_STOP to every named car now, and again at every :meth:`step` for ``repeat_s``."""
        for car in cars:
            if car in self.senders:
                self._until[car] = now + repeat_s
                self.senders[car].send(0.0, 0.0, Flags.E_STOP | Flags.STOP | Flags.PING)

    def cancel(self, cars: Iterable[int]) -> None:
        """Stop repeating the e-stop to the named cars (the operator released them: a
        repeat arriving after their RELEASE would latch them again)."""
        for car in cars:
            self._until.pop(car, None)

    def ping(self, cars: Iterable[int]) -> None:
        """Ask the named cars for their state (a PING is never applied)."""
        for car in cars:
            if car in self.senders:
                self.senders[car].send(0.0, 0.0, Flags.STOP | Flags.PING)

    def step(self, now: float) -> None:
        """Repeat pending e-stops; read answers."""
        for car, until in list(self._until.items()):
            if now < until:
                self.senders[car].send(0.0, 0.0, Flags.E_STOP | Flags.STOP | Flags.PING)
            else:
                del self._until[car]
        for car, sender in self.senders.items():
            for answer in sender.answers():
                self.answers[car] = answer
                self.answered_at[car] = now

    @property
    def busy(self) -> bool:
        return bool(self._until)

    def close(self) -> None:
        for sender in self.senders.values():
            sender.close()  # stop_repeats=0: it sends nothing on the way out
        self.senders.clear()


def first_e_stop(source: str, cars: Iterable[int] = ()) -> list[int]:
    """One E_STOP (with PING) to each named car (none: every car) whose ``link`` a config
    *file* names, read with tomllib alone; the cars it reached. Anything unexpected (a
    shipped name, a car without a plain ``udp://HOST:PORT`` link) is left to the typed
    path that follows. These are version-1 datagrams: a car whose link needs more ignores
    them and is stopped by the typed path's, a few milliseconds later."""
    try:
        tables = tomllib.loads(Path(source).read_text(encoding="utf-8")).get("cars", [])
    except (OSError, ValueError):
        return []
    wanted, reached = set(cars), []
    for table in tables if isinstance(tables, list) else []:
        car, link = (table.get("id"), table.get("link")) if isinstance(table, dict) else (None, None)
        if not (isinstance(car, int) and 1 <= car <= 255 and isinstance(link, str) and link.startswith("udp://")):
            continue
        host, _, port = link[len("udp://"):].rpartition(":")
        if (wanted and car not in wanted) or not host or not port.isdigit():
            continue
        try:
            with CommandSender(car, (host.strip("[]"), int(port)), stop_repeats=0) as sender:
                sender.send(0.0, 0.0, Flags.E_STOP | Flags.STOP | Flags.PING)
        except (OSError, ValueError):
            continue
        reached.append(car)
    return reached

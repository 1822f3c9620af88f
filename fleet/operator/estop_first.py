"""``trustfg stop``'s first E_STOPs: sent before the rest of the program loads.

An e-stop is measured from the operator's command, and a fresh Python process spends most
of its first tens of milliseconds importing. So ``trustfg stop`` (fleet.operator.estop, called by
the cli before logging is set up) parses its arguments and, before it imports the typed
config (whose dataclasses take tens of milliseconds to build), the car links' senders, the
bus or logging, calls :func:`first_e_stop`: it reads each car's ``link`` and key straight
from the config file with tomllib and sends one E_STOP to each (bridge.carlink.direct,
which imports only the framing of bridge.carlink.frame). The typed path follows and is the
authority: it repeats the E_STOPs (fleet.operator.estop_direct.LinkStopper), reads the cars' answers,
stops the cars on the bus and reports, whatever the first datagrams did.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Iterable

from ...bridge.carlink.direct import send_e_stop
from ...bridge.carlink.keys import key_for

DIRECT_PERIOD_S = 0.02
"""The direct path repeats its E_STOP at the command rate of a car process (50 Hz)."""
DIRECT_REPEAT_S = 0.5
"""... for this long after the stop (25 datagrams: losing a few does not matter)."""


def first_e_stop(source: str, cars: Iterable[int] = ()) -> list[int]:
    """One E_STOP (with PING) to each named car (none: every car) whose ``link`` (and, for
    version 2, key) a config *file* names, read with tomllib alone; the cars it reached.
    Anything unexpected (a shipped name, a car without a plain ``udp://HOST:PORT`` link, a
    key that does not read) is left to the typed path that follows, a few milliseconds
    later."""
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
            key = key_for(car, table.get("link_version", 2), table.get("link_key_file", ""), table.get("link_key", ""))
            send_e_stop(car, (host.strip("[]"), int(port)), key)
        except Exception:  # noqa: BLE001 -- anything here is the typed path's to report
            continue
        reached.append(car)
    return reached

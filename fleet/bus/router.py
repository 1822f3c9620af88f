"""``trustfg router``: a Zenoh router for a fleet whose members cannot reach each other.

    trustfg router [--config deploy/zenoh/router.json5] [--listen ENDPOINT ...]

The eclipse-zenoh package opens a session in router mode itself, so a lab without the
``zenohd`` binary (neither PyPI nor Debian ships one) gets the same routing from the
package it already has: car processes with ``[bus] mode = "client"`` and ``connect`` =
the router's endpoint talk to each other only through it (``deploy/zenoh/router.json5``
has the lab's settings; ``--listen`` replaces its endpoints). It prints ``READY`` once it
listens and runs until SIGTERM or SIGINT. The router keeps no state of the fleet's: it
only forwards, so it can be restarted (the advanced subscribers recover the latest plans).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import sys
import threading
from importlib import resources

import zenoh

from ...agent.config import Scenario
from ..program import command_parser, stop_on_signals
from .zenoh_setup import zenoh_runtime_threads

log = logging.getLogger(__name__)

SHIPPED = "deploy/zenoh/router.json5"


def shipped_config() -> str:
    """The path of the router config shipped with the package."""
    return str(resources.files("trustfg").joinpath(SHIPPED))


def router_config(path: str, listen: list[str]) -> zenoh.Config:
    """The router's zenoh.Config: the file, in router mode, with ``listen`` if given."""
    config = zenoh.Config.from_file(path)
    config.insert_json5("mode", json.dumps("router"))
    if listen:
        config.insert_json5("listen/endpoints", json.dumps(listen))
    return config


def through_router(scenario: Scenario, endpoint: str) -> Scenario:
    """The fleet config with every member a Zenoh client of the router at ``endpoint``:
    no car listens or connects to another; everything goes through the router."""
    return dataclasses.replace(
        scenario, cars=tuple(dataclasses.replace(car, listen=()) for car in scenario.cars),
        bus=dataclasses.replace(scenario.bus, mode="client", listen=(), connect=(endpoint,)))


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg router", __doc__)
    parser.add_argument("--config", default=shipped_config(), help="Zenoh router config (default: the shipped %s)" % SHIPPED)
    parser.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                        help="listen here instead of the config's endpoints, e.g. tcp/0.0.0.0:7447 (repeatable)")
    args = parser.parse_args(argv)
    stop = stop_on_signals(threading.Event())
    zenoh_runtime_threads()  # a router links every car: one lingering close must not stall it
    try:
        session = zenoh.open(router_config(args.config, args.listen))
    except Exception as exc:  # zenoh raises its own errors for bad files, values or busy ports
        print(f"trustfg router: cannot start: {exc}", file=sys.stderr)
        return 2
    try:
        log.info("router %s listening on %s", session.zid(), args.listen or "the config's endpoints")
        print("READY", flush=True)
        stop.wait()
    finally:
        session.close()
    return 0

"""``trustfg foxglove --config FILE``: the live fleet for Foxglove, over its WebSocket protocol.

Joins the bus as an observer and serves what it hears with Foxglove's SDK
(``foxglove.start_server``, subprotocol ``foxglove.sdk.v1``, the SDK's name for
``foxglove.websocket.v1``): every fleet message as JSON on its key expression, and the scene
Foxglove's 3D panel draws (fleet.recording.foxglove_scene: the map, the cars, their plans,
goals and epsilon circles, frame transforms, a log). In Foxglove: *Open connection* ->
*Foxglove WebSocket* -> ``ws://HOST:PORT``. The map is sent again every few seconds for
clients that connect late.

    trustfg foxglove --config deploy/lab/fleet.toml [--port 8766] [--host 127.0.0.1]
"""

from __future__ import annotations

import sys
import threading
import time

import foxglove

from ..agent import messages
from ..agent.config import Scenario
from ..agent.scenario_files import load_scenario
from ..fleet.bus.session import FleetBus
from ..fleet.program import command_parser, configured, stop_on_signals
from ..fleet.recording.foxglove_scene import FoxgloveLog
from ..fleet.recording.mcap_file import schema

MAP_PERIOD_S = 2.0


class FoxgloveLive:
    """The server and the bus observer feeding it; ``step()`` forwards what arrived,
    ``run()`` loops until ``stop``. A context manager: the server and the session close."""

    def __init__(self, scenario: Scenario, host: str = "127.0.0.1", port: int = 8766,
                 listen: tuple[str, ...] = ()) -> None:
        self.scenario = scenario
        self._context = foxglove.Context()
        self._log = FoxgloveLog(scenario, self._context)
        self._inbox = messages.Inbox()
        self._bus = FleetBus(scenario.bus, scenario.fleet, None, listen=listen)
        self._server = None
        self._host, self._port = host, port
        self._next_map = 0.0
        self.stop = threading.Event()

    @property
    def port(self) -> int:
        return self._server.port if self._server is not None else self._port

    def __enter__(self) -> "FoxgloveLive":
        self._server = foxglove.start_server(name=f"trustfg {self.scenario.fleet}", host=self._host,
                                             port=self._port, context=self._context)
        try:
            self._bus.open()
        except BaseException:
            self._server.stop()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self._bus.close()
        if self._server is not None:
            self._server.stop()
            self._server = None

    def step(self, wait_s: float = 0.1) -> int:
        """Forward every message that arrived (waiting up to ``wait_s``); how many."""
        self._bus.wait(wait_s)
        now = time.time()
        if now >= self._next_map:
            self._next_map = now + MAP_PERIOD_S
            self._log.write_map(now)
        forwarded = 0
        for received in self._bus.drain():
            message = self._inbox.accept(received.payload, key_sender=received.sender)
            if message is not None:
                self._log.write(message.kind, message.sender, received.at, messages.to_dict(message),
                                schema(message.kind))
                forwarded += 1
        return forwarded

    def run(self) -> None:
        while not self.stop.is_set():
            self.step()


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg foxglove", __doc__)
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--host", default="127.0.0.1", help="address to serve on (default %(default)s)")
    parser.add_argument("--port", type=int, default=8766, help="WebSocket port (default %(default)s)")
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on (repeatable)")
    args = parser.parse_args(argv)
    scenario = configured("trustfg foxglove", lambda: load_scenario(args.config))
    live = FoxgloveLive(scenario, args.host, args.port, tuple(args.listen))
    stop_on_signals(live.stop)
    try:
        with live:
            print(f"Foxglove: ws://{args.host}:{live.port} (fleet {scenario.fleet!r}; Ctrl-C to stop)", flush=True)
            live.run()
    except OSError as exc:
        print(f"trustfg foxglove: cannot serve on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 1
    return 0

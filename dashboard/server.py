"""``trustfg dashboard``: the fleet, live in a web page (or a recorded run, replayed).

    trustfg dashboard --config FILE [--host H] [--port P] [--listen ENDPOINT]
    trustfg dashboard --replay RUN  [--host H] [--port P]

A Starlette (ASGI) app served by uvicorn. Live, it joins the fleet's Zenoh bus as an
observer; replaying, it plays an MCAP recording (trustfg.fleet.recording) at real time, with
play, pause, speed and a time slider. Either way the messages feed one
:class:`dashboard.state.FleetView`, and every connected page gets a snapshot over a
WebSocket 10 times a second. The page (dashboard/static) is plain HTML, SVG and
JavaScript: nothing to build.

    GET /               the page
    GET /api/map        the static map: bounds, obstacles, cars, goals
    GET /api/snapshot   the latest snapshot (what the page draws), as JSON
    WS  /ws             {"type": "map"} once, then {"type": "snapshot"} at 10 Hz; the page
                        may send {"type": "seek", "t": T}, {"type": "play"}, {"type": "pause"},
                        {"type": "speed", "value": X} to drive a replay
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import logging
import sys
import time
from pathlib import Path

import uvicorn
from starlette.applications import Starlette
from starlette.responses import FileResponse, JSONResponse
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.staticfiles import StaticFiles
from starlette.websockets import WebSocket, WebSocketDisconnect

from ..agent import messages
from ..agent.config import ConfigError, Scenario
from ..agent.scenario_files import load_scenario
from ..fleet.bus import FleetBus
from ..fleet.recording import Recorded, read_recording, resolve_run
from .state import FleetView

log = logging.getLogger(__name__)

STATIC = Path(__file__).resolve().parent / "static"
TICK_S = 0.05
SNAPSHOT_PERIOD_S = 0.1


class LiveSource:
    """The fleet's bus, as an observer."""

    mode = "live"

    def __init__(self, scenario: Scenario, listen: tuple[str, ...]):
        self.scenario = scenario
        self.bus = FleetBus(scenario.bus, scenario.fleet, None, listen=listen)
        self.inbox = messages.Inbox()

    def open(self) -> None:
        self.bus.open()

    def close(self) -> None:
        self.bus.close()

    def feed(self, view: FleetView, wall_dt: float) -> None:
        for received in self.bus.drain():
            message = self.inbox.accept(received.payload, key_sender=received.sender)
            if message is not None:
                view.update(message, received.at)
        for car, up in list(self.bus.alive.items()):
            view.liveliness(car, up)
        view.now = max(view.now, time.time())

    def status(self) -> dict:
        return {"mode": "live", "bus": self.bus.counters.get("liveliness_up", 0) > 0,
                "alive": sorted(c for c, up in self.bus.alive.items() if up),
                "dropped": dict(self.inbox.dropped)}

    def control(self, command: dict, view: FleetView) -> FleetView:
        return view


class ReplaySource:
    """A recording played back at ``speed`` times real time."""

    mode = "replay"

    def __init__(self, scenario: Scenario, events: list[Recorded]):
        self.scenario = scenario
        self.events = events
        self.start = events[0].at if events else 0.0
        self.end = events[-1].at if events else 0.0
        self.position = self.start
        self.index = 0
        self.playing = True
        self.speed = 1.0
        self.inbox_errors = 0

    def open(self) -> None:
        pass

    def close(self) -> None:
        pass

    def feed(self, view: FleetView, wall_dt: float) -> None:
        if self.playing:
            self.position = min(self.end, self.position + wall_dt * self.speed)
            if self.position >= self.end:
                self.playing = False
        self._advance(view)

    def _advance(self, view: FleetView) -> None:
        while self.index < len(self.events) and self.events[self.index].at <= self.position:
            apply(view, self.events[self.index])
            self.index += 1
        view.now = max(view.now, self.position)

    def control(self, command: dict, view: FleetView) -> FleetView:
        kind = command.get("type")
        if kind == "play":
            self.playing = True
            if self.position >= self.end:
                return self.seek(self.start)
        elif kind == "pause":
            self.playing = False
        elif kind == "speed":
            value = command.get("value")
            if isinstance(value, (int, float)) and 0.05 <= value <= 50:
                self.speed = float(value)
        elif kind == "seek":
            t = command.get("t")
            if isinstance(t, (int, float)):
                return self.seek(float(t))
        return view

    def seek(self, t: float) -> FleetView:
        """A fresh view replayed from the start up to t (a slider can go backwards)."""
        self.position = min(max(t, self.start), self.end)
        self.index = 0
        view = FleetView(self.scenario)
        self._advance(view)
        return view

    def status(self) -> dict:
        return {"mode": "replay", "start": self.start, "end": self.end, "position": self.position,
                "playing": self.playing, "speed": self.speed}


def apply(view: FleetView, event: Recorded) -> None:
    """One recorded event into a view (the same checks as live messages)."""
    if event.kind == "truth":
        cars = event.data.get("cars", {})
        view.truth(event.at, {int(car): (s["x"], s["y"]) for car, s in cars.items()})
        return
    try:
        view.update(messages.from_dict(event.data), event.at)
    except messages.MessageError:
        log.debug("skipping an invalid recorded message")


def replay_to_end(path: Path) -> FleetView:
    """The view a replay shows at the end of a recording (tests, reports)."""
    scenario, events = read_recording(path)
    source = ReplaySource(scenario, events)
    return source.seek(source.end)


class Dashboard:
    """The app's state: one view, one source, the connected pages."""

    def __init__(self, scenario: Scenario, source: LiveSource | ReplaySource):
        self.scenario = scenario
        self.source = source
        self.view = FleetView(scenario)
        self.clients: set[WebSocket] = set()
        self.latest: dict = {}

    def snapshot(self) -> dict:
        snap = self.view.snapshot()
        snap["source"] = self.source.status()
        self.latest = snap
        return snap

    async def pump(self) -> None:
        """Feed the view and push snapshots, forever (cancelled at shutdown)."""
        last = time.monotonic()
        next_snapshot = last
        while True:
            await asyncio.sleep(TICK_S)
            now = time.monotonic()
            try:
                self.source.feed(self.view, now - last)
            except Exception:  # one bad batch must not stop the page
                log.exception("dashboard: feeding the view failed")
            last = now
            if now >= next_snapshot:
                next_snapshot = now + SNAPSHOT_PERIOD_S
                text = json.dumps(self.snapshot())
                for client in list(self.clients):
                    try:
                        await client.send_text(text)
                    except Exception:
                        self.clients.discard(client)


def create_app(dashboard: Dashboard) -> Starlette:
    async def index(request):
        return FileResponse(STATIC / "index.html")

    async def map_(request):
        return JSONResponse(dashboard.view.map())

    async def snapshot(request):
        return JSONResponse(dashboard.latest or dashboard.snapshot())

    async def ws(websocket: WebSocket):
        await websocket.accept()
        await websocket.send_text(json.dumps(dashboard.view.map()))
        await websocket.send_text(json.dumps(dashboard.snapshot()))
        dashboard.clients.add(websocket)
        try:
            while True:
                text = await websocket.receive_text()
                try:
                    command = json.loads(text)
                except ValueError:
                    continue
                if isinstance(command, dict):
                    dashboard.view = dashboard.source.control(command, dashboard.view)
        except WebSocketDisconnect:
            pass
        finally:
            dashboard.clients.discard(websocket)

    @contextlib.asynccontextmanager
    async def lifespan(app):
        dashboard.source.open()
        task = asyncio.create_task(dashboard.pump())
        try:
            yield
        finally:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            dashboard.source.close()

    return Starlette(routes=[
        Route("/", index), Route("/api/map", map_), Route("/api/snapshot", snapshot),
        WebSocketRoute("/ws", ws), Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ], lifespan=lifespan)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="trustfg dashboard", description=__doc__.split("\n")[0])
    source_group = parser.add_mutually_exclusive_group(required=True)
    source_group.add_argument("--config", type=Path, help="fleet config TOML (live)")
    source_group.add_argument("--replay", type=Path, help="a run folder or .mcap recording to play")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8765)
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on (repeatable)")
    args = parser.parse_args(argv)
    try:
        if args.replay:
            scenario, events = read_recording(resolve_run(args.replay))
            source: LiveSource | ReplaySource = ReplaySource(scenario, events)
        else:
            scenario = load_scenario(args.config)
            source = LiveSource(scenario, tuple(args.listen))
    except (ConfigError, OSError, ValueError) as exc:
        print(f"trustfg dashboard: {exc}", file=sys.stderr)
        return 2
    dashboard = Dashboard(scenario, source)
    config = uvicorn.Config(create_app(dashboard), host=args.host, port=args.port, log_level="warning")
    server = uvicorn.Server(config)
    print(f"dashboard: http://{args.host}:{args.port}/", flush=True)
    server.run()
    return 0

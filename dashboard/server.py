"""``trustfg dashboard``: the fleet, live in a web page (or a recorded run, replayed).

A Starlette app: live, it observes the fleet's bus; replaying, it plays an MCAP recording
at real time. Either way one :class:`~.state.FleetView` is fed, and every open page gets
its snapshot over a WebSocket at 10 Hz (docs/design/links.md, "The dashboard"). Endpoints:

    GET /               the page (dashboard/static: plain HTML, SVG and JavaScript)
    GET /api/map        the static map: bounds, obstacles, cars, goals
    GET /api/snapshot   a snapshot made now (what the page draws), as JSON
    POST /api/operator  operator mode only (--operator): e-stop, release, abort, for the
                        holder of the session's token (dashboard/estop_panel.py)
    WS  /ws             {"type": "map"} once, then {"type": "snapshot"} at 10 Hz; the page
                        may send {"type": "seek", "t": T}, {"type": "play"}, {"type": "pause"},
                        {"type": "speed", "value": X} to drive a replay
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
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
from ..fleet.bus.session import FleetBus
from ..fleet.operator.session import OperatorSession
from ..fleet.program import command_parser
from ..fleet.recording.mcap_file import Recorded, read_recording, resolve_run
from .estop_panel import OperatorPanel, check_operator_mode, load_token
from .state import FleetView

log = logging.getLogger(__name__)

STATIC = Path(__file__).resolve().parent / "static"
TICK_S = 0.05
SNAPSHOT_PERIOD_S = 0.1


class LiveSource:
    """The fleet's bus, as an observer (and, in operator mode, as the operator: ``token``)."""

    mode = "live"

    def __init__(self, scenario: Scenario, listen: tuple[str, ...], token: str | None = None):
        self.scenario = scenario
        self.bus = FleetBus(scenario.bus, scenario.fleet, None, listen=listen, operator_kinds=("start", "stop"))
        self.inbox = messages.Inbox()
        self.token = token
        self.operator: OperatorPanel | None = None

    def open(self) -> None:
        self.bus.open()
        if self.token is not None:
            self.operator = OperatorPanel(OperatorSession(self.scenario, self.bus), self.token)

    def close(self) -> None:
        if self.operator is not None:
            self.operator.session.close()
        self.bus.close()

    def feed(self, view: FleetView, wall_dt: float) -> None:
        if self.operator is not None:
            self.operator.session.step()  # the heartbeat; the direct path's repeats
        for received in self.bus.drain():
            message = self.inbox.accept(received.payload, key_sender=received.sender)
            if message is not None:
                view.update(message, received.at)
                if self.operator is not None:
                    self.operator.session.heard(message, received.at)
        for car, up in self.bus.on_bus().items():
            view.liveliness(car, up)
        view.now = max(view.now, time.time())

    def status(self) -> dict:
        return {"mode": "live", "bus": self.bus.counters.get("liveliness_up", 0) > 0,
                "alive": sorted(c for c, up in self.bus.on_bus().items() if up),
                "dropped": dict(self.inbox.dropped),
                "operator": self.operator.status() if self.operator is not None else {"enabled": False}}

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

    def snapshot(self) -> dict:
        snap = self.view.snapshot()
        snap["source"] = self.source.status()
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
            if self.clients and now >= next_snapshot:  # no page open: no snapshot (building one takes CPU the fleet shares)
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
        return JSONResponse(dashboard.snapshot())

    async def operator(request):
        panel = getattr(dashboard.source, "operator", None)
        if panel is None:
            return JSONResponse({"ok": False, "error": "not in operator mode (trustfg dashboard --operator)"}, 404)
        try:
            body = await request.json()
        except ValueError:
            body = None
        status, answer = panel.act(request.headers.get("authorization"), body)
        return JSONResponse(answer, status)

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
        Route("/api/operator", operator, methods=["POST"]),
        WebSocketRoute("/ws", ws), Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ], lifespan=lifespan)


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg dashboard", __doc__)
    source_group = parser.add_mutually_exclusive_group(required=True)
    source_group.add_argument("--config", type=Path, help="fleet config TOML (live)")
    source_group.add_argument("--replay", type=Path, help="a run folder or .mcap recording to play")
    parser.add_argument("--host", default="127.0.0.1", help="address to serve the page on")
    parser.add_argument("--port", type=int, default=8765, help="port to serve the page on (0: any free one)")
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on (repeatable)")
    parser.add_argument("--operator", action="store_true",
                        help="operator mode: a stop button for the holder of the printed token, and the heartbeat")
    parser.add_argument("--token-file", type=Path, default=None,
                        help="operator mode: read the token from this file (default: a new random one)")
    parser.add_argument("--tls-cert", type=Path, default=None, help="serve HTTPS with this certificate (PEM)")
    parser.add_argument("--tls-key", type=Path, default=None, help="... and this private key (PEM)")
    args = parser.parse_args(argv)
    if bool(args.tls_cert) != bool(args.tls_key):
        parser.error("--tls-cert and --tls-key go together")
    if args.operator and args.replay:
        parser.error("--operator needs a live fleet (--config)")
    token = None
    try:
        if args.replay:
            scenario, events = read_recording(resolve_run(args.replay))
            source: LiveSource | ReplaySource = ReplaySource(scenario, events)
        else:
            scenario = load_scenario(args.config)
            if args.operator:
                check_operator_mode(scenario, args.host, https=args.tls_cert is not None)
                token = load_token(args.token_file)
            source = LiveSource(scenario, tuple(args.listen), token)
        sock = socket.socket(socket.AF_INET6 if ":" in args.host else socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((args.host, args.port))
    except (ConfigError, OSError, ValueError) as exc:
        print(f"trustfg dashboard: {exc}", file=sys.stderr)
        return 2
    dashboard = Dashboard(scenario, source)
    config = uvicorn.Config(create_app(dashboard), log_level="warning",
                            ssl_certfile=str(args.tls_cert) if args.tls_cert else None,
                            ssl_keyfile=str(args.tls_key) if args.tls_key else None)
    server = uvicorn.Server(config)
    host, port = sock.getsockname()[:2]
    url = f"{'https' if args.tls_cert else 'http'}://{host if ':' not in host else f'[{host}]'}:{port}/"
    print(f"dashboard: {url}" + (f"?token={token}" if token else ""), flush=True)
    server.run(sockets=[sock])
    return 0

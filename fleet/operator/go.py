"""``trustfg go --config FILE``: the operator's session -- start a trial, watch it, stop it.

It joins the bus as the operator, publishes the heartbeat the cars' deadman listens for,
and waits (``--wait``) until every car process is on the bus and ready (waiting, or
arrived from the last trial), saying who is not. With a car missing or e-stopped it starts
nothing unless ``--allow-missing`` (then the ready cars start); with the e-stop's direct
path to a car missing (a key that does not read, an address that does not resolve) it
exits with 2 unless ``--bus-stop-only``, which it says loudly. The start names the next
trial: every car may set off ``--lead`` s from now (plus ``--stagger`` s per car, in id
order) at ``--cruise`` m/s; it prints who arrives until every started car is at its goal
(exit 0). Keys in a terminal: SPACE or s e-stops every car (on the links and the bus), r
releases, a aborts the trial (cars hold and wait), q or Ctrl-C aborts and quits. A car
stays e-stopped until released, also after this session ends.
"""

from __future__ import annotations

import contextlib
import select
import sys
import termios
import threading
import time
import tty

from ...agent import messages
from ...agent.scenario_files import load_scenario
from ..bus.session import BusError, FleetBus
from ..program import command_parser, configured, stop_on_signals
from .estop_direct import missing_paths
from .session import OperatorSession

READY = ("waiting", "arrived")
KEYS = "keys: SPACE/s e-stop every car, r release, a abort the trial, q quit"


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg go", __doc__)
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--lead", type=float, default=2.0, help="seconds from now to the first departure")
    parser.add_argument("--stagger", type=float, default=0.0, help="extra seconds per car, in id order")
    parser.add_argument("--cruise", type=float, default=None, help="cruise speed, m/s (default: the planner's)")
    parser.add_argument("--wait", type=float, default=10.0, help="seconds to wait for every car to be ready")
    parser.add_argument("--allow-missing", action="store_true", help="start the ready cars even if some are not")
    parser.add_argument("--bus-stop-only", action="store_true",
                        help="start even if the e-stop cannot reach some cars' links directly (the bus path alone)")
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on (repeatable)")
    args = parser.parse_args(argv)
    fleet = configured("trustfg go", lambda: load_scenario(args.config))
    cruise = args.cruise or fleet.planner.cruise_speed_mps
    if not 0 < cruise <= fleet.vehicle.max_speed_mps:
        parser.error(f"--cruise must be within (0, {fleet.vehicle.max_speed_mps}]")
    if not (args.lead > 0 and args.stagger >= 0 and args.wait >= 0):
        parser.error("--lead must be > 0, --stagger and --wait >= 0")
    missing = missing_paths(fleet)
    if missing and not args.bus_stop_only:
        print(f"trustfg go: not starting: no direct e-stop path to {_cars(missing)}; mend that (docs/lab-guide.md, "
              f"car-link keys), or --bus-stop-only to stop those cars on the bus alone", file=sys.stderr)
        return 2
    if missing:
        print(f"WARNING: --bus-stop-only: the e-stop reaches {_cars(missing)} on the bus alone, through the car "
              f"process: a hung car process there does not stop its car", file=sys.stderr, flush=True)
    stop = stop_on_signals(threading.Event())
    try:
        with FleetBus(fleet.bus, fleet.fleet, None, listen=tuple(args.listen), kinds=("status",),
                      operator_kinds=()) as bus:
            session = OperatorSession(fleet, bus)
            try:
                return Go(fleet, bus, session, stop, args, cruise).run()
            finally:
                session.close()
    except BusError as exc:
        print(f"trustfg go: {exc}", file=sys.stderr)
        return 1


def _cars(missing: dict[int, str]) -> str:
    return "; ".join(f"car {car} ({why})" for car, why in sorted(missing.items()))


class Go:
    """One session of ``trustfg go``: wait for the cars, start, watch, take keys."""

    def __init__(self, fleet, bus, session: OperatorSession, stop: threading.Event, args, cruise: float):
        self.fleet, self.bus, self.session, self.stop, self.args, self.cruise = fleet, bus, session, stop, args, cruise
        self.inbox = messages.Inbox()
        self.ids = [c.id for c in fleet.cars]

    def poll(self, wait_s: float = 0.0) -> None:
        self.session.step()
        for received in self.bus.drain():
            message = self.inbox.accept(received.payload, key_sender=received.sender)
            if message is not None:
                self.session.heard(message, received.at)
        if wait_s:
            self.bus.wait(wait_s)

    def ready(self) -> tuple[list[int], dict[int, str]]:
        """Cars ready to start, and why the others are not."""
        alive = set(self.session.alive())
        ready, not_ready = [], {}
        for car in self.ids:
            state = self.session.cars[car].state
            if car not in alive:
                not_ready[car] = "not on the bus"
            elif state not in READY:
                not_ready[car] = state or "no status yet"
            else:
                ready.append(car)
        return ready, not_ready

    def run(self) -> int:
        deadline = time.monotonic() + self.args.wait
        while not self.stop.is_set():
            self.poll(0.05)
            ready, not_ready = self.ready()
            if not not_ready or time.monotonic() > deadline:
                break
        print("cars: " + ", ".join([f"{car} ready" for car in ready]
                                   + [f"{car} {why}" for car, why in not_ready.items()]), flush=True)
        if self.stop.is_set():
            return 130
        if not ready or (not_ready and not self.args.allow_missing):
            print(f"trustfg go: not starting: car{'s' if len(not_ready) > 1 else ''} "
                  f"{' '.join(map(str, not_ready))} not ready (--allow-missing starts the others)", file=sys.stderr)
            return 1
        now = time.time()
        departures = {car: (now + self.args.lead + k * self.args.stagger, self.cruise) for k, car in enumerate(ready)}
        trial = self.session.start(departures)
        print(f"trial {trial} started: cars {' '.join(map(str, ready))} leave from t+{self.args.lead:.1f}s "
              f"at {self.cruise} m/s", flush=True)
        with _keys() as keys:
            if keys is None:
                print("(not a terminal: no keys; Ctrl-C aborts the trial)", flush=True)
            else:
                print(KEYS, flush=True)
            return self.watch(trial, ready, keys)

    def watch(self, trial: int, cars: list[int], keys) -> int:
        arrived: set[int] = set()
        said = {car: "driving" for car in cars}
        while True:
            self.poll(0.0)
            for car in cars:
                seen = self.session.cars[car]
                if car not in arrived and seen.trial == trial and seen.state == "arrived":
                    arrived.add(car)
                    print(f"car {car} is at its goal", flush=True)
                elif seen.trial == trial and seen.state not in (said[car], "arrived"):
                    print(f"car {car}: {seen.state}", flush=True)  # stuck, e-stopped, back to waiting...
                if seen.trial == trial:
                    said[car] = seen.state
            if len(arrived) == len(cars):
                print(f"trial {trial} ended: every car at its goal", flush=True)
                return 0
            key = keys() if keys is not None else ""
            if self.stop.is_set() or key == "q":
                self.session.abort(trial=trial)
                print(f"trial {trial} aborted: the cars hold and wait", flush=True)
                return 130 if self.stop.is_set() else 1
            if key in (" ", "s"):
                self.session.estop()
                print("E-STOP every car (r releases, q quits)", flush=True)
            elif key == "r":
                self.session.release()
                print("released: the cars wait for a new start (q quits)", flush=True)
            elif key == "a":
                self.session.abort(trial=trial)
                print(f"trial {trial} aborted: the cars hold and wait (q quits)", flush=True)
            self.bus.wait(0.02)


@contextlib.contextmanager
def _keys():
    """A function returning the key pressed since the last call ("" if none), or None
    when stdin is not a terminal; the terminal is restored on the way out."""
    if not sys.stdin.isatty():
        yield None
        return
    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    tty.setcbreak(fd)
    try:
        yield lambda: sys.stdin.read(1) if select.select([sys.stdin], [], [], 0.0)[0] else ""
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)

"""``trustfg go --config FILE``: the operator's start signal for a fleet in the lab.

Joins the fleet's bus as an observer and publishes the start message: every car may set
off ``--lead`` seconds from now (plus ``--stagger`` seconds per car, in id order) at
``--cruise`` m/s. It stays on the bus -- late car processes get the start from its cache
-- and prints who is where until every car reports it is at its goal, or Ctrl-C.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

from ..agent import messages
from ..agent.scenario_files import load_scenario
from .bus import BusError, FleetBus
from .command import configured, stop_on_signals


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="trustfg go", description=__doc__.split("\n")[0])
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--lead", type=float, default=2.0, help="seconds from now to the first departure")
    parser.add_argument("--stagger", type=float, default=0.0, help="extra seconds per car, in id order")
    parser.add_argument("--cruise", type=float, default=None, help="cruise speed, m/s (default: planner's)")
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on (repeatable)")
    args = parser.parse_args(argv)
    fleet = configured("trustfg go", lambda: load_scenario(args.config))
    cruise = args.cruise or fleet.planner.cruise_speed_mps
    if not 0 < cruise <= fleet.vehicle.max_speed_mps:
        parser.error(f"--cruise must be within (0, {fleet.vehicle.max_speed_mps}]")
    stop = stop_on_signals(threading.Event())
    now = time.time()
    departures = {car.id: (now + args.lead + k * args.stagger, cruise) for k, car in enumerate(fleet.cars)}
    inbox = messages.Inbox()
    at_goal: dict[int, bool] = {}
    try:
        with FleetBus(fleet.bus, fleet.fleet, None, listen=tuple(args.listen), kinds=("status",)) as bus:
            bus.publish("start", messages.encode(messages.StartMessage(1, now, departures)))
            print(f"start sent: cars {sorted(departures)} leave from t+{args.lead:.1f}s at {cruise} m/s", flush=True)
            while not stop.is_set() and not (at_goal and all(at_goal.get(c.id) for c in fleet.cars)):
                for received in bus.drain():
                    status = inbox.accept(received.payload, key_sender=received.sender)
                    if isinstance(status, messages.StatusMessage):
                        if at_goal.get(status.sender) != status.at_goal and status.at_goal:
                            print(f"car {status.sender} is at its goal", flush=True)
                        at_goal[status.sender] = status.at_goal
                bus.wait(0.2)
    except BusError as exc:
        print(f"trustfg go: {exc}", file=sys.stderr)
        return 1
    return 0

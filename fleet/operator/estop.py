"""``trustfg stop --config FILE [--cars N ...]``: the emergency stop of a fleet, or of some cars.

An e-stop goes two independent ways at once: E_STOP datagrams straight to each named car's
link (the car latches it whatever else it hears) and a stop message on the bus, which
every car process applies. ``--release`` releases on both paths (a car latches per
sender, so the operator's own RELEASE clears what the operator sent on the link); the car
then waits for a new start. ``--abort`` ends the running trial instead: the cars hold
(STOP, not latched) and wait for the next start. The first E_STOPs leave before anything
heavy loads (fleet.operator.estop_first). It prints, per car, what each path confirmed
and exits with 1 when a named car confirmed on neither.
"""

from __future__ import annotations

import argparse
import sys
import time
from typing import TYPE_CHECKING, Callable

from ..program import command_parser, configured
from .estop_first import DIRECT_PERIOD_S, DIRECT_REPEAT_S, first_e_stop

if TYPE_CHECKING:
    from ...agent.config import Scenario
    from .estop_direct import LinkStopper

BUS_JOIN_S = 1.0
"""A release or an abort waits up to this long for the car processes to be seen on the bus."""
ASK_AGAIN_PERIODS = 1.5
"""Status periods after which a car not heard since the message went out is asked again."""

CONFIRMED = {"estop": lambda state: state == "e_stopped", "release": lambda state: state not in ("e_stopped", ""),
             "abort": lambda state: state not in ("driving", "stuck", "")}


def main(argv: list[str] | None = None, ready: Callable[[], None] = lambda: None) -> int:
    """``ready()`` is called once the first E_STOPs are out (the cli sets up logging there)."""
    issued = time.time()  # the command, as the operator gave it
    parser = command_parser("trustfg stop", __doc__)
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--cars", type=int, nargs="+", default=[], help="the cars to stop (default: every car)")
    what = parser.add_mutually_exclusive_group()
    what.add_argument("--release", action="store_true",
                      help="release an e-stop (on the bus, and straight to version-2 links)")
    what.add_argument("--abort", action="store_true", help="end the running trial: cars hold and wait")
    parser.add_argument("--trial", type=int, default=0, help="with --abort: only this trial (0: whichever runs)")
    parser.add_argument("--path", choices=("both", "bus", "link"), default="both",
                        help="which way an e-stop (or a release) goes")
    parser.add_argument("--repeat", type=float, default=DIRECT_REPEAT_S,
                        help="seconds the E_STOP datagrams are repeated on the links")
    parser.add_argument("--wait", type=float, default=2.0, help="seconds to wait for the cars to confirm")
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on (repeatable)")
    args = parser.parse_args(argv)
    action = "release" if args.release else "abort" if args.abort else "estop"
    if action == "abort" and args.path == "link":
        parser.error("an abort goes on the bus only (--path bus or both)")
    if not (args.repeat >= 0 and args.wait >= 0):
        parser.error("--repeat and --wait must be >= 0")
    sent_direct = time.time() if action == "estop" and args.path != "bus" and first_e_stop(args.config, args.cars) \
        else None  # the first E_STOPs, before the typed config loads (tens of ms)
    ready()
    from ...agent.scenario_files import load_scenario  # after the first E_STOPs, as are the paths
    from .estop_direct import LinkStopper, named

    fleet = configured("trustfg stop", lambda: load_scenario(args.config))
    try:
        cars = named(fleet, args.cars)
    except ValueError as exc:
        parser.error(str(exc))
    stopper = None
    if action == "estop" and args.path != "bus":
        stopper = configured("trustfg stop", lambda: LinkStopper(fleet))  # the direct path, repeated: no Zenoh yet
        stopper.engage(cars, time.time(), args.repeat)
        sent_direct = sent_direct or time.time()
    elif action == "release":
        stopper = configured("trustfg stop", lambda: LinkStopper(fleet))  # to see the latch go
        if args.path != "bus":
            stopper.release(cars, time.time())  # the operator's own latches (a version-2 link)
    try:
        return _on_the_bus(fleet, cars, action, args, stopper, issued, sent_direct)
    finally:
        if stopper is not None:
            stopper.close()


def _on_the_bus(fleet: "Scenario", cars: list[int], action: str, args: argparse.Namespace,
                stopper: LinkStopper | None, issued: float, sent_direct: float | None) -> int:
    import logging  # as everything here: imported after the direct path went out

    from ...agent import messages
    from ..bus.session import BusError, FleetBus
    from .session import OperatorSession

    bus = None
    session = None
    seen = {car: "" for car in cars}
    try:
        if args.path != "link":
            bus = FleetBus(fleet.bus, fleet.fleet, None, listen=tuple(args.listen), operator_kinds=())
            bus.open()
            if action != "estop":  # not urgent: first let the session reach the car processes (their
                _wait_alive(bus, cars, BUS_JOIN_S)  # tokens), or the message waits for their history query
            session = OperatorSession(fleet, bus, direct=False)
            {"estop": session.estop, "release": session.release,
             "abort": lambda cars: session.abort(cars, args.trial)}[action](args.cars)
        published = time.time()
        inbox = messages.Inbox()
        deadline = time.monotonic() + max(args.wait, args.repeat)
        # A car tells its mode at once and then every status period: a car not heard by
        # ASK_AGAIN_PERIODS of them most often never got our status subscription (Zenoh
        # now and then loses a declaration between peers that open at once), so declare it
        # again rather than wait out the bus's own SILENT_S watch.
        ask_again_s = ASK_AGAIN_PERIODS * fleet.control.status_period_s
        next_ask = time.monotonic() + ask_again_s
        next_ping = 0.0
        while time.monotonic() < deadline:
            now = time.time()
            if bus is not None and time.monotonic() >= next_ask:
                next_ask = time.monotonic() + ask_again_s
                unheard = [car for car in cars if not seen[car]]
                if unheard:
                    logging.getLogger(__name__).info("no status yet from cars %s: subscribing to status again",
                                                     " ".join(map(str, unheard)))
                    bus.subscribe_again("status")
            if stopper is not None:
                if action == "release" and time.monotonic() >= next_ping:
                    next_ping = time.monotonic() + 0.1
                    stopper.ping(cars)
                stopper.step(now)
            if bus is not None:
                for received in bus.drain():
                    message = inbox.accept(received.payload, key_sender=received.sender)
                    if isinstance(message, messages.StatusMessage) and message.sender in seen \
                            and received.at >= published:
                        seen[message.sender] = message.state
            on_bus = bus is None or all(CONFIRMED[action](seen[car]) for car in cars)
            on_links = stopper is None or all(car in stopper.answers for car in cars if car in stopper.senders)
            if on_bus and on_links and all(_confirmed(action, seen[car], stopper, car) for car in cars) \
                    and not _busy(stopper):
                break  # every car confirmed on every path asked; else until --wait
            time.sleep(DIRECT_PERIOD_S)
    except BusError as exc:
        print(f"trustfg stop: the bus: {exc}", file=sys.stderr)
        if stopper is None or action != "estop":
            return 1
    finally:
        if session is not None:
            session.close()
        if bus is not None:
            bus.close()
    return _report(cars, action, seen, stopper, issued, sent_direct)


def _wait_alive(bus, cars: list[int], timeout_s: float) -> None:
    """Until every named car process is seen on the bus, or ``timeout_s``. A session that
    publishes the moment it opens reaches only the peers it is already connected to; the
    others get the message later, from the cache, when their subscribers query it."""
    deadline = time.monotonic() + timeout_s
    while not all(bus.on_bus().get(car) for car in cars) and time.monotonic() < deadline:
        bus.wait(0.01)
        bus.drain()


def _busy(stopper: LinkStopper | None) -> bool:
    return stopper is not None and stopper.busy


def _latched(stopper: LinkStopper | None, car: int) -> bool | None:
    answer = stopper.answers.get(car) if stopper is not None else None
    return None if answer is None else answer.e_stop_latched


def _confirmed(action: str, state: str, stopper: LinkStopper | None, car: int) -> bool:
    latched = _latched(stopper, car)
    if action == "estop":
        return CONFIRMED[action](state) or latched is True
    if action == "release":
        return CONFIRMED[action](state) and latched is not True
    return CONFIRMED[action](state)


def _report(cars: list[int], action: str, seen: dict[int, str], stopper: LinkStopper | None, issued: float,
            sent_direct: float | None) -> int:
    if sent_direct is not None:
        direct = [car for car in cars if stopper is None or car not in stopper.unreachable]
        print(f"E_STOP sent straight to the links of cars {' '.join(map(str, direct))} "
              f"{(sent_direct - issued) * 1e3:.0f} ms after the command")
    print(f"{'car':>4}  {'bus (car process)':<20} {'link (the car)':<20}")
    failed = []
    for car in cars:
        state = seen[car] or "no answer"
        latched = _latched(stopper, car)
        link = "-" if stopper is None else "no key here" if car in stopper.unreachable else {
            True: "e-stop latched", False: "not latched", None: "no answer"}[latched]
        print(f"{car:>4}  {state:<20} {link:<20}")
        if not _confirmed(action, seen[car], stopper, car):
            failed.append(car)
    if failed:
        print(f"trustfg stop: not confirmed by cars {' '.join(map(str, failed))}", file=sys.stderr)
        return 1
    return 0

"""``trustfg check --config FILE``: the bring-up check of a fleet, with its motors held.

It drives nothing: it listens to Motive, PINGs every car's link (a PING is never applied:
bridge.carlink.answer), listens to the bus and asks every car process for its clock. Then
it prints one table, a row per configured car:

    pose     its rigid body's pose on the map (x, y, yaw), and how far from its start
    link     whether the car answers on its ``link`` (round trip; its e-stop latch)
    bus      whether its car process is on the bus, its state and trial
    clock    its computer's clock against this one (+- half the query's round trip)

and below it what is missing and what warns (a clock off by more than
``operator.clock_tolerance_s``, a scene that fails ``trustfg scenario check``). Exit
status 0 when nothing is missing and nothing warned, else 1.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, field

from ...agent import messages
from ...agent.config import Scenario
from ...agent.scenario_files import load_scenario
from ...bridge import natnet
from ...bridge.carlink import Answer
from ...bridge.natnet_client import NatNetClient, NatNetConnectionError, client_options
from ..bus.session import BusError, FleetBus
from ..program import command_parser, configured
from ..sim.scene_gen import scene_problem
from .estop_direct import LinkStopper

CLOCK_QUERIES = 5
START_TOLERANCE_M = 0.1


@dataclass
class Seen:
    """What the check saw of one car."""

    pose: tuple[float, float, float] | None = None  # from Motive
    tracked: bool = False
    answer: Answer | None = None
    rtt_ms: float | None = None
    alive: bool = False
    status: messages.StatusMessage | None = None
    clock: tuple[float, float] | None = None  # (offset s, +- s)


@dataclass
class Report:
    rows: list[list[str]]
    missing: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def report(fleet: Scenario, seen: dict[int, Seen], motive: str | None, others: list[int]) -> Report:
    """The table and what is missing (pure): ``motive`` is None when Motive streams, else
    the problem; ``others`` are rigid bodies in the stream that no car is configured for."""
    out = Report(rows=[["car", "body", "pose x y (m) yaw (deg)", "from start", "link", "bus", "clock offset"]])
    if motive is not None:
        out.missing.append(f"Motive: {motive}")
    tolerance = fleet.operator.clock_tolerance_s
    for car in fleet.cars:
        s = seen[car.id]
        if s.pose is not None and s.tracked:
            x, y, yaw = s.pose
            pose = f"{x:6.2f} {y:6.2f} {math.degrees(yaw):7.1f}"
            off = math.hypot(x - car.start[0], y - car.start[1])
            turn = abs((yaw - car.start_heading + math.pi) % (2 * math.pi) - math.pi)
            start = f"{off:.2f} m {math.degrees(turn):.0f} deg"
            if off > START_TOLERANCE_M:
                out.warnings.append(f"car {car.id}: {off:.2f} m from its start {car.start}")
        else:
            pose, start = ("untracked" if s.pose is not None else "not in the stream"), "-"
            if motive is None:
                out.missing.append(f"car {car.id}: rigid body {car.body_id} {pose} in Motive")
        if s.answer is not None:
            link = f"answers {s.rtt_ms:.1f} ms" + (", E-STOP" if s.answer.e_stop_latched else "")
        else:
            link = "no answer"
            out.missing.append(f"car {car.id}: no answer on its link {car.link or '(none configured)'}")
        if s.alive and s.status is not None:
            bus = f"{s.status.state}, trial {s.status.trial}"
        else:
            bus = "on the bus, no status" if s.alive else "not on the bus"
            out.missing.append(f"car {car.id}: its car process is {bus}")
        if s.clock is not None:
            offset, spread = s.clock
            clock = f"{offset * 1e3:+.1f} +- {spread * 1e3:.1f} ms"
            if abs(offset) - spread > tolerance:
                clock += " WARN"
                out.warnings.append(f"car {car.id}: its clock is {offset * 1e3:+.0f} ms off this one's "
                                    f"(tolerance {tolerance * 1e3:.0f} ms): check chrony (docs/lab-guide.md)")
        else:
            clock = "-"
        out.rows.append([str(car.id), str(car.body_id), pose, start, link, bus, clock])
    if others:
        out.warnings.append(f"rigid bodies {' '.join(map(str, others))} stream but belong to no car "
                            "(streaming ids: docs/lab-guide.md)")
    return out


def best_offset(samples: list[tuple[float, float, float]]) -> tuple[float, float] | None:
    """(offset, +-) of a clock from (sent, theirs, received) samples: the one with the
    shortest round trip, their clock against the middle of it (Cristian's method)."""
    if not samples:
        return None
    sent, theirs, received = min(samples, key=lambda s: s[2] - s[0])
    return theirs - (sent + received) / 2, (received - sent) / 2


def gather(fleet: Scenario, wait_s: float, listen: tuple[str, ...], use_natnet: bool) -> tuple[dict, str | None, list]:
    """Listen, ping and ask for ``wait_s``; what was seen."""
    seen = {car.id: Seen() for car in fleet.cars}
    bodies = {car.body_id: car.id for car in fleet.cars}
    client, motive = None, "not asked (--no-natnet)"
    if use_natnet:
        try:
            client = NatNetClient(client_options(fleet.natnet)).start()
            motive = None
        except NatNetConnectionError as exc:
            motive = str(exc)
    stopper = LinkStopper(fleet)
    inbox = messages.Inbox()
    try:
        with FleetBus(fleet.bus, fleet.fleet, None, listen=listen, kinds=("status",), operator_kinds=()) as bus:
            deadline = time.monotonic() + wait_s
            next_ping = 0.0
            while time.monotonic() < deadline:
                if time.monotonic() >= next_ping:
                    next_ping = time.monotonic() + 0.2
                    stopper.ping(seen)
                stopper.step(time.time())
                for received in bus.drain():
                    message = inbox.accept(received.payload, key_sender=received.sender)
                    if isinstance(message, messages.StatusMessage) and message.sender in seen:
                        seen[message.sender].status = message
                time.sleep(0.002)  # answers are read when they come: their round trip is the link's
            for car, answer in stopper.answers.items():
                seen[car].answer = answer
                seen[car].rtt_ms = (stopper.answered_at[car] - answer.stamp_s) * 1e3
            for car, up in bus.on_bus().items():
                if car in seen:
                    seen[car].alive = up
            for car in seen:
                if seen[car].alive:
                    samples = [bus.query_clocks(car, 0.5) for _ in range(CLOCK_QUERIES)]
                    seen[car].clock = best_offset([s for s in samples if s is not None])
    finally:
        stopper.close()
        others = []
        if client is not None:
            for body_id, sample in client.latest_all().items():
                car = bodies.get(body_id)
                if car is None:
                    others.append(body_id)
                    continue
                seen[car].tracked = sample.body.tracking_valid
                seen[car].pose = natnet.to_ground_plane(sample.body.position, sample.body.orientation,
                                                        fleet.natnet.up_axis)
            client.close()
    return seen, motive, sorted(others)


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg check", __doc__)
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--wait", type=float, default=3.0, help="seconds to listen before the table")
    parser.add_argument("--no-natnet", action="store_true", help="do not listen to Motive from here")
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on (repeatable)")
    args = parser.parse_args(argv)
    if not args.wait > 0:
        parser.error("--wait must be > 0")
    fleet = configured("trustfg check", lambda: load_scenario(args.config))
    print(f"trustfg check: {len(fleet.cars)} cars, motors held (PINGs only); listening {args.wait:.0f} s ...",
          flush=True)
    try:
        seen, motive, others = gather(fleet, args.wait, tuple(args.listen), not args.no_natnet)
    except BusError as exc:
        print(f"trustfg check: the bus: {exc}", file=sys.stderr)
        return 1
    out = report(fleet, seen, motive, others)
    problem = scene_problem(fleet)
    if problem is not None:
        out.warnings.append(f"the scene: {problem}")
    widths = [max(len(row[i]) for row in out.rows) for i in range(len(out.rows[0]))]
    for row in out.rows:
        print("  ".join(cell.ljust(width) for cell, width in zip(row, widths)).rstrip())
    for line in out.warnings:
        print(f"warning: {line}")
    for line in out.missing:
        print(f"missing: {line}")
    if not out.missing and not out.warnings:
        print("nothing missing")
    return 1 if out.missing or out.warnings else 0

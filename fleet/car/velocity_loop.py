"""A car's velocity loop, in a process of its own: the 50 Hz ticks never wait for planning.

The car process spawns it through fleet.car.velocity_handle and feeds it through one
pipe: ``("plan", plan)``, ``("permit", Permit)`` (what the operator's protocol lets the
car do, valid until its lease, ``control.lease_s`` on ``time.monotonic()``, runs out) and
``("quit",)``. The loop owns its own NatNet client, the car link and, at
``control.command_rate_hz`` on absolute deadlines, the control step both simulations
share (bridge.drive), the turn between laps and the motion watch. A lapsed lease stops the
car (an e-stop kept) until a fresh permit comes; a closed pipe sends STOP and ends the
loop. It reports through shared memory, so it never waits for its parent, and runs at
SCHED_FIFO ``control.realtime_priority`` where the OS grants it (else it says so once).
docs/design/architecture.md, "The velocity loop", tells the whole of it.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import signal
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field, fields
from typing import Any

from ...agent.config import CarConfig, Scenario
from ...agent.gp import Plan
from ...agent.guard import reaction_time
from ...agent.sight import in_sight
from ...agent.world import SignedDistanceField
from ...bridge import natnet
from ...bridge.carlink import SOURCE_CAR_PROCESS, CommandSender, Flags
from ...bridge.drive import drive
from ...bridge.motion_watch import MotionWatch
from ...bridge.natnet_client import NatNetClient, NatNetConnectionError, client_options, fresh_pose
from ...bridge.trajectory_controller import turn_towards
from .report import ControlStats
from .ticker import ticks

log = logging.getLogger("trustfg.fleet.car.velocity_loop")

SWITCH_INTERVAL_S = 0.001
GAP_WINDOW_S = 5.0
"""The guard's command hold is the longest gap between control ticks over this window: a
process that stalled lately is taken to stall again (tests/agent/test_guard.py)."""
@dataclass(frozen=True)
class Report:
    """The loop's counters as last written (``answered_at``: fleet clock, -inf: never)."""

    ticks: int = 0
    sent: int = 0
    stops: int = 0
    stale_pose_stops: int = 0
    guard_limited: int = 0
    lease_lapsed: int = 0
    stuck: bool = False
    answers: int = 0
    latched: bool = False
    answered_at: float = -math.inf
    natnet_up: bool = False
    realtime: bool = False


REPORT_FIELDS = tuple(f.name for f in fields(Report))
"""What the loop reports through shared memory (floats), in this order."""
REPORT_INDEX = {name: i for i, name in enumerate(REPORT_FIELDS)}
REPORT_KINDS = {f.name: type(f.default) for f in fields(Report)}
"""How each float reads back (int, bool or float, by the field's default)."""


@dataclass(frozen=True)
class Permit:
    """What the operator's protocol lets the car do, until ``valid_until`` (monotonic)."""

    may_drive: bool = False
    """A trial runs, its departure passed, the operator is heard (agent.operator_state)."""
    at_goal: bool = False
    e_stop: bool = False
    release: bool = False
    trial: int = 0
    turn: tuple[float, float] = (0.0, -math.inf)
    """(heading, until): turning in place between laps until ``until`` (fleet clock)."""
    valid_until: float = -math.inf


@dataclass(frozen=True)
class Allowed:
    """What a tick may do under a permit at a given moment."""

    go: bool
    e_stop: bool
    release: bool
    lapsed: bool


def allowed(permit: Permit, now_mono: float) -> Allowed:
    """The lease rule: past ``valid_until`` nothing but stopping -- an e-stop kept, a
    release not (a RELEASE must never be sent on an old word)."""
    lapsed = now_mono > permit.valid_until
    return Allowed(go=permit.may_drive and not permit.at_goal and not permit.e_stop and not lapsed,
                   e_stop=permit.e_stop, release=permit.release and not permit.e_stop and not lapsed,
                   lapsed=lapsed)


@dataclass(frozen=True)
class LoopSettings:
    """Everything the spawned loop needs (pickled once, at spawn)."""

    scenario: Scenario
    car_id: int
    sdf: SignedDistanceField
    """The car process's field, sent rather than built again (scipy stays out of the loop)."""
    log_level: int = logging.INFO


def realtime(priority: int) -> str:
    """Ask for SCHED_FIFO at ``priority`` for this process (0: do not); the scheduling we got."""
    if priority <= 0 or not hasattr(os, "sched_setscheduler"):
        return "normal"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return f"fifo {priority}"
    except (PermissionError, OSError) as exc:
        log.info("command loop at normal priority: real-time priority %d not granted (%s)", priority, exc)
        return "normal"


def name_process(name: str) -> None:
    """Name this process as ps, top and /proc/PID/comm show it (Linux; 15 bytes kept)."""
    try:
        import ctypes

        ctypes.CDLL(None).prctl(15, name.encode()[:15], 0, 0, 0)  # PR_SET_NAME
    except (OSError, AttributeError):
        pass


# --- the spawned process ---------------------------------------------------------------------


@dataclass
class VelocityLoop:
    """The command process's state; ``tick`` is one control step (:func:`serve` runs them
    at the command rate; benchmarks/bench_velocity_tick.py times one car's)."""

    scenario: Scenario
    car: CarConfig
    report: Any
    clock: Any
    sdf: Any
    plan: Plan | None = None
    permit: Permit = Permit()
    natnet: NatNetClient | None = None
    control: ControlStats = field(default_factory=ControlStats)
    motion: MotionWatch = field(default_factory=MotionWatch)
    trial: int = 0
    lapsed_since: float | None = None
    counts: dict = field(default_factory=lambda: dict.fromkeys(REPORT_FIELDS, 0.0))

    def _publish(self, name: str, value: float) -> None:
        self.counts[name] = value
        self.report[REPORT_INDEX[name]] = value

    def own_pose(self) -> tuple[tuple[float, float, float], float] | None:
        """The car's own fresh, tracked pose (x, y, yaw) and its age in seconds."""
        return fresh_pose(self.natnet, self.car.body_id, self.scenario.control.pose_timeout_s,
                          self.scenario.natnet.up_axis)

    def others_seen(self) -> list[tuple[float, float, float, float]]:
        """Fresh, tracked poses (x, y, yaw) and radii of every other car of the fleet, or
        with a sensing range of those within it (the guard sees what the car sees:
        docs/design/safety.md, "Limited sight")."""
        now_mono, up = time.monotonic(), self.scenario.natnet.up_axis
        radii = {c.body_id: c.radius_m for c in self.scenario.cars if c.id != self.car.id}
        others = []
        for body_id, sample in (self.natnet.latest_all() if self.natnet is not None else {}).items():
            if (body_id not in radii or not sample.body.tracking_valid
                    or now_mono - sample.received_s > self.scenario.control.pose_timeout_s):
                continue
            x, y, yaw = natnet.to_ground_plane(sample.body.position, sample.body.orientation, up)
            if math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw):
                others.append((x, y, yaw, radii[body_id]))
        sight = self.scenario.sensing_range(self.car)
        if others and math.isfinite(sight):
            own = self.own_pose()
            seen = in_sight(own[0][:2], [o[:2] for o in others], sight,
                            self.sdf if self.scenario.sensing.line_of_sight else None) if own else []
            others = [o for o, ok in zip(others, seen) if ok]
        return others

    def take(self, message: tuple) -> bool:
        """A message from the car process; False on quit."""
        kind = message[0]
        if kind == "plan":
            self.plan = message[1]
        elif kind == "permit":
            self.permit = message[1]
            if self.permit.trial != self.trial:  # a new trial: the motion watch starts afresh
                self.trial = self.permit.trial
                self.motion.clear()
                self._publish("stuck", 0.0)
        elif kind == "quit":
            return False
        return True

    def tick(self, sender: CommandSender, now_mono: float, tick_gap_s: float) -> None:
        """One command: see the module docstring (and fleet.car.process for the rules)."""
        may = allowed(self.permit, now_mono)
        if may.lapsed and self.permit.valid_until > -math.inf:
            self._publish("lease_lapsed", self.counts["lease_lapsed"] + 1)
            if self.lapsed_since is None:
                self.lapsed_since = now_mono
                log.warning("car %d: the car process's permit lapsed %.2f s ago: stopping the car",
                            self.car.id, now_mono - self.permit.valid_until)
        elif not may.lapsed and self.lapsed_since is not None:
            log.info("car %d: a fresh permit after %.2f s", self.car.id, now_mono - self.lapsed_since)
            self.lapsed_since = None
        flags = Flags.E_STOP if may.e_stop else Flags.RELEASE if may.release else Flags.NONE
        seen = self.own_pose()
        pose, age = seen if seen is not None else (None, 0.0)
        now = self.clock()
        control = self.control
        heading, until = self.permit.turn
        turning = pose is not None and may.go and now < until
        if pose is None:
            control.stale_pose_stops += 1
            control.stops += 1
            sender.send(0.0, 0.0, Flags.STOP | flags)
        elif turning:  # between laps: turning in place towards the next leg
            sender.send(0.0, turn_towards(heading, pose[2], self.scenario.tracking, self.scenario.vehicle), flags)
        else:  # the control step both simulations share (bridge.drive): STOP without a plan or leave
            command = drive(self.plan, now, pose, may.go, self.others_seen, self.car.radius_m, self.scenario,
                            self.sdf, reaction_time(age, tick_gap_s, self.scenario.guard))
            if command.stop:
                control.stops += 1
                sender.send(0.0, 0.0, Flags.STOP | flags)
            else:
                control.guard_limited += command.guard_limited
                sender.send(command.v, command.omega, flags)
                if self.motion.add(now, pose[0], pose[1], command.v):
                    self._publish("stuck", float(self.motion.stuck))
                    log.info("car %d: %s: %s", self.car.id, "stuck" if self.motion.stuck else "moving again",
                             self.motion.why)
        control.sent += 1
        for name in ("sent", "stops", "stale_pose_stops", "guard_limited", "ticks"):
            self._publish(name, getattr(control, name))

    def answered(self, latched: bool) -> None:
        self._publish("latched", float(latched))
        self._publish("answered_at", self.clock())
        self._publish("answers", self.counts["answers"] + 1)


def connect_motive(loop: VelocityLoop, stop: threading.Event) -> None:
    """Reach Motive (retrying every ``control.retry_s``) and hand the client to the loop."""
    # A tick reads the newest pose: frames are taken from the socket and decoded when it
    # asks, not as they come (50 Hz of Motive's 120-360; the same pose, with its own
    # arrival time), and no thread wakes for each.
    options = dataclasses.replace(client_options(loop.scenario.natnet), decode_on_read=True, pull=True)
    while not stop.is_set():
        client = NatNetClient(options)
        try:
            client.start()
        except NatNetConnectionError as exc:
            log.debug("car %d: command loop waits for Motive: %s", loop.car.id, exc)
            stop.wait(loop.scenario.control.retry_s)
            continue
        if stop.is_set():
            client.close()
            return
        loop.natnet = client
        loop._publish("natnet_up", 1.0)
        return


def serve(settings: LoopSettings, conn: Any, report: Any) -> None:
    """The command process's main: ticks until told to quit or its pipe closes."""
    logging.basicConfig(level=settings.log_level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    stop = threading.Event()
    # Ctrl-C and a SIGTERM to the process group reach the car process too, which stops us
    # once it is done (its summary needs ours); its death closes our pipe, which stops us.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    scenario = settings.scenario
    car = scenario.car(settings.car_id)
    name_process(f"trustfg-cmd-{car.id}")  # ps and top show it; the spawn command line does not say
    scheduling = realtime(scenario.control.realtime_priority)  # before any thread: they inherit it
    offset = car.clock_offset_s
    loop = VelocityLoop(scenario, car, report, clock=lambda: time.time() + offset, sdf=settings.sdf)
    loop._publish("realtime", float(scheduling != "normal"))
    connector = threading.Thread(target=connect_motive, args=(loop, stop), name=f"natnet-connect-{car.id}", daemon=True)
    connector.start()
    rate = scenario.control.command_rate_hz
    gaps: deque[float] = deque(maxlen=int(GAP_WINDOW_S * rate))
    with CommandSender.for_car(car, source=SOURCE_CAR_PROCESS, stamp_clock=loop.clock) as sender:
        loop.control.started = time.monotonic()
        next_ping = loop.control.started
        last = None
        for deadline, now_mono in ticks(1.0 / rate, stop):
            loop.control.add(max(0.0, now_mono - deadline) * 1e3, int(60 * rate))
            gaps.append(1.0 / rate if last is None else now_mono - last)
            last = now_mono
            try:
                while conn.poll():
                    if not loop.take(conn.recv()):
                        stop.set()
            except (EOFError, OSError):  # the car process is gone: stop the car, then ourselves
                log.warning("car %d: the car process is gone: stopping the car", car.id)
                stop.set()
            if stop.is_set():
                break
            try:
                loop.tick(sender, now_mono, max(gaps))
                if now_mono >= next_ping:
                    next_ping = max(next_ping + scenario.control.link_ping_period_s, now_mono)
                    sender.send(0.0, 0.0, Flags.STOP | Flags.PING)
                for answer in sender.answers():
                    loop.answered(answer.e_stop_latched)
            except Exception:  # a bad tick must not take the car's brakes with it
                log.exception("car %d: control tick failed; commanding stop", car.id)
                sender.send(0.0, 0.0, Flags.STOP | (Flags.E_STOP if loop.permit.e_stop else 0))
        loop.control.stopped = time.monotonic()
        sender.stop()  # STOP datagrams (E_STOP kept) before anything else
        summary = loop.control.summary() | {"scheduling": scheduling,
                                            "lease_lapsed": int(loop.counts["lease_lapsed"])}
        link = {"link_sent": sender.stats.sent, "link_answers": sender.stats.answers}
    stop.set()
    if loop.natnet is not None:
        loop.natnet.close()
    try:
        conn.send(("final", summary, link))
    except (OSError, ValueError):
        pass

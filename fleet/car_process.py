"""``trustfg car --id N --config FILE``: one car's process, agent and bridge together.

Threads, each owning what it touches:

* the NatNet client's socket thread hands every frame to a queue (and keeps the latest
  pose of every rigid body);
* Zenoh's callbacks hand every fleet message to the bus queue (trustfg.fleet.bus);
* the control thread, at ``control.command_rate_hz`` on absolute deadlines, reads the
  car's own latest pose and the current plan and sends one command datagram: the
  tracking command, or STOP when there is no fresh pose (older than
  ``control.pose_timeout_s``), no plan, no start yet, or the car has arrived; the
  tracking speed is capped by the proximity guard (bridge.guard) against the other cars
  it sees and the walls of the map;
* the main thread runs the agent: it drains frames and messages, gathers evidence,
  replans every ``control.replan_period_s`` and publishes plan, trust, pose and status.

A car that does not move although it is told to (its command link is cut, it is
blocked, its motors are off) is *stuck*: after ``STUCK_AFTER_S`` of commanded motion
without motion, the process keeps commanding its plan (so the car goes again if it can)
but tells its peers the truth -- a plan that stands still where the car stands -- so
nobody waits for a car that announces it is about to drive through.

The planner (GTSAM, numpy) holds the GIL while it works; the control thread is kept
responsive by a short interpreter switch interval, and its timing (command rate, jitter)
is measured and reported. SIGTERM or SIGINT stops the loops, sends STOP to the car, and
closes every socket and session. ``--stats FILE`` writes a JSON summary at exit.

The car is chosen by addresses in the config (its NatNet server, its ``link``), never by
a simulation switch: the same process drives a real car or one of mocap_sim's.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import logging
import math
import sys
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..agent import messages
from ..agent.car_agent import CarAgent
from ..agent.config import CarConfig, ConfigError, Scenario
from ..agent.gp import standing
from ..agent.scenario_files import load_scenario
from ..agent.world import build_sdf
from ..bridge import natnet
from ..bridge.carlink import CommandSender, Flags, link_key
from ..bridge.drive import drive
from ..bridge.natnet_client import NatNetClient, NatNetClientOptions
from .bus import FleetBus, Received
from .command import configured, stop_on_signals
from .laps import Laps
from .ticker import ticks

log = logging.getLogger(__name__)

SWITCH_INTERVAL_S = 0.001
STUCK_AFTER_S = 0.8
STUCK_COMMAND_MPS = 0.1
STUCK_MOTION_MPS = 0.03


def natnet_options(scenario: Scenario) -> NatNetClientOptions:
    """The NatNet client's options from the config; ConfigError for a version the codec
    does not decode."""
    n = scenario.natnet
    if n.version and n.version not in natnet.STREAM_VERSIONS:
        raise ConfigError(f"natnet.version: {n.version} is not one the bridge decodes "
                          f"({', '.join(natnet.STREAM_VERSIONS)})")
    version = natnet.Version.parse(n.version) if n.version else None
    return NatNetClientOptions(
        server_address=n.server, command_port=n.command_port, multicast=n.mode == "multicast",
        multicast_group=n.multicast_group, data_port=n.data_port, local_address=n.local_interface,
        natnet_version=version, handshake=version is None or n.mode == "unicast",
    )


@dataclass
class ControlStats:
    """Timing of the control loop, measured on the loop itself."""

    sent: int = 0
    stops: int = 0
    stale_pose_stops: int = 0
    guard_limited: int = 0
    """Ticks whose forward speed the proximity guard lowered (bridge.guard)."""
    late_ms: deque = field(default_factory=lambda: deque(maxlen=100_000))
    """Lateness of the latest ticks (bounded: a lab run may last hours)."""
    late_p99_by_minute: deque = field(default_factory=lambda: deque(maxlen=24 * 60))
    """p99 lateness of every minute of ticks, ms (does the timing hold over hours?)."""
    ticks: int = 0
    started: float = 0.0
    stopped: float = 0.0

    def add(self, late_ms: float, per_minute: int) -> None:
        self.late_ms.append(late_ms)
        self.ticks += 1
        if self.ticks % per_minute == 0:
            minute = list(itertools.islice(reversed(self.late_ms), per_minute))
            self.late_p99_by_minute.append(round(float(np.percentile(minute, 99)), 3))

    def summary(self) -> dict:
        elapsed = max(self.stopped - self.started, 1e-9)
        late = np.array(self.late_ms) if self.late_ms else np.zeros(1)
        return {
            "sent": self.sent, "stops": self.stops, "stale_pose_stops": self.stale_pose_stops,
            "guard_limited": self.guard_limited, "rate_hz": round(self.sent / elapsed, 2),
            "jitter_ms_p50": round(float(np.percentile(late, 50)), 3),
            "jitter_ms_p99": round(float(np.percentile(late, 99)), 3),
            "jitter_ms_max": round(float(np.max(late)), 3),
            "late_ms_p99_by_minute": list(self.late_p99_by_minute),
        }


class CarProcess:
    """Everything one car runs; ``run()`` returns when ``stop`` is set."""

    def __init__(self, scenario: Scenario, car: CarConfig, clock=time.time):
        if not car.link:
            raise ConfigError(f"cars[id={car.id}].link: a car process needs the address of its car")
        self.scenario = scenario
        self.car = car
        self.clock = clock
        self.natnet = natnet_options(scenario)
        link_key(car)  # a missing or bad key is a config error now, not when driving
        self.stop = threading.Event()
        self.agent = CarAgent(car=car, scenario=scenario, sdf=build_sdf(scenario.world),
                              depart_at=math.inf, clock=time.perf_counter)
        self.inbox = messages.Inbox()
        self.frames: deque = deque(maxlen=4096)
        self.counters: Counter = Counter()
        self.control = ControlStats()
        self.started = False
        self.state = "waiting"
        self._plan = None  # what the control thread follows (swapped atomically)
        self._bodies = {c.body_id: c.id for c in scenario.cars}
        self._seq: Counter = Counter()
        self._alive: dict[int, bool] = {}
        self.stuck = False
        self._motion: deque = deque()  # (t, x, y, commanded v) of the control loop
        self.laps = Laps(car, scenario.control.laps, scenario.control.lap_turn_s)

    # --- inputs ---------------------------------------------------------------------------

    def _on_frame(self, frame: natnet.Frame) -> None:
        """NatNet socket thread: hand over, never block (the oldest goes, counted, if the
        agent loop fell that far behind)."""
        if len(self.frames) == self.frames.maxlen:
            self.counters["frames_overflowed"] += 1
        self.frames.append((self.clock(), frame))

    def _observe_frames(self) -> None:
        up = self.scenario.natnet.up_axis
        while self.frames:
            t, frame = self.frames.popleft()
            for body in frame.rigid_bodies:
                car_id = self._bodies.get(body.id)
                if car_id is None or not body.tracking_valid:
                    continue
                x, y, yaw = natnet.to_ground_plane(body.position, body.orientation, up)
                if all(map(math.isfinite, (x, y, yaw))):
                    self.agent.observe(t, car_id, x, y, yaw)

    def _handle(self, received: Received) -> None:
        message = self.inbox.accept(received.payload, key_sender=received.sender)
        if message is None:
            return
        if isinstance(message, messages.StartMessage):
            self._start(message)
        elif isinstance(message, (messages.PlanMessage, messages.TrustReport)):
            self.agent.receive(message, received.at)

    def _start(self, message: messages.StartMessage) -> None:
        if self.started or self.car.id not in message.departures:
            return
        depart, cruise = message.departures[self.car.id]
        self.agent.set_departure(depart, cruise)
        self.started = True
        self.state = "driving"
        log.info("car %d: start at %.2f (in %.2f s), cruise %.2f m/s", self.car.id, depart,
                 depart - self.clock(), cruise)

    # --- the control thread -----------------------------------------------------------------

    def _own_pose(self, natnet_client: NatNetClient) -> tuple[float, float, float] | None:
        sample = natnet_client.latest(self.car.body_id)
        if sample is None or not sample.body.tracking_valid:
            return None
        if time.monotonic() - sample.received_s > self.scenario.control.pose_timeout_s:
            return None
        return natnet.to_ground_plane(sample.body.position, sample.body.orientation,
                                      self.scenario.natnet.up_axis)

    def _others_seen(self, natnet_client: NatNetClient) -> list[tuple[float, float, float, float]]:
        """Fresh, tracked poses (x, y, yaw) and radii of every other car of the fleet."""
        now_mono, up = time.monotonic(), self.scenario.natnet.up_axis
        others = []
        for body_id, sample in natnet_client.latest_all().items():
            car_id = self._bodies.get(body_id)
            if (car_id is None or car_id == self.car.id or not sample.body.tracking_valid
                    or now_mono - sample.received_s > self.scenario.control.pose_timeout_s):
                continue
            x, y, yaw = natnet.to_ground_plane(sample.body.position, sample.body.orientation, up)
            if math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw):
                others.append((x, y, yaw, self.agent.radius(car_id)))
        return others

    def _control_loop(self, natnet_client: NatNetClient, sender: CommandSender) -> None:
        self.control.started = time.monotonic()
        for deadline, now_mono in ticks(1.0 / self.scenario.control.command_rate_hz, self.stop):
            self.control.add(max(0.0, now_mono - deadline) * 1e3, int(60 * self.scenario.control.command_rate_hz))
            try:
                self._command(natnet_client, sender)
            except Exception:  # a bad tick must not take the car's brakes with it
                log.exception("car %d: control tick failed; commanding stop", self.car.id)
                sender.send(0.0, 0.0, Flags.STOP)
        self.control.stopped = time.monotonic()

    def _command(self, natnet_client: NatNetClient, sender: CommandSender) -> None:
        pose = self._own_pose(natnet_client)
        plan = self._plan
        now = self.clock()
        turn = pose and self.laps.turn_command(now, pose[2], self.scenario.tracking, self.scenario.vehicle)
        if pose is None:
            self.control.stale_pose_stops += 1
            self.control.stops += 1
            sender.send(0.0, 0.0, Flags.STOP)
        elif turn:  # between laps: turning in place towards the next leg
            sender.send(*turn)
        elif plan is None or not self.started or now < self.agent.depart_at or self.agent.at_goal:
            self.control.stops += 1
            sender.send(0.0, 0.0, Flags.STOP)
        else:  # the control step both simulations share (bridge.drive)
            command = drive(plan, now, pose, True, lambda: self._others_seen(natnet_client), self.car.radius_m,
                            self.scenario, self.agent.sdf)
            self.control.guard_limited += command.guard_limited
            sender.send(command.v, command.omega)
            self._watch_motion(now, pose, command.v)
        self.control.sent += 1

    def _watch_motion(self, now: float, pose: tuple[float, float, float], v_commanded: float) -> None:
        """Set ``stuck`` while the car does not move though commanded to; clear it when it moves."""
        self._motion.append((now, pose[0], pose[1], v_commanded))
        while self._motion and self._motion[0][0] < now - STUCK_AFTER_S:
            self._motion.popleft()
        t0, x0, y0, _ = self._motion[0]
        if now - t0 < 0.5 * STUCK_AFTER_S:
            return
        speed = math.hypot(pose[0] - x0, pose[1] - y0) / (now - t0)
        commanded = min(v for *_, v in self._motion)
        if not self.stuck and commanded > STUCK_COMMAND_MPS and speed < STUCK_MOTION_MPS and now - t0 >= 0.9 * STUCK_AFTER_S:
            self.stuck = True
            self.counters["stuck"] += 1
            log.warning("car %d: commanded %.2f m/s but not moving: telling peers it stands still", self.car.id, commanded)
        elif self.stuck and speed > 2 * STUCK_MOTION_MPS:
            self.stuck = False
            log.info("car %d: moving again", self.car.id)

    # --- the main loop -------------------------------------------------------------------------

    def run(self, stats_path: Path | None = None) -> int:
        scenario, car = self.scenario, self.car
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        log.info("car %d: NatNet %s at %s, link %s (version %d)", car.id, scenario.natnet.mode, scenario.natnet.server,
                 car.link, car.link_version)
        with CommandSender.for_car(car, stamp_clock=self.clock) as sender, \
                NatNetClient(self.natnet, on_frame=self._on_frame) as natnet_client, \
                FleetBus(scenario.bus, scenario.fleet, car.id, listen=car.listen, clock=self.clock) as bus:
            controller = threading.Thread(target=self._control_loop, args=(natnet_client, sender),
                                          name=f"control-{car.id}", daemon=True)
            controller.start()
            try:
                self._main_loop(bus, natnet_client)
            finally:
                self.stop.set()
                controller.join(timeout=2.0)
                sender.stop()  # STOP datagrams before the socket closes
                self.state = "stopped"
                self._publish_status(bus)
                if stats_path is not None:
                    self._write_stats(stats_path, natnet_client, bus, sender)
        return 0

    def _main_loop(self, bus: FleetBus, natnet_client: NatNetClient) -> None:
        control = self.scenario.control
        started_wait = self.clock()
        now = self.clock()
        next_replan = next_plan = now
        next_trust = now + control.trust_report_period_s * (self.car.id % 7) / 7
        next_pose = now
        next_status = now
        while not self.stop.is_set():
            now = self.clock()
            self._observe_frames()
            for received in bus.drain():
                self._handle(received)
            for peer, up in list(bus.alive.items()):
                if not up and self._alive.get(peer, True):
                    log.warning("car %d: car %d left the bus", self.car.id, peer)
                    self.agent.peer_gone(peer)
                self._alive[peer] = up
            if not self.started and control.start_timeout_s and now - started_wait > control.start_timeout_s:
                log.warning("car %d: no start message for %.0f s; starting now", self.car.id, control.start_timeout_s)
                self._start(messages.StartMessage(0, now, {self.car.id: (now, self.scenario.planner.cruise_speed_mps)}))
            self.agent.gather_evidence(now)
            if now >= next_replan:
                next_replan += control.replan_period_s
                if now - next_replan > control.replan_period_s:
                    next_replan = now + control.replan_period_s  # do not try to catch up
                self._replan(now)
                next_plan = now + control.plan_period_s
                self._publish_plan(bus, now, repeat=False)  # a new plan goes out at once, both ways
            if now >= next_plan:  # and again every plan_period_s, best effort: a lost plan is soon replaced
                next_plan = max(next_plan + control.plan_period_s, now)
                self._publish_plan(bus, now, repeat=True)
            if now >= next_trust:
                next_trust = max(next_trust + control.trust_report_period_s, now)
                bus.publish("trust", messages.encode(self.agent.trust_message(now)))
            if now >= next_pose:
                next_pose = max(next_pose + control.pose_period_s, now)
                self._publish_pose(bus, natnet_client, now)
            if now >= next_status:
                next_status = max(next_status + control.status_period_s, now)
                self._publish_status(bus)
            bus.wait(0.005)  # wakes at once when a message arrives

    def _replan(self, now: float) -> None:
        if not self.started:
            own = self.agent.tracks.get(self.car.id)
            motion = own.motion() if own else None
            if motion is not None:  # show where we stand until we may go
                self.agent.plan = standing(motion.position, now)
        else:
            try:
                self.agent.replan(now)
            except Exception:  # keep the last plan; the car keeps tracking it
                log.exception("car %d: replanning raised", self.car.id)
                self.counters["replan_errors"] += 1
        own = self.agent.tracks.get(self.car.id)
        motion = own.motion() if own else None
        if motion is not None and self.laps.advance(self.agent, tuple(motion.position), now):
            log.info("car %d: lap %d of %d", self.car.id, self.laps.lap, self.laps.laps)
        if self.arrived:
            self.state = "arrived"
        elif self.started:
            self.state = "stuck" if self.stuck else "driving"
        self._plan = self.agent.plan

    @property
    def arrived(self) -> bool:
        """At the goal of the last lap."""
        return self.agent.at_goal and self.laps.done

    def _publish_plan(self, bus: FleetBus, now: float, repeat: bool) -> None:
        outgoing = self.agent.plan_message(now)
        own = self.agent.tracks.get(self.car.id)
        motion = own.motion() if own else None
        if outgoing is not None and self.stuck and motion is not None:  # the truth: standing still
            outgoing = dataclasses.replace(outgoing, plan=standing(motion.position, now))
        if outgoing is not None:
            bus.publish("plan", messages.encode(outgoing), repeat=repeat)

    def _publish_pose(self, bus: FleetBus, natnet_client: NatNetClient, now: float) -> None:
        pose = self._own_pose(natnet_client)
        x, y, yaw = pose if pose is not None else (0.0, 0.0, 0.0)
        self._seq["pose"] += 1
        bus.publish("pose", messages.encode(messages.PoseMessage(
            self.car.id, self._seq["pose"], now, x, y, yaw, pose is not None)))

    def _publish_status(self, bus: FleetBus) -> None:
        self._seq["status"] += 1
        last = self.agent.last_result
        counters = {k: v for k, v in (self.agent.counters | self.counters).items()}
        counters |= {f"inbox_{k}": v for k, v in self.inbox.dropped.items()}
        counters["commands_sent"] = self.control.sent
        counters["stale_pose_stops"] = self.control.stale_pose_stops
        counters["guard_limited"] = self.control.guard_limited
        counters["lap"] = self.laps.lap
        now = self.clock()
        for peer, view in self.agent.peers.items():  # how fresh each peer's plan is, for resync checks
            counters[f"plan_age_ms_{peer}"] = int(min(1e9, max(0.0, now - view.accepted_received) * 1e3))
        bus.publish("status", messages.encode(messages.StatusMessage(
            self.car.id, self._seq["status"], self.clock(), self.state,
            last.time_ms if last else 0.0, last.iterations if last else 0, self.arrived,
            dict(sorted(counters.items(), key=lambda kv: not kv[0].startswith(("plan", "deadlock")))[:64]))))

    def _write_stats(self, path: Path, natnet_client: NatNetClient, bus: FleetBus,
                     sender: CommandSender) -> None:
        nat = natnet_client.stats()
        stats = {
            "car_id": self.car.id,
            "state": self.state,
            "at_goal": self.arrived,
            "replan_ms": [round(x, 3) for x in self.agent.replan_ms],
            "control": self.control.summary(),
            "agent": dict(self.agent.counters),
            "trust": dict(self.agent.trust.counters),
            "inbox_dropped": dict(self.inbox.dropped),
            "inbox_accepted": dict(self.inbox.accepted),
            "bus": dict(bus.counters),
            "natnet": {"received": nat.received, "decoded": nat.decoded, "dropped": nat.dropped,
                       "rejected": dict(nat.rejected)},
            "link_sent": sender.stats.sent,
        }
        path.write_text(json.dumps(stats, indent=1))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="trustfg car", description="Run one car: agent and bridge.")
    parser.add_argument("--id", type=int, required=True, help="this car's id (a [[cars]] entry of the config)")
    parser.add_argument("--config", required=True, help="fleet config: a TOML file or a shipped name (lab/fleet)")
    parser.add_argument("--stats", type=Path, default=None, help="write a JSON summary here at exit")
    args = parser.parse_args(argv)
    def build() -> CarProcess:
        scenario = load_scenario(args.config)
        return CarProcess(scenario, scenario.car(args.id))

    process = configured("trustfg car", build)
    stop_on_signals(process.stop)
    return process.run(args.stats)

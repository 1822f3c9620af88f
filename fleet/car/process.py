"""``trustfg car --id N --config FILE``: one car's process, agent and bridge together.

The main thread runs the agent: each pass pulls the waiting NatNet datagrams (the client has
no thread), drains the fleet messages Zenoh's callbacks queued (fleet.bus.session), hands
the operator's messages to :class:`~trustfg.agent.operator_state.Operation`, gathers
evidence, replans every ``control.replan_period_s`` and publishes plan, trust, pose and
status. The 50 Hz velocity loop is a process of its own (fleet.car.velocity_loop, fed
through fleet.car.velocity_handle): it commands STOP from the first tick and drives only
on a permit this loop renews on every pass. Before Motive, the bus or the peers answer,
the process holds its car, says in one line what it waits for and retries; a car told to
drive that does not move is *stuck*, and its plans say so. The car is chosen by addresses
in the config, never by a simulation switch. docs/design/architecture.md, "The car
process", tells the whole of it.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import threading
import time
from collections import Counter, deque
from pathlib import Path

from ...agent import messages
from ...agent.car_agent import CarAgent
from ...agent.config import CarConfig, ConfigError, Scenario
from ...agent.gp import standing
from ...agent.operator_state import Mode, Operation
from ...agent.planner import warm_compiled
from ...agent.scenario_files import load_scenario
from ...agent.sight import visible
from ...agent.world import build_sdf
from ...bridge import natnet
from ...bridge.carlink import link_key
from ...bridge.natnet_client import NatNetClient, NatNetConnectionError, client_options, fresh_pose
from ..bus.key_exprs import HEARD_BY_CARS
from ..bus.session import FleetBus, Received
from ..bus.zenoh_setup import BusError, zenoh_config
from ..cpu import Sections, Snapshot, Tally, breakdown, snapshot
from ..program import command_parser, configured, stop_on_signals
from .laps import Laps
from .report import WaitingLog, status_counters, waiting_for, write_stats
from .velocity_handle import VelocityLoopHandle
from .velocity_loop import Report

log = logging.getLogger(__name__)


class CarProcess:
    """Everything one car runs; ``run()`` returns when ``stop`` is set."""

    def __init__(self, scenario: Scenario, car: CarConfig, clock=None):
        if not car.link:
            raise ConfigError(f"cars[id={car.id}].link: a car process needs the address of its car")
        try:  # a bad [bus] or zenoh_config file is the config's fault: one line now, not retries
            zenoh_config(scenario.bus, car.listen)
        except BusError as exc:
            raise ConfigError(str(exc)) from None
        self.scenario = scenario
        self.car = car
        if clock is None and car.clock_offset_s:
            log.warning("car %d: running with a clock %+.3f s off the fleet's (clock_offset_s, for tests)",
                        car.id, car.clock_offset_s)
        self.clock = clock or (lambda: time.time() + car.clock_offset_s)
        # The agent takes poses at the command rate, as in the in-process fleet (its
        # validated rate): the frames between are left undecoded (Motive streams 120-360 Hz).
        self.natnet = dataclasses.replace(client_options(scenario.natnet), pull=True,
                                          max_frame_rate_hz=scenario.control.command_rate_hz)
        link_key(car)  # a missing or bad key is a config error now, not when driving
        self.stop = threading.Event()
        self.sdf = build_sdf(scenario.world)
        self._sight_sdf = self.sdf if scenario.sensing.line_of_sight else None
        """The map that hides peers behind walls (SensingConfig.line_of_sight), else None."""
        self.agent = self._new_agent()
        self.operation = Operation(car.id, scenario.operator)
        self.inbox = messages.Inbox()
        self.frames: deque = deque(maxlen=4096)
        self.counters: Counter = Counter()
        self.command = VelocityLoopHandle(scenario, car, self.sdf)
        self.command_report = Report()
        self.stuck = False
        self.state = Mode.WAITING.value
        self._natnet: NatNetClient | None = None  # set by the connector thread once Motive answers
        self._natnet_problem = "connecting"
        self._waiting = WaitingLog(car.id)
        self._plan = None  # what the command loop follows
        self._bodies = {c.body_id: c.id for c in scenario.cars}
        self._seq: Counter = Counter()
        self._alive: dict[int, bool] = {}
        """Peers' liveliness tokens as last seen (a token going down: the peer left)."""
        self._on_bus: dict[int, bool] = {}
        """Peers on the bus by token or, a token lost by Zenoh, by hearing (FleetBus.on_bus)."""
        self.laps = Laps(car, scenario.control.laps, scenario.control.lap_turn_s)
        self.sections = Sections()
        """The main thread's CPU by section of its loop (fleet.cpu)."""
        self._driving_cpu: list[Snapshot] = []
        """Snapshots as the car starts to drive and as it stops (its first trial)."""
        self.replan_cpu: dict[str, Tally] = {}
        """Per replan outcome (first, retry, fallback, kept, ...): the replans and their CPU."""
        self.first_broke: Counter = Counter()
        """Replans whose first plan failed verification, by what it broke ('limits',
        'limits+peer', ...; agent.safe_plan.Outcome.first_broke)."""

    def _new_agent(self) -> CarAgent:
        """A fresh mind: a car plans every trial anew (``CarAgent.carry_over`` keeps what it
        knows of its peers)."""
        return CarAgent(car=self.car, scenario=self.scenario, sdf=self.sdf, depart_at=math.inf,
                        clock=time.thread_time)  # the replan budget is CPU time (VerifyConfig.budget_ms)

    # --- inputs ---------------------------------------------------------------------------

    def _on_frame(self, frame: natnet.Frame, received_s: float) -> None:
        """A frame the NatNet client took (monotonic ``received_s``), stamped with its
        arrival on the fleet clock: hand over, never block (the oldest goes, counted, if
        the agent loop fell that far behind)."""
        if len(self.frames) == self.frames.maxlen:
            self.counters["frames_overflowed"] += 1
        self.frames.append((self.clock() - (time.monotonic() - received_s), frame))

    def _observe_frames(self) -> None:
        if self._natnet is not None:
            self._natnet.pump()  # the datagrams waiting since the last pass
        up = self.scenario.natnet.up_axis
        while self.frames:
            t, frame = self.frames.popleft()
            poses = {}
            for body in frame.rigid_bodies:
                car_id = self._bodies.get(body.id)
                if car_id is None or not body.tracking_valid:
                    continue
                x, y, yaw = natnet.to_ground_plane(body.position, body.orientation, up)
                if all(map(math.isfinite, (x, y, yaw))):
                    poses[car_id] = (x, y, yaw)
            # A sensing range (agent.sight): the mind gets the peers within it of where we are.
            own = poses.get(self.car.id) or self._last_own_xy()
            for car_id, pose in visible(poses, self.car.id, own, self.agent.sight_range, self._sight_sdf).items():
                self.agent.observe(t, car_id, *pose)

    def _last_own_xy(self) -> tuple[float, float] | None:
        """Where the agent last saw its own car (None: never)."""
        track = self.agent.tracks.get(self.car.id)
        if track is None or track.last_stamp is None:
            return None
        return tuple(track.samples[-1, 1:3])

    def _handle(self, received: Received) -> None:
        message = self.inbox.accept(received.payload, key_sender=received.sender)
        if message is None:
            return
        if isinstance(message, messages.HeartbeatMessage):
            unheard_start = self.operation.heard_operator(received.at)
            if unheard_start is not None:
                self._start(unheard_start)
        elif isinstance(message, messages.StartMessage):
            self._start(message)
        elif isinstance(message, messages.StopMessage):
            if self.operation.take_stop(message, self.clock()):
                log.warning("car %d: %s", self.car.id, self.operation.reason)
                self._feed_command_loop(self.clock())  # an e-stop goes out now, not after the pass
        elif isinstance(message, (messages.PlanMessage, messages.TrustReport)):
            self.agent.receive(message, received.at)

    def _start(self, message: messages.StartMessage | None) -> None:
        """A start from the operator (None: ``control.start_timeout_s`` ran out)."""
        now = self.clock()
        if message is None:
            self.operation.take_start_without_operator(now, self.scenario.planner.cruise_speed_mps)
            taken = True
        else:
            before = self.operation.reason
            taken = self.operation.take_start(message, now)
            if not taken and self.operation.reason != before:
                log.warning("car %d: %s", self.car.id, self.operation.reason)
        if not taken:
            return
        depart, cruise = self.operation.depart_at, self.operation.cruise_mps
        self._plan = None
        agent = self._new_agent()
        agent.carry_over(self.agent)  # a new plan, the same memory of the peers
        agent.set_departure(depart, cruise)
        self.agent = agent
        self.laps = Laps(self.car, self.scenario.control.laps, self.scenario.control.lap_turn_s)
        self.stuck = False  # the command loop's motion watch starts afresh with the trial
        log.info("car %d: trial %d: start at %.2f (in %.2f s), cruise %.2f m/s", self.car.id,
                 self.operation.trial, depart, depart - now, cruise)

    def _own_pose(self) -> tuple[tuple[float, float, float], float] | None:
        """The car's own fresh, tracked pose (x, y, yaw) and its age in seconds (the
        command loop reads its own; this one is for the bus and for what we wait for)."""
        return fresh_pose(self._natnet, self.car.body_id, self.scenario.control.pose_timeout_s,
                          self.scenario.natnet.up_axis)

    # --- the command loop (fleet.car.velocity_loop) ------------------------------------------------

    def _feed_command_loop(self, now: float) -> None:
        """The plan and a fresh permit to the command loop; what it reports, taken in."""
        if self.operation.check_deadman(now):
            log.warning("car %d: %s", self.car.id, self.operation.reason)
        link = self.operation.next_flags(now)
        command = self.command
        if not self.stop.is_set():  # stopping, SIGTERM may have reached the loop first (one process group)
            command.keep_alive()
        command.send_plan(self._plan)
        command.grant(may_drive=self.operation.may_drive(now), at_goal=self.agent.at_goal, e_stop=link.e_stop,
                      release=link.release, trial=self.operation.trial, turn=self.laps.turn)
        report, before = command.report(), self.command_report
        self.command_report = report
        if report.answers != before.answers and self.operation.car_reports_latch(report.latched, now):
            log.warning("car %d: %s", self.car.id, self.operation.reason)
        if report.stuck != self.stuck and self.operation.mode == Mode.DRIVING:
            self.stuck = report.stuck
            self.counters["stuck"] += self.stuck
            log.log(logging.WARNING if self.stuck else logging.INFO, "car %d: %s", self.car.id,
                    "told to drive but not moving: telling peers it stands still" if self.stuck
                    else "moving again")

    # --- the main loop -------------------------------------------------------------------------

    def run(self, stats_path: Path | None = None) -> int:
        scenario, car = self.scenario, self.car
        log.info("car %d: NatNet %s at %s, link %s (version %d)", car.id, scenario.natnet.mode, scenario.natnet.server,
                 car.link, car.link_version)
        self.command.start()  # STOP to the car from its first tick, whatever else is not up yet
        warm_compiled()  # the mind's compiled loops loaded now, not in its first replan or sighting
        connector = threading.Thread(target=self._connect_natnet, name=f"natnet-connect-{car.id}", daemon=True)
        connector.start()
        bus = None
        try:
            bus = self._open_bus()
            if bus is not None:
                self._main_loop(bus)
        finally:
            self.stop.set()
            self._watch_driving_cpu(stopping=True)  # while the command loop is there to read
            self.command.close()  # STOP datagrams before anything else
            connector.join(timeout=self.natnet.connect_timeout_s + 1.0)
            self.state = "stopped"
            if bus is not None:
                self._publish_status(bus)
            if stats_path is not None:
                write_stats(stats_path, self, bus)
            if self._natnet is not None:
                self._natnet.close()
            if bus is not None:
                bus.close()
        return 0

    def _connect_natnet(self) -> None:
        """The connector thread: reach Motive (retrying) and hand the client over."""
        while not self.stop.is_set():
            client = NatNetClient(self.natnet, on_frame=self._on_frame)
            try:
                client.start()
            except NatNetConnectionError as exc:
                self._natnet_problem = str(exc)
                self.stop.wait(self.scenario.control.retry_s)
                continue
            if self.stop.is_set():
                client.close()
                return
            self._natnet = client
            log.info("car %d: receiving NatNet %s from %s", self.car.id, client.version, self.scenario.natnet.server)
            return

    def _open_bus(self) -> FleetBus | None:
        """The bus, once it opens (retrying every ``control.retry_s``); None if stopped first."""
        while not self.stop.is_set():
            bus = FleetBus(self.scenario.bus, self.scenario.fleet, self.car.id, listen=self.car.listen,
                           kinds=HEARD_BY_CARS, clock=self.clock)
            try:
                bus.open()
                return bus
            except BusError as exc:
                log.warning("car %d: waiting for the bus: %s; retrying in %.0f s", self.car.id,
                            str(exc).splitlines()[0], self.scenario.control.retry_s)
                bus.close()
                self.stop.wait(self.scenario.control.retry_s)
        return None

    def waiting_for(self, now: float) -> tuple[str, ...]:
        """What this car process is waiting for, in words (empty: nothing)."""
        n = self.scenario.natnet
        return waiting_for(
            motive=None if self._natnet is not None else f"{n.server}:{n.command_port} ({self._natnet_problem})",
            body=None if self._natnet is None or self._own_pose() is not None else self.car.body_id,
            link=None if now - self.command_report.answered_at <= 3 * self.scenario.control.link_ping_period_s + 1.0
            else self.car.link,
            absent_peers=[c.id for c in self.scenario.cars if c.id != self.car.id and not self._on_bus.get(c.id)],
            mode=self.operation.mode, hears_operator=self.operation.hears_operator(now))

    def _main_loop(self, bus: FleetBus) -> None:
        control = self.scenario.control
        started_wait = self.clock()
        now = self.clock()
        next_replan = next_plan = now
        next_trust = now + control.trust_report_period_s * (self.car.id % 7) / 7
        next_pose = now
        next_status = now
        next_say = now + 1.0
        book = self.sections.book
        while not self.stop.is_set():
            now = self.clock()
            book("loop")
            self._observe_frames()
            book("frames")
            for received in bus.drain():
                self._handle(received)
            book("messages")
            for peer, up in list(bus.alive.items()):
                if not up and self._alive.get(peer, True):
                    log.warning("car %d: car %d left the bus", self.car.id, peer)
                    self.agent.peer_gone(peer)
                self._alive[peer] = up
            if (self.operation.mode == Mode.WAITING and self.operation.trial == 0 and control.start_timeout_s
                    and now - started_wait > control.start_timeout_s):
                log.warning("car %d: no start message for %.0f s; starting now", self.car.id, control.start_timeout_s)
                self._start(None)
            book("loop")
            self._feed_command_loop(now)
            book("command_loop")
            self.agent.gather_evidence(now)
            book("evidence")
            if now >= next_replan:
                next_replan += control.replan_period_s
                if now - next_replan > control.replan_period_s:
                    next_replan = now + control.replan_period_s  # do not try to catch up
                self._replan(now)
                book("replan")
                self._feed_command_loop(self.clock())
                book("command_loop")
                next_plan = now + control.plan_period_s
                self._publish_plan(bus, now, repeat=False)  # a new plan goes out at once, both ways
            if now >= next_plan:  # and again every plan_period_s, best effort: a lost plan is soon replaced
                next_plan = max(next_plan + control.plan_period_s, now)
                self._publish_plan(bus, now, repeat=True)
            if now >= next_trust:
                next_trust = max(next_trust + control.trust_report_period_s, now)
                # Stamped as it goes out, not at the pass's start: a replan earlier in
                # the pass made ``now`` old, and peers read their estimate of our clock
                # off these stamps (agent.clocks).
                bus.publish("trust", messages.encode(self.agent.trust_message(self.clock())))
            if now >= next_pose:
                next_pose = max(next_pose + control.pose_period_s, now)
                self._publish_pose(bus, now)
            book("publish")
            state = self._state()
            if now >= next_status or state != self.state:  # a new mode is told at once
                self.state = state
                next_status = max(next_status + control.status_period_s, now)
                self._publish_status(bus)
            if now >= next_say:
                next_say = now + 1.0
                self._on_bus = bus.on_bus()
                self._waiting.say(self.state, self.waiting_for(now), now)
            self._watch_driving_cpu()
            book("status")
            # Until the next thing due (a message wakes it at once), at most a command
            # period: the permit, the deadman and the operator's flags are looked at in each pass.
            due = min(next_replan, next_plan, next_trust, next_pose, next_status, next_say,
                      self.agent.next_evidence_at())
            bus.wait(min(max(due - self.clock(), 0.0), 1.0 / control.command_rate_hz))
            book("wait")

    def _watch_driving_cpu(self, stopping: bool = False) -> None:
        """Snapshots of the car's CPU (fleet.cpu) as it starts to drive and as it stops
        driving (arrived, or the process ``stopping``), its first trial's: what a driving
        car costs, in the ``--stats`` summary."""
        driving = self.operation.mode == Mode.DRIVING and not stopping
        if driving and not self._driving_cpu or not driving and len(self._driving_cpu) == 1:
            self._driving_cpu.append(snapshot(self.sections, os.getpid(), self.command.pid))

    def driving_cpu(self) -> dict | None:
        """Where the car's CPU went while it drove (fleet.cpu.breakdown); None if it did not."""
        if len(self._driving_cpu) < 2:
            return None
        natnet = self._natnet.thread_id if self._natnet is not None else None
        return breakdown(*self._driving_cpu, threading.main_thread().native_id, natnet)

    def _state(self) -> str:
        mode = self.operation.mode
        if mode == Mode.DRIVING and self.stuck:
            return "stuck"
        return mode.value

    def _replan(self, now: float) -> None:
        # Arrived, the agent still watches whether it walls a stalled car in; stepping
        # aside, the trial goes on (agent.deadlock, agent.operator_state).
        parked = self.operation.mode == Mode.ARRIVED and self.arrived
        if self.operation.mode != Mode.DRIVING and not parked:
            own = self.agent.tracks.get(self.car.id)
            motion = own.motion() if own else None
            if motion is not None:  # show where we stand until we may go
                self.agent.plan = standing(motion.position, now)
        else:
            stepped_aside = self.agent.deadlock.steps_aside
            before, started = self.agent.last_outcome, time.thread_time()
            try:
                self.agent.replan(now)
            except Exception:  # keep the last plan; the car keeps tracking it
                log.exception("car %d: replanning raised", self.car.id)
                self.counters["replan_errors"] += 1
            outcome = self.agent.last_outcome
            if outcome is not None and outcome is not before:  # a replan ended: its CPU, by how
                self.replan_cpu.setdefault(outcome.outcome, Tally()).add(time.thread_time() - started)
                if outcome.first_broke:
                    self.first_broke["+".join(outcome.first_broke)] += 1
            aside = self.agent.deadlock.detour
            if parked and not self.agent.at_goal and aside is not None and aside.for_peer is not None:
                if self.operation.step_aside(now, aside.for_peer):
                    log.info("car %d: %s", self.car.id, self.operation.reason)
            elif self.agent.deadlock.steps_aside > stepped_aside and aside is not None:
                log.info("car %d: at its goal, stepping aside for car %d, which it walls in", self.car.id,
                         aside.for_peer)  # before its trial ended: the trial simply goes on
        own = self.agent.tracks.get(self.car.id)
        motion = own.motion() if own else None
        if self.operation.mode == Mode.DRIVING and motion is not None \
                and self.laps.advance(self.agent, tuple(motion.position), now):
            log.info("car %d: lap %d of %d", self.car.id, self.laps.lap, self.laps.laps)
        if self.operation.mode == Mode.DRIVING and self.arrived:
            self.operation.arrived()
            log.info("car %d: %s", self.car.id, self.operation.reason)
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
            outgoing = dataclasses.replace(outgoing, plan=standing(motion.position, now), stuck=True)
        if outgoing is not None:
            bus.publish("plan", messages.encode(outgoing), repeat=repeat)

    def _publish_pose(self, bus: FleetBus, now: float) -> None:
        seen = self._own_pose()
        x, y, yaw = seen[0] if seen is not None else (0.0, 0.0, 0.0)
        self._seq["pose"] += 1
        bus.publish("pose", messages.encode(messages.PoseMessage(
            self.car.id, self._seq["pose"], now, x, y, yaw, seen is not None)))

    def _publish_status(self, bus: FleetBus) -> None:
        self._seq["status"] += 1
        last = self.agent.last_result
        bus.publish("status", messages.encode(messages.StatusMessage(
            self.car.id, self._seq["status"], self.clock(), self.state,
            last.time_ms if last else 0.0, last.iterations if last else 0, self.arrived,
            status_counters(self, self.clock()), self.operation.trial)))


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg car", __doc__.split("\n")[0])
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

"""``trustfg sim``: the main job -- a whole fleet as separate OS processes on one machine.

    trustfg sim [--scenario FILE] [--cars N] [--liar ID [--attack NAME] [--attack-param K=V ...]
                [--misinformation P]] [--clock-offset ID=S ...] [--out DIR] [--seed S] [--timeout S]
                [--laps K] [--natnet-version V] [--mocap ARG ...]

It wires the scenario for loopback (free ports, fresh car-link keys) into DIR/fleet.toml;
starts ``trustfg mocap-sim``, then one ``trustfg car`` per car (and the dashboard); joins
the bus as the operator, waits for every car and sends the start (departures and cruise
speeds drawn from ``--seed`` as the in-process fleet draws them); records every message
until every car is at its goal or the timeout; stops every child (also on Ctrl-C) and
prints and writes DIR/summary.json from mocap-sim's ground truth and the cars' own stats.
Exit status: 0 when every car arrived with no breach and no process crashed; 1 otherwise.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ...agent.config import (
    ATTACKS,
    PAPER_LIAR,
    AttackConfig,
    ConfigError,
    Scenario,
    liar_attack,
    parse_attack,
    parse_id_values,
)
from ...agent.planner import warm_compiled
from ...agent.scenario_files import dump_scenario, load_scenario
from ...bridge import natnet
from ..bus.session import FleetBus
from ..car.laps import final_legs
from ..cpu import capacity_note, machine_load, usable_cores
from ..operator.session import OperatorSession
from ..program import command_parser, configured, stop_on_signals
from ..recording.mcap_file import convert_run
from ..sim.in_process import draw_departures
from ..sim.scene_gen import scene_problem
from .link_keys import with_link_keys
from .ports import free_port
from .processes import READY_TIMEOUT_S, Processes, wait_ready
from .summary import Recorder, print_summary, summarise

log = logging.getLogger(__name__)

START_LEAD_S = 1.0


DEFAULT_SCENES = (("intersection", 4), ("intersection-8", 8), ("intersection-16", 16))
"""The shipped scenes ``trustfg sim`` runs without --scenario, by fleet size: the crossing,
with queues on its approaches for more cars."""


def default_scenario(cars: int | None) -> str:
    """The shipped scene ``trustfg sim`` runs without --scenario: the smallest of
    DEFAULT_SCENES with at least ``cars`` cars (None: the crossing of four)."""
    for name, size in DEFAULT_SCENES:
        if cars is None or cars <= size:
            return name
    name, size = DEFAULT_SCENES[-1]
    raise ConfigError(f"no shipped scene has {cars} cars (the largest, {name} and circle-16, have {size}): "
                      f"make one with 'trustfg scenario generate --kind circle --cars {cars} --out FILE' "
                      "and pass --scenario FILE")


def loopback_fleet(scenario: Scenario, cars: int | None, liar: int | list[int] | None = None,
                   misinformation: float | None = None, infra_ip: str = "127.0.0.1",
                   car_ips: dict[int, str] | None = None, attack: AttackConfig | None = None,
                   clock_offsets: dict[int, float] | None = None) -> Scenario:
    """The scenario wired for one machine: ports, endpoints, unicast NatNet. Car(s) ``liar``
    run ``attack`` (config.liar_attack); ``clock_offsets`` give car processes clocks off
    the fleet's (tests). mocap-sim and the observers live at ``infra_ip``; car N's process
    at ``car_ips[N]`` (default: the same address): the fault tests give each its own netns."""
    chosen = scenario.cars if cars is None else scenario.cars[:cars]
    if cars is not None and len(chosen) < cars:
        raise ConfigError(f"scenario {scenario.name!r} has {len(scenario.cars)} cars, {cars} were asked for")
    liars = [] if liar is None else [liar] if isinstance(liar, int) else list(liar)
    named = set(liars) | set(clock_offsets or {})
    if named - {c.id for c in chosen}:
        raise ConfigError(f"cars {sorted(named)}: not all among {[c.id for c in chosen]}")
    lie = liar_attack(attack, misinformation) if liars else None
    wired = []
    for car in chosen:
        ip = (car_ips or {}).get(car.id, infra_ip)
        wired.append(dataclasses.replace(
            car, link=f"udp://{infra_ip}:{free_port(socket.SOCK_DGRAM)}",
            listen=(f"tcp/{ip}:{free_port()}", f"udp/{ip}:{free_port(socket.SOCK_DGRAM)}?rel=0"),
            attack=lie if car.id in liars else car.attack,
            clock_offset_s=(clock_offsets or {}).get(car.id, car.clock_offset_s)))
    endpoints = tuple(e for car in wired for e in car.listen)
    fleet = dataclasses.replace(
        scenario, cars=tuple(wired),
        bus=dataclasses.replace(scenario.bus, mode="peer", listen=(), connect=endpoints, multicast_scouting=False),
        natnet=dataclasses.replace(scenario.natnet, server=infra_ip, mode="unicast",
                                   command_port=free_port(socket.SOCK_DGRAM), data_port=free_port(socket.SOCK_DGRAM),
                                   local_interface="0.0.0.0"))
    fleet.validate()
    return fleet


def with_deadman(scenario: Scenario, deadman_s: float | None) -> Scenario:
    """The scenario with ``operator.deadman_s`` set (None: as it is)."""
    if deadman_s is None:
        return scenario
    operator = dataclasses.replace(scenario.operator, deadman_s=deadman_s)
    operator.validate("operator")
    return dataclasses.replace(scenario, operator=operator)


def departures(scenario: Scenario, seed: int, t_go: float) -> dict[int, tuple[float, float]]:
    """Desynchronised departures, as the in-process fleet draws them for the same seed."""
    delay, cruise = draw_departures(scenario, np.random.default_rng(seed))
    return {car.id: (t_go + float(delay[i]), float(cruise[i])) for i, car in enumerate(scenario.cars)}


@dataclass
class RunContext:
    """What a scheduled fault action may touch while a run goes on."""

    scenario: Scenario
    out: Path
    processes: Processes
    config_path: Path
    t_go: float
    recorder: "Recorder | None" = None
    events: list[tuple[float, str]] = field(default_factory=list)

    def speed(self, car_id: int) -> float:
        """The car's speed as its last two published poses tell (0 if unknown)."""
        poses = self.recorder.poses.get(car_id, ()) if self.recorder else ()
        if len(poses) < 2 or poses[1].stamp <= poses[0].stamp:
            return 0.0
        a, b = poses
        return float(np.hypot(b.x - a.x, b.y - a.y) / (b.stamp - a.stamp))

    def position(self, car_id: int) -> tuple[float, float] | None:
        """The car's position as its last published pose tells (None if unknown)."""
        poses = self.recorder.poses.get(car_id, ()) if self.recorder else ()
        return (poses[-1].x, poses[-1].y) if poses else None

    def car_args(self, car_id: int) -> list[str]:
        return ["car", "--id", str(car_id), "--config", str(self.config_path),
                "--stats", str(self.out / f"car_{car_id}.json")]

    def note(self, what: str) -> None:
        self.events.append((time.time(), what))
        print(f"  t+{time.time() - self.t_go:5.1f}s: {what}", flush=True)


END_CLOSE_TIMEOUT_S = 15.0
"""How long the observer's session may take to close at the end of a run."""


def run(scenario: Scenario, out: Path, seed: int = 0, timeout_s: float | None = None,
        natnet_version: str = natnet.DEFAULT_STREAM_VERSION, mocap_args: tuple[str, ...] = (), stop: threading.Event | None = None,
        dashboard_port: int | None = None, wrap: Callable[[str, list[str]], list[str]] | None = None,
        schedule: list[tuple[float, Callable[[RunContext], None]]] = (), infra_ip: str = "127.0.0.1",
        stay: bool = False, on_end: Callable[[], None] | None = None) -> dict:
    """Run the fleet to completion; returns the summary (also written to out/summary.json).

    ``dashboard_port``: also start ``trustfg dashboard`` there (0: any free port).
    ``wrap(name, argv)``: how to start each child (e.g. inside a network namespace).
    ``schedule``: (seconds after the go, action) -- faults injected during the run.
    ``stay``: run until the timeout even when every car has arrived (further trials).
    ``on_end()``: called when the run is over, before anything is stopped (the fault lab
    lifts its faults, so the observer's session closes with its peers in reach)."""
    stop = stop or threading.Event()
    out.mkdir(parents=True, exist_ok=True)
    warm_compiled()  # compiled and cached once here, not by every car process at once
    scenario = with_link_keys(scenario, out / "keys")
    config_path = out / "fleet.toml"
    config_path.write_text(dump_scenario(scenario))
    timeout_s = timeout_s or scenario.sim.timeout_s * scenario.control.laps + 15.0
    processes = Processes(wrap)
    observer_endpoint = f"tcp/{infra_ip}:{free_port()}"
    pending = sorted(schedule, key=lambda item: item[0])
    context = None
    summary: dict = {}
    t_go = None
    crashed_early: list[str] = []
    try:
        _start_children(processes, scenario, out, config_path, seed=seed, natnet_version=natnet_version,
                        mocap_args=mocap_args, stop=stop, dashboard_port=dashboard_port, infra_ip=infra_ip)
        with FleetBus(scenario.bus, scenario.fleet, None, listen=(observer_endpoint,),
                      operator_kinds=("start", "stop")) as bus:
            recorder = Recorder(bus, out / "messages.jsonl")
            operator = OperatorSession(scenario, bus, direct=False)  # the heartbeat, the start
            try:
                _wait_for_cars(scenario, processes, recorder, operator, stop)
                # The go comes no sooner than sim.settle_s after the last car came up: strangers
                # still, cars would plan around each other with the widest epsilon.
                t_go = time.time() + max(START_LEAD_S, scenario.sim.settle_s)
                operator.start(departures(scenario, seed, t_go), trial=1)
                context = RunContext(scenario, out, processes, config_path, t_go, recorder)
                print(f"trustfg sim: go (seed {seed}); recording to {out}", flush=True)
                _drive(context, operator, pending, timeout_s, stay, stop)
                crashed_early = processes.crashed()
                processes.cpu.sample(mark="end")
                recorder.poll()
            finally:
                _end_run(processes, recorder, bus, on_end)
        processes.stop()
        summary = _summary(scenario, out, processes, recorder, bus, t_go, crashed_early)
    finally:
        processes.stop()
    if context is not None and context.events:
        summary["events"] = [[round(t - context.t_go, 3), what] for t, what in context.events]
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    summary["recording"] = str(convert_run(out, scenario))
    return summary


def _start_children(processes: Processes, scenario: Scenario, out: Path, config_path: Path, *, seed: int,
                    natnet_version: str, mocap_args: tuple[str, ...], stop: threading.Event,
                    dashboard_port: int | None, infra_ip: str) -> None:
    """Start mocap-sim and wait for it, then the dashboard if asked for, then every car."""
    mocap = processes.start("mocap-sim", ["mocap-sim", "--config", str(config_path), "--ground-truth",
                                          str(out / "ground_truth.csv"), "--natnet-version", natnet_version,
                                          "--command-log", str(out / "commands.csv"),
                                          "--seed", str(seed), *mocap_args],
                            out / "mocap_sim.log", stdout=subprocess.PIPE)
    wait_ready(mocap, stop)
    if dashboard_port is not None:
        port = dashboard_port or free_port()
        processes.start("dashboard", ["dashboard", "--config", str(config_path), "--port", str(port),
                                      "--listen", f"tcp/{infra_ip}:{free_port()}"], out / "dashboard.log")
        print(f"dashboard: http://127.0.0.1:{port}/", flush=True)
    for car in scenario.cars:
        processes.start(f"car {car.id}", RunContext(scenario, out, processes, config_path, 0.0).car_args(car.id),
                        out / f"car_{car.id}.log")


def _wait_for_cars(scenario: Scenario, processes: Processes, recorder: Recorder, operator: OperatorSession,
                   stop: threading.Event) -> None:
    """Until every car is on the bus (its token up, or heard though its token never reached
    us: OperatorSession.alive) and its status in; RuntimeError if one crashed or is late."""
    ids = [c.id for c in scenario.cars]
    print(f"trustfg sim: {len(ids)} cars, waiting for them to come up ...", flush=True)
    deadline = time.monotonic() + READY_TIMEOUT_S + 5 * len(ids)

    def missing() -> list[int]:
        alive = operator.alive()
        return [i for i in ids if not (i in alive and i in recorder.status)]

    while not stop.is_set() and missing():
        recorder.poll()
        operator.step()
        if processes.crashed() or time.monotonic() > deadline:
            raise RuntimeError(f"cars {missing()} did not come up (crashed: {processes.crashed()})")
        time.sleep(0.05)


def _drive(context: RunContext, operator: OperatorSession, pending: list[tuple[float, Callable]],
           timeout_s: float, stay: bool, stop: threading.Event) -> None:
    """From the go until every car is at its goal and no action is pending (or, with
    ``stay``, the timeout): record, keep the heartbeat, run the scheduled actions when
    due, mark the CPU samples and report progress every 5 s."""
    processes, recorder, t_go = context.processes, context.recorder, context.t_go
    ids = [c.id for c in context.scenario.cars]
    end = time.monotonic() + timeout_s
    next_report = time.monotonic() + 5.0
    while not stop.is_set() and time.monotonic() < end:
        recorder.poll()
        operator.step()
        while pending and time.time() >= t_go + pending[0][0]:
            t_action, action = pending.pop(0)
            again = action(context)  # a number: not yet, ask again that much later
            if isinstance(again, (int, float)) and not isinstance(again, bool):
                pending.append((time.time() - t_go + float(again), action))
                pending.sort(key=lambda item: item[0])
        if "go" not in processes.cpu.marks and time.time() >= t_go:
            processes.cpu.sample(mark="go")  # the go itself: the wait before it plans nothing
        arrived = [i for i in ids if recorder.status.get(i) and recorder.status[i].at_goal]
        if arrived and "first_arrival" not in processes.cpu.marks:
            processes.cpu.sample(mark="first_arrival")
        if len(arrived) == len(ids) and not pending and not stay:
            break
        if time.monotonic() > next_report:
            next_report += 5.0
            processes.cpu.sample()
            print(f"  t+{time.time() - t_go:5.1f}s: {len(arrived)}/{len(ids)} cars at their goals",
                  flush=True)
        time.sleep(0.05)


def _end_run(processes: Processes, recorder: Recorder, bus: FleetBus, on_end: Callable[[], None] | None) -> None:
    """The run is over: ``on_end()``, the cars stopped, the last messages recorded, and the
    observer's session closed."""
    if on_end is not None:
        on_end()
    processes.stop([name for name in processes.children if name.startswith("car")])
    recorder.poll()
    recorder.close()
    # Wait for the session to close (its listener with it) rather than leave it
    # to a thread: this process goes on (tests, the fault matrix's next run).
    bus.close(timeout_s=END_CLOSE_TIMEOUT_S)


def _summary(scenario: Scenario, out: Path, processes: Processes, recorder: Recorder, bus: FleetBus,
             t_go: float | None, crashed_early: list[str]) -> dict:
    """The run's summary: summary.summarise's keys, how the observer's session closed, the
    CPU between the go and the first arrival, and the machine's load."""
    summary = summarise(final_legs(scenario), out, recorder, t_go, crashed_early)
    # A close that failed may leave the observer's listener open in this process (it
    # goes with the process; a caller that runs on, like a test, should know)
    summary["observer_close"] = {name: bus.counters[name] for name in ("close_timed_out", "close_failed")}
    if any(summary["observer_close"].values()):
        print(f"trustfg sim: the observer's Zenoh session did not close cleanly: {summary['observer_close']}",
              file=sys.stderr, flush=True)
    summary["cpu"] = processes.cpu.summary("go", "first_arrival")
    # From the go to the first arrival; with no car in, to the end of the run (a run
    # in which no car arrived is the most starved, not the least).
    until = "first_arrival" if "first_arrival" in processes.cpu.marks else "end"
    window = summary["cpu"] if until == "first_arrival" else processes.cpu.summary("go", until)
    summary["machine"] = machine_load(window, usable_cores(), until)
    summary["t_go"] = t_go  # the go, on the clock of the messages' stamps (None: no go)
    return summary




def _port_free(port: int) -> bool:
    with socket.socket() as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg sim", __doc__)
    parser.add_argument("--scenario", default=None,
                        help="a scenario file, or a shipped scene's name (default: intersection; "
                             "intersection-8 for 5-8 cars, intersection-16 for 9-16)")
    parser.add_argument("--cars", type=int, default=None, help="use the first N cars of the scenario")
    parser.add_argument("--liar", type=int, action="append", default=None, metavar="ID",
                        help="a car that lies (repeatable: --attack collude needs two)")
    parser.add_argument("--attack", default=PAPER_LIAR,
                        help=f"how the liars lie: {', '.join(ATTACKS)}, or several joined by + (default %(default)s)")
    parser.add_argument("--attack-param", action="append", default=[], metavar="KEY=NUMBER",
                        help="an attack parameter (repeatable), e.g. --attack-param bias_m=0.14")
    parser.add_argument("--misinformation", type=float, default=None,
                        help="the liar's fraction of false plans, for attacks with one (default 0.4)")
    parser.add_argument("--clock-offset", action="append", default=[], metavar="ID=SECONDS",
                        help="run car ID's process with a clock that far ahead of the fleet's (tests; repeatable)")
    parser.add_argument("--out", type=Path, default=None, help="run folder (default runs/sim-<time>)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the departures and cruise speeds")
    parser.add_argument("--timeout", type=float, default=None, help="seconds after the start (default: scenario's + 15)")
    parser.add_argument("--laps", type=int, default=None,
                        help="drive every route K times, back and forth (default: the scenario's control.laps, 1)")
    parser.add_argument("--natnet-version", choices=natnet.STREAM_VERSIONS, default=natnet.DEFAULT_STREAM_VERSION,
                        help="NatNet version mocap-sim streams (default %(default)s)")
    parser.add_argument("--no-dashboard", action="store_true", help="do not start the dashboard")
    parser.add_argument("--dashboard-port", type=int, default=8765, help="dashboard port (0: any free one)")
    parser.add_argument("--stay", action="store_true",
                        help="keep the fleet up after the cars arrive, until --timeout or Ctrl-C (more trials: "
                             "trustfg go, trustfg stop)")
    parser.add_argument("--deadman", type=float, default=None,
                        help="cars stop when the launcher's heartbeat is missing this long, s (default: off)")
    parser.add_argument("--mocap", action="append", default=[], metavar="ARG",
                        help="extra argument for mocap-sim, e.g. --mocap=--drop-rate=0.3 (repeatable)")
    args = parser.parse_args(argv)
    if args.cars is not None and args.cars < 1:
        parser.error("--cars must be at least 1")
    if args.misinformation is not None and not 0.0 <= args.misinformation <= 1.0:
        parser.error("--misinformation must be within [0, 1]")
    if args.laps is not None and args.laps < 1:
        parser.error("--laps must be at least 1")
    fleet = configured("trustfg sim", lambda: with_deadman(loopback_fleet(
        load_scenario(args.scenario or default_scenario(args.cars)), args.cars, args.liar, args.misinformation,
        attack=parse_attack(args.attack, args.attack_param),
        clock_offsets=parse_id_values(args.clock_offset, "--clock-offset")), args.deadman))
    if args.laps is not None:
        fleet = dataclasses.replace(fleet, control=dataclasses.replace(fleet.control, laps=args.laps))
    problem = scene_problem(fleet)
    if problem is not None:
        print(f"trustfg sim: warning: {problem}", file=sys.stderr)
    crowded = capacity_note(len(fleet.cars), usable_cores())
    if crowded is not None:
        print(f"trustfg sim: warning: {crowded}", file=sys.stderr)
    out = args.out or Path("runs") / time.strftime("sim-%Y%m%d-%H%M%S")
    stop = stop_on_signals(threading.Event())
    try:
        port = None if args.no_dashboard else (args.dashboard_port if _port_free(args.dashboard_port) else 0)
        summary = run(fleet, out, args.seed, args.timeout, args.natnet_version, tuple(args.mocap), stop, port,
                      stay=args.stay)
    except RuntimeError as exc:
        print(f"trustfg sim: {exc} (logs in {out})", file=sys.stderr)
        return 1
    print_summary(summary)
    print(f"\nwrote {out.resolve()} (replay: trustfg dashboard --replay {out}; report: trustfg report {out})")
    if stop.is_set():
        print("interrupted", file=sys.stderr)
        return 130
    ok = not summary["breaches"] and not summary["crashed"] and all(summary["reached_goal"])
    return 0 if ok else 1

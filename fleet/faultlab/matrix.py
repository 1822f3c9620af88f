"""The fault matrix: a 4-car ``trustfg sim`` with every car process in its own network
namespace, under each fault, over several seeds.

    sudo trustfg faults [--seeds K] [--cases NAME ...] [--out DIR]

Cases (t = seconds after the start; car 2 is the victim where one car suffers):

    baseline       no fault
    loss-10/30/50  that % of every packet into every car's namespace dropped (nftables)
    delay-50ms     every Zenoh link (TCP and UDP) through a relay holding each chunk or
                   datagram 50 +- 20 ms
    partition      car 2 cut off from the other cars for t = 4..7 s, then healed
    kill-restart   car 2's process SIGKILLed (once it drives, from t = 4 s), started again
                   2 s later; the fleet is configured to let a restarted car rejoin the
                   running trial (operator.rejoin_trial; by default it would wait for the
                   operator's next start)
    mocap-drop-30  30 % of NatNet frames dropped (mocap-sim)
    occlusion      car 2's rigid body untracked for 1 s (once it drives, from t = 4 s)
    link-cut       car 2's command datagrams dropped from then to the end (nftables)
    link-cut-entry the same, from when car 2 enters the crossing (x >= -0.55 m): it comes
                   to rest in car 3's lane, and the others must go round it (a car that
                   cannot move is no car to give way to: agent.deadlock)
    lossy-clock    loss-30 and delay-50ms together, and car 2's process on a clock 0.3 s
                   ahead of the fleet's: honest cars must stay trusted (>= 0.8 after 3 s)

Measured per run, from mocap-sim's ground truth and the recorded messages:

    breaches          pairs with clearance < 0.1 m
    goals             cars that reached their goal (a car whose link is cut cannot)
    time_to_stop_s    from the fault being in place to the victim's car applying a zero
                      command (the car process's STOP when its pose is invalid or 200 ms
                      old, or the car's own 250 ms watchdog), from mocap-sim's command log
                      at physics resolution (5 ms); standstill follows after braking
                      (v / 1.5 m/s^2)
    time_to_recover_s from the heal until every car's status reports a plan younger than
                      1 s from every peer: plans resynchronised; after a restart, from
                      the restarted process's first status (its start-up is the next)
    time_to_rejoin_s  from the restart until the restarted process's first status: the
                      start-up of a car process (interpreter, GTSAM, Zenoh, NatNet) on
                      this machine
    honest_trust_min  least trust any car still reports in any peer at the end: silence
                      and loss must not read as lying
    trust_after_3s    least trust any car reported in any peer from 3 s after the start
    plan_age_ms       how old each car's view of each peer's plan is (status counters
                      plan_age_ms_<peer>, every status after the go): p50 and p99
    wall_clearance_m  least distance from a car's edge to a building (negative: into it)
"""

from __future__ import annotations

import csv
import dataclasses
import json
import signal
import socket
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ...agent.scenario_files import load_scenario
from ..launch.launcher import RunContext, free_port, loopback_fleet, run
from ..program import command_parser
from . import netem

SCENARIO = "intersection"
VICTIM = 2
FRESH_PLAN_MS = 1000


@dataclass
class Case:
    name: str
    prepare: Callable[["Setup"], None] = lambda setup: None
    """Change the fleet config or mocap-sim's arguments before the run."""
    schedule: list[tuple[float, Callable[["Setup", RunContext], None]]] = field(default_factory=list)
    measures_stop: bool = False
    """The victim loses its pose, process or link ("fault:" event): time it takes to stop."""
    measures_recovery: bool = False
    """The victim rejoins ("heal:" event): time until plans are resynchronised."""
    restarts: bool = False
    """The heal starts the victim's process anew: recovery counts from its first status
    (the process up and on the bus), and the start-up before it is reported apart."""
    link_cut: bool = False


@dataclass
class Setup:
    lab: netem.Lab
    fleet: object
    mocap_args: list[str]
    control_port: int
    out: Path
    """The run's output folder; files a case writes for the run go here."""
    killed_at: float | None = None
    stop: threading.Event = field(default_factory=threading.Event)
    """Set to end the run early (fleet.launch.launcher.run's ``stop``), with its summary as usual."""

    def control(self, command: dict) -> None:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(json.dumps(command).encode(), (self.lab.infra_ip, self.control_port))


def _loss(percent: int) -> Case:
    return Case(f"loss-{percent}", schedule=[(0.0, lambda s, c: [s.lab.loss(car, percent) for car in s.lab.car_ids])])


def _delay(setup: Setup) -> None:
    """Route every Zenoh link through a delaying relay; no gossip, so no short cuts."""
    relays = []
    for car in setup.fleet.cars:
        for endpoint in car.listen:  # its TCP link and its UDP one (best effort: plans, poses, trust)
            protocol, rest = endpoint.split("/", 1)
            address, _, metadata = rest.partition("?")
            host, port = address.rsplit(":", 1)
            relay_host, relay_port = setup.lab.relay(host, int(port), 0.050, 0.020, datagrams=protocol == "udp")
            relays.append(f"{protocol}/{relay_host}:{relay_port}" + (f"?{metadata}" if metadata else ""))
    setup.out.mkdir(parents=True, exist_ok=True)
    zenoh_file = setup.out.resolve() / "no-gossip.json5"
    zenoh_file.write_text('{ scouting: { gossip: { enabled: false } } }\n')
    setup.fleet = dataclasses.replace(setup.fleet, bus=dataclasses.replace(
        setup.fleet.bus, connect=tuple(relays), zenoh_config=str(zenoh_file),
        max_links=2))  # a TCP and a UDP link per pair, both relayed


def _skewed_clock(setup: Setup) -> None:
    """Delay every link, and run the victim's process on a clock 0.3 s ahead."""
    _delay(setup)
    setup.fleet = dataclasses.replace(setup.fleet, cars=tuple(
        dataclasses.replace(c, clock_offset_s=0.3) if c.id == VICTIM else c for c in setup.fleet.cars))


Action = Callable[["Setup", RunContext], None]
Scheduled = Callable[["Setup", RunContext], float | None]

DRIVING_MPS = 0.15
"""The victim counts as driving above this speed."""


def when(ready: Callable[[RunContext], bool], action: Action, retry_s: float) -> Scheduled:
    """Run ``action`` once ``ready``; until then ask again in ``retry_s``."""
    def run_when_ready(setup: "Setup", context: RunContext) -> float | None:
        if not ready(context):
            return retry_s
        action(setup, context)
        return None
    return run_when_ready


def when_moving(action: Action) -> Scheduled:
    """Run ``action`` once the victim is driving (a fault on a car that waits at its start
    shows nothing); until then ask again in 0.1 s."""
    return when(lambda context: context.speed(VICTIM) >= DRIVING_MPS, action, 0.1)


ENTRY_X = -0.55
"""Car 2 drives east along y = -0.4; the crossing starts at x = -0.8 and car 3's lane
(southbound) is x = -0.4: cut here, car 2 stops in that lane (0.25 s watchdog, then
braking at 1.5 m/s^2: about 0.25 m further on at 0.55 m/s)."""


def when_entering(action: Action) -> Scheduled:
    """Run ``action`` once the victim drives into the crossing (x >= ENTRY_X); until
    then ask again in 0.05 s."""
    def entering(context: RunContext) -> bool:
        where = context.position(VICTIM)
        return where is not None and where[0] >= ENTRY_X and context.speed(VICTIM) >= DRIVING_MPS
    return when(entering, action, 0.05)


def _cut_link(setup: "Setup", context: RunContext) -> None:
    setup.lab.cut_link(VICTIM, _link_port(setup))
    context.note(f"fault: cut car {VICTIM}'s command link")


def _kill(setup: Setup, context: RunContext) -> None:
    context.processes.kill(f"car {VICTIM}")
    setup.killed_at = time.time()
    context.note(f"fault: SIGKILL car {VICTIM}")


def _rejoin(setup: Setup) -> None:
    """A restarted car process may rejoin the running trial (by default it waits)."""
    setup.fleet = dataclasses.replace(setup.fleet, operator=dataclasses.replace(setup.fleet.operator, rejoin_trial=True))


def _restart(setup: Setup, context: RunContext) -> float | None:
    if setup.killed_at is None or time.time() < setup.killed_at + 2.0:
        return 0.1  # two seconds after the kill
    context.note(f"heal: restart car {VICTIM}")
    context.processes.start(f"car {VICTIM}", context.car_args(VICTIM), context.out / f"car_{VICTIM}.log")
    return None


def _end_once_the_others_arrive(setup: Setup, context: RunContext) -> float | None:
    """With its link cut the victim cannot arrive: end the run once it has been cut,
    stands, and every other car is at its goal (the timeout is only the backstop)."""
    status = context.recorder.status if context.recorder else {}
    cut = any(what.startswith("fault:") for _, what in context.events)
    others = [i for i in setup.lab.car_ids if i != VICTIM]
    if cut and context.speed(VICTIM) < 0.01 and all(status.get(i) and status[i].at_goal for i in others):
        setup.stop.set()
        return None
    return 0.5


def _link_port(setup: Setup) -> int:
    car = next(c for c in setup.fleet.cars if c.id == VICTIM)
    return int(car.link.rsplit(":", 1)[1])


CASES = {case.name: case for case in [
    Case("baseline"),
    _loss(10), _loss(30), _loss(50),
    Case("delay-50ms", prepare=_delay),
    Case("partition", schedule=[(4.0, lambda s, c: (c.note(f"fault: partition car {VICTIM}"), s.lab.partition(VICTIM))),
                                (7.0, lambda s, c: (c.note(f"heal: car {VICTIM} rejoins"), s.lab.clear(VICTIM)))],
         measures_recovery=True),
    Case("kill-restart", prepare=_rejoin, schedule=[(4.0, when_moving(_kill)), (6.0, _restart)], measures_stop=True,
         measures_recovery=True, restarts=True),
    Case("mocap-drop-30", prepare=lambda s: s.mocap_args.append("--drop-rate=0.3")),
    Case("occlusion", schedule=[(4.0, when_moving(lambda s, c: (
        s.control({"occlude": VICTIM, "seconds": 1.0}), c.note(f"fault: occlude car {VICTIM} for 1 s"))))],
        measures_stop=True),
    Case("link-cut", schedule=[(4.0, when_moving(_cut_link)), (4.0, _end_once_the_others_arrive)],
         measures_stop=True, link_cut=True),
    Case("link-cut-entry", schedule=[(0.0, when_entering(_cut_link)), (4.0, _end_once_the_others_arrive)],
         measures_stop=True, link_cut=True),
    Case("lossy-clock", prepare=_skewed_clock,
         schedule=[(0.0, lambda s, c: [s.lab.loss(car, 30) for car in s.lab.car_ids])]),
]}


def run_case(case: Case, seed: int, out: Path) -> dict:
    """One run of one case; returns its row of measurements."""
    scenario = load_scenario(SCENARIO)
    ids = [c.id for c in scenario.cars]
    with netem.Lab(ids) as lab:
        fleet = loopback_fleet(scenario, None, None, 0.0, infra_ip=lab.infra_ip, car_ips=lab.car_ips())
        setup = Setup(lab, fleet, [], free_port(socket.SOCK_DGRAM), out)
        case.prepare(setup)
        setup.mocap_args.append(f"--control-port={setup.control_port}")
        schedule = [(t, (lambda action: lambda context: action(setup, context))(action)) for t, action in case.schedule]
        timeout = 40.0 if case.link_cut else None
        summary = run(setup.fleet, out, seed=seed, timeout_s=timeout, stop=setup.stop, mocap_args=tuple(setup.mocap_args),
                      wrap=lab.wrap, schedule=schedule, infra_ip=lab.infra_ip, on_end=lab.clear_all)
    return measure(case, summary, out)


def measure(case: Case, summary: dict, out: Path) -> dict:
    ids = summary["car_ids"]
    t_go = summary.get("t_go")
    row = {
        "case": case.name, "breaches": len(summary["breaches"]),
        "goals": sum(summary["reached_goal"]), "cars": len(ids), "crashed": summary["crashed"],
        "time_to_stop_s": None, "time_to_recover_s": None, "time_to_rejoin_s": None,
        "honest_trust_min": min((v for r in summary["trust"] for v in r if v is not None), default=None),
        "wall_clearance_m": summary["obstacle_min_clearance"],
        "trust_after_3s": summary.get("honest_trust_min_after_settle"),
        "observer_close": summary.get("observer_close"),
    }
    events = summary.get("events", [])
    fault = next((t for t, what in events if what.startswith("fault:")), None)
    heal = next((t for t, what in events if what.startswith("heal:")), None)
    row["fault_at_s"], row["heal_at_s"] = fault, heal
    if case.measures_stop and fault is not None and t_go is not None:
        row["time_to_stop_s"] = _time_to_stop(out / "commands.csv", VICTIM, t_go + fault)
    if case.measures_recovery and heal is not None and t_go is not None:
        since = t_go + heal
        if case.restarts:
            back = _first_status(out / "messages.jsonl", VICTIM, since)
            row["time_to_rejoin_s"] = None if back is None else round(back - since, 3)
            since = back
        if since is not None:
            row["time_to_recover_s"] = _time_to_recover(out / "messages.jsonl", ids, since)
    row["plan_age_ms_p50"], row["plan_age_ms_p99"] = plan_age_percentiles(out / "messages.jsonl", t_go)
    row["breach_pairs"] = summary["breaches"]
    row["not_arrived"] = not_arrived(out, summary)
    return row


def not_arrived(out: Path, summary: dict) -> dict[int, dict]:
    """For each car short of its goal at the end, why, as far as the run says: where it
    stands (ground truth), and its last status (state, plan outcomes, guard, deadlocks)."""
    ids = [car for car, arrived in zip(summary["car_ids"], summary["reached_goal"]) if not arrived]
    if not ids:
        return {}
    where: dict[int, tuple[float, float]] = {}
    with open(out / "ground_truth.csv", newline="") as f:
        for r in csv.DictReader(f):
            if int(r["car_id"]) in ids:
                where[int(r["car_id"])] = (round(float(r["x"]), 3), round(float(r["y"]), 3))
    status: dict[int, dict] = {}
    with open(out / "messages.jsonl") as f:
        for line in f:
            if '"status"' in line:
                record = json.loads(line)
                message = record.get("message", {})
                if record.get("kind") == "status" and message.get("id") in ids:
                    status[message["id"]] = message
    keep = ("plans_first", "plans_retry", "plans_fallback", "guard_limited", "deadlocks", "deadlock_yields",
            "deadlock_steps_aside", "stale_pose_stops")
    return {car: {"at": where.get(car), "state": status.get(car, {}).get("state"),
                  **{k: v for k, v in status.get(car, {}).get("counters", {}).items() if k in keep}}
            for car in ids}


def plan_age_percentiles(messages_path: Path, since: float | None) -> tuple[float | None, float | None]:
    """p50 and p99 of every plan age (ms) the cars' statuses report after ``since``."""
    ages = []
    with open(messages_path) as f:
        for line in f:
            if '"status"' not in line:
                continue
            record = json.loads(line)
            if record.get("kind") != "status" or "message" not in record or (since and record["t"] < since):
                continue
            ages += [v for k, v in record["message"]["counters"].items() if k.startswith("plan_age_ms_")]
    if not ages:
        return None, None
    return float(np.percentile(ages, 50)), float(np.percentile(ages, 99))


def _time_to_stop(commands: Path, car: int, onset: float) -> float | None:
    """From the fault until the car applies a zero command (mocap-sim's command log, at
    physics resolution); None if it was already stopped."""
    with open(commands, newline="") as f:
        rows = [(float(r["t"]), float(r["v_cmd"]), float(r["omega_cmd"])) for r in csv.DictReader(f)
                if int(r["car_id"]) == car]
    before = [r for r in rows if r[0] < onset]
    if not before or (before[-1][1] == 0.0 and before[-1][2] == 0.0):
        return None
    after = [r for r in rows if r[0] >= onset and r[1] == 0.0 and r[2] == 0.0]
    return round(after[0][0] - onset, 3) if after else float("inf")


def _first_status(messages_path: Path, car_id: int, since: float) -> float | None:
    """When car ``car_id``'s first status after ``since`` was recorded (None: none was)."""
    with open(messages_path) as f:
        for line in f:
            record = json.loads(line)
            if (record.get("kind") == "status" and "message" in record and record["t"] >= since
                    and record["message"]["id"] == car_id):
                return record["t"]
    return None


def _time_to_recover(messages_path: Path, ids: list[int], heal: float) -> float | None:
    """From the heal until every car has had a fresh plan from every peer."""
    fresh: dict[int, bool] = {}
    with open(messages_path) as f:
        for line in f:
            record = json.loads(line)
            if record.get("kind") != "status" or "message" not in record or record["t"] < heal:
                continue
            message = record["message"]
            ages = [message["counters"].get(f"plan_age_ms_{peer}") for peer in ids if peer != message["id"]]
            fresh[message["id"]] = all(a is not None and a < FRESH_PLAN_MS for a in ages)
            if len(fresh) == len(ids) and all(fresh.values()):
                return round(record["t"] - heal, 3)
    return None


def table(rows: list[dict]) -> str:
    """fault, runs, breaches, goals reached, max time to stop, max time to recover, least trust,
    least trust after 3 s, least wall clearance, plan age (median of the runs' p50, largest of
    their p99), crashed."""
    by_case: dict[str, list[dict]] = {}
    for row in rows:
        by_case.setdefault(row["case"], []).append(row)
    lines = ["| fault | runs | breaches | goals reached | max time to stop (s) | max time to recover (s) "
             "| least trust reported | least trust after 3 s | least wall clearance (m) "
             "| plan age p50 / p99 (ms) | crashed |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for name, group in by_case.items():
        stops = [r["time_to_stop_s"] for r in group if r["time_to_stop_s"] is not None]
        recovers = [r["time_to_recover_s"] for r in group]
        trust = [r["honest_trust_min"] for r in group if r["honest_trust_min"] is not None]
        settled = [r["trust_after_3s"] for r in group if r.get("trust_after_3s") is not None]
        p50 = [r["plan_age_ms_p50"] for r in group if r.get("plan_age_ms_p50") is not None]
        p99 = [r["plan_age_ms_p99"] for r in group if r.get("plan_age_ms_p99") is not None]
        age = f"{np.median(p50):.0f} / {max(p99):.0f}" if p99 else "-"
        if not CASES[name].measures_recovery:
            recover = "-"
        else:
            recover = "never" if None in recovers else f"{max(recovers):.2f}"
            rejoins = [r.get("time_to_rejoin_s") for r in group]
            if CASES[name].restarts and None not in rejoins:
                recover += f" (after {max(rejoins):.2f} s of start-up)"
        cells = [name, len(group), sum(r["breaches"] for r in group),
                 f"{sum(r['goals'] for r in group)}/{sum(r['cars'] for r in group)}",
                 f"{max(stops):.3f}" if stops else "-", recover,
                 f"{min(trust):.2f}" if trust else "-", f"{min(settled):.2f}" if settled else "-",
                 f"{min(r['wall_clearance_m'] for r in group):.3f}", age,
                 sum(len(r["crashed"]) for r in group)]
        lines.append("| " + " | ".join(map(str, cells)) + " |")
    return "\n".join(lines)


def cases_told() -> str:
    """What each case does: the table of this module's docstring, the one place it is written."""
    return "cases (" + __doc__.split("\nCases (", 1)[1].split("\n\nMeasured", 1)[0]


def main(argv: list[str] | None = None) -> int:
    parser = command_parser("trustfg faults", __doc__,
                            epilog=cases_told() + "\n\nNeeds root: network namespaces and nftables.")
    parser.add_argument("--seeds", type=int, default=3, help="runs per case (seeds 0..K-1)")
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES), metavar="CASE",
                        help="the cases to run, from the list below (default: all)")
    parser.add_argument("--out", type=Path, default=None, help="folder for the runs (default runs/faults-<time>)")
    args = parser.parse_args(argv)
    reason = netem.available()
    if reason:
        print(f"trustfg faults: {reason}", file=sys.stderr)
        return 2
    out = args.out or Path("runs") / time.strftime("faults-%Y%m%d-%H%M%S")
    # SIGTERM unwinds like Ctrl-C, so every namespace, rule and process is removed.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    rows = []
    for name in args.cases:
        for seed in range(args.seeds):
            print(f"[faults] {name} seed {seed} ...", file=sys.stderr, flush=True)
            row = run_case(CASES[name], seed, out / f"{name}-{seed}")
            print(f"[faults] {name} seed {seed}: {row}", file=sys.stderr, flush=True)
            rows.append(row)
    (out / "faults.json").write_text(json.dumps(rows, indent=1))
    print(table(rows))
    return 0

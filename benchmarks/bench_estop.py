"""E-stop latency in ``trustfg sim``: from ``trustfg stop`` to every car applying zero.

    python benchmarks/bench_estop.py [--rounds 20] [--bus-rounds 5] [--session-rounds 5] [--release-rounds 0]
                                     [--seed 0] [--out FILE]

Runs ``trustfg sim --stay`` with four cars and joins its bus as the operator. Each round
starts a trial, waits a random moment while the cars drive (U(1, 4) s after the departure,
from ``--seed``), runs ``trustfg stop`` as a fresh process and times from just before its
start until every moving car applies zero for good (mocap-sim's command log, 5 ms ticks);
every car must then hold for a second; release; back to the starts. Every fourth round
freezes the car processes (SIGSTOP) first and stops with ``--path link`` alone; resumed,
they command motion again and the cars must still hold. ``--bus-rounds`` use the bus
path alone, ``--session-rounds`` use the benchmark's own operator session (as ``trustfg
go``'s stop key does). ``--release-rounds`` freeze the car processes and stop on the links
as above, and then release with ``trustfg stop --release`` as a fresh process: whether it
confirms every car on the bus and on its link within its default ``--wait`` (the benchmark
releases through its own session afterwards either way). Results:
docs/results/performance.md#e-stop.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from trustfg.agent import messages
from trustfg.agent.scenario_files import load_scenario
from trustfg.fleet.bus.session import FleetBus
from trustfg.fleet.launch.ports import free_port
from trustfg.fleet.launch.testbed import CommandLog
from trustfg.fleet.operator.session import OperatorSession

HOLD_S = 1.0


def car_pids(run: Path) -> list[int]:
    """The car processes of a ``trustfg sim`` run (each leads its own process group)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                argv = (entry / "cmdline").read_bytes().split(b"\0")
            except OSError:
                continue
            if b"car" in argv and str(run / "fleet.toml").encode() in argv:
                pids.append(int(entry.name))
    return pids


class Operator:
    """The benchmark's operator on the run's bus (heartbeat, starts, releases)."""

    def __init__(self, fleet):
        self.bus = FleetBus(fleet.bus, fleet.fleet, None, listen=(f"tcp/127.0.0.1:{free_port()}",),
                            kinds=("status",), operator_kinds=())
        self.bus.open()
        self.session = OperatorSession(fleet, self.bus)
        self.inbox = messages.Inbox()

    def poll(self, seconds: float = 0.0) -> None:
        end = time.monotonic() + seconds
        while True:
            self.session.step()
            for received in self.bus.drain():
                message = self.inbox.accept(received.payload, key_sender=received.sender)
                if message is not None:
                    self.session.heard(message, received.at)
            if time.monotonic() >= end:
                return
            time.sleep(0.01)

    def wait_states(self, wanted: set[str], timeout_s: float) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            self.poll(0.02)
            if all(seen.state in wanted for seen in self.session.cars.values()):
                return True
        return False


def one_stop(run: Path, log: CommandLog, operator: Operator, ids: list[int], delay_s: float, path: str,
             pause: bool, control_port: int, release_by_stop: bool = False) -> dict:
    now = time.time()
    operator.session.start({car: (now + 0.5, 0.4) for car in ids})
    operator.poll(0.5 + delay_s)
    moving = log.moving()
    pids = car_pids(run) if pause else []
    for pid in pids:
        os.killpg(pid, signal.SIGSTOP)
    issued = time.time()
    if path == "session":  # what trustfg go's stop key and the dashboard's button do
        operator.session.estop()
        exit_status = 0
    else:
        exit_status = subprocess.run([sys.executable, "-m", "trustfg", "stop", "--config", str(run / "fleet.toml"),
                                      "--path", path, "--wait", "1"], capture_output=True, timeout=30).returncode
    operator.poll(HOLD_S)
    for pid in pids:
        os.killpg(pid, signal.SIGCONT)
    if pause:
        operator.poll(HOLD_S)  # the processes, resumed, command motion: the cars must hold
    held = log.held_since(issued, ids)
    latency = max((held[car] - issued for car in moving if held[car] is not None), default=None)
    row = {"path": path, "car_processes_paused": pause, "moving_at_stop": sorted(moving),
           "latency_s": None if latency is None else round(latency, 4),
           "all_stopped": all(held[car] is not None for car in ids),
           "moved_again": sorted(log.moved_after(max((t for t in held.values() if t), default=issued))),
           "stop_exit": exit_status}
    if release_by_stop:
        released = subprocess.run([sys.executable, "-m", "trustfg", "stop", "--config", str(run / "fleet.toml"),
                                   "--release"], capture_output=True, text=True, timeout=30)
        row["release_exit"] = released.returncode
        row["release_confirmed"] = released.returncode == 0 and released.stdout.count("not latched") == len(ids)
        row["release_asked_again"] = "subscribing to status again" in released.stderr
    operator.session.release()
    operator.wait_states({"waiting", "arrived"}, 10.0)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(b'{"reset": true}', ("127.0.0.1", control_port))
    operator.poll(0.5)
    return row


def summary(rows: list[dict]) -> dict:
    values = np.array([r["latency_s"] for r in rows if r["latency_s"] is not None]) * 1e3
    if not len(values):
        return {"stops": len(rows)}
    return {"stops": len(rows), "measured": len(values), "median_ms": round(float(np.median(values)), 1),
            "p90_ms": round(float(np.percentile(values, 90)), 1), "max_ms": round(float(values.max()), 1),
            "all_stopped": all(r["all_stopped"] for r in rows),
            "moved_again": sum(bool(r["moved_again"]) for r in rows)}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=20, help="e-stop rounds with trustfg stop's default (both paths)")
    parser.add_argument("--bus-rounds", type=int, default=5, help="e-stop rounds on the bus path alone")
    parser.add_argument("--session-rounds", type=int, default=5,
                        help="e-stop rounds from a running operator's session (go's key, the dashboard's button)")
    parser.add_argument("--release-rounds", type=int, default=0,
                        help="rounds that stop on the links with the car processes frozen, then release with "
                             "trustfg stop --release")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random moments")
    parser.add_argument("--out", type=Path, default=None, help="write every stop as JSON here")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    run = Path(tempfile.mkdtemp(prefix="bench-estop-"))
    control_port = free_port(socket.SOCK_DGRAM)
    sim = subprocess.Popen([sys.executable, "-m", "trustfg", "sim", "--no-dashboard", "--stay", "--timeout", "3600",
                            "--out", str(run), f"--mocap=--control-port={control_port}"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    rows: list[dict] = []
    operator = None
    try:
        for line in sim.stdout:
            if "go (seed" in line:
                break
        fleet = load_scenario(run / "fleet.toml")
        ids = [c.id for c in fleet.cars]
        operator = Operator(fleet)
        operator.poll(1.0)
        operator.session.abort()  # the launcher's own trial: ours start from the starts
        operator.wait_states({"waiting"}, 10.0)
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.sendto(b'{"reset": true}', ("127.0.0.1", control_port))
        plan = ([("both", k % 4 == 3, False) for k in range(args.rounds)] + [("bus", False, False)] * args.bus_rounds
                + [("session", False, False)] * args.session_rounds + [("link", True, True)] * args.release_rounds)
        for k, (path, pause, release_by_stop) in enumerate(plan):
            row = one_stop(run, CommandLog(run / "commands.csv"), operator, ids, float(rng.uniform(1.0, 4.0)),
                           "link" if pause else path, pause, control_port, release_by_stop)
            rows.append(row)
            print(f"stop {k + 1}/{len(plan)}: {row}", flush=True)
    finally:
        if operator is not None:
            operator.bus.close()
        os.killpg(sim.pid, signal.SIGINT)
        sim.wait(60)
    both = [r for r in rows if r["path"] in ("both", "link") and "release_exit" not in r]
    releases = [r for r in rows if "release_exit" in r]
    result = {"trustfg stop (both paths; every 4th: link only, car processes stopped)": summary(both),
              "of which car processes stopped": summary([r for r in both if r["car_processes_paused"]]),
              "bus path alone": summary([r for r in rows if r["path"] == "bus"]),
              "an operator's session (both paths)": summary([r for r in rows if r["path"] == "session"]),
              "trustfg stop --release after a link stop, car processes stopped and resumed": {
                  "releases": len(releases), "confirmed": sum(r["release_confirmed"] for r in releases),
                  "status asked again": sum(r["release_asked_again"] for r in releases),
                  "stops": summary(releases)},
              "rows": rows}
    for name, numbers in result.items():
        if name != "rows":
            print(f"{name}: {numbers}")
    if args.out:
        args.out.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

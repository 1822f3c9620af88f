"""What a ``trustfg sim`` run records and how it is summarised: the observer on the bus
(:class:`Recorder`), the summary from mocap-sim's ground truth and the cars' own
statistics (:func:`summarise`, written to RUN/summary.json) and its printout."""

from __future__ import annotations

import csv
import json
from collections import Counter, defaultdict, deque
from pathlib import Path

import numpy as np

from ...agent import messages
from ...agent.config import Scenario
from ...agent.world import build_sdf
from ..bus.session import FleetBus
from ..sim.run_record import RunRecord, arrivals, motion_summary, plan_outcomes
from ..sim.trust_record import clock_offsets, lies_due, trust_over_time


class Recorder:
    """The observer on the bus: records every message, keeps what the summary needs."""

    def __init__(self, bus: FleetBus, path: Path):
        self.bus = bus
        self.inbox = messages.Inbox()
        self.file = open(path, "w")
        self.counts: Counter = Counter()
        self.per_sender: dict[int, Counter] = defaultdict(Counter)
        self.status: dict[int, messages.StatusMessage] = {}
        self.trust: dict[int, messages.TrustReport] = {}
        self.trust_log: deque = deque(maxlen=200_000)
        """(arrival, truster, trustee, overall trust) of every trust report, for the summary."""
        self.poses: dict[int, deque] = defaultdict(lambda: deque(maxlen=2))
        """The last two poses each car published (its speed, for fault schedules)."""

    def poll(self) -> None:
        for received in self.bus.drain():
            message = self.inbox.accept(received.payload, key_sender=received.sender)
            record = {"t": round(received.at, 4), "sender": received.sender, "kind": received.kind}
            if message is None:
                record["dropped"] = True
            else:
                record["message"] = messages.to_dict(message)
                self.counts[received.kind] += 1
                self.per_sender[received.sender][received.kind] += 1
                if isinstance(message, messages.StatusMessage):
                    self.status[message.sender] = message
                elif isinstance(message, messages.PoseMessage) and message.valid:
                    self.poses[message.sender].append(message)
                elif isinstance(message, messages.TrustReport):
                    self.trust[message.sender] = message
                    self.trust_log.extend((received.at, message.sender, peer, pt.trust)
                                          for peer, pt in message.peers.items())
            self.file.write(json.dumps(record) + "\n")

    def close(self) -> None:
        self.file.close()


def read_ground_truth(path: Path, ids: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(times (T,), states (T, n, 5)) from mocap-sim's CSV; rows of a time step together."""
    rows = defaultdict(dict)
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            rows[float(row["t"])][int(row["car_id"])] = [float(row[k]) for k in ("x", "y", "yaw", "v", "omega")]
    times = sorted(t for t, cars in rows.items() if all(i in cars for i in ids))
    states = np.array([[rows[t][i] for i in ids] for t in times])
    return np.array(times), states


def summarise(scenario: Scenario, out: Path, recorder: Recorder, t_go: float | None,
              crashed: list[str]) -> dict:
    """The RUN keys (fleet.sim.run_record) from mocap-sim's ground truth, plus what only a run of
    processes has: replan times, messages, command timing, crashes."""
    ids = [c.id for c in scenario.cars]
    times, states = read_ground_truth(out / "ground_truth.csv", ids)
    rel_times = times - (t_go or times[0])
    depart = [0.0] * len(ids)
    start = next((json.loads(line)["message"] for line in open(out / "messages.jsonl")
                  if '"kind": "start"' in line and '"message"' in line), None)
    if start and t_go is not None:
        depart = [start["cars"][str(i)]["depart"] - t_go for i in ids]
    record = RunRecord(seed=-1, car_ids=ids, radii=[c.radius_m for c in scenario.cars], times=rel_times,
                       states=states, arrived_at=arrivals(scenario, rel_times, states), depart_at=depart,
                       trust_times=np.zeros(0), trust=np.zeros(0), transparency=np.zeros(0),
                       epsilon=np.zeros(0), replan_ms=[], counters=[], inbox=[])
    stats = {i: _read_json(out / f"car_{i}.json") for i in ids}
    summary = {"scenario": scenario.name} | motion_summary(scenario, record, build_sdf(scenario.world)) | {
        "trust": [[1.0 if a == b else _trust(recorder, a, b) for b in ids] for a in ids],
        "replan_ms": {str(i): _replan_stats(stats[i]) for i in ids},
        "messages": dict(recorder.counts) | {"dropped_by_recorder": dict(recorder.inbox.dropped)},
        "messages_per_car": {str(i): dict(recorder.per_sender.get(i, {})) for i in ids},
        "control": {str(i): (stats[i] or {}).get("control") for i in ids},
        "cpu_driving": {str(i): (stats[i] or {}).get("cpu_driving") for i in ids},
        "replan_cpu": {str(i): (stats[i] or {}).get("replan_cpu") for i in ids},
        "first_broke": {str(i): (stats[i] or {}).get("first_broke") for i in ids},
        **_outcomes(ids, stats),
        "crashed": sorted(int(name.split()[1]) for name in crashed if name.startswith("car"))
        + (["mocap-sim"] if "mocap-sim" in crashed else []),
        "clock_offsets": clock_offsets(stats, ids),
    }
    if t_go is not None:
        summary |= trust_over_time(scenario, list(recorder.trust_log), t_go)
        if scenario.liars:
            summary |= lies_due(scenario, out / "messages.jsonl", times, states, t_go)
    return summary


def _trust(recorder: Recorder, a: int, b: int) -> float | None:
    report = recorder.trust.get(a)
    if report is None or b not in report.peers:
        return None
    return round(report.peers[b].trust, 4)


def _read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _outcomes(ids: list[int], stats: dict[int, dict | None]) -> dict:
    """``plans`` and ``deadlocks`` (fleet totals, fleet.sim.run_record.plan_outcomes) and
    ``plan_outcomes`` per car, from each car's own counters."""
    outcomes = plan_outcomes([(stats[i] or {}).get("agent", {}) for i in ids])
    per_car = outcomes.pop("outcomes")
    return outcomes | {"plan_outcomes": {str(i): {k.removeprefix("plans_"): v for k, v in car.items()}
                                         for i, car in zip(ids, per_car)}}


def _replan_stats(stats: dict | None) -> dict | None:
    if not stats or not stats.get("replan_ms"):
        return None
    values = np.array(stats["replan_ms"])
    return {"count": len(values), "median": round(float(np.median(values)), 2),
            "p95": round(float(np.percentile(values, 95)), 2), "max": round(float(values.max()), 2)}


def print_summary(summary: dict) -> None:
    ids = summary["car_ids"]
    print(f"\n== trustfg sim: {summary['scenario']}, cars {ids}")
    print(f"breaches (pairs closer than the required clearance): {summary['breaches'] or 'none'}")
    print(f"reached goal: {summary['reached_goal']}, makespan {summary['makespan_s']} s, "
          f"obstacle clearance {summary['obstacle_min_clearance']} m")
    print("min distance matrix (m):")
    print(np.array2string(np.array(summary["min_distance"]), precision=2, suppress_small=True))
    print("trust matrix (truster row, trustee column):")
    for a, row in zip(ids, summary["trust"]):
        print(f"  {a}: " + "  ".join("  -  " if v is None else f"{v:.2f}" for v in row))
    print("replan ms (median / p95):  " + "  ".join(
        f"{i}: {r['median']}/{r['p95']}" if r else f"{i}: -" for i, r in summary["replan_ms"].items()))
    print("plans (verified first try / on retry / fallback), deadlocks:  " + "  ".join(
        f"{i}: {o['first']}/{o['retry']}/{o['fallback']}" + (f" (+{o['kept']} kept)" if o.get("kept") else "")
        + f" {o['deadlocks']}" for i, o in summary["plan_outcomes"].items()))
    print("commands (Hz, lateness p99 ms, ticks stopped on a lapsed permit): " + "  ".join(
        f"{i}: {c['rate_hz']}/{c['jitter_ms_p99']}/{c.get('lease_lapsed', '-')}" if c else f"{i}: -"
        for i, c in summary["control"].items()))
    print("cpu (share of one core, whole run / go to first arrival): " + "  ".join(
        f"{name}: {c['share']}/{c.get('share_go_first_arrival')}" if c else f"{name}: -"
        for name, c in summary.get("cpu", {}).items()))
    machine = summary.get("machine")
    if machine and machine["saturated"]:
        window = "the first arrival" if machine.get("until", "first_arrival") == "first_arrival" \
            else "the end of the run (no car arrived)"
        print(f"the machine was saturated: the processes took {machine['busy_cores']} of its {machine['cores']} "
              f"cores from the go to {window}, so the cars were starved -- replan times, lapsed "
              "permits and arrivals measure the machine here, not the planner")
    print(f"messages: {summary['messages']}")
    if "liar_id" in summary:
        print(f"liars {summary['liar_ids']}: min distance from honest cars {summary['liar_min_distance']}, "
              f"honest-liar breaches {summary['liar_breaches'] or 'none'}, first lie due at "
              f"{summary.get('first_lie_due_s', '-')} s, sustained from {summary.get('sustained_lie_due_s', '-')} s, "
              f"detected at {summary.get('trust_detected_at_s', '-')} s")
    print("clock offsets as peers estimate them (ms, median): " + "  ".join(
        f"{car}: {ms:+.0f}" for car, ms in summary.get("clock_offsets", {}).items()))
    print(f"crashed: {summary['crashed'] or 'none'}")

"""What a car process tells about itself: its control loop's timing, what it waits for
(one line, while it starts up or holds), and its ``--stats`` file at exit."""

from __future__ import annotations

import itertools
import json
import logging
import math
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...agent.operator_state import Mode

if TYPE_CHECKING:  # the command loop's process imports this module: no Zenoh there
    from ..bus.session import FleetBus

log = logging.getLogger("trustfg.fleet.car.process")


@dataclass
class ControlStats:
    """Timing of the control loop, measured on the loop itself."""

    sent: int = 0
    stops: int = 0
    stale_pose_stops: int = 0
    guard_limited: int = 0
    """Ticks whose forward speed the proximity guard lowered (agent.guard)."""
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


def waiting_for(*, motive: str | None, body: int | None, link: str | None, absent_peers: list[int],
                mode: Mode, hears_operator: bool) -> tuple[str, ...]:
    """What a car process waits for, in words (empty: nothing): ``motive`` (its address and
    the last problem) until NatNet is up, ``body`` until its rigid body is tracked in the
    stream, ``link`` while its car does not answer, the peers not on the bus, and what the
    operator has yet to do."""
    items = []
    if motive is not None:
        items.append(f"Motive at {motive}")
    if body is not None:
        items.append(f"its rigid body {body} tracked in Motive's stream")
    if link is not None:
        items.append(f"its car to answer on {link}")
    if absent_peers:
        items.append("peers " + " ".join(map(str, absent_peers)) + " on the bus")
    if mode in (Mode.WAITING, Mode.ARRIVED):
        items.append("the operator's start")
    elif mode == Mode.E_STOPPED:
        items.append("the operator's release")
    if not hears_operator:
        items.append("the operator's heartbeat")
    return tuple(items)


class WaitingLog:
    """Says in one line what a car process waits for: when that changes, and every
    ``reminder_s`` while it does not."""

    def __init__(self, car_id: int, reminder_s: float = 30.0):
        self.car_id = car_id
        self.reminder_s = reminder_s
        self.said: tuple[str, ...] = ()
        self._said_at = -math.inf

    def say(self, state: str, waiting: tuple[str, ...], now: float) -> None:
        if waiting == self.said and now - self._said_at < self.reminder_s:
            return
        self.said, self._said_at = waiting, now
        if waiting:
            log.info("car %d (%s): waiting for %s", self.car_id, state, "; ".join(waiting))
        else:
            log.info("car %d (%s): everything is up", self.car_id, state)


def status_counters(process: Any, now: float) -> dict[str, int]:
    """The counters a car process's status message carries (at most 64: the plan ages, the
    plan outcomes, deadlocks, the car link's and the peers' clock offsets first, which resync
    checks, the dashboard and ``trustfg check`` read)."""
    counters = dict(process.agent.counters | process.counters)
    counters |= {f"inbox_{k}": v for k, v in process.inbox.dropped.items()}
    control = process.command_report  # the command loop's (fleet.car.velocity_loop)
    counters["commands_sent"] = control.sent
    counters["stale_pose_stops"] = control.stale_pose_stops
    counters["guard_limited"] = control.guard_limited
    counters["link_lease_lapsed"] = control.lease_lapsed
    counters["link_loop_restarts"] = process.command.restarts
    counters["lap"] = process.laps.lap
    if process.agent.liar is not None:
        counters |= {f"attack_{k}": v for k, v in process.agent.liar.counters.items()}
    for peer, view in process.agent.peers.items():  # how fresh each peer's plan is
        counters[f"plan_age_ms_{peer}"] = int(min(1e9, max(0.0, now - view.accepted_received) * 1e3))
    counters |= clock_counters(process.agent.clock_offsets())  # each peer's clock, as we estimate it
    # the car link, as the car's answers tell
    counters["link_answer_age_ms"] = int(min(1e9, max(0.0, now - control.answered_at) * 1e3))
    counters["link_e_stop_latched"] = int(control.latched)
    # plan ages and outcomes (agent.safe_plan), deadlocks, the link, the peers' clocks (agent.clocks)
    first = ("plan", "deadlock", "link_", "clock_")
    return dict(sorted(counters.items(), key=lambda kv: not kv[0].startswith(first))[:64])


def clock_counters(offsets: dict[int, float]) -> dict[str, int]:
    """Peers' clock offsets as status counters (counts are >= 0): ``clock_ahead_ms_N`` or
    ``clock_behind_ms_N``, milliseconds (dashboard.state reads them back)."""
    return {f"clock_{'ahead' if offset >= 0 else 'behind'}_ms_{peer}": int(round(abs(offset) * 1e3))
            for peer, offset in offsets.items()}


def write_stats(path: Path, process: Any, bus: FleetBus | None) -> None:
    """The ``--stats`` JSON summary of a car process (fleet.car.process.CarProcess), at its exit."""
    nat = process._natnet.stats() if process._natnet is not None else None
    agent = process.agent
    stats = {
        "car_id": process.car.id,
        "state": process.state,
        "trial": process.operation.trial,
        "at_goal": process.arrived,
        "replan_ms": [round(x, 3) for x in agent.replan_ms],
        "control": process.command.final or {},
        "agent": dict(agent.counters),
        "trust": dict(agent.trust.counters),
        "clock_offsets_s": {str(peer): round(offset, 4) for peer, offset in agent.clock_offsets().items()},
        "attack": dict(agent.liar.counters) if agent.liar is not None else None,
        "inbox_dropped": dict(process.inbox.dropped),
        "inbox_accepted": dict(process.inbox.accepted),
        "bus": dict(bus.counters) if bus is not None else {},
        "natnet": {"received": nat.received, "decoded": nat.decoded, "skipped": nat.skipped, "dropped": nat.dropped,
                   "rejected": dict(nat.rejected)} if nat is not None else None,
        "link_sent": process.command.link.get("link_sent"),
        "link_answers": process.command.link.get("link_answers"),
        "cpu_driving": process.driving_cpu(),
        "replan_cpu": {outcome: {"count": tally.count, "cpu_s": round(tally.cpu_s, 4)}
                       for outcome, tally in sorted(process.replan_cpu.items())},
        "first_broke": dict(sorted(process.first_broke.items())),
    }
    path.write_text(json.dumps(stats, indent=1))

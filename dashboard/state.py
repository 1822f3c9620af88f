"""What the dashboard knows of the fleet, built from fleet messages alone (pure logic).

:class:`FleetView` takes decoded messages with the time they arrived -- live from the bus
or replayed from a recording -- and keeps, per car, its latest pose, plan, trust report and
status, message rates over the last ``RATE_WINDOW_S``, the running minimum distance between
every pair of cars (from ground truth when the recording has it, else from the poses the
cars publish), and the alerts a person watching should see: ``breach`` (two cars closer
than their breach distance now), ``low_trust`` (a car's trust in a peer below
``LOW_TRUST``), ``stale_peer`` (nothing heard from a car for ``STALE_AFTER_S``, or its
process left the bus), ``lost_pose`` (a car does not see itself, or its pose is older than
``LOST_POSE_AFTER_S``) and ``clock`` (a car's clock more than ``CLOCK_ALERT_S`` off, the
median of its peers' estimates: its plans are still corrected, but its NTP needs a look).
With a sensing range (SensingConfig) it also shows who sees whom, from the poses and each
car's range, and for every trust a car reports whether its own eyes or its witnesses'
testimonies set it (:func:`trust_source`).
"""

from __future__ import annotations

import math
from collections import defaultdict, deque
from dataclasses import dataclass, field

import numpy as np
from matplotlib.colors import to_hex

from ..agent import messages, metrics
from ..agent.config import Scenario, TrustConfig
from ..agent.sight import in_sight
from ..agent.world import build_sdf

RATE_WINDOW_S = 2.0
STALE_AFTER_S = 1.5
LOST_POSE_AFTER_S = 0.5
LOW_TRUST = 0.6
PLAN_SAMPLES = 40
CLOCK_ALERT_S = 0.1


def css_color(name: str) -> str:
    """A colour the browser understands (matplotlib names like 'tab:blue' become hex;
    a name matplotlib does not know becomes grey)."""
    try:
        return to_hex(name)
    except ValueError:
        return "#7f7f7f"


@dataclass
class CarView:
    id: int
    color: str
    goal: tuple[float, float]
    radius: float
    pose: messages.PoseMessage | None = None
    pose_at: float = -math.inf
    plan: messages.PlanMessage | None = None
    trust: messages.TrustReport | None = None
    status: messages.StatusMessage | None = None
    heard_at: float = -math.inf
    alive: bool | None = None
    arrivals: dict[str, deque] = field(default_factory=lambda: defaultdict(deque))


def trust_source(entry: messages.PeerTrust, config: TrustConfig) -> str:
    """Where a reported trust came from: ``"witnesses"`` where testimonies moved it off
    the reporter's own evidence (the report's tau is fused, its alpha and beta are the
    reporter's own: agent.trust.TrustBook.report), else ``"own"``, or ``"none"`` with no
    evidence of its own at all (a stranger's prior)."""
    pa, pb = config.prior_alpha, config.prior_beta
    own = [(a + pa + 1.0) / (a + b + pa + pb + 2.0) for a, b in zip(entry.alpha, entry.beta)]
    if any(abs(fused - mine) > 1e-3 for fused, mine in zip(entry.tau, own)):
        return "witnesses"
    return "own" if sum(entry.alpha) + sum(entry.beta) > 0.0 else "none"


def plan_outcomes(status: messages.StatusMessage | None) -> dict[str, int] | None:
    """How the car's replans ended (verified first try, on retry, fallbacks, kept) and its
    deadlocks and steps aside, from the counters of its status (agent.safe_plan,
    agent.deadlock)."""
    if status is None:
        return None
    c = status.counters
    return {"first": c.get("plans_first", 0), "retry": c.get("plans_retry", 0),
            "fallback": c.get("plans_fallback", 0), "kept": c.get("plans_kept", 0), "deadlocks": c.get("deadlocks", 0),
            "aside": c.get("deadlock_steps_aside", 0)}


class FleetView:
    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.cars = {c.id: CarView(c.id, css_color(color), c.goal, c.radius_m)
                     for c, color in zip(scenario.cars, scenario.car_colors())}
        self.ids = [c.id for c in scenario.cars]
        n = len(self.ids)
        self.min_distance = np.full((n, n), np.inf)
        np.fill_diagonal(self.min_distance, 0.0)
        self.distance_source = "poses"
        self.now = -math.inf
        self.alert_since: dict[tuple, float] = {}
        self.breach_distance = metrics.breach_distances([c.radius_m for c in scenario.cars],
                                                        scenario.safety.clearance_m)
        """(n, n) centre distance below which each pair breaches, in ``ids`` order."""
        self._index = {car_id: i for i, car_id in enumerate(self.ids)}
        self.messages = 0
        self.ranges = {c.id: scenario.sensing_range(c) for c in scenario.cars}
        """Each car's sensing range, m (inf: it sees every peer)."""
        self.limited = any(math.isfinite(r) for r in self.ranges.values())
        self._walls = build_sdf(scenario.world) if self.limited and scenario.sensing.line_of_sight else None

    # --- inputs ----------------------------------------------------------------------------

    def update(self, message: messages.Message, at: float) -> None:
        """One decoded message that arrived (or was recorded) at time ``at``."""
        self.now = max(self.now, at)
        car = self.cars.get(message.sender)
        if car is None:
            return  # the operator's start, or a car this map does not know
        self.messages += 1
        car.heard_at = at
        window = car.arrivals[message.kind]
        window.append(at)
        while window and window[0] < at - RATE_WINDOW_S:
            window.popleft()
        if isinstance(message, messages.PoseMessage):
            car.pose, car.pose_at = message, at
            if message.valid and self.distance_source == "poses":
                self._track_distances({cid: (c.pose.x, c.pose.y) for cid, c in self.cars.items()
                                       if c.pose is not None and c.pose.valid and at - c.pose_at <= LOST_POSE_AFTER_S})
        elif isinstance(message, messages.PlanMessage):
            car.plan = message
        elif isinstance(message, messages.TrustReport):
            car.trust = message
        elif isinstance(message, messages.StatusMessage):
            car.status = message

    def truth(self, at: float, positions: dict[int, tuple[float, float]]) -> None:
        """A ground-truth sample (every car at once); from then on it drives the distances."""
        self.now = max(self.now, at)
        if self.distance_source != "ground truth":
            self.distance_source = "ground truth"
            self.min_distance[:] = np.inf
            np.fill_diagonal(self.min_distance, 0.0)
        self._track_distances(positions)

    def liveliness(self, car_id: int, alive: bool) -> None:
        if car_id in self.cars:
            self.cars[car_id].alive = alive

    def _track_distances(self, positions: dict[int, tuple[float, float]]) -> None:
        for a, ia in enumerate(self.ids):
            for b in range(a + 1, len(self.ids)):
                ib = self.ids[b]
                if ia in positions and ib in positions:
                    d = math.dist(positions[ia], positions[ib])
                    if d < self.min_distance[a, b]:
                        self.min_distance[a, b] = self.min_distance[b, a] = d

    # --- outputs ---------------------------------------------------------------------------

    def distances_now(self) -> dict[tuple[int, int], float]:
        seen = {cid: (c.pose.x, c.pose.y) for cid, c in self.cars.items()
                if c.pose is not None and c.pose.valid and self.now - c.pose_at <= LOST_POSE_AFTER_S}
        return {(a, b): math.dist(seen[a], seen[b]) for a in seen for b in seen if a < b}

    def sight_now(self) -> list[list[int]] | None:
        """[a, b] for every car a that sees car b now, from their fresh poses and a's range
        (and the walls, with line of sight); None when every car sees every peer."""
        if not self.limited:
            return None
        seen = {cid: (c.pose.x, c.pose.y) for cid, c in self.cars.items()
                if c.pose is not None and c.pose.valid and self.now - c.pose_at <= LOST_POSE_AFTER_S}
        pairs = []
        for a, where in seen.items():
            others = [b for b in seen if b != a]
            if others:
                mask = in_sight(where, np.array([seen[b] for b in others]), self.ranges[a], self._walls)
                pairs += [[a, b] for b, ok in zip(others, mask) if ok]
        return sorted(pairs)

    def clock_offset(self, car_id: int) -> float | None:
        """The median of the peers' estimates of ``car_id``'s clock offset (seconds), from the
        ``clock_ahead_ms_N`` / ``clock_behind_ms_N`` counters of their status."""
        seen = []
        for other in self.cars.values():
            counters = other.status.counters if other.status is not None and other.id != car_id else {}
            for sign, key in ((1, f"clock_ahead_ms_{car_id}"), (-1, f"clock_behind_ms_{car_id}")):
                if key in counters:
                    seen.append(sign * counters[key] / 1e3)
        return float(np.median(seen)) if seen else None

    def alerts(self) -> list[dict]:
        found = []
        for a in self.cars:
            offset = self.clock_offset(a)
            if offset is not None and abs(offset) > CLOCK_ALERT_S:
                found.append(("clock", (a,), f"car {a}'s clock is {offset * 1e3:+.0f} ms off, its peers say"))
        for (a, b), d in self.distances_now().items():
            if d < self.breach_distance[self._index[a], self._index[b]]:
                found.append(("breach", (a, b), f"cars {a} and {b} are {d:.2f} m apart"))
        for a, car in self.cars.items():
            if car.trust is not None:
                for b, pt in car.trust.peers.items():
                    if b in self.cars and pt.trust < LOW_TRUST:
                        found.append(("low_trust", (a, b), f"car {a} trusts car {b} only {pt.trust:.2f}"))
            silent = self.now - car.heard_at
            if car.alive is False or (math.isfinite(car.heard_at) and silent > STALE_AFTER_S):
                why = "left the bus" if car.alive is False else f"silent for {silent:.1f} s"
                found.append(("stale_peer", (a,), f"car {a} {why}"))
            if car.pose is not None and (not car.pose.valid or self.now - car.pose_at > LOST_POSE_AFTER_S):
                found.append(("lost_pose", (a,), f"car {a} has lost its pose"))
        current = {(kind, cars) for kind, cars, _ in found}
        for key in list(self.alert_since):
            if key not in current:
                del self.alert_since[key]
        out = []
        for kind, cars, text in found:
            since = self.alert_since.setdefault((kind, cars), self.now)
            out.append({"kind": kind, "cars": list(cars), "text": text, "since": round(since, 3)})
        return out

    def snapshot(self) -> dict:
        cars = []
        for cid in self.ids:
            car = self.cars[cid]
            pose = None
            if car.pose is not None:
                pose = {"x": car.pose.x, "y": car.pose.y, "yaw": car.pose.yaw, "valid": car.pose.valid,
                        "age_s": round(self.now - car.pose_at, 3)}
            plan = None
            if car.plan is not None:
                p = car.plan.plan
                times = np.linspace(max(self.now, p.t0), max(p.t_end, self.now), PLAN_SAMPLES)
                plan = np.round(p.position_at(times), 4).tolist()
            status = car.status
            cars.append({
                "id": cid, "color": car.color, "goal": list(car.goal), "radius": car.radius,
                "pose": pose, "plan": plan,
                "state": status.state if status else None, "at_goal": bool(status and status.at_goal),
                "replan_ms": round(status.replan_ms, 2) if status else None,
                "iterations": status.iterations if status else None,
                "rates": {kind: round(len(w) / RATE_WINDOW_S, 1) for kind, w in car.arrivals.items()},
                "clock_offset_ms": None if (offset := self.clock_offset(cid)) is None else round(offset * 1e3, 1),
                "alive": car.alive, "last_heard_s": round(self.now - car.heard_at, 2) if math.isfinite(car.heard_at) else None,
                "outcomes": plan_outcomes(status),
            })
        trust = {}
        for cid in self.ids:
            report = self.cars[cid].trust
            if report is not None:
                trust[str(cid)] = {str(peer): {"trust": round(pt.trust, 4), "tau": [round(x, 4) for x in pt.tau],
                                               "epsilon": round(pt.epsilon, 4),
                                               "source": trust_source(pt, self.scenario.trust)}
                                   for peer, pt in report.peers.items()}
        matrix = [[None if not math.isfinite(x) else round(float(x), 4) for x in row] for row in self.min_distance]
        return {
            "type": "snapshot", "t": self.now, "cars": cars, "trust": trust,
            "min_distance": {"ids": self.ids, "matrix": matrix, "source": self.distance_source},
            "alerts": self.alerts(), "messages": self.messages, "sight": self.sight_now(),
        }

    def map(self) -> dict:
        world = self.scenario.world
        return {
            "type": "map", "fleet": self.scenario.fleet, "scenario": self.scenario.name,
            "bounds": list(world.bounds_m),
            "obstacles": [{"kind": o.kind, "min": list(o.min), "max": list(o.max),
                           "points": [list(p) for p in o.points]} for o in world.obstacles],
            "cars": [{"id": c.id, "color": self.cars[c.id].color, "goal": list(c.goal), "start": list(c.start),
                      "radius": c.radius_m} for c in self.scenario.cars],
            "breach_distance": self.breach_distance.round(4).tolist(), "low_trust": LOW_TRUST,
            "sensing_range": {str(cid): (r if math.isfinite(r) else None) for cid, r in self.ranges.items()},
        }

"""A run of the fleet, however it was made, and the one summary of its executed motion.

The in-process fleet (fleet.sim.in_process) returns a :class:`RunRecord`; ``trustfg sim``
builds one from mocap-sim's ground truth, ``trustfg report`` from a recording. All three
summarise it with :func:`motion_summary` (the RUN keys of docs/user-guide.md), so a
breach, an arrival or a makespan means the same everywhere.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from ...agent import metrics
from ...agent.config import Scenario
from ...agent.world import SignedDistanceField


@dataclass
class RunRecord:
    """Everything a run produced, for metrics and figures."""

    seed: int
    car_ids: list[int]
    radii: list[float]
    times: np.ndarray
    """(T,) time of each recorded step, seconds from the run's start."""
    states: np.ndarray
    """(T, n, 5): x, y, yaw, v, omega of each car (ground truth)."""
    arrived_at: list[float | None]
    depart_at: list[float]
    trust_times: np.ndarray
    trust: np.ndarray
    """(T_trust, n, n): overall trust of truster (row) in trustee (column); diagonal 1."""
    transparency: np.ndarray
    """(T_trust, n, n): transparency trust, same layout."""
    epsilon: np.ndarray
    """(T_trust, n, n): safety distance each car keeps from each peer."""
    replan_ms: list[list[float]]
    counters: list[dict[str, int]]
    inbox: list[dict[str, int]]
    final_plans: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    plan_log: list = field(default_factory=list)
    """(t, car index, Plan) of every replan, when simulate(keep_plans=True)."""
    first_lie_s: list = field(default_factory=list)
    """Per car: when it first published a plan false by more than plan_reject_m within
    what the audit holds it to (agent.attacks.Liar; liars only; None: never)."""
    told: list = field(default_factory=list)
    """Per car: (stamp, plan as published, lied) of every plan a liar published (Liar.told)."""
    tracking_error: list = field(default_factory=list)
    """Per car: how far (m) the car was from where its plan had it, at every step it drove
    on its plan unhindered (departed, not arrived, its command not capped by the guard)."""


def arrivals(scenario: Scenario, times: np.ndarray, states: np.ndarray) -> list[float | None]:
    """When each car first came within the scenario's arrival radius of its goal."""
    goals = np.array([car.goal for car in scenario.cars])
    return metrics.reached_at(times, states[:, :, :2], goals, scenario.arrival_radius_m)


def motion_summary(scenario: Scenario, record: RunRecord, sdf: SignedDistanceField) -> dict:
    """The RUN keys that come from executed motion: distances, breaches, arrivals,
    inconsistency, and (with a liar) how close the honest cars came to it."""
    positions = record.states[:, :, :2]
    radii = np.array(record.radii)
    distance = metrics.min_distance_matrix(positions)
    clearance = metrics.clearance_matrix(distance, radii)
    arrived = record.arrived_at
    reached = [a is not None for a in arrived]
    run = {
        "car_ids": record.car_ids,
        "min_distance": rounded(distance),
        "min_clearance": rounded(clearance),
        "breaches": metrics.breaches(clearance, record.car_ids, scenario.safety.clearance_m),
        "obstacle_min_clearance": round(metrics.obstacle_min_clearance(positions, radii, sdf), 4),
        "reached_goal": reached,
        "makespan_s": round(max(arrived), 3) if all(reached) else None,
        "inconsistency": round(metrics.inconsistency_index(record.times, record.states, record.depart_at, arrived), 4),
    }
    liars = scenario.liars
    if liars:
        lying = [record.car_ids.index(car_id) for car_id in liars]
        honest = [i for i, car_id in enumerate(record.car_ids) if car_id not in liars]
        run["liar_id"] = liars[0]
        run["liar_ids"] = liars
        run["honest_ids"] = [record.car_ids[i] for i in honest]
        run["liar_min_distance"] = [round(float(min(distance[i, j] for j in lying)), 4) for i in honest]
        run["liar_min_clearance"] = round(float(min((clearance[i, j] for i in honest for j in lying),
                                                    default=np.inf)), 4)
        run["liar_breaches"] = [pair for pair in run["breaches"] if (pair[0] in liars) != (pair[1] in liars)]
    return run


def rounded(matrix: np.ndarray) -> list[list[float]]:
    return [[round(float(x), 4) for x in row] for row in matrix]


OUTCOMES = ("plans_first", "plans_retry", "plans_fallback", "plans_unverified", "plans_kept", "deadlocks",
            "deadlock_yields", "deadlock_steps_aside")
"""The counters of how a car's replans ended (agent.safe_plan) and of its deadlocks
(agent.deadlock), as CarAgent counts them."""


def plan_outcomes(counters: list[dict[str, int]]) -> dict:
    """RUN keys from each car's counters (in car order): ``plans`` (fleet totals of
    replans verified first try, on retry, fallbacks, unverified), ``deadlocks``,
    ``deadlock_yields`` and ``deadlock_steps_aside`` (totals), and ``outcomes`` per car."""
    per_car = [{key: int(c.get(key, 0)) for key in OUTCOMES} for c in counters]
    total = {key: sum(car[key] for car in per_car) for key in OUTCOMES}
    return {
        "plans": {key.removeprefix("plans_"): total[key] for key in OUTCOMES if key.startswith("plans_")},
        "deadlocks": total["deadlocks"],
        "deadlock_yields": total["deadlock_yields"],
        "deadlock_steps_aside": total["deadlock_steps_aside"],
        "outcomes": per_car,
    }


def fingerprint(scenario: Scenario) -> str:
    """A digest of everything a run depends on besides its seed (the scene's whole
    configuration, a method's switches included): two runs of one fingerprint and seed
    are the same run (in the same code and environment: fleet.experiments.run_environment)."""
    return hashlib.sha256(repr(scenario).encode()).hexdigest()[:16]

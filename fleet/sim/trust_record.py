"""What a run's trust reports say over time: the trust keys both simulations share.

The in-process fleet samples every car's trust directly (fleet.experiments.paper); ``trustfg
sim`` only hears the trust reports the cars publish, and rebuilds the same keys from them
here: each car's latest report about a peer holds until its next.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...agent import metrics
from ...agent.audit import false_claim_times, sustained_lie
from ...agent.config import Scenario
from ...agent.gp import Plan

TRUST_SETTLE_S = 3.0
"""Honest trust is judged from this long after the start: before, evidence is still coming in."""
TRUST_GAP = 0.2
"""A liar is detected when every honest car trusts it this much less than every honest peer."""
LIE_SUSTAINED_S = 1.0
"""A lie is sustained once it has kept coming due for this long (agent.audit.sustained_lie):
a shorter one, such as a liar's lie about its departure told while it still stands, can
leave it less than TRUST_GAP below honest peers, and forgetting closes the gap before the
next lie. Detection is timed from a sustained lie."""


def trust_over_time(scenario: Scenario, log: list[tuple[float, int, int, float]], t_go: float) -> dict:
    """The trust keys of the in-process experiments (fleet.experiments.paper.summarise) from the
    trust reports the observer heard: each car's latest report holds until its next."""
    ids = [c.id for c in scenario.cars]
    index = {car: i for i, car in enumerate(ids)}
    current = np.full((len(ids), len(ids)), np.nan)
    np.fill_diagonal(current, 1.0)
    times, matrices = [], []
    for at, truster, trustee, value in sorted(log):
        if truster in index and trustee in index:
            current[index[truster], index[trustee]] = value
            times.append(at - t_go)
            matrices.append(current.copy())
    if not times:
        return {}
    times, trust = np.array(times), np.nan_to_num(np.array(matrices), nan=2.0 / 3.0)
    liars = [index[i] for i in scenario.liars]
    honest = [i for i in range(len(ids)) if i not in liars]
    after = times >= TRUST_SETTLE_S
    pairs = [trust[after][:, a, b] for a in honest for b in honest if a != b]
    out = {"honest_trust_min_after_settle": round(float(np.min(pairs)), 4) if pairs and after.any() else None}
    if liars:
        found = [metrics.trust_detection(times, trust, liar, honest, TRUST_GAP) for liar in liars]
        out["trust_detected_at_s"] = None if None in found else round(max(found), 2)
    return out


def clock_offsets(stats: dict[int, dict | None], ids: list[int]) -> dict[str, float]:
    """Per car: the median of its peers' estimates of its clock offset, ms."""
    seen = {i: [s["clock_offsets_s"][str(i)] for s in stats.values()
                if s and str(i) in s.get("clock_offsets_s", {})] for i in ids}
    return {str(i): round(float(np.median(v)) * 1e3, 1) for i, v in seen.items() if v}


def lies_due(scenario: Scenario, messages_path: Path, times: np.ndarray, states: np.ndarray,
             t_go: float) -> dict:
    """When the liars' lies came due (s after the go), from every plan the liars published
    as the observer heard them, against mocap-sim's ground truth (agent.audit's rules: the
    earliest moments the lies could have been caught). ``first_lie_due_s``: the first lie
    of any liar. ``sustained_lie_due_s``: when every liar had begun a lie lasting
    LIE_SUSTAINED_S (agent.audit.sustained_lie) -- a liar standing still has nothing its
    attack can bend, so a lie told before it stands (before the go, or before a deadlock)
    stops there, and trust forgets it. None: no such lie came due."""
    ids = [c.id for c in scenario.cars]
    told: dict[int, list[tuple[float, Plan, bool]]] = {car: [] for car in scenario.liars}
    with open(messages_path) as f:
        for line in f:
            if '"plan"' not in line:
                continue
            record = json.loads(line)
            message = record.get("message", {})
            if record.get("kind") == "plan" and message.get("id") in told:
                plan = Plan(message["t0"], message["dt"], np.array(message["positions"]),
                            np.array(message["velocities"]))
                told[message["id"]].append((message["stamp"], plan, True))  # judged by the truth alone
    first, sustained = [], []
    for car, plans in told.items():
        due = false_claim_times(sorted(plans, key=lambda told: told[0]),
                                positions_at(times, states[:, ids.index(car), :2]), scenario.trust)
        if len(due):
            first.append(float(due[0]) - t_go)
        sustained.append(sustained_lie(due, scenario.trust, LIE_SUSTAINED_S))
    return {"first_lie_due_s": round(min(first), 2) if first else None,
            "sustained_lie_due_s": None if not sustained or None in sustained
            else round(max(sustained) - t_go, 2)}


def positions_at(times: np.ndarray, xy: np.ndarray):
    """Where a car truly was at given times, linear between the recorded ones."""
    return lambda t: np.stack([np.interp(t, times, xy[:, 0]), np.interp(t, times, xy[:, 1])], axis=1)

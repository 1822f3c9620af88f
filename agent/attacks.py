"""How a liar lies: the attack suite, for experiments (agent.config.attacks names and
documents every attack and its parameters).

A liar plans and drives on its true plan (except ``framing``, which steers the car). What
it tells the fleet is a function of that true plan, the time, its own seeded generator
and what it sees (the other cars' observed motion): :meth:`Liar.plan` turns the true plan
into the plan and stamp it publishes, :meth:`Liar.testimony` its honest trust report into
the one it publishes, :meth:`Liar.steer` its planning request into the one it solves.
Several attacks joined by ``+`` apply in the order named.

Every attack, and the defence that stops it: docs/design/trust.md, "The attack suite".
"""

from __future__ import annotations

import dataclasses
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from .config import AttackConfig
from .gp import Plan
from .messages import PeerTrust, TrustReport
from .planner import PeerConstraint, PlanRequest
from .sightings import Motion

HISTORY = 64
"""Own true plans kept for replay (at 5 Hz: 12.8 s)."""
TOLD = 512
"""Plans as published kept for experiments' bookkeeping (at 5 Hz: 100 s)."""
FRAMING_SPEED_MPS = 0.5
"""How fast a framer plans to close in on its victim."""


@dataclass
class Liar:
    """One car's attack and the little it must remember."""

    car_id: int
    attack: AttackConfig
    rng: np.random.Generator
    partners: frozenset[int] = frozenset()
    """The other cars of a colluding group."""
    history: deque = field(default_factory=lambda: deque(maxlen=HISTORY))
    """(time, own true plan), for replay."""
    first_at: float | None = None
    victim: int | None = None
    victim_until: float = -np.inf
    counters: Counter = field(default_factory=Counter)
    tolerance_m: float = np.inf
    """How false a plan must be to count as a lie for the record: the fleet's
    ``plan_reject_m``, beyond which a claim is a full transparency failure ..."""
    horizon_s: float = 0.0
    """... within this far past its stamp: what the audit holds a plan to (its notice
    after the next plan). A claim further ahead is superseded before it comes due, and no
    observation can tell it from a mind changed in time."""
    first_lie_at: float | None = None
    """When it first published such a lie (bookkeeping for experiments)."""
    told: deque = field(default_factory=lambda: deque(maxlen=TOLD))
    """(stamp, plan as published, whether it lied), for experiments to find when a lie
    first came due (audit.first_false_claim)."""

    def plan(self, plan: Plan, now: float, own: Motion | None, seen: dict[int, Motion]) -> tuple[Plan, float]:
        """The plan and stamp to publish instead of (``plan``, ``now``)."""
        if self.first_at is None:
            self.first_at = now
        stamp, lied = now, False
        out = plan
        for name in self.attack.names:
            lie = PLAN_LIES.get(name)
            if lie is not None:
                out, stamp, told = lie(self, self.attack.of(name), out, stamp, now, own, seen)
                lied |= told
        self.history.append((now, plan))
        self.told.append((stamp, out, lied))
        if lied:
            self.counters["plans_falsified"] += 1
            if self.first_lie_at is None and _deviation(out, stamp, plan, now, self.horizon_s) > self.tolerance_m:
                self.first_lie_at = now
        return out, stamp

    def testimony(self, report: TrustReport) -> TrustReport:
        for name in self.attack.names:
            lie = TESTIMONY_LIES.get(name)
            if lie is not None:
                report = lie(self, self.attack.of(name), report)
        return report

    def steer(self, request: PlanRequest, peers: list[tuple[int, PeerConstraint]], now: float,
              seen: dict[int, Motion]) -> tuple[PlanRequest, list[tuple[int, PeerConstraint]]]:
        """The planning request this car really solves (``framing`` only)."""
        if "framing" not in self.attack.names:
            return request, peers
        return _framing_steer(self, self.attack.of("framing"), request, peers, now, seen)


# --- plan lies: (liar, params, plan, stamp, now, own, seen) -> (plan, stamp, lied) -----------------


def _random_offset(rng: np.random.Generator, low: float, high: float) -> np.ndarray:
    length = rng.uniform(low, high)
    angle = rng.uniform(0.0, 2.0 * np.pi)
    return length * np.array([np.cos(angle), np.sin(angle)])


def _displaced(liar, params, plan, stamp, now, own, seen):
    if params.p <= 0.0 or liar.rng.random() >= params.p:
        return plan, stamp, False
    return plan.shifted(_random_offset(liar.rng, params.offset_min_m, params.offset_max_m)), stamp, True


def _forged_stamp(liar, params, plan, stamp, now, own, seen):
    plan, _, displaced = _displaced(liar, params, plan, stamp, now, own, seen)
    return plan, stamp + params.shift_s, displaced or params.shift_s != 0.0


def _bias(liar, params, plan, stamp, now, own, seen):
    if own is None:
        return plan, stamp, False
    victim = int(params.victim) or _nearest(own.position, seen)
    if victim is None or victim not in seen:
        return plan, stamp, False
    away = own.position - seen[victim].position
    distance = float(np.linalg.norm(away))
    if distance < 1e-6:
        return plan, stamp, False
    return plan.shifted(params.direction * params.bias_m * away / distance), stamp, True


def _false_future(liar, params, plan, stamp, now, own, seen):
    times = plan.times()
    velocity = plan.velocities
    speed = np.linalg.norm(velocity, axis=1)
    if not np.any(speed > 0.05):
        return plan, stamp, False
    left = np.stack([-velocity[:, 1], velocity[:, 0]], axis=1) / np.maximum(speed, 1e-9)[:, None]
    left[speed <= 0.05] = 0.0
    grown = np.clip((times - stamp) / params.ramp_s, 0.0, 1.0)
    growing = (times > stamp) & (times < stamp + params.ramp_s)
    bend = params.side * params.bend_m
    positions = plan.positions + bend * grown[:, None] * left
    velocities = velocity + np.where(growing[:, None], bend / params.ramp_s * left, 0.0)
    return Plan(plan.t0, plan.dt, positions, velocities), stamp, True


def _false_yield(liar, params, plan, stamp, now, own, seen):
    if not np.any(np.linalg.norm(plan.velocities, axis=1) > 0.05):
        return plan, stamp, False
    u = np.maximum(plan.times() - stamp, 0.0)
    braking = u < params.stop_s
    warped = np.where(braking, u - u**2 / (2.0 * params.stop_s), params.stop_s / 2.0)  # tau(u)
    rate = np.where(braking, 1.0 - u / params.stop_s, 0.0)  # tau'(u)
    positions, velocities = plan.state_at(stamp + warped)
    return Plan(plan.t0, plan.dt, positions, velocities * rate[:, None]), stamp, True


def _on_off(liar, params, plan, stamp, now, own, seen):
    phase = (now - liar.first_at) % (params.on_s + params.off_s)
    if phase >= params.on_s:
        return plan, stamp, False
    return plan.shifted(_random_offset(liar.rng, params.offset_min_m, params.offset_max_m)), stamp, True


def _replay(liar, params, plan, stamp, now, own, seen):
    if params.p <= 0.0 or liar.rng.random() >= params.p:
        return plan, stamp, False
    old = [(t, p) for t, p in liar.history if t <= now - params.age_s]
    if not old:
        return plan, stamp, False
    then, was = old[-1]
    return Plan(was.t0 + (now - then), was.dt, was.positions.copy(), was.velocities.copy()), stamp, True


def _collude(liar, params, plan, stamp, now, own, seen):
    return _displaced(liar, params, plan, stamp, now, own, seen)


PLAN_LIES = {
    "displaced": _displaced, "forged-future": _forged_stamp, "forged-past": _forged_stamp, "bias": _bias, "false-future": _false_future,
    "false-yield": _false_yield, "on-off": _on_off, "replay": _replay, "collude": _collude,
}


def _deviation(told: Plan, stamp: float, true: Plan, now: float, horizon_s: float) -> float:
    """How far what it told is from the truth over the next ``horizon_s``: the claim for
    ``stamp + u`` against where it will be at ``now + u``."""
    u = np.linspace(0.0, horizon_s, 15)
    return float(np.max(np.linalg.norm(told.position_at(stamp + u) - true.position_at(now + u), axis=1)))


def _nearest(position: np.ndarray, seen: dict[int, Motion]) -> int | None:
    if not seen:
        return None
    return min(seen, key=lambda car: float(np.linalg.norm(seen[car].position - position)))


# --- testimony lies: (liar, params, report) -> report ---------------------------------------------


def _claim(amount: float, good: bool, pt: PeerTrust, dims=(0, 1, 2)) -> PeerTrust:
    alpha, beta, tau = list(pt.alpha), list(pt.beta), list(pt.tau)
    for d in dims:
        alpha[d], beta[d], tau[d] = (amount, 0.0, 1.0) if good else (0.0, amount, 0.0)
    return PeerTrust(tuple(alpha), tuple(beta), tuple(tau), min(tau), pt.epsilon)


def _swapped(pt: PeerTrust) -> PeerTrust:
    return PeerTrust(alpha=pt.beta, beta=pt.alpha, tau=tuple(1.0 - x for x in pt.tau), trust=1.0 - pt.trust,
                     epsilon=pt.epsilon)


def _rewrite(report: TrustReport, change) -> TrustReport:
    return TrustReport(report.sender, report.seq, report.stamp,
                       {peer: change(peer, pt) for peer, pt in report.peers.items()})


def _false_testimony(liar, params, report):
    return _rewrite(report, lambda peer, pt: _swapped(pt))


def _slander(liar, params, report):
    target = int(params.target)
    return _rewrite(report, lambda peer, pt: _claim(params.amount, False, pt) if target in (0, peer) else pt)


def _praise(liar, params, report):
    target = int(params.target)
    return _rewrite(report, lambda peer, pt: _claim(params.amount, True, pt) if target in (0, peer) else pt)


def _framing_testimony(liar, params, report):
    return _rewrite(report, lambda peer, pt: _claim(params.amount, False, pt, dims=(0,)) if peer == liar.victim else pt)


def _collude_testimony(liar, params, report):
    def change(peer: int, pt: PeerTrust) -> PeerTrust:
        if peer in liar.partners:
            return _claim(params.amount, True, pt)
        return _swapped(pt) if params.slander else pt
    return _rewrite(report, change)


TESTIMONY_LIES = {
    "false-testimony": _false_testimony, "slander": _slander, "praise": _praise,
    "framing": _framing_testimony, "collude": _collude_testimony,
}


# --- framing: a car that drives to make another look unsafe ------------------------------------------


def _framing_steer(liar, params, request, peers, now, seen):
    if liar.victim is None:
        liar.victim = int(params.victim) or _nearest(request.position, seen)
        liar.victim_until = now + params.duration_s
    victim = seen.get(liar.victim)
    if victim is None or now > liar.victim_until:
        return request, peers
    speed = float(np.linalg.norm(victim.velocity))
    heading = victim.velocity / speed if speed > 0.05 else np.array([np.cos(victim.yaw), np.sin(victim.yaw)])
    target = victim.position - params.gap_m * heading
    distance = float(np.linalg.norm(target - request.position))
    liar.counters["framing_steers"] += 1
    steered = dataclasses.replace(request, goal=target, t_arrive=request.t_now + max(1.0, distance / FRAMING_SPEED_MPS),
                                  route=(), lane=())
    return steered, [(peer, dataclasses.replace(c, epsilon=min(c.epsilon, params.gap_m)) if peer == liar.victim else c)
                     for peer, c in peers]

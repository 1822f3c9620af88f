"""The fallback: a braking trajectory along the last verified plan.

When no new plan verifies within a replan's budget (agent.safe_plan), the car commits
to a trajectory along the path of its last verified plan -- a path it knows clear of the
walls -- that brakes to a stop short of everything it knows of, and publishes it as its
plan (its peers then plan around a car that is stopping). It follows the plan's timing
(or the car's present speed along its path) until t_b, then brakes at
``VerifyConfig.fallback_decel_mps2``:

    s(tau) = s_b + v_b (tau - t_b) - a (tau - t_b)^2 / 2,     t_b <= tau <= t_b + v_b / a

with the latest t_b that still verifies, down to braking at once.
docs/design/safety.md, "Verified plans".
"""

from __future__ import annotations

import math

import numpy as np

from .config import VerifyConfig
from .gp import Plan, standing
from .planner import PlanRequest
from .verify import Bounds, Verdict, verify
from .world import SignedDistanceField

ON_PLAN_M = 0.10
ON_PLAN_MPS = 0.15
"""The car follows the verified plan's timing while this close to its state now."""
CRUISE_MAX_S = 4.0
"""Off the plan's timing, the fallback keeps the present speed at most this long."""
BRAKE_FRACTIONS = (0.8, 0.6, 0.4, 0.2, 0.0)
"""Braking times tried, as fractions of the way from now to the first conflict."""
DT_S = 0.1
"""Support spacing of a braking trajectory (coarser when it would need too many)."""
MAX_STATES = 200
PATH_SAMPLES = 400
MOVING_MPS = 0.02


def fallback(reference: Plan | None, request: PlanRequest, bounds: Bounds, sdf: SignedDistanceField,
             config: VerifyConfig) -> tuple[Plan, Verdict]:
    """The braking trajectory along ``reference`` that goes furthest and still verifies
    (or, when none does, the one that brakes at once), with its verdict."""
    t_now = request.t_now
    position = np.asarray(request.position, float)
    velocity = np.asarray(request.velocity, float)
    decel = config.fallback_decel_mps2
    timing = _timing(reference, position, velocity, t_now)
    heading = request.heading
    if timing is None:
        plan = standing(position, t_now)
        return plan, verify(plan, request.peers, bounds, sdf, config, start_heading=heading)
    verdict = verify(timing, request.peers, bounds, sdf, config, t_from=t_now, start_heading=heading)
    # Kept only if it comes to rest itself: its last support state, not state_at(t_end),
    # which reads zero at the end of every plan -- a cruise at the present speed read as
    # stopping would be kept at every replan, and the car would creep on for good.
    if verdict.ok and float(np.linalg.norm(timing.velocities[-1])) < MOVING_MPS:
        return timing, verdict  # the verified plan is still clear: keep it
    first = min((c.t for c in verdict.conflicts), default=timing.t_end)
    for fraction in BRAKE_FRACTIONS:
        plan = brake_after(timing, t_now + fraction * max(first - t_now, 0.0), decel, t_now)
        candidate = verify(plan, request.peers, bounds, sdf, config, start_heading=heading)
        if candidate.ok:
            return plan, candidate
    return plan, candidate  # braking at once (fraction 0) did not verify either


def _timing(reference: Plan | None, position: np.ndarray, velocity: np.ndarray, t_now: float) -> Plan | None:
    """The verified plan while the car is on it; else the present speed along its path
    (or along the velocity, without one); None when the car stands and has no plan."""
    speed = float(np.linalg.norm(velocity))
    if reference is not None:
        (p,), (v,) = reference.state_at(t_now)
        if np.linalg.norm(p - position) <= ON_PLAN_M and np.linalg.norm(v - velocity) <= ON_PLAN_MPS:
            return reference
    if speed < MOVING_MPS:
        return None
    if reference is None:
        path = np.array([position, position + velocity * CRUISE_MAX_S])
    else:
        times = np.linspace(max(t_now - 1.0, reference.t0), max(reference.t_end, t_now), PATH_SAMPLES)
        samples = reference.position_at(times)
        nearest = int(np.argmin(np.linalg.norm(samples - position, axis=1)))
        path = np.vstack([position, samples[nearest + 1:]])
    return along(path, np.full(1, speed), t_now, CRUISE_MAX_S)


def along(path: np.ndarray, speed: np.ndarray, t_now: float, duration: float) -> Plan | None:
    """A plan along the polyline ``path`` at ``speed`` (constant), for ``duration`` or
    until the path ends, where it stands; None for a path of no length."""
    step = np.linalg.norm(np.diff(path, axis=0), axis=1)
    path = path[np.concatenate([[True], step > 1e-9])]
    if len(path) < 2:
        return None
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    v = float(speed[0])
    duration = min(duration, cum[-1] / v)
    n = max(3, min(MAX_STATES, int(math.ceil(duration / DT_S)) + 2))
    dt = max(DT_S, duration / (n - 2))
    tau = np.arange(n) * dt
    s = np.minimum(v * tau, cum[-1])
    moving = v * tau < cum[-1] - 1e-9
    return _on_path(path, cum, s, np.where(moving, v, 0.0), t_now, dt)


def brake_after(timing: Plan, t_b: float, decel: float, t_now: float) -> Plan:
    """``timing`` until ``t_b``, then braking at ``decel`` along the rest of its path."""
    t_b = min(max(t_b, t_now), timing.t_end)
    (p_b,), (v_b,) = timing.state_at(t_b)
    speed = float(np.linalg.norm(v_b))
    stop = speed / decel
    span = (t_b - t_now) + stop
    n = max(3, min(MAX_STATES, int(math.ceil(span / DT_S)) + 2))
    dt = max(DT_S, span / (n - 2))
    tau = t_now + np.arange(n) * dt
    positions, velocities = timing.state_at(np.minimum(tau, t_b))
    after = tau > t_b
    if np.any(after) and speed > 1e-6:
        rest = timing.position_at(np.linspace(t_b, max(timing.t_end, t_b), PATH_SAMPLES))
        path = np.vstack([p_b, rest])
        step = np.linalg.norm(np.diff(path, axis=0), axis=1)
        path = path[np.concatenate([[True], step > 1e-9])]
        if len(path) >= 2:
            cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
            late = np.clip(tau[after] - t_b, 0.0, stop)
            s = np.minimum(speed * late - 0.5 * decel * late**2, cum[-1])
            v = np.where(s >= cum[-1] - 1e-9, 0.0, speed - decel * late)
            braking = _on_path(path, cum, s, v, t_now, dt)
            positions[after], velocities[after] = braking.positions, braking.velocities
        else:
            velocities[after] = 0.0
    elif np.any(after):
        velocities[after] = 0.0
    return Plan(t0=t_now, dt=dt, positions=positions, velocities=velocities)


def _on_path(path: np.ndarray, cum: np.ndarray, s: np.ndarray, speed: np.ndarray, t0: float, dt: float) -> Plan:
    """States at arc lengths ``s`` along ``path`` (cumulative lengths ``cum``) moving at ``speed``."""
    positions = np.stack([np.interp(s, cum, path[:, 0]), np.interp(s, cum, path[:, 1])], axis=1)
    which = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(path) - 2)
    direction = np.diff(path, axis=0)[which] / np.maximum(np.diff(cum)[which], 1e-9)[:, None]
    return Plan(t0=t0, dt=dt, positions=positions, velocities=direction * np.asarray(speed)[:, None])

"""A plan's path at a pace the car can drive (path-velocity decomposition).

From a standstill the optimiser's soft start prior returns plans that set off faster
than the car can accelerate, and the check of the vehicle's limits (agent.verify)
refuses them. :func:`retime` keeps the path and changes only when the car is where: the
speed along the finely sampled path is bounded by the plan's own, the car's top speed
and a share ``ACCEL_SHARE`` of its acceleration from the speed it has (a forward pass)
and down to the plan's speed at its end (a backward pass),

    u_{k+1} <= sqrt(u_k^2 + 2 a ds_k)  (forward),   u_k <= sqrt(u_{k+1}^2 + 2 a ds_k)  (backward)

and no step is taken sooner than the plan takes it. The result is a guess like any other:
agent.safe_plan verifies it. docs/design/safety.md, "Verified plans".
"""

from __future__ import annotations

import numpy as np

from .gp import Plan

ACCEL_SHARE = 0.8
"""Of the vehicle's acceleration, what the retimed pace may use (tracking needs the rest)."""
SAMPLES_PER_INTERVAL = 20


def retime(plan: Plan, speed_now: float, max_speed: float, max_accel: float) -> Plan:
    """``plan``'s path from its start, driven from ``speed_now`` within the limits."""
    fine = np.linspace(plan.t0, plan.t_end, (plan.n - 1) * SAMPLES_PER_INTERVAL + 1)
    points, velocities = plan.state_at(fine)
    along = np.diff(points, axis=0)
    ds = np.linalg.norm(along, axis=1)
    a = ACCEL_SHARE * max_accel
    u = np.minimum(np.linalg.norm(velocities, axis=1), max_speed)
    u[0] = min(max(speed_now, 0.0), max_speed)
    for k in range(len(ds)):  # forward: what the car can reach
        u[k + 1] = min(u[k + 1], np.sqrt(u[k] ** 2 + 2.0 * a * ds[k]))
    for k in range(len(ds) - 1, 0, -1):  # backward: what it can brake from (the start is given)
        u[k] = min(u[k], np.sqrt(u[k + 1] ** 2 + 2.0 * a * ds[k]))
    mean = u[:-1] + u[1:]
    step = np.where(mean > 1e-9, 2.0 * ds / np.maximum(mean, 1e-9), 0.0)
    step = np.maximum(step, np.diff(fine))  # never sooner than the plan
    arrive = plan.t0 + np.concatenate([[0.0], np.cumsum(step)])
    # Support states at the plan's own times: where the retimed car is then, moving along
    # the path at the retimed speed of that step.
    times = plan.times()
    position = np.column_stack([np.interp(times, arrive, points[:, i]) for i in range(2)])
    k = np.clip(np.searchsorted(arrive, times, side="right") - 1, 0, len(step) - 1)
    heading = along[k] / np.maximum(ds[k], 1e-9)[:, None]
    pace = np.where(step > 0.0, ds / np.maximum(step, 1e-9), 0.0)  # each step's mean speed
    middle = 0.5 * (arrive[:-1] + arrive[1:])
    speed = np.interp(times, np.concatenate([[arrive[0]], middle]), np.concatenate([[u[0]], pace]))
    return Plan(plan.t0, plan.dt, position, heading * speed[:, None])

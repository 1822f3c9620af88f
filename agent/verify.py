"""Verification of a plan before a car uses or publishes it.

The optimiser's hinges are soft, so every plan is checked, independently of how it was
made, against everything the car planned against (the idea of RMADER's check; Tordesillas
and How, "Robust MADER", 2022). Over the plan's span, at check times t_k spaced for
``sample_m`` of relative travel, with half the travel between samples added as slack:

    walls    d(p(t_k))            >= eps_obs - tol (eps_obs - d_obs)        (eq. 6)
    peer b   |p(t_k) - p_b(t_k)|  >= eps_ab  - tol (eps_ab  - d_ab)         (eq. 9)
    limits   lag = max_t |int_0^t (|v| - u) dt|  <= limit_lag_m    (first limits_horizon_s)
    turning  |phi(s_b) - phi(s_a)| <= (s_b - s_a) / R + slack       (car-like cars, whole plan)

u the speed of a car that follows |v| within v_max and a_max from the speed it has
(agent.follower); phi(s) the path's heading at arc length s, the car's own at s = 0
(agent.steering.turning_excess). A plan that starts nearer may not bring the car nearer.
Pure: no clock, no I/O. docs/design/safety.md, "Verified plans".
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .config import VehicleConfig, VerifyConfig
from .follower import follower_speeds
from .gaps import half_steps, peer_gaps
from .gp import Plan
from .planner import PeerConstraint
from .steering import turning_excess
from .world import SignedDistanceField

MAX_SAMPLES = 4000
"""Bound on the check times of one plan (a 20 s plan at 1.6 m/s closing speed needs 1600)."""
START_SLACK_M = 1e-3


@dataclass(frozen=True)
class Conflict:
    """The worst violation of one kind (and peer) found in a plan."""

    kind: str
    """'obstacle', 'peer', 'limits' (speed and acceleration) or 'turning' (a car-like car
    cannot follow the path from its heading)."""
    t: float
    """Absolute time of the worst sample."""
    excess: float
    """How far beyond what is tolerated (> 0): distance lacking, m; lag beyond the allowed
    one ('limits'), m; heading turned beyond what the radius allows ('turning'), rad."""
    peer: int = -1
    """Index into the peers the plan was checked against ('peer' only)."""
    position: tuple[float, float] = (0.0, 0.0)
    """Where the plan is at ``t``."""
    other: tuple[float, float] = (0.0, 0.0)
    """Where the peer's plan is at ``t`` ('peer' only)."""


@dataclass(frozen=True)
class Verdict:
    ok: bool
    conflicts: tuple[Conflict, ...] = ()
    """The worst violation of each kind and of each peer, earliest first."""
    clearance: float = math.inf
    """Least sampled distance to a peer minus that peer's breach distance (m)."""
    obstacle_clearance: float = math.inf
    """Least sampled distance to a wall minus the wall's breach distance (m)."""
    samples: int = 0


@dataclass(frozen=True)
class Bounds:
    """What a plan must keep, per car: derived from SafetyConfig and the vehicle."""

    epsilon_obstacle: float
    obstacle_breach: float
    breach: tuple[float, ...]
    """Breach distance d_ab per peer, in the order of the peers checked against."""
    max_speed_mps: float
    max_accel_mps2: float
    min_turn_radius_m: float = 0.0
    """A car-like car's minimum turning radius; 0: the car turns in place (no 'turning' check)."""

    @classmethod
    def of(cls, epsilon_obstacle: float, obstacle_breach: float, breach: Sequence[float],
           vehicle: VehicleConfig) -> "Bounds":
        return cls(epsilon_obstacle, obstacle_breach, tuple(breach), vehicle.max_speed_mps, vehicle.max_accel_mps2,
                   vehicle.min_turn_radius_m if vehicle.car_like else 0.0)


def check_times(plan: Plan, peers: Sequence[PeerConstraint], sample_m: float,
                t_from: float | None = None) -> np.ndarray:
    """Times over [t_from (default t0), t_end] spaced for ``sample_m`` of travel, from the
    fastest support speed of the plan and the peers (the actual travel is measured later)."""
    start = plan.t0 if t_from is None else max(plan.t0, t_from)
    end = max(plan.t_end, start)
    speed = float(np.max(np.linalg.norm(plan.velocities, axis=1))) if plan.n else 0.0
    peer_speed = max((float(np.max(np.linalg.norm(p.plan.velocities, axis=1))) for p in peers), default=0.0)
    # Hermite interpolation can overshoot the support speeds a little: 25 % headroom.
    closing = 1.25 * (speed + peer_speed) + 1e-3
    count = int(min(MAX_SAMPLES, max(2, math.ceil((end - start) * closing / sample_m) + 1)))
    return np.linspace(start, end, count)


def verify(plan: Plan, peers: Sequence[PeerConstraint], bounds: Bounds, sdf: SignedDistanceField,
           config: VerifyConfig, t_from: float | None = None, start_speed: float | None = None,
           start_heading: float | None = None) -> Verdict:
    """Check ``plan`` against the walls, every peer plan it was made against (with that
    peer's epsilon, at the same absolute times), and the vehicle's limits, driven from
    ``start_speed`` (the speed the car has where the plan starts; default: the plan's own)
    and, for a car-like car, from ``start_heading`` (default: the path's own first
    direction)."""
    if len(bounds.breach) != len(peers):
        raise ValueError(f"{len(peers)} peers but {len(bounds.breach)} breach distances")
    times = check_times(plan, peers, config.sample_m, t_from)
    samples = len(times)
    p, v = plan.state_at(times)
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
        return Verdict(False, (Conflict("obstacle", float(times[0]), math.inf),), samples=len(times))
    tol = config.tolerance
    conflicts: list[Conflict] = []
    own_step = half_steps(p)

    # Car-like: the path's turns against the turning radius, from the car's heading.
    if bounds.min_turn_radius_m > 0.0:
        excess, k = turning_excess(p, start_heading, bounds.min_turn_radius_m, config.turning_slack_rad,
                                   config.sample_m)
        if excess > 0.0:
            conflicts.append(Conflict("turning", float(times[k]), excess, position=_xy(p[k])))

    # Walls, eq. (6): d(p) - half the step travelled >= eps_obs - tol (eps_obs - d_obs).
    wall = sdf.distance(p) - own_step
    need = _from_start(bounds.epsilon_obstacle - tol * (bounds.epsilon_obstacle - bounds.obstacle_breach), wall)
    k = int(np.argmin(wall))
    obstacle_clearance = float(wall[k] - bounds.obstacle_breach)
    if wall[k] < need:
        conflicts.append(Conflict("obstacle", float(times[k]), float(need - wall[k]), position=_xy(p[k])))

    # Peers, eq. (9), at the same absolute times.
    clearance = math.inf
    for b, (peer, breach) in enumerate(zip(peers, bounds.breach)):
        held = len(times)  # the peer held where its plan ends: for good, or for its hold_s
        if peer.hold_s is not None:
            held = int(np.searchsorted(times, peer.plan.t_end + peer.hold_s, side="right"))
        if held == 0:
            continue  # the whole plan lies past the peer's hold (VerifyConfig.peer_hold_s)
        gap = peer_gaps(p[:held], times[:held], peer.plan)  # |p - q| less half the larger step (agent.gaps)
        k = int(np.argmin(gap))
        clearance = min(clearance, float(gap[k] - breach))
        need = _from_start(peer.epsilon - tol * (peer.epsilon - breach), gap)
        if gap[k] < need:
            (q,) = peer.plan.position_at(times[k:k + 1])
            conflicts.append(Conflict("peer", float(times[k]), float(need - gap[k]), b, _xy(p[k]), _xy(q)))

    # The vehicle's limits over the near term: speed, and the acceleration along the track.
    near = times <= times[0] + config.limits_horizon_s
    times, p, v = times[near], p[near], v[near]
    lag, k = follower_lag(times, np.linalg.norm(v, axis=1), bounds.max_speed_mps, bounds.max_accel_mps2,
                          start_speed)
    if lag > config.limit_lag_m:
        conflicts.append(Conflict("limits", float(times[k]), lag - config.limit_lag_m, position=_xy(p[k])))

    conflicts.sort(key=lambda c: c.t)
    return Verdict(not conflicts, tuple(conflicts), clearance, obstacle_clearance, samples)


def follower_lag(times: np.ndarray, speed: np.ndarray, max_speed: float, max_accel: float,
                 start_speed: float | None = None) -> tuple[float, int]:
    """How far behind (or ahead of) a plan's speed profile a car falls that follows it as
    closely as its limits allow -- speed u <= max_speed, |du/dt| <= max_accel, starting at
    ``start_speed`` (default the plan's) -- and the sample where that is largest:
    max_t |int (s - u) dt|."""
    if len(times) < 2:
        return 0.0, 0
    step = float(times[1] - times[0])
    u = follower_speeds(speed, speed[0] if start_speed is None else start_speed, max_speed, max_accel * step)
    lag = np.abs(np.cumsum(speed - u) * step)
    k = int(np.argmax(lag))
    return float(lag[k]), k


def _from_start(need: float, distance: np.ndarray) -> float:
    """What a plan must keep: ``need``, or where it starts already nearer, no nearer
    than it starts (less a millimetre of rounding) -- it cannot undo the present."""
    return min(need, float(distance[0]) - START_SLACK_M)


def _xy(point: np.ndarray) -> tuple[float, float]:
    return (float(point[0]), float(point[1]))

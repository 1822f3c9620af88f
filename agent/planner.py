"""One car's trajectory as a GTSAM factor graph, solved by Levenberg-Marquardt.

The MAP problem of the paper, eq. (9), over support states x_i = (p_i, v_i), i = 0..N-1,
at absolute times t_i = t0 + i*dt:

  start prior    PriorFactorPoint2(p_0), PriorFactorVector(v_0)   current pose and velocity
  goal prior     PriorFactorPoint2(p_N-1) = goal, PriorFactorVector(v_N-1) = 0
  GP prior       WnoaMotionFactorPoint2(x_i, x_i+1)                eq. (3), smoothness
  checks         obstacle hinge (eq. (6)), proximity hinge to every peer (eq. (9)), soft
                 speed limit, lane and consistency (agent.factors), at each support state
                 and between them (agent.interval_factors)
  car-like       a heading per support state, its start at the car's yaw, no sliding, no
                 reversing, no curve tighter than the turning radius (agent.heading_factors),
                 (``turn_room``) room to turn away from a peer that stands ahead (agent.turn_room),
                 and (``keep_right_m``) peers it closes on seen to the left (agent.keep_right)

Peers out of reach are left out (:func:`peers_within_reach`); a replan is warm-started
from the previous plan. docs/design/planner.md.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from dataclasses import dataclass

import gtsam
import numpy as np
from gtsam.symbol_shorthand import V, X

from . import factors, follower, gaps, interpolate, interval_kernel, motion_fit
from .config import PlannerConfig
from .gp import Plan, interpolation_weights
from .heading_factors import add_heading_factors, insert_headings
from .interval_factors import add_batched_checks, add_gtsam_interp_checks
from .keep_right import keep_right
from .routes import path_length
from .steering import MOVING_MPS, departure_arc, initial_headings
from .turn_room import add_turn_room_factors
from .world import SignedDistanceField


class PlanningError(RuntimeError):
    """The planner could not produce a plan (bad input or a solver failure)."""


@dataclass(frozen=True)
class PeerConstraint:
    """A peer's shared plan (held constant) and the safety distance to keep from it."""

    plan: Plan
    epsilon: float
    hold_s: float | None = None
    """How long past the end of its plan verification holds the peer where the plan
    ends (None: for good; VerifyConfig.peer_hold_s)."""
    parked: bool = False
    """The peer is done driving: it stands at its goal, or beside it where it stepped
    aside for a car (agent.car_agent.parked). A fleet of parked peers sets no pace."""


@dataclass(frozen=True)
class PlanRequest:
    t_now: float
    position: np.ndarray
    velocity: np.ndarray
    goal: np.ndarray
    t_arrive: float
    """Planned arrival time at the goal (absolute); the horizon is t_arrive - t_now."""
    epsilon_obstacle: float
    """Obstacle hinge threshold, centre to surface (SafetyConfig.epsilon_obstacle)."""
    peers: tuple[PeerConstraint, ...] = ()
    warm_start: Plan | None = None
    route: tuple[tuple[float, float], ...] = ()
    """Via points between the start and the goal; they seed a cold start."""
    lane: tuple[tuple[float, float], ...] = ()
    """The car's lane centre line from its original start through its via points (the
    goal closes it); empty: no lane keeping."""
    steering: tuple[float, float] | None = None
    """A car-like car's (heading where the plan starts, rad; minimum turning radius, m):
    the plan sets off along the heading and is held to what front-wheel steering can drive
    (agent.heading_factors, agent.steering.held_to). None: the car turns in place."""

    @property
    def car_like(self) -> bool:
        return self.steering is not None

    @property
    def heading(self) -> float | None:
        """A car-like car's heading where the plan starts; None for a car that turns in place."""
        return None if self.steering is None else self.steering[0]

    @property
    def min_turn_radius_m(self) -> float:
        """A car-like car's minimum turning radius; 0 for a car that turns in place."""
        return 0.0 if self.steering is None else self.steering[1]


@dataclass(frozen=True)
class PlanResult:
    plan: Plan
    iterations: int
    initial_error: float
    final_error: float
    time_ms: float
    warm: bool
    peers_out_of_reach: int = 0
    """Peers of the request left out of the graph: they cannot come within reach during
    the horizon (:func:`peers_within_reach`)."""


def plan_trajectory(request: PlanRequest, config: PlannerConfig, sdf: SignedDistanceField) -> PlanResult:
    """Solve the trajectory of one car; raise PlanningError on bad input.

    A cold start (no previous plan) with many support states is solved coarse to fine:
    first with about half the states, then refined at full resolution warm-started from
    that plan -- the expensive first iterations, far from the optimum, run on a graph
    half the size.
    """
    started = time.perf_counter()
    _check_request(request)
    n = config.support_states
    if request.warm_start is None and n >= 2 * COARSE_MIN_STATES - 1:
        coarse = dataclasses.replace(config, support_states=(n + 1) // 2)
        first = plan_trajectory(request, coarse, sdf)
        refined = plan_trajectory(dataclasses.replace(request, warm_start=first.plan), config, sdf)
        return dataclasses.replace(refined, iterations=first.iterations + refined.iterations,
                                   initial_error=first.initial_error,
                                   time_ms=(time.perf_counter() - started) * 1e3, warm=False)
    horizon = max(request.t_arrive - request.t_now, config.min_horizon_s)
    dt = horizon / (n - 1)
    t0 = request.t_now
    problem = interval_problem(request, config, sdf, t0, dt)
    graph = build_graph(request, config, sdf, t0, dt, problem)
    left_out = len(request.peers) - problem.n_peers if config.proximity else 0
    if request.warm_start is not None:
        values = _values(anchored(request.warm_start.resampled(t0, dt, n), request.position, request.velocity),
                         request.heading if request.car_like else None)
    else:
        # Cold start: the route at a few different paces (early, even, late through the
        # middle); LM starts from the one whose checks cost least, typically the one
        # that is not where the peers are when they are there.
        sigmas = factors.interval_sigmas(problem, config.sigma_obstacle, config.sigma_proximity,
                                         config.sigma_speed, config.sigma_lane, config.sigma_consistency)
        candidates = [seed_plan(request, t0, dt, n, pace, config.turn_radius_margin, first)
                      for first in _seed_entries(request, config.turn_radius_margin, sdf) for pace in SEED_PACES]
        values = _values(min(candidates, key=lambda seed: _checks_cost(problem, seed, sigmas)),
                         request.heading if request.car_like else None)
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(config.max_iterations)
    params.setRelativeErrorTol(config.relative_error_tol)
    params.setAbsoluteErrorTol(config.absolute_error_tol)
    params.setlambdaInitial(config.lambda_initial)
    params.setlambdaFactor(config.lambda_factor)
    params.setDiagonalDamping(config.diagonal_damping)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    initial_error = optimizer.error()  # evaluated by the constructor
    try:
        result = optimizer.optimize()
    except RuntimeError as exc:  # e.g. an indeterminant linear system
        raise PlanningError(f"Levenberg-Marquardt failed: {exc}") from exc
    positions = gtsam.utilities.extractVectors(result, "x")
    velocities = gtsam.utilities.extractVectors(result, "v")
    if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(velocities))):
        raise PlanningError("the solver returned non-finite states")
    plan = Plan(t0=t0, dt=dt, positions=positions, velocities=velocities)
    return PlanResult(
        plan=plan,
        iterations=optimizer.iterations(),
        initial_error=float(initial_error),
        final_error=float(optimizer.error()),
        time_ms=(time.perf_counter() - started) * 1e3,
        warm=request.warm_start is not None,
        peers_out_of_reach=left_out,
    )


def _checks_cost(problem: factors.IntervalProblem, plan: Plan, sigmas: np.ndarray) -> float:
    residual, _ = factors.evaluate_intervals(problem, plan.positions, plan.velocities, jacobians=False)
    return 0.5 * float(np.sum((residual / sigmas) ** 2))


def build_graph(request: PlanRequest, config: PlannerConfig, sdf: SignedDistanceField,
                t0: float, dt: float, problem: factors.IntervalProblem | None = None
                ) -> gtsam.NonlinearFactorGraph:
    n = config.support_states
    graph = gtsam.NonlinearFactorGraph()
    iso = gtsam.noiseModel.Isotropic.Sigma
    graph.add(gtsam.PriorFactorPoint2(X(0), request.position, iso(2, config.sigma_start)))
    graph.add(gtsam.PriorFactorVector(V(0), request.velocity, iso(2, config.sigma_start_velocity)))
    graph.add(gtsam.PriorFactorPoint2(X(n - 1), request.goal, iso(2, config.sigma_goal)))
    graph.add(gtsam.PriorFactorVector(V(n - 1), np.zeros(2), iso(2, config.sigma_goal_velocity)))
    qc = np.full(2, config.qc)
    states = [gtsam.StateData(X(i), V(i), t0 + i * dt) for i in range(n)]
    for i in range(n - 1):
        graph.add(gtsam.WnoaMotionFactorPoint2(states[i], states[i + 1], qc))
    if problem is None:
        problem = interval_problem(request, config, sdf, t0, dt)
    if config.interpolation == "batched":
        add_batched_checks(graph, problem, config)
    else:
        add_gtsam_interp_checks(graph, problem, config, states, qc)
    if request.car_like:
        radius = planned_turn_radius(request, config)
        add_heading_factors(graph, n, dt, 1.0 / radius, request.heading,
                            config.intervals_per_factor, config.sigma_sideways, config.sigma_turning)
        if config.turn_room:
            add_turn_room_factors(graph, problem.peer_positions, problem.epsilons, dt, radius,
                                  config.intervals_per_factor, config.sigma_turn_room)
    return graph


def planned_turn_radius(request: PlanRequest, config: PlannerConfig) -> float:
    """The radius a car-like plan turns on at the tightest: the car's, widened by
    ``turn_radius_margin`` so that the tracker has steering left to correct with."""
    return request.min_turn_radius_m * (1.0 + config.turn_radius_margin)


def interval_problem(request: PlanRequest, config: PlannerConfig, sdf: SignedDistanceField,
                     t0: float, dt: float) -> factors.IntervalProblem:
    """The constants of every interval's checks for this replan."""
    n = config.support_states
    fractions = factors.check_fractions(config.interp_checks)
    check_times = t0 + (np.arange(n - 1)[:, None] + fractions[None, :]) * dt  # (I, K)
    peers = request.peers if config.proximity or config.consistency else ()
    near = peers_within_reach(peers, request.position, check_times, config) if config.proximity else ()
    if near:
        peer_positions = np.stack([positions for _, positions in near], axis=2)
        epsilons = np.array([peer.epsilon for peer, _ in near])
        if request.car_like and config.keep_right_m > 0:
            peer_positions, epsilons = _kept_right(request, config, check_times, near, peer_positions, epsilons)
    else:
        peer_positions = np.zeros((n - 1, len(fractions), 0, 2))
        epsilons = np.zeros(0)
    targets = None
    if config.consistency and peers and not all(peer.parked for peer in peers):
        # abar_i: the peers' mean acceleration magnitude over interval i (all peers: this
        # is the fleet's manner of driving, near or far). With every peer parked the
        # fleet has done driving: abar would be 0, every acceleration a cost, and the last
        # car out would wait to set off at every replan, so there is no target.
        accel = np.stack([np.linalg.norm(p.plan.acceleration_at(check_times.ravel()), axis=1)
                          .reshape(check_times.shape) for p in peers])  # (M, I, K)
        targets = accel.mean(axis=(0, 2))
    return factors.IntervalProblem(
        dt=dt,
        weights=interpolation_weights(dt, fractions),
        sdf=sdf,
        epsilon_obstacle=request.epsilon_obstacle,
        peer_positions=peer_positions,
        epsilons=epsilons,
        max_speed=config.max_speed_mps,
        consistency_targets=targets,
        lane=route_segments(request) if config.lane_keeping else np.zeros((0, 2, 2)),
    )


def peers_within_reach(peers: tuple[PeerConstraint, ...], position: np.ndarray, check_times: np.ndarray,
                       config: PlannerConfig) -> list[tuple[PeerConstraint, np.ndarray]]:
    """The peers that could come within their epsilon of us before the horizon ends, each
    with its positions at the check times (I, K, 2), in request order.

    A plan drives at most v = ``max_speed_mps`` (its speed limit), and so does a peer's,
    so over the horizon H = t_end - t0 the two close in by at most 2 v H. A peer is left
    out only if it is out of reach both ways:

    * by the speed bounds: |p_b(t0) - p_a(t0)| >= eps_b + margin + 2 v H, where p_a(t0) is
      where our plan starts and p_b(t0) where its plan has it now -- it cannot reach us
      whatever either of us replans; and
    * by its plan, as the graph would use it: at every check time t,
      |p_b(t) - p_a(t0)| >= eps_b + margin + v (t - t0), so its proximity rows would be zero
      for every plan we can drive (this holds even if its plan breaks the speed bound).

    ``margin`` is ``reach_margin_m`` (a plan's soft speed limit may be exceeded a little).
    """
    if not peers:
        return []
    t0, t_end = float(check_times[0, 0]), float(check_times[-1, -1])
    v, margin = config.max_speed_mps, config.reach_margin_m
    times = check_times.ravel()  # begins with t0
    travel = v * (times - t0)
    kept = []
    for peer in peers:
        positions = peer.plan.position_at(times)
        gaps = np.hypot(positions[:, 0] - position[0], positions[:, 1] - position[1])
        reach = peer.epsilon + margin
        if gaps[0] < reach + 2.0 * v * (t_end - t0) or np.any(gaps < reach + travel):
            kept.append((peer, positions.reshape(*check_times.shape, 2)))
    return kept


def _kept_right(request: PlanRequest, config: PlannerConfig, check_times: np.ndarray,
                near: list[tuple[PeerConstraint, np.ndarray]], peer_positions: np.ndarray,
                epsilons: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The near peers as a car-like plan sees them under the keep-right convention
    (agent.keep_right), judged on our previous plan (or, cold, where we are and head)."""
    times = check_times.ravel()
    shape = (*check_times.shape, 2)
    if request.warm_start is not None:
        positions, velocities = request.warm_start.state_at(times)
    else:
        positions = np.broadcast_to(request.position, (len(times), 2))
        velocities = np.broadcast_to(request.velocity, (len(times), 2))
    speed = np.linalg.norm(velocities, axis=1, keepdims=True)
    heading = np.array([math.cos(request.heading), math.sin(request.heading)])
    directions = np.where(speed >= MOVING_MPS, velocities / np.maximum(speed, 1e-9), heading)
    peer_velocities = np.stack([peer.plan.state_at(times)[1].reshape(shape) for peer, _ in near], axis=2)
    return keep_right(positions.reshape(shape), directions.reshape(shape), velocities.reshape(shape),
                      peer_positions, peer_velocities, epsilons, config.keep_right_m)


def route_segments(request: PlanRequest) -> np.ndarray:
    """The lane centre line as segments of the polyline lane[0] -> ... -> goal."""
    points = np.array([*request.lane, request.goal], dtype=float)
    if len(points) < 2:
        return np.zeros((0, 2, 2))
    return np.stack([points[:-1], points[1:]], axis=1)


# --- seeding and checks ----------------------------------------------------------------------


COARSE_MIN_STATES = 11
"""Cold starts with at least 2 * this - 1 support states are solved coarse to fine."""
SEED_PACES = (1.0, 0.6, 1.6, 2.4)
"""Exponents gamma of the cold-start time warps u -> u**gamma (1: even pace)."""
SEED_CHECK_M = 0.05
"""Spacing of the wall checks along a car-like seed's straight to a via point, m."""


def _values(plan: Plan, heading: float | None = None) -> gtsam.Values:
    """The plan's states as Values; with a ``heading`` (a car-like car's), the heading
    variables too, started from the plan's directions of motion (agent.steering)."""
    values = gtsam.Values()
    insert = values.insert
    positions, velocities = _state_keys(plan.n)
    for key, position in zip(positions, plan.positions):
        insert(key, position)
    for key, velocity in zip(velocities, plan.velocities):
        insert(key, velocity)
    if heading is not None:
        insert_headings(values, initial_headings(plan.velocities, heading))
    return values


@functools.lru_cache(maxsize=8)
def _state_keys(n: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """The keys p_i = X(i) and v_i = V(i), i < n (made once: a replan builds Values often)."""
    return tuple(X(i) for i in range(n)), tuple(V(i) for i in range(n))


def _seed_entries(request: PlanRequest, turn_radius_margin: float, sdf: SignedDistanceField) -> list[int]:
    """Where cold seeds join the route: index k of the first of request.route[k:] + goal
    they head for. A car that turns in place follows the whole route (k = 0). A car-like
    car tries every k whose way there (departure arc, then straight) keeps
    ``epsilon_obstacle`` from the walls, shortest way (on along the route) first, and the
    whole route last: a car moved off its route (a detour, a fallback) may face away from
    via points already behind it, and heading back for them means a loop it may have no
    room for."""
    if not request.car_like or not request.route:
        return [0]
    radius = request.min_turn_radius_m * (1.0 + turn_radius_margin)
    points = np.array([request.position, *request.route, request.goal], dtype=float)
    clear = {}
    for k in range(len(points) - 1):
        arc = departure_arc(points[0], request.heading, points[k + 1], radius)
        start = arc[-1] if len(arc) else points[0]
        count = max(2, int(np.ceil(np.linalg.norm(points[k + 1] - start) / SEED_CHECK_M)) + 1)
        way = np.vstack([arc, start + np.linspace(0.0, 1.0, count)[1:, None] * (points[k + 1] - start)])
        if np.min(sdf.distance(way)) >= request.epsilon_obstacle:
            clear[k] = path_length(np.vstack([points[:1], arc, points[k + 1:]]))
    return sorted(clear, key=clear.__getitem__) + ([] if 0 in clear else [0])


def seed_plan(request: PlanRequest, t0: float, dt: float, n: int, pace: float = 1.0,
              turn_radius_margin: float = 0.0, first: int = 0) -> Plan:
    """A cold-start trajectory along start -> via points route[first:] -> goal, easing in
    and out; a car-like car's begins with the arc that turns it from its heading to face
    the first of them (agent.steering.departure_arc, at the planned radius).

    The arc length follows smoothstep(w(u)) with w(u) = u**pace on normalised time u, so
    pace > 1 lingers early and hurries late, pace < 1 the reverse.
    """
    points = np.array([request.position, *request.route[first:], request.goal], dtype=float)
    if request.car_like:
        radius = request.min_turn_radius_m * (1.0 + turn_radius_margin)
        arc = departure_arc(points[0], request.heading, points[1], radius)
        points = np.vstack([points[:1], arc, points[1:]])
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    length = cum[-1]
    horizon = dt * (n - 1)
    u = np.linspace(0.0, 1.0, n)
    w = u**pace
    dw = pace * u ** (pace - 1.0) if pace >= 1.0 else pace * np.power(np.maximum(u, 1e-9), pace - 1.0)
    s = length * (3 * w**2 - 2 * w**3)  # smoothstep: starts and ends at rest
    ds = length * (6 * w - 6 * w**2) * dw / horizon
    positions = np.stack([np.interp(s, cum, points[:, 0]), np.interp(s, cum, points[:, 1])], axis=1)
    which = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    direction = np.diff(points, axis=0)[which] / np.maximum(seg[which], 1e-9)[:, None]
    velocities = direction * ds[:, None]
    return Plan(t0=t0, dt=dt, positions=positions, velocities=velocities)


def anchored(plan: Plan, position: np.ndarray, velocity: np.ndarray) -> Plan:
    """The warm start moved to begin at the measured state.

    Between replans the car drifts a little from its plan; shifting the old plan by that
    offset, fading linearly to nothing at the goal, starts the solver where the start
    prior wants it instead of paying for the drift in the first iterations.
    """
    fade = np.linspace(1.0, 0.0, plan.n)[:, None]
    return Plan(plan.t0, plan.dt, plan.positions + fade * (position - plan.positions[0]),
                plan.velocities + fade * (velocity - plan.velocities[0]))


def _check_request(request: PlanRequest) -> None:
    for name in ("position", "velocity", "goal"):
        value = np.asarray(getattr(request, name), dtype=float)
        if value.shape != (2,) or not np.all(np.isfinite(value)):
            raise PlanningError(f"{name} must be a finite 2-vector, got {value!r}")
    if not (np.isfinite(request.t_now) and np.isfinite(request.t_arrive)):
        raise PlanningError("t_now and t_arrive must be finite")
    if not (np.isfinite(request.epsilon_obstacle) and request.epsilon_obstacle > 0):
        raise PlanningError(f"epsilon_obstacle must be positive, got {request.epsilon_obstacle}")
    for peer in request.peers:
        if not (np.isfinite(peer.epsilon) and peer.epsilon > 0):
            raise PlanningError(f"peer epsilon must be positive, got {peer.epsilon}")


def warm_compiled() -> None:
    """Compile, or load from numba's cache, a car's mind's compiled loops (the planner's
    agent.interval_kernel and agent.interpolate, verification's agent.follower and agent.gaps,
    and the peers' track fit agent.motion_fit) -- once before many processes start, or before a
    car's first replan."""
    interval_kernel.warm()
    interpolate.warm()
    follower.warm()
    gaps.warm()
    motion_fit.warm()

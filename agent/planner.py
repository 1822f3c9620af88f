"""One car's trajectory as a GTSAM factor graph, solved by Levenberg-Marquardt.

The MAP problem of the paper, eq. (9), over support states x_i = (p_i, v_i), i = 0..N-1,
at absolute times t_i = t0 + i*dt:

  start prior    PriorFactorPoint2(p_0), PriorFactorVector(v_0)   current pose and velocity
  goal prior     PriorFactorPoint2(p_N-1) = goal, PriorFactorVector(v_N-1) = 0
  GP prior       WnoaMotionFactorPoint2(x_i, x_i+1)                eq. (3), smoothness
  checks         obstacle hinge (eq. (6)), proximity hinge to every peer (eq. (9)),
                 soft speed limit and consistency (agent.factors)

The checks run at each support state and at ``interp_checks`` GP-interpolated times per
interval, so a thin obstacle or a crossing peer cannot slip between two states. Two
equivalent ways to build them (``PlannerConfig.interpolation``):

* ``batched`` (default): one CustomFactor per interval, keys (p_i, v_i, p_i+1, v_i+1).
  All intervals are evaluated together in one vectorised numpy call (a
  :class:`BatchedIntervals` cache shared by the interval factors); each factor returns its
  own slice. The residual of an interval depends only on its own four states, and the
  cache is reused only when those match exactly, so each factor is still a pure function
  of its keys: batching saves Python calls, not correctness.
* ``gtsam``: GTSAM's own ``WnoaInterpFactorPoint2`` wraps a per-time CustomFactor on an
  interpolated state; slower (one Python call per check), kept as the reference.

Replanning is warm-started from the previous plan resampled on the new time grid
(receding horizon), so a replan takes a few LM iterations.
"""

from __future__ import annotations

import dataclasses
import functools
import threading
import time
from dataclasses import dataclass

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, V, X

from . import factors
from .config import PlannerConfig
from .gp import Plan, interpolation_weights
from .world import SignedDistanceField


class PlanningError(RuntimeError):
    """The planner could not produce a plan (bad input or a solver failure)."""


@dataclass(frozen=True)
class PeerConstraint:
    """A peer's shared plan (held constant) and the safety distance to keep from it."""

    plan: Plan
    epsilon: float


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


@dataclass(frozen=True)
class PlanResult:
    plan: Plan
    iterations: int
    initial_error: float
    final_error: float
    time_ms: float
    warm: bool


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
    if request.warm_start is not None:
        values = _values(anchored(request.warm_start.resampled(t0, dt, n), request.position, request.velocity))
    else:
        # Cold start: the route at a few different paces (early, even, late through the
        # middle); LM starts from the one whose checks cost least, typically the one
        # that is not where the peers are when they are there.
        sigmas = factors.interval_sigmas(problem, config.sigma_obstacle, config.sigma_proximity,
                                         config.sigma_speed, config.sigma_lane, config.sigma_consistency)
        candidates = [seed_plan(request, t0, dt, n, pace) for pace in SEED_PACES]
        values = _values(min(candidates, key=lambda seed: _checks_cost(problem, seed, sigmas)))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(config.max_iterations)
    params.setRelativeErrorTol(config.relative_error_tol)
    params.setAbsoluteErrorTol(config.absolute_error_tol)
    params.setlambdaInitial(config.lambda_initial)
    params.setlambdaFactor(config.lambda_factor)
    params.setDiagonalDamping(config.diagonal_damping)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, values, params)
    initial_error = graph.error(values)
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
    return graph


def interval_problem(request: PlanRequest, config: PlannerConfig, sdf: SignedDistanceField,
                     t0: float, dt: float) -> factors.IntervalProblem:
    """The constants of every interval's checks for this replan."""
    n = config.support_states
    fractions = factors.check_fractions(config.interp_checks)
    check_times = t0 + (np.arange(n - 1)[:, None] + fractions[None, :]) * dt  # (I, K)
    peers = request.peers if config.proximity or config.consistency else ()
    if peers and config.proximity:
        peer_positions = np.stack([p.plan.position_at(check_times.ravel()).reshape(*check_times.shape, 2)
                                   for p in peers], axis=2)
        epsilons = np.array([p.epsilon for p in peers])
    else:
        peer_positions = np.zeros((n - 1, len(fractions), 0, 2))
        epsilons = np.zeros(0)
    targets = None
    if config.consistency and peers:
        # abar_i: the peers' mean acceleration magnitude over interval i.
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


def route_segments(request: PlanRequest) -> np.ndarray:
    """The lane centre line as segments of the polyline lane[0] -> ... -> goal."""
    points = np.array([*request.lane, request.goal], dtype=float)
    if len(points) < 2:
        return np.zeros((0, 2, 2))
    return np.stack([points[:-1], points[1:]], axis=1)


class BatchedIntervals:
    """Evaluates every interval of a trajectory in one vectorised call, for many factors.

    GTSAM linearises (or evaluates) factors one after another on the same Values; the
    first interval factor to ask computes all intervals, the others read their slice.
    A slice is served only if the factor's own four states equal those it was computed
    from, so a factor's output never depends on any other key.
    """

    def __init__(self, problem: factors.IntervalProblem, n: int):
        self.problem = problem
        self.n = n
        self._lock = threading.Lock()
        self._keys = [(X(i), V(i)) for i in range(n)]
        self._states: list[tuple[float, float, float, float]] = []
        self._residual: np.ndarray | None = None
        self._jacobian: np.ndarray | None = None
        self.evaluations = 0

    def _state(self, values: gtsam.Values, i: int) -> tuple[float, float, float, float]:
        x, v = self._keys[i]
        p, w = values.atPoint2(x), values.atVector(v)
        return (p[0], p[1], w[0], w[1])

    def interval(self, i: int, values: gtsam.Values, want_jacobian: bool
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        left, right = self._state(values, i), self._state(values, i + 1)
        with self._lock:
            fresh = (
                self._residual is not None
                and (self._jacobian is not None or not want_jacobian)
                and self._states[i] == left and self._states[i + 1] == right
            )
            if not fresh:
                positions = gtsam.utilities.extractVectors(values, "x")
                velocities = gtsam.utilities.extractVectors(values, "v")
                self._states = [tuple(row) for row in np.hstack([positions, velocities]).tolist()]
                self._residual, self._jacobian = factors.evaluate_intervals(
                    self.problem, positions, velocities, jacobians=want_jacobian)
                self.evaluations += 1
            residual = self._residual[i]
            jacobian = self._jacobian[i] if want_jacobian else None
        return residual, jacobian


def _batched_interval_error(batch: BatchedIntervals, i: int, this: gtsam.CustomFactor,
                            values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
    residual, jacobian = batch.interval(i, values, H is not None)
    if H is not None:
        for j in range(4):
            H[j] = jacobian[:, j, :]
    return residual


def add_batched_checks(graph: gtsam.NonlinearFactorGraph, problem: factors.IntervalProblem,
                       config: PlannerConfig) -> BatchedIntervals:
    n = config.support_states
    batch = BatchedIntervals(problem, n)
    sigmas = factors.interval_sigmas(problem, config.sigma_obstacle, config.sigma_proximity,
                                     config.sigma_speed, config.sigma_lane, config.sigma_consistency)
    model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
    for i in range(n - 1):
        keys = [X(i), V(i), X(i + 1), V(i + 1)]
        graph.add(gtsam.CustomFactor(model, keys, functools.partial(_batched_interval_error, batch, i)))
    return batch


# --- the reference construction with GTSAM's own interpolation factor ----------------------


def _check_error(problem: factors.IntervalProblem, i: int, k: int, this: gtsam.CustomFactor,
                 values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
    """Rows of one check on (p, v) at check time k of interval i (keys: p, v)."""
    keys = this.keys()
    p = values.atPoint2(keys[0])
    v = values.atPoint2(keys[1])  # interpolated velocities are stored as Vector2
    residual, d_dp, d_dv = factors.check_residuals(
        p, v, problem.peer_positions[i, k], problem.epsilons, problem.sdf,
        problem.epsilon_obstacle, problem.max_speed, problem.lane)
    if H is not None:
        H[0] = d_dp
        H[1] = d_dv
    return residual


def _consistency_error(problem: factors.IntervalProblem, i: int, this: gtsam.CustomFactor,
                       values: gtsam.Values, H: list[np.ndarray] | None) -> np.ndarray:
    keys = this.keys()
    v0, v1 = values.atVector(keys[0]), values.atVector(keys[1])
    a = (v1 - v0) / problem.dt
    root = np.sqrt(a @ a + factors.SMOOTH_ACCEL_DELTA**2)
    excess = root - factors.SMOOTH_ACCEL_DELTA - problem.consistency_targets[i]
    if H is not None:
        da = (a / root / problem.dt)[None, :] if excess > 0.0 else np.zeros((1, 2))
        H[0] = -da
        H[1] = da
    return np.array([max(excess, 0.0)])


def add_gtsam_interp_checks(graph: gtsam.NonlinearFactorGraph, problem: factors.IntervalProblem,
                            config: PlannerConfig, states: list, qc: np.ndarray) -> None:
    sigmas = factors.check_sigmas(problem, config.sigma_obstacle, config.sigma_proximity,
                                  config.sigma_speed, config.sigma_lane)
    model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
    fractions = factors.check_fractions(config.interp_checks)
    index = 0
    for i in range(len(states) - 1):
        left, right = states[i], states[i + 1]
        graph.add(gtsam.CustomFactor(model, [X(i), V(i)], functools.partial(_check_error, problem, i, 0)))
        for k in range(1, len(fractions)):
            t = left.time + fractions[k] * (right.time - left.time)
            inner = gtsam.CustomFactor(model, [A(index), B(index)],
                                       functools.partial(_check_error, problem, i, k))
            interp = gtsam.StateData(A(index), B(index), t)
            graph.add(gtsam.WnoaInterpFactorPoint2(inner, {left, right}, {interp}, qc, True))
            index += 1
        if problem.consistency_targets is not None:
            graph.add(gtsam.CustomFactor(
                gtsam.noiseModel.Isotropic.Sigma(1, config.sigma_consistency), [V(i), V(i + 1)],
                functools.partial(_consistency_error, problem, i)))


# --- seeding and checks ----------------------------------------------------------------------


COARSE_MIN_STATES = 11
"""Cold starts with at least 2 * this - 1 support states are solved coarse to fine."""
SEED_PACES = (1.0, 0.6, 1.6, 2.4)
"""Exponents gamma of the cold-start time warps u -> u**gamma (1: even pace)."""


def _values(plan: Plan) -> gtsam.Values:
    values = gtsam.Values()
    for i in range(plan.n):
        values.insert(X(i), plan.positions[i])
        values.insert(V(i), plan.velocities[i])
    return values


def seed_plan(request: PlanRequest, t0: float, dt: float, n: int, pace: float = 1.0) -> Plan:
    """A cold-start trajectory along start -> via points -> goal, easing in and out.

    The arc length follows smoothstep(w(u)) with w(u) = u**pace on normalised time u, so
    pace > 1 lingers early and hurries late, pace < 1 the reverse.
    """
    points = np.array([request.position, *request.route, request.goal], dtype=float)
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

"""Error functions of our own factors, with analytic Jacobians.

Each function is pure: it maps the four states of one interval of the trajectory,
(p_i, v_i, p_{i+1}, v_{i+1}), to a residual vector and d(residual)/d(state) blocks. The
planner wraps them in GTSAM CustomFactors (agent.planner); tests check every Jacobian
against central differences.

Residual rows of one interval, for the check times tau_k = t_i + u_k*dt (u_0 = 0 is the
support state itself, the rest are GP-interpolated, agent.gp):

for each check k:
  obstacle   (eqs. (4)-(6))  c_obs = max(0, eps_obs - d(p(tau_k)))              1 row
  proximity  (eqs. (7)-(9))  c_t   = max(0, eps_ab - ||p(tau_k) - p_b(tau_k)||)  M rows
             against each peer b's shared plan p_b, a constant here, evaluated at the
             same absolute time (so plans with different t0/dt compare correctly)
  speed                      max(0, ||v(tau_k)|| - v_max)                         1 row
  lane                       p(tau_k) - q(p(tau_k)), q the nearest point of the    2 rows
                             car's route polyline (its lane centre line); a soft
                             pull, so a car leaves its lane only to avoid someone
then once per interval:
  consistency (Sec. III.D)   max(0, |a_i|_delta - abar_i)                          1 row
             where a_i = (v_{i+1} - v_i)/dt is the interval's mean acceleration
             (exact for the WNOA mean, whose acceleration is linear in time),
             |a|_delta = sqrt(|a|^2 + delta^2) - delta a smooth magnitude, and abar_i
             the peers' mean acceleration magnitude over the same interval. The hinge
             is one-sided: a car is pulled down to the fleet's acceleration, never
             pushed to accelerate more than it needs (a two-sided pull makes cars copy
             each other's manoeuvres and the fleet oscillates).

A hinge is flat (zero residual, zero Jacobian) when inactive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .world import SignedDistanceField

SMOOTH_ACCEL_DELTA = 0.2
"""delta of the smooth magnitude |a|_delta, m/s^2: keeps the consistency row
differentiable at zero acceleration."""


@dataclass(frozen=True)
class IntervalProblem:
    """Everything an interval's residual depends on besides its own four states.

    Arrays are over intervals I, check times K and peers M.
    """

    dt: float
    weights: np.ndarray
    """(K, 2, 4): [p(tau_k), v(tau_k)] = weights[k] @ [p_i, v_i, p_i+1, v_i+1] per axis."""
    sdf: SignedDistanceField
    epsilon_obstacle: float
    peer_positions: np.ndarray
    """(I, K, M, 2) where each peer's plan says it is at each check time."""
    epsilons: np.ndarray
    """(M,) proximity threshold per peer, eps_ab = eps_0 * g(tau_b)."""
    max_speed: float
    consistency_targets: np.ndarray | None
    """(I,) abar_i, or None when the consistency factor is off."""
    lane: np.ndarray
    """(S, 2, 2) segments (a, b) of the route polyline; S = 0 turns lane keeping off."""

    @property
    def n_checks(self) -> int:
        return self.weights.shape[0]

    @property
    def n_peers(self) -> int:
        return self.peer_positions.shape[2]

    @property
    def rows(self) -> int:
        """Residual rows per interval: K checks of (obstacle, M peers, speed, lane x/y),
        then one consistency row."""
        consistency = 1 if self.consistency_targets is not None else 0
        lane = 2 if len(self.lane) else 0
        return self.n_checks * (self.n_peers + 2 + lane) + consistency


def check_sigmas(problem: IntervalProblem, sigma_obstacle: float, sigma_proximity: float,
                 sigma_speed: float, sigma_lane: float) -> np.ndarray:
    """Noise sigma of the rows of one check, in the order check_residuals emits."""
    lane = [sigma_lane, sigma_lane] if len(problem.lane) else []
    return np.concatenate([[sigma_obstacle], np.full(problem.n_peers, sigma_proximity),
                           [sigma_speed], lane])


def interval_sigmas(problem: IntervalProblem, sigma_obstacle: float, sigma_proximity: float,
                    sigma_speed: float, sigma_lane: float, sigma_consistency: float) -> np.ndarray:
    """Noise sigma of each row of one interval, in the order evaluate_intervals emits."""
    per_check = check_sigmas(problem, sigma_obstacle, sigma_proximity, sigma_speed, sigma_lane)
    parts = [np.tile(per_check, problem.n_checks)]
    if problem.consistency_targets is not None:
        parts.append([sigma_consistency])
    return np.concatenate(parts)


def hinge(epsilon: np.ndarray | float, distance: np.ndarray) -> np.ndarray:
    """max(0, epsilon - d), eqs. (6) and (9)."""
    return np.maximum(0.0, epsilon - distance)


def nearest_on_polyline(p: np.ndarray, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest point q of a polyline to points p (..., 2), and dq/dp (..., 2, 2).

    On a segment's interior q moves along the segment, dq/dp = u u^T (u its unit
    direction); at an end point q is fixed, dq/dp = 0.
    """
    a, b = segments[:, 0], segments[:, 1]  # (S, 2)
    ab = b - a
    length2 = np.maximum(np.sum(ab * ab, axis=-1), 1e-12)
    s = np.sum((p[..., None, :] - a) * ab, axis=-1) / length2  # (..., S)
    interior = (s > 0.0) & (s < 1.0)
    s = np.clip(s, 0.0, 1.0)
    q = a + s[..., None] * ab  # (..., S, 2)
    d2 = np.sum((p[..., None, :] - q) ** 2, axis=-1)
    best = np.argmin(d2, axis=-1)
    q_best = np.take_along_axis(q, best[..., None, None], axis=-2)[..., 0, :]
    unit = ab / np.sqrt(length2)[:, None]
    projector = unit[:, :, None] * unit[:, None, :]  # (S, 2, 2)
    on_interior = np.take_along_axis(interior, best[..., None], axis=-1)[..., 0]
    dq_dp = np.where(on_interior[..., None, None], projector[best], 0.0)
    return q_best, dq_dp


def check_residuals(p: np.ndarray, v: np.ndarray, peer_positions: np.ndarray,
                    epsilons: np.ndarray, sdf: SignedDistanceField, epsilon_obstacle: float,
                    max_speed: float, lane: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rows of the checks at positions p (..., 2) with velocities v (..., 2).

    Returns the residuals (..., R) with R = M + 2 (+ 2 with a lane) rows [obstacle,
    peer 1..M, speed, lane x, lane y] and their derivatives d/dp and d/dv, (..., R, 2).
    """
    # Obstacle, eq. (6): c = max(0, eps - d(p)); dc/dp = -grad d where active.
    dist, grad = sdf.distance_and_gradient(p)
    active = dist < epsilon_obstacle
    obstacle = hinge(epsilon_obstacle, dist)
    obstacle_dp = np.where(active[..., None], -grad, 0.0)

    # Proximity, eq. (9): c = max(0, eps_b - |p - p_b|); dc/dp = -(p - p_b)/|p - p_b|.
    diff = p[..., None, :] - peer_positions  # (..., M, 2)
    d = np.sqrt(np.sum(diff * diff, axis=-1))
    active = d < epsilons
    proximity = hinge(epsilons, d)
    safe_d = np.where(d > 1e-9, d, 1.0)
    proximity_dp = np.where(active[..., None], -diff / safe_d[..., None], 0.0)

    # Soft speed limit: c = max(0, |v| - vmax); dc/dv = v/|v| where active.
    speed = np.sqrt(np.sum(v * v, axis=-1))
    active = speed > max_speed
    over = np.where(active, speed - max_speed, 0.0)
    safe_speed = np.where(speed > 1e-9, speed, 1.0)
    speed_dv = np.where(active[..., None], v / safe_speed[..., None], 0.0)

    rows = [obstacle[..., None], proximity, over[..., None]]
    zeros = np.zeros_like(obstacle_dp)[..., None, :]
    d_dp = [obstacle_dp[..., None, :], proximity_dp, zeros]
    d_dv = [zeros, np.zeros_like(proximity_dp), speed_dv[..., None, :]]
    if lane is not None and len(lane):
        # Lane keeping: residual p - q(p); d/dp = I - dq/dp.
        q, dq_dp = nearest_on_polyline(p, lane)
        rows.append(p - q)
        d_dp.append(np.eye(2) - dq_dp)
        d_dv.append(np.zeros_like(dq_dp))
    return (np.concatenate(rows, axis=-1), np.concatenate(d_dp, axis=-2),
            np.concatenate(d_dv, axis=-2))


def evaluate_intervals(problem: IntervalProblem, positions: np.ndarray, velocities: np.ndarray,
                       intervals: np.ndarray | None = None, jacobians: bool = True
                       ) -> tuple[np.ndarray, np.ndarray | None]:
    """Residuals (I, R) and Jacobians (I, R, 4, 2) of the given intervals, vectorised.

    ``positions``/``velocities`` are the support states (N, 2); ``intervals`` selects which
    intervals i (default: all N-1). Jacobian block j of a row is d(row)/d(state j) with
    states ordered (p_i, v_i, p_{i+1}, v_{i+1}).
    """
    if intervals is None:
        intervals = np.arange(len(positions) - 1)
    # States of each interval stacked as (I, 4, 2): p_i, v_i, p_{i+1}, v_{i+1}.
    states = np.stack([positions[intervals], velocities[intervals],
                       positions[intervals + 1], velocities[intervals + 1]], axis=1)
    w_pos = problem.weights[:, 0, :]  # (K, 4)
    w_vel = problem.weights[:, 1, :]
    p = np.einsum("kj,ijd->ikd", w_pos, states)  # (I, K, 2): GP-interpolated positions
    v = np.einsum("kj,ijd->ikd", w_vel, states)
    r, d_dp, d_dv = check_residuals(p, v, problem.peer_positions[intervals], problem.epsilons,
                                    problem.sdf, problem.epsilon_obstacle, problem.max_speed,
                                    problem.lane)
    n_int = len(intervals)
    residual = r.reshape(n_int, -1)
    consistency = problem.consistency_targets is not None
    if consistency:
        # |a|_delta - abar with a = (v_{i+1} - v_i)/dt.
        a = (states[:, 3] - states[:, 1]) / problem.dt  # (I, 2)
        root = np.sqrt(np.sum(a * a, axis=-1) + SMOOTH_ACCEL_DELTA**2)
        excess = root - SMOOTH_ACCEL_DELTA - problem.consistency_targets[intervals]
        consistency_active = excess > 0.0
        residual = np.concatenate([residual, np.maximum(excess, 0.0)[:, None]], axis=1)
    if not jacobians:
        return residual, None
    # Chain rule through the interpolation: d row/d state_j = d_dp * w_pos[k, j] + d_dv * w_vel[k, j].
    jac = (np.einsum("ikrd,kj->ikrjd", d_dp, w_pos) + np.einsum("ikrd,kj->ikrjd", d_dv, w_vel))
    jac = jac.reshape(n_int, -1, 4, 2)
    if consistency:
        da = np.where(consistency_active[:, None], a / root[:, None] / problem.dt, 0.0)  # d/dv_{i+1}
        extra = np.zeros((n_int, 1, 4, 2))
        extra[:, 0, 1] = -da
        extra[:, 0, 3] = da
        jac = np.concatenate([jac, extra], axis=1)
    return residual, jac


def check_fractions(n_interp: int) -> np.ndarray:
    """u_k of the check times within an interval: the support state, then n_interp more."""
    return np.arange(n_interp + 1) / (n_interp + 1)


def acceleration_magnitudes(velocities: np.ndarray, dt: float) -> np.ndarray:
    """|a_i| = |(v_{i+1} - v_i)/dt| of each interval of a plan (N-1,)."""
    return np.linalg.norm(np.diff(velocities, axis=0), axis=1) / dt
